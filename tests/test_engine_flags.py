"""Each engine reads its own command-line flags (`options_from_flags`) and refuses the others' (issue #28)."""
from __future__ import annotations

import argparse

import pytest

from mech2spice.backends import BACKENDS
from mech2spice.errors import Mech2SpiceError


def flags(**given):
    return argparse.Namespace(**given)


@pytest.mark.parametrize("name", list(BACKENDS))
def test_no_flags_give_the_defaults(name):
    cls = BACKENDS[name]
    assert cls.options_from_flags(flags()) == cls.Options()


def test_steps_mean_each_engines_own_step():
    assert BACKENDS["rk4"].options_from_flags(flags(steps=40)).steps_per_period == 40
    assert BACKENDS["carrier"].options_from_flags(flags(steps=16)).steps_per_period == 16
    assert BACKENDS["envelope"].options_from_flags(flags(steps=2)).step_periods == 0.5
    with pytest.raises(Mech2SpiceError, match="ngspice's step is --max-step"):
        BACKENDS["ngspice"].options_from_flags(flags(steps=40))


def test_circuit_flags_go_to_the_circuit_simulators_only():
    o = BACKENDS["vacask"].options_from_flags(flags(method="gear", max_step=0.1, ngspice_timeout=5.0))
    assert (o.method, o.max_step_periods, o.timeout_s) == ("gear", 0.1, 5.0)
    for name in ("rk4", "envelope", "logic"):
        with pytest.raises(Mech2SpiceError, match=f"circuit simulators .*not {name}"):
            BACKENDS[name].options_from_flags(flags(method="gear"))


def test_speed_flags_follow_the_latency_capability():
    takes_latency = {n for n, cls in BACKENDS.items() if cls.capabilities.latency}
    assert takes_latency == {"envelope", "carrier"}
    for name, cls in BACKENDS.items():
        if name in takes_latency:
            assert cls.options_from_flags(flags(latency=1e-3)).latency == 1e-3
        else:
            with pytest.raises(Mech2SpiceError, match=f"--latency: envelope backend options, not {name}'s"):
                cls.options_from_flags(flags(latency=1e-3))
    with pytest.raises(Mech2SpiceError, match="--exponential and --parallel: .* not carrier's"):
        BACKENDS["carrier"].options_from_flags(flags(latency=1e-3, parallel="off"))
    assert BACKENDS["envelope"].options_from_flags(flags(exponential="off")).exponential is False


def test_a_bad_value_is_refused_by_the_engines_own_check():
    with pytest.raises(Mech2SpiceError, match="max_step_periods"):
        BACKENDS["ngspice"].options_from_flags(flags(max_step=0.5))
