"""The processor Monte-Carlo's samples per core-second at two commits, in one run: the engine code of --before
(a git revision, unpacked into a temporary folder) against this tree's (or --after REV), each in its own
warm worker process, the same sample indices run by both in turn (which goes first alternating from sample to
sample), so that a change in the machine's load falls on both.  For a change of the compiled loops, which
cannot both live in one process (scripts/cpu_mc_speed.py compares settings within one).

    python scripts/cpu_mc_ab.py --before REV [--after REV] [--cycles 60] [--indices 0,1,2]
        [--params centered_fc2] [--spread 0.01] [--trim fcb] [--trim-residual 1e-4] [--seed 7]
        [--max-fanout 12] [--program programs/sieve.asm] [--out FILE]

Each worker builds the samples as `cpu montecarlo` does (experiments/mc_clocked.CpuMC, the processor's own
step, OpenBLAS on one thread), runs one warm-up cycle, then times each sample whole (model build, power-up,
cycles) in its own process CPU seconds.  Writes JSON: each way's CPU seconds, samples per core-second and
gate-block steps, their ratios, and per sample whether the cycle records and the verdict are equal and the
largest difference of any read amplitude (u_R) between the two.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def worker(a) -> None:
    """Serve sample indices read from stdin, one JSON line out per sample (the parent alternates workers)."""
    from mech2spice.experiments import montecarlo as mc
    from mech2spice.experiments.blas import set_blas_threads
    from mech2spice.experiments.mc_clocked import CpuMC
    from mech2spice.physics.params import load_params
    set_blas_threads(1)
    spec = mc.spec_of({"local": a.spread, "trim": a.trim, "trim_residual": a.trim_residual})
    mcx = CpuMC(a.program, a.cycles, load_params(a.params), "envelope", spec, a.seed, max_fanout=a.max_fanout)
    mcx._machine(0).step()                   # the compiled kernels loaded
    print(json.dumps({"ready": True}), flush=True)
    for line in sys.stdin:
        i = int(line)
        c0 = time.process_time()
        cpu = mcx._machine(i)
        cycles, amps, ok, reason = [], [], True, None
        try:
            for want in mcx.want:
                got = cpu.step()
                cycles.append(str(got))
                amps.append([abs(cpu.amps[p]) for p in cpu.probes])
                if any(getattr(got, f) != getattr(want, f) for f in mcx.compared(want)):
                    ok = False
                    break
        except Exception as e:               # an invalid bit or a divergence: a failed sample
            ok, reason = False, str(e).splitlines()[0]
        print(json.dumps({"i": i, "cpu_s": time.process_time() - c0, "block_steps": cpu.block_steps,
                          "cycles": cycles, "amps": amps, "pass": ok, "reason": reason,
                          "step": cpu.step_periods}), flush=True)


def unpack(rev: str, into: Path) -> Path:
    """The package and programs of git revision `rev` in a folder of their own."""
    tar = subprocess.run(["git", "-C", str(ROOT), "archive", rev, "mech2spice", "programs", "verilog"],
                         check=True, capture_output=True).stdout
    into.mkdir()
    subprocess.run(["tar", "-x", "-C", str(into)], input=tar, check=True)
    return into


def start(tree: Path, argv: list[str]) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(tree), "OMP_NUM_THREADS": "1"}
    p = subprocess.Popen([sys.executable, str(Path(__file__).resolve()), "--worker", *argv], cwd=tree, env=env,
                         stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    assert json.loads(p.stdout.readline())["ready"]
    return p


def ask(p: subprocess.Popen, i: int) -> dict:
    p.stdin.write(f"{i}\n")
    p.stdin.flush()
    return json.loads(p.stdout.readline())


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", help="git revision of the engine code 'before'")
    ap.add_argument("--after", default=None, help="git revision 'after' (default: this tree as it is)")
    ap.add_argument("--cycles", type=int, default=60)
    ap.add_argument("--indices", default="0,1,2")
    ap.add_argument("--params", default="centered_fc2")
    ap.add_argument("--spread", type=float, default=0.01)
    ap.add_argument("--trim", default="fcb")
    ap.add_argument("--trim-residual", type=float, default=1e-4)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--max-fanout", type=int, default=12)
    ap.add_argument("--program", default="programs/sieve.asm")
    ap.add_argument("--out", default=None)
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.worker:
        return worker(a)
    if not a.before:
        ap.error("--before REV is needed")
    argv = [f"--{k.replace('_', '-')}={v}" for k, v in vars(a).items()
            if k in ("cycles", "params", "spread", "trim", "trim_residual", "seed", "max_fanout", "program")]
    load0, t0 = os.getloadavg(), time.time()
    with tempfile.TemporaryDirectory() as tmp:
        trees = {"before": unpack(a.before, Path(tmp) / "before")}
        trees["after"] = unpack(a.after, Path(tmp) / "after") if a.after else ROOT
        procs = {k: start(t, argv) for k, t in trees.items()}
        runs = {k: [] for k in procs}
        indices = [int(x) for x in a.indices.split(",")]
        for n, i in enumerate(indices):
            for k in (list(procs) if n % 2 == 0 else list(procs)[::-1]):
                runs[k].append(ask(procs[k], i))
        for p in procs.values():
            p.stdin.close()
            p.wait()
    per = []
    for i, x, y in zip(indices, runs["before"], runs["after"]):
        dev = max((float(np.abs(np.subtract(u, v)).max()) for u, v in zip(x["amps"], y["amps"])), default=None)
        per.append({"i": i, "pass": [x["pass"], y["pass"]], "cycles_equal": x["cycles"] == y["cycles"],
                    "cycles_run": [len(x["cycles"]), len(y["cycles"])], "max_read_difference_uR": dev,
                    "cpu_s": [round(x["cpu_s"], 3), round(y["cpu_s"], 3)],
                    "block_steps": [x["block_steps"], y["block_steps"]], "reason": [x["reason"], y["reason"]]})
    total = {k: {"cpu_s": round(sum(r["cpu_s"] for r in v), 2),
                 "samples_per_core_s": len(v) / sum(r["cpu_s"] for r in v),
                 "block_steps": sum(r["block_steps"] for r in v), "step_periods": v[0]["step"]}
             for k, v in runs.items()}
    res = {"command": "python scripts/cpu_mc_ab.py " + " ".join(
               f"--{k.replace('_', '-')} {v}" for k, v in vars(a).items() if k not in ("out", "worker") and v is not None),
           "before": a.before, "after": a.after or "working tree", "cores": os.cpu_count(),
           "load_avg_before": load0, "load_avg_after": os.getloadavg(), "wall_s": round(time.time() - t0, 1),
           **total, "speed_ratio": total["after"]["samples_per_core_s"] / total["before"]["samples_per_core_s"],
           "work_ratio": total["before"]["block_steps"] / total["after"]["block_steps"],
           "all_cycles_equal": all(r["cycles_equal"] for r in per),
           "all_verdicts_equal": all(r["pass"][0] == r["pass"][1] for r in per), "per_sample": per}
    text = json.dumps(res, indent=1)
    if a.out:
        Path(a.out).write_text(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
