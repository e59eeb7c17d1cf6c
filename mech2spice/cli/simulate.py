"""`synth`, `simulate`, `emit` and `subckts`: a design through synthesis, an engine or a netlist."""
from __future__ import annotations

import argparse
from pathlib import Path

from .. import inputs
from ..backends import BACKENDS, engine_class
from ..errors import Mech2SpiceError
from ..physics.network import MAX_FANOUT
from ..physics.params import PRESETS, params_file
from ..spice import DEFAULT_TIMEOUT_S
from ._output import jsonable as _jsonable, log as _log, print_json as _print_json, progress as _progress


def design_args(sp) -> None:
    """The arguments every command on one design takes."""
    sp.add_argument("design", help="Verilog file")
    sp.add_argument("--top", help="top module (default: the only/auto-detected top)")
    sp.add_argument("--params", default="default", help=f"gate parameters: {', '.join(PRESETS)} "
                    "or a JSON file (fields, or a block file: docs/design.md)")
    sp.add_argument("--max-fanout", type=inputs.integer(2, inputs.MAX_FANOUT_LIMIT), default=MAX_FANOUT,
                    help="insert NOR-pair buffers so no gate drives more loads (default 12, the largest "
                         "fan-out measured to work)")
    sp.add_argument("--observe", action="append", metavar="PORT",
                    help="model only these output ports and their fan-in cones (repeatable; cone "
                         "pruning, its amplitude cost: reports/fidelity.md)")
    sp.add_argument("--json", action="store_true", help="machine-readable output")


def add_parsers(sub) -> None:
    """Register `synth`, `simulate` and `emit`."""
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
                       epilog="""clocked designs (flip-flops on one edge of one clock port):
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
    s.add_argument("--vcd", metavar="FILE", help="clocked designs: write the trace as a waveform (VCD, for GTKWave "
                   "or Surfer) to FILE: one time unit per cycle, the inputs and output ports as vectors (x: an "
                   "invalid bit), each output bit's amplitude in u_R as a real")
    inputs.force_arg(s, "--vcd")
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
    s.add_argument("--format", choices=[*_circuit_engines(), "veriloga"],
                   default="ngspice", help="netlist for ngspice or VACASK (carrier level, the default, or the "
                                           "envelope equations), or the Verilog-A library")
    s.add_argument("--periods", type=inputs.integer(1, inputs.MAX_PERIODS), default=None,
                   help="simulated drive periods (default: settle budget)")
    s.add_argument("--method", choices=["trap", "gear"], help="integration method (default trap)")
    s.add_argument("--max-step", type=inputs.number(0), help="max step in drive periods (default 1/40; "
                                                            "the envelope forms: 2)")
    s.set_defaults(func=cmd_emit)


def add_subckts_parser(sub) -> None:
    """Register `subckts`."""
    s = sub.add_parser("subckts", help="regenerate the .subckt library (checked in under subckts/)")
    s.add_argument("-o", "--output", default="subckts", help="directory (default subckts/)")
    s.add_argument("--params", default="default", help="gate parameters")
    s.add_argument("--json", action="store_true")
    inputs.force_arg(s, "--output")
    s.set_defaults(func=cmd_subckts)


def _circuit_engines() -> list[str]:
    """The engines that run a circuit simulator: their names are `emit`'s netlist formats."""
    return [name for name, cls in BACKENDS.items() if cls.capabilities.simulator]


def _backends_help() -> str:
    """Each registered engine with the first line of its docstring (the registry is the one list)."""
    return "the engine (default rk4): " + "; ".join(
        f"{name}: {(cls.__doc__ or '').strip().splitlines()[0].rstrip('.')}" for name, cls in BACKENDS.items())



def _netlist(args):
    from ..synthesis.synth import observe, synthesize
    nl = synthesize(args.design, top=args.top, max_fanout=getattr(args, "max_fanout", None))
    return observe(nl, args.observe) if getattr(args, "observe", None) else nl


