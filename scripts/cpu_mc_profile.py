"""Where one processor Monte-Carlo sample's time goes: setup, power-up, and each kind of engine run.

    python scripts/cpu_mc_profile.py [--sample 1] [--cycles 30] [--max-fanout 4] [--step PERIODS] [--blas-threads N]
        [--params centered_fc2] [--spread 0.01] [--trim fc] [--trim-residual 1e-4] [--seed 7]

Builds the sample as `cpu montecarlo` does (experiments/mc_clocked.CpuMC._machine) after a warm-up sample
that loads the compiled kernels, then runs its cycles with every engine run of cpu/physical.PhysicalCPU
timed and sorted by kind: the pulse (clock on, always run in full), the pause after the edge (the new
registers settle), the pause after a new read word (the datapath settles on rdata).  Prints JSON: for each
kind the runs, the periods scheduled, the periods integrated (a pause ends once settled), the gate-block
steps (the compiled loop's work) and the process CPU seconds; the build and power-up CPU seconds; and the
cProfile entries of the whole sample above 2 % of it (wall seconds: on a loaded machine they exceed the CPU
seconds).  --blas-threads N: OpenBLAS on N threads (default: as loaded, one per core; `cpu montecarlo
--scheduler inline` sets 1, experiments/blas.py).
"""
import argparse
import cProfile
import json
import os
import pstats
import time

from mech2spice.cpu import physical
from mech2spice.experiments import montecarlo as mc
from mech2spice.experiments.blas import blas_threads, set_blas_threads
from mech2spice.experiments.mc_clocked import CpuMC
from mech2spice.physics.params import load_params


def instrument(stats: dict):
    """Wrap PhysicalCPU._run so that every run adds to stats[kind]."""
    run = physical.PhysicalCPU._run

    def timed(self, periods, values, clock):
        kind = ("pulse" if clock else "pause, new rdata" if values.get("rdata", self.rdata) != self.rdata
                else "pause")
        c0, sim0, bs0 = time.process_time(), self.simulated, self.block_steps
        out = run(self, periods, values, clock)
        s = stats.setdefault(kind, {"runs": 0, "periods": 0, "integrated": 0, "block_steps": 0, "cpu_s": 0.0})
        s["runs"] += 1
        s["periods"] += periods
        s["integrated"] += self.simulated - sim0
        s["block_steps"] += self.block_steps - bs0
        s["cpu_s"] += time.process_time() - c0
        return out

    physical.PhysicalCPU._run = timed


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--sample", type=int, default=1)
    ap.add_argument("--cycles", type=int, default=30)
    ap.add_argument("--max-fanout", type=int, default=4)
    ap.add_argument("--step", type=float, default=None)
    ap.add_argument("--params", default="centered_fc2")
    ap.add_argument("--spread", type=float, default=0.01)
    ap.add_argument("--trim", default="fc")
    ap.add_argument("--trim-residual", type=float, default=1e-4)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--program", default="programs/sieve.asm")
    ap.add_argument("--blas-threads", type=int, default=None)
    a = ap.parse_args()
    if a.blas_threads:
        set_blas_threads(a.blas_threads)
    spec = mc.spec_of({"local": a.spread, "trim": a.trim, "trim_residual": a.trim_residual})
    mcx = CpuMC(a.program, a.cycles, load_params(a.params), "envelope", spec, a.seed, max_fanout=a.max_fanout,
                step=a.step)
    mcx._machine(0).step()                       # warm-up: the compiled kernels loaded
    stats, load0 = {}, os.getloadavg()
    instrument(stats)
    prof = cProfile.Profile()
    c0 = time.process_time()
    prof.enable()
    cpu = mcx._machine(a.sample, power_up=False)
    c_build = time.process_time() - c0
    cpu.amps = cpu._reset()
    c_up = time.process_time() - c0 - c_build
    up = {k: dict(v) for k, v in stats.items()}
    stats.clear()
    for _ in mcx.want:
        cpu.step()
    prof.disable()
    total = time.process_time() - c0
    ps = pstats.Stats(prof)
    entries = sorted(((v[3], f"{k[0].split('mech2spice/')[-1]}:{k[1]}({k[2]})") for k, v in ps.stats.items()),
                     reverse=True)
    print(json.dumps({
        "sample": a.sample, "cycles": a.cycles, "max_fanout": a.max_fanout, "step_periods": cpu.step_periods,
        "params": a.params, "blas_threads": blas_threads(), "load_avg": [load0, os.getloadavg()], "cpu_s": round(total, 2),
        "build_cpu_s": round(c_build, 2), "power_up_cpu_s": round(c_up, 2), "power_up_runs": up,
        "cycles_runs": stats, "profile_cumulative_s": [(round(t, 2), name) for t, name in entries if t > 0.02 * total]},
        indent=1))


if __name__ == "__main__":
    main()
