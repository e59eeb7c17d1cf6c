"""The `mech2spice` command line.  Command names and JSON fields are a contract: keep them stable."""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import sys
import time

import numpy as np

from . import inputs
from .errors import Mech2SpiceError
from .experiments.trim import add_trim_arguments, trim_from_args

from .backends import BACKENDS
from .physics.network import MAX_FANOUT
from .spice._common import DEFAULT_TIMEOUT_S


def _jsonable(o):
    """numpy values and tuples as JSON; every key is kept (user port names may be anything)."""
    if isinstance(o, dict):
        return {str(k): _jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_jsonable(v) for v in o]
    if isinstance(o, np.ndarray):
        return _jsonable(o.tolist())
    if isinstance(o, (np.floating, float)):
        return None if not np.isfinite(o) else float(o)
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.bool_,)):
        return bool(o)
    return o


def _print_json(data) -> None:
    print(json.dumps(_jsonable(data), indent=2))


def _progress(args):
    """Progress of long steps on stderr: a bar on a terminal; redirected, a timestamped line every
    backends._base.PROGRESS_EVERY_S (a log file still shows the run moving); nothing with --json."""
    if getattr(args, "json", False):
        return False
    return True if sys.stderr.isatty() else _log(args)


def _log(args):
    quiet = getattr(args, "json", False)
    t0 = time.time()
    return (lambda msg: None) if quiet else (lambda msg: print(f"[{time.time() - t0:6.1f}s] {msg}",
                                                               file=sys.stderr, flush=True))


# --- gate ----------------------------------------------------------------------
def cmd_gate(args) -> int:
    """`mech2spice gate`: characterise the NOR gate (or --sens/--spread); print text or JSON, return 0."""
    from .experiments import characterise
    from .physics.params import load_params
    p = load_params(args.params)
    trim = trim_from_args(args, args.spread is not None)
    if args.sens or args.spread is not None:
        return _gate_robustness(args, p, trim)
    if args.samples is not None or args.seed is not None:
        raise Mech2SpiceError("--samples and --seed apply to --spread SIGMA")
    out = characterise.characterise(p, quick=args.quick, log=_log(args))
    if out.get("diverged"):
        raise Mech2SpiceError(f"parameters '{p.name}': the RK4 truth-table run failed: {out['diverged']}")
    if args.report:
        from .reports.gate import write_gate_report
        write_gate_report(out, args.report, log=_log(args))
    out.pop("_figures", None)             # the report's plot data, not part of the result
    out["pass"] = bool(out.get("switches")) and out.get("min_margin", -1) > 0 and all(
        r["pass"] for r in out.get("requirements", {}).values())
    if args.json:
        _print_json(out)
    else:
        _print_gate(out)
    return 0


def _gate_robustness(args, p, trim) -> int:
    """`gate --sens` / `gate --spread`: sensitivities and tolerance instead of the characterisation."""
    from .experiments import tolerance
    if args.quick or args.report:
        raise Mech2SpiceError("--quick and --report apply to the characterisation, not to --sens/--spread")
    if args.spread is None and (args.samples is not None or args.seed is not None):
        raise Mech2SpiceError("--samples and --seed apply to --spread SIGMA")
    out = tolerance.robustness(p, args.sens, args.spread, 200 if args.samples is None else args.samples,
                               0 if args.seed is None else args.seed, log=_log(args), trim=trim)
    if args.json:
        _print_json(out)
    else:
        print(tolerance.text(out))
    return 0


