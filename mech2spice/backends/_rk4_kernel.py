"""Compiled RK4 inner loop (numba): the same scheme as rk4.py's numpy path, without per-step
Python overhead.  Runs whole drive periods at constant drive amplitudes; rk4.integrate falls back
to numpy for periods in which the stimulus changes, and when numba is missing.

With thermal noise (`noisy`), each step ends with the additive-noise kick of rk4.py's stochastic scheme
(`noise_kick`); without it the loop runs exactly the deterministic arithmetic (bit-identical results).
"""
from __future__ import annotations

import numpy as np

from . import _jit
from ._jit import njit      # numba's njit with a cache concurrent processes cannot corrupt

AVAILABLE = _jit.AVAILABLE     # rk4.py reads it, studies/performance.py sets it False


@njit(cache=True, fastmath=False)
def _accel(x, v, out, Kp, Ki, Kd, Cp, Ci, Cd, inv_m, qf, qs, qg, ddof, damp, dsin):
    n, B = x.shape
    for i in range(n):
        for b in range(B):
            acc = 0.0
            for k in range(Kp[i], Kp[i + 1]):
                acc -= Kd[k] * x[Ki[k], b]
            for k in range(Cp[i], Cp[i + 1]):
                acc -= Cd[k] * v[Ci[k], b]
            out[i, b] = acc
    for q in range(qf.size):
        f, s, g = qf[q], qs[q], qg[q]
        for b in range(B):
            uf = x[f, b]
            out[f, b] -= 2.0 * g * uf * x[s, b]
            out[s, b] -= g * uf * uf
    for d in range(ddof.size):
        for b in range(B):
            out[ddof[d], b] += damp[d, b] * dsin[d]
    for i in range(n):
        for b in range(B):
            out[i, b] *= inv_m[i]


@njit(cache=True, fastmath=False)
def noise_kick(x, v, fw, fz, tmp, Cp, Ci, Cd, inv_m):
    """x += dZ/m, v += dW/m - M^-1 C dZ/m: the noise increments of one step (fw = dW, fz = dZ forces)."""
    n, B = x.shape
    for i in range(n):
        for b in range(B):
            tmp[i, b] = fz[i, b] * inv_m[i]
            x[i, b] += tmp[i, b]
    for i in range(n):
        for b in range(B):
            acc = 0.0
            for k in range(Cp[i], Cp[i + 1]):
                acc += Cd[k] * tmp[Ci[k], b]
            v[i, b] += (fw[i, b] - acc) * inv_m[i]


