"""All steady states of many copies of a one-insulator network over many input points, fast.

The equations are the envelope's (envelope.py): Z(s) A = F with Z(s) = Z0 + diag(g s), and the
insulator's balance r(s) = k_s s + h.|A|^2 / 2 = 0, g = 2 gamma, h = gamma.  The oscillating DOFs may
be coupled (springs, dashpots): Z0 is a small dense matrix per copy.

Input points differ only in drive amplitudes.  Drives fall into groups (0: constant, 1..: scaled by an
input level), so F = sum_g a_g f_g and, with R_g(s) = Z(s)^-1 f_g,

    r(s; a) = k_s s + 1/2 sum_gh a_g a_h W_gh(s),     W_gh(s) = sum_f h_f Re(conj(R_fg) R_fh).

The W_gh need one linear solve per s for the whole input grid, so every input point's r(s) on a fine
s grid is one matrix product.  Roots: sign changes on that grid, refined by Illinois regula falsi.
The grid spans only where roots can be: k_s |s| <= 1/2 sum |a_g| |a_h| |W_gh(s)| (found on a coarse
scan).  Each root's stability: eigenvalues of the envelope equations linearised there (analytic
Jacobian, the same equations as Envelope.jacobian).  This does not assume the insulator sees the
inputs only through x1^2 + x2^2: with spread the four gate oscillators differ and it does not.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import Mech2SpiceError
from .model import MechModel
from .steady import STABLE_TOL

N_GRID = 4000          # fine-grid points over the root range (measured against 20000: docs/robustness.md)
WIDE_STEP = 0.004      # coarse-scan spacing in s: resonances are >= 0.06 wide in s for the gate's DOFs
BOUND_SAFETY = 1.5     # on the coarse scan's bound, for peaks falling between its points
ILLINOIS_STEPS = 8        # converged to rounding after 4 on the gate (measured)


@dataclass
class Stack:
    """Envelope arrays of B copies of one network (same topology, different values)."""
    omega: float
    Z0: np.ndarray         # (B, nf, nf) complex
    Binv: np.ndarray       # (B, nf, nf) complex: (2 i w M + C)^-1 of the fast block
    g: np.ndarray          # (B, nf) 2 gamma to the slow DOF
    h: np.ndarray          # (B, nf) gamma
    ks: np.ndarray         # (B,)
    cs: np.ndarray
    ms: np.ndarray
    f: np.ndarray          # (B, nf, n_groups) complex forcing of each drive group at level 1
    out: int               # row of the output DOF among the fast DOFs

    @property
    def groups(self) -> int:
        """How many input groups (forcing columns) the stack holds."""
        return self.f.shape[2]


def stack(models: list[MechModel], groups: np.ndarray, out_dof: int) -> Stack:
    """Stack B models of one topology with exactly one slow DOF; groups[d] is drive d's group."""
    parts = [_arrays(m, np.asarray(groups), out_dof) for m in models]
    per_copy = ("Z0", "Binv", "g", "h", "ks", "cs", "ms", "f")
    return Stack(models[0].omega, **{k: np.stack([p[k] for p in parts]) for k in per_copy}, out=parts[0]["out"])


def _arrays(m: MechModel, groups: np.ndarray, out_dof: int):
    slow = np.flatnonzero(m.slow)
    fast = np.flatnonzero(~np.asarray(m.slow, bool))
    if slow.size != 1:
        raise Mech2SpiceError(f"the batched steady-state scan needs exactly one slow DOF, got {slow.size}")
    K, C, M, w = m.K.toarray(), m.C.toarray(), np.asarray(m.mass), m.omega
    if np.any(K[slow][:, fast]) or np.any(C[slow][:, fast]):
        raise Mech2SpiceError("a spring or dashpot joins the slow DOF to an oscillating one")
    Kf, Cf, Mf = K[np.ix_(fast, fast)], C[np.ix_(fast, fast)], np.diag(M[fast])
    pos = -np.ones(m.n, int)
    pos[fast] = np.arange(fast.size)
    g, h = np.zeros(fast.size), np.zeros(fast.size)
    for qf, _, gam in m.quads:
        g[pos[qf]] += 2 * gam
        h[pos[qf]] += gam
    f = np.zeros((fast.size, int(groups.max(initial=0)) + 1), complex)
    for d, grp in zip(m.drives, groups):
        f[pos[d.dof], grp] += -1j * d.amplitude * np.exp(1j * d.phase)
    s = slow[0]
    return {"Z0": Kf - w * w * Mf + 1j * w * Cf, "Binv": np.linalg.inv(2j * w * Mf + Cf), "g": g, "h": h,
            "ks": K[s, s], "cs": C[s, s], "ms": M[s], "f": f, "out": int(pos[out_dof])}