def _print_gate(out: dict) -> None:
    print(f"parameters: {out['params']['name']}   omega = {out['params']['omega']:.6g} rad/s")
    print("truth table (RK4, amplitudes in u_R):")
    for r in out["truth_table"]:
        logic = "invalid" if r["logic"] is None else r["logic"]
        print(f"  {r['inputs'][0]}{r['inputs'][1]} -> {r['output_amplitude']:.4f}  logic {logic}  "
              f"(NOR = {r['expected']}, margin {r['margin']:+.3f})")
    print(f"gate switches: {'yes' if out['switches'] else 'NO'}")
    print(f"RK4 vs steady state: {out['rk4_vs_steady']:.2e} u_R; "
          f"halving the RK4 step changes outputs by {out['step_halving_change']:.1e} u_R")
    print(f"min margin over valid inputs (steady state): {out['min_margin']:+.4f} of a band "
          f"at inputs {out['min_margin_detail'].get('at_inputs')}")
    if "omega_scan" in out:
        s = out["omega_scan"]
        print(f"scan over omega: largest channel amplitude {s['max_channel_amplitude']:.3g} u_R, "
              f"largest 00-vs-11 contrast {s['max_switch_contrast']:.2e} u_R (at omega = {s['at_omega']:.3g})")
    if "delay_periods" in out:
        print(f"delay: {out['delay_periods']:.0f} periods per gate (mean), {out['delay_max_periods']:.0f} max")
    for name, r in out.get("requirements", {}).items():
        print(f"  [{'pass' if r['pass'] else 'FAIL'}] {name}: {r['figure']}")


# --- synth / simulate ------------------------------------------------------------
def _netlist(args):
    from .synthesis.synth import observe, synthesize
    nl = synthesize(args.design, top=args.top, max_fanout=getattr(args, "max_fanout", None))
    return observe(nl, args.observe) if getattr(args, "observe", None) else nl


def cmd_synth(args) -> int:
    """`mech2spice synth`: synthesize a design and print its gate, latch, oscillator and spring counts."""
    from .physics import network
    from .physics.params import load_params
    nl = _netlist(args)
    model = network.build(nl, load_params(args.params))
    out = {"top": nl.top, "gates": len(model.design.gates), "latches": len(nl.latches()), **model.counts(),
           "inputs": nl.inputs, "outputs": nl.outputs, "clock": nl.clock, "logic_gates": len(nl.gates()),
           "logic_depth": network.logic_depth(nl),
           "signed": [p for p in {**nl.inputs, **nl.outputs} if p in nl.signed]}     # two's complement ports
    if args.json:
        _print_json(out)
    else:
        print(f"{out['top']}: {out['gates']} NOR gates ({out['logic_gates']} logic + {out['latches']} latches), "
              f"logic depth {out['logic_depth']}" + (f", clock '{nl.clock}'" if nl.clock else ""))
        print(f"  {out['oscillators']} oscillators, {out['linear_springs']} linear springs, "
              f"{out['nonlinear_springs']} nonlinear springs, {out['dashpots']} dashpots")
        print(f"  inputs  {out['inputs']}\n  outputs {out['outputs']}"
              + (f"\n  signed  {', '.join(out['signed'])} (two's complement values)" if out["signed"] else ""))
    return 0


def _parse_sets(items: list[str]) -> dict[str, int]:
    return inputs.parse_sets(items)


def _clocked_steps(args, nl) -> list[dict]:
    """The clocked stimulus from --stimulus or --cycles, checked (shape, types, the cycle cap)."""
    if args.stimulus and args.cycles:
        raise Mech2SpiceError("give --cycles or --stimulus, not both")
    if args.stimulus:
        return inputs.stimulus_steps(args.stimulus, _parse_sets(args.set), args.backend)
    if not args.cycles:
        raise Mech2SpiceError(f"{nl.top} is clocked by '{nl.clock}': give --cycles N or --stimulus FILE.json")
    inputs.check_cycles(args.cycles, args.backend)
    return [{"set": _parse_sets(args.set), "cycles": args.cycles}]


