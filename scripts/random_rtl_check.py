"""`verify` on random single-clock designs (tests/random_rtl.py): registers with and without reset or power-up
value, next states through `if`/`case`/`?:` on one another, every third seed on the falling edge.  Each design
goes through `mech2spice verify --cycles N --json` in a subprocess; designs that synthesis leaves without a
flip-flop are counted apart.  docs/verify.md, "Random designs".

Usage:  python scripts/random_rtl_check.py [--seeds 0 60] [--cycles 300] [--clocking single|mixed|two]
                                         [--out reports/random_rtl.json]
`--clocking mixed`: each register on a random edge of one clock; `two`: of one of two clocks (both sampled).
"""
from __future__ import annotations

import argparse
import collections
import datetime
import json
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))

from random_rtl import design      # noqa: E402


def _one(seed: int, cycles: int, folder: Path, clocking: str = "single") -> dict:
    edge = clocking if clocking != "single" else "negedge" if seed % 3 == 0 else "posedge"
    src = folder / f"random_{seed}.v"
    src.write_text(design(seed, edge))
    proc = subprocess.run([sys.executable, "-m", "mech2spice.cli", "verify", str(src), "--cycles", str(cycles),
                           "--json"], capture_output=True, text=True, timeout=900)
    row = {"seed": seed, "edge": edge, "exit": proc.returncode}
    try:
        res = json.loads(proc.stdout)
    except ValueError:
        row["error"] = proc.stderr.strip().splitlines()[-1] if proc.stderr.strip() else "no output"
        return row
    co = res["cosim"]
    row.update(verdict=res["verdict"], equivalence=res["equivalence"]["status"], mismatches=len(co["mismatches"]),
               undefined_bits=co["undefined_bits"], power_up_start=co.get("power_up_start"),
               sampled_clocks=res.get("sampled_clocks", []))
    return row


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, nargs=2, default=(0, 60), metavar=("FIRST", "END"))
    p.add_argument("--cycles", type=int, default=300)
    p.add_argument("--clocking", choices=("single", "mixed", "two"), default="single")
    p.add_argument("--out", type=Path, default=ROOT / "reports" / "random_rtl.json")
    args = p.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory(prefix="random_rtl_") as tmp:
        for seed in range(*args.seeds):
            rows.append(_one(seed, args.cycles, Path(tmp), args.clocking))
            print(json.dumps(rows[-1]), flush=True)
    kinds = collections.Counter("no flip-flop" if "no flip-flops" in r.get("error", "") else
                                r.get("verdict", "error") for r in rows)
    started = [r for r in rows if r.get("power_up_start")]
    summary = {"designs": len(rows), "outcomes": dict(kinds), "second_icarus_run": len(started),
               "passed_after_start": sum(r["verdict"] == "pass" for r in started)}
    out = {"script": "scripts/random_rtl_check.py", "clocking": args.clocking, "date": datetime.datetime.now(datetime.timezone.utc).isoformat(),
           "machine": platform.platform(), "cycles": args.cycles, "summary": summary, "rows": rows}
    args.out.write_text(json.dumps(out, indent=1) + "\n")
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    sys.exit(main())
