"""Steady states (the paper's semi-analytic method) and their linear stability.

Fix the slow DOFs s; the oscillating DOFs are then linear, Z(s) A = F^.  The
mean force of |A|^2 on s must balance its spring: r(s) = K_s s + H|A(s)|^2/2 = 0.
With one slow DOF (a single gate) every root is found by scanning r over the
whole range s can reach and refining each sign change; each root's stability
comes from the eigenvalues of the envelope equations linearised there.  A
steady state can satisfy the balance and still be unstable (the insulator
self-oscillates): ../shared/reference/gate-operating-point.md, section 3.

correction="2w" refines each root with the insulators' 2-omega motion put back (Envelope2w):
the averaged balance drops it, and where the gate's output is steep (the transition between the
bands) that shifts the output by up to 1.8e-3 u_R against harmonic balance (docs/vacask.md).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.optimize import brentq, fsolve

from .envelope import Envelope
from ..errors import Mech2SpiceError

STABLE_TOL = 1e-9     # growth rates (1/time) below this count as stable
CORRECTIONS = (None, "2w")


class Envelope2w(Envelope):
    """The envelope equations plus the omega part of (2-omega slow motion) x (fast DOF).

    Each slow DOF is s + Re(S e^{2 i omega t}) with Z_s(2 omega) S = -H A^2 / 2; the coupling force
    -G s u_f then has the omega phasor -(G S) conj(A) / 2 (docs/physics.md, "What the envelope
    equations drop").  In a steady state A' = 0, so this is the whole first correction."""

    def __init__(self, model):
        super().__init__(model)
        w = self.omega
        Zs2 = (self.Ks - 4 * w * w * sp.diags(self.ms) + 2j * w * self.Cs).tocsc()
        self._solve_s2 = spla.factorized(Zs2) if self.slow.size else None

    @classmethod
    def of(cls, model) -> "Envelope2w":
        """The model's corrected operator, built once (beside Envelope.of's)."""
        env = model.derived.get("envelope2w")
        if env is None:
            env = model.derived["envelope2w"] = cls(model)
        return env

    def s2(self, A):
        """Complex 2-omega amplitude S of each slow DOF (n_slow, B)."""
        rhs = -(self.H @ (A * A)) / 2
        if self._solve_s2 is None:
            return rhs
        return self._solve_s2(rhs.reshape(self.slow.size, -1)).reshape(rhs.shape)

    def residual_fast(self, A, s, F):
        """Envelope.residual_fast minus (G S) conj(A) / 2: the omega part of the 2-omega slow motion."""
        return super().residual_fast(A, s, F) - 0.5 * (self.G @ self.s2(A)) * np.conj(A)


@dataclass
class SteadyState:
    """One steady state: slow coordinates, fast complex amplitudes, and its largest growth rate."""
    s: np.ndarray            # slow coordinates (n_slow,)
    A: np.ndarray            # complex amplitudes of the oscillating DOFs (n_fast,)
    growth: float            # largest real part of the linearised envelope eigenvalues
    freq: float              # |imaginary part| of that eigenvalue (rad/s)

    @property
    def stable(self) -> bool:
        """True if no linearised envelope eigenvalue has real part >= STABLE_TOL."""
        return self.growth < STABLE_TOL


def s_reach(env: Envelope, F: np.ndarray) -> float:
    """Bound on |s|: every |A_f| is at most |F_f| / (omega c_f), its resonant value."""
    c = env.Bop.diagonal().real
    amax2 = (np.abs(F) / (env.omega * np.maximum(c, 1e-300))) ** 2
    return float((abs(env.H) @ amax2).max() / 2 / np.abs(env.Ks.diagonal()).min()) * 1.05 + 1e-12


def balance_grid(env: Envelope, F: np.ndarray, s: np.ndarray) -> np.ndarray:
    """r(s) for forcings F (n_fast, B) on a grid s (S,): (B, S). One slow DOF, diagonal Z only."""
    z = env.z0_diag[:, None] + env.G.toarray()[:, :1] * s[None, :]
    inv_abs2 = 1.0 / np.abs(z) ** 2                              # (n_fast, S)
    weights = (np.abs(F) ** 2).T * env.H.toarray()[0][None, :]   # (B, n_fast)
    return env.Ks.diagonal()[0] * s[None, :] + 0.5 * weights @ inv_abs2


def balance(env: Envelope, F: np.ndarray, s: np.ndarray) -> np.ndarray:
    """The slow DOFs' force residual K_s s - (slow force of the fast response to s): zero at a steady state."""
    A = env.fast_response(s, F)
    return env.Ks @ s - env.slow_force(A[:, None])[:, 0]


def stability(env: Envelope, A: np.ndarray, s: np.ndarray, F: np.ndarray) -> tuple[float, float]:
    """(largest real part, |imaginary part| of that eigenvalue) of the envelope Jacobian at (A, s)."""
    ev = np.linalg.eigvals(env.jacobian(env.pack(A, s, np.zeros_like(s)), F))
    k = int(np.argmax(ev.real))
    return float(ev.real[k]), float(abs(ev.imag[k]))


def _state(env: Envelope, F: np.ndarray, s: np.ndarray) -> SteadyState:
    A = env.fast_response(s, F)
    g, w = stability(env, A, s, F)
    return SteadyState(s, A, g, w)


def steady_states(env: Envelope, F: np.ndarray, n_grid: int = 20000,
                  starts: list[np.ndarray] | None = None, correction: str | None = None) -> list[SteadyState]:
    """Every steady state for forcing F (n_fast,), sorted by s.

    One slow DOF with uncoupled oscillators: all roots, by scanning.  Otherwise:
    Newton from each of `starts` (e.g. states an integrator settled to).
    correction="2w": each root then refined by refine_2w (a root Newton loses there is dropped)."""
    if correction not in CORRECTIONS:
        raise Mech2SpiceError(f"unknown steady-state correction {correction!r} (choose from: 2w)")
    F = np.asarray(F).reshape(-1)
    if env.slow.size == 1 and env.diagonal:
        found = [_state(env, F, np.array([r])) for r in _scan_roots(env, F, n_grid)]
    elif not starts:
        raise Mech2SpiceError("a network with several slow DOFs needs starting points for its steady states")
    else:
        found = []
        for s0 in starts:
            s, info, ok, msg = fsolve(lambda s: balance(env, F, s), np.asarray(s0, float), full_output=True,
                                      xtol=1e-12)
            if ok == 1 and not any(np.allclose(s, f.s, atol=1e-9) for f in found):
                found.append(_state(env, F, s))
    if correction == "2w":
        found = _distinct([r for r in (refine_2w(env, F, st) for st in found) if r is not None])
    return found


def refine_2w(env: Envelope, F: np.ndarray, state: SteadyState) -> SteadyState | None:
    """Newton on the 2-omega-corrected steady-state equations (Envelope2w's fast residual = 0 and the slow
    balance), started from an averaged steady state; its stability from Envelope2w's Jacobian.  None when
    Newton does not converge (the correction moved a fold past this root)."""
    e2 = Envelope2w.of(env.model)
    F = np.asarray(F).reshape(-1)
    nf = env.fast.size

    def residual(y):
        A, s = y[:nf] + 1j * y[nf:2 * nf], y[2 * nf:]
        R = e2.residual_fast(A[:, None], s[:, None], F[:, None])[:, 0]
        return np.concatenate([R.real, R.imag, env.Ks @ s - env.slow_force(A[:, None])[:, 0]])

    y0 = np.concatenate([state.A.real, state.A.imag, state.s])
    y, _, ok, _ = fsolve(residual, y0, full_output=True, xtol=1e-13)
    scale = max(np.abs(F).max(), 1e-300)
    if ok != 1 and np.abs(residual(y)).max() > 1e-10 * scale:
        return None
    A, s = y[:nf] + 1j * y[nf:2 * nf], y[2 * nf:]
    g, w = stability(e2, A, s, F)
    return SteadyState(s, A, g, w)


def carrier_state(env: Envelope, state: SteadyState) -> tuple[np.ndarray, np.ndarray]:
    """Positions and velocities (n,) at t = 0 of the oscillators in `state`: u_f = Re(A e^{i omega t}), the
    slow DOFs at s + Re(S e^{2 i omega t}) with their 2-omega motion S (Envelope2w.s2): the start an
    integrator needs to begin on the periodic state instead of ringing around it."""
    m, w = env.model, env.omega
    S = Envelope2w.of(m).s2(state.A[:, None])[:, 0]
    x, v = np.zeros(m.n), np.zeros(m.n)
    x[env.fast], v[env.fast] = state.A.real, (1j * w * state.A).real
    x[env.slow], v[env.slow] = state.s + S.real, (2j * w * S).real
    return x, v


def _distinct(states: list[SteadyState]) -> list[SteadyState]:
    """States sorted by s, one per root (refining two nearby roots can land on the same one)."""
    out: list[SteadyState] = []
    for st in sorted(states, key=lambda x: tuple(x.s)):
        if not any(np.allclose(st.s, o.s, rtol=1e-7, atol=1e-12 * max(np.abs(st.s).max(), 1e-300)) for o in out):
            out.append(st)
    return out


def _scan_roots(env: Envelope, F: np.ndarray, n_grid: int) -> list[float]:
    with np.errstate(all="ignore"):
        lim = s_reach(env, F)
        s = np.linspace(-lim, lim, n_grid)
        r = balance_grid(env, F[:, None], s)[0]
    if not (np.isfinite(lim) and np.isfinite(r).all()):      # brentq would stop at a NaN with a traceback
        raise Mech2SpiceError("the steady-state scan is not finite: a gate parameter is too large or too small "
                              "for double precision (a quality factor of 1e300?)")
    idx = np.flatnonzero(np.sign(r[:-1]) != np.sign(r[1:]))
    f = lambda x: balance_grid(env, F[:, None], np.array([x]))[0, 0]
    return [brentq(f, s[i], s[i + 1], xtol=1e-14, rtol=1e-13) for i in idx]
