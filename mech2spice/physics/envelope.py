"""Slowly-varying amplitude (envelope) equations, generated from the mechanical model.

Each oscillating DOF is written u = Re(A e^{i omega t}) with A slowly varying;
slow DOFs (insulators) keep their own real coordinate s.  Averaging over one
drive period (dropping the 2*omega part of u^2 and terms of order A'') gives

    (2 i omega M + C) A' = F^ - Z0 A - (G s) * A         Z0 = K - omega^2 M + i omega C  (fast block)
    M_s s'' = -K_s s - C_s s' - H |A|^2 / 2

with F^ = -i a e^{i phase} for a drive a sin(omega t + phase), G[f, s] = 2 gamma
and H[s, f] = gamma for every quadratic coupling.  The same equations give the
paper's semi-analytic steady state (A' = 0, s' = 0) and its linear stability.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import Mech2SpiceError
from .model import MechModel


class Envelope:
    def __init__(self, model: MechModel):
        model.check()
        a = model.arrays
        self.model = model
        self.omega = w = model.omega
        self.fast = np.flatnonzero(~a["slow"])
        self.slow = np.flatnonzero(a["slow"])
        pos_f = -np.ones(model.n, int)
        pos_f[self.fast] = np.arange(self.fast.size)
        pos_s = -np.ones(model.n, int)
        pos_s[self.slow] = np.arange(self.slow.size)
        self._check_links(model, a["slow"])

        K, C = model.K.tocsr(), model.C.tocsr()
        Kff, Cff = K[self.fast][:, self.fast], C[self.fast][:, self.fast]
        Mf = sp.diags(a["mass"][self.fast])
        self.Z0 = (Kff - w * w * Mf + 1j * w * Cff).tocsc()
        self.Bop = (2j * w * Mf + Cff).tocsc()
        self._Bsolve = spla.factorized(self.Bop)
        self.z0_diag = self.Z0.diagonal()
        self.diagonal = self.Z0.nnz == self.fast.size      # no fast-fast couplings

        qf, qs, g = pos_f[a["quad_fast"]], pos_s[a["quad_slow"]], a["quad_gamma"]
        nf, ns = self.fast.size, self.slow.size
        self.G = sp.csr_matrix((2 * g, (qf, qs)), shape=(nf, ns))
        self.H = sp.csr_matrix((g, (qs, qf)), shape=(ns, nf))
        self.ms = a["mass"][self.slow]
        # sparse: a dense slow block made every step O(n_slow^2) (reports/performance.md)
        self.Ks = K[self.slow][:, self.slow].tocsr()
        self.Cs = C[self.slow][:, self.slow].tocsr()

        dof = a["drive_dof"]
        if np.any(a["slow"][dof]):
            raise Mech2SpiceError("the envelope model cannot drive a slow DOF at omega")
        # settle detection watches the channels (the logic signals): gate oscillators ring in slow,
        # lightly damped gate-insulator modes that change no logic level (reports/envelope.md)
        gates = model.design.gates
        self.watch = pos_f[[g.channel for g in gates]] if gates else np.arange(nf)
        self.Dmap = sp.csr_matrix((-1j * np.exp(1j * a["drive_phase"]),
                                   (pos_f[dof], np.arange(dof.size))), shape=(nf, dof.size))

    @staticmethod
    def _check_links(model: MechModel, slow: np.ndarray) -> None:
        for i, j, _ in model.springs + model.dashpots:
            if slow[i] != slow[j]:
                raise Mech2SpiceError(
                    f"link between oscillating '{model.names[i]}' and slow '{model.names[j]}' "
                    "has no envelope form")

    @classmethod
    def of(cls, model: MechModel) -> "Envelope":
        """The model's envelope operator, built once (it factorises a sparse matrix); the model drops it
        when edited."""
        env = model.derived.get("envelope")
        if env is None:
            env = model.derived["envelope"] = cls(model)
        return env

    def kernel(self):
        """The compiled loop's arrays (envelope_kernel.Kernel), built once."""
        if getattr(self, "_kernel", None) is None:
            from ..backends._envelope_kernel import Kernel
            self._kernel = Kernel(self)
        return self._kernel

    def block_inverse(self, max_block: int = 64):
        """Bop^-1 as a sparse matrix when Bop's connected blocks are small (a channel and the dashpot
        gates it drives), else None.  Cached."""
        if not hasattr(self, "_binv"):
            from scipy.sparse.csgraph import connected_components
            n, label = connected_components(abs(self.Bop), directed=False)
            sizes = np.bincount(label, minlength=n)
            self._binv = None
            if sizes.size == 0 or sizes.max() <= max_block:
                B = self.Bop.tocsr()
                rows, cols, vals = [], [], []
                order = np.argsort(label, kind="stable")
                for idx in np.split(order, np.cumsum(sizes)[:-1]):
                    inv = np.linalg.inv(B[idx][:, idx].toarray())
                    rows.append(np.repeat(idx, idx.size))
                    cols.append(np.tile(idx, idx.size))
                    vals.append(inv.ravel())
                nf = self.fast.size
                self._binv = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                                           shape=(nf, nf)) if nf else None
        return self._binv

    # --- pieces --------------------------------------------------------------
    def forcing(self, amps: np.ndarray) -> np.ndarray:
        """Complex forcing F^ (n_fast, B) from drive amplitudes (n_drives, B)."""
        return self.Dmap @ np.asarray(amps, float).reshape(len(self.model.drives), -1)

    def residual_fast(self, A, s, F):
        return F - self.Z0 @ A - (self.G @ s) * A

    def slow_force(self, A):
        return -(self.H @ (np.abs(A) ** 2)) / 2

    def rhs(self, A, s, sd, F):
        """Time derivatives (A', s', s'') for states of shape (n_fast, B), (n_slow, B)."""
        Ad = self._Bsolve(self.residual_fast(A, s, F))
        sdd = (self.slow_force(A) - self.Ks @ s - self.Cs @ sd) / self.ms[:, None]   # no negated matrix copies
        return Ad, sd, sdd

    def fast_response(self, s: np.ndarray, F: np.ndarray) -> np.ndarray:
        """A solving Z(s) A = F for one slow state s (n_slow,) and forcing F (n_fast,)."""
        if self.diagonal:
            return F / (self.z0_diag + self.G @ s)
        Z = (self.Z0 + sp.diags(self.G @ s)).tocsc()
        return spla.spsolve(Z, F)

    # --- real-vector form for Jacobians --------------------------------------
    def pack(self, A, s, sd) -> np.ndarray:
        return np.concatenate([A.real, A.imag, s, sd])

    def unpack(self, y):
        nf, ns = self.fast.size, self.slow.size
        return (y[:nf] + 1j * y[nf:2 * nf]), y[2 * nf:2 * nf + ns], y[2 * nf + ns:]

    def rhs_real(self, y: np.ndarray, F: np.ndarray) -> np.ndarray:
        A, s, sd = self.unpack(y)
        Ad, sd_, sdd = self.rhs(A[:, None], s[:, None], sd[:, None], F[:, None])
        return self.pack(Ad[:, 0], sd_[:, 0], sdd[:, 0])

    def jacobian(self, y: np.ndarray, F: np.ndarray) -> np.ndarray:
        """Central finite-difference Jacobian of the real envelope equations."""
        J = np.empty((y.size, y.size))
        scale = np.maximum(np.abs(y), 1e-6 * max(np.abs(y).max(), 1e-12))
        for k in range(y.size):
            e = np.zeros_like(y)
            e[k] = 1e-6 * scale[k]
            J[:, k] = (self.rhs_real(y + e, F) - self.rhs_real(y - e, F)) / (2 * e[k])
        return J