def responses(st: Stack, b: int, s: np.ndarray) -> np.ndarray:
    """R_g(s) = Z(s)^-1 f_g for copy b at slow positions s (S,): (S, nf, n_groups)."""
    Z = st.Z0[b][None] + (st.g[b][None, :, None] * np.eye(st.g.shape[1])[None]) * s[:, None, None]
    return np.linalg.solve(Z, np.broadcast_to(st.f[b], (s.size,) + st.f[b].shape))


def w_matrix(st: Stack, b: int, R: np.ndarray) -> np.ndarray:
    """W_gh = sum_f h_f Re(conj(R_fg) R_fh): (S, n_groups, n_groups)."""
    return np.einsum("f,sfg,sfh->sgh", st.h[b], R.conj(), R).real


@dataclass
class Roots:
    """Every steady state of one copy over the input points."""
    point: np.ndarray       # (n,) input-point index of each state
    s: np.ndarray           # (n,) insulator position
    amp: np.ndarray         # (n,) |A| of the output DOF
    growth: np.ndarray      # (n,) largest real part of the linearised envelope eigenvalues

    @property
    def stable(self) -> np.ndarray:
        """Which roots are linearly stable (growth rate below STABLE_TOL)."""
        return self.growth < STABLE_TOL


def roots(st: Stack, b: int, levels: np.ndarray, n_grid: int = N_GRID) -> Roots:
    """All steady states of copy b for input points levels (P, n_groups) (column 0: constant drives, 1)."""
    levels = np.asarray(levels, float)
    lo, hi = root_range(st, b, np.abs(levels).max(axis=0))
    s = np.linspace(lo, hi, n_grid)
    W = w_matrix(st, b, responses(st, b, s)).reshape(n_grid, -1)          # (S, G*G)
    used = np.flatnonzero(np.abs(W).max(axis=0) > 0)
    q = (levels[:, :, None] * levels[:, None, :]).reshape(levels.shape[0], -1)[:, used]
    pts, idx = _sign_changes(st.ks[b] * s, 0.5 * W[:, used].T, q)
    r0 = _refine(st, b, q[pts], used, s[idx], s[idx + 1])
    return _states(st, b, levels, pts, r0)


OVERFLOW = ("the steady-state scan overflowed: a gate parameter is too large or too small for double precision "
            "(the insulator's range is not a finite number)")


def root_range(st: Stack, b: int, amax: np.ndarray) -> tuple[float, float]:
    """Interval of s that can hold a root for any input point with |a_g| <= amax (coarse scan)."""
    L = _wide_bound(st, b, amax)
    if not np.isfinite(L):
        raise Mech2SpiceError(OVERFLOW)
    s = np.linspace(-L, L, max(int(min(2 * L / WIDE_STEP, 40000)), 3) | 1)
    W = w_matrix(st, b, responses(st, b, s))
    bound = 0.5 * BOUND_SAFETY * np.einsum("sgh,g,h->s", np.abs(W), amax, amax)
    ok = np.flatnonzero(abs(st.ks[b]) * np.abs(s) <= bound)
    if not ok.size:                      # even s = 0 fails: the bound is NaN (inf - inf in the responses)
        raise Mech2SpiceError(OVERFLOW)
    step = s[1] - s[0]
    return float(s[ok[0]] - 2 * step), float(s[ok[-1]] + 2 * step)


