"""`mech2spice cpu ...`: assemble and run programs for the 8-bit processor.

Registered by the main command line with ``add_parser(subparsers)``.  Handlers return the exit
code and raise Mech2SpiceError for user errors (the main CLI prints those as one line, exit 2).
"""

from __future__ import annotations

import sys
from pathlib import Path

from ..errors import Mech2SpiceError
from ..inputs import (MAX_CPU_CYCLES, check_output_file, envelope_speed_args, force_arg, integer, number,
                      strict_json, write_bytes, write_text)
from ..backends import BACKENDS as ENGINES
from ..cpu.physical import ETD_PROCESSOR_STEP, PHYSICAL, PROCESSOR_STEP, SETTLE_TOL
from ..cpu.settle_check import PERIODS as SETTLE_CHECK_PERIODS
from ..cpu.machines import BACKENDS, CIRCUIT
from ..physics.params import params_file
from ..cpu.run import check_run_outputs, is_image, load_program, run_program

MAX_CIRCUIT_CYCLES = 2000    # one VACASK process; the sieve needs 457


def add_parser(subparsers) -> None:
    """Register the `cpu` command and its `asm` and `run` subcommands."""
    cpu = subparsers.add_parser(
        "cpu", help="assemble and run programs on the 8-bit mechanical processor",
        description="The paper's 8-bit processor (verilog/cpu.v): assemble programs, run them on the "
                    "instruction-set simulator or on the synthesized NOR netlist.")
    sub = cpu.add_subparsers(dest="cpu_command", required=True)

    a = sub.add_parser("asm", help="assemble PROG.asm into a memory image",
                       description="Assemble PROG.asm into a binary memory image (address 0 first).")
    a.add_argument("program", help="assembly source (.asm)")
    a.add_argument("-o", "--output", required=True, help="binary image to write")
    force_arg(a, "-o")
    a.add_argument("--listing", action="store_true", help="print the listing (address, bytes, source)")
    a.set_defaults(func=cmd_asm)

    e = sub.add_parser("emit", help="write the processor and PROG as one self-contained VACASK netlist",
                       description="Write the whole processor (envelope-level devices), its 256-byte memory "
                                   "holding PROG (Verilog-A byte cells) and the clock schedule of --cycles "
                                   "cycles as one VACASK netlist with its Verilog-A embedded: `vacask FILE` runs "
                                   "the program (docs/cpu_circuit.md).")
    e.add_argument("program", help="assembly source (.asm) or binary image")
    e.add_argument("-o", "--output", required=True, help="netlist to write (.sim)")
    force_arg(e, "-o")
    e.add_argument("--cycles", type=integer(1, MAX_CPU_CYCLES), default=30,
                   help=f"clock cycles after the reset (default 30, at most {MAX_CIRCUIT_CYCLES})")
    circuit_args(e)
    e.add_argument("--json", action="store_true", help="machine-readable output")
    e.set_defaults(func=cmd_emit)

    r = sub.add_parser("run", help="run a program until it halts (a jump to itself)",
                       description="Run PROG (.asm, or a binary image) until it halts or --max-cycles. "
                                   "Exit code 0 when it halted, 1 when it ran out of cycles.")
    r.add_argument("program", help="assembly source (.asm) or binary image")
    r.add_argument("--backend", default="iss", choices=BACKENDS,
                   help="iss (instruction-set simulator), logic (the NOR netlist), envelope, carrier or rk4 (the "
                        "netlist as 6486 oscillators; envelope ~0.04 s per cycle, the sieve in ~18 s on a quiet machine: "
                        "reports/cpu_physical.md; carrier: oscillator level, Lawson RK4, reports/carrier.md), "
                        "vacask-envelope (the whole processor and its memory as one VACASK netlist, run for "
                        "--max-cycles cycles in one process, or with --checkpoint one process per "
                        "--checkpoint-every cycles, each continuing the last one's state: reports/cpu_circuit.md)")
    r.add_argument("--max-cycles", type=integer(0, MAX_CPU_CYCLES), default=100_000,
                   help="stop after this many cycles in total (default 100000)")
    r.add_argument("--checkpoint", metavar="FILE", help="write the machine state to FILE (JSON) as it runs")
    r.add_argument("--checkpoint-every", type=integer(1, MAX_CPU_CYCLES), default=None, metavar="N",
                   help="cycles between checkpoints (default 1000; 10 for envelope / carrier / rk4 and "
                        "vacask-envelope, whose checkpoint also keeps the oscillator or circuit state in a file "
                        "FILE.state-*.npz that FILE names; for vacask-envelope also the cycles per simulator "
                        "process)")
    r.add_argument("--step", type=number(0), default=None, metavar="PERIODS",
                   help=f"envelope step in drive periods (default {PROCESSOR_STEP:g}, {ETD_PROCESSOR_STEP:g} where ETDRK4 "
                        "steps the amplitudes, shortened to the stability bound; refused above it)")
    r.add_argument("--settle", type=number(0, lo_open=False), default=None, metavar="TOL",
                   help=f"envelope, carrier, rk4: end each pause once every channel stays within TOL u_R for two 200-period "
                        f"windows (default {SETTLE_TOL}; 0 = full fixed-length pauses)")
    r.add_argument("--params", default=None, help="gate parameters of envelope / rk4 runs: default, printed, "
                   "robust, classic or a JSON file (fields, or a block file: docs/design.md)")
    envelope_speed_args(r)
    r.add_argument("--steps", type=integer(4, 10_000), default=None, metavar="N",
                   help="carrier, rk4: steps per drive period (default 12 and 80)")
    r.add_argument("--threads", type=integer(1, 64), default=None, metavar="N",
                   help="carrier: split each step over N threads (default 1; 2 uses both cores of an idle machine; "
                        "more than 1 turns the default latency off, the latency loop being serial)")
    from .montecarlo import max_fanout_arg
    max_fanout_arg(r)
    r.add_argument("--trace", metavar="FILE", help="write one JSON line per cycle to FILE: the cycle's record, the "
                   "registers after it and (envelope, carrier, rk4) every probed amplitude in u_R")
    r.add_argument("--vcd", metavar="FILE", help="write the run as a waveform (VCD, for GTKWave or Surfer) to FILE "
                   "when it ends: one time unit per cycle; the cycle's bus (pc, phase, raddr, rdata, we, waddr, wdata, "
                   "opcode), the registers after it and (envelope, carrier, rk4, vacask-envelope) every probed "
                   "amplitude in u_R as a real")
    r.add_argument("--resume", action="store_true", help="continue from --checkpoint FILE")
    r.add_argument("--settle-check", type=integer(100, 10**6), nargs="?", const=SETTLE_CHECK_PERIODS, default=None,
                   metavar="PERIODS", help="envelope, carrier, rk4: judge every read against its own future: a copy "
                   f"of the state continues PERIODS more (default {SETTLE_CHECK_PERIODS}) with nothing skipped; a read "
                   "is settled when no bit changes band and each moves by at most a quarter of its margin "
                   "(JSON settle_check, exit 1 if not; ~0.2 s a read on the processor, ~3.5 min for the sieve)")
    r.add_argument("--stability", choices=("off", "end", "cycle"), default="off",
                   help="end: the oscillator-level machine's stability verdict at its halt (envelope, carrier, "
                        "rk4; adds `stable` and `stability` to the JSON; 3-30 s on the processor); cycle: after "
                        "every cycle too, stopping at the first unstable one (adds `stability_cycles`; ~4 s a "
                        "cycle, ~30 min for the sieve; docs/stability.md)")
    force_arg(r, "--checkpoint, --trace or --vcd")
    circuit_args(r)
    r.add_argument("--json", action="store_true", help="machine-readable output")
    r.set_defaults(func=cmd_run)

    from .montecarlo import add_cpu_parser
    add_cpu_parser(sub)                     # `cpu montecarlo`


