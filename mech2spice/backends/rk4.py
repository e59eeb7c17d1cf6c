"""Reference integrator: fixed-step classical RK4 over the mechanical model.

Vectorised over a batch (state arrays are (n_dof, B)); all linear forces,
quadratic couplings and drives are one sparse mat-vec per stage.  The step is
a whole fraction of the drive period so every period holds the same samples;
each probe is demodulated on the fly (amplitude and phase at omega, and its
mean) over every whole period.

Thermal noise (`noise_temperature` T > 0, physics/noise.py): the SDE  dx = v dt,
M dv = F(x, v, t) dt + sqrt(2 T) G dW  has additive noise, and each step is

    (x, v) <- RK4(x, v) + (M^-1 dZ,  M^-1 dW - M^-1 C M^-1 dZ)

with dW = sqrt(2T) G Delta W, dZ = sqrt(2T) G Delta Z (Delta Z = int int dW ds, drawn jointly with
Delta W).  This is the order-1.5 strong Taylor scheme for additive noise (Kloeden & Platen, Numerical
Solution of SDEs, 1992, Sec. 10.4) with its deterministic part replaced by classical RK4 (which agrees
with it through h^2): L^1 f = (M^-1 G, -M^-1 C M^-1 G) is constant because only the dashpots depend on
v, so the terms the scheme drops are O(h^2.5) and the strong order is 1.5 (measured on common Brownian
paths: 2.0 on a linear oscillator, 2.1 on a NOR gate, experiments/noise_agreement.strong_errors).  Each period's increments
come from a generator seeded with (noise_seed, period index), so chunked and whole runs agree; T = 0 runs
the deterministic arithmetic unchanged (bit-identical, tests/test_noise.py).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..errors import Mech2SpiceError
from ..inputs import check_fields
from ..physics import noise as thermal
from ..physics.model import MechModel
from ..physics.stimulus import Stimulus
from ..run_result import Run, blowup_bound, check_divergence
from ._base import (Capabilities, Engine, oscillator_phasors, SettleWatch, probe_dofs, progress_bar,
                    refuse_circuit_flags, speed_flags, watched_dofs)
from .envelope import SETTLE_MIN, SETTLE_WINDOW

DEFAULT_STEPS_PER_PERIOD = 80   # 40 (the paper's 0.025 periods) leaves a 1e-3 u_R error; see reports/gate.md


def force_matrix(model: MechModel) -> sp.csr_matrix:
    """A such that  m * a = A @ [x; v; u_f u_s; u_f^2; drive forces]."""
    a = model.arrays
    n, nq, nd = model.n, len(model.quads), len(model.drives)
    qi = np.arange(nq)
    Qf = sp.csr_matrix((-2 * a["quad_gamma"], (a["quad_fast"], qi)), shape=(n, nq))
    Qs = sp.csr_matrix((-a["quad_gamma"], (a["quad_slow"], qi)), shape=(n, nq))
    D = sp.csr_matrix((np.ones(nd), (a["drive_dof"], np.arange(nd))), shape=(n, nd))
    return sp.hstack([-model.K, -model.C, Qf, Qs, D]).tocsr()


class _Rhs:
    """Acceleration for a state; built once per model."""

    def __init__(self, model: MechModel):
        a = model.arrays
        self.A = force_matrix(model)
        self.inv_m = (1.0 / a["mass"])[:, None]
        self.qf, self.qs = a["quad_fast"], a["quad_slow"]

    def __call__(self, x, v, drive):
        uf = x[self.qf]
        z = np.concatenate([x, v, uf * x[self.qs], uf * uf, drive])
        return (self.A @ z) * self.inv_m


@np.errstate(over="ignore", invalid="ignore")     # a blow-up is caught per period with a clear error
def integrate(model: MechModel, periods: int, *, steps_per_period: int = DEFAULT_STEPS_PER_PERIOD,
              stimulus: Stimulus | None = None, state: tuple[np.ndarray, np.ndarray] | None = None,
              start_period: int = 0, probes: list[str] | None = None, trace_every: int = 0,
              blowup: float | None = None, progress: bool = False, compiled: bool = True,
              noise_temperature: float = 0.0, noise_seed: int = 0, settle_tol: float | None = None) -> Run:
    """Integrate `periods` drive periods from `start_period` (state at rest unless given).

    compiled=True uses the numba kernel (rk4_kernel.py) for whole periods at constant drive
    amplitudes; the numpy path (compiled=False) is the same scheme and the fallback.
    noise_temperature > 0 adds the Langevin forces of every dashpot (module doc).
    settle_tol (u_R): skip idle time by the envelope's rule (`_base.SettleWatch`): once every channel
    settled, the state at the period boundary is held until the stimulus next changes."""
    model.check()
    stimulus = stimulus or Stimulus.constant(model)
    B, N = stimulus.batch, int(steps_per_period)
    if N < 4:
        raise Mech2SpiceError("RK4 needs at least 4 steps per drive period")
    T = model.period
    h = T / N
    rhs = _Rhs(model)
    names = list(probes or model.probes)
    pidx = probe_dofs(model, names)
    watch = SettleWatch(settle_tol * model.amplitude_unit, SETTLE_MIN, SETTLE_WINDOW) if settle_tol else None
    if watch is not None:                   # the watched channels ride along as extra probes
        pidx = np.concatenate([pidx, watched_dofs(model)])
    blowup = blowup or blowup_bound(model)

    # Drive phase tables for the three distinct stage times of step j (periodic in N).
    a = model.arrays
    ph = a["drive_phase"][None, :]
    j = np.arange(N + 1)[:, None]
    sin_full = np.sin(model.omega * j * h + ph)[..., None]              # (N+1, nd, 1)
    sin_half = np.sin(model.omega * (j[:-1] + 0.5) * h + ph)[..., None]  # (N, nd, 1)
    demod = np.exp(-1j * model.omega * (np.arange(1, N + 1) * h))        # samples at step ends

    x, v = (np.zeros((model.n, B)), np.zeros((model.n, B))) if state is None else \
        (np.array(state[0], float), np.array(state[1], float))
    amp = np.zeros((periods, pidx.size, B), complex)
    mean = np.zeros((periods, pidx.size, B))
    traces, trace_t = [], []
    kern = _kernel(model, N, h, sin_full, sin_half, demod, pidx, blowup, compiled and not trace_every, B)
    noise = _Noise(model, noise_temperature, noise_seed, N, h, B)
    bar = progress_bar(periods, progress)
    k, seg_now, since, settled = 0, None, 0, 0
    while k < periods:
        t = (start_period + k) * T
        amps = stimulus.at(t + 1e-9 * h)
        whole = int(min(np.floor((stimulus.next_change(t + 1e-9 * h) - t) / T + 1e-9), periods))  # at these amps
        if stimulus.segment(t + 1e-9 * h) != seg_now:
            seg_now, since = stimulus.segment(t + 1e-9 * h), 0
            if watch is not None:
                watch.restart()
        if kern is not None and whole >= 1:
            n = min(whole, periods - k, KERNEL_CHUNK if noise.off else 1)
            n = min(n, watch.periods_to_check(since)) if watch is not None else n
            x, v = np.ascontiguousarray(x), np.ascontiguousarray(v)
            amp[k:k + n], mean[k:k + n], bad = kern.run(x, v, amps, n, noise.period(start_period + k))
            if bad >= 0:
                check_divergence(model, x, (start_period + k + bad + 1) * T, bound=blowup)
        else:
            n = 1
            x, v = _numpy_period(rhs, x, v, stimulus, start_period + k, N, h, T, sin_full, sin_half, demod,
                                 pidx, amp[k], mean[k], trace_every, traces, trace_t, noise)
            check_divergence(model, x, (start_period + k + 1) * T, bound=blowup)
        if watch is not None and whole >= n and watch.update(np.abs(amp[k:k + n, len(names):]), since):
            hold = min(whole, periods - k) - n          # the settled orbit, held up to the stimulus change
            amp[k + n:k + n + hold], mean[k + n:k + n + hold] = amp[k + n - 1], mean[k + n - 1]
            settled += hold
            n += hold
        k += n
        since += n
        bar.update(n)
    bar.close()
    t_end = (start_period + 1 + np.arange(periods)) * T
    return Run(names, T, t_end, amp[:, :len(names)], mean[:, :len(names)], x, v, (start_period + periods) * T,
               np.array(traces) if traces else None, np.array(trace_t) if trace_t else None,
               extra={"compiled": kern is not None}, state=(x, v), settled_periods=settled)


KERNEL_CHUNK = 200     # periods per compiled call: bounds the progress-bar and Ctrl-C latency
# reports/performance.md: the compiled loop beats numpy's sparse product below ~3000 oscillator-copies
# (1.7x at 1020) and loses above it (numpy 1.8x at 12000), so large runs take the numpy path.
KERNEL_MAX_SIZE = 3000


def _kernel(model, N, h, sin_full, sin_half, demod, pidx, bound, wanted: bool, batch: int = 1):
    from . import _rk4_kernel as rk4_kernel
    if not (wanted and rk4_kernel.AVAILABLE) or model.n * batch > KERNEL_MAX_SIZE:
        return None
    return rk4_kernel.Kernel(model, N, h, sin_full, sin_half, demod, pidx, bound)


class _Noise:
    """The Langevin force increments of each period (None for every period when T = 0)."""

    def __init__(self, model: MechModel, T: float, seed: int, N: int, h: float, batch: int):
        self.T = thermal.check_temperature(T)
        self.off = self.T == 0
        self.G = None if self.off else thermal.noise_matrix(model)
        self.C = model.C
        self.inv_m = (1.0 / model.arrays["mass"])[:, None]
        self.seed, self.N, self.h, self.B = int(seed), N, h, batch

    def period(self, index: int):
        """(dW, dZ) forces of every step of period `index`, each (N, n, B); None without noise."""
        if self.off:
            return None
        return thermal.carrier_increments(self.G, self.T, self.h, self.N, self.B,
                                          thermal.period_rng(self.seed, index))

    def kick(self, x, v, fw, fz):
        """The step's noise increments added to x, v (the kernel's noise_kick in numpy)."""
        dz = fz * self.inv_m
        return x + dz, v + (fw - self.C @ dz) * self.inv_m


def _numpy_period(rhs, x, v, stimulus, period_index, N, h, T, sin_full, sin_half, demod, pidx, amp_out,
                  mean_out, trace_every, traces, trace_t, noise: _Noise | None = None):
    """One drive period with the numpy RK4 (stimulus may change at any step)."""
    inc = noise.period(period_index) if noise is not None else None
    acc = np.zeros(amp_out.shape, complex)
    acc0 = np.zeros(mean_out.shape)
    t_next = -np.inf
    for s in range(N):
        t = period_index * T + s * h
        if t >= t_next - 1e-9 * h:
            amps, t_next = stimulus.at(t + 1e-9 * h), stimulus.next_change(t + 1e-9 * h)
        d0, dh, d1 = amps * sin_full[s], amps * sin_half[s], amps * sin_full[s + 1]
        k1v = rhs(x, v, d0)
        x2, v2 = x + 0.5 * h * v, v + 0.5 * h * k1v
        k2v = rhs(x2, v2, dh)
        x3, v3 = x + 0.5 * h * v2, v + 0.5 * h * k2v
        k3v = rhs(x3, v3, dh)
        x4, v4 = x + h * v3, v + h * k3v
        k4v = rhs(x4, v4, d1)
        x = x + (h / 6) * (v + 2 * v2 + 2 * v3 + v4)
        v = v + (h / 6) * (k1v + 2 * k2v + 2 * k3v + k4v)
        if inc is not None:
            x, v = noise.kick(x, v, inc[0][s], inc[1][s])
        xp = x[pidx]
        acc += xp * demod[s]
        acc0 += xp
        if trace_every and s % trace_every == 0:
            traces.append(xp.copy())
            trace_t.append(t + h)
    amp_out[:] = acc * (2.0 / N)
    mean_out[:] = acc0 / N
    return x, v


@dataclass(frozen=True)
class RK4Options:
    """Settings of the carrier-level RK4 engine."""
    steps_per_period: int = DEFAULT_STEPS_PER_PERIOD
    compiled: bool = True
    noise_temperature: float = 0.0       # k_B T in model energy units (physics/noise.py); 0: deterministic
    noise_seed: int = 0                  # the Langevin forces' seed (with the period index)
    settle_tol: float | None = None      # u_R; None: integrate every period (no idle skipping)

    def __post_init__(self):
        self.validate()              # a bad value fails where it is set, not later inside a run

    def validate(self) -> None:
        """Refuse steps the scheme cannot take and temperatures that are not numbers >= 0."""
        check_fields(self)
        if int(self.steps_per_period) != self.steps_per_period or self.steps_per_period < 4:
            raise Mech2SpiceError("RK4 needs a whole number of at least 4 steps per drive period")
        thermal.check_temperature(self.noise_temperature)
        if self.settle_tol is not None and not (np.isfinite(self.settle_tol) and self.settle_tol > 0):
            raise Mech2SpiceError(f"settle tolerance {self.settle_tol!r} u_R: must be a positive number")
        if self.settle_tol is not None and self.noise_temperature:
            raise Mech2SpiceError("idle-time skipping holds a settled state: it cannot be combined with thermal noise")
        if isinstance(self.noise_seed, bool) or not isinstance(self.noise_seed, (int, np.integer)) or self.noise_seed < 0:
            raise Mech2SpiceError(f"RK4 noise seed {self.noise_seed!r}: must be an integer >= 0")


OSCILLATOR_STEPS_PER_S = 1.5e7   # compiled loop on this 2-core machine (reports/performance.md: 1.4-2e7)


class RK4Engine(Engine):
    """Fixed-step classical RK4 on the carrier: the textbook reference every reduced model is checked against."""

    name = "rk4"
    capabilities = Capabilities(batch=True, state=True, checkpoint=True, settle=True, noise=True)
    Options = RK4Options

    @classmethod
    def flag_changes(cls, flags) -> dict:
        """--steps: steps per drive period."""
        refuse_circuit_flags(cls.name, flags)
        steps = getattr(flags, "steps", None)
        return {**({"steps_per_period": steps} if steps else {}), **speed_flags(cls.name, flags, ())}

    def estimate_seconds(self, model, periods, batch=1):
        """Wall time from the measured oscillator-step rate."""
        return model.n * batch * periods * self.options.steps_per_period / OSCILLATOR_STEPS_PER_S

    def phasors(self, model, state, t):
        """The displacements and velocities as phasors (_base.oscillator_phasors)."""
        return oscillator_phasors(model, state[0], state[1], t)

    def run(self, model, periods, stimulus=None, *, state=None, start_period=0, probes=None, progress=False):
        """RK4 over `periods` drive periods (see `integrate`)."""
        return integrate(model, periods, steps_per_period=self.options.steps_per_period, stimulus=stimulus,
                         state=state, start_period=start_period, probes=probes, progress=progress,
                         compiled=self.options.compiled, noise_temperature=self.options.noise_temperature,
                         noise_seed=self.options.noise_seed, settle_tol=self.options.settle_tol)
