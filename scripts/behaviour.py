"""Record the command line's JSON on a fixed set of runs, and compare two recordings.

Used to show that a restructuring changed no behaviour: record before the move, record after, compare.

    python scripts/behaviour.py record OUT.json [--only NAME ...]   # runs `python -m mech2spice.cli`
    python scripts/behaviour.py compare BEFORE.json AFTER.json       # exit 1 on any difference

Numbers must agree within 1e-9 (relative, or absolute near zero); fields that measure the machine
(`wall_s`) and paths are ignored.  Runs from the repository root it lives in.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
ADDER = ["verilog/adder2.v", "--set", "a=3", "--set", "b=2"]
COUNTER_STIMULUS = [{"set": {"rst": 1}, "cycles": 1}, {"set": {"rst": 0, "en": 1}, "cycles": 3}]

# name -> argv after `mech2spice`
RUNS = {
    "gate": ["gate", "--json"],
    "gate_robust": ["gate", "--params", "robust", "--json"],
    "gate_spread_default": ["gate", "--spread", "1e-6", "--samples", "40", "--json"],
    "gate_spread_robust": ["gate", "--params", "robust", "--spread", "1e-5", "--samples", "40", "--json"],
    "simulate_adder_envelope_robust": ["simulate", *ADDER, "--backend", "envelope", "--params", "robust", "--json"],
    "synth_adder": ["synth", "verilog/adder2.v", "--json"],
    "synth_sqrt": ["synth", "verilog/sqrt.v", "--json"],
    "synth_cpu": ["synth", "verilog/cpu.v", "--json"],
    **{f"simulate_adder_{b}": ["simulate", *ADDER, "--backend", b, "--json"]
       for b in ("logic", "rk4", "envelope", "ngspice", "ngspice-envelope")},
    "simulate_sqrt_envelope": ["simulate", "verilog/sqrt.v", "--stimulus", "verilog/sqrt_2809.json",
                               "--backend", "envelope", "--json"],
    "simulate_counter_logic": ["simulate", "verilog/counter4.v", "--stimulus", "{counter}", "--backend", "logic",
                               "--json"],
    "simulate_counter_envelope": ["simulate", "verilog/counter4.v", "--stimulus", "{counter}",
                                  "--backend", "envelope", "--json"],
    "cpu_iss_sieve": ["cpu", "run", "programs/sieve.asm", "--backend", "iss", "--json"],
    "cpu_iss_30": ["cpu", "run", "programs/sieve.asm", "--backend", "iss", "--max-cycles", "30", "--json"],
    "cpu_envelope_30": ["cpu", "run", "programs/sieve.asm", "--backend", "envelope", "--max-cycles", "30",
                        "--json"],
}
IGNORED = {"wall_s", "netlist", "files", "cpu_s_total", "wall_s_total"}   # the machine, not the physics
TOL = 1e-9


def record(out: Path, only: list[str] | None) -> None:
    stim = out.with_name(out.stem + ".counter.json")     # the counter's stimulus, for the runs' time only
    stim.write_text(json.dumps(COUNTER_STIMULUS))
    try:
        _record(out, only, stim)
    finally:
        stim.unlink()


def _record(out: Path, only: list[str] | None, stim: Path) -> None:
    results = json.loads(out.read_text()) if out.exists() and only else {}
    for name, argv in RUNS.items():
        if only and name not in only:
            continue
        argv = [a.replace("{counter}", str(stim)) for a in argv]
        t0 = time.time()
        p = subprocess.run([sys.executable, "-m", "mech2spice.cli", *argv], cwd=ROOT, capture_output=True,
                           text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
        try:
            data = json.loads(p.stdout)
        except json.JSONDecodeError:
            data = None
        results[name] = {"exit": p.returncode, "json": data, "stderr": p.stderr.strip()[-500:] if data is None else ""}
        print(f"{name}: exit {p.returncode}, {time.time() - t0:.1f} s", file=sys.stderr, flush=True)
        out.write_text(json.dumps(results, indent=1, sort_keys=True))


def differences(a, b, path: str = "") -> list[str]:
    """Every place where two JSON values differ beyond TOL."""
    if isinstance(a, dict) and isinstance(b, dict):
        out = [f"{path}/{k}: only in {'before' if k in a else 'after'}" for k in sorted(set(a) ^ set(b))
               if k not in IGNORED]
        for k in sorted(set(a) & set(b)):
            if k not in IGNORED:
                out += differences(a[k], b[k], f"{path}/{k}")
        return out
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return [f"{path}: length {len(a)} != {len(b)}"]
        return [d for i, (x, y) in enumerate(zip(a, b)) for d in differences(x, y, f"{path}[{i}]")]
    if isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
        if a == b or math.isclose(a, b, rel_tol=TOL, abs_tol=TOL):
            return []
        return [f"{path}: {a!r} != {b!r}"]
    return [] if a == b else [f"{path}: {a!r} != {b!r}"]


def compare(before: Path, after: Path) -> int:
    a, b = json.loads(before.read_text()), json.loads(after.read_text())
    diffs = differences(a, b)
    for d in diffs:
        print(d)
    print(f"{len(set(a) & set(b))} runs compared, {len(diffs)} differences")
    return 1 if diffs else 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("record")
    r.add_argument("out", type=Path)
    r.add_argument("--only", nargs="*")
    c = sub.add_parser("compare")
    c.add_argument("before", type=Path)
    c.add_argument("after", type=Path)
    args = ap.parse_args()
    if args.cmd == "record":
        record(args.out, args.only)
        return 0
    return compare(args.before, args.after)


if __name__ == "__main__":
    sys.exit(main())
