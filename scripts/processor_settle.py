"""What is still to come when the processor's pauses end early (issue #25): the truth the settle rule is judged by.

Runs a program on the envelope processor at its defaults (or the given settings) and, after every pause,
continues a copy of the state for --extra periods at the same step with nothing skipped (no idle skipping,
no per-gate latency): the probed amplitudes there are where the read was heading.  Per read and probed bit:
the amplitude read, the amplitude reached, its band and margin (band widths) at both.  Writes JSON lines
(one per pause) and prints a summary.

    python scripts/processor_settle.py programs/sieve.asm --cycles 457 --out build/settle.jsonl
"""
from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace

import numpy as np

from mech2spice.backends import make_engine
from mech2spice.cpu.machines import make_cpu
from mech2spice.cpu.run import load_program, make_memory
from mech2spice.physics import network


STEP_PROBE = 64       # periods every block runs for the rate estimate


def margin_bw(levels, x: float) -> float:
    """Signed distance of x to the nearest edge of the band it lies in, in that band's widths (< 0: in none)."""
    b = levels.band_of(x)
    if b is None:
        return -min(min(abs(x - lo), abs(x - hi)) / (hi - lo) for lo, hi in (levels.band0, levels.band1))
    lo, hi = levels.band0 if b == 0 else levels.band1
    return min(x - lo, hi - x) / (hi - lo)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("program")
    ap.add_argument("--cycles", type=int, default=457)
    ap.add_argument("--extra", type=int, default=6000, help="periods the copy continues (default 6000)")
    ap.add_argument("--settle", type=float, default=None, help="the processor's settle (default its own)")
    ap.add_argument("--latency", type=float, default=None, help="the processor's latency (default its own)")
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    physical = {k: v for k, v in (("settle", args.settle), ("latency", args.latency)) if v is not None}
    cpu = make_cpu("envelope", make_memory(load_program(args.program)), **physical)
    levels, u_r = cpu.p.levels, cpu.p.u_r
    ref = make_engine("envelope", replace(cpu.pause_engine.options, settle_tol=None, latency=None))
    run, rows = cpu._run, []

    def checked(periods, values, clock):
        amps = run(periods, values, clock)
        if clock:
            return amps
        stim = network.stimulus(cpu.model, cpu.netlist, cpu.p, [(0, [values])], clock=[[0]])
        t0 = time.perf_counter()
        r = ref.run(cpu.model, args.extra, stim, state=tuple(np.array(a) for a in cpu.state[:3]),
                    start_period=cpu.period, probes=cpu.probes)
        reached = np.abs(r.amp[-10:, :, 0]).mean(axis=0) / u_r
        one = ref.run(cpu.model, STEP_PROBE, stim, state=tuple(np.array(a) for a in cpu.state[:3]),
                      start_period=cpu.period, probes=cpu.probes)
        moved = np.abs(one.amp[-1, :, 0]) / u_r       # after one step of every block: the scheme's own rate
        row = {"cycle": cpu.cycle, "period": cpu.period, "check_s": time.perf_counter() - t0, "bits": {}}
        for name, a in zip(cpu.probes, reached):
            read = amps[name]
            row["bits"][name] = [read, float(a), margin_bw(levels, read), margin_bw(levels, float(a))]
        row["step_change"] = dict(zip(cpu.probes, (moved - np.array([amps[n] for n in cpu.probes])).tolist()))
        rows.append(row)
        return amps

    cpu._run = checked
    t0 = time.perf_counter()
    with open(args.out, "w") as f:
        while not cpu.halted and cpu.cycle < args.cycles:
            n = len(rows)
            cpu.step()
            for row in rows[n:]:
                f.write(json.dumps(row) + "\n")
            f.flush()
    worst = max(((abs(b[1] - b[0]) / (levels.width(levels.band_of(b[0]) or 0)), r["cycle"], name)
                 for r in rows for name, b in r["bits"].items() if levels.band_of(b[0]) is not None), default=None)
    flips = [(r["cycle"], n) for r in rows for n, b in r["bits"].items()
             if levels.band_of(b[0]) != levels.band_of(b[1])]
    print(json.dumps({"cycles": cpu.cycle, "reads": len(rows), "wall_s": time.perf_counter() - t0,
                      "worst_still_to_come_bw": worst, "band_changes": flips[:20], "n_band_changes": len(flips),
                      "min_margin_read": min(b[2] for r in rows for b in r["bits"].values()),
                      "min_margin_reached": min(b[3] for r in rows for b in r["bits"].values())}, indent=1))


if __name__ == "__main__":
    main()
