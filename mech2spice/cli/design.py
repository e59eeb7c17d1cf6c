"""`mech2spice design`: the block-structure search (design/search.py), resumable from its checkpoint."""
from __future__ import annotations

from pathlib import Path

from .. import inputs
from ..errors import Mech2SpiceError

DEFAULT_OUT = "reports/design_search.json"


def add_parser(subparsers) -> None:
    """Register the `design` command."""
    from ..design.grammar import STRUCTURES
    s = subparsers.add_parser(
        "design", help="search block structures for a NOR gate that tolerates element spread",
        description="For each block structure of the grammar (docs/design.md), optimise its parameters with "
                    "differential evolution on its tolerance: the largest spread at which the 1st-percentile "
                    "worst margin of the loaded gate stays > 0 (nominal truth table, bands and stable steady "
                    "states as constraints), then measure the best point's yield at SIGMA and its tolerance "
                    "(largest sigma with >= 99 % yield) on more samples. "
                    "Each finished structure is checkpointed to --out; a rerun with the same settings resumes.")
    s.add_argument("--structures", default=",".join(STRUCTURES), metavar="A,B,...",
                   help=f"structures to search (default all: {','.join(STRUCTURES)})")
    s.add_argument("--sigma", type=inputs.number(0), default=0.01, help="relative spread at which each best block's yield is reported (0.01)")
    s.add_argument("--samples", type=inputs.integer(2, 10_000), default=16,
                   help="spread samples per objective evaluation (16; common random numbers)")
    s.add_argument("--tol-samples", type=inputs.integer(100, 100_000), default=100,
                   help="samples of the tolerance bisection of each best point (100)")
    s.add_argument("--seed", type=inputs.integer(0, 2 ** 32 - 1), default=0)
    s.add_argument("--maxiter", type=inputs.integer(1, 10_000), default=200, help="generations at most (200)")
    s.add_argument("--popsize", type=inputs.integer(2, 100), default=6, help="population per parameter (6)")
    s.add_argument("--budget-s", type=inputs.number(0), default=300.0,
                   help="wall-clock budget of each structure's search in seconds (300)")
    s.add_argument("--out", default=DEFAULT_OUT, help=f"checkpoint / result file (default {DEFAULT_OUT})")
    s.add_argument("--merge", nargs="+", metavar="FILE",
                   help="search nothing: merge these records of other runs into --out (per structure the run with "
                        "the larger tolerance wins; every run is listed under the entry's 'runs')")
    s.add_argument("--install-robust", action="store_true",
                   help="write the best block to the package's blocks/robust.json (--params robust), once it "
                        "loads and its nominal gate works (else exit 2, the installed block untouched)")
    s.add_argument("--json", action="store_true", help="machine-readable output")
    s.set_defaults(func=cmd_design)
    add_center_parser(subparsers)


def _check_files(args) -> None:
    """Before any search: --out (never a --merge file; a search record, whole, if it exists), every --merge
    record whole, and that the package's blocks folder takes --install-robust."""
    from ..design import search
    merges = [("the --merge file", f) for f in args.merge or ()]
    out = inputs.check_output_file(args.out, merges, "search record", kind=search.RECORD_KIND,
                                   remedy="give another --out", parents=True)      # write_atomic makes folders
    if args.merge and not out.is_file():
        raise Mech2SpiceError(f"--merge merges into the search record --out {args.out}, which "
                              + ("is not a regular file (a device or a pipe)" if out.exists() else "does not exist"))
    if args.merge or (out.is_file() and out.stat().st_size):
        search.read_record(out)
    for _, f in merges:
        search.read_record(Path(f))
    if args.install_robust:
        from .. import data
        inputs.check_output_file(data.path("blocks", "robust.json"), [("the --out file", args.out), *merges],
                                 "installed block")


def cmd_design(args) -> int:
    """Run (or resume) the search; print per structure its best parameters, tolerance, margin, DOFs."""
    from ._output import log as _log, print_json as _print_json, progress as _progress
    from ..design import search
    settings = {"sigma": args.sigma, "samples": args.samples, "seed": args.seed, "maxiter": args.maxiter,
                "popsize": args.popsize, "budget_s": args.budget_s, "tol_samples": args.tol_samples}
    structures = [s.strip() for s in args.structures.split(",") if s.strip()]
    if not structures and not args.merge:
        raise Mech2SpiceError("--structures names none: give at least one structure to search")
    _check_files(args)
    if args.merge:
        state = search.merge(Path(args.out), [Path(f) for f in args.merge], _log(args))
        settings = state["settings"]
    else:
        state = search.run(structures, Path(args.out), settings, _log(args),
                           progress=_progress(args))
    out = search.summary(state)
    if args.install_robust:
        if not out["best"]:
            raise Mech2SpiceError(f"--install-robust: no structure in {args.out} has a working nominal gate: "
                                  "nothing installed")
        from .. import data
        search.install_block(state["structures"][out["best"]], data.path("blocks", "robust.json"))
    if args.json:
        _print_json(out)
        return 0
    for name, r in out["structures"].items():
        t = r["tolerance"]
        print(f"{name:12s} DOFs {r['dofs_per_gate']}  nominal margin {r['nominal_margin']:+.4f}  "
              f"tolerance {t if t is None else f'{t:.3g}'}  yield@{settings['sigma']:g} {r['yield']:.3f}  "
              f"q1 {r['margin_quantiles']['1%']:+.3f}  ({r['search']['evaluations']} evaluations, "
              f"{r['search']['wall_s']:.0f} s)")
    print(f"best: {out['best']}" + (" (installed as --params robust)" if args.install_robust and out["best"] else ""))
    return 0