def _wide_bound(st: Stack, b: int, amax: np.ndarray) -> float:
    """Generous |s| bound: each DOF at resonance (|A| <= force / (w c)), its force including one hop
    through its couplings from directly driven neighbours."""
    Z0, w = st.Z0[b], st.omega
    c = np.maximum(np.abs(Z0.diagonal().imag) / w, 1e-12)
    force = np.abs(st.f[b]) @ amax
    off = np.abs(Z0 - np.diag(Z0.diagonal()))
    amp = (force + off @ (force / (w * c))) / (w * c)
    return float(np.abs(st.h[b]) @ amp ** 2 / (2 * abs(st.ks[b]))) * 1.05 + 1e-9


def _sign_changes(lin: np.ndarray, Wt: np.ndarray, q: np.ndarray, chunk: int = 2_000_000):
    """(point, grid index) of every sign change of r = lin + q @ Wt along s, in point chunks."""
    pts, idx = [], []
    step = max(1, chunk // lin.size)
    for p0 in range(0, q.shape[0], step):
        neg = np.signbit(lin[None, :] + q[p0:p0 + step] @ Wt)
        p, j = np.nonzero(neg[:, 1:] != neg[:, :-1])
        pts.append(p + p0)
        idx.append(j)
    return np.concatenate(pts), np.concatenate(idx)


def _residual(st: Stack, b: int, q: np.ndarray, used: np.ndarray, s: np.ndarray) -> np.ndarray:
    W = w_matrix(st, b, responses(st, b, s)).reshape(s.size, -1)[:, used]
    return st.ks[b] * s + 0.5 * np.einsum("nk,nk->n", q, W)


def _refine(st, b, q, used, a, c) -> np.ndarray:
    """Illinois regula falsi on brackets [a, c] (vectorised)."""
    fa, fc = _residual(st, b, q, used, a), _residual(st, b, q, used, c)
    for _ in range(ILLINOIS_STEPS):
        den = fc - fa
        x = np.where(den != 0, c - fc * (c - a) / np.where(den != 0, den, 1), c)
        fx = _residual(st, b, q, used, x)
        flip = np.signbit(fx) != np.signbit(fc)
        a, fa = np.where(flip, c, a), np.where(flip, fc, 0.5 * fa)
        c, fc = x, fx
    return c


def _states(st: Stack, b: int, levels: np.ndarray, pts: np.ndarray, s: np.ndarray) -> Roots:
    R = responses(st, b, s)                                       # (n, nf, G)
    A = np.einsum("nfg,ng->nf", R, levels[pts])
    return Roots(pts, s, np.abs(A[:, st.out]), growth(st, b, A, s))


def jacobian(st: Stack, b: int, A: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Real Jacobian of the envelope equations at states (A (n, nf), s (n,)), variables
    (Re A, Im A, s, s'): (n, 2 nf + 2, 2 nf + 2)."""
    n, nf = A.shape
    Bi = st.Binv[b]
    Z = st.Z0[b][None] + (st.g[b][None, :, None] * np.eye(nf)[None]) * s[:, None, None]
    M1 = -Bi[None] @ Z
    v = -(Bi[None] @ (st.g[b][None, :] * A)[..., None])[..., 0]
    J = np.zeros((n, 2 * nf + 2, 2 * nf + 2))
    J[:, :nf, :nf], J[:, :nf, nf:2 * nf] = M1.real, -M1.imag
    J[:, nf:2 * nf, :nf], J[:, nf:2 * nf, nf:2 * nf] = M1.imag, M1.real
    J[:, :nf, 2 * nf], J[:, nf:2 * nf, 2 * nf] = v.real, v.imag
    J[:, 2 * nf, 2 * nf + 1] = 1.0
    ms = st.ms[b]
    J[:, 2 * nf + 1, :nf] = -st.h[b] * A.real / ms
    J[:, 2 * nf + 1, nf:2 * nf] = -st.h[b] * A.imag / ms
    J[:, 2 * nf + 1, 2 * nf] = -st.ks[b] / ms
    J[:, 2 * nf + 1, 2 * nf + 1] = -st.cs[b] / ms
    return J


def growth(st: Stack, b: int, A: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Largest real part of the linearised envelope eigenvalues at each state."""
    if not s.size:
        return np.zeros(0)
    return np.linalg.eigvals(jacobian(st, b, A, s)).real.max(axis=1)
