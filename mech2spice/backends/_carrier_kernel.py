"""Compiled Lawson RK4 loop of the carrier engine (numba); carrier.py holds the scheme's derivation.

Layout (structure of arrays, by kind).  The operator renumbers the DOFs so that DOFs of one kind (every
gate's channel, then every insulator, then every gate oscillator: the same mass, stiffness and damping)
are contiguous; `seg` holds the kinds' boundaries and E, H, inv_m one row per kind.  A step is four
passes, one per RK4 stage, each over a range of DOFs in two loops:

1. the gather loop: the explicit force of each DOF (drive, coupling springs and dashpots, quadratic
   couplings; one CSR each, so DOF ranges are independent and nothing is scattered);
2. the combine loop, per kind: the propagator entries are scalars there, so the loop is a plain
   elementwise update the compiler vectorises.

With `threads` > 1 each pass's DOFs are split into contiguous ranges on numba's thread pool (one barrier
per pass).  Batch members run one after another; each is a row of the (B, n) state arrays.
"""
from __future__ import annotations

import numpy as np

from . import _jit
from ._jit import njit      # numba's njit with a cache concurrent processes cannot corrupt

AVAILABLE = _jit.AVAILABLE     # carrier.py reads it

try:
    from numba import prange
except ImportError:            # pragma: no cover - exercised only without numba
    prange = range

DONE, SETTLED, DIVERGED = 0, 1, 2
_FLAGS = dict(cache=True, fastmath={"contract"})     # FMA contraction only: no reassociation of sums


@njit(**_FLAGS)
def _forces(i0, i1, x, v, s, c, P, Q, groups, Ci, Ck, Cd, Qi, Qg, f):
    """f[i] = the explicit force on DOF i in [i0, i1): drive, coupling springs and dashpots, quadratic couplings.

    groups[r] = (lo, hi, coupling width, quad width, coupling base, quad base, slow, driven): the DOFs lo..hi
    share their number of couplings and of quadratic partners, stored column by column from the bases
    (entry k of DOF i at base + k (hi - lo) + i - lo).  The loops run over a column's DOFs innermost: unit
    stride, one trip count, so the compiler vectorises them (gathers for the partners' x and v)."""
    for r in range(groups.shape[0]):
        g0, g1 = groups[r, 0], groups[r, 1]
        lo, hi = max(i0, g0), min(i1, g1)
        if lo >= hi:
            continue
        m, slow = g1 - g0, groups[r, 6]
        if groups[r, 7]:
            for i in range(lo, hi):
                f[i] = P[i] * s + Q[i] * c
        else:
            for i in range(lo, hi):
                f[i] = 0.0
        for k in range(groups[r, 2]):                  # coupling springs and dashpots: + k_ij x_j + c_ij v_j
            o = groups[r, 4] - g0 + k * m
            for i in range(lo, hi):
                j = Ci[o + i]
                f[i] += Ck[o + i] * x[j] + Cd[o + i] * v[j]
        for k in range(groups[r, 3]):                  # V = gamma u_f^2 u_s
            o = groups[r, 5] - g0 + k * m
            if slow:                                   # on the slow DOF: - gamma x_f^2
                for i in range(lo, hi):
                    u = x[Qi[o + i]]
                    f[i] -= Qg[o + i] * u * u
            else:                                      # on the fast DOF: - 2 gamma x_f x_s
                for i in range(lo, hi):
                    f[i] -= Qg[o + i] * x[i] * x[Qi[o + i]]


@njit(inline="always", **_FLAGS)
def _range(seg, t, i0, i1):
    """The part of [i0, i1) that holds kind t."""
    return max(i0, seg[t]), min(i1, seg[t + 1])


@njit(**_FLAGS)
def _combine1(i0, i1, h, x, v, f, xa, va, xe, ve, xn, vn, seg, inv_m, E, H):
    """After stage 1: stage-2 state E(h/2)(y + h/2 a1) into (xa, va), E(h/2) y into (xe, ve),
    E(h)(y + h/6 a1) into (xn, vn)."""
    for t in range(seg.size - 1):
        lo, hi = _range(seg, t, i0, i1)
        im, h0, h1, h2, h3 = inv_m[t], H[t, 0], H[t, 1], H[t, 2], H[t, 3]
        e0, e1, e2, e3 = E[t, 0], E[t, 1], E[t, 2], E[t, 3]
        for i in range(lo, hi):
            a = f[i] * im
            xi, vi = x[i], v[i]
            w = vi + 0.5 * h * a
            xa[i] = h0 * xi + h1 * w
            va[i] = h2 * xi + h3 * w
            xe[i] = h0 * xi + h1 * vi
            ve[i] = h2 * xi + h3 * vi
            w = vi + h / 6.0 * a
            xn[i] = e0 * xi + e1 * w
            vn[i] = e2 * xi + e3 * w