def cmd_simulate_clocked(args, nl) -> int:
    """`simulate` for a clocked design: run the cycles and print the trace; 0 if every cycle is valid, else 1."""
    from . import simulation
    from .physics.params import load_params
    if args.clock and args.clock != nl.clock:
        raise Mech2SpiceError(f"--clock {args.clock}: the design's flip-flops are clocked by '{nl.clock}'")
    cycles = simulation.expand_steps(_clocked_steps(args, nl))
    if args.backend == "logic":
        res = simulation.run_clocked_logic(nl, cycles)
    else:
        p = load_params(args.params)
        timing = simulation.clock_timing(nl, args.pulse, args.pause, p)
        res = simulation.run_clocked_physical(nl, p, cycles, args.backend, timing,
                                            progress=_progress(args),
                                            options=_engine_options(args), log=_log(args),
                                            noise=(args.noise, args.noise_seed))
    if args.json:
        _print_json(res)
    else:
        if "timing" in res:
            t = res["timing"]
            print(f"clock: pulse {t['pulse']} periods, pause {t['pause']} periods "
                  f"(derived from logic depth {t['logic_depth']}: {t['derived_pause']})")
        for e in res["trace"]:
            outs = ", ".join(f"{p}={'invalid' if v is None else v}" for p, v in e["outputs"].items())
            mg = "" if e["min_margin"] is None else f"  (margin {e['min_margin']:+.3f})"
            print(f"  cycle {e['cycle']:4d}: {outs}{mg}")
        print(f"backend {res['backend']}, {res['periods']} periods, {res['wall_s']:.1f} s, valid: {res['valid']}")
    return 0 if res["valid"] else 1


def cmd_simulate(args) -> int:
    """`mech2spice simulate`: run one input set (or the clock cycles); 0 if the outputs are valid, else 1."""
    from . import simulation
    from .physics.params import load_params
    nl = _netlist(args)
    if nl.clock:
        return cmd_simulate_clocked(args, nl)
    if args.cycles or args.stimulus or args.clock:
        raise Mech2SpiceError(f"{nl.top} has no flip-flops: --clock/--cycles/--stimulus apply to clocked designs")
    values = _parse_sets(args.set)
    res = simulation.run_physical(nl, load_params(args.params), [values], args.backend, periods=args.periods,
                                progress=_progress(args), options=_engine_options(args),
                                log=_log(args), noise=(args.noise, args.noise_seed))[0]
    res["inputs"] = values
    if args.json:
        _print_json(res)
    else:
        for port, v in res["outputs"].items():
            print(f"{port} = {'invalid' if v is None else v}")
        for bit, a in res["amplitudes"].items():
            print(f"  {bit}: {a:.4f} u_R -> {'invalid' if res['bits'][bit] is None else res['bits'][bit]}")
        print(f"backend {res['backend']}, {res['periods']} periods, {res['wall_s']:.1f} s, valid: {res['valid']}")
    return 0 if res["valid"] else 1


# --- SPICE --------------------------------------------------------------------------
def cmd_emit(args) -> int:
    """`mech2spice emit`: write the design as an ngspice or VACASK netlist, or the Verilog-A library."""
    from . import simulation
    from .physics import network
    from .synthesis.ports import pack_inputs
    from .physics.params import load_params
    p = load_params(args.params)
    if args.format == "veriloga":                  # the device library, defaults from --params
        import re
        from .spice import veriloga
        text = veriloga.combined(p)
        inputs.write_text(args.output, text, encoding="ascii")
        info = {"netlist": args.output, "format": "veriloga", "modules": re.findall(r"^module (\w+)", text, re.M)}
        if args.json:
            _print_json(info)
        else:
            print(f"wrote {args.output}: Verilog-A, {len(info['modules'])} modules; compile with openvaf-r")
        return 0
    nl = _netlist(args)
    values = _parse_sets(args.set)
    pack_inputs(nl, values)
    model = network.build(nl, p)
    stim = network.stimulus(model, nl, p, [(0, [values])])
    periods = args.periods or simulation.period_budget(nl)
    title = f"mech2spice: {nl.top} with {', '.join(f'{k}={v}' for k, v in values.items()) or 'inputs 0'}"
    from .spice.readout import about as about_line
    about = about_line(args.design, nl.top, values)
    if args.format == "ngspice":
        from .spice import carrier as spice
        opts = _engine_options(args, "ngspice")
        text = spice.emit(model, periods, stim, options=opts, title=title, about=about)
        run_with = f"ngspice -b {args.output} (it prints each output bit and port it reads)"
    elif args.format == "ngspice-envelope":
        from .spice import envelope
        opts = _engine_options(args, "ngspice-envelope")
        text = envelope.emit_envelope(model, stim, periods, opts, title=title, about=about)
        run_with = f"ngspice -b {args.output} (it prints each output bit and port it reads)"
    else:                                          # vacask | vacask-envelope: Verilog-A embedded, one file
        from dataclasses import replace
        from .spice import vacask
        form = vacask.ENVELOPE if args.format == "vacask-envelope" else vacask.CARRIER
        opts = (vacask.VacaskEnvelopeOptions if form == vacask.ENVELOPE else vacask.VacaskOptions)()
        opts = replace(opts, **{k: v for k, v in (("method", args.method), ("max_step_periods", args.max_step))
                                if v is not None})
        text = vacask.emit(model, periods, stim, options=opts, form=form, title=title, standalone=True,
                           about=about).text
        run_with = f"vacask {args.output} (in its folder: it writes the .va and tran1.raw there)"
    inputs.write_text(args.output, text, encoding="ascii")    # the path was checked before the work
    info = {"netlist": args.output, "format": args.format, "periods": periods, "oscillators": model.n,
            "probes": list(model.probes), "options": _jsonable(opts.__dict__)}
    if args.json:
        _print_json(info)
    else:
        print(f"wrote {args.output}: {model.n} oscillators, {periods} periods; run with: {run_with}")
    return 0