def circuit_args(parser) -> None:
    """Options of the circuit netlist (`cpu emit`, `cpu run --backend vacask-envelope`)."""
    from ..cpu.circuit import MAX_STEP
    parser.add_argument("--max-step", type=number(0), default=None, metavar="PERIODS",
                        help=f"vacask-envelope: VACASK's largest time step in drive periods (default {MAX_STEP:g})")
    parser.add_argument("--reltol", type=number(0), default=None, metavar="TOL",
                        help="vacask-envelope: VACASK's relative tolerance (default 1e-2; it sets the time step: "
                             "reports/cpu_circuit.md)")
    parser.add_argument("--settle-periods", type=integer(1, 10**6), default=None, metavar="N",
                        help="vacask-envelope: periods each cycle settles before its clock pulse (default one "
                             "pause of the clock schedule, 11575: docs/cpu_circuit.md)")


def _circuit_options(args) -> dict:
    out = {}
    if args.max_step is not None:
        out["max_step"] = args.max_step
    if args.settle_periods is not None:
        out["settle"] = args.settle_periods
    if args.reltol is not None:
        out["reltol"] = args.reltol
    return out


def cmd_emit(args) -> int:
    """`cpu emit`: write the processor with PROG in its memory as one VACASK netlist; returns 0."""
    from ..cpu.circuit import emit_cpu
    if args.cycles > MAX_CIRCUIT_CYCLES:
        raise Mech2SpiceError(f"--cycles {args.cycles}: at most {MAX_CIRCUIT_CYCLES} cycles in one netlist")
    from ..spice import NETLIST
    check_output_file(args.output, {"the program": args.program}, "netlist", kind=NETLIST, force=args.force)
    prog = load_program(args.program)
    if prog.tape is not None:
        raise Mech2SpiceError(f"{args.program} maps a tape: the circuit's memory is the 256-byte array only")
    opts = _circuit_options(args)
    net = emit_cpu(prog.image, args.cycles, standalone=True, **opts)
    write_text(args.output, net.text, encoding="ascii")
    info = {"netlist": args.output, "cycles": args.cycles, "periods": net.schedule.stop,
            "schedule": vars(net.schedule), **net.stats, "bytes": len(net.text)}
    print(strict_json(info, indent=2) if args.json else
          f"wrote {args.output}: {net.stats['dofs']} DOFs, memory of 256 bytes, {args.cycles} cycles "
          f"({net.schedule.stop} drive periods); run it with: vacask {args.output}")
    return 0


