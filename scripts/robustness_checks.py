"""The supplementary measurements behind docs/robustness.md (the main figures come from `mech2spice gate`).

    python scripts/robustness_checks.py reference [PARAMS]  # the preliminary study's setting: unloaded, 17 k/c/gamma
    python scripts/robustness_checks.py load       # the load-pair reduction vs the whole downstream gate
    python scripts/robustness_checks.py settle     # why reports/gate.md's cascade gives 0.907 at (0.67, 0.67)
    python scripts/robustness_checks.py subsets    # linearised margin/|gradient| at the limiting point by element group

Each prints JSON.  Deterministic (fixed seeds); run times are for the shared 2-core sandbox.
"""
from __future__ import annotations

import json
import sys
import time

import numpy as np

from mech2spice.backends import rk4
from mech2spice.experiments import characterise, tolerance
from mech2spice.physics import loaded, nor, params, sensitivity, spread, steady, steady_batch
from mech2spice.physics.envelope import Envelope

P = params.DEFAULT


def reference(spec: str | None = None, samples: int = 200, seed: int = 0) -> dict:
    """Unloaded single gate, spread on each DOF's k and c and each gamma only (17 draws), as in the
    preliminary study: yield (margin > 0 over the valid region) and 'nominal truth table kept'."""
    p = params.load_params(spec)
    m = nor.single_gate(p, 1.0, 1.0)                      # input drives at 1 F_R, scaled per point
    groups = np.array([0 if d.name.endswith("src") else int(d.name[1]) for d in m.drives])
    elems = [e for e in spread.elements(m) if e.kind in ("k", "c", "gamma")]
    levels, expect = loaded.input_grid()
    nominal = np.array([[1, a, b] for a in (0.5, 0.97) for b in (0.5, 0.97)])
    nom_expect = np.array([1, 0, 0, 0])
    eps = spread.draws(len(elems), samples, seed)
    out = {"params": p.name, "elements": len(elems), "samples": samples, "seed": seed, "rows": []}
    for sigma in (1e-5, 1e-4, 1e-3, 1e-2):
        margin_ok = table_ok = 0
        for i in range(samples):
            st = steady_batch.stack([spread.scaled(m, elems, 1 + sigma * eps[i])], groups, m.index("g0.C"))
            margin_ok += loaded.point_margins(steady_batch.roots(st, 0, levels), expect, p.u_r).min() > 0
            r = steady_batch.roots(st, 0, nominal)
            ok = r.stable & (loaded.band_margin(r.amp / p.u_r, nom_expect[r.point]) > 0)
            table_ok += all(ok[r.stable & (r.point == k)].all() and (r.stable & (r.point == k)).any()
                            for k in range(4))
        out["rows"].append({"sigma": sigma, "margin_yield": margin_ok / samples, "truth_table_kept": table_ok / samples})
    return out


def load(samples: int = 12, seed: int = 1, sigma: float = 1e-5) -> dict:
    """(a) gradient of the limiting point's margin with the load pair's insulator at rest ('pair') and with
    the whole downstream gate ('gate', two insulators: implicit-function theorem on the full model);
    (b) RK4 from rest with the whole downstream gate at each sample's worst point vs the 'pair' steady state."""
    grads = {}
    for kind in ("pair", "gate"):
        lg = loaded.build(P, kind)
        elems = spread.elements(lg.model, lg.block_dofs)
        m = loaded.at_inputs(lg, 0.67, 0.67)
        env = Envelope(m)
        F = env.forcing(np.array([d.amplitude for d in m.drives]))[:, 0]
        starts = [np.array([0.0167] + [0.0] * (env.slow.size - 1))] + \
                 [np.array([0.0167, s]) for s in np.linspace(-0.2, 0.2, 9)] * (env.slow.size > 1)
        st = [s for s in steady.steady_states(env, F, starts=starts) if s.stable]
        op = sensitivity.Operator(m, elems)
        y = op.polish(op.pack(st[0].A, st[0].s))
        g = op.amplitude_sensitivity(y, lg.gate.channel) / P.u_r / (loaded.BAND1[1] - loaded.BAND1[0])
        grads[kind] = dict(zip(sensitivity.element_names(elems), g))
    names = list(grads["pair"])
    a, b = np.array([grads["pair"][n] for n in names]), np.array([grads["gate"][n] for n in names])
    load_terms = [n for n in names if "load" in n]
    out = {"limiting_point": [0.67, 0.67], "gradient_norm": {"pair": float(np.linalg.norm(a)),
                                                             "gate": float(np.linalg.norm(b))},
           "relative_difference": float(np.linalg.norm(a - b) / np.linalg.norm(b)),
           "load_terms": {n: [grads["pair"][n], grads["gate"][n]] for n in load_terms}}
    sampler = tolerance.Sampler(P, samples, seed)
    res = sampler.run(sigma)
    picks = [(i, int(res["worst_point"][i])) for i in range(samples)]
    t0 = time.time()
    checks = tolerance.rk4_check(sampler, sigma, picks, periods=16000, load="gate")
    out["rk4_full_load"] = {"sigma": sigma, "samples": samples, "seed": seed, "wall_s": time.time() - t0,
                            "agree": sum((c["margin_rk4"] > 0) == (c["margin_steady"] > 0) for c in checks),
                            "checks": checks}
    return out


