"""The three thermal-noise implementations against each other and against linear response.

Two scenes, each measured as the steady-state variance of a probe's complex amplitude A (per drive
period), E|A - <A>|^2 (the sum of both quadrature variances):

* a linear driven oscillator: equipartition gives <u^2> = T / k, i.e. E|A - <A>|^2 = 2 T / k, reduced by
  the one-period average the demodulation takes (`period_average_factor`);
* one NOR gate in its '1' state (both inputs 0): the prediction is the stationary covariance P of the
  envelope equations linearised at the gate's steady state, J P + P J^T + D = 0 (Lyapunov), D the
  noise covariance of physics/noise.py projected as in backends/_noise_envelope.py.

RK4 and the noisy envelope start a batch of copies at the deterministic steady state and take the
variance across the batch after `periods`; ngspice cannot start from a state, so it runs one long
transient from rest and takes the variance over time after a settling stretch.
"""
from __future__ import annotations

import math

import numpy as np
import scipy.linalg as sla

from ..backends import envelope as det_env
from ..backends import rk4
from ..backends import _noise_envelope as noisy_env
from ..physics import noise as thermal
from ..physics.envelope import Envelope
from ..physics.model import MechModel
from ..physics.nor import single_gate
from ..physics.params import DEFAULT, GateParams
from ..physics.stimulus import Stimulus

SETTLE_PERIODS = 3000        # from rest to the gate's steady state (the slowest mode: the insulator, tau ~ 27 T)


def linear_oscillator(Q: float = 20.0, omega: float = 1.0, k: float = 1.0, drive: float = 0.01) -> MechModel:
    """One linear oscillator at resonance with the drive, mass k / omega^2, quality factor Q."""
    m = MechModel(omega=omega)
    mass = k / omega ** 2
    m.add_dof("x", mass, k, math.sqrt(k * mass) / Q)
    m.add_drive(0, drive)
    m.add_probe("x", 0)
    return m


def period_average_factor(rate: float, period: float) -> float:
    """Var of a one-period mean of a process with correlation exp(-rate |t|), over its variance."""
    x = rate * period
    return 2 * (x - 1 + math.exp(-x)) / x ** 2


def linear_prediction(model: MechModel, T: float) -> float:
    """E|A - <A>|^2 of the single linear oscillator: 2 T / k times the period-average factor."""
    rate = model.c_total[0] / (2 * model.mass[0])
    return 2 * thermal.linear_variance(T, model.k_total[0]) * period_average_factor(rate, model.period)


def gate(p: GateParams = DEFAULT) -> MechModel:
    """The gate scene: one NOR gate, both inputs at the nominal '0', channel probed."""
    return single_gate(p)


def steady_envelope_state(model: MechModel):
    """The deterministic envelope state (A, s, s') after SETTLE_PERIODS from rest."""
    run = det_env.integrate(model, SETTLE_PERIODS, step_periods=det_env.default_step(model))
    return run.state


def gate_prediction(model: MechModel, T: float, probe: str | None = None) -> float:
    """E|A - <A>|^2 of `probe` from the envelope equations linearised at the steady state (Lyapunov)."""
    env = Envelope.of(model)
    A, s, sd = steady_envelope_state(model)
    F = env.forcing(np.array([d.amplitude for d in model.drives]))[:, 0]
    y = env.pack(A[:, 0], s[:, 0], sd[:, 0])
    J = env.jacobian(y, F)
    Sig = _noise_loading(model, T)
    P = sla.solve_continuous_lyapunov(J, -Sig @ Sig.T)
    nf = env.fast.size
    r = list(env.fast).index(model.probes[probe or next(iter(model.probes))])
    return float(P[r, r] + P[nf + r, nf + r])


def _noise_loading(model: MechModel, T: float) -> np.ndarray:
    """Sigma with y' = (...) + Sigma xi (xi unit white) for the packed real envelope state [Re A, Im A, s, s']."""
    env = Envelope.of(model)
    G = thermal.noise_matrix(model).toarray()
    Gf, Gs = G[env.fast], G[env.slow]
    nf, ns, m = env.fast.size, env.slow.size, G.shape[1]
    L = math.sqrt(4 * T) * env.solve_rate(Gf.astype(complex)) if nf else np.zeros((0, m), complex)
    Sig = np.zeros((2 * nf + 2 * ns, 3 * m))
    Sig[:nf, :m], Sig[:nf, m:2 * m] = L.real, -L.imag            # Re(L (w_a + i w_b))
    Sig[nf:2 * nf, :m], Sig[nf:2 * nf, m:2 * m] = L.imag, L.real  # Im(...)
    Sig[2 * nf + ns:, 2 * m:] = math.sqrt(2 * T) * Gs / env.ms[:, None]
    return Sig


