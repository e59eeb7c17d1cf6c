"""Thermal noise of the mechanical model: the Langevin forces of its dashpots and the temperature scale.

Fluctuation-dissipation: a dashpot c at temperature T exerts a white random force of one-sided power
spectral density 4 k_B T c (two-sided 2 k_B T c: <f(t) f(t')> = 2 k_B T c delta(t - t')).  T is given in
model energy units (k_B T itself); `KelvinScale` converts to kelvin for one stated physical scaling.

Which elements fluctuate (docs/robustness.md, "Thermal noise"):
  * each DOF's *local* dashpot to ground, when positive: a force on that DOF;
  * each coupling dashpot: equal and opposite forces on its two ends (a force on the relative
    coordinate);
  * a *negative* local dashpot (a dashpot gate's local damping is c_g - c_couple < 0) is an active
    element, not a dissipative one: the fluctuation-dissipation theorem gives it no noise, and what noise
    it would add depends on how it is realised (an amplifier's noise).  It gets none here.
So the force covariance is 2 k_B T G G^T with one column of G per noisy element (sqrt(c) at its DOF, or
+sqrt(c) / -sqrt(c) at a coupling's two ends): positive semi-definite by construction, which the total
damping matrix C is not when local values are negative.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..errors import Mech2SpiceError
from .model import MechModel

K_BOLTZMANN = 1.380649e-23      # J/K


def check_temperature(T) -> float:
    """A noise temperature (model energy units): a finite number >= 0."""
    if isinstance(T, bool) or not isinstance(T, (int, float)) or not (math.isfinite(T) and T >= 0):
        raise Mech2SpiceError(f"noise temperature {T!r}: must be a finite number >= 0 (model energy units)")
    return float(T)


def noisy_elements(model: MechModel) -> list[tuple[int, int, float]]:
    """(i, j, c) for every dashpot that fluctuates: j = -1 for a positive local dashpot to ground."""
    out = [(i, -1, float(c)) for i, c in enumerate(model.c_local) if c > 0]
    out += [(i, j, float(c)) for i, j, c in model.dashpots if c > 0]
    return out


def noise_matrix(model: MechModel) -> sp.csr_matrix:
    """G (n_dof x n_elements): the Langevin force is sqrt(2 k_B T) G xi(t), xi unit white noises."""
    rows, cols, vals = [], [], []
    for e, (i, j, c) in enumerate(noisy_elements(model)):
        rows.append(i), cols.append(e), vals.append(math.sqrt(c))
        if j >= 0:
            rows.append(j), cols.append(e), vals.append(-math.sqrt(c))
    return sp.csr_matrix((vals, (rows, cols)), shape=(model.n, len(noisy_elements(model))))


def period_rng(seed: int, period: int) -> np.random.Generator:
    """The generator of one drive period's noise: the same numbers whatever chunking reaches that period."""
    return np.random.default_rng([int(seed), int(period), 0x4e4f495345])


def carrier_increments(G: sp.csr_matrix, T: float, h: float, steps: int, batch: int, rng):
    """Force increments over `steps` steps of length h: (dW, dZ), each (steps, n_dof, batch), with
    dW = int f dt and dZ = int int f ds dt over a step (f the Langevin force).  Per element the pair
    (Delta W, Delta Z) is drawn exactly: Var = h, h^3/3, Cov = h^2/2 (Kloeden & Platen 1992, eq. 10.4.3)."""
    m = G.shape[1]
    xi = rng.standard_normal((2, steps, m, batch))
    scale = math.sqrt(2.0 * T)
    dW = math.sqrt(h) * xi[0]
    dZ = 0.5 * h ** 1.5 * (xi[0] + xi[1] / math.sqrt(3.0))
    return _through(G, dW) * scale, _through(G, dZ) * scale


def _through(G: sp.csr_matrix, w: np.ndarray) -> np.ndarray:
    """G applied to (steps, m, batch) -> (steps, n, batch)."""
    steps, m, B = w.shape
    out = G @ w.transpose(1, 0, 2).reshape(m, steps * B)
    return np.ascontiguousarray(np.asarray(out).reshape(G.shape[0], steps, B).transpose(1, 0, 2))


def linear_variance(T: float, k: float) -> float:
    """<x^2> of a linear oscillator of stiffness k in equilibrium at k_B T = T (equipartition)."""
    return T / k


@dataclass(frozen=True)
class KelvinScale:
    """One physical realisation of the model's units: the channel's mass, the drive frequency and the
    displacement that u_R stands for.  Model energy E is E * energy_joule J in it."""
    channel_mass_kg: float = 1e-12      # a 1 ng silicon resonator (e.g. a ~60 x 10 x 1 um beam)
    frequency_hz: float = 1e6           # its drive frequency
    u_r_m: float = 10e-9                # the logic amplitude u_R: 10 nm

    def energy_joule(self, m_c: float, omega: float, u_r: float) -> float:
        """Joule per model energy unit: mass scale x length scale^2 x (time scale)^-2."""
        mass = self.channel_mass_kg / m_c
        length = self.u_r_m / u_r
        rate = 2 * math.pi * self.frequency_hz / omega
        return mass * length ** 2 * rate ** 2

    def kelvin(self, T: float, p) -> float:
        """The temperature (K) of model noise temperature T for gate parameters p."""
        return T * self.energy_joule(p.m_c, p.omega, p.u_r) / K_BOLTZMANN

    def describe(self) -> str:
        """One line naming the scaling."""
        return (f"channel mass {self.channel_mass_kg * 1e12:g} ng, drive {self.frequency_hz / 1e6:g} MHz, "
                f"u_R = {self.u_r_m * 1e9:g} nm")


SCALE = KelvinScale()