def cmd_asm(args) -> int:
    """`cpu asm`: write PROG.asm's memory image (and print its listing if asked); returns 0."""
    if Path(args.program).suffix.lower() != ".asm":
        raise Mech2SpiceError(f"{args.program}: expected an assembly source (.asm)")
    check_output_file(args.output, {"the program": args.program}, "memory image", kind=IMAGE, force=args.force)
    prog = load_program(args.program)
    write_bytes(args.output, prog.image)
    if args.listing:
        print(prog.listing)
    print(f"wrote {args.output}: {len(prog.image)} bytes", file=sys.stderr if args.listing else sys.stdout)
    return 0


IMAGE = ("a memory image", is_image)


def _takes(backend: str, option: str) -> bool:
    """Whether the engine `backend` has the option `option` (the processor's flags follow its engine's options)."""
    from dataclasses import fields
    cls = ENGINES.get(backend)
    return cls is not None and option in {f.name for f in fields(cls.Options)}


def cmd_run(args) -> int:
    """`cpu run`: run a program on the chosen backend; returns 0 if it halted, 1 if it ran out of cycles."""
    check_run_outputs(args.checkpoint, args.trace, args.program, args.resume, args.force, params_file(args.params),
                      vcd=args.vcd)
    for flag, value in (("--settle-check", args.settle_check), (f"--stability {args.stability}", args.stability != "off")):
        if value and args.backend not in PHYSICAL:
            raise Mech2SpiceError(f"{flag} judges an oscillator-level machine ({', '.join(PHYSICAL)}), "
                                  f"not --backend {args.backend}")
    physical = {}
    if args.step is not None:
        physical["step"] = args.step
    if args.settle is not None:
        physical["settle"] = args.settle or None
    if args.latency is not None:
        physical["latency"] = args.latency or None
    if args.settle_check is not None:
        physical["settle_check"] = args.settle_check
    physical.update({k: getattr(args, k) == "on" for k in ("exponential", "parallel") if getattr(args, k)})
    carrier = {k: v for k, v in (("steps_per_period", args.steps), ("threads", args.threads)) if v is not None}
    if args.threads is not None and not _takes(args.backend, "threads"):
        raise Mech2SpiceError("--threads applies to the carrier backend only")
    if args.steps is not None and not _takes(args.backend, "steps_per_period"):
        raise Mech2SpiceError("--steps applies to the carrier and rk4 backends only")
    oscillator_level = _takes(args.backend, "steps_per_period")      # rk4, carrier: no envelope step
    own = {"settle", "settle_check", *(["latency"] if _takes(args.backend, "latency") else [])}
    if oscillator_level and set(physical) - own:
        raise Mech2SpiceError(f"--step, --exponential and --parallel apply to the envelope backend; "
                              f"the {args.backend} backend's are --steps"
                              f"{', --threads, --latency' if _takes(args.backend, 'threads') else ''} and --settle")
    if physical and args.backend not in PHYSICAL:
        raise Mech2SpiceError("--step, --settle, --latency, --exponential and --parallel apply to the envelope "
                              "backend only (--settle also to carrier and rk4, --latency also to carrier)")
    physical.update(carrier)
    if args.max_fanout is not None:
        if args.backend not in PHYSICAL:
            raise Mech2SpiceError(f"--max-fanout applies to the {', '.join(PHYSICAL)} backends only")
        physical["max_fanout"] = args.max_fanout
    if args.params is not None:
        if args.backend not in PHYSICAL:
            raise Mech2SpiceError("--params applies to the envelope, carrier and rk4 backends only")
        from ..physics.params import load_params
        physical["p"] = load_params(args.params)
    physical.update(_circuit_options(args))
    if args.backend in CIRCUIT:
        if args.max_cycles > MAX_CIRCUIT_CYCLES:
            raise Mech2SpiceError(f"--backend vacask-envelope: give --max-cycles N <= {MAX_CIRCUIT_CYCLES} "
                                  "(the sieve halts after 457)")
        if len(physical) != len(_circuit_options(args)):
            raise Mech2SpiceError("--step, --settle, --latency and --params do not apply to vacask-envelope "
                                  "(use --max-step, --settle-periods)")
        physical["cycles"] = args.max_cycles
    elif _circuit_options(args):
        raise Mech2SpiceError("--max-step and --settle-periods apply to the vacask-envelope backend only")
    if args.checkpoint_every and not args.checkpoint:
        raise Mech2SpiceError("--checkpoint-every needs --checkpoint FILE")
    if args.trace is not None and args.resume and not Path(args.trace).exists():
        raise Mech2SpiceError(f"--resume with --trace {args.trace}: the trace to continue does not exist")
    from ._output import progress as _progress
    res = run_program(args.program, args.backend, args.max_cycles, checkpoint=args.checkpoint,
                      resume=args.resume, progress=_progress(args),
                      checkpoint_every=args.checkpoint_every, trace=args.trace, force=args.force,
                      stability=args.stability, vcd=args.vcd, **physical)
    if args.json:
        print(strict_json(res, indent=2))
    else:
        _print_run(res)
    agrees = res.get("iss_check", {}).get("mismatches", 0) == 0
    return 0 if res["halted"] and res.get("stable", True) and res.get("settled", True) and agrees else 1