@njit(cache=True, fastmath=False)
def run_periods(x, v, nper, N, h, Kp, Ki, Kd, Cp, Ci, Cd, inv_m, qf, qs, qg, ddof, damp,
                sin_full, sin_half, dre, dim, pidx, bound, amp_re, amp_im, mean, noisy, fw, fz):
    """Advance nper periods of N steps; fill per-period demodulation; return the index of the first
    period after which |x| exceeded `bound` (or was NaN), else -1.  With `noisy`, step s of period p
    adds the force increments fw[p * N + s], fz[p * N + s] (noise_kick)."""
    n, B = x.shape
    k1 = np.empty_like(x)
    k2 = np.empty_like(x)
    k3 = np.empty_like(x)
    k4 = np.empty_like(x)
    xs = np.empty_like(x)

    v2 = np.empty_like(x)
    v3 = np.empty_like(x)
    v4 = np.empty_like(x)
    np_ = pidx.size
    for p in range(nper):
        for s in range(N):
            _accel(x, v, k1, Kp, Ki, Kd, Cp, Ci, Cd, inv_m, qf, qs, qg, ddof, damp, sin_full[s])
            for i in range(n):
                for b in range(B):
                    xs[i, b] = x[i, b] + 0.5 * h * v[i, b]
                    v2[i, b] = v[i, b] + 0.5 * h * k1[i, b]
            _accel(xs, v2, k2, Kp, Ki, Kd, Cp, Ci, Cd, inv_m, qf, qs, qg, ddof, damp, sin_half[s])
            for i in range(n):
                for b in range(B):
                    xs[i, b] = x[i, b] + 0.5 * h * v2[i, b]
                    v3[i, b] = v[i, b] + 0.5 * h * k2[i, b]
            _accel(xs, v3, k3, Kp, Ki, Kd, Cp, Ci, Cd, inv_m, qf, qs, qg, ddof, damp, sin_half[s])
            for i in range(n):
                for b in range(B):
                    xs[i, b] = x[i, b] + h * v3[i, b]
                    v4[i, b] = v[i, b] + h * k3[i, b]
            _accel(xs, v4, k4, Kp, Ki, Kd, Cp, Ci, Cd, inv_m, qf, qs, qg, ddof, damp, sin_full[s + 1])
            for i in range(n):
                for b in range(B):
                    x[i, b] += (h / 6.0) * (v[i, b] + 2.0 * v2[i, b] + 2.0 * v3[i, b] + v4[i, b])
                    v[i, b] += (h / 6.0) * (k1[i, b] + 2.0 * k2[i, b] + 2.0 * k3[i, b] + k4[i, b])
            if noisy:
                noise_kick(x, v, fw[p * N + s], fz[p * N + s], xs, Cp, Ci, Cd, inv_m)
            for j in range(np_):
                for b in range(B):
                    u = x[pidx[j], b]
                    amp_re[p, j, b] += u * dre[s]
                    amp_im[p, j, b] += u * dim[s]
                    mean[p, j, b] += u
        worst = 0.0
        for i in range(n):
            for b in range(B):
                a = abs(x[i, b])
                if not a < bound:          # catches NaN too
                    return p
                worst = max(worst, a)
    return -1


_NO_NOISE = np.zeros((1, 1, 1))


class Kernel:
    """Arrays the compiled loop needs, built once per model."""

    def __init__(self, model, N: int, h: float, sin_full, sin_half, demod, pidx, bound):
        a = model.arrays
        K, C = model.K.tocsr(), model.C.tocsr()
        self.K = (K.indptr.astype(np.int64), K.indices.astype(np.int64), K.data.astype(np.float64))
        self.C = (C.indptr.astype(np.int64), C.indices.astype(np.int64), C.data.astype(np.float64))
        self.inv_m = 1.0 / a["mass"]
        self.q = (a["quad_fast"].astype(np.int64), a["quad_slow"].astype(np.int64), a["quad_gamma"])
        self.ddof = a["drive_dof"].astype(np.int64)
        self.sin_full = np.ascontiguousarray(sin_full[:, :, 0])
        self.sin_half = np.ascontiguousarray(sin_half[:, :, 0])
        self.dre, self.dim = np.ascontiguousarray(demod.real), np.ascontiguousarray(demod.imag)
        self.pidx = pidx.astype(np.int64)
        self.N, self.h, self.bound = N, h, bound

    def run(self, x, v, amps, nper, noise=None):
        """Advance x, v in place by nper periods; return (per-period probe amplitudes, means, first bad period or -1).

        noise: (dW, dZ) force increments, each (nper * N, n, B), or None (deterministic)."""
        B = x.shape[1]
        fw, fz = noise if noise is not None else (_NO_NOISE, _NO_NOISE)
        amp_re = np.zeros((nper, self.pidx.size, B))
        amp_im = np.zeros_like(amp_re)
        mean = np.zeros_like(amp_re)
        bad = run_periods(x, v, nper, self.N, self.h, *self.K, *self.C, self.inv_m, *self.q, self.ddof,
                          np.ascontiguousarray(amps, dtype=np.float64), self.sin_full, self.sin_half,
                          self.dre, self.dim, self.pidx, self.bound, amp_re, amp_im, mean,
                          noise is not None, fw, fz)
        return (amp_re + 1j * amp_im) * (2.0 / self.N), mean / self.N, bad
