"""Samples per core-second of the processor Monte-Carlo before and after: the processor's own envelope step
and OpenBLAS's own thread count (the cores) against --step S (0: the processor's own) and --blas-threads N;
or, with --compare etd, the exponential step before ETDRK4 (insulators exact, RK4 on every amplitude: the
processor's own step under it) against ETDRK4 (each amplitude's own rate exact too: its own step), both at
--blas-threads N; or, with --compare step20, ETDRK4 as the processor stepped it before (its step capped at 16, its
weights refreshed when lambda h moved by 0.01) against now (cpu/physical.ETD_PROCESSOR_STEP, LAMBDA_TOL).

    python scripts/cpu_mc_speed.py [--samples 8] [--cycles 30] [--step 10] [--blas-threads 1] [--max-fanout 4]
        [--params centered_fc2] [--spread 0.01] [--trim fc] [--trim-residual 1e-4] [--seed 7]
        [--program programs/sieve.asm] [--indices 0,9] [--out reports/cpu_mc_speed.json]

Runs the same sample indices both ways in this one process, as `cpu montecarlo` builds them
(experiments/mc_clocked.CpuMC._machine: the sample's model, power-up, then cycle after cycle against the
ISS), alternating which way goes first from sample to sample so that a change in the machine's load
falls on both.  A one-cycle warm-up loads the compiled kernels first.  Each sample is timed whole
(model build, power-up, cycles) in process CPU seconds.  Writes JSON: each way's CPU seconds, samples per
core-second and gate-block steps integrated (the kernel's work, which the load does not blur), their
ratios, and for every sample whether its cycle records (pc, phase, read address and data, write enable,
write address and data) and its verdict are the same both ways, with the largest difference of any read
amplitude (latch outputs and ports, u_R) between the two.  The load average and core count are recorded
before and after.
"""
import argparse
import json
import os
import time

import numpy as np

from mech2spice.backends import _envelope_latency as _lat
from mech2spice.experiments import montecarlo as mc
from mech2spice.experiments.blas import set_blas_threads
from mech2spice.experiments.mc_clocked import CpuMC
from mech2spice.physics.params import load_params


