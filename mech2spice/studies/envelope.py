"""Envelope vs RK4, scene by scene; the envelope step on the adder; the enforced stability bound, measured
into envelope.json in the report directory (mech2spice/reports/envelope.py renders envelope.md and its PNGs).

Scenes (mech2spice/experiments/scenes.py): single gate (4 nominal inputs; 16 band-edge input pairs), the 3-gate
chain with its 00 -> 10 -> 00 switching transient and band-edge members (characterise.cascade), fan-out
2 and 3 (characterise.fanout_test), the 2-bit adder (all 16 inputs after 2900 periods at 0, as in
reports/adder.md) and the latch pulse sequence (characterise.latch_sequence).  Each runs on RK4 at 80
steps/period (the reference the issue names), on RK4 at 160 (to measure the reference's own error) and
on the envelope model; variants of the envelope equations (validate.VARIANTS) apportion what is left.
One section, `all` (~10 min on a 2-core machine; `--quick`: the default envelope step only and a short
step sweep, the same scenes).  `--cache DIR` keeps the RK4 runs as data files (_datafile.py) between runs.
"""
from __future__ import annotations

import platform
import time
from pathlib import Path

import numpy as np

from ..errors import Mech2SpiceError
from ..experiments import characterise as ch
from ..experiments import validate as V
from ..experiments import scenes as S
from ..backends import envelope
from ..physics.params import DEFAULT
from . import _datafile
from ._common import SANDBOX, conditions, log, timed

SECTIONS = ("all",)
MACHINE = f"{SANDBOX}, shared"
P = DEFAULT
STEPS = sorted({0.5, 2.0, envelope.DEFAULT_STEP})   # envelope steps per scene (periods); 2 was the default until 5c6b8d2
SWEEP = [0.25, 0.5, 1, 2, 4, 6, 8, 12]          # adder, through envelope.integrate
REFUSE = [16, 20, 24]                            # beyond the enforced bound: must be refused (24: unstable)
FREE = [6, 8, 10, 12, 16, 20, 21, 22, 23, 24, 26, 28, 32]   # adder, no bound check (validate.integrate_free)
# --quick: the default step per scene, and of the adder's step study what the text cites (1/4 and 4 periods'
# wall times, one step past the bound refused, the last finite step and the first to blow up)
QUICK = {"steps": [envelope.DEFAULT_STEP], "sweep": [0.25, 4, 8], "refuse": [16], "free": [12, 24, 28]}
STAB_AT = [0, 20, 100, 300, 1000, 2900, 2920, 3000, 3200, 3500, 4000, 5800]
DECIMALS = 3           # the figures' traces in u_R: 1/50 of a pixel (the latch's: 5, its difference panel is ~1e-3)


def cached(cache: Path | None, key: str, fn, valid):
    """fn()'s result, kept as CACHE/KEY.npz (a data file: _datafile.py) and read back from there later (no
    cache: just fn()).  The cache may hold anyone's files: one that is not a results file, or whose content
    fails `valid`, is refused in one line (delete it to measure again); a pickle there is never opened."""
    if cache is None:
        return fn()
    f = cache / f"{key}.npz"
    if f.exists():
        out = _datafile.load(f)
        if not valid(out):
            raise Mech2SpiceError(f"{f} does not hold what `report envelope` keeps there: delete it to measure again")
        return out
    out = fn()
    cache.mkdir(parents=True, exist_ok=True)
    _datafile.dump(f, out)
    return out


def _is_run(r) -> bool:
    """validate.run_rk4's or run_envelope's result: amplitudes (periods, probes, batch) and times."""
    return (isinstance(r, dict) and isinstance(r.get("amp"), np.ndarray) and r["amp"].ndim == 3
            and isinstance(r.get("t"), np.ndarray) and isinstance(r.get("wall_s"), float))


def _is_timed(r) -> bool:
    """timed(latch_sequence): (its dict, wall seconds)."""
    return isinstance(r, tuple) and len(r) == 2 and isinstance(r[0], dict) and isinstance(r[1], float)


