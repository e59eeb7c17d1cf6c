"""Energy per operation (physics/energy.py, experiments/energy.py): steady dissipation equals the drives' input power, for the
classic and a non-classic block; switching events dissipate a positive energy far above kT ln 2."""
import numpy as np
import pytest

from mech2spice.experiments.energy import gate_energy
from mech2spice.physics import energy, nor
from mech2spice.physics.params import DEFAULT
from test_blocks import buffer_block


@pytest.mark.parametrize("p", [DEFAULT, buffer_block()],
                         ids=["classic", "buffer"])
@pytest.mark.parametrize("x1", [0.5, 0.97])
def test_steady_dissipation_equals_source_power(p, x1):
    m = nor.single_gate(p, x1, 0.5)
    states = [(A, ok) for A, _, ok in energy.steady_amplitudes(m) if ok]
    assert states
    A = states[0][0]
    pd, ps = float(energy.dissipated_power(m, A)), energy.source_power(m, A)
    assert pd > 0 and abs(pd - ps) < 1e-9 * ps


def test_switching_energy_and_scaling():
    e = gate_energy(DEFAULT, transient_periods=1500)
    for ev in e["switching"].values():
        assert ev["delay_periods"] and 50 < ev["delay_periods"] < 1000
        assert ev["energy_model"] > 0 and ev["energy_J"] > 1e3 * e["kT_ln2_J"]["300K"]
    st = e["steady"]["00"]
    assert abs(st["power_model"] - st["source_power_model"]) < 1e-9 * st["power_model"]
    assert e["kT_ln2_J"]["300K"] == pytest.approx(2.871e-21, rel=1e-3)