def _envelope_speed_options(args, name: str) -> dict:
    """--latency TOL|off (envelope, carrier), --exponential on|off, --parallel on|off: the engines' speed-ups."""
    given = {k: getattr(args, k, None) for k in ("latency", "exponential", "parallel")}
    given = {k: v for k, v in given.items() if v is not None}
    if "latency" in given and name == "carrier":
        if set(given) != {"latency"}:
            raise Mech2SpiceError("--exponential and --parallel: envelope backend options, not carrier's")
    elif given and name != "envelope":
        raise Mech2SpiceError(f"{', '.join('--' + k for k in given)}: envelope backend options, not {name}'s")
    return {k: (v or None) if k == "latency" else v == "on" for k, v in given.items()}


def _engine_options(args, backend: str | None = None):
    """The engine's options from the flags: --steps (steps per drive period), --method / --max-step (ngspice)."""
    from dataclasses import replace
    from .backends import engine_class
    name = backend or args.backend
    steps, method, max_step = (getattr(args, k, None) for k in ("steps", "method", "max_step"))
    changes = {}
    timeout = getattr(args, "ngspice_timeout", None)
    if name.startswith(("ngspice", "vacask")):                 # the circuit simulators' settings
        changes.update({k: v for k, v in (("method", method), ("max_step_periods", max_step), ("timeout_s", timeout))
                        if v is not None})
        if steps:
            raise Mech2SpiceError(f"--steps applies to rk4, carrier and envelope; {name}'s step is --max-step")
    elif method or max_step or timeout:
        raise Mech2SpiceError(f"--method, --max-step and --ngspice-timeout apply to the circuit simulators "
                              f"(ngspice, vacask), not {name}")
    elif steps and name in ("rk4", "carrier"):
        changes["steps_per_period"] = steps
    elif steps and name == "envelope":
        changes["step_periods"] = 1.0 / steps
    changes.update(_envelope_speed_options(args, name))
    options = replace(engine_class(name).Options(), **changes)
    options.validate()
    return options


def cmd_subckts(args) -> int:
    """`mech2spice subckts`: write the ngspice .subckt library for --params and list its files."""
    from .physics.params import load_params
    from .spice.carrier import write_subckt_library
    paths = write_subckt_library(args.output, load_params(args.params))
    if args.json:
        _print_json({"files": [str(x) for x in paths]})
    else:
        for x in paths:
            print(x)
    return 0


# --- parser --------------------------------------------------------------------
class _Parser(argparse.ArgumentParser):
    """argparse with usage errors as one line (exit 2), like every other error."""

    def error(self, message):
        """Print the usage error as one line on stderr and exit 2."""
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (see {self.prog} --help)\n")


def _backends_help() -> str:
    """Each registered engine with the first line of its docstring (the registry is the one list)."""
    return "the engine (default rk4): " + "; ".join(
        f"{name}: {(cls.__doc__ or '').strip().splitlines()[0].rstrip('.')}" for name, cls in BACKENDS.items())