# --- measurements --------------------------------------------------------------------------------
def scenes() -> list[S.Scene]:
    """The seven scenes: the gate (nominal, band edge), the chain, fan-out 2 and 3, the adder, the latch."""
    return [S.gate_scene(P, "nominal"), S.gate_scene(P, "edge"), S.chain_scene(P), S.fanout_scene(P, 2),
            S.fanout_scene(P, 3), S.adder_scene(P), S.latch_scene(P)]


def measure_scene(sc: S.Scene, cache, steps=STEPS) -> dict:
    """One scene on RK4 at 80 and 160 steps/period and on the envelope (`steps`, variants), compared."""
    log(f"{sc.name}: RK4 80 and 160 steps/period, {sc.periods} periods, batch {sc.stimulus.batch}")
    r80 = cached(cache, f"{sc.name}_rk4_80", lambda: V.run_rk4(sc, 80), _is_run)
    r160 = cached(cache, f"{sc.name}_rk4_160", lambda: V.run_rk4(sc, 160), _is_run)
    out = {"scene": sc.name, "description": sc.description, "oscillators": sc.model.n, "batch": sc.stimulus.batch,
           "periods": sc.periods, "bound": envelope.max_step_periods(sc.model),
           "wall_rk4_80": r80["wall_s"], "wall_rk4_160": r160["wall_s"],
           "rk4_80_vs_160": V.compare(sc, r160, r80), "env": {}, "variants": {}}
    steps = list(steps) + ([1.0] if sc.name == "latch" else [])   # clocked designs run at 1 period
    for step in steps:
        e = V.run_envelope(sc, step)
        out["env"][step] = {"wall_s": e["wall_s"], "vs80": V.compare(sc, r80, e), "vs160": V.compare(sc, r160, e),
                            "run": e}
        log(f"  envelope step {step:g}: {e['wall_s']:.2f} s, vs RK4-80 {_short(out['env'][step]['vs80'])}")
    vstep = 0.5 if sc.model.n < 60 else 1.0
    for name, cls in V.VARIANTS.items():
        e = V.run_envelope(sc, vstep, env=cls(sc.model))
        out["variants"][name] = {"step": vstep, "wall_s": e["wall_s"], "vs160": V.compare(sc, r160, e),
                                 "vs80": V.compare(sc, r80, e)}
        log(f"  variant {name:8s} step {vstep:g}: vs RK4-160 {_short(out['variants'][name]['vs160'])}")
    out["r80"], out["r160"] = r80, r160
    return out


def _short(c: dict) -> str:
    return f"amp {c['amp_err']:.2e} u_R, time {100 * c['time_err']:.2f} %, traj {c['traj_err']:.3f} u_R"


def latch_official(cache) -> dict:
    """characterise.latch_sequence on both backends; if its envelope path fails, the identical model, schedule
    and decoding through scenes.latch_scene / characterise.latch_decode (checked equal on RK4), with the error recorded."""
    log("latch: characterise.latch_sequence on rk4 and envelope")
    r = cached(cache, "latch_seq_rk4", lambda: timed(lambda: ch.latch_sequence(P, "rk4")), _is_timed)
    error = None
    try:
        e = timed(lambda: ch.latch_sequence(P, "envelope"))
    except Exception as ex:                       # noqa: BLE001 - reported, not hidden
        error = f"{type(ex).__name__}: {ex}"
        log(f"  characterise.latch_sequence(p, 'envelope') failed: {error}; using validate.latch_scene")
        sc = S.latch_scene(P)
        run = V.run_envelope(sc, 0.5)
        e = (ch.latch_decode(sc, run["amp"][1:, :, 0]), run["wall_s"])
    res = V.latch_compare(P, env_result=e[0], rk4_result=r[0])
    res["wall_rk4"], res["wall_env"], res["envelope_error"] = r[1], e[1], error
    return res