def cmd_synth(args) -> int:
    """`mech2spice synth`: synthesize a design and print its gate, latch, oscillator and spring counts."""
    from ..physics import network
    from ..physics.params import load_params
    nl = _netlist(args)
    model = network.build(nl, load_params(args.params))
    out = {"top": nl.top, "gates": len(model.design.gates), "latches": len(nl.latches()), **model.counts(),
           "inputs": nl.inputs, "outputs": nl.outputs, "clock": nl.clock, "sampled_clocks": list(nl.sampled),
           "logic_gates": len(nl.gates()),
           "logic_depth": network.logic_depth(nl),
           "signed": [p for p in {**nl.inputs, **nl.outputs} if p in nl.signed],     # two's complement ports
           "races": [r.as_dict() for r in nl.races]}       # warned on stderr too (synthesis/races.py)
    if args.json:
        _print_json(out)
    else:
        print(f"{out['top']}: {out['gates']} NOR gates ({out['logic_gates']} logic + {out['latches']} latches), "
              f"logic depth {out['logic_depth']}" + (f", clock {nl.clock_text()}" if nl.clocked else ""))
        if nl.sampled:
            print("  clocks sampled: each is an input given every cycle of the mechanical clock, a flip-flop "
                  "capturing where its clock's samples change (docs/rtl.md, \"Sampled clocks\")")
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
        return inputs.stimulus_steps(args.stimulus, _parse_sets(args.set), engine_class(args.backend))
    if not args.cycles:
        raise Mech2SpiceError(f"{nl.top} is clocked by {nl.clock_text()}: give --cycles N or --stimulus FILE.json")
    if nl.sampled:          # --cycles holds every input, the sampled clocks too: no edge would ever come
        raise Mech2SpiceError(f"--cycles {args.cycles}: {nl.top}'s clocks are sampled inputs "
                              f"({', '.join(nl.sampled)}), and --cycles holds them: give their value in each "
                              "cycle of --stimulus")
    inputs.check_cycles(args.cycles, engine_class(args.backend))
    return [{"set": _parse_sets(args.set), "cycles": args.cycles}]


def cmd_simulate_clocked(args, nl) -> int:
    """`simulate` for a clocked design: run the cycles and print the trace; 0 if every cycle is valid, else 1."""
    from .. import simulation
    from ..physics.params import load_params
    if args.clock and nl.sampled:
        raise Mech2SpiceError(f"--clock {args.clock}: {nl.top}'s clocks are sampled inputs "
                              f"({', '.join(nl.sampled)}): give their value in each cycle of --stimulus")
    if args.clock and args.clock != nl.clock:
        raise Mech2SpiceError(f"--clock {args.clock}: the design's flip-flops are clocked by '{nl.clock}'")
    if args.vcd is not None:
        from ..waveform import is_vcd
        inputs.check_output_file(args.vcd, [*inputs.design_inputs(args.design), ("the --stimulus file", args.stimulus),
                                            ("the --params file", params_file(args.params))],
                                 "VCD file", kind=("a VCD file", is_vcd), force=args.force)
    cycles = simulation.expand_steps(_clocked_steps(args, nl))
    if not BACKENDS[args.backend].capabilities.physical:       # the logic oracle
        from ..backends import noisy_engine
        noisy_engine(args.backend, _engine_options(args), args.noise, args.noise_seed)   # refuses what it cannot use
        res = simulation.run_clocked_logic(nl, cycles)
    else:
        p = load_params(args.params)
        from ..experiments import clocking
        timing = clocking.clock_timing(nl, args.pulse, args.pause, p)
        res = simulation.run_clocked_physical(nl, p, cycles, args.backend, timing,
                                            progress=_progress(args),
                                            options=_engine_options(args), log=_log(args),
                                            noise=(args.noise, args.noise_seed))
    if args.vcd is not None:
        from ..waveform import write_vcd
        write_vcd(args.vcd, simulation.clocked_waveform(nl, cycles, res))
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
        print(f"backend {res['backend']}, {res['periods']} periods, {res['wall_s']:.1f} s{_verdict_share(res)}, "
              f"valid: {res['valid']}")
    return 0 if res["valid"] else 1


def _verdict_share(res: dict) -> str:
    """' (verdict 0.3 s)': the stability verdicts' part of the wall time, where the run paid any."""
    v = res.get("verdict_s")
    return f" (verdict {v:.1f} s)" if v else ""


