"""Where the envelope model agrees with RK4, measured scene by scene, and why it differs where it does.

Scenes run on both backends from rest and are compared on settled amplitudes (AMP_TOL) and switching
times (TIME_TOL); the variants Envelope2w, EnvelopeA2, Envelope2wA2 put back what the envelope equations
drop.  The criteria and the variants' equations: docs/physics.md, section "What the envelope equations drop".
"""
from __future__ import annotations

import math
import time

import numpy as np

from ..backends import envelope, rk4
from ..compare import AVG
from ..physics.model import MechModel
from ..physics.params import DEFAULT, GateParams
from ..physics.steady import Envelope2w   # the steady-state solver's correction too
from . import characterise as ch
from .scenes import MID, Scene

AMP_TOL = 0.02          # u_R, settled amplitudes
TIME_TOL = 0.10         # relative, threshold-crossing times


# --- running ---------------------------------------------------------------------------------
def run_rk4(scene: Scene, steps: int | None = None) -> dict:
    """The scene on RK4 at `steps` per period (default 80): amplitudes (P, probes, B) in u_R, the time each
    sample stands for (periods), and wall time."""
    t0 = time.perf_counter()
    steps = int(steps or rk4.DEFAULT_STEPS_PER_PERIOD)
    r = rk4.integrate(scene.model, scene.periods, steps_per_period=steps, stimulus=scene.stimulus,
                      probes=scene.probes)
    amp = np.abs(r.amp) / scene.model.params.u_r
    t = np.arange(scene.periods) + 0.5             # each sample demodulates one whole period
    return _ran(amp, t, t0, "rk4", steps)


def run_envelope(scene: Scene, step: float | None = None, env: envelope.Envelope | None = None) -> dict:
    """The scene on the envelope model with `step` periods (default envelope.DEFAULT_STEP); `env` runs a
    variant Envelope (this module's classes) instead.  Returns what run_rk4 does, from rest."""
    t0 = time.perf_counter()
    step = float(step or envelope.DEFAULT_STEP)
    if env is None:
        r = envelope.integrate(scene.model, scene.periods, step_periods=step, stimulus=scene.stimulus,
                               probes=scene.probes)
        a = np.abs(r.amp) / scene.model.params.u_r
        per = max(1, int(round(step)))
        amp = a[per - 1::per]                        # integrate() repeats the value over each chunk
        t = per * (np.arange(amp.shape[0]) + 1.0)
    else:
        amp, t = integrate_free(env, scene, step)
        if step < 1:                                 # keep one sample per period, like integrate()
            k = int(round(1 / step))
            amp, t = amp[k - 1::k], t[k - 1::k]
    amp = np.concatenate([np.zeros((1,) + amp.shape[1:]), amp])      # every scene starts from rest
    t = np.concatenate([[0.0], t])
    return _ran(amp, t, t0, "envelope", step)


def _ran(amp, t, t0: float, backend: str, step) -> dict:
    return {"amp": amp, "t": t, "wall_s": time.perf_counter() - t0, "backend": backend, "step": step}


def integrate_free(env: envelope.Envelope, scene: Scene, step: float, blowup: float = 50.0):
    """envelope.integrate's scheme with any Envelope (sub)class and any step (periods, no stability
    check); forcing is taken at each step's start.  Returns (|A| per step in u_R, step-end times in
    periods).  Stops early (amplitudes NaN from there on) once |A| exceeds `blowup` u_R."""
    p = scene.model.params
    T = env.model.period
    h = step * T
    nsteps = int(math.ceil(scene.periods / step - 1e-9))
    B = scene.stimulus.batch
    nf, ns = env.fast.size, env.slow.size
    A, s, sd = np.zeros((nf, B), complex), np.zeros((ns, B)), np.zeros((ns, B))
    pos = {d: k for k, d in enumerate(env.fast)}
    prow = np.array([pos[scene.model.probes[n]] for n in scene.probes], int)
    out = np.full((nsteps, len(prow), B), np.nan)
    with np.errstate(over="ignore", invalid="ignore"):
        for j in range(nsteps):
            F = env.forcing(scene.stimulus.at(j * h + 1e-9 * h))
            A, s, sd = envelope.rk4_step(env, A, s, sd, F, h)
            mag = np.abs(A)
            out[j] = mag[prow] / p.u_r
            if not np.all(np.isfinite(mag)) or mag.max() > blowup * p.u_r:
                break
    return out, step * (np.arange(nsteps) + 1.0)


