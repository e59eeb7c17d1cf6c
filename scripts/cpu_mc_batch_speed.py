"""Samples per core-second of the processor Monte-Carlo, one sample per run against several per union model.

    python scripts/cpu_mc_batch_speed.py [--samples 4] [--cycles 30] [--batch 4] [--params centered_fc2]
        [--spread 0.01] [--trim fc] [--trim-residual 1e-4] [--seed 7] [--program programs/sieve.asm]

Runs the same sample indices both ways in this one process, back to back (after a one-cycle warm-up that
loads the compiled kernels), as `cpu montecarlo` evaluates them (experiments/mc_clocked.CpuMC, batch 1 and
batch B: cpu/batch.py).  Prints JSON: each way's process CPU seconds, wall seconds, samples per core-second,
the ratio batched / unbatched, and whether every sample's record (pass, failing fields, first bad cycle,
cycles run) is the same both ways.
"""
import argparse
import json
import os
import time

from mech2spice.experiments import montecarlo as mc
from mech2spice.experiments.mc_clocked import CpuMC
from mech2spice.physics.params import load_params


def timed(mcx, indices):
    c0, w0 = time.process_time(), time.perf_counter()
    recs = mcx.evaluate(indices)
    return recs, time.process_time() - c0, time.perf_counter() - w0


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--samples", type=int, default=4)
    ap.add_argument("--cycles", type=int, default=30)
    ap.add_argument("--batch", type=int, default=4)
    ap.add_argument("--params", default="centered_fc2")
    ap.add_argument("--spread", type=float, default=0.01)
    ap.add_argument("--trim", default="fc")
    ap.add_argument("--trim-residual", type=float, default=1e-4)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--max-fanout", type=int, default=None)
    ap.add_argument("--program", default="programs/sieve.asm")
    a = ap.parse_args()
    spec = mc.spec_of({"local": a.spread, "trim": a.trim, "trim_residual": a.trim_residual})
    p = load_params(a.params)
    make = lambda b, n: CpuMC(a.program, n, p, "envelope", spec, a.seed, batch=b, max_fanout=a.max_fanout)
    make(2, 1).evaluate([0, 1])                    # warm-up: both paths' kernels loaded
    idx = list(range(a.samples))
    one, c1, w1 = timed(make(1, a.cycles), idx)
    many, cb, wb = timed(make(a.batch, a.cycles), idx)
    keys = ("pass", "failing_bits", "first_bad_cycle", "cycles_run", "reason")
    same = [all(x.get(k) == y.get(k) for k in keys) for x, y in zip(one, many)]
    print(json.dumps({
        "samples": a.samples, "cycles": a.cycles, "batch": a.batch, "params": a.params,
        "spread": a.spread, "trim": a.trim, "trim_residual": a.trim_residual, "seed": a.seed,
        "max_fanout": a.max_fanout, "load_avg": os.getloadavg(),
        "unbatched": {"cpu_s": round(c1, 2), "wall_s": round(w1, 2), "samples_per_core_s": a.samples / c1},
        "batched": {"cpu_s": round(cb, 2), "wall_s": round(wb, 2), "samples_per_core_s": a.samples / cb},
        "ratio": c1 / cb, "records_equal": same, "passed": [r["pass"] for r in one],
        "records": {"unbatched": one, "batched": many}}, indent=1, default=str))


if __name__ == "__main__":
    main()
