"""`mech2spice report NAME [NAME...] | all`: regenerate reports/*.md.

Registered by the main command line with ``add_parser(subparsers)``; also ``python -m mech2spice.reports``.
The handler returns the exit code and raises Mech2SpiceError for user errors (one line on stderr, exit 2).
"""
from __future__ import annotations

import argparse
import contextlib
import sys
import time
from pathlib import Path

from ..errors import Mech2SpiceError
from ..inputs import MAX_CYCLES, check_inside, check_output_dir, check_output_file, integer, number, strict_json
from . import REPORTS, module

# Options a report's write() takes, as command-line flags: (flag, dest, argparse keywords).  Defaults are
# left to each write(); an option a named report does not take is an error.
OPTIONS = [
    ("--quick", "quick", dict(action="store_true", help="fewer points / shorter runs")),
    ("--only", "only", dict(action="append", metavar="SECTION",
                            help="measure these sections only, merged into the existing JSON (repeatable; "
                                 "see the report's module docstring for its sections)")),
    ("--render", "render", dict(action="store_true", help="measure nothing: rewrite the report from its stored "
                                                          "results")),
    ("--design", "design", dict(action="append", metavar="NAME", help="accuracy section for these designs only")),
    ("--cycles", "cycles", dict(type=integer(0, MAX_CYCLES), metavar="N",
                                help="processor cycles to run (cpu_physical: 0 = to the halt; fidelity: the first N "
                                     "sieve cycles, default 30)")),
    ("--sqrt-rk4", "sqrt_rk4", dict(action="store_true", help="also run sqrt(2809) on RK4 (~20 min)")),
    ("--sqrt-rk4-full", "sqrt_rk4_full", dict(action="store_true", help="also the whole sqrt schedule on RK4")),
    ("--skip-slow", "skip_slow", dict(action="store_true", help="leave out the slowest runs (cpu: the "
                                                                "logic-level Minsky machine, ~2.5 min; design: the "
                                                                "sieve on the envelope)")),
    ("--cache", "cache", dict(metavar="DIR", help="keep the RK4 runs in DIR between invocations")),
    ("--program", "program", dict(metavar="FILE", help="program to run (default programs/sieve.asm)")),
    ("--backend", "backend", dict(choices=["envelope", "rk4"], help="oscillator-level backend (default envelope)")),
    ("--step", "step", dict(type=number(0), metavar="PERIODS", help="envelope step in drive periods")),
    ("--settle", "settle", dict(type=number(0, lo_open=False), metavar="TOL",
                                help="envelope settle tolerance in u_R (0: full pauses)")),
    ("--checkpoint", "checkpoint", dict(metavar="FILE", help="checkpoint file (with --resume: continue from it)")),
    ("--resume", "resume", dict(action="store_true", help="continue from --checkpoint FILE")),
    ("--carrier-trace", "carrier_trace", dict(metavar="FILE", help="carrier `cpu run --trace` of the sieve (default "
                                                                   "build/carrier/sieve_carrier.jsonl)")),
    ("--envelope-trace", "envelope_trace", dict(metavar="FILE", help="envelope `cpu run --trace` of the sieve "
                                                                     "(default build/carrier/sieve_envelope.jsonl)")),
    ("--processor-check", "processor_check", dict(metavar="FILE", help="experiments.processor_check's JSON "
                                                                       "(default build/carrier/processor_check.json)")),
    ("--latency-trace", "latency_trace", dict(metavar="FILE", help="carrier `cpu run --trace` of the sieve with "
                                                                   "per-gate latency (default "
                                                                   "build/carrier/sieve_latency.jsonl)")),
    ("--name", "name", dict(metavar="STEM", help="report file stem (default cpu_physical)")),
]