def settle() -> dict:
    """Gate 1 of the 3-gate chain vs a single gate at inputs (0.67, 0.67), RK4 from rest, and the slowest
    envelope eigenvalue of the single gate's steady state there."""
    marks = [1500, 3000, 4500, 6000, 9000, 12000, 20000]

    def amp(model, probes, steps=rk4.DEFAULT_STEPS_PER_PERIOD):
        run = rk4.integrate(model, 20000, steps_per_period=steps, probes=probes, blowup=1e3 * P.u_r)
        return np.abs(run.amp[:, :, 0]) / P.u_r

    a1 = amp(nor.single_gate(P, 0.67, 0.67), ["g0"])[:, 0]
    ac = amp(nor.chain(P, 3, 0.67, 0.67), ["g0", "g1", "g2"])
    a2 = amp(nor.single_gate(P, 0.67, 0.67), ["g0"], 160)[:, 0]
    states = characterise.steady_outputs(P, np.array([0.67]), np.array([0.67]))[0]
    env, F, ch = characterise.gate_forcing(P, np.array([0.67]), np.array([0.67]))
    ss = steady.steady_states(env, F[:, 0])
    return {"periods": marks,
            "single_gate": [float(a1[k - 1]) for k in marks],
            "chain_gate1": [float(ac[k - 1, 0]) for k in marks],
            "chain_gate2": [float(ac[k - 1, 1]) for k in marks],
            "chain_gate3": [float(ac[k - 1, 2]) for k in marks],
            "single_gate_160_steps": [float(a2[k - 1]) for k in marks],
            "steady_states": [{"amplitude": a, "stable": s} for a, s in states],
            "slowest_rate_per_s": [s.growth for s in ss],
            "time_constant_periods": [-1 / s.growth / P.period for s in ss]}


def subsets() -> dict:
    """margin / |gradient| at the limiting point over groups of elements: which spread sets the tolerance."""
    s = sensitivity.gate_sensitivity(P)
    names, g, m = s["elements"], np.asarray(s["limiting"]["gradient"]), s["limiting"]["margin"]
    groups = {
        "all (36 elements + omega)": names,
        "all but omega (what --spread draws)": [n for n in names if n != "omega"],
        "gate's own k, c, gamma (the preliminary study's 17)": [n for n in names if n.split()[0] in ("k", "c", "gamma")
                                                                and "load" not in n],
        "gate's own k, m, c, gamma, drive": [n for n in names if "load" not in n and not n.startswith(("spring", "dashpot"))
                                            and n != "omega"],
        "load pair only (k, m, c of load.G1s/G1d)": [n for n in names if n.split()[-1].startswith("load.")],
        "coupling springs and dashpots only": [n for n in names if n.startswith(("spring", "dashpot"))],
        "channel k_C only": ["k gate.C"],
    }
    out = {"limiting_point": s["limiting"]["inputs"], "margin": m, "groups": {}}
    for label, sel in groups.items():
        idx = [names.index(n) for n in sel]
        norm = float(np.linalg.norm(g[idx]))
        out["groups"][label] = {"elements": len(idx), "gradient_norm": norm, "margin_over_norm": m / norm,
                                "sigma_99_linear_one_point": m / norm / 2.326}
    return out


if __name__ == "__main__":
    what = sys.argv[1] if len(sys.argv) > 1 else ""
    funcs = {"reference": reference, "load": load, "settle": settle, "subsets": subsets}
    if what not in funcs:
        sys.exit(__doc__)
    t0 = time.time()
    res = funcs[what](*sys.argv[2:])
    res["wall_s"] = time.time() - t0
    print(json.dumps(res, indent=1, default=float))
