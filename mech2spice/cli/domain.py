"""`domain`: where a design works as the drive frequency, the supply drive and a stiffness drift move."""
from __future__ import annotations

import argparse
from pathlib import Path

from .. import inputs
from ..errors import Mech2SpiceError
from ..experiments.trim import add_trim_arguments
from ..physics.params import PRESETS, params_file
from ._output import jsonable, print_json, progress as _progress

GATE = "gate"


def add_parser(sub) -> None:
    """Register `domain`."""
    d = sub.add_parser("domain", help="operating domain: where a design works as the drive frequency, the supply "
                                      "drive and a stiffness drift move (a 2-D map, PNG + JSON)",
                       formatter_class=argparse.RawDescriptionHelpFormatter,
                       description="Evaluate DESIGN on a grid of operating points and map where it works. DESIGN: "
                                   "'gate' (the loaded NOR gate: inputs anywhere in the bands must give outputs in "
                                   "the right band; ~0.5 s a point), a combinational Verilog file (every input "
                                   "vector against the logic oracle; ~10 s a point on the adder) or a processor "
                                   "program .asm (--cycles cycles against the ISS; ~15-40 s a point).",
                       epilog="""axes (relative changes from nominal, 0 = nominal; docs/robustness.md, "Operating domain"):
  freq   the drive frequency (the structure, its coupling dashpots included, stays as built)
  amp    the supply drive F_C of every gate (inputs and clock stay at their logic levels)
  drift  every stiffness times (1 + drift): a common-mode temperature drift, as --drift
exit 1 when the grid holds the nominal point (0, 0) and the nominal design fails there.
example:
  mech2spice domain gate --params centered_fc2 --sweep freq=-1e-3:1e-3:7 --sweep amp=-0.1:0.1:7 -o gate.png""")
    d.add_argument("design", help="'gate', a combinational Verilog file, or a processor program (.asm)")
    d.add_argument("--sweep", action="append", required=True, metavar="NAME=LO:HI:N",
                   help="an axis (freq, amp, drift) and its N values from LO to HI; exactly two axes with several "
                        "values; NAME=V holds the third at V (default 0)")
    d.add_argument("--params", default="default", help=f"gate parameters: {', '.join(PRESETS)} or a JSON file")
    d.add_argument("--top", help="top module of a Verilog DESIGN")
    d.add_argument("--backend", default=None, choices=["envelope", "rk4", "carrier"],
                   help="engine of a Verilog or processor DESIGN (default envelope)")
    d.add_argument("--cycles", type=inputs.integer(1, 10_000), default=None,
                   help="processor cycles compared with the ISS at each point (default 30)")
    d.add_argument("--spread", type=inputs.number(0, 1), default=None, metavar="SIGMA",
                   help="also evaluate --samples spread samples at each point (the same samples everywhere)")
    d.add_argument("--samples", type=inputs.integer(1, 10_000), default=None,
                   help="spread samples per point (default 8)")
    d.add_argument("--seed", type=inputs.integer(0, 2 ** 31 - 1), default=0, help="the samples' seed (default 0)")
    add_trim_arguments(d)
    d.add_argument("-o", "--output", metavar="MAP.png", help="write the map's figure to MAP.png and its JSON to "
                                                            "MAP.json")
    inputs.force_arg(d, "-o")
    d.add_argument("--json", action="store_true", help="print the map as JSON")
    d.set_defaults(func=cmd_domain)


def _evaluator(args, p):
    from ..experiments import domain
    spread = {}
    if args.spread is not None:
        if args.drift is not None:
            raise Mech2SpiceError("--drift: sweep it instead (--sweep drift=LO:HI:N or drift=V)")
        from ..experiments.trim import trim_from_args
        mode, residual, _ = trim_from_args(args)
        spread = dict(sigma=args.spread, samples=8 if args.samples is None else args.samples, seed=args.seed,
                      trim=mode, residual=residual)
    elif any(v is not None for v in (args.samples, args.trim, args.trim_residual, args.drift)):
        raise Mech2SpiceError("--samples, --trim, --trim-residual and --drift apply to --spread SIGMA")
    kind = "gate" if args.design == GATE else "program" if Path(args.design).suffix.lower() == ".asm" else "verilog"
    _refuse_unused(args, kind)
    backend = args.backend or "envelope"
    if kind == "gate":
        return domain.GateDomain(p, **spread)
    if kind == "program":
        from ..cpu.run import load_program
        load_program(args.design)                     # a bad program is one line now, not after a model build
        return domain.CpuDomain(args.design, args.cycles or 30, p, backend, **spread)
    from ..experiments.montecarlo import all_vectors
    from ..synthesis.synth import synthesize
    nl = synthesize(args.design, top=args.top)
    if nl.clocked:
        raise Mech2SpiceError(f"{nl.top} is clocked: domain maps the gate, combinational designs and the processor")
    return domain.DesignDomain(nl, p, all_vectors(nl), backend, **spread)


def _refuse_unused(args, kind: str) -> None:
    """A flag this kind of DESIGN has no use for is refused, not ignored."""
    if args.top is not None and kind != "verilog":
        raise Mech2SpiceError("--top names the top module of a Verilog DESIGN")
    if args.cycles is not None and kind != "program":
        raise Mech2SpiceError("--cycles applies to a processor program DESIGN (.asm)")
    if args.backend is not None and kind == "gate":
        raise Mech2SpiceError("--backend applies to a Verilog or processor DESIGN (the gate's margin is its own "
                              "loaded steady state)")


def _outputs(args) -> tuple[Path, Path] | None:
    if args.output is None:
        return None
    png = Path(args.output)
    if png.suffix.lower() != ".png":
        raise Mech2SpiceError(f"-o {args.output}: expected a .png name (the JSON goes beside it)")
    out = png.with_suffix(".json")
    reads = [*([] if args.design == GATE else inputs.design_inputs(args.design)),
             ("the --params file", params_file(args.params))]
    inputs.check_output_file(png, reads, "figure", kind=("a PNG image", _is_png), force=args.force)
    inputs.check_output_file(out, reads, "map JSON", kind=("a domain map", _is_map), force=args.force)
    return png, out


def _is_png(path) -> bool:
    return inputs.head(path, 8) == b"\x89PNG\r\n\x1a\n"


def _is_map(path) -> bool:
    first = inputs.head(path, 200).lstrip()
    return first.startswith(b"{") and b'"design"' in first


def cmd_domain(args) -> int:
    """`mech2spice domain`: map where DESIGN works; 0 if it works at the nominal point (when on the grid)."""
    import json
    from ..experiments import domain
    from ..physics.params import load_params
    x, y, fixed = domain.grid_axes(args.sweep)
    files = _outputs(args)
    p = load_params(args.params)
    ev = _evaluator(args, p)
    m = {**domain.domain_map(ev, x, y, fixed, _progress(args)), "params": p.name}
    if files is not None:
        from ..reports.domain import plot_map
        plot_map(m, files[0])
        inputs.write_text(files[1], json.dumps(jsonable(m), indent=1))
    if args.json:
        print_json(m)
    else:
        _print_map(m, files)
    return 0 if m["nominal_works"] in (True, None) else 1


def _print_map(m: dict, files) -> None:
    from ..reports.domain import table
    print(f"{m['design']}: works at {m['works']} of {m['points']} points ({m['x']['name']} across, "
          f"{m['y']['name']} down; ok/x nominal, k/n spread samples); {m['wall_s']:.0f} s")
    print("\n".join(table(m)))
    if files:
        print(f"wrote {files[0]} and {files[1]}")