# --- time integration of the envelope equations ---------------------------------
RK4_STABILITY = 2.5          # |lambda h| RK4 keeps stable (its region reaches ~2.8 on both axes)


RATE_SAFETY = 1.5            # x the largest |eigenvalue| at rest: along switching trajectories it moved by
                             # <= 3 % (reports/envelope.md), so this leaves a wide margin


def gershgorin_rate(env: Envelope, s_max: float = 0.5) -> float:
    """Upper bound (Gershgorin) on |eigenvalue| of the envelope equations' linear part, with the slow
    DOFs displaced by up to s_max.  Safe but ~3.5x above the true rate (reports/envelope.md)."""
    Bd = np.abs(env.Bop.diagonal())
    Zrow = np.asarray(abs(env.Z0).sum(axis=1)).ravel() + np.asarray(abs(env.G).sum(axis=1)).ravel() * s_max
    fast = float((Zrow / Bd).max()) if Bd.size else 0.0
    return max(fast, _slow_rate_bound(env))


def _slow_rate_bound(env: Envelope) -> float:
    if not env.slow.size:
        return 0.0
    return float(np.max(np.sqrt(np.abs(env.Ks.diagonal()) / env.ms) + np.abs(env.Cs.diagonal()) / env.ms))


def spectral_rate(env: Envelope) -> float | None:
    """The largest |eigenvalue| of the linear part at rest: ARPACK on A' = -Bop^-1 Z0 A for the amplitudes,
    exact roots for the insulators (each its own damped oscillator when Ks, Cs are diagonal).  None if
    ARPACK does not converge or the slow block is coupled."""
    slow = 0.0
    if env.slow.size:
        if env.Ks.nnz > env.slow.size or env.Cs.nnz > env.slow.size:
            return None
        k, c, m = env.Ks.diagonal(), env.Cs.diagonal(), env.ms
        slow = float(np.max(np.abs(np.stack([(-c + s * np.sqrt(c * c - 4 * k * m + 0j)) / (2 * m)
                                              for s in (1, -1)]))))
    nf = env.fast.size
    if nf == 0:
        return slow
    op = spla.LinearOperator((nf, nf), matvec=lambda x: -env._Bsolve(env.Z0 @ x), dtype=complex)
    try:
        if nf < 3:
            lam = np.linalg.eigvals(np.column_stack([op.matvec(e) for e in np.eye(nf, dtype=complex)]))
        else:
            lam = spla.eigs(op, k=1, which="LM", v0=np.ones(nf, complex), tol=1e-4, maxiter=5000,
                            return_eigenvectors=False)
    except spla.ArpackNoConvergence:
        return None
    return max(slow, float(np.abs(lam).max()))


