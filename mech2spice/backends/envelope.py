"""The envelope engine: RK4 on the slowly-varying amplitude equations (physics.envelope), steps of whole periods.

The step is held below RK4's stability limit for the fastest envelope rate (`max_step_periods`); a
clocked run may skip idle time: a stretch of constant stimulus ends once every channel has settled
(`settle_tol`).  The compiled loop (_envelope_kernel.py, numba) and the numpy path compute the same
equations; what each speed-up costs in accuracy is measured in reports/fidelity.md.

Three more options (docs/latency.md): `latency` freezes settled gate blocks until an input moves
(_envelope_latency.py), `exponential` steps the insulators' linear oscillators exactly (Lawson RK4) and, with
`etd` (the default), each amplitude's own rate too (ETDRK4), which lifts the stability bounds they set and
leaves RK4 only the coupling between oscillators, `parallel` computes the rates on all cores.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import Mech2SpiceError
from ..inputs import check_fields
from ..physics.envelope import Envelope, gershgorin_rate, spectral_rate
from ..physics.model import MechModel
from ..physics.stimulus import Stimulus
from . import _envelope_kernel
from ..run_result import Run, blowup_bound, check_divergence
from ._base import (SPEED_FLAGS, Capabilities, Engine, probe_dofs, progress_bar, refuse_circuit_flags,
                    speed_flags)

RK4_STABILITY = 2.5          # |lambda h| RK4 keeps stable (its region reaches ~2.8 on both axes)
RATE_SAFETY = 1.5            # x the largest |eigenvalue| at rest: along switching trajectories it moved by
                             # <= 3 % (reports/envelope.md), so this leaves a wide margin
ETD_ROTATION = 3.5           # rad: the most an amplitude's own rate may turn it in one ETDRK4 step.  The coupling
                             # alone would allow 63 periods on the centred processor, but its sieve diverged at 40
                             # periods (5.8 rad; fan-out 12) and ran at 32 (4.6 rad): stepped exactly, the own
                             # rotation still beats against the coupling the RK4 part integrates (docs/latency.md)


DEFAULT_STEP = 4.0           # periods, at most: no accuracy cost on the adder (reports/envelope.md; bound 15.1)
PROCESSOR_LATENCY = 0.1      # u_R: a processor run's per-gate latency threshold by default (docs/latency.md)
EXPONENTIAL_STEP = 16.0      # periods, at most, with the exponential step: 0.005 u_R on the chain (docs/latency.md)


def rate_bound(model: MechModel, exponential: bool = False, etd: bool = True) -> float:
    """The envelope rate the step limit uses: RATE_SAFETY x the spectral rate (Gershgorin where that
    cannot be computed); `exponential`: without the insulators' own modes, which that step treats exactly,
    and with `etd` without each amplitude's own rate (the same).  Cached with the model."""
    own = exponential and etd
    key = "envelope_rate_coupling" if own else "envelope_rate_fast" if exponential else "envelope_rate"
    rate = model.derived.get(key)
    if rate is None:
        env = Envelope.of(model)
        rho = spectral_rate(env, slow_modes=not exponential, own_rates=not own)
        rate = model.derived[key] = RATE_SAFETY * rho if rho is not None else gershgorin_rate(env)
        if own and rho is not None:
            rate = model.derived[key] = max(rate, RK4_STABILITY / ETD_ROTATION * own_rate_max(env))
    return rate


def own_rate_max(env: Envelope) -> float:
    """The largest |own rate| of any amplitude at rest (the diagonal of Bop^-1 Z0; _envelope_latency.own_rates)."""
    from ._envelope_latency import own_rates
    return float(np.abs(own_rates(env, env.block_inverse())[0]).max()) if env.fast.size else 0.0


