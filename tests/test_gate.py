"""The NOR gate: truth table decoded from RK4, agreement with the steady-state solver, convergence,
cascade level restoration, fan-out, and clear errors for bad parameters."""
from dataclasses import replace

import numpy as np
import pytest

from mech2spice.experiments import characterise
from mech2spice.physics import nor, params, steady
from mech2spice.backends import rk4
from mech2spice.experiments.characterise import run_from_rest
from mech2spice.experiments.scenes import LEVEL, PAIRS
from mech2spice.physics.envelope import Envelope
from mech2spice.errors import DivergenceError, Mech2SpiceError


def test_truth_table_decoded_from_rk4(gate_run):
    _, amp = gate_run
    for (a, b), out in zip(PAIRS, amp):
        assert params.band_of(out) == int(not (a or b)), (a, b, out)
        assert params.margin(out, int(not (a or b))) > 0.05


def test_rk4_agrees_with_steady_state(p, gate_run):
    _, amp = gate_run
    ss = characterise.steady_outputs(p, np.array([LEVEL[a] for a, _ in PAIRS]),
                                     np.array([LEVEL[b] for _, b in PAIRS]))
    for states, out in zip(ss, amp):
        stable = [a for a, ok in states if ok]
        assert len(stable) == 1                      # no multistability at nominal inputs
        assert abs(stable[0] - out) < 0.005


def test_step_halving_converged(p, gate_run):
    run80, _ = gate_run
    levels = np.array([[LEVEL[a], LEVEL[b]] for a, b in PAIRS])
    run160, _ = run_from_rest(nor.single_gate(p), p, levels, 2000, steps=160)
    a80 = np.abs(run80.amp[-1, 0]) / p.u_r
    a160 = np.abs(run160.amp[-1, 0]) / p.u_r
    assert np.abs(a80 - a160).max() < 1e-4


def test_valid_region_has_positive_margin_and_no_multistability(p):
    vm = characterise.valid_region_margin(p, per_band=8)
    assert vm["multistable_points"] == 0
    assert vm["min_margin"] > 0


def test_printed_parameters_do_not_switch():
    pr = params.PRINTED
    levels = np.array([[LEVEL[a], LEVEL[b]] for a, b in PAIRS])
    _, amp = run_from_rest(nor.single_gate(pr), pr, levels, 600, steps=40)
    assert amp[0].max() < 0.05                       # far below the '0' band, let alone '1'
    assert np.ptp(amp[0]) < 1e-3                     # inputs barely matter


def test_cascade_restores_levels_and_has_delay(p):
    cas = characterise.cascade(p, hold=1500)
    for r in cas["restoration"]:
        assert r["stage_margins"][2] > 0.15, r        # band-edge inputs come back well inside the band
    # reports/gate.md: 173 periods per gate (mean), 224 at most, measured on this cascade
    assert 160 < cas["delay_periods"] < 190 and cas["delay_max"] < 240


@pytest.mark.parametrize("n_loads", [2, 3])
def test_fanout(p, n_loads):
    fo = characterise.fanout_test(p, n_loads, periods=2000)
    assert fo["correct"]
    assert fo["min_margin"] > 0.05
    assert fo["driver_swing_with_load_state"] < 0.01
    assert fo["branch_spread"] < 1e-6


def test_envelope_decay_matches_rk4_ringdown(p):
    """A lone Q=200 oscillator: envelope eigenvalue == RK4 ring-down rate (checks the averaging)."""
    from mech2spice.physics.model import MechModel
    m = MechModel(omega=p.omega, params=p)
    k = p.m_g * p.omega ** 2
    c = p.damping(p.m_g, k, p.q_g)
    m.add_dof("x", p.m_g, k, c)
    m.add_drive(0, 0.0)
    m.add_probe("x", 0)
    env = Envelope(m)
    ev = np.linalg.eigvals(env.jacobian(env.pack(np.array([1e-3 + 0j]), np.zeros(0), np.zeros(0)),
                                        np.zeros(1, complex)))
    run = rk4.integrate(m, 200, state=(np.array([[p.u_r]]), np.zeros((1, 1))))
    a = np.abs(run.amp[:, 0, 0])
    rate = -np.polyfit(run.t_end[20:], np.log(a[20:]), 1)[0]
    assert abs(ev.real.max() + rate) / rate < 0.01
    assert abs(rate - c / (2 * p.m_g)) / rate < 0.01


def test_divergence_names_dof_and_time(p):
    bad = replace(p, gamma_ic=5e5)                   # channel feedback runs away
    m = nor.single_gate(bad)
    with pytest.raises(DivergenceError) as e:
        rk4.integrate(m, 400, steps_per_period=40)
    assert "g0." in str(e.value) and "drive periods" in str(e.value)
    assert e.value.t > 0


def test_negative_stiffness_is_refused(p):
    with pytest.raises(Mech2SpiceError, match="k_g"):
        nor.single_gate(replace(p, k_g=-1.0))
    from mech2spice.physics.model import MechModel
    with pytest.raises(Mech2SpiceError, match="total stiffness"):
        MechModel(omega=1.0).add_dof("x", 1.0, -2.0, 0.1)


def test_steady_state_finds_every_root(p):
    """Where the gate has three steady states (source drive F_C = 2.0, inputs 0.95), the scan returns all three,
    the same ones Newton finds from 60 starts through the general (sparse-solve) residual, and each balances."""
    from scipy.optimize import fsolve
    q = replace(p, f_c=2.0)
    env, F, ch = characterise.gate_forcing(q, np.array([0.95]), np.array([0.95]))
    states = steady.steady_states(env, F[:, 0])
    assert len(states) == 3
    lim = steady.s_reach(env, F[:, 0])
    newton = set()
    for s0 in np.linspace(-lim, lim, 60):
        s, _, ok, _ = fsolve(lambda s: steady.balance(env, F[:, 0], s), [s0], full_output=True, xtol=1e-13)
        if ok == 1:
            newton.add(round(float(s[0]) / lim, 7))
    assert sorted(newton) == pytest.approx([float(st.s[0]) / lim for st in states], abs=1e-6)
    for s in states:                                  # each root really balances the insulator
        assert abs(steady.balance(env, F[:, 0], s.s)[0]) < 1e-8
    assert sum(st.stable for st in states) >= 1


def test_envelope_model_matches_rk4_on_gate(p, gate_run):
    from mech2spice.backends import envelope
    from mech2spice.experiments.characterise import truth_table_stimulus
    _, amp = gate_run
    run = envelope.integrate(nor.single_gate(p), 2000, step_periods=1.0, stimulus=truth_table_stimulus(p))
    env_amp = np.abs(run.amp[-1, 0]) / p.u_r
    assert np.abs(env_amp - amp).max() < 0.02


def test_envelope_refuses_unstable_step(p):
    from mech2spice.backends import envelope
    m = nor.single_gate(p)
    limit = envelope.max_step_periods(m)
    with pytest.raises(Mech2SpiceError, match="stability limit"):
        envelope.integrate(m, 10, step_periods=float(np.ceil(limit + 1)))