def _print_run(res: dict) -> None:
    regs = res["registers"]
    state = "halted" if res["halted"] else "did not halt"
    print(f"{state} after {res['cycles']} cycles ({res['backend']}, {res['wall_s']:.2f} s)")
    if "model" in res:
        m = res["model"]
        print(f"model: {m['oscillators']} oscillators, {m['linear_springs']} springs, "
              f"{m['nonlinear_springs']} nonlinear springs, {m['dashpots']} dashpots")
    if "iss_check" in res:
        chk = res["iss_check"]
        first = chk["first_mismatch"]
        print(f"ISS check: every cycle equal to the instruction-set simulator ({chk['cycles_checked']} cycles "
              f"from cycle {chk['from_cycle']})" if not chk["mismatches"] else
              f"ISS check: {chk['mismatches']} of {chk['cycles_checked']} cycles differ from the instruction-set "
              f"simulator, first at cycle {first['cycle']}")
    for label, values in res.get("results", {}).items():
        print(f"{label}{'' if res['halted'] else ' (not halted: partial)'}: {' '.join(map(str, values))}")
    print("registers: " + " ".join(f"{k}={v}" for k, v in regs.items()))
    if "stability" in res:
        st = res["stability"]
        judged = res.get("stability_cycles")
        where = f"every one of {len(judged)} cycles judged" if judged and res["stable"] else \
            f"cycle {st['cycle']}" if judged else "at the end"
        print(f"stable: {res['stable']}, {where} (least stable mode: growth {st['growth_rate']} per drive "
              f"period, period {st['mode_period']}, in {', '.join(st['mode_dofs'][:3])})")
    if "settle_check" in res:
        sc, w = res["settle_check"], res["settle_check"]["worst"]
        print(f"settled: {sc['settled']}: {sc['reads']} reads each continued {sc['periods']} periods; "
              f"{sc['reads_not_settled']} not settled; most still to come {sc['worst_still_to_come_bw']:.4f} band "
              f"widths ({w.get('bit')}, cycle {w.get('cycle')})")
    mem = res["memory"]
    print("memory (hex, row = 16 addresses):")
    for row in range(16):
        cells = " ".join(f"{v:02x}" for v in mem[16 * row:16 * row + 16])
        print(f"  {16 * row:3d}: {cells}")
    for addr, dev in res.get("devices", {}).items():
        print(f"tape at {addr}: head {dev['head']}, {dev['steps']} moves, cells {dev['cells']}")
