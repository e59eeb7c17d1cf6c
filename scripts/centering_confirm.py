"""Monte-Carlo confirmation of a centred block (docs/design.md, "Design centering"): the loaded gate's yield
over the valid input region (experiments/tolerance.py's Sampler, the grid `gate --spread` uses) under a
relative spread, optionally trimmed as physics/spread.py's trim model does (each oscillating DOF of the
block: total k/m, with fc also c/m, set to nominal x (1 + residual z)).

    python scripts/centering_confirm.py BLOCK.json --spread 0.01 [--trim fc --residual 1e-4] [--samples N] [--why]

Prints one JSON object: yield, its 95 % Wilson interval, with --tolerance the largest spread at 99 %
yield (same trim), the failing samples' worst input points, with --why per failing sample how many points
fail, how many lost every stable state (margin -1) and the steady states at its worst point with their
growth rates (1/time; > 0: unstable), wall time and the 1-minute load at the start and the end (the
machine is shared)."""
from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np

from mech2spice.experiments import tolerance as tol
from mech2spice.physics import loaded, steady_batch
from mech2spice.physics.params import load_params


def why(s: tol.Sampler, spread: float, sample: int) -> dict:
    """Sample `sample`'s failure: its worst point, how many points fail or lost every state, the states there."""
    st = steady_batch.stack([s.model(spread, sample)], s.base.input_groups(), s.base.gate.channel)
    r = steady_batch.roots(st, 0, s.levels, s.n_grid)
    pm = loaded.point_margins(r, s.expect, s.p.u_r, s.p.levels)
    k = int(pm.argmin())
    at = r.point == k
    return {"sample": sample, "margin": float(pm.min()), "inputs": s.levels[k, 1:].round(4).tolist(),
            "expect": int(s.expect[k]), "failing_points": int(np.sum(pm <= 0)), "lost_points": int(np.sum(pm == -1)),
            "states": [{"amp": float(x / s.p.u_r), "growth": float(g)} for x, g in zip(r.amp[at], r.growth[at])]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("block")
    ap.add_argument("--spread", type=float, required=True)
    ap.add_argument("--trim", choices=("none", "f", "fc"), default="none")
    ap.add_argument("--residual", type=float, default=0.0)
    ap.add_argument("--samples", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--per-band", type=int, default=15)
    ap.add_argument("--n-grid", type=int, default=4000)
    ap.add_argument("--only", metavar="KIND", help="spread only elements of this kind (k, m, c, spring, dashpot, "
                                                  "gamma, drive): which kind fails the block")
    ap.add_argument("--why", action="store_true", help="per failing sample: where and how it fails")
    ap.add_argument("--tolerance", action="store_true",
                    help="also the largest spread with 99 %% yield (tolerance.py's bisection, same draws)")
    a = ap.parse_args()
    t0, load0 = time.time(), os.getloadavg()[0]
    p = load_params(a.block)
    s = tol.Sampler(p, a.samples, a.seed, a.per_band, a.n_grid, a.trim, a.residual)
    if a.only:
        s.eps[:, [e.kind != a.only for e in s.elements]] = 0.0
    res = s.run(a.spread)
    worst = res["margins"]
    where = [s.levels[k, 1:].tolist() for k in res["worst_point"]]
    k = int(np.sum(worst > 0))
    extra = {"tolerance": tol.tolerance(s, lo=a.spread / 100, hi=min(1.0, a.spread * 10))} if a.tolerance else {}
    if a.why:
        extra["fails"] = [why(s, a.spread, i) for i in np.flatnonzero(worst <= 0)]
        extra["lost_stability"] = sum(f["margin"] == -1 for f in extra["fails"])
    print(json.dumps({"block": a.block, "spread": a.spread, "only": a.only, "trim": a.trim, "residual": a.residual,
                      "samples": a.samples, "seed": a.seed, "grid": [a.per_band, a.n_grid],
                      "nominal_margin": float(s.margins(s.base.model).min()), "yield": k / a.samples,
                      "yield_ci95": list(tol.wilson(k, a.samples)),
                      "margin_quantiles": {q: float(np.percentile(worst, q)) for q in (1, 5, 50)},
                      "failing_points": [w for w, m in zip(where, worst) if m <= 0][:20],
                      **extra, "wall_s": time.time() - t0, "loadavg_1min": [load0, os.getloadavg()[0]]}, indent=1))


if __name__ == "__main__":
    main()
