"""Thermal noise in the envelope model: the Langevin forces of physics/noise.py as complex-amplitude noise.

A white force f(t) with <f(t) f(t')> = 2 T c delta(t - t') on an oscillating DOF enters the envelope
equations (physics/envelope.py) through its complex amplitude at omega, zeta = 2 f e^{-i omega t}
(the factor 2 as for a drive: F^ is twice the mean of f e^{-i omega t}).  Averaged over a period, zeta is
circular complex white noise: <zeta zeta*> = 8 T c delta, <zeta zeta> = 0 (the e^{-2 i omega t} part
averages out), i.e. real and imaginary parts each of strength 4 T c, independent.  So

    (2 i omega M + C) dA = (...) dt + sqrt(4 T) G_f (dW_re + i dW_im)

and a slow DOF (a real coordinate in the envelope model) keeps its real force: M_s ds' = (...) dt +
sqrt(2 T) G_s dW.  For one linear oscillator at resonance this gives E|A|^2 = 2 T / k, i.e. <u^2> = T / k,
equipartition (docs/robustness.md derives it).

Integrator: the noise is additive, so each step is a Strang splitting -- half the step's Wiener
increment, one classical RK4 step of the deterministic envelope equations (backends.envelope.rk4_step),
the other half.  Strong order 1 for additive noise (as Euler-Maruyama; Kloeden & Platen 1992, Sec. 10.2);
placing the kicks symmetrically makes the stationary variance of a linear mode exact to O((lambda h)^2)
instead of O(lambda h).  Each period's increments come from a generator seeded with (seed, period index).
The deterministic envelope engine (backends/envelope.py) is untouched: this module only reads it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import Mech2SpiceError
from ..inputs import check_fields
from ..physics import noise as thermal
from ..physics.envelope import Envelope
from ..physics.model import MechModel
from ..physics.stimulus import Stimulus
from . import envelope as det
from ..run_result import Run, blowup_bound, check_divergence
from ._base import Capabilities, Engine, probe_dofs, progress_bar

DEFAULT_NOISE_STEP = 1.0      # periods, at most: the linear-mode variance bias is O((lambda h)^2), lambda h ~ 0.02


class EnvelopeNoise:
    """The envelope model's noise operators for one model: complex fast kicks, real slow kicks."""

    def __init__(self, model: MechModel, T: float):
        self.env = Envelope.of(model)
        self.T = thermal.check_temperature(T)
        G = thermal.noise_matrix(model).tocsr()
        self.Gf, self.Gs = G[self.env.fast], G[self.env.slow]
        self.inv_ms = 1.0 / self.env.ms[:, None]

    def kicks(self, h: float, steps: int, batch: int, rng) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per step and half step: (dA, dsd), arrays (steps, 2, n, B): the A and s' increments of the Wiener
        increments over each half of each step (variance h/2 each)."""
        m = self.Gf.shape[1]
        xi = rng.standard_normal((3, steps, 2, m, batch)) * math.sqrt(h / 2)
        nf, ns = self.Gf.shape[0], self.Gs.shape[0]
        flat = lambda w: w.transpose(2, 0, 1, 3).reshape(m, -1)
        zeta = math.sqrt(4 * self.T) * (self.Gf @ flat(xi[0]) + 1j * (self.Gf @ flat(xi[1])))
        dA = self.env.solve_rate(np.asarray(zeta)) if nf else np.zeros((0, zeta.shape[1]), complex)
        dsd = math.sqrt(2 * self.T) * np.asarray(self.Gs @ flat(xi[2])) * self.inv_ms
        shape = lambda a, n: np.ascontiguousarray(a.reshape(n, steps, 2, batch).transpose(1, 2, 0, 3))
        return shape(dA, nf), shape(dsd, ns)


def integrate(model: MechModel, periods: int, *, temperature: float, seed: int = 0,
              step_periods: float = DEFAULT_NOISE_STEP, stimulus: Stimulus | None = None, state=None,
              start_period: int = 0, probes: list[str] | None = None, progress: bool = False) -> Run:
    """The envelope equations with thermal noise over `periods` drive periods (state (A, s, s') as the
    deterministic envelope engine's, so either can continue the other)."""
    noise = EnvelopeNoise(model, temperature)
    env = noise.env
    T = model.period
    det._check_step(model, step_periods)
    sub, per = det._step_layout(step_periods)
    if per != 1:
        raise Mech2SpiceError("the noisy envelope integrator takes steps of at most one period (1, 1/2, 1/4, ...)")
    h = T / sub
    stimulus = stimulus or Stimulus.constant(model)
    B = stimulus.batch
    nf, ns = env.fast.size, env.slow.size
    A, s, sd = (np.zeros((nf, B), complex), np.zeros((ns, B)), np.zeros((ns, B))) if state is None else \
        (state[0].copy(), state[1].copy(), state[2].copy())
    names = list(probes or model.probes)
    prow = det._probe_rows(env, probe_dofs(model, names))
    amp = np.zeros((periods, len(names), B), complex)
    bound = blowup_bound(model)
    bar = progress_bar(periods, progress)
    for k in range(periods):
        t = (start_period + k) * T
        F = env.forcing(stimulus.at(t + 1e-9 * h))
        dA, dsd = noise.kicks(h, sub, B, thermal.period_rng(seed, start_period + k)) if noise.T else (None, None)
        for j in range(sub):
            if dA is not None:
                A, sd = A + dA[j, 0], sd + dsd[j, 0]
            A, s, sd = det.rk4_step(env, A, s, sd, F, h)
            if dA is not None:
                A, sd = A + dA[j, 1], sd + dsd[j, 1]
        if not np.all(np.abs(A) < bound):
            check_divergence(model, A, t + T, dofs=env.fast, bound=bound)
        amp[k] = A[prow]
        bar.update(1)
    bar.close()
    t_end = (start_period + 1 + np.arange(periods)) * T
    return Run(names, T, t_end, amp, np.zeros(amp.shape), None, None, (start_period + periods) * T,
               state=(A, s, sd))


@dataclass(frozen=True)
class NoisyEnvelopeOptions:
    """Settings of the envelope model with thermal noise."""
    noise_temperature: float = 0.0
    noise_seed: int = 0
    step_periods: float | None = None     # None: the longest of 1, 1/2, ... periods within the stability bound

    def __post_init__(self):
        self.validate()              # a bad value fails where it is set, not later inside a run

    def validate(self) -> None:
        """Refuse temperatures, seeds and steps that are not usable."""
        check_fields(self)
        thermal.check_temperature(self.noise_temperature)
        if isinstance(self.noise_seed, bool) or not isinstance(self.noise_seed, (int, np.integer)) or self.noise_seed < 0:
            raise Mech2SpiceError(f"noise seed {self.noise_seed!r}: must be an integer >= 0")
        if self.step_periods is not None:
            if not (np.isfinite(self.step_periods) and 0 < self.step_periods <= 1):
                raise Mech2SpiceError(f"noisy envelope step {self.step_periods!r}: must be in (0, 1] periods")
            det._step_layout(self.step_periods)


class NoisyEnvelopeEngine(Engine):
    """The envelope equations with thermal noise (stochastic RK4 splitting, steps of at most one period).

    Not in the registry: `backends.noisy_engine` picks it for `--backend envelope --noise T` with T > 0."""

    name = "envelope"
    capabilities = Capabilities(batch=True, state=True, checkpoint=True, averaged=True)
    Options = NoisyEnvelopeOptions

    def step(self, model: MechModel) -> float:
        """The step (periods): the set one, else the longest of 1, 1/2, 1/4 ... within the stability bound."""
        return self.options.step_periods or det.default_step(model, cap=DEFAULT_NOISE_STEP)

    def phasors(self, model, state, t):
        """The envelope state itself: (A, s)."""
        return state[0], state[1]

    def run(self, model, periods, stimulus=None, *, state=None, start_period=0, probes=None, progress=False):
        """The noisy envelope equations over `periods` drive periods (see `integrate`)."""
        return integrate(model, periods, temperature=self.options.noise_temperature, seed=self.options.noise_seed,
                         step_periods=self.step(model), stimulus=stimulus, state=state,
                         start_period=start_period, probes=probes, progress=progress)