class EnvelopeA2(envelope.Envelope):
    """envelope.Envelope keeping M A'' to next order in the slow time, see docs/physics.md."""

    def __init__(self, model: MechModel):
        super().__init__(model)
        self.mf = model.arrays["mass"][self.fast][:, None]

    def rhs(self, A, s, sd, F):
        """(A', s', s'') with A' corrected for M A'' to next order in the slow time."""
        R = self.residual_fast(A, s, F)
        Ad0 = self.solve_rate(R)
        dR = -(self.Z0 @ Ad0) - (self.G @ s) * Ad0 - (self.G @ sd) * A
        Ad = self.solve_rate(R - self.mf * self.solve_rate(dR))
        sdd = (-(self.Ks @ s) - self.Cs @ sd + self.slow_force(A)) / self.ms[:, None]
        return Ad, sd, sdd


class Envelope2wA2(Envelope2w, EnvelopeA2):
    """Both corrections (EnvelopeA2.rhs calls Envelope2w.residual_fast through the MRO)."""


VARIANTS = {"envelope": envelope.Envelope, "+2w": Envelope2w, "+A''": EnvelopeA2, "+2w+A''": Envelope2wA2}


# --- comparing -------------------------------------------------------------------------------
GRAZE = 5.0    # periods: a series back across MID within this has touched the threshold, not switched


def crossings(a: np.ndarray, t: np.ndarray, start: float, stop: float) -> list[float]:
    """Times (periods after `start`) at which the series a(t) crosses MID within (start, stop]; a pair of
    crossings less than GRAZE apart (the series grazing the threshold) counts as none, so that a graze in
    one engine that the other just misses is not a disagreement."""
    keep = (t > start) & (t <= stop) & np.isfinite(a)
    a, t = a[keep] - MID, t[keep]
    if a.size < 2:
        return []
    k = np.flatnonzero(np.sign(a[:-1]) * np.sign(a[1:]) < 0)
    times = [float(t[i] + (t[i + 1] - t[i]) * a[i] / (a[i] - a[i + 1]) - start) for i in k]
    out: list[float] = []
    for x in times:
        if out and x - out[-1] < GRAZE:
            out.pop()
        else:
            out.append(x)
    return out


def settled(a: np.ndarray, t: np.ndarray, end: float) -> np.ndarray:
    """Mean over the AVG periods before `end` (probes, B); the last sample at or before `end` when the
    samples are sparser than that (envelope steps longer than AVG periods)."""
    keep = (t > end - AVG) & (t <= end)
    if not keep.any():
        keep = t == t[t <= end].max()
    return a[keep].mean(axis=0)


def compare(scene: Scene, ref: dict, test: dict) -> dict:
    """Settled-amplitude and switching-time agreement of `test` against `ref` (both from run())."""
    wins = []
    for w in scene.windows:
        d = settled(test["amp"], test["t"], w) - settled(ref["amp"], ref["t"], w)
        wins.append({"end": w, "max_abs_diff": float(np.nanmax(np.abs(d))) if np.all(np.isfinite(d)) else math.inf,
                     "ref": settled(ref["amp"], ref["t"], w).tolist(),
                     "test": settled(test["amp"], test["t"], w).tolist()})
    amp_err = max(x["max_abs_diff"] for x in wins)
    cross = []
    bounds = list(scene.events) + [scene.periods]
    for e, (t0, t1) in enumerate(zip(bounds[:-1], bounds[1:])):
        for j, probe in enumerate(scene.probes):
            for b, label in enumerate(scene.members):
                cr = crossings(ref["amp"][:, j, b], ref["t"], t0, t1)
                ct = crossings(test["amp"][:, j, b], test["t"], t0, t1)
                if not cr and not ct:
                    continue
                row = {"event": t0, "probe": probe, "member": label, "n_ref": len(cr), "n_test": len(ct),
                       "first_ref": cr[0] if cr else None, "first_test": ct[0] if ct else None,
                       "last_ref": cr[-1] if cr else None, "last_test": ct[-1] if ct else None}
                if cr and ct:
                    row["first_rel"] = abs(ct[0] - cr[0]) / cr[0]
                    row["last_rel"] = abs(ct[-1] - cr[-1]) / cr[-1]
                else:
                    row["first_rel"] = row["last_rel"] = math.inf
                cross.append(row)
    time_err = max((max(c["first_rel"], c["last_rel"]) for c in cross), default=0.0)
    # trajectory difference on the common period grid (envelope samples interpolated)
    traj = _trajectory_diff(ref, test)
    return {"amp_err": amp_err, "windows": wins, "time_err": time_err, "crossings": cross,
            "n_crossings": len(cross), "crossing_count_mismatch": sum(c["n_ref"] != c["n_test"] for c in cross),
            "traj_err": traj, "amp_ok": amp_err <= AMP_TOL, "time_ok": time_err <= TIME_TOL}


