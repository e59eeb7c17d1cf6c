"""`mech2spice verify`: formal equivalence and co-simulation against Icarus (mech2spice/verify.py)."""
from __future__ import annotations

from pathlib import Path

from .. import inputs
from ..backends import BACKENDS
from ..errors import Mech2SpiceError
from ..physics.network import MAX_FANOUT
from ..verify import COSIM_BUDGET_S, PROOF_BUDGET_S, check_names, exit_code, junit_xml, reset_ports, text, verify


def add_parser(subparsers) -> None:
    """Register the `verify` command."""
    s = subparsers.add_parser(
        "verify", help="prove the NOR network equal to the Verilog and co-simulate it against Icarus",
        description="1. Formal equivalence of the mapped NOR network (written back as Verilog) and the source, "
                    "with Yosys (miter + SAT: an induction step and a bounded check from the all-zero state, the resets "
                    "asserted in cycle 0; a counterexample replayed on Icarus and the logic backend). "
                    "2. Co-simulation of the source on Icarus Verilog against a backend on the same vectors "
                    "(clocked: a reset cycle, then random inputs per cycle). Exit 0 when proved and every bit "
                    "agrees, 1 on a counterexample, a mismatch, an invalid output or an unproved equivalence.")
    s.add_argument("design", help="Verilog file")
    s.add_argument("--top", help="top module (default: the only/auto-detected top)")
    s.add_argument("--backend", default="logic", choices=list(BACKENDS),
                   help="the network's engine for the co-simulation (default logic; a physical one runs a sample)")
    s.add_argument("--vectors", type=inputs.integer(1, 10_000_000), metavar="N",
                   help="random input vectors (default 2000 on logic, 16 on a physical backend; all of them when "
                        "there are no more)")
    s.add_argument("--exhaustive", action="store_true", help="every input vector (combinational designs)")
    s.add_argument("--cycles", type=inputs.integer(1, inputs.MAX_CYCLES), metavar="N",
                   help="clock cycles after the reset cycle's start (default 1000 on logic, 8 on a physical backend)")
    s.add_argument("--reset", metavar="PORT[=LEVEL]", action="append",
                   help="a reset asserted in cycle 0 (and now and then later) of the co-simulation and the proof, "
                        "at LEVEL (1: active high, 0: active low); repeat for several; 'none': no reset. Default: "
                        "the inputs the source's flip-flops reset on, with their polarity (Yosys's $sdff/$adff "
                        "cells), else an input named rst/reset (high) or rst_n/rstn/reset_n/resetn (low)")
    s.add_argument("--proof-time", type=inputs.number(1, 86400), metavar="S", default=PROOF_BUDGET_S,
                   help=f"wall-clock budget of the proof in seconds (default {PROOF_BUDGET_S}); when it runs out the "
                        "equivalence is 'unknown' with the depth reached")
    s.add_argument("--cosim-time", type=inputs.number(1, 86400), metavar="S", default=COSIM_BUDGET_S,
                   help=f"wall-clock budget of each Icarus run of the co-simulation in seconds (default "
                        f"{COSIM_BUDGET_S}); when it runs out, the cycles (vectors) Icarus read are the ones compared, "
                        "and the report says how many")
    s.add_argument("--proof-engine", choices=("auto", "abc", "sat"), default="auto",
                   help="the equivalence proof's engine: auto (default: Berkeley ABC's pdr/iprove first with 3/4 of "
                        "the budget when berkeley-abc is installed, then Yosys sat), abc, or sat (docs/verify.md)")
    s.add_argument("--seed", type=inputs.integer(0, 2 ** 32 - 1), default=0, help="random seed (default 0)")
    s.add_argument("--params", default="default", help="gate parameters of a physical backend")
    s.add_argument("--max-fanout", type=inputs.integer(2, inputs.MAX_FANOUT_LIMIT), default=MAX_FANOUT,
                   help=f"buffer trees as `simulate` builds them, so the network proved and co-simulated is the "
                        f"one it runs (default {MAX_FANOUT})")
    s.add_argument("--no-equivalence", action="store_true", help="co-simulation only")
    s.add_argument("--junit", metavar="FILE", help="also write a JUnit XML report")
    s.add_argument("--vcd", metavar="FILE",
                   help="also write the co-simulation as a waveform (VCD, for GTKWave or Surfer): inputs, source "
                        "(Icarus) and network per output port, the differing bits, amplitudes in u_R; the proof's "
                        "counterexample replayed in a later time range (docs/waveforms.md)")
    inputs.force_arg(s, "--junit or --vcd")
    s.add_argument("--json", action="store_true", help="machine-readable output")
    s.set_defaults(func=cmd_verify)


