"""mech2spice.compare: the one measure of a run against a reference run."""
import numpy as np

from mech2spice.compare import AVG, agreement, settled, settled_agreement, trajectory
from mech2spice.physics import nor
from mech2spice.physics.params import DEFAULT, NOMINAL0, NOMINAL1
from mech2spice.physics.stimulus import Stimulus


def test_settled_averages_the_last_periods_only():
    amp = np.concatenate([np.full(5, 100.0), np.full(AVG, 2.0 + 1j)])
    assert settled(amp) == 2.0 + 1j


def test_agreement_amplitude_and_phase():
    ref = np.array([1.0, 1j])
    got = np.array([1.5, 1.0])                    # +0.5 in |A|; 90 degrees on the second
    d = agreement(ref, got, unit=0.5)
    assert np.isclose(d.amp, 1.0) and np.isclose(d.phase_deg, 90.0)


def test_agreement_ignores_phases_below_the_floor():
    ref, got = np.array([1.0, 0.01]), np.array([1.0, -0.01])
    assert agreement(ref, got, 1.0).phase_deg == 180.0
    assert agreement(ref, got, 1.0, floor=0.1).phase_deg == 0.0


def test_settled_agreement_and_trajectory_differ_where_a_run_overshoots():
    ref = np.ones(50, complex)
    got = ref.copy()
    got[3] = 3.0                                  # a start-up overshoot, long settled
    assert settled_agreement(ref, got, 1.0).amp == 0.0
    assert trajectory(ref, got, 1.0) == 2.0
    assert trajectory(ref, got, 1.0, skip=10) == 0.0


def test_input_levels_one_member_per_pair():
    m = nor.single_gate(DEFAULT)
    pairs = [(NOMINAL0, NOMINAL1), (NOMINAL1, NOMINAL0)]
    st = Stimulus.input_levels(m, pairs, DEFAULT.f_r)
    assert st.batch == 2
    for k, drives in enumerate(m.design.input_drives):
        for d in drives:
            assert np.allclose(st.amps[0, d], [p[k] * DEFAULT.f_r for p in pairs])