def add_center_parser(subparsers) -> None:
    """Register the `center` command (design/centering.py)."""
    from ..design.centering import GROWTH_FLOOR, TRIMS
    s = subparsers.add_parser(
        "center", help="design centering of the NOR block by worst-case distance (docs/design.md)",
        description="Maximise the smallest worst-case distance beta = margin / ||sigma o grad margin|| over the "
                    "loaded gate's margin, fold and stability constraints (every valid input point) under a spread "
                    "spec, by trust-region linear programming over the block's parameters and bands, seeded by a "
                    "working block.  Resumable: the record DIR/centering.json is written after every step; "
                    "DIR/best.json is the best block (a --params file).")
    s.add_argument("--from", dest="seed", default="robust", help="seed block: a preset or block file (robust)")
    s.add_argument("--spread", type=inputs.number(0, 1), default=0.01, help="relative spread (0.01)")
    s.add_argument("--trim", choices=TRIMS, default="none", help="trim k/m (f) or k/m and c/m (fc) (none)")
    s.add_argument("--trim-residual", type=inputs.number(0, 1), default=0.0, help="trim residual (0)")
    s.add_argument("--steps", type=inputs.integer(0, 10_000), default=50, help="steps in all (50)")
    s.add_argument("--fixed-levels", action="store_true", help="keep the seed's bands (default: optimise them)")
    s.add_argument("--growth-floor", type=inputs.number(0), default=GROWTH_FLOOR,
                   help=f"slowest decay rate (1/time) of any stable state over the grid ({GROWTH_FLOOR})")
    s.add_argument("--out", required=True, metavar="DIR", help="record and best block folder")
    inputs.force_arg(s, "--out's best.json")
    s.add_argument("--json", action="store_true", help="machine-readable output")
    s.set_defaults(func=cmd_center)


def _check_center_out(args) -> None:
    """Before any analysis: DIR takes files; its record and best block are never the --from block, and an
    existing best block is this command's own (else --force; an existing record is read, and refused unless
    it is a centering record, before any step)."""
    from ..design import centering
    from ..physics.params import params_file
    inputs.check_output_dir(args.out, "centering folder", parents=True)
    seed = {"the --from block": params_file(args.seed)}
    inputs.check_output_file(Path(args.out) / centering.RECORD, seed, "centering record", parents=True)
    inputs.check_output_file(Path(args.out) / centering.BEST, seed, "best block", kind=centering.BEST_KIND,
                             force=args.force, parents=True)


def cmd_center(args) -> int:
    """Run or resume a centering; print the best block's figures."""
    from ._output import log as _log, print_json as _print_json
    from ..design import centering
    from ..physics.params import load_params
    if args.trim == "none" and args.trim_residual:
        raise Mech2SpiceError("--trim-residual needs --trim f or fc")
    spec = centering.TrimmedSpread(args.spread, args.trim, args.trim_residual)
    spec.validate()
    settings = centering.Settings(args.seed, spec, levels=not args.fixed_levels, growth_floor=args.growth_floor)
    _check_center_out(args)
    out = centering.run(load_params(args.seed), settings, args.out, args.steps, _log(args))
    if args.json:
        _print_json(out)
        return 0
    print(f"best step {out['best_step']} of {out['steps']}: linear tolerance {out['tolerance_linear']:.3g} "
          f"(seed {out['seed']['tolerance_linear']:.3g}), beta at the target {out['beta_target']:.3g}, "
          f"nominal margin {out['nominal_margin']:+.4f}; block: {out['best_file']}")
    hd = out["held_damping"]
    print(f"insulator Q {hd['q_insulator']:.3g} ({len(hd['tried']) - 1} damping steps): the held counter4 "
          + ("settles" if hd["reached"] else "still circles (not a block for latches)")
          + f", growth {out['held_growth']} per period (floor -{hd['floor']:g})")
    return 0