def adder_sweep(sc: S.Scene, r80: dict, r160: dict, quick: bool = False) -> dict:
    """The adder over envelope steps: the sweep, steps that must be refused, unchecked steps, eigenvalues."""
    sweep, refuse, free_steps = (QUICK["sweep"], QUICK["refuse"], QUICK["free"]) if quick else (SWEEP, REFUSE, FREE)
    log("adder: envelope step sweep")
    rows = []
    for step in sweep:
        e = V.run_envelope(sc, step)
        rows.append({"step": step, "wall_s": e["wall_s"], "vs80": V.compare(sc, r80, e),
                     "vs160": V.compare(sc, r160, e), "path": "envelope.integrate"})
        log(f"  step {step:g}: {e['wall_s']:.2f} s {_short(rows[-1]['vs80'])}")
    refused = []
    for step in refuse:
        try:
            V.run_envelope(sc, step)
            refused.append({"step": step, "refused": False})
        except Mech2SpiceError as ex:
            refused.append({"step": step, "refused": True, "message": str(ex)})
    free = []
    env = envelope.Envelope(sc.model)
    for step in free_steps:
        e = V.run_envelope(sc, step, env=env)
        ok = bool(np.isfinite(e["amp"]).all())
        row = {"step": step, "wall_s": e["wall_s"], "finite": ok, "path": "validate.integrate_free"}
        if ok:
            row["vs80"] = V.compare(sc, r80, e)
        else:
            bad = np.flatnonzero(~np.isfinite(e["amp"]).all(axis=(1, 2)))[0]
            row["blowup_period"] = float(e["t"][bad])
        free.append(row)
        log(f"  free step {step:g}: {'finite ' + _short(row['vs80']) if ok else 'BLEW UP at %.0f' % row['blowup_period']}")
    log("adder: linearised envelope eigenvalues along the trajectory")
    stab = V.stability_along(sc, STAB_AT)
    gate_stab = V.stability_along(S.gate_scene(P, "nominal"), [0, 100, 2500])
    chain_stab = V.stability_along(S.chain_scene(P, edges=False), [0, 200, 1500, 1700, 3000, 3200, 4500])
    env = envelope.Envelope(sc.model)
    return {"sweep": rows, "refused": refused, "free": free, "stability": stab, "bound": envelope.max_step_periods(sc.model),
            "gershgorin_rate": envelope.gershgorin_rate(env), "spectral_rate": envelope.spectral_rate(env),
            "rate_safety": envelope.RATE_SAFETY, "gate_stability": gate_stab, "chain_stability": chain_stab,
            "gate_bound": envelope.max_step_periods(S.gate_scene(P).model),
            "chain_bound": envelope.max_step_periods(S.chain_scene(P).model),
            "T": P.period}


def worst_state(adder: S.Scene, sw: dict) -> dict:
    """Eigenvalues at the state that limits the step most (for the stability-region plot) and the
    2-omega split of the insulators' forcing along the adder's trajectory."""
    worst = min(sw["stability"], key=lambda s: s["rk4_stable_step_periods"])
    env = envelope.Envelope(adder.model)
    st = V.trajectory_states(adder, 2.0, [worst["period"]])[worst["period"]]
    F = env.forcing(adder.stimulus.at(worst["period"] * P.period + 1e-9))
    eigs = [V.jacobian_eigs(env, st[0][:, b], st[1][:, b], st[2][:, b], F[:, b]) for b in range(16)]
    return {"eigs_worst": np.concatenate(eigs),
            "two_omega": {t: V.two_omega_split(adder.model, x[0])
                          for t, x in V.trajectory_states(adder, 2.0, [2920, 3100, 5800]).items()},
            "Zs2": abs(P.k_i - 4 * P.omega ** 2 * P.m_i + 2j * P.omega * P.c_i)}


def _trace(t, amp, every: int, window=(-np.inf, np.inf), decimals: int = DECIMALS) -> dict:
    """Times and amplitudes about every `every` periods inside `window` (periods), rounded for the figures."""
    k = max(1, round(every / (t[2] - t[1])))
    keep = (t >= window[0]) & (t <= window[1])
    return {"t": np.round(t[keep][::k], 2), "amp": np.round(amp[keep][::k], decimals)}


