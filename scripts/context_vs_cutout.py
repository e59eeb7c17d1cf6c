"""Check the context model's assumption against cut-outs of real processor gates.

    python scripts/context_vs_cutout.py SAMPLE [--cycles 3] [--params centered_fc2] [--spread 0.01 --trim fc
        --trim-residual 1e-4] [--seed 7] [--program programs/sieve.asm] [--min-fanout 2]

Runs sample SAMPLE's processor as `cpu montecarlo` does for --cycles cycles, then cuts out every NOR block
with at least --min-fanout loads (scripts/cpu_mc_diagnosis.local_gate: the sample's element values, all its
load pairs, upstream stand-ins at the network's input levels) twice: (a) the loads' insulators where the
network holds them, (b) where their logic states put them in the context model (physics/context.py:
insulator_positions at the block's decoded output and each load's decoded other input).  For each it takes
the stable output amplitude nearest the network's and prints JSON: per model the largest and the 95th
percentile error against the network's amplitude (u_R), the count within TOL (0.02 u_R), and the worst gates.
"""
import argparse
import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from cpu_mc_diagnosis import Diagnosis, local_gate            # noqa: E402

from mech2spice.experiments import montecarlo as mc          # noqa: E402
from mech2spice.experiments.mc_clocked import CpuMC          # noqa: E402
from mech2spice.physics import context, steady_batch         # noqa: E402
from mech2spice.physics.envelope import Envelope             # noqa: E402
from mech2spice.physics.params import load_params            # noqa: E402

TOL = 0.02


def nearest(p, model, groups, ch, x, a_net):
    st = steady_batch.stack([model], groups, ch)
    r = steady_batch.roots(st, 0, np.array([[1.0, *x]]))
    amps = r.amp[r.stable] / p.u_r
    return float(amps[np.argmin(np.abs(amps - a_net))]) if amps.size else float("nan")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("sample", type=int)
    ap.add_argument("--cycles", type=int, default=3)
    ap.add_argument("--params", default="centered_fc2")
    ap.add_argument("--program", default="programs/sieve.asm")
    ap.add_argument("--spread", type=float, default=0.01)
    ap.add_argument("--trim", default="fc")
    ap.add_argument("--trim-residual", type=float, default=1e-4)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--min-fanout", type=int, default=2)
    a = ap.parse_args()
    t0 = time.process_time()
    p = load_params(a.params)
    spec = mc.spec_of({"local": a.spread, "trim": a.trim, "trim_residual": a.trim_residual})
    job = CpuMC(a.program, a.cycles, p, "envelope", spec, a.seed)
    d = Diagnosis(job, a.sample)
    for _ in range(a.cycles):
        d.cpu.step()
    tab = context.insulator_positions(p)
    m, env = d.m, Envelope.of(d.m)
    s_net = dict(zip(env.slow, np.real(d.cpu.state[1][:, 0])))
    ins_of = {f: s for f, s, _ in m.quads}                       # gate oscillator -> its insulator
    block_of = {dof: (b, k) for b in m.design.gates for k, pair in enumerate(b.inputs) for dof in pair}
    values = {"rdata": d.cpu.rdata}
    rows, skipped = [], 0
    for b in m.design.gates:
        if d.fan[b.channel] < a.min_fanout:
            continue
        a_net = d.amp(b.channel)
        own = p.levels.band_of(a_net)
        x = [d.level(pin, values)[0] for pin in d.pins[b.name]]
        if own is None:
            skipped += 1
            continue
        s_ctx = {}
        for j in {j for i, j, _ in m.springs if i == b.channel} | {j for i, j, _ in m.dashpots if i == b.channel}:
            load, pin = block_of[j]
            other = p.levels.band_of(d.level(d.pins[load.name][1 - pin], values)[0])
            s_ctx[ins_of[j]] = tab[(own, other if other is not None else 0)]
        live = nearest(p, *local_gate(m, p, b, d.pins[b.name], None, None, s_net), x, a_net)
        ctx = nearest(p, *local_gate(m, p, b, d.pins[b.name], None, None, {**s_net, **s_ctx}), x, a_net)
        rows.append((b.name, d.fan[b.channel], a_net, live, ctx))
    err = lambda k: np.abs(np.array([r[k] for r in rows]) - np.array([r[2] for r in rows]))
    out = {"sample": a.sample, "cycles": a.cycles, "gates": len(rows), "skipped_invalid": skipped, "tol": TOL,
           "cpu_s": round(time.process_time() - t0, 1), "load_avg": os.getloadavg()[0]}
    for k, name in ((3, "cutout_network_insulators"), (4, "context_logic_state_insulators")):
        e = err(k)
        worst = np.argsort(-np.nan_to_num(e, nan=9))[:5]
        out[name] = {"max": float(np.nanmax(e)), "p95": float(np.nanpercentile(e, 95)), "within_tol": int((e <= TOL).sum()),
                     "no_stable_state": int(np.isnan(e).sum()),
                     "worst": [dict(gate=rows[w][0], fanout=rows[w][1], network=round(rows[w][2], 4),
                                    model=round(rows[w][k], 4)) for w in worst]}
    print(json.dumps(out))


if __name__ == "__main__":
    main()
