"""Energy per operation of a NOR block: steady dissipation, per drive period, per switching event.

In steady state u_i = Re(A_i e^{i omega t}); a dashpot c across a velocity difference dissipates, on
average, c omega^2 |A_i - A_j|^2 / 2.  The model's damping terms are each DOF's local dashpot to ground
(c_local, total minus attached coupling dashpots; it may be negative: then it feeds energy in) and each
coupling dashpot, so

    P = sum_i c_local_i omega^2 |A_i|^2 / 2 + sum_(ij) c_ij omega^2 |A_i - A_j|^2 / 2 (+ c_s s'^2, slow DOFs)

and in steady state P equals the power the drives put in, sum_d 1/2 Re(conj(F_d) i omega A_d)
(`source_power`, a check).  Physical scaling (`Scaling`): model units are mapped to a resonator by a
frequency, the source-driven channel's effective mass and the displacement u_R stands for; energies
compared with kT ln 2.  The measurement on a gate (RK4 runs of switching events) is experiments/energy.py.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .model import MechModel

K_B = 1.380649e-23        # J/K


def dissipated_power(model: MechModel, A: np.ndarray, s_dot: np.ndarray | None = None) -> np.ndarray:
    """Mean dissipated power for complex amplitudes A (n, ...) of every DOF (slow DOFs: their s' or 0)."""
    A = np.asarray(A, complex)
    w2 = model.omega ** 2
    fast = ~np.asarray(model.slow, bool)
    c = np.asarray(model.c_local)
    shape = (-1,) + (1,) * (A.ndim - 1)
    p = 0.5 * w2 * np.sum((c * fast).reshape(shape) * np.abs(A) ** 2, axis=0)
    for i, j, cij in model.dashpots:
        p = p + 0.5 * w2 * cij * np.abs(A[i] - A[j]) ** 2
    if s_dot is not None:
        p = p + np.sum((c * ~fast).reshape(shape) * np.asarray(s_dot) ** 2, axis=0)
    return p


def source_power(model: MechModel, A: np.ndarray, amps: np.ndarray | None = None) -> float:
    """Mean power the drives put in at amplitudes A (n,): a sin(wt + phi) = Re(-i a e^{i phi} e^{iwt})."""
    out = 0.0
    for k, d in enumerate(model.drives):
        a = d.amplitude if amps is None else amps[k]
        F = -1j * a * np.exp(1j * d.phase)
        out += 0.5 * np.real(np.conj(F) * 1j * model.omega * A[d.dof])
    return float(out)


def steady_amplitudes(model: MechModel) -> list[tuple[np.ndarray, float, bool]]:
    """Every steady state (A over all DOFs, insulator position, stable) of a one-insulator model at its
    drive amplitudes (batched all-roots scan)."""
    from . import steady_batch
    fast = np.flatnonzero(~np.asarray(model.slow, bool))
    st = steady_batch.stack([model], np.zeros(len(model.drives), int), int(fast[0]))
    r = steady_batch.roots(st, 0, np.ones((1, 1)))
    out = []
    for s, ok in zip(r.s, r.stable):
        A = np.zeros(model.n, complex)
        A[fast] = steady_batch.responses(st, 0, np.array([s]))[0, :, 0]
        out.append((A, float(s), bool(ok)))
    return out


@dataclass(frozen=True)
class Scaling:
    """Model units -> SI: the drive frequency, the effective mass of the source-driven channel (the same
    resonator for every block), the displacement u_R stands for."""
    frequency_hz: float = 1e6
    channel_mass_kg: float = 1e-12       # a ~ (50 um)^3 silicon resonator's effective mass
    u_r_m: float = 10e-9                 # u_R stands for 10 nm of output amplitude

    def energy_unit(self, model: MechModel, channel_mass: float, u_r: float) -> float:
        """Joules per model energy unit: mass scale x length scale^2 / time scale^2."""
        mass = self.channel_mass_kg / channel_mass
        length = self.u_r_m / u_r
        time = model.omega / (2 * math.pi * self.frequency_hz)
        return mass * length ** 2 / time ** 2

    def describe(self) -> str:
        return (f"{self.frequency_hz / 1e6:g} MHz drive, channel (source DOF) effective mass "
                f"{self.channel_mass_kg:.0e} kg, "
                f"u_R = {self.u_r_m * 1e9:g} nm")


def kt_ln2(temperature_k: float) -> float:
    """Landauer's bound kT ln 2 in joules."""
    return K_B * temperature_k * math.log(2)
