"""Logic levels are block data (physics/params.Levels): read from parameter and block files, validated, and
read by the physics that grids, drives and scores a gate."""
import json

import numpy as np
import pytest

from mech2spice.errors import Mech2SpiceError
from mech2spice.physics import loaded, nor
from mech2spice.physics.params import BAND0, BAND1, DEFAULT, DEFAULT_LEVELS, PRESETS, Levels, load_params
from dataclasses import replace

NARROW = Levels((0.2, 0.5), (0.9, 1.1), 0.35, 1.0)


def test_default_levels_are_the_papers_bands():
    assert DEFAULT.levels == DEFAULT_LEVELS
    assert (DEFAULT_LEVELS.band0, DEFAULT_LEVELS.band1) == (BAND0, BAND1) == ((0.365, 0.67), (0.92, 1.025))
    assert (DEFAULT_LEVELS.nominal0, DEFAULT_LEVELS.nominal1) == (0.5, 0.97)
    for name in PRESETS:           # the centred blocks (design/centering.py) carry bands of their own
        if not name.startswith("centered"):
            assert PRESETS[name].levels == DEFAULT_LEVELS, name


@pytest.mark.parametrize("x, bit, margin", [(0.5, 0, 0.135 / 0.305), (0.97, 1, 0.05 / 0.105), (0.8, None, -0.12 / 0.305)])
def test_band_and_margin(x, bit, margin):
    assert DEFAULT_LEVELS.band_of(x) == bit
    assert DEFAULT_LEVELS.margin(x) == pytest.approx(margin)


@pytest.mark.parametrize("bad", [{"band0": [0.5, 0.4], "band1": [0.9, 1.0]},
                                 {"band0": [0.2, 0.95], "band1": [0.9, 1.0]},
                                 {"band0": [0.2, 0.5], "band1": [0.9, 1.0], "nominal0": 0.7},
                                 {"band0": [0.2, 0.5]},
                                 {"band0": [0.2, "x"], "band1": [0.9, 1.0]},
                                 {"band0": [0.2, 0.5], "band1": [0.9, 1.0], "colour": 1}])
def test_bad_levels_are_refused(tmp_path, bad):
    f = tmp_path / "p.json"
    f.write_text(json.dumps({"levels": bad}))
    with pytest.raises(Mech2SpiceError, match="levels|band|nominal"):
        load_params(str(f))


def test_levels_from_a_parameter_file_and_a_block_file(tmp_path):
    f = tmp_path / "p.json"
    f.write_text(json.dumps({"q_c": 150.0, "levels": NARROW.to_dict()}))
    assert load_params(str(f)).levels == NARROW
    robust = PRESETS["robust"]
    block = {"block": robust.structure.to_dict(), "f_r": robust.f_r, "u_r": robust.u_r, "omega": robust.omega,
             "levels": NARROW.to_dict()}
    g = tmp_path / "b.json"
    g.write_text(json.dumps(block))
    p = load_params(str(g))
    assert p.levels == NARROW and p.structure == robust.structure
    assert type(p).from_dict(p.to_dict()) == p


def test_the_input_grid_spans_the_blocks_own_bands():
    lv, expect = loaded.input_grid(5, NARROW)
    assert lv[:, 1].min() == 0.2 and lv[:, 1].max() == 1.1
    zero_zero = (lv[:, 1] <= 0.5) & (lv[:, 2] <= 0.5)
    assert np.array_equal(expect, zero_zero.astype(int))


def test_constant_inputs_are_driven_at_the_blocks_nominal_levels():
    p = replace(DEFAULT, levels=NARROW)
    amps = lambda m: [m.drives[d].amplitude for pair in m.design.input_drives for d in pair]
    assert amps(nor.single_gate(p)) == pytest.approx([a * 0.35 / 0.5 for a in amps(nor.single_gate(DEFAULT))])
    assert amps(nor.single_gate(p)) == pytest.approx([0.35 * p.f_r] * 4)
