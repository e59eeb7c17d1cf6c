"""The `mech2spice` command line: the parser of every command, and the one handler that turns expected
failures into one line on stderr (exit 2).  Command names and JSON fields are a contract: keep them stable.

One module per command group (gate, simulate, cpu, montecarlo, design, verify); `_output` holds what they
all print through.  The report command's parser lives with the reports (`reports/cli.py`)."""
from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
from pathlib import Path

from .. import inputs
from ..backends import engine_class
from ..errors import Mech2SpiceError
from . import cpu, design, domain, gate, montecarlo, simulate, verify


# --- parser --------------------------------------------------------------------
class _Parser(argparse.ArgumentParser):
    """argparse with usage errors as one line (exit 2), like every other error."""

    def error(self, message):
        """Print the usage error as one line on stderr and exit 2."""
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (see {self.prog} --help)\n")


def version() -> str:
    """The installed distribution's version, else (a source tree run in place) the package's own."""
    from importlib import metadata
    try:
        return metadata.version("mech2spice")
    except metadata.PackageNotFoundError:
        from .. import __version__
        return __version__


def build_parser() -> argparse.ArgumentParser:
    """The `mech2spice` argument parser with every subcommand."""
    ap = _Parser(
        prog="mech2spice",
        description="Verilog -> networks of nonlinear mechanical NOR gates -> RK4 / envelope / ngspice.")
    ap.add_argument("--version", action="version", version=f"mech2spice {version()}")
    sub = ap.add_subparsers(dest="command", required=True)
    gate.add_parser(sub)
    simulate.add_parsers(sub)                 # synth, simulate, emit
    cpu.add_parser(sub)
    from ..reports.cli import add_parser as add_report_parser
    add_report_parser(sub)
    montecarlo.add_parser(sub)
    design.add_parser(sub)
    verify.add_parser(sub)
    domain.add_parser(sub)
    simulate.add_subckts_parser(sub)
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
    print("mech2spice: error: " + _visible(" ".join(msg.split())), file=sys.stderr)
    return 2


def _visible(text: str) -> str:
    """A message with each control character escaped: a NUL or an ESC taken from a user's file (a port name)
    hid part of the line or reached the terminal as a command (an ESC [31m turned it red)."""
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text)


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
    from ..physics.params import load_params, params_file
    if getattr(args, "params", None) is not None:
        load_params(args.params)
    design_file, command = getattr(args, "design", None), args.command
    if command == "emit":
        from ..spice import NETLIST
        read = [*inputs.design_inputs(design_file), ("the --params file", params_file(args.params))]
        inputs.check_output_file(args.output, read, "netlist file", kind=NETLIST, force=args.force)
    elif command == "subckts":
        from ..spice.oscillator_netlist import check_library_files
        inputs.check_output_dir(args.output, "subckt directory")
        check_library_files(args.output, load_params(args.params), {"the --params file": params_file(args.params)},
                            args.force)
    elif command == "gate" and args.report and not (args.sens or args.spread is not None):
        # (with --sens/--spread, --report is refused as a flag combination, before any path is read)
        from ..reports import REPORTS
        inputs.check_output_dir(args.report, "report directory")
        for name in REPORTS["gate"].writes:                  # gate.json beside gate.md: never the --params file
            inputs.check_output_file(Path(args.report) / name, {"the --params file": params_file(args.params)},
                                     "gate report file")
    if getattr(args, "stimulus", None):
        inputs.stimulus_steps(args.stimulus, {}, engine_class(args.backend))