def traces(by: dict, latch: dict) -> dict:
    """What the figures draw, at about a pixel's resolution: the chain's transient (member 0) and band-edge
    member (3), the adder's 16 sums around the input change, the latch sequence's output on both engines."""
    E, chain, adder, lat = envelope.DEFAULT_STEP, by["chain3"], by["adder2"], by["latch"]
    hold = adder["periods"] // 2
    window = (hold - 100, hold + 1600)                  # the adder figure's x range
    seq = {k: _trace(np.arange(1.0, latch[k]["amplitude"].shape[0] + 1), latch[k]["amplitude"][:, :2], 16,
                     decimals=5) for k in ("rk4", "env")}
    return {"chain3": {name: _trace(r["t"], r["amp"][:, :, [0, 3]], 8)
                       for name, r in (("rk4_80", chain["r80"]), ("rk4_160", chain["r160"]),
                                       ("envelope", chain["env"][E]["run"]))},
            "adder2": {name: _trace(r["t"], r["amp"], 8, window)
                       for name, r in (("rk4_80", adder["r80"]), ("envelope", adder["env"][E]["run"]))},
            "latch": {"sequence": seq, "starts": latch["rk4"]["starts"],
                      **{name: _trace(r["t"], r["amp"][:, :1, :1], 16, decimals=5)
                         for name, r in (("rk4_80", lat["r80"]), ("envelope_1", lat["env"][1.0]["run"]))}}}


def _scores(c: dict) -> dict:
    """A comparison without its per-crossing and per-window lists (the text cites those at the default step only)."""
    return {k: v for k, v in c.items() if k not in ("crossings", "windows")}


def _scene_json(r: dict) -> dict:
    """A scene's comparisons without its runs (traces() keeps what the figures draw); steps as keys."""
    out = {k: v for k, v in r.items() if k not in ("r80", "r160")}
    out["env"] = {f"{st:g}": {k: v for k, v in e.items() if k != "run"} for st, e in r["env"].items()}
    out["rk4_80_vs_160"] = _scores(r["rk4_80_vs_160"])
    out["variants"] = {name: {**v, "vs80": _scores(v["vs80"]), "vs160": _scores(v["vs160"])}
                       for name, v in r["variants"].items()}
    return out


def _sweep_json(sw: dict) -> dict:
    """The step study without per-crossing lists; eigenvalues as real and imaginary parts; periods as keys."""
    eigs = sw["eigs_worst"]
    rows = lambda key: [{**r, **{c: _scores(r[c]) for c in ("vs80", "vs160") if c in r}} for r in sw[key]]  # noqa: E731
    return {**sw, "sweep": rows("sweep"), "free": rows("free"),
            "eigs_worst": {"re": np.round(eigs.real, 6), "im": np.round(eigs.imag, 6)},
            "two_omega": {str(t): v for t, v in sw["two_omega"].items()}}


def settings() -> dict:
    """The engine's constants and the criteria the text states."""
    return {"default_step": envelope.DEFAULT_STEP, "rk4_stability": envelope.RK4_STABILITY, "amp_tol": V.AMP_TOL,
            "time_tol": V.TIME_TOL, "avg": V.AVG, "mid": S.MID}


def measure(section: str = "all", quick: bool = False, cache=None) -> dict:
    """Every scene (RK4 runs kept in `cache` if given), the latch sequence and the adder's step study."""
    cache = Path(cache) if cache else None
    t_start = time.perf_counter()
    results = [measure_scene(sc, cache, QUICK["steps"] if quick else STEPS) for sc in scenes()]
    by = {r["scene"]: r for r in results}
    latch = latch_official(cache)
    adder = scenes()[5]
    sw = adder_sweep(adder, by["adder2"]["r80"], by["adder2"]["r160"], quick)
    sw.update(worst_state(adder, sw))
    sw["total_s"] = time.perf_counter() - t_start
    return {"scenes": [_scene_json(r) for r in results], "traces": traces(by, latch),
            "latch": {k: v for k, v in latch.items() if k not in ("rk4", "env")}, "sweep": _sweep_json(sw),
            "settings": settings(), "quick": quick, "machine": MACHINE, "python": platform.python_version(),
            "total_s": sw["total_s"], "conditions": conditions()}