JUNIT = ("a JUnit report", lambda p: inputs.head(p, 256).lstrip().startswith(b"<?xml")
          and b"<testsuite " in inputs.head(p))


def _check_junit(args) -> None:
    """--junit, before any work: none of the files the run reads (the design, the files it includes, the
    --params file), and an existing file only if it is a JUnit report (else --force)."""
    from ..physics.params import params_file
    read = [*inputs.design_inputs(args.design), ("the --params file", params_file(args.params))]
    inputs.check_output_file(args.junit, read, "JUnit file", kind=JUNIT, force=args.force)


def _check_vcd(args) -> None:
    """--vcd, before any work, as --junit: none of the files the run reads nor the --junit file, an existing
    file only if it is a VCD file (else --force)."""
    from ..physics.params import params_file
    from ..waveform import is_vcd
    other = [*inputs.design_inputs(args.design), ("the --params file", params_file(args.params))]
    if args.junit:
        other.append(("the --junit file", args.junit))
    inputs.check_output_file(args.vcd, other, "VCD file", kind=("a VCD file", is_vcd), force=args.force)


def cmd_verify(args) -> int:
    """`mech2spice verify`: print the report (text or JSON), write --junit; 0 pass, 1 otherwise."""
    from ._output import log as _log, print_json as _print_json, progress as _progress
    from ..physics.params import load_params
    from ..synthesis.synth import synthesize
    if args.vectors is not None and args.exhaustive:
        raise Mech2SpiceError("give --vectors N or --exhaustive, not both")
    if args.junit:
        _check_junit(args)
    if args.vcd is not None:
        _check_vcd(args)
    if not Path(args.design).is_file():
        raise Mech2SpiceError(f"cannot read Verilog file {args.design}: no such file")
    nl = synthesize(args.design, top=args.top, max_fanout=args.max_fanout)
    check_names(nl)                                # every name the generated Verilog holds, before the work
    if not nl.clocked and args.cycles:
        raise Mech2SpiceError(f"{nl.top} has no flip-flops: --cycles applies to clocked designs (use --vectors)")
    if nl.clocked and (args.vectors or args.exhaustive):
        raise Mech2SpiceError(f"{nl.top} is clocked by {nl.clock_text()}: give --cycles N, not --vectors/--exhaustive")
    if not nl.clocked and args.reset:
        raise Mech2SpiceError(f"{nl.top} has no flip-flops: --reset applies to clocked designs")
    if nl.clocked and args.reset:
        if "none" in args.reset and len(args.reset) > 1:
            raise Mech2SpiceError("--reset none: give it alone (no reset), not beside other --reset ports")
        reset_ports(nl, args.reset)                # checked before the work starts
    params = load_params(args.params) if BACKENDS[args.backend].capabilities.physical else None
    res = verify(args.design, backend=args.backend, vectors=args.cycles or args.vectors, exhaustive=args.exhaustive,
                 seed=args.seed, params=params, progress=_progress(args), log=_log(args), netlist=nl,
                 reset=args.reset, equivalence_check=not args.no_equivalence, proof_time=args.proof_time,
                 keep_trace=args.vcd is not None, proof_engine=args.proof_engine, cosim_time=args.cosim_time)
    if args.junit:
        inputs.write_text(args.junit, junit_xml(res))
    if args.vcd is not None:
        from ..verify_vcd import verify_waveform
        from ..waveform import write_vcd
        wave, sections = verify_waveform(nl, res)
        write_vcd(args.vcd, wave)
        res["vcd"] = {"file": args.vcd, **sections}
    if args.json:
        _print_json(res)
    else:
        print(text(res))
    return exit_code(res)
