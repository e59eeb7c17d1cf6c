"""Energy per operation of a NOR block: steady dissipation, per drive period, per switching event.

In steady state u_i = Re(A_i e^{i omega t}); a dashpot c across a velocity difference dissipates, on
average, c omega^2 |A_i - A_j|^2 / 2.  The model's damping terms are each DOF's local dashpot to ground
(c_local, total minus attached coupling dashpots; it may be negative: then it feeds energy in) and each
coupling dashpot, so

    P = sum_i c_local_i omega^2 |A_i|^2 / 2 + sum_(ij) c_ij omega^2 |A_i - A_j|^2 / 2 (+ c_s s'^2, slow DOFs)

and in steady state P equals the power the drives put in, sum_d 1/2 Re(conj(F_d) i omega A_d)
(`source_power`, a check).  A switching event: the gate from the steady state of one input pair to
that of another (RK4 run); its energy is the integral of P(t) from the input step until the output
stays inside its new band (the delay), and `excess_over_final` the integral of P(t) minus the final
steady P over the whole transient (negative when the gate dissipates less on the way).  Physical scaling (`Scaling`): model units are mapped to a resonator by a frequency, the
source-driven channel's effective mass and the displacement u_R stands for; energies compared with kT ln 2.
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


def gate_energy(p, scaling: Scaling = Scaling(), transient_periods: int = 3000, steps: int = 40) -> dict:
    """Steady power of one free-standing gate at the four nominal input pairs, energy per drive period, and
    the energy of the switching events 00 -> 10 (output 1 -> 0) and 10 -> 00 (0 -> 1) with their delays
    (periods from the input step until the output stays inside its new band), RK4 (every DOF probed)."""
    from ..backends import rk4
    from ..experiments.scenes import levels_stimulus
    from . import nor
    from .params import NOMINAL0, NOMINAL1, band_of
    pairs = {"00": (NOMINAL0, NOMINAL0), "10": (NOMINAL1, NOMINAL0), "01": (NOMINAL0, NOMINAL1),
             "11": (NOMINAL1, NOMINAL1)}
    m = nor.single_gate(p)
    names = list(m.names)
    seq = [("00", "10"), ("10", "00")]
    levels = lambda k: np.array([pairs[a if k == 0 else b] for a, b in seq])   # noqa: E731
    half = transient_periods
    stim = levels_stimulus(m, p, [(0, levels(0)), (half, levels(1))])
    run = rk4.integrate(m, 2 * half, steps_per_period=steps, stimulus=stim, probes=names)
    A = np.moveaxis(run.amp, 1, 0)                      # (n, P, B)
    slow = np.asarray(m.slow, bool)
    s_mean = run.mean[:, slow, :]
    s_dot = np.gradient(s_mean, m.period, axis=0)        # (P, n_slow, B)
    s_dot_full = np.zeros_like(A.real)
    s_dot_full[slow] = np.moveaxis(s_dot, 1, 0)
    P = dissipated_power(m, A, s_dot_full)              # (P, B)
    out_row = names.index(m.names[m.probes["g0"]])
    unit = scaling.energy_unit(m, p.structure.dof(p.structure.source).m, p.u_r)
    events = {}
    for b, (a, z) in enumerate(seq):
        p_after = P[-20:, b].mean()
        transient = P[half:, b] - p_after
        amp = np.abs(A[out_row, half:, b]) / p.u_r
        want = int(not (pairs[z][0] > 0.8 or pairs[z][1] > 0.8))
        inside = np.array([band_of(x) == want for x in amp])
        delay = int(np.flatnonzero(~inside)[-1] + 1) if (~inside).any() else 0
        delay = delay if inside[-20:].all() else None
        excess = float(np.sum(transient) * m.period)
        during = float(np.sum(P[half:half + delay, b]) * m.period) if delay is not None else None
        events[f"{a}->{z}"] = {"energy_model": during, "energy_J": during * unit if during is not None else None,
                               "excess_over_final_model": excess, "delay_periods": delay,
                               "power_before": float(P[half - 1, b]), "power_after": float(p_after)}
    steady = {}
    for key, (x1, x2) in pairs.items():
        mm = nor.single_gate(p, x1, x2)
        states = [(A_, ok) for A_, _, ok in steady_amplitudes(mm) if ok]
        if not states:
            steady[key] = None
            continue
        A_ = states[0][0]
        pw = float(dissipated_power(mm, A_))
        steady[key] = {"power_model": pw, "source_power_model": source_power(mm, A_),
                       "per_period_model": pw * mm.period, "per_period_J": pw * mm.period * unit,
                       "stable_states": len(states)}
    return {"steady": steady, "switching": events, "scaling": scaling.describe(), "joule_per_model_unit": unit,
            "kT_ln2_J": {"300K": kt_ln2(300.0), "4K": kt_ln2(4.0)},
            "method": f"RK4 {steps} steps/period, {transient_periods} periods per input pair; steady states "
                      "from the batched all-roots scan (first stable state)"}