def needs_etd(model: MechModel, step_periods: float, exponential: bool, etd: bool = True) -> bool:
    """Whether the exponential step takes ETDRK4 at this step: only where the amplitudes' own rates bound it
    (the insulators-only bound is shorter).  Elsewhere RK4 on the amplitudes is within its bound and each
    block-step costs ~1.5x less (docs/latency.md): the default block's processor (bound 27.5, step 16) is
    stepped as before."""
    return bool(exponential and etd and step_periods > max_step_periods(model, True, False))


def max_step_periods(model: MechModel, exponential: bool = False, etd: bool = True) -> float:
    """The longest stable RK4 step on this model's envelope equations, in drive periods."""
    return RK4_STABILITY / rate_bound(model, exponential, etd) / model.period


def default_step(model: MechModel, cap: float | None = None, exponential: bool = False, etd: bool = True) -> float:
    """The longest of 20, 16, 8, 4, 2, 1 periods within `cap` (DEFAULT_STEP, EXPONENTIAL_STEP with the
    exponential step; the processor's ETD_PROCESSOR_STEP) and the model's stability bound (else half a period):
    whole steps keep stimulus changes, which fall on whole periods, on step boundaries.  20 only where ETDRK4
    steps the model there (needs_etd): that is the accuracy it was measured at (cpu/physical.py)."""
    cap = cap or (EXPONENTIAL_STEP if exponential else DEFAULT_STEP)
    bound = max_step_periods(model, exponential, etd)
    for step in (20, 16, 8, 4, 2, 1):
        if step <= min(cap, bound) and (step <= 16 or needs_etd(model, step, exponential, etd)):
            return float(step)
    return 0.5


def kernel(model: MechModel):
    """The compiled loop's arrays for this model (built once), or None without numba."""
    if not _envelope_kernel.AVAILABLE:
        return None
    kern = model.derived.get("envelope_kernel")
    if kern is None:
        kern = model.derived["envelope_kernel"] = _envelope_kernel.Kernel(Envelope.of(model))
    return kern


SETTLE_WINDOW = 200          # periods: more than one gate delay (173 mean, 224 max: reports/gate.md), so
                             # a signal in flight moves some channel by a large part of a band per window
SETTLE_MIN = 400             # periods after a stimulus change before a window counts: an input change
                             # first moves gate oscillators and insulators, not yet channels
CHUNK_PERIODS = 2000         # periods per compiled call: bounds the progress-bar and Ctrl-C latency


