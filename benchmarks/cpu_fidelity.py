#!/usr/bin/env python3
"""What each speed-up of the physical processor costs in accuracy (issue 6, multi-fidelity).

Runs the first N sieve cycles of `verilog/cpu.v` at envelope fidelity under several settings, side by
side in one process, and compares every cycle with the ISS (decoded port activity and registers) and
with the reference setting (the full fixed-length pauses, step 2 periods): the largest difference of
any probed amplitude (output bits and latch outputs) at the end of each cycle, the smallest band
margin of any decoded bit, the drive periods actually integrated and the wall time.

usage: python benchmarks/cpu_fidelity.py [--cycles 30] [--out reports/cpu_fidelity.json]
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from mech2spice.cpu import run as R
from mech2spice.cpu.iss import ISS
from mech2spice.cpu.physical import PhysicalCPU
from mech2spice.params import margin

# (label, envelope step in periods, settle tolerance in u_R or None)
SETTINGS = [("reference: step 2, full pauses", 2.0, None),
            ("step 4, full pauses", 4.0, None),
            ("step 4, settle 0.05", 4.0, 0.05),
            ("step 4, settle 0.1", 4.0, 0.1),
            ("step 4, settle 0.2", 4.0, 0.2)]


def run_setting(prog, cycles: int, step: float, settle) -> dict:
    iss = ISS(R.make_memory(prog))
    t0 = time.perf_counter()
    cpu = PhysicalCPU(R.make_memory(prog), "envelope", step=step, settle=settle)
    reset_s = time.perf_counter() - t0
    rows = []
    for _ in range(cycles):
        t = time.perf_counter()
        sim0 = cpu.simulated
        want, got = iss.step(), cpu.step()
        try:
            same = want == got and iss.registers() == cpu.registers()
        except Exception as err:          # an invalid bit: report it as a disagreement
            same, got = False, str(err)
        amps = dict(cpu.amps)
        rows.append({"cycle": len(rows), "same": bool(same), "wall_s": time.perf_counter() - t,
                     "simulated": cpu.simulated - sim0, "amps": amps,
                     "min_margin": float(min(margin(v) for v in amps.values()))})
        if not same:
            break
    return {"reset_s": reset_s, "rows": rows, "periods": cpu.period, "simulated": cpu.simulated,
            "wall_s": time.perf_counter() - t0}


def compare(res: dict) -> list[dict]:
    ref = res[SETTINGS[0][0]]["rows"]
    out = []
    for label, step, settle in SETTINGS:
        r = res[label]
        rows = r["rows"]
        diffs = [max(abs(row["amps"][k] - rr["amps"][k]) for k in rr["amps"]) for row, rr in zip(rows, ref)]
        out.append({"setting": label, "step": step, "settle": settle, "cycles": len(rows),
                    "all_same_as_iss": all(row["same"] for row in rows),
                    "max_amp_diff": float(max(diffs)), "min_margin": min(row["min_margin"] for row in rows),
                    "periods": r["periods"], "simulated": r["simulated"],
                    "wall_s": r["wall_s"], "reset_s": r["reset_s"],
                    "s_per_cycle": (r["wall_s"] - r["reset_s"]) / max(len(rows), 1)})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cycles", type=int, default=30)
    ap.add_argument("--out", default="reports/cpu_fidelity.json")
    a = ap.parse_args()
    prog = R.load_program("programs/sieve.asm")
    PhysicalCPU(R.make_memory(prog), "envelope", step=4.0, settle=0.1)     # compile the kernel first
    res = {}
    for label, step, settle in SETTINGS:
        res[label] = run_setting(prog, a.cycles, step, settle)
        print(label, f"{res[label]['wall_s']:.0f} s", flush=True)
    table = compare(res)
    for row in table:
        print(row)
    Path(a.out).write_text(json.dumps({"cycles": a.cycles, "table": table,
                                       "machine": "2-core Debian 12 sandbox (shared)"}, indent=1))


if __name__ == "__main__":
    main()
