"""Compiled RK4 loop for the envelope equations (numba): the scheme of envelope.py's numpy path, with
the sparse products and the (2 i omega M + C) solve fused into one pass per stage.

The solve multiplies by Bop's inverse, which is block diagonal with small blocks (a channel and the
dashpot gates it drives: at most 1 + fan-out DOFs), so it is one sparse product without divisions.
Where blocks are large it falls back to SuperLU's factors (Pr Bop Pc = L U) as two triangular sweeps.
Both paths compute the numpy path's equations to rounding.  The loop can stop early once the network has settled (every
channel's amplitude steady within a tolerance), which is what lets a clocked run skip idle time.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from . import _envelope_latency
from ._rk4_kernel import AVAILABLE, njit

try:
    from numba import prange
except ImportError:            # pragma: no cover - without numba
    prange = range

DONE, SETTLED, DIVERGED = 0, 1, 2
FAST = {"contract", "reassoc", "nsz", "arcp"}     # not nnan/ninf: the divergence check must see NaN


@njit(cache=True, fastmath=FAST)
def _rhs(A, s, sd, F, Z, G, H, Ks, Cs, inv_ms, L, U, perm_r, perm_c, Ad, sdd, work, work2, Binv):
    Zp, Zi, Zd = Z
    Gp, Gi, Gd = G
    Hp, Hi, Hd = H
    Kp, Ki, Kd = Ks
    Cp, Ci, Cd = Cs
    nf, B = A.shape
    ns = s.shape[0]
    for b in range(B):
        for f in range(nf):                       # residual F - Z0 A - (G s) A, scattered by perm_r
            r = F[f, b]
            for k in range(Zp[f], Zp[f + 1]):
                r -= Zd[k] * A[Zi[k], b]
            gs = 0.0
            for k in range(Gp[f], Gp[f + 1]):
                gs += Gd[k] * s[Gi[k], b]
            work[perm_r[f]] = r - gs * A[f, b]
        if Binv[0].size > 1:                      # block inverse: one sparse product, no divisions
            Bp, Bi, Bd = Binv
            for f in range(nf):
                acc = 0j
                for k in range(Bp[f], Bp[f + 1]):
                    acc += Bd[k] * work[Bi[k]]
                Ad[f, b] = acc
        else:
            _lu_solve(L, U, perm_c, work, work2, Ad, b)
        for j in range(ns):
            acc = 0.0
            for k in range(Hp[j], Hp[j + 1]):
                a = A[Hi[k], b]
                acc -= 0.5 * Hd[k] * (a.real * a.real + a.imag * a.imag)
            for k in range(Kp[j], Kp[j + 1]):
                acc -= Kd[k] * s[Ki[k], b]
            for k in range(Cp[j], Cp[j + 1]):
                acc -= Cd[k] * sd[Ci[k], b]
            sdd[j, b] = acc * inv_ms[j]


@njit(cache=True, fastmath=FAST, parallel=True)
def _rhs_parallel(A, s, sd, F, Z, G, H, Ks, Cs, inv_ms, L, U, perm_r, perm_c, Ad, sdd, work, work2, Binv):
    """_rhs on all cores (the block-inverse path only: rows are independent within each pass)."""
    Zp, Zi, Zd = Z
    Gp, Gi, Gd = G
    Hp, Hi, Hd = H
    Kp, Ki, Kd = Ks
    Cp, Ci, Cd = Cs
    Bp, Bi, Bd = Binv
    nf, B = A.shape
    ns = s.shape[0]
    for b in range(B):
        for f in prange(nf):
            r = F[f, b]
            for k in range(Zp[f], Zp[f + 1]):
                r -= Zd[k] * A[Zi[k], b]
            gs = 0.0
            for k in range(Gp[f], Gp[f + 1]):
                gs += Gd[k] * s[Gi[k], b]
            work[f] = r - gs * A[f, b]
        for f in prange(nf):
            acc = 0j
            for k in range(Bp[f], Bp[f + 1]):
                acc += Bd[k] * work[Bi[k]]
            Ad[f, b] = acc
        for j in prange(ns):
            acc = 0.0
            for k in range(Hp[j], Hp[j + 1]):
                a = A[Hi[k], b]
                acc -= 0.5 * Hd[k] * (a.real * a.real + a.imag * a.imag)
            for k in range(Kp[j], Kp[j + 1]):
                acc -= Kd[k] * s[Ki[k], b]
            for k in range(Cp[j], Cp[j + 1]):
                acc -= Cd[k] * sd[Ci[k], b]
            sdd[j, b] = acc * inv_ms[j]


@njit(cache=True, fastmath=FAST)
def _lu_solve(L, U, perm_c, work, work2, Ad, b):
    """Pr Bop Pc = L U: forward then backward sweep (diagonals last / first in sorted rows)."""
    Lp, Li, Ld = L
    Up, Ui, Ud = U
    nf = work.size
    for i in range(nf):
        acc = work[i]
        last = Lp[i + 1] - 1
        for k in range(Lp[i], last):
            acc -= Ld[k] * work[Li[k]]
        work[i] = acc / Ld[last]
    for i in range(nf - 1, -1, -1):
        acc = work[i]
        first = Up[i]
        for k in range(first + 1, Up[i + 1]):
            acc -= Ud[k] * work2[Ui[k]]
        work2[i] = acc / Ud[first]
    for f in range(nf):
        Ad[f, b] = work2[perm_c[f]]


@njit(cache=True, fastmath=FAST)
def _rates(parallel, A, s, sd, F, Z, G, H, Ks, Cs, inv_ms, L, U, perm_r, perm_c, Ad, sdd, work, work2, Binv):
    """_rhs_parallel or _rhs, chosen by a flag: a compiled function passed as an argument would put its
    dispatcher in run_steps' signature, which numba's on-disk cache never matches in another process
    (every run recompiled and appended an entry until saving the index failed: numba issue 2956)."""
    if parallel:
        _rhs_parallel(A, s, sd, F, Z, G, H, Ks, Cs, inv_ms, L, U, perm_r, perm_c, Ad, sdd, work, work2, Binv)
    else:
        _rhs(A, s, sd, F, Z, G, H, Ks, Cs, inv_ms, L, U, perm_r, perm_c, Ad, sdd, work, work2, Binv)


@njit(cache=True, fastmath=FAST, nogil=True)     # nogil: a Dask worker's own threads run beside it (mc_run)
def run_steps(A, s, sd, nsteps, sub, per, h, F, Z, G, H, Ks, Cs, inv_ms, L, U, perm_r, perm_c, Binv, prow,
              amp, bound, settle_tol, watch, check_every, settle_from, parallel):
    """Advance up to nsteps RK4 steps of h (sub steps span `per` periods), writing A[prow] for each
    period into amp.  Returns (steps done, DONE | SETTLED | DIVERGED).  With settle_tol > 0 the loop
    stops, from step settle_from on, once two windows of check_every steps in a row each saw every
    watched amplitude (the channels) stay within a range of settle_tol.  parallel: the rates by
    _rhs_parallel, else _rhs (_rates)."""
    nf, B = A.shape
    ns = s.shape[0]
    a1 = np.empty_like(A)
    a2 = np.empty_like(A)
    a3 = np.empty_like(A)
    a4 = np.empty_like(A)
    At = np.empty_like(A)
    st = np.empty_like(s)
    vt = np.empty_like(s)
    c1 = np.empty_like(s)
    c2 = np.empty_like(s)
    c3 = np.empty_like(s)
    c4 = np.empty_like(s)
    v2 = np.empty_like(s)
    v3 = np.empty_like(s)
    v4 = np.empty_like(s)
    work = np.empty(nf, A.dtype)
    work2 = np.empty(nf, A.dtype)
    lo = np.zeros((watch.size, B))
    hi = np.zeros((watch.size, B))
    quiet = 0
    for n in range(nsteps):
        _rates(parallel, A, s, sd, F, Z, G, H, Ks, Cs, inv_ms, L, U, perm_r, perm_c, a1, c1, work, work2, Binv)
        if settle_tol > 0.0 and n % check_every == 0:
            if n >= settle_from + check_every:         # a whole window since the last reset
                worst = 0.0
                for q in range(watch.size):
                    for b in range(B):
                        worst = max(worst, hi[q, b] - lo[q, b])
                quiet = quiet + 1 if worst < settle_tol else 0
                if quiet >= 2:
                    return n, 1
            for q in range(watch.size):
                for b in range(B):
                    lo[q, b] = hi[q, b] = abs(A[watch[q], b])
        for f in range(nf):
            for b in range(B):
                At[f, b] = A[f, b] + 0.5 * h * a1[f, b]
        for j in range(ns):
            for b in range(B):
                st[j, b] = s[j, b] + 0.5 * h * sd[j, b]
                v2[j, b] = sd[j, b] + 0.5 * h * c1[j, b]
        _rates(parallel, At, st, v2, F, Z, G, H, Ks, Cs, inv_ms, L, U, perm_r, perm_c, a2, c2, work, work2, Binv)
        for f in range(nf):
            for b in range(B):
                At[f, b] = A[f, b] + 0.5 * h * a2[f, b]
        for j in range(ns):
            for b in range(B):
                st[j, b] = s[j, b] + 0.5 * h * v2[j, b]
                v3[j, b] = sd[j, b] + 0.5 * h * c2[j, b]
        _rates(parallel, At, st, v3, F, Z, G, H, Ks, Cs, inv_ms, L, U, perm_r, perm_c, a3, c3, work, work2, Binv)
        for f in range(nf):
            for b in range(B):
                At[f, b] = A[f, b] + h * a3[f, b]
        for j in range(ns):
            for b in range(B):
                st[j, b] = s[j, b] + h * v3[j, b]
                v4[j, b] = sd[j, b] + h * c3[j, b]
        _rates(parallel, At, st, v4, F, Z, G, H, Ks, Cs, inv_ms, L, U, perm_r, perm_c, a4, c4, work, work2, Binv)
        for f in range(nf):
            for b in range(B):
                A[f, b] += (h / 6.0) * (a1[f, b] + 2.0 * a2[f, b] + 2.0 * a3[f, b] + a4[f, b])
                if not abs(A[f, b]) < bound:     # catches NaN too
                    return n, 2
        if settle_tol > 0.0:
            for q in range(watch.size):
                for b in range(B):
                    m = abs(A[watch[q], b])
                    lo[q, b] = min(lo[q, b], m)
                    hi[q, b] = max(hi[q, b], m)
        for j in range(ns):
            for b in range(B):
                s[j, b] += (h / 6.0) * (sd[j, b] + 2.0 * v2[j, b] + 2.0 * v3[j, b] + v4[j, b])
                sd[j, b] += (h / 6.0) * (c1[j, b] + 2.0 * c2[j, b] + 2.0 * c3[j, b] + c4[j, b])
        if (n + 1) % sub == 0:
            c = (n + 1) // sub - 1
            for p in range(per):
                for q in range(prow.size):
                    for b in range(B):
                        amp[c * per + p, q, b] = A[prow[q], b]
    return nsteps, 0


def _csr(M, dtype):
    M = M.tocsr()
    M.sort_indices()
    return (M.indptr.astype(np.int64), M.indices.astype(np.int64), np.ascontiguousarray(M.data, dtype=dtype))


class Kernel:
    """The envelope operator's arrays in the compiled loop's layout, built once per Envelope."""

    def __init__(self, env):
        Binv = env.block_inverse()
        if Binv is not None:                      # identity permutations, empty factors
            nf = env.fast.size
            self.Binv = _csr(Binv, complex)
            self.perm_r = self.perm_c = np.arange(nf, dtype=np.int64)
            self.L = self.U = _csr(sp.csr_matrix((1, 1), dtype=complex), complex)
        else:
            lu = spla.splu(env.Bop.tocsc())
            self.L, self.U = _csr(lu.L, complex), _csr(lu.U, complex)
            self.perm_r, self.perm_c = lu.perm_r.astype(np.int64), lu.perm_c.astype(np.int64)
            self.Binv = (np.zeros(1, np.int64), np.zeros(0, np.int64), np.zeros(0, complex))
        self.Z = _csr(env.Z0, complex)
        self.G = _csr(env.G, float)
        self.H = _csr(env.H, float)
        self.Ks, self.Cs = _csr(env.Ks, float), _csr(env.Cs, float)
        self.inv_ms = 1.0 / env.ms if env.slow.size else np.zeros(0)
        self.watch = env.watch.astype(np.int64)
        self.blocks = _envelope_latency.Blocks(env, Binv) if Binv is not None else None
        self.own = _envelope_latency.own_rates(env, Binv) if Binv is not None else None

    def run(self, A, s, sd, nchunks, sub, per, h, F, prow, bound, settle_tol=0.0, check_every=1, settle_from=0,
            parallel=False):
        """nchunks chunks of `sub` steps spanning `per` periods; returns (amp, steps done, status).
        parallel: the rates on all cores (with the block inverse; else serial)."""
        parallel = bool(parallel and self.Binv[0].size > 1)
        amp = np.empty((nchunks * per, prow.size, A.shape[1]), complex)
        done, status = run_steps(A, s, sd, nchunks * sub, sub, per, h, np.ascontiguousarray(F, complex), self.Z, self.G,
                                 self.H, self.Ks, self.Cs, self.inv_ms, self.L, self.U, self.perm_r,
                                 self.perm_c, self.Binv, prow.astype(np.int64), amp, bound, settle_tol,
                                 self.watch, check_every, settle_from, parallel)
        return amp, int(done), int(status)

    def propagators(self, env, h, own: bool = True):
        """The exponential step's exact parts (cached per step): the insulators' propagators over h/2 and h
        and, with `own`, each amplitude's own rate (own_rates); None where the insulators are coupled."""
        cache = self.__dict__.setdefault("_props", {})
        if (h, own) not in cache:
            ins = _envelope_latency.propagators(env, h)
            rates = self.own if own else (np.zeros(1, complex), np.zeros(1, complex))
            cache[h, own] = None if ins is None or rates is None else (*ins, *rates, own)
        return cache[h, own]

    def run_latent(self, A, s, sd, lat, nchunks, sub, per, h, F, prow, bound, settle_tol, check_every, settle_from,
                   tol, hold, lat_check, need, props=None, amp_from: int = 0, need_calm: int | None = None,
                   channels_calm: bool = False, wake_tol: float = -1.0):
        """`run` with per-block latency (_envelope_latency); `lat` (the blocks' latency state) is updated
        in place; props: Kernel.propagators (the exponential step) or None; amp's periods before amp_from
        are not written; need_calm: the quiet checks of a block's own channel (None: need); channels_calm:
        the inputs' calm test on channels only; wake_tol >= 0: the wake-ups' threshold on input channels.
        Returns (amp, steps done, status, block-steps integrated)."""
        amp = np.empty((nchunks * per, prow.size, A.shape[1]), complex)
        expo = props is not None
        Eh, Ef, own0, binv, etd = props if expo else (np.zeros((1, 4)), np.zeros((1, 4)), np.zeros(1, complex),
                                                       np.zeros(1, complex), False)
        active, quiet, snap_f, snap_s, snap_F = lat
        done, status, work = _envelope_latency.run_latent(
            A, s, sd, nchunks * sub, sub, per, h, np.ascontiguousarray(F, complex), self.Z, self.G, self.H,
            self.Ks, self.Cs, self.inv_ms, self.Binv, prow.astype(np.int64), amp, bound, settle_tol, self.watch,
            check_every, settle_from, self.blocks.arrays(), active, quiet, snap_f, snap_s, snap_F, tol, hold,
            lat_check, need, self.blocks.always, expo, Eh, Ef, etd, own0, binv, _envelope_latency.LAMBDA_TOL,
            amp_from, need if need_calm is None else need_calm, channels_calm, wake_tol)
        return amp, int(done), int(status), int(work)


__all__ = ["AVAILABLE", "Kernel", "DONE", "SETTLED", "DIVERGED"]