def _batch_stimulus(model: MechModel, batch: int) -> Stimulus:
    st = Stimulus.constant(model)
    return Stimulus(st.times, np.repeat(st.amps, batch, axis=-1))


def _spread(a: np.ndarray) -> float:
    """E|A - <A>|^2 over the samples in a."""
    return float(np.mean(np.abs(a - a.mean()) ** 2))


def rk4_variance(model: MechModel, T: float, batch: int, periods: int, seed: int = 0) -> float:
    """RK4 (stochastic, module rk4) from the deterministic steady state: variance across the batch at the end."""
    det = rk4.integrate(model, SETTLE_PERIODS)
    x0, v0 = (np.repeat(a, batch, axis=1) for a in det.state)
    run = rk4.integrate(model, periods, stimulus=_batch_stimulus(model, batch), state=(x0, v0),
                        start_period=SETTLE_PERIODS, noise_temperature=T, noise_seed=seed)
    return _spread(run.amp[-1, 0])


def envelope_variance(model: MechModel, T: float, batch: int, periods: int, seed: int = 0) -> float:
    """The noisy envelope from the deterministic envelope steady state: variance across the batch at the end."""
    A, s, sd = steady_envelope_state(model)
    state = tuple(np.repeat(a, batch, axis=1) for a in (A, s, sd))
    run = noisy_env.integrate(model, periods, temperature=T, seed=seed, stimulus=_batch_stimulus(model, batch),
                              state=state, start_period=SETTLE_PERIODS)
    return _spread(run.amp[-1, 0])


def ngspice_variance(model: MechModel, T: float, periods: int, settle: int, seed: int = 0) -> float:
    """ngspice (trnoise sources) from rest: variance over time of the per-period amplitude after `settle`."""
    from ..spice import runner
    from ..spice.oscillator_netlist import SpiceOptions, noisy_options
    run = runner.run_batch(model, settle + periods, options=noisy_options(SpiceOptions(), T, seed))
    return _spread(run.amp[settle:, 0, 0])


def strong_errors(steps=(8, 16, 32, 64), fine: int = 512, periods: int = 4, batch: int = 200, T: float = 1e-2,
                  seed: int = 5, model: MechModel | None = None) -> dict[int, float]:
    """RMS end-point error of the stochastic RK4 against a `fine`-step run on the same Brownian paths, for a
    linear oscillator (Q 20, undriven) from rest or `model` under its drives: {steps per period: error}.  Coarse runs get their increments by
    summing the fine ones (Delta W exactly, Delta Z = sum Z_j + h_f sum_{i<j} Delta W_i), so every run sees
    one path per batch member; the slope of log error against log h is the scheme's strong order."""
    from unittest import mock
    if model is None:
        model = linear_oscillator(drive=0.0)
        model.drives.clear()
        model.invalidate()
    st = _batch_stimulus(model, batch)

    def increments(G, T_, h, n, B, rng):
        k = fine // n
        hf = h / k
        xi = rng.standard_normal((2, fine, G.shape[1], B))
        dw = math.sqrt(hf) * xi[0]
        dz = 0.5 * hf ** 1.5 * (xi[0] + xi[1] / math.sqrt(3.0))
        dw, dz = dw.reshape(n, k, *dw.shape[1:]), dz.reshape(n, k, *dz.shape[1:])
        before = np.cumsum(dw, axis=1) - dw                     # sum of the earlier fine dW within a coarse step
        DW, DZ = dw.sum(axis=1), dz.sum(axis=1) + hf * before.sum(axis=1)
        s = math.sqrt(2.0 * T_)
        return thermal._through(G, DW) * s, thermal._through(G, DZ) * s

    with mock.patch.object(rk4.thermal, "carrier_increments", increments):
        ref = rk4.integrate(model, periods, steps_per_period=fine, stimulus=st, noise_temperature=T, noise_seed=seed)
        out = {}
        for n in steps:
            r = rk4.integrate(model, periods, steps_per_period=n, stimulus=st, noise_temperature=T, noise_seed=seed)
            out[n] = float(np.sqrt(np.mean((r.x - ref.x) ** 2 + (r.v - ref.v) ** 2)))
    return out


def observed_order(errors: dict[int, float]) -> float:
    """The least-squares slope of log error against log step (h ~ 1 / steps per period)."""
    n = np.array(sorted(errors))
    return float(-np.polyfit(np.log(n), np.log([errors[k] for k in n]), 1)[0])