def _trajectory_diff(ref: dict, test: dict) -> float:
    a, t = test["amp"], test["t"]
    worst = 0.0
    for j in range(a.shape[1]):
        for b in range(a.shape[2]):
            ok = np.isfinite(a[:, j, b])
            if not ok.all():
                return math.inf
            y = np.interp(ref["t"], t, a[:, j, b])
            worst = max(worst, float(np.abs(y - ref["amp"][:, j, b]).max()))
    return worst


def scene_table_row(name: str, cmp: dict) -> dict:
    """One summary row of a scene's compare() result: errors, crossing counts, pass."""
    return {"scene": name, "amp_err": cmp["amp_err"], "time_err": cmp["time_err"], "traj_err": cmp["traj_err"],
            "n_crossings": cmp["n_crossings"], "count_mismatch": cmp["crossing_count_mismatch"],
            "pass": bool(cmp["amp_ok"] and cmp["time_ok"] and cmp["crossing_count_mismatch"] == 0)}


# --- the latch --------------------------------------------------------------------------------
def latch_compare(p: GateParams = DEFAULT, env_result: dict | None = None, rk4_result: dict | None = None) -> dict:
    """characterise.latch_sequence on RK4 and on the envelope (its default step, 1/2 period)."""
    t0 = time.perf_counter()
    r = rk4_result or ch.latch_sequence(p, "rk4")
    w_r = time.perf_counter() - t0
    t0 = time.perf_counter()
    e = env_result or ch.latch_sequence(p, "envelope")
    w_e = time.perf_counter() - t0
    dec_r = [d["logic"] for d in r["decoded"]]
    dec_e = [d["logic"] for d in e["decoded"]]
    out_diff = max(abs(a["output"] - b["output"]) for a, b in zip(r["decoded"], e["decoded"]))
    rel = [abs(a - b) / a for a, b in zip(r["output_delays"], e["output_delays"])]
    return {"decoded_rk4": dec_r, "decoded_env": dec_e, "identical": dec_r == dec_e,
            "max_output_diff": out_diff, "delays_rk4": r["output_delays"], "delays_env": e["output_delays"],
            "delay_rel": rel, "traj_err": float(np.abs(r["amplitude"] - e["amplitude"]).max()),
            "wall_rk4": w_r, "wall_env": w_e, "rk4": r, "env": e,
            "amp_ok": out_diff <= AMP_TOL, "time_ok": max(rel) <= TIME_TOL}


# --- stability of the envelope integrator ----------------------------------------------------
def rk4_growth(z: np.ndarray) -> np.ndarray:
    """|R(z)| of classical RK4, R(z) = 1 + z + z^2/2 + z^3/6 + z^4/24."""
    return np.abs(1 + z + z ** 2 / 2 + z ** 3 / 6 + z ** 4 / 24)


def rk4_stable_step(lams: np.ndarray) -> float:
    """Largest h with |R(h lambda)| <= 1 for every eigenvalue (those with Re > -1e-9 are skipped:
    a neutral or growing mode of the equations is not a property of the step)."""
    lams = np.asarray(lams)
    lams = lams[lams.real < -1e-9]
    if lams.size == 0:
        return math.inf
    # along each ray h * lambda, the first h where |R| > 1: scan on a grid, then bisect (vectorised)
    x = np.linspace(0, 4.0, 4001)[1:]                      # |h lambda| up to 4 (RK4's region ends < 2.8)
    bad = rk4_growth(x[None, :] * (lams / np.abs(lams))[:, None]) > 1 + 1e-12
    has = bad.any(axis=1)
    if not has.any():
        return math.inf
    lams, bad = lams[has], bad[has]
    first = bad.argmax(axis=1)
    hi = x[first] / np.abs(lams)
    lo = np.where(first > 0, x[np.maximum(first - 1, 0)], 0.0) / np.abs(lams)
    for _ in range(50):
        mid = (lo + hi) / 2
        ok = rk4_growth(mid * lams) <= 1 + 1e-12
        lo, hi = np.where(ok, mid, lo), np.where(ok, hi, mid)
    return float(lo.min())


