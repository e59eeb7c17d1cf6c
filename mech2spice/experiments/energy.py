"""Energy per operation of a NOR block, measured: steady power at the four input pairs (physics/energy.py's
formulas on the all-roots steady states) and the energy of the switching events on RK4.

A switching event: the gate from the steady state of one input pair to that of another (RK4 run); its energy
is the integral of P(t) from the input step until the output stays inside its new band (the delay), and
`excess_over_final` the integral of P(t) minus the final steady P over the whole transient (negative when the
gate dissipates less on the way).
"""
from __future__ import annotations

import numpy as np

from ..backends import rk4
from ..physics import nor
from ..physics.energy import Scaling, dissipated_power, kt_ln2, source_power, steady_amplitudes
from .scenes import levels_stimulus


def gate_energy(p, scaling: Scaling = Scaling(), transient_periods: int = 3000, steps: int = 40) -> dict:
    """Steady power of one free-standing gate at the four nominal input pairs, energy per drive period, and
    the energy of the switching events 00 -> 10 (output 1 -> 0) and 10 -> 00 (0 -> 1) with their delays
    (periods from the input step until the output stays inside its new band), RK4 (every DOF probed)."""
    n0, n1 = p.levels.nominal0, p.levels.nominal1
    pairs = {"00": (n0, n0), "10": (n1, n0), "01": (n0, n1), "11": (n1, n1)}
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
        want = int(z == "00")
        inside = np.array([p.levels.band_of(x) == want for x in amp])
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