def integrate(model: MechModel, periods: int, *, step_periods: float = 0.5, stimulus=None, state=None,
              start_period: int = 0, probes: list[str] | None = None, progress: bool = False,
              settle_tol: float | None = None, compiled: bool = True, latency: float | None = None,
              parallel: bool = False, exponential: bool = False, keep_periods: int | None = None,
              etd: bool = True, latency_calm: float | None = None, latency_wake: float | None = None) -> Run:
    """RK4 on the envelope equations with a step of `step_periods` drive periods (must divide 1 or be whole).

    Returns a Run whose per-period amplitudes are the envelope itself.  A step beyond the measured
    stability bound is refused.  With `settle_tol` (u_R), each stretch of constant stimulus ends once every
    channel's amplitude stayed within a range of `settle_tol` for two SETTLE_WINDOWs in a row: the rest of
    the stretch is the settled state, held (idle-time skipping; the slow small ringing this ignores and
    its error are measured in reports/fidelity.md).  compiled=True uses the numba loop
    (envelope_kernel.py) where numba exists.  With `latency` (u_R) and the compiled loop, settled gate
    blocks are frozen until their inputs move by more than `latency` (_envelope_latency.py); the state
    then carries the blocks' latency record too.  parallel: the compiled loop's rates on all cores
    (without latency: its active rows are too few to share out).  exponential: the insulators' linear
    oscillators are stepped exactly (Lawson RK4), which lifts the stability bound they set.  keep_periods:
    the Run keeps only the last so many periods' amplitudes (a caller that reads the end of each of many
    long pauses need not have every period written: the processor; the loop writes only those).
    latency_calm: the processor's freeze rule (docs/latency.md, "The calm rule"): a block freezes once its
    input channels stayed calm for LATENCY_HOLD and its own channel for `latency_calm` periods; None: once
    it and every input it records stayed calm for LATENCY_HOLD.  latency_wake (u_R): a frozen block wakes once
    one of its input channels moved by this much since it froze (docs/latency.md, "The wake threshold");
    None: by `latency`, as its other inputs."""
    env = Envelope.of(model)
    T = model.period
    etd = needs_etd(model, step_periods, exponential, etd)
    _check_step(model, step_periods, exponential, etd)
    sub, per = _step_layout(step_periods)
    h = T * per / sub
    stimulus = stimulus or Stimulus.constant(model)
    B = stimulus.batch
    nf, ns = env.fast.size, env.slow.size
    A, s, sd = (np.zeros((nf, B), complex), np.zeros((ns, B)), np.zeros((ns, B))) if state is None else \
        (state[0].copy(), state[1].copy(), state[2].copy())
    names = list(probes or model.probes)
    prow = _probe_rows(env, probe_dofs(model, names))
    rec = _Record(periods, keep_periods, len(names), B)
    tol = settle_tol * model.amplitude_unit if settle_tol else 0.0
    check = sub * max(1, int(round(SETTLE_WINDOW / per)))
    kern = kernel(model) if compiled else None
    props = _propagators(kern, env, exponential, T * per / sub, etd)
    lat = _latency_state(kern, state, B) if latency or exponential else None
    lat_tol, hold = (latency or 0.0) * model.amplitude_unit, LATENCY_HOLD * T
    lat_check = max(1, int(round(LATENCY_WINDOW / per))) * sub
    need = -(-LATENCY_HOLD // (lat_check // sub * per)) + 1     # quiet checks spanning HOLD periods
    need_calm = need if latency_calm is None else min(need, int(-(-latency_calm // (lat_check // sub * per))) + 1)
    block_steps = 0
    bound = blowup_bound(model)
    settled_periods = 0
    bar = progress_bar(periods, progress)
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
        if lat is not None:
            seg, done, status, work = kern.run_latent(A, s, sd, lat, nchunks, sub, per, h, F, prow, bound, tol,
                                                      check, settle_from, lat_tol, hold, lat_check, need, props,
                                                      amp_from=max(0, rec.first - k), need_calm=need_calm,
                                                      channels_calm=latency_calm is not None,
                                                      wake_tol=-1.0 if latency_wake is None
                                                      else latency_wake * model.amplitude_unit)
            block_steps += work
        elif kern is not None:
            seg, done, status = kern.run(A, s, sd, nchunks, sub, per, h, F, prow, bound, tol, check, settle_from,
                                         parallel)
        else:
            seg, done, status = _numpy_chunks(env, A, s, sd, nchunks, sub, per, h, F, prow, bound, tol, check,
                                              settle_from)
        if status == _envelope_kernel.DIVERGED:
            check_divergence(model, A, t + (done + 1) * h, dofs=env.fast, bound=bound)
        n = min(nchunks * per, periods - k)
        rec.put(k, seg[:n])
        if status == _envelope_kernel.SETTLED:        # hold the settled state up to the stimulus change
            got = done // sub * per
            n = min(to_change * per, periods - k)
            rec.hold(k + got, k + n, A[prow])
            settled_periods += n - got
        k += n
        since += n
        bar.update(n)
    bar.close()
    t_end = (start_period + 1 + np.arange(periods - rec.amp.shape[0], periods)) * T
    extra = {"block_steps": block_steps, "blocks": kern.blocks.n} if lat is not None else {}
    amp = rec.amp
    return Run(names, T, t_end, amp, np.zeros(amp.shape), None, None, (start_period + periods) * T,
               state=(A, s, sd, *lat) if lat is not None else (A, s, sd), settled_periods=settled_periods,
               extra=extra)


class _Record:
    """The per-period amplitudes a run keeps: every period, or only the last `keep` of them."""

    def __init__(self, periods: int, keep: int | None, n_probes: int, batch: int):
        self.first = periods - min(periods, keep) if keep else 0        # the first period kept
        self.amp = np.empty((periods - self.first, n_probes, batch), complex)   # every one written

    def put(self, k: int, seg: np.ndarray) -> None:
        """Periods k .. k + len(seg) integrated."""
        lo = max(k, self.first)
        if lo < k + len(seg):
            self.amp[lo - self.first:k + len(seg) - self.first] = seg[lo - k:]

    def hold(self, k0: int, k1: int, value: np.ndarray) -> None:
        """Periods k0 .. k1 held at `value` (a settled state)."""
        lo = max(k0, self.first)
        if lo < k1:
            self.amp[lo - self.first:k1 - self.first] = value


LATENCY_WINDOW = 32          # periods between freeze checks
LATENCY_HOLD = 200           # periods, about one gate delay (173 mean, reports/gate.md): a block freezes once
                             # its inputs and itself stayed quiet this long (the calm rule where
                             # Options.latency_calm is set) and its rates predict < the threshold over this


def _propagators(kern, env, exponential: bool, h: float, etd: bool = True):
    """The exponential step's exact parts (Kernel.propagators; None without it)."""
    if not exponential:
        return None
    props = kern.propagators(env, h, etd) if kern is not None and kern.blocks is not None else None
    if props is None:
        raise Mech2SpiceError("the exponential envelope step needs the compiled loop (numba), small Bop "
                              "blocks and uncoupled insulators")
    return props


def _latency_state(kern, state, B: int):
    """The blocks' latency record to continue from (copied), fresh (all active) at the start."""
    if kern is None or kern.blocks is None:
        return None
    if state is not None and len(state) == 8 and state[3].size == kern.blocks.n:
        return tuple(np.array(x) for x in state[3:])
    return kern.blocks.fresh_state(B)


def _check_step(model: MechModel, step_periods: float, exponential: bool = False, etd: bool = True) -> None:
    limit = max_step_periods(model, exponential, etd)
    if not step_periods > 0:
        raise Mech2SpiceError(f"envelope step {step_periods:g} periods: must be positive")
    if step_periods > limit:
        raise Mech2SpiceError(f"envelope step {step_periods:g} periods exceeds the stability limit "
                              f"{limit:.3g} periods for this network (fastest envelope rate "
                              f"{rate_bound(model, exponential, etd):.3g} 1/s)")


def _probe_rows(env: Envelope, dofs: np.ndarray) -> np.ndarray:
    """Rows of the fast block holding these DOFs."""
    pos = env.__dict__.get("_fast_row")
    if pos is None:                              # built once: a processor cycle asks three times
        pos = env._fast_row = -np.ones(env.model.n, int)
        pos[env.fast] = np.arange(env.fast.size)
    rows = pos[np.asarray(dofs, int)]
    if np.any(rows < 0):
        raise KeyError("a probe is not an oscillating DOF")
    return rows


def _numpy_chunks(env, A, s, sd, nchunks, sub, per, h, F, prow, bound, tol, check, settle_from):
    """The compiled loop's contract in numpy (used without numba); updates A, s, sd in place."""
    amp = np.zeros((nchunks * per, prow.size, A.shape[1]), complex)
    w, quiet = env.watch, 0
    lo = hi = np.abs(A[w])
    for n in range(nchunks * sub):
        if tol and n % check == 0:
            if n >= settle_from + check:
                quiet = quiet + 1 if (hi - lo).max(initial=0) < tol else 0
                if quiet >= 2:
                    return amp, n, _envelope_kernel.SETTLED
            lo = hi = np.abs(A[w])
        A[:], s[:], sd[:] = rk4_step(env, A, s, sd, F, h)
        if not np.all(np.abs(A) < bound):
            return amp, n, _envelope_kernel.DIVERGED
        lo, hi = np.minimum(lo, np.abs(A[w])), np.maximum(hi, np.abs(A[w]))
        if (n + 1) % sub == 0:
            c = (n + 1) // sub - 1
            amp[c * per:(c + 1) * per] = A[prow]
    return amp, nchunks * sub, _envelope_kernel.DONE


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


def rk4_step(env: Envelope, A, s, sd, F, h):
    """One classical RK4 step of the envelope equations at constant forcing F."""
    a1, b1, c1 = env.rhs(A, s, sd, F)
    a2, b2, c2 = env.rhs(A + 0.5 * h * a1, s + 0.5 * h * b1, sd + 0.5 * h * c1, F)
    a3, b3, c3 = env.rhs(A + 0.5 * h * a2, s + 0.5 * h * b2, sd + 0.5 * h * c2, F)
    a4, b4, c4 = env.rhs(A + h * a3, s + h * b3, sd + h * c3, F)
    return (A + h / 6 * (a1 + 2 * a2 + 2 * a3 + a4), s + h / 6 * (b1 + 2 * b2 + 2 * b3 + b4),
            sd + h / 6 * (c1 + 2 * c2 + 2 * c3 + c4))


@dataclass(frozen=True)
class EnvelopeOptions:
    """Settings of the envelope engine."""
    step_periods: float | None = None    # None: default_step(model)
    settle_tol: float | None = None      # u_R; None: integrate every period (no idle skipping)
    compiled: bool = True
    latency: float | None = None         # u_R; None: integrate every gate at every step
    parallel: bool = False               # the compiled loop's rates on all cores (without latency)
    exponential: bool = False            # the insulators stepped exactly: lifts the stability bound
    etd: bool = True                     # with exponential: each amplitude's own rate stepped exactly too (ETDRK4)
                                         # where that alone lets the step be taken (needs_etd)
    keep_periods: int | None = None      # the Run keeps only the last so many periods (None: all)
    latency_calm: float | None = None    # the calm rule (integrate): periods a gate block's own channel stays calm
                                         # before it freezes, its input channels LATENCY_HOLD; None: the hold rule
    latency_wake: float | None = None    # u_R: a frozen gate block wakes once an input channel moved this much;
                                         # None: the latency threshold

    def __post_init__(self):
        self.validate()              # a bad value fails where it is set, not later inside a run

    def validate(self) -> None:
        """Refuse steps and tolerances that are not positive numbers."""
        check_fields(self)
        if self.step_periods is not None:
            if not (np.isfinite(self.step_periods) and self.step_periods > 0):
                raise Mech2SpiceError(f"envelope step {self.step_periods!r} periods: must be a positive number")
            _step_layout(self.step_periods)
        if self.settle_tol is not None and not (np.isfinite(self.settle_tol) and self.settle_tol > 0):
            raise Mech2SpiceError(f"settle tolerance {self.settle_tol!r} u_R: must be a positive number")
        if self.latency_calm is not None and not (np.isfinite(self.latency_calm) and self.latency_calm > 0):
            raise Mech2SpiceError(f"latency calm time {self.latency_calm!r} periods: must be a positive number")
        if self.latency_wake is not None and not (np.isfinite(self.latency_wake) and 0 < self.latency_wake < 1):
            raise Mech2SpiceError(f"latency wake threshold {self.latency_wake!r} u_R: must be a number between 0 "
                                  "and 1")
        if self.keep_periods is not None and self.keep_periods < 1:
            raise Mech2SpiceError(f"keep_periods {self.keep_periods!r}: must be at least 1")
        if self.latency is not None and not (np.isfinite(self.latency) and 0 < self.latency < 1):
            raise Mech2SpiceError(f"latency threshold {self.latency!r} u_R: must be a number between 0 and 1 "
                                  "(or off)")


SECONDS_PER_OSCILLATOR_STEP = 1.6e-7   # compiled loop: 0.48 ms per period at 12000 oscillators, step 4 T
                                       # (reports/performance.md)


class EnvelopeEngine(Engine):
    """RK4 on the slowly-varying amplitude equations, steps of whole drive periods."""

    name = "envelope"
    capabilities = Capabilities(batch=True, state=True, checkpoint=True, settle=True, averaged=True, noise=True,
                                latency=True)
    Options = EnvelopeOptions

    @classmethod
    def flag_changes(cls, flags) -> dict:
        """--steps N: one step per N-th of a period (step_periods 1/N); --latency, --exponential, --parallel."""
        refuse_circuit_flags(cls.name, flags)
        steps = getattr(flags, "steps", None)
        return {**({"step_periods": 1.0 / steps} if steps else {}), **speed_flags(cls.name, flags, SPEED_FLAGS)}

    def estimate_seconds(self, model, periods, batch=1):
        """Wall time from the measured rate, without idle skipping (an upper bound for settling runs)."""
        return model.n * batch * periods / self.step(model) * SECONDS_PER_OSCILLATOR_STEP

    def prepare(self, model: MechModel) -> None:
        """Build what the model caches for this engine (the envelope operator, the compiled loop's arrays,
        the stability bound, the insulators' propagators): after it, run() only integrates."""
        step = self.step(model)
        etd = needs_etd(model, step, self.options.exponential, self.options.etd)
        _check_step(model, step, self.options.exponential, etd)
        kern = kernel(model) if self.options.compiled else None
        sub, per = _step_layout(step)
        _propagators(kern, Envelope.of(model), self.options.exponential, model.period * per / sub, etd)

    @classmethod
    def processor_latency(cls, threads: int = 1) -> float | None:
        """PROCESSOR_LATENCY, whatever the threads (its options have none)."""
        return PROCESSOR_LATENCY

    def longest_step(self, model: MechModel, cap: float) -> float:
        """The longest of 20, 16, 8, 4, 2, 1 periods up to `cap` within the model's stability bound (default_step)."""
        return default_step(model, cap, exponential=self.options.exponential, etd=self.options.etd)

    def takes_etd(self, model: MechModel, step: float) -> bool:
        """ETDRK4 at this step (needs_etd): the exponential step, and the insulators-only bound shorter."""
        return needs_etd(model, step, self.options.exponential, self.options.etd)

    def step(self, model: MechModel) -> float:
        """The step this engine takes on `model`, in drive periods."""
        return self.options.step_periods or default_step(model, exponential=self.options.exponential,
                                                         etd=self.options.etd)

    def dynamical_state(self, state):
        """(A, s, s'): the latency record (integrate's state[3:]) dropped."""
        return state[:3]

    def phasors(self, model, state, t):
        """The envelope state itself: (A, s)."""
        return state[0], state[1]

    def rests_on_fixed_point(self) -> bool:
        """RK4 steps rest exactly on the equations' fixed points; the exponential (Lawson) step's rest point
        is off by its local error (~4e-3 u_R at step 16: reports/fidelity.md)."""
        return not self.options.exponential

    def run(self, model, periods, stimulus=None, *, state=None, start_period=0, probes=None, progress=False):
        """The envelope equations over `periods` drive periods (see `integrate`)."""
        return integrate(model, periods, step_periods=self.step(model), stimulus=stimulus, state=state,
                         start_period=start_period, probes=probes, progress=progress,
                         settle_tol=self.options.settle_tol, compiled=self.options.compiled,
                         latency=self.options.latency, parallel=self.options.parallel,
                         exponential=self.options.exponential, keep_periods=self.options.keep_periods,
                         etd=self.options.etd, latency_calm=self.options.latency_calm,
                         latency_wake=self.options.latency_wake)