def version() -> str:
    """The installed distribution's version, else (a source tree run in place) the package's own."""
    from importlib import metadata
    try:
        return metadata.version("mech2spice")
    except metadata.PackageNotFoundError:
        from . import __version__
        return __version__


def build_parser() -> argparse.ArgumentParser:
    """The `mech2spice` argument parser with every subcommand."""
    ap = _Parser(
        prog="mech2spice",
        description="Verilog -> networks of nonlinear mechanical NOR gates -> RK4 / envelope / ngspice.")
    ap.add_argument("--version", action="version", version=f"mech2spice {version()}")
    sub = ap.add_subparsers(dest="command", required=True)

    g = sub.add_parser("gate", help="characterise the NOR gate against the paper's six requirements",
                       description="Characterise the mechanical NOR gate: truth table decoded from RK4, "
                                   "steady-state map and margin, cascade, delay, fan-out, requirements.")
    g.add_argument("--params", default="default", help="'default', 'printed' (Appendix A), a shipped block "
                   "('robust', 'classic') or a JSON file (fields, or a block file: docs/design.md)")
    g.add_argument("--quick", action="store_true", help="shorter runs (about 1 minute)")
    g.add_argument("--report", metavar="DIR", help="also write DIR/gate.md and PNG figures")
    g.add_argument("--json", action="store_true", help="machine-readable output")
    g.add_argument("--sens", action="store_true",
                   help="sensitivity of the outputs and margins to every element (docs/robustness.md)")
    g.add_argument("--spread", type=inputs.number(0, 1), metavar="SIGMA",
                   help="relative Gaussian spread on every element: yield, margin quantiles, tolerance")
    g.add_argument("--samples", type=inputs.integer(1, 100_000), metavar="N",
                   help="Monte-Carlo samples for --spread (default 200)")
    g.add_argument("--seed", type=inputs.integer(0, 2 ** 32 - 1), metavar="S",
                   help="random seed for --spread (default 0)")
    add_trim_arguments(g)
    g.set_defaults(func=cmd_gate)

    def design_args(sp):
        sp.add_argument("design", help="Verilog file")
        sp.add_argument("--top", help="top module (default: the only/auto-detected top)")
        sp.add_argument("--params", default="default", help="gate parameters: default, printed, robust, classic "
                        "or a JSON file (fields, or a block file: docs/design.md)")
        sp.add_argument("--max-fanout", type=inputs.integer(2, inputs.MAX_FANOUT_LIMIT), default=MAX_FANOUT,
                        help="insert NOR-pair buffers so no gate drives more loads (default 12, the largest "
                             "fan-out measured to work)")
        sp.add_argument("--observe", action="append", metavar="PORT",
                        help="model only these output ports and their fan-in cones (repeatable; cone "
                             "pruning, its amplitude cost: reports/fidelity.md)")
        sp.add_argument("--json", action="store_true", help="machine-readable output")

    s = sub.add_parser("synth", help="synthesise Verilog to mechanical NOR gates and count elements",
                       description="Verilog -> Yosys -> NOR netlist -> mechanical model; prints element counts "
                                   "in the paper's convention (6 oscillators and 5 nonlinear springs per gate; "
                                   "one spring + one dashpot per gate-to-gate connection).")
    design_args(s)
    s.set_defaults(func=cmd_synth)

    s = sub.add_parser("simulate", help="simulate a design and decode its outputs",
                       formatter_class=argparse.RawDescriptionHelpFormatter,
                       description="Apply input values (unset inputs are 0), simulate until the outputs settle "
                                   "(or --periods), and decode each output bit from its amplitude. A bit outside "
                                   "both bands is reported invalid, never rounded; the exit code is 1 then.",
                       epilog="""clocked designs (posedge flip-flops on one clock port):
  --cycles N holds the --set inputs and pulses the clock N times; --stimulus FILE.json applies
  [{"set": {"PORT": INT, ...}, "cycles": N}, ...] in order (settings persist between steps).
  A cycle is a settle phase (clock 0, 'pause' periods) then an enable pulse ('pulse' periods);
  trace entry k holds the outputs read after clock edge k, with the next step's inputs applied.
  The physical run starts with every oscillator at rest. From rest a latch settles to the value at
  its D input, not necessarily 0, so registers without a reset may start differently from the
  logic backend (which starts them at 0): reset them synchronously in the first cycle.""")
    design_args(s)
    s.add_argument("--set", action="append", metavar="PORT=INT", help="input value (repeatable)")
    s.add_argument("--backend", default="rk4", choices=list(BACKENDS), help=_backends_help())
    s.add_argument("--periods", type=inputs.integer(1, inputs.MAX_PERIODS), default=None,
                   help="simulate exactly this many drive periods (default: until the outputs settle)")
    s.add_argument("--steps", type=inputs.integer(1, inputs.MAX_STEPS), default=None,
                   help="steps per drive period (rk4 default 80, carrier 12; envelope default: one step per 4 periods, "
                        "fewer where the stability bound is lower)")
    inputs.envelope_speed_args(s)
    s.add_argument("--method", choices=["trap", "gear"],
                   help="circuit simulator (ngspice, vacask) integration method (default trap)")
    s.add_argument("--max-step", type=inputs.number(0), help="circuit simulator max step in drive periods (default "
                                                            "1/40; the envelope netlists: 2)")
    s.add_argument("--ngspice-timeout", type=inputs.number(0), default=None, metavar="SECONDS",
                   help=f"stop an ngspice or VACASK run after this long (default {DEFAULT_TIMEOUT_S:g} s)")
    s.add_argument("--clock", metavar="PORT", help="the clock port (default: the one clocking the flip-flops)")
    s.add_argument("--cycles", type=inputs.integer(1, inputs.MAX_CYCLES),
                   help=f"clock cycles to run with the --set inputs held (at most {inputs.MAX_CYCLES:,} on the "
                        f"logic backend, {inputs.MAX_PHYSICAL_CYCLES:,} on the others)")
    s.add_argument("--stimulus", metavar="FILE.json", help="clocked stimulus: a list of {set, cycles} steps")
    s.add_argument("--pulse", type=inputs.integer(1, inputs.MAX_PERIODS),
                   help="enable pulse length in drive periods (default 800, measured)")
    s.add_argument("--pause", type=inputs.integer(1, inputs.MAX_PERIODS),
                   help="settle time between pulses in drive periods (default: from logic depth)")
    s.add_argument("--noise", type=inputs.number(0, lo_open=False), default=0.0, metavar="T",
                   help="thermal noise on rk4, envelope, ngspice: k_B T in model energy units (docs/robustness.md)")
    s.add_argument("--noise-seed", type=inputs.integer(0, 2 ** 31 - 1), default=0, metavar="S",
                   help="the thermal noise's seed (default 0)")
    s.set_defaults(func=cmd_simulate)

    s = sub.add_parser("emit", help="write a self-contained ngspice or VACASK netlist of a design, or the Verilog-A library",
                       description="Write DESIGN as a hierarchical netlist: ngspice (library .subckts inlined, "
                                   "stimulus, .tran, .options, .save of the output probes and a .control block: "
                                   "`ngspice -b OUT.cir` runs it and prints each output bit and port it reads), vacask / vacask-envelope (the Verilog-A devices embedded; `vacask "
                                   "OUT.sim` runs it), or veriloga (the device library, defaults from --params).")
    design_args(s)
    s.add_argument("--set", action="append", metavar="PORT=INT", help="input value (repeatable)")
    s.add_argument("-o", "--output", required=True, help="netlist file to write")
    inputs.force_arg(s, "-o")
    s.add_argument("--format", choices=["ngspice", "ngspice-envelope", "vacask", "vacask-envelope", "veriloga"],
                   default="ngspice", help="netlist for ngspice or VACASK (carrier level, the default, or the "
                                           "envelope equations), or the Verilog-A library")
    s.add_argument("--periods", type=inputs.integer(1, inputs.MAX_PERIODS), default=None,
                   help="simulated drive periods (default: settle budget)")
    s.add_argument("--method", choices=["trap", "gear"], help="integration method (default trap)")
    s.add_argument("--max-step", type=inputs.number(0), help="max step in drive periods (default 1/40; "
                                                            "the envelope forms: 2)")
    s.set_defaults(func=cmd_emit)

    from .cpu.cli import add_parser as add_cpu_parser
    add_cpu_parser(sub)
    from .reports.cli import add_parser as add_report_parser; add_report_parser(sub)  # noqa: E702
    from .experiments.mc_cli import add_parser as add_mc_parser; add_mc_parser(sub)  # noqa: E702
    from .design.cli import add_parser as add_design_parser; add_design_parser(sub)  # noqa: E702
    from .verify import add_parser as add_verify_parser; add_verify_parser(sub)  # noqa: E702

    s = sub.add_parser("subckts", help="regenerate the .subckt library (checked in under subckts/)")
    s.add_argument("-o", "--output", default="subckts", help="directory (default subckts/)")
    s.add_argument("--params", default="default", help="gate parameters")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=cmd_subckts)
    return ap


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread so that `finally` blocks and context managers clean up."""


BUG_EXIT = 3
BUG_LINE = ("mech2spice: this is a bug, not a problem with your input: please report it with the command line "
            "and the traceback above")


def main(argv: list[str] | None = None) -> int:
    """Run one command; the exit code is 0, 1 (a valid run with an invalid result), 2 (bad input or an
    expected failure, one line on stderr), 130 (interrupted) or 3 (a bug, with a traceback)."""
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as e:            # --help (0) or a usage error, already printed as one line (2)
        return e.code if isinstance(e.code, int) else 2
    with _signals():
        return _run(args)


def _run(args) -> int:
    """The one handler: every expected failure becomes one line on stderr and exit 2."""
    try:
        _precheck(args)
        code = args.func(args)
        sys.stdout.flush()             # a closed pipe shows here, not at interpreter exit
        return code
    except Mech2SpiceError as e:
        return _fail(str(e))
    except KeyboardInterrupt:
        print("mech2spice: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        _drop_stdout()
        return _fail("the output pipe was closed before everything was written")
    except OSError as e:
        return _fail(f"{e.strerror or e}" + (f": {e.filename}" if e.filename else ""))
    except MemoryError:
        return _fail("out of memory: try a smaller design, fewer cycles or --observe")
    except Exception:
        import traceback
        traceback.print_exc()
        print(BUG_LINE, file=sys.stderr)
        return BUG_EXIT


def _fail(msg: str) -> int:
    print("mech2spice: error: " + " ".join(msg.split()), file=sys.stderr)
    return 2


def _drop_stdout() -> None:
    """Point stdout at /dev/null so Python's final flush does not fail again on the closed pipe."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):     # stdout is not a real file (e.g. under pytest)
        pass


