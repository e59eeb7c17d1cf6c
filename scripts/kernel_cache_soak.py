"""Many envelope runs, each in its own process, from one clone: does the kernel cache hold (issue 26)?

    git clone REPO /tmp/soak
    python scripts/kernel_cache_soak.py /tmp/soak --runs 100 --out soak.json [-- MECH2SPICE ARGS ...]

Runs the mech2spice command (default: a 2-bit adder on the envelope engine) RUNS times in the clone, one
process each, and records per run the exit code, the wall time, the kernels compiled (numba cache misses,
from mech2spice.backends.kernel_cache; null in a tree without it, which runs the command directly) and
the size of numba's cache in the clone's mech2spice/backends/__pycache__ after it.  Writes the records
and a summary as JSON and prints the summary.  Exit 0 when every run exited 0 and no run after the first
compiled anything, else 1; bad arguments: one line on stderr, exit 2.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

COMMAND = ["simulate", "verilog/adder2.v", "--set", "a=1", "--set", "b=2", "--backend", "envelope", "--json"]


def cache_size(clone: Path) -> tuple[int, int]:
    """(bytes, files) of numba's cache files (.nbi index, .nbc data) for the clone's kernels."""
    files = list((clone / "mech2spice" / "backends" / "__pycache__").glob("*.nb[ic]"))
    return sum(f.stat().st_size for f in files), len(files)


def run_once(clone: Path, command: list[str], stats_file: Path, with_stats: bool) -> dict:
    """One process: exit code, wall time, kernels compiled (None without stats) and the cache after it."""
    env = {n: v for n, v in os.environ.items() if not n.startswith("NUMBA_")}     # the clone's own cache
    env["PYTHONPATH"] = str(clone)
    stats_file.unlink(missing_ok=True)
    head = ["-m", "mech2spice.backends.kernel_cache", "--out", str(stats_file), "--"] if with_stats else \
        ["-m", "mech2spice.cli"]
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, *head, *command], cwd=clone, env=env, stdout=subprocess.DEVNULL,
                       stderr=subprocess.PIPE, text=True)
    wall = time.perf_counter() - t0
    compiled = None
    if with_stats and stats_file.exists() and stats_file.stat().st_size:
        compiled = json.loads(stats_file.read_text())["compiled"]
    size, files = cache_size(clone)
    error = _error(p.stderr) if p.returncode else None
    return {"rc": p.returncode, "wall_s": round(wall, 3), "compiled": compiled, "cache_bytes": size,
            "cache_files": files, "error": error}


def _error(stderr: str) -> str | None:
    """The exception a traceback ended in (the CLI's last line follows it), else stderr's last line."""
    lines = stderr.strip().splitlines()
    found = [ln for ln in lines if re.match(r"[A-Za-z_][\w.]*(Error|Exception): ", ln)]
    return (found or lines or [None])[-1]


def summary(runs: list[dict], before: tuple[int, int]) -> dict:
    later = runs[1:]
    failed = [k for k, r in enumerate(runs, 1) if r["rc"] != 0]
    return {"runs": len(runs), "exit_codes": dict(Counter(r["rc"] for r in runs)),
            "first_failure": failed[0] if failed else None,
            "first_error": runs[failed[0] - 1]["error"] if failed else None,
            "first_wall_s": runs[0]["wall_s"],
            "later_wall_s": _spread([r["wall_s"] for r in later]),
            "first_compiled": runs[0]["compiled"],
            "later_compiled_total": None if any(r["compiled"] is None for r in later) else
            sum(r["compiled"] for r in later),
            "cache_before": before, "cache_after_first": (runs[0]["cache_bytes"], runs[0]["cache_files"]),
            "cache_after_last": (runs[-1]["cache_bytes"], runs[-1]["cache_files"])}


def _spread(xs: list[float]) -> dict | None:
    if not xs:
        return None
    return {"median": round(statistics.median(xs), 3), "min": min(xs), "max": max(xs)}


def _args(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("clone", type=Path, help="a fresh clone of mech2spice (its cache is the one measured)")
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--out", type=Path, default=Path("kernel_cache_soak.json"))
    ap.add_argument("command", nargs="*", default=None, help="mech2spice arguments after -- (default: the adder on envelope)")
    ap.error = lambda msg: ap.exit(2, f"kernel_cache_soak: {msg}\n")      # one line, not the usage
    a = ap.parse_args(argv)
    if not (a.clone / "mech2spice" / "cli.py").is_file():
        ap.exit(2, f"kernel_cache_soak: {a.clone} is not a mech2spice tree\n")
    if a.runs < 1:
        ap.exit(2, f"kernel_cache_soak: --runs {a.runs}: must be at least 1\n")
    return a


def main(argv: list[str] | None = None) -> int:
    a = _args(argv)
    clone = a.clone.resolve()
    with_stats = (clone / "mech2spice" / "backends" / "kernel_cache.py").is_file()
    stats_file = clone / ".kernel_cache_soak.stats.json"
    before, runs = cache_size(clone), []
    for k in range(a.runs):
        runs.append(run_once(clone, a.command or COMMAND, stats_file, with_stats))
        if (k + 1) % 10 == 0 or runs[-1]["rc"]:
            r = runs[-1]
            print(f"run {k + 1}: rc {r['rc']}, {r['wall_s']} s, compiled {r['compiled']}, "
                  f"cache {r['cache_bytes']} B", file=sys.stderr)
    stats_file.unlink(missing_ok=True)
    s = summary(runs, before)
    a.out.write_text(json.dumps({"clone": str(clone), "command": a.command or COMMAND, "summary": s,
                                 "runs": runs}, indent=1))
    print(json.dumps(s, indent=1))
    ok = s["exit_codes"] == {0: len(runs)} and not s["later_compiled_total"]
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
