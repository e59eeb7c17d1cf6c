"""The held counter4's stability for a block, and the insulator damping that reaches the floor (issue #27).

    python scripts/held_damping.py PARAMS [--damp OUT.json]

PARAMS: a preset name or a block file.  Prints, as JSON, the held counter4's growth per cycle
(experiments/held.py) and, with --damp, lowers the insulator's Q until it decays at HELD_GROWTH_FLOOR and
writes the block (the input block file's other fields kept, its note extended) to OUT.json.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from mech2spice.experiments import held
from mech2spice.physics.params import load_params


def block_file(params: str, p, record: dict) -> dict:
    """The block file for the damped p: the source file's fields where there is one, the insulator's Q and
    the damping record replaced."""
    src = Path(params)
    if not src.is_file():
        src = Path(__file__).resolve().parent.parent / "mech2spice" / "data" / "blocks" / f"{params}.json"
    data = json.loads(src.read_text())
    data["block"] = p.structure.to_dict()
    data.setdefault("search", {})["held_damping"] = {k: record[k] for k in ("floor", "reached", "q_insulator",
                                                                           "tried")}
    data.setdefault("measured", {})["held_growth"] = record["tried"][-1]["growth"]
    return data


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("params")
    ap.add_argument("--damp", type=Path, metavar="OUT.json")
    args = ap.parse_args()
    p, t0 = load_params(args.params), time.time()
    if args.damp is None:
        out = held.held_growth(p)
        out["growth"] = held.json_rate(out["growth"])
    else:
        p, out = held.damp_insulator(p, log=lambda m: print(m, file=sys.stderr, flush=True))
        args.damp.write_text(json.dumps(block_file(args.params, p, out), indent=1) + "\n")
    print(json.dumps({"params": args.params, "q_insulator": held.insulator_q(p), **out,
                      "wall_s": round(time.time() - t0, 1)}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
