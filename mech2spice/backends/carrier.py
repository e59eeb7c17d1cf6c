"""The carrier engine: oscillator-level integration with the linear oscillators propagated exactly (Lawson RK4).

Every DOF's own linear oscillator  m x'' + c x' + k x  (its total stiffness and damping, the diagonal of
K and C) is stepped by its exact 2x2 propagator E(t) = exp(L t),  L = [[0, 1], [-k/m, -c/m]].  What is
left, the coupling springs and dashpots, the quadratic couplings and the drives, is the explicit part
g(t, y) = (0, f(t, x, v) / m), and classical RK4 is applied to the transformed variable z = E(-t) y
(the integrating-factor or Lawson RK4 scheme: J. D. Lawson, SIAM J. Numer. Anal. 4, 372 (1967);
Hochbruck & Ostermann, Acta Numerica 19, 209 (2010), Sec. 2.6).  In that frame the carrier has been
taken out: the explicit forces, seen through E(-t), vary at the beat between drive and resonance and at
twice the drive frequency (the quadratic terms' DC and 2-omega content), not at the carrier's full rate,
so a step of T/10 keeps RK4's accuracy at T/160 where plain RK4 needs T/80 (reports/speed_accuracy.md).
The scheme is exact for uncoupled linear oscillators at any step and reduces to classical RK4 when
every propagator is the identity.

One step, with Eh = E(h/2), E1 = E(h), a_k the explicit accelerations of stage k:

    y2 = Eh (y + h/2 g1)             y3 = Eh y + h/2 g2           y4 = E1 y + h Eh g3
    y+ = E1 (y + h/6 g1) + h/3 Eh (g2 + g3) + h/6 g4

Each probe's amplitude at the drive frequency is the period's trapezoid-rule Fourier coefficient (second
order in the step, where RK4's end-point sum is first order: a difference of 1e-4 u_R on a switching gate
at 160 steps).  Idle time (`settle_tol`) is skipped as in the envelope engine: once every channel's
amplitude stayed within `settle_tol` for two windows, the state at the period boundary is held (a
settled orbit is periodic, so whole periods leave it unchanged) until the stimulus next changes.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..errors import Mech2SpiceError
from ..inputs import check_fields
from ..physics.model import MechModel
from ..physics.stimulus import Stimulus
from . import _carrier_kernel as kernel
from . import _carrier_latency as latent
from ..run_result import Run, blowup_bound, check_divergence
from ._base import (Capabilities, Engine, oscillator_phasors, probe_dofs, progress_bar,
                    refuse_circuit_flags, speed_flags, watched_dofs)
from .envelope import SETTLE_MIN, SETTLE_WINDOW

DEFAULT_STEPS_PER_PERIOD = 12    # as accurate as RK4 at 160 steps on a switching gate; within 4e-4 u_R of it on
                                 # the adder's 16 inputs (10 steps: 8.6e-4; reports/carrier.md)
CHUNK_PERIODS = 200              # periods per compiled call: bounds the progress-bar and Ctrl-C latency


def propagators(mkc: np.ndarray, h: float) -> np.ndarray:
    """(4, n): the entries xx, xv, vx, vv of the exact propagator exp(L h) of each linear oscillator,
    given (mass, stiffness, damping) as the rows of `mkc` (n, 3).

    exp(L h) = e^{mu h} [cosh(nu h) I + sinh(nu h)/nu (L - mu I)],  mu = -c/2m,  nu = sqrt(mu^2 - k/m),
    real for every damping (nu is imaginary below critical damping); sinh(nu h)/nu -> h as nu -> 0."""
    k, c = mkc[:, 1] / mkc[:, 0], mkc[:, 2] / mkc[:, 0]
    mu = -0.5 * c                                   # L - mu I = [[-mu, 1], [-k, mu]]
    nu = np.sqrt((mu * mu - k).astype(complex))
    ch = np.cosh(nu * h).real
    small = np.abs(nu * h) < 1e-8
    sh = np.where(small, h, np.sinh(nu * h) / np.where(small, 1.0, nu)).real
    g = np.exp(mu * h)
    return np.array([g * (ch - mu * sh), g * sh, g * (-k * sh), g * (ch + mu * sh)])


class Operator:
    """The arrays the compiled loop reads, built once per model and step (model.derived caches it).

    The loop numbers the DOFs (`order`: loop index -> model DOF; `pos`: the inverse) by kind (same mass,
    stiffness, damping and slowness: a gate's channel, insulator, gate oscillators), then by whether a
    drive acts on them and by their numbers of couplings and quadratic partners.  One row of propagator
    entries then serves each contiguous kind (`seg`), and each group of equal counts (`groups`) stores its
    partners column by column, so the loop's inner trip counts are constant over long runs
    (_carrier_kernel.py)."""

    def __init__(self, model: MechModel, N: int):
        a = model.arrays
        self.n, self.N, self.h = model.n, N, model.period / N
        kinds, kind = np.unique(np.stack([a["mass"], a["k_total"], a["c_total"], a["slow"]], 1), axis=0,
                                return_inverse=True)
        kind = kind.ravel()
        coupling = self._couplings(model)
        partners = self._partners(model)
        driven = np.zeros(model.n, bool)
        driven[a["drive_dof"]] = True
        wc, wq = np.diff(coupling.indptr), np.diff(partners.indptr)
        self.order = np.lexsort((np.arange(model.n), wq, wc, driven, kind))
        self.pos = np.empty(model.n, np.int64)
        self.pos[self.order] = np.arange(model.n)
        self.seg = np.searchsorted(kind[self.order], np.arange(len(kinds) + 1)).astype(np.int64)
        self.inv_m = 1.0 / kinds[:, 0]
        self.E = np.ascontiguousarray(propagators(kinds, self.h).T)
        self.H = np.ascontiguousarray(propagators(kinds, self.h / 2).T)
        key = np.stack([kind, driven, wc, wq], 1)[self.order]
        self.groups, self.ell = self._ell(key, kinds[:, 3], coupling[self.order][:, self.order].tocsr(),
                                          partners[self.order][:, self.order].tocsr())
        self.gkind = (np.searchsorted(self.seg, self.groups[:, 0], side="right") - 1).astype(np.int64)
        w, t = model.omega, self.h * np.arange(N)[:, None] + self.h * np.array([0.0, 0.5, 1.0])
        self.trig = np.ascontiguousarray(np.stack([np.sin(w * t[:, 0]), np.cos(w * t[:, 0]),
                                                   np.sin(w * t[:, 1]), np.cos(w * t[:, 1]),
                                                   np.sin(w * t[:, 2]), np.cos(w * t[:, 2])], axis=1))
        self.demod = np.exp(-1j * w * self.h * np.arange(1, N + 1))
        self.drive_dof = self.pos[a["drive_dof"]]
        self.drive_cos, self.drive_sin = np.cos(a["drive_phase"]), np.sin(a["drive_phase"])

    @staticmethod
    def _couplings(model: MechModel) -> sp.csr_matrix:
        """Off-diagonal springs and dashpots as one complex matrix k_ij + i c_ij: force on i = sum k_ij x_j + c_ij v_j."""
        n = model.n
        if not (model.springs or model.dashpots):
            return sp.csr_matrix((n, n), dtype=complex)
        off = -(model.K - sp.diags(model.K.diagonal())) - 1j * (model.C - sp.diags(model.C.diagonal()))
        off = sp.csr_matrix(off)
        off.eliminate_zeros()
        return off

    @staticmethod
    def _partners(model: MechModel) -> sp.csr_matrix:
        """The quadratic couplings V = gamma u_f^2 u_s as a matrix of force coefficients: on the fast DOF
        -x_f sum 2 gamma x_s (entry (f, s) = 2 gamma), on the slow one -sum gamma x_f^2 (entry (s, f) = gamma)."""
        a, n = model.arrays, model.n
        f, s, g = a["quad_fast"], a["quad_slow"], a["quad_gamma"]
        return sp.csr_matrix((np.concatenate([2 * g, g]), (np.concatenate([f, s]), np.concatenate([s, f]))),
                             shape=(n, n))

    @staticmethod
    def _ell(key: np.ndarray, slow_kind: np.ndarray, coupling: sp.csr_matrix, partners: sp.csr_matrix):
        """groups (lo, hi, wc, wq, coupling base, partner base, slow, driven) and the column-major partner
        arrays (Ci, Ck, Cd, Qi, Qg) of each run of equal key (kind, driven, wc, wq)."""
        starts = np.flatnonzero(np.r_[True, np.any(key[1:] != key[:-1], axis=1)])
        ends = np.r_[starts[1:], len(key)]
        groups, Ci, Ck, Qi, Qg = [], [], [], [], []
        nc = nq = 0
        for lo, hi in zip(starts, ends):
            kd, drv, wc, wq = key[lo]
            groups.append((lo, hi, wc, wq, nc, nq, int(slow_kind[kd]), drv))
            for mat, width, idx, val in ((coupling, wc, Ci, Ck), (partners, wq, Qi, Qg)):
                rows = mat.indptr[lo:hi]
                for k in range(width):
                    idx.append(mat.indices[rows + k])
                    val.append(mat.data[rows + k])
            nc, nq = nc + wc * (hi - lo), nq + wq * (hi - lo)
        cat = lambda parts, dt: np.ascontiguousarray(np.concatenate(parts).astype(dt)) if parts else np.zeros(0, dt)
        ck = cat(Ck, complex)
        return (np.array(groups, np.int64).reshape(-1, 8),
                (cat(Ci, np.int32), np.ascontiguousarray(ck.real), np.ascontiguousarray(ck.imag),
                 cat(Qi, np.int32), cat(Qg, float)))

    def to_loop(self, state: np.ndarray) -> np.ndarray:
        """(n, B) model-numbered values -> the loop's (B, n) rows."""
        return np.ascontiguousarray(np.asarray(state, float).T[:, self.order])

    def from_loop(self, rows: np.ndarray) -> np.ndarray:
        """The loop's (B, n) rows -> (n, B) model-numbered values."""
        out = np.empty((self.n, rows.shape[0]))
        out[self.order] = rows.T
        return out

    def drive_weights(self, amps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(P, Q), each (B, n): the drive force on each DOF is P sin(omega t) + Q cos(omega t)."""
        P, Q = np.zeros((self.n, amps.shape[1])), np.zeros((self.n, amps.shape[1]))
        np.add.at(P, self.drive_dof, amps * self.drive_cos[:, None])     # several drives may share a DOF
        np.add.at(Q, self.drive_dof, amps * self.drive_sin[:, None])
        return np.ascontiguousarray(P.T), np.ascontiguousarray(Q.T)

    def cuts(self, threads: int) -> np.ndarray:
        """DOF range boundaries of each thread's share of a pass."""
        return np.linspace(0, self.n, max(1, threads) + 1).astype(np.int64)


def operator(model: MechModel, N: int) -> Operator:
    """The model's operator for N steps per period, cached with the model."""
    key = ("carrier", N)
    op = model.derived.get(key)
    if op is None:
        op = model.derived[key] = Operator(model, N)
    return op


def blocks(model: MechModel, op: Operator) -> latent.Blocks:
    """The model's gate blocks in the operator's numbering (latency), cached with the model."""
    key = ("carrier-blocks", op.N)
    blk = model.derived.get(key)
    if blk is None:
        blk = model.derived[key] = latent.Blocks(model, op)
    return blk


@np.errstate(over="ignore", invalid="ignore")
def integrate(model: MechModel, periods: int, *, steps_per_period: int = DEFAULT_STEPS_PER_PERIOD,
              stimulus: Stimulus | None = None, state=None, start_period: int = 0, probes=None,
              progress: bool = False, settle_tol: float | None = None, threads: int = 1,
              latency: float | None = None) -> Run:
    """Lawson RK4 over `periods` drive periods from `start_period` (from rest unless `state` = (x, v), each (n, B)).

    Stimulus changes must fall on whole periods.  settle_tol (u_R): skip idle time (module doc).
    latency (u_R): freeze settled gate blocks until an input channel moves by more than this
    (_carrier_latency.py, one thread); the state then carries the blocks' latency record too."""
    if not kernel.AVAILABLE:
        raise Mech2SpiceError("the carrier engine needs numba (pip install numba)")
    model.check()
    stimulus = stimulus or Stimulus.constant(model)
    B, N, T = stimulus.batch, int(steps_per_period), model.period
    op = operator(model, N)
    names = list(probes or model.probes)
    pidx = op.pos[probe_dofs(model, names)]
    widx = op.pos[watched_dofs(model)]
    X, V = _start(model, op, state, B)
    lat = _latency(model, op, state, B, pidx, widx) if latency else None
    amp = np.empty((periods, len(names), B), complex)
    mean = np.empty((periods, len(names), B))
    tol = settle_tol * model.amplitude_unit if settle_tol else 0.0
    bound, cuts = blowup_bound(model), op.cuts(threads)
    settled, k, since, seg_now = 0, 0, 0, None
    work = np.zeros(1, np.int64)                     # active blocks x steps (latency)
    bar = progress_bar(periods, progress)
    with _numba_threads(threads):
        while k < periods:
            t = (start_period + k) * T
            seg = stimulus.segment(t + 1e-9 * T)
            if seg != seg_now:                       # a new stretch of constant stimulus: fresh settle windows
                seg_now, since = seg, 0
                watch = (np.full((widx.size, B), np.inf), np.zeros((widx.size, B)), np.zeros(B, np.int64))
            to_change = _periods_to_change(stimulus, t, T, periods - k)
            n = min(to_change, CHUNK_PERIODS)
            P, Q = op.drive_weights(stimulus.at(t + 1e-9 * T))
            common = (X, V, n, N, op.h, P, Q)
            tail = (op.trig, op.demod, pidx, widx, bound, tol, SETTLE_WINDOW, SETTLE_MIN, since, watch,
                    amp[k:k + n], mean[k:k + n])
            if lat is None:
                done, status = kernel.run_periods(*common, op.seg, op.inv_m, op.E, op.H, op.groups, *op.ell, *tail,
                                                  cuts)
            else:
                done, status = latent.run_periods(*common, op.gkind, op.inv_m, op.E, op.H, op.groups, *op.ell, *tail,
                                                  *lat[0], latency * model.amplitude_unit, latent.WINDOW_PERIODS,
                                                  lat[1], *lat[2], work)
            if status == kernel.DIVERGED:
                check_divergence(model, op.from_loop(X), t + (done + 1) * T, bound=bound)
            if status == kernel.SETTLED:         # hold the settled orbit up to the stimulus change
                n = to_change
                amp[k + done:k + n], mean[k + done:k + n] = amp[k + done - 1], mean[k + done - 1]
                settled += n - done
            k, since = k + n, since + n
            bar.update(n)
    bar.close()
    x, v = op.from_loop(X), op.from_loop(V)
    t_end = (start_period + 1 + np.arange(periods)) * T
    out_state = (x, v) if lat is None else (x, v, *lat[2])
    return Run(names, T, t_end, amp, mean, x, v, (start_period + periods) * T, state=out_state,
               settled_periods=settled, extra={"steps_per_period": N, **({"block_steps": int(work[0])} if lat else {})})


def _latency(model: MechModel, op: Operator, state, B: int, pidx, widx):
    """(the blocks' arrays, the tracked-DOF mask, the latency record): the record the state carries (copied),
    or a fresh one with every block active."""
    blk = blocks(model, op)
    track = np.zeros(op.n, np.bool_)
    track[blk.channel], track[pidx], track[widx] = True, True, True
    fresh = blk.fresh_record(B, op.N, op.n)
    if state is not None and len(state) == 2 + len(fresh) and all(
            np.shape(a) == f.shape for a, f in zip(state[2:], fresh)):
        record = tuple(np.array(a, dtype=f.dtype) for a, f in zip(state[2:], fresh))
    else:
        record = fresh
    return blk.arrays(), track, record


def _start(model: MechModel, op: Operator, state, B: int) -> tuple[np.ndarray, np.ndarray]:
    """The loop's (B, n) state arrays: at rest, or the given (x, v), each (n, B)."""
    if state is None:
        return np.zeros((B, model.n)), np.zeros((B, model.n))
    x, v = (np.asarray(s, float) for s in state[:2])
    if x.shape != (model.n, B) or v.shape != (model.n, B):
        raise Mech2SpiceError(f"carrier state of shape {x.shape} does not fit this model and batch "
                              f"({model.n} DOFs, {B} members)")
    return op.to_loop(x), op.to_loop(v)


def _periods_to_change(stimulus: Stimulus, t: float, T: float, left: int) -> int:
    """Whole periods until the stimulus next changes (at most `left`); a change inside a period is refused."""
    span = (stimulus.next_change(t + 1e-9 * T) - t) / T
    if not np.isfinite(span) or span >= left:
        return left
    whole = round(span)
    if abs(span - whole) > 1e-6 or whole < 1:
        raise Mech2SpiceError(f"the carrier engine steps whole drive periods: a stimulus change at "
                              f"{t / T + span:.4g} periods does not fall on one")
    return int(whole)


class _numba_threads:
    """Run the block on `threads` numba threads, restoring the count after."""

    def __init__(self, threads: int):
        self.threads = threads

    def __enter__(self):
        if self.threads > 1:
            import numba
            self.before = numba.get_num_threads()
            numba.set_num_threads(min(self.threads, numba.config.NUMBA_NUM_THREADS))

    def __exit__(self, *exc):
        if self.threads > 1:
            import numba
            numba.set_num_threads(self.before)


@dataclass(frozen=True)
class CarrierOptions:
    """Settings of the carrier engine."""
    steps_per_period: int = DEFAULT_STEPS_PER_PERIOD
    settle_tol: float | None = None      # u_R; None: integrate every period (no idle skipping)
    threads: int = 1                     # >1: each pass's DOFs split over numba's thread pool
    latency: float | None = None         # u_R; None: integrate every gate at every step (_carrier_latency.py)

    def __post_init__(self):
        self.validate()              # a bad value fails where it is set, not later inside a run

    def validate(self) -> None:
        """Refuse steps, tolerances and thread counts the engine cannot take."""
        check_fields(self)
        if isinstance(self.steps_per_period, bool) or int(self.steps_per_period) != self.steps_per_period \
                or self.steps_per_period < 4:
            raise Mech2SpiceError("the carrier engine needs a whole number of at least 4 steps per drive period")
        if self.settle_tol is not None and not (np.isfinite(self.settle_tol) and self.settle_tol > 0):
            raise Mech2SpiceError(f"settle tolerance {self.settle_tol!r} u_R: must be a positive number")
        if isinstance(self.threads, bool) or int(self.threads) != self.threads or not 1 <= self.threads <= 64:
            raise Mech2SpiceError(f"carrier threads {self.threads!r}: must be a whole number from 1 to 64")
        if self.latency is not None and not (np.isfinite(self.latency) and 0 < self.latency < 1):
            raise Mech2SpiceError(f"latency threshold {self.latency!r} u_R: must be a number between 0 and 1 "
                                  "(or None for off)")
        if self.latency is not None and self.threads > 1:
            raise Mech2SpiceError("the carrier's latency loop runs on one thread: choose latency or threads")


PROCESSOR_LATENCY = 0.05  # u_R: a processor run's default (docs/carrier.md: its cost against the carrier without it)
OSCILLATOR_STEPS_PER_S = 4.7e7   # one thread on the processor model, this 2-core machine (docs/carrier.md, "Measured")


class CarrierEngine(Engine):
    """Lawson RK4 on the carrier: the linear oscillators exact, couplings and nonlinearity explicit."""

    name = "carrier"
    capabilities = Capabilities(batch=True, state=True, checkpoint=True, settle=True, latency=True)
    Options = CarrierOptions

    @classmethod
    def flag_changes(cls, flags) -> dict:
        """--steps: steps per drive period; --latency TOL|off."""
        refuse_circuit_flags(cls.name, flags)
        steps = getattr(flags, "steps", None)
        return {**({"steps_per_period": steps} if steps else {}), **speed_flags(cls.name, flags, ("latency",))}

    def estimate_seconds(self, model, periods, batch=1):
        """Wall time from the measured oscillator-step rate (without idle skipping or latency)."""
        return model.n * batch * periods * self.options.steps_per_period / OSCILLATOR_STEPS_PER_S

    def step(self, model: MechModel) -> float:
        """Stimulus changes must fall on whole drive periods."""
        return 1.0

    def dynamical_state(self, state):
        """(x, v): the latency record (integrate's state[2:]) dropped."""
        return state[:2]

    @classmethod
    def processor_latency(cls, threads: int = 1) -> float | None:
        """PROCESSOR_LATENCY on one thread; with more, every gate (the latency loop is serial)."""
        return PROCESSOR_LATENCY if threads == 1 else None

    def reported_step(self, step: float) -> float:
        """Its own step, one carrier step in drive periods."""
        return 1.0 / self.options.steps_per_period

    def phasors(self, model, state, t):
        """The displacements and velocities as phasors (_base.oscillator_phasors)."""
        return oscillator_phasors(model, state[0], state[1], t)

    def run(self, model, periods, stimulus=None, *, state=None, start_period=0, probes=None, progress=False):
        """Lawson RK4 over `periods` drive periods (see `integrate`)."""
        return integrate(model, periods, steps_per_period=self.options.steps_per_period, stimulus=stimulus,
                         state=state, start_period=start_period, probes=probes, progress=progress,
                         settle_tol=self.options.settle_tol, threads=self.options.threads,
                         latency=self.options.latency)