@njit(**_FLAGS)
def _combine2(i0, i1, h, f, vb, ve, xn, vn, seg, inv_m, H):
    """After stage 2: the stage-3 state is (xe, vb = ve + h/2 a2); E(h/2) h/3 a2 into the new state."""
    for t in range(seg.size - 1):
        lo, hi = _range(seg, t, i0, i1)
        im, h1, h3 = inv_m[t], H[t, 1] * h / 3.0, H[t, 3] * h / 3.0
        for i in range(lo, hi):
            a = f[i] * im
            vb[i] = ve[i] + 0.5 * h * a
            xn[i] += h1 * a
            vn[i] += h3 * a


@njit(**_FLAGS)
def _combine3(i0, i1, h, f, xa, va, xe, ve, xn, vn, seg, inv_m, H):
    """After stage 3: stage-4 state E(h/2)(ye + h a3) into (xa, va); E(h/2) h/3 a3 into the new state."""
    for t in range(seg.size - 1):
        lo, hi = _range(seg, t, i0, i1)
        im, h0, h1, h2, h3 = inv_m[t], H[t, 0], H[t, 1], H[t, 2], H[t, 3]
        for i in range(lo, hi):
            a = f[i] * im
            w = ve[i] + h * a
            xa[i] = h0 * xe[i] + h1 * w
            va[i] = h2 * xe[i] + h3 * w
            xn[i] += h1 * (h / 3.0) * a
            vn[i] += h3 * (h / 3.0) * a


@njit(**_FLAGS)
def _combine4(i0, i1, h, f, x, v, xn, vn, seg, inv_m):
    """After stage 4: y <- (xn, vn + h/6 a4)."""
    for t in range(seg.size - 1):
        lo, hi = _range(seg, t, i0, i1)
        im = inv_m[t] * h / 6.0
        for i in range(lo, hi):
            x[i] = xn[i]
            v[i] = vn[i] + im * f[i]


@njit(**_FLAGS)
def _stage(k, i0, i1, h, x, v, w, sc, P, Q, seg, inv_m, E, H, groups, Ci, Ck, Cd, Qi, Qg):
    """Stage k (0..3) of one step over DOFs [i0, i1): its forces, then its combine loop."""
    xa, va, vb, xe, ve, xn, vn, f = w[0], w[1], w[2], w[3], w[4], w[5], w[6], w[7]
    if k == 0:
        _forces(i0, i1, x, v, sc[0], sc[1], P, Q, groups, Ci, Ck, Cd, Qi, Qg, f)
        _combine1(i0, i1, h, x, v, f, xa, va, xe, ve, xn, vn, seg, inv_m, E, H)
    elif k == 1:
        _forces(i0, i1, xa, va, sc[2], sc[3], P, Q, groups, Ci, Ck, Cd, Qi, Qg, f)
        _combine2(i0, i1, h, f, vb, ve, xn, vn, seg, inv_m, H)
    elif k == 2:
        _forces(i0, i1, xe, vb, sc[2], sc[3], P, Q, groups, Ci, Ck, Cd, Qi, Qg, f)
        _combine3(i0, i1, h, f, xa, va, xe, ve, xn, vn, seg, inv_m, H)
    else:
        _forces(i0, i1, xa, va, sc[4], sc[5], P, Q, groups, Ci, Ck, Cd, Qi, Qg, f)
        _combine4(i0, i1, h, f, x, v, xn, vn, seg, inv_m)


@njit(**_FLAGS)
def _step_serial(h, x, v, w, sc, P, Q, seg, inv_m, E, H, groups, Ci, Ck, Cd, Qi, Qg):
    """One Lawson RK4 step of one member, in place; w holds the work arrays, sc the stages' sines and cosines."""
    for k in range(4):
        _stage(k, 0, x.size, h, x, v, w, sc, P, Q, seg, inv_m, E, H, groups, Ci, Ck, Cd, Qi, Qg)


