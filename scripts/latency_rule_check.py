"""The processor's latency freeze rules against runs that freeze nothing, on spread samples and on nominal blocks.

    python scripts/latency_rule_check.py [--cycles 30] [--indices 0,1,2,3] [--params centered_fc2]
        [--spread 0.01] [--trim fcb] [--trim-residual 1e-4] [--seed 7] [--max-fanout 12]
        [--nominal centered_fc2,default] [--out reports/latency_wake_rule.json]

Spread samples (built as `cpu montecarlo` builds them, experiments/mc_clocked.CpuMC): each runs `--cycles` sieve
cycles four ways at the processor's own step: a reference with latency 1e-6 u_R (nothing freezes that moves),
the hold rule (latency 0.1, `latency_calm=None`: a block and every input it records calm for LATENCY_HOLD), the
calm rule (latency 0.1, cpu/physical.LATENCY_CALM: its input channels calm for LATENCY_HOLD, its own channel for
LATENCY_CALM), both waking a frozen block once an input moved 0.1 u_R, and the calm rule with the wake threshold
(cpu/physical.LATENCY_WAKE: an input channel moved 0.05 u_R), the processor's default.  Each rule is compared with
the reference: the fields `cpu montecarlo` compares with
the ISS (write data and address only where the write is enabled), the latch and port bits read in another
band ("flips"), and the largest read difference of the bits in the same band (u_R); and its gate-block steps.

Nominal blocks: the same cycles at the processor's defaults with each rule against the full envelope (step 2, full
pauses, no latency, RK4: the yardstick of reports/fidelity.md), the largest read difference and whether every cycle
record is equal.  (Before issue 36's session 18 this reference kept the processor's settle and latency 0.1, so its
figures left out the latency's own error.)
"""
import argparse
import json
import os
import time

import numpy as np

from mech2spice.cpu.physical import LATENCY_CALM, LATENCY_WAKE, PhysicalCPU
from mech2spice.cpu.run import load_program, make_memory
from mech2spice.experiments.mc_clocked import add_sample_options, cpu_mc_of, sampled
from mech2spice.physics import spread
from mech2spice.physics.params import load_params

RULES = {"reference": dict(latency=1e-6, latency_calm=None, latency_wake=None),
         "hold": dict(latency=0.1, latency_calm=None, latency_wake=None),
         "calm": dict(latency=0.1, latency_calm=LATENCY_CALM, latency_wake=None),
         "wake": dict(latency=0.1, latency_calm=LATENCY_CALM, latency_wake=LATENCY_WAKE)}
COMPARED = [k for k in RULES if k != "reference"]
# the full envelope, reports/fidelity.md's yardstick: step 2, full pauses, every gate integrated, RK4
REFERENCE = dict(step=2.0, settle=None, latency=None, exponential=False, latency_calm=None, latency_wake=None)


def run(program: str, p, cycles: int, *, model_of=None, max_fanout=None, **settings) -> dict:
    """`cycles` cycles: each cycle's record and read amplitudes (u_R, in probe order), block-steps, CPU s."""
    c0 = time.process_time()
    cpu = PhysicalCPU(make_memory(load_program(program)), "envelope", p, power_up=False, max_fanout=max_fanout,
                      **settings)
    if model_of is not None:
        cpu.model = model_of(cpu.model)
    cpu.amps = cpu._reset()
    records, reads = [], []
    for _ in range(cycles):
        got = cpu.step()
        records.append({f: getattr(got, f) for f in ("pc", "phase", "raddr", "rdata", "we", "waddr", "wdata")})
        reads.append([cpu.amps[q] for q in cpu.probes])
    return {"records": records, "reads": np.array(reads), "block_steps": cpu.block_steps,
            "cpu_s": time.process_time() - c0, "probes": cpu.probes, "band": p.levels.band_of}


def compared(rec: dict) -> dict:
    """The fields cpu montecarlo compares with the ISS (mc_clocked.CpuMC.compared)."""
    return {k: v for k, v in rec.items() if rec["we"] or k not in ("wdata", "waddr")}


def against(ref: dict, got: dict) -> dict:
    bands = np.vectorize(ref["band"])
    same = bands(ref["reads"]) == bands(got["reads"])
    flips = [{"cycle": int(c), "bit": ref["probes"][q]} for c, q in zip(*np.nonzero(~same))]
    return {"block_steps": got["block_steps"], "cpu_s": round(got["cpu_s"], 2),
            "compared_fields_equal": all(compared(a) == compared(b) for a, b in zip(ref["records"], got["records"])),
            "records_equal": ref["records"] == got["records"], "bit_flips": len(flips), "flips": flips[:20],
            "max_read_difference_uR": float(np.abs(ref["reads"] - got["reads"])[same].max())}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cycles", type=int, default=30)
    ap.add_argument("--indices", default="0,1,2,3")
    add_sample_options(ap)
    ap.add_argument("--nominal", default="centered_fc2,default", help="blocks run against the full envelope "
                    "('' for none)")
    ap.add_argument("--out", default=None)
    a = ap.parse_args()
    t0, load0 = time.time(), os.getloadavg()
    mcx = cpu_mc_of(a, 1)
    p = mcx.p
    samples = []
    for i in [int(x) for x in a.indices.split(",") if x]:
        model_of = lambda nominal: sampled(nominal, spread.elements(nominal), mcx.spec, a.seed, i)[0]
        runs = {k: run(a.program, p, a.cycles, model_of=model_of, max_fanout=a.max_fanout, **s)
                for k, s in RULES.items()}
        samples.append({"index": i, "reference_block_steps": runs["reference"]["block_steps"],
                        **{k: against(runs["reference"], runs[k]) for k in COMPARED}})
        print(json.dumps({"sample": i, **{k: {x: samples[-1][k][x] for x in ("block_steps", "bit_flips",
              "max_read_difference_uR")} for k in COMPARED}}), flush=True)
    nominal = []
    for name in [x for x in a.nominal.split(",") if x]:
        q = load_params(name)
        ref = run(a.program, q, a.cycles, **REFERENCE)
        nominal.append({"params": name, **{k: against(ref, run(a.program, q, a.cycles, **RULES[k]))
                                           for k in COMPARED}})
        print(json.dumps({"nominal": name, **{k: {x: nominal[-1][k][x] for x in ("block_steps", "records_equal",
              "max_read_difference_uR")} for k in COMPARED}}), flush=True)
    res = {"command": "python scripts/latency_rule_check.py " + " ".join(
               f"--{k.replace('_', '-')} {v}" for k, v in vars(a).items() if k != "out"),
           "latency_calm": LATENCY_CALM, "latency_wake": LATENCY_WAKE, "cycles": a.cycles, "params": a.params, "spread": a.spread, "trim": a.trim,
           "trim_residual": a.trim_residual, "seed": a.seed, "max_fanout": a.max_fanout, "cores": os.cpu_count(),
           "load_avg_before": load0, "load_avg_after": os.getloadavg(), "wall_s": round(time.time() - t0, 1),
           "samples": samples, "nominal": nominal}
    text = json.dumps(res, indent=1)
    if a.out:
        with open(a.out, "w") as fh:
            fh.write(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
