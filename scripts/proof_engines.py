"""The equivalence proof per engine (docs/verify.md, "Engines"): `verify.equivalence` with ABC alone, sat
alone and the default (auto: ABC first, then sat), one Markdown row per design and engine: status, wall
time, the engine that decided.

    python scripts/proof_engines.py [--engines abc,sat,auto] [--budget S] NAME_OR_FILE ...

A NAME is a design of $MECH2SPICE_BENCHMARKS/rtl/manifest.json (its file, top and reset from there, the
reset rule of `verify` otherwise); a FILE is a Verilog file (verilog/cpu.v), its top found by synthesis.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from mech2spice import verify as V                      # noqa: E402
from mech2spice.errors import Mech2SpiceError           # noqa: E402
from mech2spice.synthesis.synth import synthesize       # noqa: E402


def _design(arg: str) -> tuple[str, Path, str | None]:
    """(name, file, top) of a suite name or a file."""
    if Path(arg).exists():
        return Path(arg).stem, Path(arg), None
    rtl = Path(os.environ.get("MECH2SPICE_BENCHMARKS", "")) / "rtl"
    for d in json.loads((rtl / "manifest.json").read_text())["designs"]:
        if d["name"] == arg:
            return arg, rtl / d["file"], d.get("top")
    raise SystemExit(f"{arg}: neither a file nor a design of {rtl / 'manifest.json'}")


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("designs", nargs="+")
    ap.add_argument("--engines", default="sat,abc")
    ap.add_argument("--budget", type=float, default=V.PROOF_BUDGET_S)
    args = ap.parse_args(argv)
    print(f"<!-- scripts/proof_engines.py --engines {args.engines} --budget {args.budget:g}; load "
          f"{os.getloadavg()[0]:.1f}; ABC {V.abc_tool() or 'absent'} -->")
    print("| design | gates / latches | engine | status | wall s | decided by | note |")
    print("|---|---|---|---|---|---|---|")
    for arg in args.designs:
        name, path, top = _design(arg)
        try:
            nl = synthesize(path, top=top)
        except Mech2SpiceError as err:                  # a refusal of synthesis: its line, no proof
            print(f"| {name} | - | - | refused | - | - | {str(err)[:160]} |", flush=True)
            continue
        resets = V.reset_ports(nl, None, path) if nl.clock else []
        for engine in args.engines.split(","):
            t0 = time.time()
            eq = V.equivalence(path, nl, args.budget, resets, engine=engine)
            note = (eq["engine_note"] or "") if eq["status"] == "proved" else eq["detail"]
            print(f"| {name} | {len(nl.gates())} / {len(nl.latches())} | {engine} | {eq['status']} | "
                  f"{time.time() - t0:.1f} | {eq['equivalence_engine']} | {note[:160]} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
