"""Steady states (the paper's semi-analytic method) and their linear stability.

Fix the slow DOFs s; the oscillating DOFs are then linear, Z(s) A = F^.  The
mean force of |A|^2 on s must balance its spring: r(s) = K_s s + H|A(s)|^2/2 = 0.
With one slow DOF (a single gate) every root is found by scanning r over the
whole range s can reach and refining each sign change; each root's stability
comes from the eigenvalues of the envelope equations linearised there.  A
steady state can satisfy the balance and still be unstable (the insulator
self-oscillates): ../shared/reference/gate-operating-point.md, section 3.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq, fsolve

from .envelope import Envelope
from ..errors import Mech2SpiceError

STABLE_TOL = 1e-9     # growth rates (1/time) below this count as stable


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
                  starts: list[np.ndarray] | None = None) -> list[SteadyState]:
    """Every steady state for forcing F (n_fast,), sorted by s.

    One slow DOF with uncoupled oscillators: all roots, by scanning.  Otherwise:
    Newton from each of `starts` (e.g. states an integrator settled to)."""
    F = np.asarray(F).reshape(-1)
    if env.slow.size == 1 and env.diagonal:
        return [_state(env, F, np.array([r])) for r in _scan_roots(env, F, n_grid)]
    if not starts:
        raise Mech2SpiceError("a network with several slow DOFs needs starting points for its steady states")
    found: list[SteadyState] = []
    for s0 in starts:
        s, info, ok, msg = fsolve(lambda s: balance(env, F, s), np.asarray(s0, float), full_output=True,
                                  xtol=1e-12)
        if ok == 1 and not any(np.allclose(s, f.s, atol=1e-9) for f in found):
            found.append(_state(env, F, s))
    return found


def _scan_roots(env: Envelope, F: np.ndarray, n_grid: int) -> list[float]:
    lim = s_reach(env, F)
    s = np.linspace(-lim, lim, n_grid)
    r = balance_grid(env, F[:, None], s)[0]
    idx = np.flatnonzero(np.sign(r[:-1]) != np.sign(r[1:]))
    f = lambda x: balance_grid(env, F[:, None], np.array([x]))[0, 0]
    return [brentq(f, s[i], s[i + 1], xtol=1e-14, rtol=1e-13) for i in idx]