@contextlib.contextmanager
def _signals():
    """SIGTERM and SIGINT stop ngspice children and raise in the main thread (so temp dirs go)."""
    def stop(signum, frame):
        runner = sys.modules.get("mech2spice.spice.runner")
        if runner is not None:
            runner.stop_all()
        raise Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()
    old = {}
    try:
        for sig in (signal.SIGTERM, signal.SIGINT):
            old[sig] = signal.signal(sig, stop)
    except ValueError:                 # not the main thread: leave signals to the caller
        pass
    try:
        yield
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)
        runner = sys.modules.get("mech2spice.spice.runner")
        if runner is not None:
            runner.allow_runs()


def _precheck(args) -> None:
    """Check every user-supplied file before any work: parameters, stimulus, outputs (never an input)."""
    from .physics.params import load_params
    if getattr(args, "params", None) is not None:
        load_params(args.params)
    design, command = getattr(args, "design", None), args.command
    if command == "emit":
        from .spice._common import NETLIST
        read = {"the design": design, "the --params file": inputs.params_file(args.params)}
        inputs.check_output_file(args.output, read, "netlist file", kind=NETLIST, force=args.force)
    elif command == "subckts":
        inputs.check_output_dir(args.output, "subckt directory")
    elif command == "gate" and args.report:
        inputs.check_output_dir(args.report, "report directory")
    if getattr(args, "stimulus", None):
        inputs.stimulus_steps(args.stimulus, {}, args.backend)


if __name__ == "__main__":
    sys.exit(main())
