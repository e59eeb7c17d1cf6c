"""Which designs of the public RTL suite race (synthesis/races.py): `synth --json` on every design of
$MECH2SPICE_BENCHMARKS/rtl/manifest.json, one row each: accepted with its races, or refused (first line).

    python scripts/race_check.py [--timeout S]

The false-positive check of docs/rtl.md, "Races between clocked blocks": only designs whose clocked blocks
pass a value through a blocking `=` on one edge should list races.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def row(bench: Path, design: dict, timeout: float) -> str:
    top = ["--top", design["top"]] if design.get("top") else []
    cmd = [sys.executable, "-m", "mech2spice.cli", "synth", str(bench / design["file"]), *top, "--json"]
    try:
        run = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return f"{design['name']}: timed out after {timeout:.0f} s"
    if run.returncode != 0:
        return f"{design['name']}: refused: {(run.stderr.strip().splitlines() or ['?'])[-1][:150]}"
    found = json.loads(run.stdout)["races"]
    names = ", ".join(f"{r['variable']} ({r['write_line']}->{r['read_line']})" for r in found)
    return f"{design['name']}: {len(found)} races" + (f": {names}" if found else "")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--timeout", type=float, default=300)
    args = ap.parse_args()
    bench = Path(os.environ.get("MECH2SPICE_BENCHMARKS", "/work/benchmarks")) / "rtl"
    for design in json.loads((bench / "manifest.json").read_text())["designs"]:
        print(row(bench, design, args.timeout), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
