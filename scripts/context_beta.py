"""The gate in its network context (physics/context.py) under spread: margin distribution and beta per fan-out.

    python scripts/context_beta.py [--params centered_fc2] [--spread 0.01] [--trim fc] [--trim-residual 1e-4]
        [--samples 40] [--seed 7] [--per-band 6] [--without KIND ...] --config N:U ...

`--without KIND ...` leaves those element kinds (k, m, c, spring, dashpot, gamma, drive) unspread: run once per
kind, it says which kind's spread the failures and the margins' spread come from.  `--limits` adds, per config,
each failing draw's margin with one kind at a time left unspread (`limits`: draw -> kind -> margin): a kind whose
removal gives a positive margin is one that draw fails by.  `--balance-point S`: trim fcb balances the pairs at
insulator position S instead of the block's s(0,0) (the choice of s(0,0), measured).

Each --config N:U is a gate with N output load pairs and U other load pairs on each of its two drivers.  Every
sample spreads the gate's, the loads' and the links' elements (experiments/montecarlo.SpreadSpec: the draws of
`cpu montecarlo`'s spec, trimmed the same way), then holds every load's insulator where its logic state puts it
(context.insulator_positions): the loads' other inputs all '0' or all '1' (both are run; the worse counts per
sample), the drivers' other loads at (1, other).  The margin is the smallest band margin over the input grid
(per_band levels per band, both inputs), judged with the loads held for NOR's output at each point.
Prints one JSON line per config: nominal margin, failures (margin < 0) with the Wilson interval, the margins'
mean and standard deviation, `beta_failures` = Phi^-1(1 - failures / samples) with its range from the Wilson
interval (with no failure only its lower end is known), and `beta_gaussian` = mean / std over the samples
that kept a state near the band (margin > -0.5): the worst-case distance if the margin were Gaussian, which the
failing samples (lost or jumped states, margin -1 and below) are not.
"""
import argparse
import json
import os
import time
from dataclasses import replace

import numpy as np

from mech2spice.experiments import montecarlo as mc
from mech2spice.experiments.tolerance import wilson
from mech2spice.physics import context, spread
from mech2spice.physics.params import load_params


def beta_failures(fails: int, n: int) -> dict:
    """Phi^-1(1 - p) at the failure fraction and at the ends of its Wilson interval (None where p = 0)."""
    from scipy.stats import norm
    lo, hi = wilson(fails, n)
    z = lambda q: float(norm.isf(q)) if 0 < q < 1 else None
    return {"beta_failures": z(fails / n), "beta_failures_ci95": [z(hi), z(lo)]}


def limits(cg, elems, held, spec, failing, seed, per_band) -> dict:
    """Per failing draw: its margin with each element kind left unspread in turn (the rest as in `spec`)."""
    out = {}
    for i in failing:
        row = {}
        for kind in mc.KINDS:
            one = replace(spec, local={**spec.local, kind: 0.0})
            sm, _ = one.sample(cg.model, elems, seed, i)
            row[kind] = round(float(context.margins(cg, held(sm, 0) + held(sm, 1), per_band).min()), 4)
        out[str(i)] = row
    return out


def one_config(p, spec, tab, n, u, samples, seed, per_band, with_limits=False):
    cg = context.build(p, n, (u, u))
    elems = spread.elements(cg.model, cg.block_dofs)
    held = lambda model, other: [context.held(cg, model, tab[(o, other)], tab[(1, other)]) for o in (0, 1)]
    nominal = min(float(context.margins(cg, held(cg.model, other), per_band)[0]) for other in (0, 1))
    m = np.empty((samples, 2))
    for i in range(samples):
        sm, _ = spec.sample(cg.model, elems, seed, i)
        m[i] = context.margins(cg, held(sm, 0) + held(sm, 1), per_band)
    worst = m.min(axis=1)
    fails = int((worst < 0).sum())
    extra = {"limits": limits(cg, elems, held, spec, np.flatnonzero(worst < 0).tolist(), seed, per_band)} \
        if with_limits else {}
    ok = worst[worst > -0.5]               # a lost or jumped state (-1 or far below) is no Gaussian tail
    return {"loads": n, "driver_loads": u, "nominal_margin": nominal, "samples": samples, "failures": fails,
            "fail_ci95": list(wilson(fails, samples)), "mean": float(worst.mean()), "std": float(worst.std(ddof=1)),
            "beta_gaussian": float(ok.mean() / ok.std(ddof=1)) if ok.size > 2 else None,
            **beta_failures(fails, samples),
            "failures_other0": int((m[:, 0] < 0).sum()), "failures_other1": int((m[:, 1] < 0).sum()),
            "elements": len(elems), **extra}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--params", default="centered_fc2")
    ap.add_argument("--spread", type=float, default=0.01)
    ap.add_argument("--trim", default="fc")
    ap.add_argument("--trim-residual", type=float, default=1e-4)
    ap.add_argument("--samples", type=int, default=40)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--per-band", type=int, default=6)
    ap.add_argument("--config", nargs="+", default=["1:0", "4:3", "12:11"])
    ap.add_argument("--without", nargs="*", default=[], choices=mc.KINDS, metavar="KIND")
    ap.add_argument("--limits", action="store_true")
    ap.add_argument("--balance-point", type=float, default=None)
    a = ap.parse_args()
    p = load_params(a.params)
    if a.balance_point is not None:
        from mech2spice.physics.loaded import digest
        context._BALANCE_POINT[digest(p)] = a.balance_point
    local = {"*": a.spread, **{kind: 0.0 for kind in a.without}}
    spec = mc.spec_of({"local": local, "trim": a.trim, "trim_residual": a.trim_residual})
    tab = context.insulator_positions(p)
    print(json.dumps({"params": a.params, "spread": a.spread, "without": a.without, "trim": a.trim,
                      "balance_point": context.balance_point(p) if a.trim == "fcb" else None,
                      "trim_residual": a.trim_residual,
                      "insulator_positions": {f"{k[0]}{k[1]}": v for k, v in tab.items()}}), flush=True)
    for c in a.config:
        n, u = map(int, c.split(":"))
        t0 = time.process_time()
        rec = one_config(p, spec, tab, n, u, a.samples, a.seed, a.per_band, a.limits)
        rec.update(cpu_s=round(time.process_time() - t0, 1), load_avg=os.getloadavg()[0])
        print(json.dumps(rec), flush=True)


if __name__ == "__main__":
    main()