def jacobian(env: envelope.Envelope, y: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Envelope.jacobian's central differences, every column in one batched rhs call."""
    n = y.size
    scale = np.maximum(np.abs(y), 1e-6 * max(np.abs(y).max(), 1e-12))
    e = 1e-6 * scale
    Y = np.concatenate([y[:, None] + np.diag(e), y[:, None] - np.diag(e)], axis=1)
    A, s, sd = env.unpack(Y)
    Ad, sd_, sdd = env.rhs(A, s, sd, np.asarray(F)[:, None])
    R = np.concatenate([Ad.real, Ad.imag, sd_, sdd])
    return (R[:, :n] - R[:, n:]) / (2 * e)


def jacobian_eigs(env: envelope.Envelope, A: np.ndarray, s: np.ndarray, sd: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Eigenvalues of the envelope Jacobian at the state (A, s, sd) under forcing F."""
    return np.linalg.eigvals(jacobian(env, env.pack(A, s, sd), F))


def stability_along(scene: Scene, at: list[int], step: float = 2.0) -> list[dict]:
    """At each period in `at`: the largest |eigenvalue| of the linearised envelope equations and the largest
    RK4 step (periods) that keeps every decaying mode stable, worst over the batch members."""
    env = envelope.Envelope(scene.model)
    T = env.model.period
    states = trajectory_states(scene, step, at)
    rows = []
    for t in at:
        A, s, sd = states[t]
        F = env.forcing(scene.stimulus.at(t * T + 1e-9 * T))
        rad, hstar, growth = 0.0, math.inf, -math.inf
        for b in range(A.shape[1]):
            ev = jacobian_eigs(env, A[:, b], s[:, b], sd[:, b], F[:, b])
            rad = max(rad, float(np.abs(ev).max()))
            hstar = min(hstar, rk4_stable_step(ev) / T)
            growth = max(growth, float(ev.real.max()))
        rows.append({"period": t, "max_abs_eig": rad, "rk4_stable_step_periods": hstar, "max_growth": growth})
    return rows


def trajectory_states(scene: Scene, step: float, at: list[int]):
    """Envelope states (A, s, sd) of every batch member at the given periods (multiples of step)."""
    env = envelope.Envelope(scene.model)
    B = scene.stimulus.batch
    state = (np.zeros((env.fast.size, B), complex), np.zeros((env.slow.size, B)), np.zeros((env.slow.size, B)))
    out, done = {}, 0
    for t in sorted(at):
        if t > done:
            r = envelope.integrate(scene.model, t - done, step_periods=step, stimulus=scene.stimulus,
                                   state=state, start_period=done, probes=scene.probes)
            state = r.state
            done = t
        out[t] = tuple(x.copy() for x in state)
    return out


def two_omega_split(model: MechModel, A: np.ndarray) -> dict:
    """How much 2-omega forcing each insulator gets, from its channel and from its gate pairs, for envelope
    states A (n_fast, B): per slow DOF  sum over couplings gamma A_f^2  (the force's 2-omega phasor is
    minus half of it).  'pair_cancellation' = |sum over gates| / sum over gates |gamma A_g^2|: 0 when every
    pair's two gates are equal and 90 degrees apart."""
    env = envelope.Envelope(model)
    a = model.arrays
    pos_f = {d: k for k, d in enumerate(env.fast)}
    pos_s = {d: k for k, d in enumerate(env.slow)}
    ns, B = env.slow.size, A.shape[1]
    ch_sum = np.zeros((ns, B), complex)
    g_sum = np.zeros((ns, B), complex)
    g_abs = np.zeros((ns, B))
    for f, s, g in zip(a["quad_fast"], a["quad_slow"], a["quad_gamma"]):
        term = g * A[pos_f[f]] ** 2
        if g < 0:                                   # channel-insulator coupling (-gamma_IC)
            ch_sum[pos_s[s]] += term
        else:
            g_sum[pos_s[s]] += term
            g_abs[pos_s[s]] += np.abs(term)
    return {"gates_over_channel": float((np.abs(g_sum) / np.maximum(np.abs(ch_sum), 1e-300)).max()),
            "pair_cancellation": float((np.abs(g_sum) / np.maximum(g_abs, 1e-300)).max()),
            "channel_2w_force_max": float(np.abs(ch_sum).max() / 2),
            "mean_force_max": float((abs(env.H) @ (np.abs(A) ** 2)).max() / 2)}