def cmd_simulate(args) -> int:
    """`mech2spice simulate`: run one input set (or the clock cycles); 0 if the outputs are valid, else 1."""
    from .. import simulation
    from ..physics.params import load_params
    nl = _netlist(args)
    if nl.clocked:
        return cmd_simulate_clocked(args, nl)
    if args.cycles or args.stimulus or args.clock or args.vcd:
        raise Mech2SpiceError(f"{nl.top} has no flip-flops: --clock/--cycles/--stimulus/--vcd apply to clocked "
                              "designs")
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
        print(f"backend {res['backend']}, {res['periods']} periods, {res['wall_s']:.1f} s{_verdict_share(res)}, "
              f"valid: {res['valid']}")
    return 0 if res["valid"] else 1


# --- SPICE --------------------------------------------------------------------------
LIBRARY_IGNORES = (("set", "--set"), ("top", "--top"), ("observe", "--observe"), ("periods", "--periods"),
                   ("method", "--method"), ("max_step", "--max-step"))


def _check_library_args(args) -> None:
    """--format veriloga writes the device library, not a design's netlist: what only a design's netlist
    reads is refused rather than ignored, and the design argument must still name a readable file."""
    given = [flag for dest, flag in LIBRARY_IGNORES if getattr(args, dest, None) is not None]
    if args.max_fanout != MAX_FANOUT:
        given.append("--max-fanout")
    if given:
        raise Mech2SpiceError(f"{', '.join(given)}: a design's netlist option; --format veriloga writes the "
                              "device library (no design is simulated)")
    if not Path(args.design).is_file():
        raise Mech2SpiceError(f"cannot read Verilog file {args.design}: no such file (--format veriloga reads "
                              "no design, but the one named must exist)")


def cmd_emit(args) -> int:
    """`mech2spice emit`: write the design as an ngspice or VACASK netlist, or the Verilog-A library."""
    from .. import simulation
    from ..physics import network
    from ..synthesis.ports import pack_inputs
    from ..physics.params import load_params
    from ..spice import combinational_only
    p = load_params(args.params)
    if args.format == "veriloga":                  # the device library, defaults from --params
        _check_library_args(args)
        import re
        from ..spice import veriloga
        text = veriloga.combined(p)
        inputs.write_text(args.output, text, encoding="ascii")
        info = {"netlist": args.output, "format": "veriloga", "modules": re.findall(r"^module (\w+)", text, re.M)}
        if args.json:
            _print_json(info)
        else:
            print(f"wrote {args.output}: Verilog-A, {len(info['modules'])} modules; compile with openvaf-r")
        return 0
    nl = _netlist(args)
    combinational_only(nl)
    values = _parse_sets(args.set)
    pack_inputs(nl, values)
    model = network.build(nl, p)
    stim = network.stimulus(model, nl, p, [(0, [values])])
    periods = args.periods or simulation.period_budget(nl)
    title = f"mech2spice: {nl.top} with {', '.join(f'{k}={v}' for k, v in values.items()) or 'inputs 0'}"
    from ..spice.readout import about as about_line
    about = about_line(args.design, nl.top, values)
    opts = _engine_options(args, args.format)      # the netlist formats are the circuit engines' names
    if args.format == "ngspice":
        from ..spice import oscillator_netlist as spice
        text = spice.emit(model, periods, stim, options=opts, title=title, about=about)
        run_with = f"ngspice -b {args.output} (it prints each output bit and port it reads)"
    elif args.format == "ngspice-envelope":
        from ..spice import envelope_netlist as envelope
        text = envelope.emit_envelope(model, stim, periods, opts, title=title, about=about)
        run_with = f"ngspice -b {args.output} (it prints each output bit and port it reads)"
    else:                                          # vacask | vacask-envelope: Verilog-A embedded, one file
        from ..spice import vacask
        form = vacask.ENVELOPE if args.format == "vacask-envelope" else vacask.CARRIER
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


def _engine_options(args, backend: str | None = None):
    """The engine's options from the flags: each engine reads the flags it takes and refuses the others
    (backends/_base.py `Engine.options_from_flags`)."""
    return engine_class(backend or args.backend).options_from_flags(args)


def cmd_subckts(args) -> int:
    """`mech2spice subckts`: write the ngspice .subckt library for --params and list its files."""
    from ..physics.params import load_params
    from ..spice.oscillator_netlist import write_subckt_library
    paths = write_subckt_library(args.output, load_params(args.params), {"the --params file": params_file(args.params)},
                                 args.force)
    if args.json:
        _print_json({"files": [str(x) for x in paths]})
    else:
        for x in paths:
            print(x)
    return 0
