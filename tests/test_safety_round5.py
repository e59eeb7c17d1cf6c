"""Safe with anyone's files, round 5: the session-26 hostile pass's findings left open then, fixed in session 27
(each test fails on the code before its fix)."""
from __future__ import annotations

import json

import pytest

from mech2spice import api
from mech2spice.errors import Mech2SpiceError

INVERTER = "module inv(input a, output y);\n  assign y = ~a;\nendmodule\n"


# ------------------------------------------------------------------ a drive no engine can step with the gates

@pytest.mark.parametrize("omega", [1e-300, 1e300])
@pytest.mark.parametrize("backend", ["carrier", "rk4", "envelope"])
def test_a_drive_frequency_far_from_every_oscillator_is_refused_not_decoded(tmp_path, backend, omega):
    """The carrier at omega = 1e-300 decoded a NaN phasor as amplitude 0.0 and reported 'invalid' (exit 1)."""
    design = tmp_path / "inv.v"
    design.write_text(INVERTER)
    params = tmp_path / "p.json"
    params.write_text(json.dumps({"omega": omega}))
    with pytest.raises(Mech2SpiceError, match="own frequency sqrt"):
        api.simulate(str(design), {"a": 1}, backend=backend, params=str(params))
