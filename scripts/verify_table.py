"""The measured table of docs/verify.md: `verify` (equivalence + co-simulation on the logic backend, default
vector / cycle counts) on every design in verilog/ that synthesises, one Markdown row each.

    python scripts/verify_table.py [DESIGN.v ...]

Designs synthesis refuses (bad_syntax, inferred_latch, loop) are listed on stderr and skipped.
"""
from __future__ import annotations

import collections
import platform
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from mech2spice import verify as V                      # noqa: E402
from mech2spice.errors import Mech2SpiceError           # noqa: E402
from mech2spice.synthesis import yosys                  # noqa: E402


def row(path: Path) -> str:
    res = V.verify(path)
    eq, co = res["equivalence"], res["cosim"]
    matched = eq["method"].split(", ")[-1].rstrip(")") if "matched" in eq["method"] else ""
    n = co.get("cycles", co.get("vectors"))
    what = "cycles" if "cycles" in co else ("(exhaustive)" if co["exhaustive"] else "random")
    icarus = collections.Counter(m["icarus"] for m in co["mismatches"])
    mism = ", ".join(f"{k} where Icarus says {v}" for v, k in sorted(icarus.items())) or "0"
    if co.get("undefined_bits"):
        mism += f" ({co['undefined_bits']} bits x in Icarus: either value agrees)"
    return (f"| {res['top']} | {res['gates']} / {res['latches']} | {eq['status']}"
            f"{' (' + matched + ')' if matched else ''}, {eq['wall_s']:.1f} s | {n} {what}, mismatches: {mism}, "
            f"{co['wall_s']:.1f} s | {res['verdict']} |")


def main(argv: list[str]) -> int:
    paths = [Path(p) for p in argv] or sorted((ROOT / "verilog").glob("*.v"))
    print(f"<!-- scripts/verify_table.py on {platform.node()}, {yosys.identity()} -->")
    print("| design | gates / latches | equivalence | co-simulation (logic) | verdict |\n|---|---|---|---|---|")
    for path in paths:
        try:
            print(row(path), flush=True)
        except Mech2SpiceError as err:
            print(f"{path.name}: skipped ({err})", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
