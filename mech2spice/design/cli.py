"""`mech2spice design`: the block-structure search (design/search.py), resumable from its checkpoint."""
from __future__ import annotations

from pathlib import Path

from .. import inputs
from ..errors import Mech2SpiceError

DEFAULT_OUT = "reports/design_search.json"


def add_parser(subparsers) -> None:
    """Register the `design` command."""
    from .grammar import STRUCTURES
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
    from . import centering
    centering.add_parser(subparsers)                 # `mech2spice center`: design/centering.py


def _check_files(args) -> None:
    """Before any search: --out (never a --merge file; a search record, whole, if it exists), every --merge
    record whole, and that the package's blocks folder takes --install-robust."""
    from . import search
    merges = [("the --merge file", f) for f in args.merge or ()]
    out = inputs.check_output_file(args.out, merges, "search record", kind=search.RECORD_KIND,
                                   remedy="give another --out", parents=True)      # write_atomic makes folders
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
    from ..cli import _log, _print_json, _progress
    from . import search
    settings = {"sigma": args.sigma, "samples": args.samples, "seed": args.seed, "maxiter": args.maxiter,
                "popsize": args.popsize, "budget_s": args.budget_s, "tol_samples": args.tol_samples}
    structures = [s.strip() for s in args.structures.split(",") if s.strip()]
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