def run_sample(mcx: CpuMC, i: int) -> dict:
    """Sample i as CpuMC._one runs it, keeping every cycle's record and read amplitudes."""
    c0 = time.process_time()
    cpu = mcx._machine(i)
    cycles, amps, verdict, reason = [], [], True, None
    try:
        for want in mcx.want:
            got = cpu.step()
            cycles.append(got)
            amps.append(np.array([cpu.amps[p] for p in cpu.probes]))
            if any(getattr(got, f) != getattr(want, f) for f in mcx.compared(want)):
                verdict = False
                break
    except Exception as e:            # an invalid bit or a divergence: a failed sample, as CpuMC records it
        verdict, reason = False, str(e).splitlines()[0]
    return {"cpu_s": time.process_time() - c0, "block_steps": cpu.block_steps, "cycles": cycles,
            "amps": amps, "pass": verdict, "reason": reason, "step": cpu.step_periods}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--samples", type=int, default=8)
    ap.add_argument("--cycles", type=int, default=30)
    ap.add_argument("--step", type=float, default=10.0, help="the step 'after' (0: the processor's own)")
    ap.add_argument("--blas-threads", type=int, default=1, help="OpenBLAS threads 'after' (before: the cores)")
    ap.add_argument("--max-fanout", type=int, default=4)
    ap.add_argument("--params", default="centered_fc2")
    ap.add_argument("--spread", type=float, default=0.01)
    ap.add_argument("--trim", default="fc")
    ap.add_argument("--trim-residual", type=float, default=1e-4)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--program", default="programs/sieve.asm")
    ap.add_argument("--indices", default=None, help="sample indices, comma-separated (default 0 .. samples-1)")
    ap.add_argument("--out", default=None, help="JSON file (default: print)")
    ap.add_argument("--compare", choices=["step", "etd", "step20"], default="step",
                    help="step: --step and --blas-threads against the defaults; etd: the step without and with ETDRK4; "
                         "step20: the ETD step as session 15 left it (cap 16, weights refreshed at |d lambda h| 0.01) "
                         "against now (cap 20, 0.1)")
    a = ap.parse_args()
    load0, t0 = os.getloadavg(), time.time()
    spec = mc.spec_of({"local": a.spread, "trim": a.trim, "trim_residual": a.trim_residual})
    p = load_params(a.params)
    lam = {"before": _lat.LAMBDA_TOL, "after": _lat.LAMBDA_TOL}
    if a.compare == "step20":
        ways = {"before": CpuMC(a.program, a.cycles, p, "envelope", spec, a.seed, max_fanout=a.max_fanout,
                                etd_step=16.0),
                "after": CpuMC(a.program, a.cycles, p, "envelope", spec, a.seed, max_fanout=a.max_fanout)}
        threads = {"before": a.blas_threads, "after": a.blas_threads}
        lam["before"] = 0.01
    elif a.compare == "etd":
        ways = {k: CpuMC(a.program, a.cycles, p, "envelope", spec, a.seed, max_fanout=a.max_fanout, etd=etd)
                for k, etd in (("before", False), ("after", True))}
        threads = {"before": a.blas_threads, "after": a.blas_threads}
    else:
        ways = {"before": CpuMC(a.program, a.cycles, p, "envelope", spec, a.seed, max_fanout=a.max_fanout),
                "after": CpuMC(a.program, a.cycles, p, "envelope", spec, a.seed, max_fanout=a.max_fanout,
                               step=a.step or None)}
        threads = {"before": os.cpu_count(), "after": a.blas_threads}
    for k, mcx in ways.items():            # warm-up: the compiled kernels loaded for both
        set_blas_threads(threads[k])
        _lat.LAMBDA_TOL = lam[k]
        mcx._machine(0).step()
    runs = {k: [] for k in ways}
    indices = [int(x) for x in a.indices.split(",")] if a.indices else list(range(a.samples))
    for n, i in enumerate(indices):
        order = list(ways) if n % 2 == 0 else list(ways)[::-1]
        for k in order:
            set_blas_threads(threads[k])
            _lat.LAMBDA_TOL = lam[k]
            runs[k].append(run_sample(ways[k], i))
    per = []
    for i, x, y in zip(indices, runs["before"], runs["after"]):
        dev = max((float(np.abs(u - v).max()) for u, v in zip(x["amps"], y["amps"])), default=None)
        per.append({"i": i, "pass_before": x["pass"], "pass_after": y["pass"], "verdict_equal": x["pass"] == y["pass"],
                    "cycles_equal": x["cycles"] == y["cycles"], "cycles_run": [len(x["cycles"]), len(y["cycles"])],
                    "max_read_difference_uR": dev, "cpu_s": [round(x["cpu_s"], 3), round(y["cpu_s"], 3)],
                    "block_steps": [x["block_steps"], y["block_steps"]], "reason": [x["reason"], y["reason"]]})
    total = {k: {"step_periods": v[0]["step"], "blas_threads": threads[k], "lambda_tol": lam[k], "cpu_s": round(sum(r["cpu_s"] for r in v), 2),
                 "samples_per_core_s": len(v) / sum(r["cpu_s"] for r in v),
                 "block_steps": sum(r["block_steps"] for r in v)} for k, v in runs.items()}
    res = {"command": "python scripts/cpu_mc_speed.py " + " ".join(
               f"--{k.replace('_', '-')} {v}" for k, v in vars(a).items() if k != "out" and v is not None),
           "samples": len(indices), "indices": indices, "cycles": a.cycles, "max_fanout": a.max_fanout, "params": a.params,
           "spread": a.spread, "trim": a.trim, "trim_residual": a.trim_residual, "seed": a.seed,
           "cores": os.cpu_count(), "load_avg_before": load0, "load_avg_after": os.getloadavg(),
           "wall_s": round(time.time() - t0, 1), **total,
           "speed_ratio": total["after"]["samples_per_core_s"] / total["before"]["samples_per_core_s"],
           "work_ratio": total["before"]["block_steps"] / total["after"]["block_steps"],
           "all_cycles_equal": all(r["cycles_equal"] for r in per), "all_verdicts_equal": all(r["verdict_equal"] for r in per),
           "per_sample": per}
    text = json.dumps(res, indent=1, default=str)
    if a.out:
        with open(a.out, "w") as fh:
            fh.write(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
