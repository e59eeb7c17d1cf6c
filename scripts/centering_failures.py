"""Why a block's Monte-Carlo samples fail (docs/design.md, "Design centering"): per failing sample its worst
input point, how many points fail and how many of them lost every stable state (margin -1), and the
steady states at the worst point with their growth rates (1/time; > 0: unstable).

    python scripts/centering_failures.py BLOCK --spread 0.01 [--trim fc --residual 1e-4] [--samples N]
        [--per-band 15 --n-grid 4000]

The samples are experiments/tolerance.py's Sampler (the draws and trim of `gate --spread`, seed 0).
Prints one JSON object, with the wall time and the 1-minute load at the start and the end."""
from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np

from mech2spice.experiments import tolerance as tol
from mech2spice.physics import loaded, steady_batch
from mech2spice.physics.params import load_params


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
    a = ap.parse_args()
    t0, load0 = time.time(), os.getloadavg()[0]
    p = load_params(a.block)
    s = tol.Sampler(p, a.samples, a.seed, a.per_band, a.n_grid, a.trim, a.residual)
    fails = []
    for i in range(a.samples):
        st = steady_batch.stack([s.model(a.spread, i)], s.base.input_groups(), s.base.gate.channel)
        r = steady_batch.roots(st, 0, s.levels, a.n_grid)
        pm = loaded.point_margins(r, s.expect, p.u_r, p.levels)
        if pm.min() > 0:
            continue
        k = int(pm.argmin())
        at = r.point == k
        fails.append({"sample": i, "margin": float(pm.min()), "inputs": s.levels[k, 1:].round(4).tolist(),
                      "expect": int(s.expect[k]), "failing_points": int(np.sum(pm <= 0)),
                      "lost_points": int(np.sum(pm == -1)),
                      "states": [{"amp": float(x / p.u_r), "growth": float(g)} for x, g in zip(r.amp[at], r.growth[at])]})
    print(json.dumps({"block": a.block, "spread": a.spread, "trim": a.trim, "residual": a.residual,
                      "samples": a.samples, "seed": a.seed, "grid": [a.per_band, a.n_grid],
                      "yield": 1 - len(fails) / a.samples, "lost_stability": sum(f["margin"] == -1 for f in fails),
                      "fails": fails, "wall_s": time.time() - t0, "loadavg_1min": [load0, os.getloadavg()[0]]}, indent=1))


if __name__ == "__main__":
    main()