def rate_bound(env: Envelope) -> float:
    """The envelope rate the step limit uses: RATE_SAFETY x the spectral rate (Gershgorin where that
    cannot be computed).  Cached on the Envelope."""
    if getattr(env, "_rate", None) is None:
        rho = spectral_rate(env)
        env._rate = RATE_SAFETY * rho if rho is not None else gershgorin_rate(env)
    return env._rate


def max_step_periods(model: MechModel) -> float:
    env = Envelope.of(model)
    return RK4_STABILITY / rate_bound(env) / (2 * np.pi / env.omega)


SETTLE_WINDOW = 200          # periods: more than one gate delay (173 mean, 224 max: reports/gate.md), so
                             # a signal in flight moves some channel by a large part of a band per window
SETTLE_MIN = 400             # periods after a stimulus change before a window counts: an input change
                             # first moves gate oscillators and insulators, not yet channels
CHUNK_PERIODS = 2000         # periods per compiled call: bounds the progress-bar and Ctrl-C latency


def integrate(model: MechModel, periods: int, *, step_periods: float = 0.5, stimulus=None, state=None,
              start_period: int = 0, probes: list[str] | None = None, progress: bool = False,
              settle: float | None = None, compiled: bool = True):
    """RK4 on the envelope equations with a step of `step_periods` drive periods (must divide 1 or be whole).

    Returns an rk4.Run whose per-period amplitudes are the envelope itself.  A step beyond the measured
    stability bound is refused.  With `settle` (u_R), each stretch of constant stimulus ends once every
    channel's amplitude stayed within a range of `settle` for two SETTLE_WINDOWs in a row: the rest of
    the stretch is the settled state, held (idle-time skipping; the slow small ringing this ignores and
    its error are measured in reports/fidelity.md).  compiled=True uses the numba loop
    (envelope_kernel.py) where numba exists."""
    from ..backends import _envelope_kernel as envelope_kernel
    from ..backends.rk4 import Run, _progress
    from .stimulus import Stimulus
    env = Envelope.of(model)
    T = 2 * np.pi / env.omega
    _check_step(env, step_periods, T)
    sub, per = _step_layout(step_periods)
    h = T * per / sub
    stimulus = stimulus or Stimulus.constant(model)
    B = stimulus.batch
    nf, ns = env.fast.size, env.slow.size
    A, s, sd = (np.zeros((nf, B), complex), np.zeros((ns, B)), np.zeros((ns, B))) if state is None else \
        (state[0].copy(), state[1].copy(), state[2].copy())
    names = list(probes or model.probes)
    prow = _probe_rows(model, env, names)
    amp = np.zeros((periods, len(names), B), complex)
    tol = settle * model.params.u_r if settle else 0.0
    check = sub * max(1, int(round(SETTLE_WINDOW / per)))
    kern = env.kernel() if compiled and envelope_kernel.AVAILABLE else None
    bound = 1e3 * model.params.u_r
    settled_periods = 0
    bar = _progress(periods, progress)
    k, seg_now, since = 0, None, 0
    while k < periods:
        t = (start_period + k) * T
        F = env.forcing(stimulus.at(t + 1e-9 * h))
        if stimulus.segment(t + 1e-9 * h) != seg_now:
            seg_now, since = stimulus.segment(t + 1e-9 * h), 0
        settle_from = max(0, SETTLE_MIN - since) // per * sub
        # chunks until the stimulus next changes (F is read at each chunk's start)
        span = min(stimulus.next_change(t + 1e-9 * h) - t, periods * T)
        to_change = min(-(-(periods - k) // per), max(1, int(np.ceil(span / (per * T) - 1e-9))))
        nchunks = min(to_change, max(1, CHUNK_PERIODS // per))
        if kern is not None:
            seg, done, status = kern.run(A, s, sd, nchunks, sub, per, h, F, prow, bound, tol, check, settle_from)
        else:
            seg, done, status = _numpy_chunks(env, A, s, sd, nchunks, sub, per, h, F, prow, bound, tol, check,
                                              settle_from)
        if status == envelope_kernel.DIVERGED:
            _check(model, env, A, t + (done + 1) * h, T)
        n = min(nchunks * per, periods - k)
        amp[k:k + n] = seg[:n]
        if status == envelope_kernel.SETTLED:        # hold the settled state up to the stimulus change
            got = done // sub * per
            n = min(to_change * per, periods - k)
            amp[k + got:k + n] = A[prow]
            settled_periods += n - got
        k += n
        since += n
        bar.update(n)
    bar.close()
    t_end = (start_period + 1 + np.arange(periods)) * T
    run = Run(names, T, t_end, amp, np.zeros(amp.shape), None, None, (start_period + periods) * T)
    run.extra["envelope_state"] = (A, s, sd)
    run.extra["settled_periods"] = settled_periods
    return run


def _check_step(env: Envelope, step_periods: float, T: float) -> None:
    limit = RK4_STABILITY / rate_bound(env) / T
    if step_periods > limit:
        raise Mech2SpiceError(f"envelope step {step_periods:g} periods exceeds the stability limit "
                              f"{limit:.3g} periods for this network (fastest envelope rate "
                              f"{rate_bound(env):.3g} 1/s)")


def _probe_rows(model: MechModel, env: Envelope, names: list[str]) -> np.ndarray:
    """Rows of the fast block for probe names or DOF names."""
    pos = {d: k for k, d in enumerate(env.fast)}
    return np.array([pos[model.probes[n] if n in model.probes else model.index(n)] for n in names], int)


def _numpy_chunks(env, A, s, sd, nchunks, sub, per, h, F, prow, bound, tol, check, settle_from):
    """The compiled loop's contract in numpy (used without numba); updates A, s, sd in place."""
    from ..backends import _envelope_kernel as envelope_kernel
    amp = np.zeros((nchunks * per, prow.size, A.shape[1]), complex)
    w, quiet = env.watch, 0
    lo = hi = np.abs(A[w])
    for n in range(nchunks * sub):
        if tol and n % check == 0:
            if n >= settle_from + check:
                quiet = quiet + 1 if (hi - lo).max(initial=0) < tol else 0
                if quiet >= 2:
                    return amp, n, envelope_kernel.SETTLED
            lo = hi = np.abs(A[w])
        A[:], s[:], sd[:] = _rk4_step(env, A, s, sd, F, h)
        if not np.all(np.abs(A) < bound):
            return amp, n, envelope_kernel.DIVERGED
        lo, hi = np.minimum(lo, np.abs(A[w])), np.maximum(hi, np.abs(A[w]))
        if (n + 1) % sub == 0:
            c = (n + 1) // sub - 1
            amp[c * per:(c + 1) * per] = A[prow]
    return amp, nchunks * sub, envelope_kernel.DONE


def _step_layout(step_periods: float) -> tuple[int, int]:
    """(substeps per chunk, periods per chunk): steps either divide one period or span whole periods,
    so stimulus changes (at whole periods) fall on step boundaries."""
    if step_periods >= 1:
        if abs(step_periods - round(step_periods)) > 1e-9:
            raise Mech2SpiceError("an envelope step longer than one period must be a whole number of periods")
        return 1, int(round(step_periods))
    sub = int(round(1 / step_periods))
    if abs(sub * step_periods - 1) > 1e-9:
        raise Mech2SpiceError("an envelope step shorter than one period must divide it (1/2, 1/4, ...)")
    return sub, 1


def _check(model: MechModel, env: Envelope, A: np.ndarray, t: float, T: float) -> None:
    from ..errors import DivergenceError
    mag = np.abs(A).max(axis=1)
    bad = ~np.isfinite(mag) | (mag > 1e3 * model.params.u_r)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise DivergenceError(model.names[env.fast[i]], t, T, float(mag[i]))


def _rk4_step(env: Envelope, A, s, sd, F, h):
    a1, b1, c1 = env.rhs(A, s, sd, F)
    a2, b2, c2 = env.rhs(A + 0.5 * h * a1, s + 0.5 * h * b1, sd + 0.5 * h * c1, F)
    a3, b3, c3 = env.rhs(A + 0.5 * h * a2, s + 0.5 * h * b2, sd + 0.5 * h * c2, F)
    a4, b4, c4 = env.rhs(A + h * a3, s + h * b3, sd + h * c3, F)
    return (A + h / 6 * (a1 + 2 * a2 + 2 * a3 + a4), s + h / 6 * (b1 + 2 * b2 + 2 * b3 + b4),
            sd + h / 6 * (c1 + 2 * c2 + 2 * c3 + c4))