def add_parser(subparsers) -> None:
    """Add `report` to the main command line's subcommands."""
    p = subparsers.add_parser("report", help="regenerate reports (reports/*.md): NAME... or all",
                              formatter_class=argparse.RawDescriptionHelpFormatter,
                              description=__doc__.splitlines()[0], epilog=_epilog())
    add_arguments(p)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The `report` arguments, on any parser."""
    p.add_argument("names", nargs="*", metavar="NAME", help="reports to write, in the order given; 'all' = "
                                                            "every report, in the order of --list")
    p.add_argument("--out", default="reports", metavar="DIR", help="directory to write (default reports/)")
    p.add_argument("--list", action="store_true", help="list the reports (name, cost, what it shows) and exit")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    g = p.add_argument_group("report options (each applies to the reports named in brackets)")
    for flag, dest, kw in OPTIONS:
        takers = [n for n, r in REPORTS.items() if dest in r.options]
        g.add_argument(flag, dest=dest, default=argparse.SUPPRESS,
                       **{**kw, "help": f"{kw['help']} [{', '.join(takers)}]"})
    p.set_defaults(func=cmd_report)


def _epilog() -> str:
    return "reports:\n" + "\n".join(f"  {n:15s} {r.cost:>8s}  {r.description}" for n, r in REPORTS.items())


def cmd_report(args) -> int:
    """List the reports, or write the ones named with the options given."""
    if args.list:
        return _list(args.json)
    names = _names(args.names)
    options = {dest: getattr(args, dest) for _, dest, _ in OPTIONS if hasattr(args, dest)}
    for name in names:
        unused = sorted(set(options) - set(REPORTS[name].options))
        if unused:
            flags = ", ".join(f for f, d, _ in OPTIONS if d in unused)
            raise Mech2SpiceError(f"report {name} takes no {flags}")
    _check_outputs(names, args.out, options)
    if options.get("render"):
        from .schemas import check_stored        # every report's files before any is drawn: nothing written
        for name in names:
            check_stored(name, args.out, options.get("name"))
    done = []
    for name in names:
        done.append(_write(name, args.out, options))
        if not args.json:
            print(f"{done[-1]['path']} ({done[-1]['wall_s']:.0f} s)", flush=True)
    if args.json:
        print(strict_json({"reports": done}, indent=2))
    return 0


def _check_outputs(names: list[str], directory: str, options: dict) -> None:
    """Before hours of measuring, not after: the folder takes files, and no file a report writes there is one
    of the files its options read (a trace, a program, the processor check)."""
    if options.get("render") and not Path(directory).is_dir():     # nothing to draw from: create nothing
        raise Mech2SpiceError(f"report directory {directory} does not exist: --render draws from the JSON a "
                              "measuring run stored there")
    check_output_dir(directory, "report directory", parents=True)
    read = [(f"the {flag} file", options[dest]) for flag, dest, kw in OPTIONS
            if kw.get("metavar") == "FILE" and dest != "checkpoint" and options.get(dest)]
    for name in names:
        for written in _files(name, options.get("name")):
            path = check_inside(written, directory, f"report {name}'s file")
            check_output_file(path, read, f"report {name}'s file", parents=True)


def _files(name: str, stem: str | None) -> list[str]:
    """The files report `name` writes in its folder; --name STEM renames them (STEM.md, STEM.json, ...)."""
    if stem is None:
        return list(REPORTS[name].writes)
    if not stem or Path(stem).name != stem or stem in (".", ".."):
        raise Mech2SpiceError(f"--name {stem!r}: a file stem, not a path (the report is written in --out)")
    return [stem + w[len(name):] if w.startswith(name) else w for w in REPORTS[name].writes]


def _names(given: list[str]) -> list[str]:
    """The report names to run: 'all' expands to every report; unknown names are an error."""
    if not given:
        raise Mech2SpiceError("name a report (or 'all'); `mech2spice report --list` lists them")
    unknown = [n for n in given if n != "all" and n not in REPORTS]
    if unknown:
        raise Mech2SpiceError(f"unknown report {', '.join(unknown)} (reports: {', '.join(REPORTS)}, all)")
    return list(REPORTS) if "all" in given else list(dict.fromkeys(given))


def _write(name: str, directory: str, options: dict) -> dict:
    """Run one report; its progress goes to stderr, so stdout carries only the result."""
    t0 = time.perf_counter()
    print(f"mech2spice report {name}: writing to {directory}", file=sys.stderr, flush=True)
    with contextlib.redirect_stdout(sys.stderr), _stored_shape(name, directory, options.get("render")):
        path = module(name).write(directory, **options)
    return {"name": name, "path": str(path), "wall_s": round(time.perf_counter() - t0, 1)}


# What a renderer raises on stored JSON of another shape (a list where a table was, a string where a count was)
SHAPE_ERRORS = (KeyError, TypeError, IndexError, ValueError, AttributeError, ZeroDivisionError)


@contextlib.contextmanager
def _stored_shape(name: str, directory: str, render: bool):
    """--render measures nothing: what fails on the stored JSON's shape is the file's fault, one line naming
    it (mech2spice/reports/schemas.py has checked every file it reads, field by field; this is the net under it)."""
    try:
        yield
    except SHAPE_ERRORS as err:
        if not render or isinstance(err, Mech2SpiceError):
            raise
        raise Mech2SpiceError(f"report {name}: the stored JSON in {directory} is not what the report reads "
                              f"({type(err).__name__}: {str(err)[:120]}): measure it again (without --render)") \
            from None


def _list(as_json: bool) -> int:
    if as_json:
        print(strict_json([{"name": n, "description": r.description, "cost": r.cost, "writes": list(r.writes),
                           "options": [f for f, d, _ in OPTIONS if d in r.options]}
                          for n, r in REPORTS.items()], indent=2))
    else:
        for n, r in REPORTS.items():
            print(f"{n:15s} {r.cost:>8s}  {r.description}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """`python -m mech2spice.reports ...`: the same as `mech2spice report ...`."""
    p = argparse.ArgumentParser(prog="python -m mech2spice.reports", description=__doc__.splitlines()[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter, epilog=_epilog())
    add_arguments(p)
    args = p.parse_args(argv)
    try:
        return args.func(args)
    except Mech2SpiceError as e:
        print(f"mech2spice: error: {e}", file=sys.stderr)
        return 2
