"""The demonstrations a block preset must pass (issue #27), run through the command line, each result kept.

    python scripts/preset_checks.py NAME OUT_DIR [--only CHECK ...]

Checks: the adder's 16 sums against Icarus on RK4, envelope and ngspice (`verify --exhaustive`), sqrt(2809)
on the envelope, the sieve to its halt on the envelope with every cycle checked against the ISS.  Each
check's JSON goes to OUT_DIR/NAME.CHECK.json and a line to stderr; OUT_DIR/NAME.summary.json collects them.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CHECKS = {
    "adder_rk4": ["verify", "verilog/adder2.v", "--backend", "rk4", "--exhaustive", "--json"],
    "adder_envelope": ["verify", "verilog/adder2.v", "--backend", "envelope", "--exhaustive", "--json"],
    "adder_ngspice": ["verify", "verilog/adder2.v", "--backend", "ngspice", "--exhaustive", "--json"],
    "sqrt_envelope": ["simulate", "verilog/sqrt.v", "--stimulus", "verilog/sqrt_2809.json", "--backend", "envelope",
                      "--json"],
    "sieve_envelope": ["cpu", "run", "programs/sieve.asm", "--backend", "envelope", "--json"],
}


def summary(name: str, res: dict) -> dict:
    """The figures a reader checks, per kind of result."""
    if name.startswith("adder"):
        co = res["cosim"]
        return {"vectors": co["vectors"], "agree": co["agree"], "valid": co.get("valid"),
                "stable": co.get("stable"), "min_margin": co.get("min_margin"), "verdict": res["verdict"]}
    if name.startswith("sqrt"):
        return {"outputs": res.get("outputs"), "valid": res.get("valid"), "min_margin": res.get("min_margin")}
    return {"halted": res["halted"], "cycles": res["cycles"], "primes": res.get("results", {}).get("primes"),
            "iss_check": res.get("iss_check", {}).get("mismatches"), "wall_s": res["wall_s"]}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("preset")
    ap.add_argument("out", type=Path)
    ap.add_argument("--only", nargs="+", choices=list(CHECKS))
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / f"{args.preset}.summary.json"
    done = json.loads(path.read_text()) if path.exists() else {}
    for name, argv in CHECKS.items():
        if args.only and name not in args.only:
            continue
        t0 = time.time()
        p = subprocess.run([sys.executable, "-m", "mech2spice.cli", *argv, "--params", args.preset], cwd=ROOT,
                           capture_output=True, text=True)
        try:
            res = json.loads(p.stdout)
        except json.JSONDecodeError:
            done[name] = {"exit": p.returncode, "error": p.stderr.strip()[-400:]}
        else:
            (args.out / f"{args.preset}.{name}.json").write_text(json.dumps(res, indent=1))
            done[name] = {"exit": p.returncode, "wall_s": round(time.time() - t0, 1), **summary(name, res)}
        print(f"{args.preset} {name}: {json.dumps(done[name])}", file=sys.stderr, flush=True)
        path.write_text(json.dumps(done, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
