"""A markdown table of a centering record (design/centering.py): per accepted step, the linear tolerance, beta
at the target spread, and the limiting constraint with its largest element shares.

    python scripts/centering_summary.py build/center_fc/centering.json [--every 10]
"""
from __future__ import annotations

import argparse
import json


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("record")
    ap.add_argument("--every", type=int, default=10, help="one row per this many steps (and the last)")
    a = ap.parse_args()
    rec = json.load(open(a.record))
    st = rec["steps"]
    cfg = {k: v for k, v in rec["settings"].items() if k != "variables"}
    levels = "free" if "band0_lo" in rec["settings"].get("variables", []) else "fixed"
    print(f"settings: {json.dumps(cfg)}, levels {levels}; "
          f"{len(st) - 1} steps, {sum(s['accepted'] for s in st[1:])} accepted, "
          f"{sum(s.get('wall_s', 0) for s in st):.0f} s")
    print("| step | linear tolerance | beta at target | nominal margin | limiting (kind, inputs) | elements (share) |")
    print("|---|---|---|---|---|---|")
    rows = [s for s in st if s["accepted"]]
    keep, seen = [], set()
    for s in rows:                       # the first accepted step of each block of `every` steps, and the last
        if s["step"] // a.every not in seen or s is rows[-1]:
            seen.add(s["step"] // a.every)
            keep.append(s)
    for s in keep:
        lim = s.get("limiting_target") or {}
        els = ", ".join(f"{e['name']} ({e['share']:.2f})" for e in lim.get("elements", [])[:2])
        ins = ", ".join(f"{v:.3f}" for v in lim.get("inputs", []))
        print(f"| {s['step']} | {s['tolerance_linear']:.3g} | {s['beta_target']:.3g} | {s['nominal_margin']:+.4f} | "
              f"{lim.get('kind', '')} ({ins}) | {els} |")


if __name__ == "__main__":
    main()