@njit(parallel=True, **_FLAGS)
def _step_threads(h, x, v, w, sc, P, Q, seg, inv_m, E, H, groups, Ci, Ck, Cd, Qi, Qg, cuts):
    """_step_serial with each stage split into the DOF ranges cuts[j]..cuts[j+1] on the thread pool."""
    for k in range(4):
        for j in prange(cuts.size - 1):
            _stage(k, cuts[j], cuts[j + 1], h, x, v, w, sc, P, Q, seg, inv_m, E, H, groups, Ci, Ck, Cd, Qi, Qg)


@njit(**_FLAGS)
def run_periods(X, V, nper, N, h, P, Q, seg, inv_m, E, H, groups, Ci, Ck, Cd, Qi, Qg, trig, demod, pidx, widx,
                bound, tol, check, settle_min, since, watch, amp, mean, cuts):
    """Advance every member of X, V (B, n) by up to `nper` periods of N steps at constant drive weights P, Q (B, n).

    Per period, the probes' complex amplitude at the drive frequency and their mean (trapezoid rule over
    the N + 1 samples of the period) go to amp (nper, probes, B) and mean.  With tol > 0 the run stops
    once the watched DOFs' amplitudes stayed within a range of tol for two windows of `check` periods in
    a row; windows start `settle_min` periods after the stimulus last changed, `since` periods before
    this call, and their record watch = (lo, hi: (watched, B) amplitude ranges, quiet: (1,) windows in a row)
    carries over from call to call.  Returns (periods done, DONE | SETTLED | DIVERGED).
    trig: (N, 6) sine and cosine of the drive phase at each step's start, middle and end."""
    B, n = X.shape
    w = np.empty((8, n))
    wre = np.empty((widx.size, B))
    wim = np.empty((widx.size, B))
    lo, hi, quiet = watch[0], watch[1], watch[2]
    threads = cuts.size > 2
    for p in range(nper):
        for b in range(B):
            x, v = X[b], V[b]
            for j in range(pidx.size):                    # trapezoid: half weight to the period's first sample
                u = x[pidx[j]]
                amp[p, j, b] = 0.5 * u * demod[N - 1]
                mean[p, j, b] = 0.5 * u
            for j in range(widx.size):
                u = x[widx[j]]
                wre[j, b] = 0.5 * u * demod[N - 1].real
                wim[j, b] = 0.5 * u * demod[N - 1].imag
            for s in range(N):
                if threads:
                    _step_threads(h, x, v, w, trig[s], P[b], Q[b], seg, inv_m, E, H, groups, Ci, Ck, Cd, Qi, Qg,
                                  cuts)
                else:
                    _step_serial(h, x, v, w, trig[s], P[b], Q[b], seg, inv_m, E, H, groups, Ci, Ck, Cd, Qi, Qg)
                f = 0.5 if s == N - 1 else 1.0
                for j in range(pidx.size):
                    u = f * x[pidx[j]]
                    amp[p, j, b] += u * demod[s]
                    mean[p, j, b] += u
                for j in range(widx.size):
                    u = f * x[widx[j]]
                    wre[j, b] += u * demod[s].real
                    wim[j, b] += u * demod[s].imag
            for i in range(n):
                if not (abs(x[i]) < bound):             # catches NaN too
                    return p, DIVERGED
        for j in range(pidx.size):
            for b in range(B):
                amp[p, j, b] *= 2.0 / N
                mean[p, j, b] /= N
        age = since + p + 1                              # periods since the stimulus changed
        if tol > 0.0 and age > settle_min:               # windows of `check` periods from settle_min on
            for j in range(widx.size):
                for b in range(B):
                    a = 2.0 / N * np.sqrt(wre[j, b] ** 2 + wim[j, b] ** 2)
                    lo[j, b] = min(lo[j, b], a)
                    hi[j, b] = max(hi[j, b], a)
            if (age - settle_min) % check == 0:
                spread = 0.0
                for j in range(widx.size):
                    for b in range(B):
                        spread = max(spread, hi[j, b] - lo[j, b])
                quiet[0] = quiet[0] + 1 if spread < tol else 0
                lo[:] = np.inf
                hi[:] = 0.0
                if quiet[0] >= 2:
                    return p + 1, SETTLED
    return nper, DONE
