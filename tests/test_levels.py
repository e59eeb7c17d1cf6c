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


# The default bands with other nominal levels: a block of them still drives itself (NARROW does not).
NEAR = Levels(DEFAULT_LEVELS.band0, DEFAULT_LEVELS.band1, 0.52, 0.98)


def test_levels_from_a_parameter_file_and_a_block_file(tmp_path):
    f = tmp_path / "p.json"
    f.write_text(json.dumps({"name": "near", "levels": NEAR.to_dict()}))
    assert load_params(str(f)).levels == NEAR
    robust = PRESETS["robust"]
    block = {"block": robust.structure.to_dict(), "f_r": robust.f_r, "u_r": robust.u_r, "omega": robust.omega,
             "levels": NEAR.to_dict()}
    g = tmp_path / "b.json"
    g.write_text(json.dumps(block))
    p = load_params(str(g))
    assert p.levels == NEAR and p.structure == robust.structure
    assert type(p)(**p.to_dict()) == p


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


def _params_file(tmp_path, levels: Levels) -> str:
    f = tmp_path / "levels.json"
    f.write_text(json.dumps({"levels": levels.to_dict()}))
    return str(f)


def test_outputs_are_decoded_in_the_blocks_own_bands(tmp_path, capsys):
    """The default block, read with two other sets of bands: its '0' (0.55 u_R for s[1] of 3 + 2) lies in
    band 0 of the first and above band 0 of the second, so the same physics is valid in one and is refused
    on load in the other (its own output levels miss its bands: it cannot drive itself)."""
    from cli_helpers import refused, run
    wide = _params_file(tmp_path, Levels((0.3, 0.6), (0.9, 1.05), 0.45, 0.97))
    code, out, _ = run(capsys, "simulate", "verilog/adder2.v", "--set", "a=3", "--set", "b=2", "--backend",
                       "envelope", "--params", wide, "--json")
    res = json.loads(out)
    assert code == 0 and res["outputs"] == {"s": 5} and res["valid"]
    s1 = res["amplitudes"]["s[1]"]
    assert res["min_margin"] == pytest.approx(min(Levels((0.3, 0.6), (0.9, 1.05)).margin(a)
                                                  for a in res["amplitudes"].values()))
    narrow = tmp_path / "narrow"
    narrow.mkdir()
    low = _params_file(narrow, Levels((0.2, 0.5), (0.9, 1.05), 0.35, 0.97))
    assert s1 > 0.5
    refused(capsys, "simulate", "verilog/adder2.v", "--set", "a=3", "--set", "b=2", "--backend", "envelope",
            "--params", low, "--json", needle="cannot drive itself")


def test_an_emitted_netlist_reads_in_the_blocks_bands(tmp_path, capsys):
    from cli_helpers import run
    lv = Levels((0.3, 0.6), (0.9, 1.05), 0.45, 0.97)
    out = tmp_path / "a.cir"
    code, _, _ = run(capsys, "emit", "verilog/adder2.v", "--set", "a=1", "--set", "b=1", "-o", out,
                     "--params", _params_file(tmp_path, lv))
    text = out.read_text()
    assert code == 0 and "'0' 0.3..0.6 u_R, '1' 0.9..1.05 u_R" in text
    assert "ge 0.3 and" in text and "le 1.05" in text and "ge 0.365" not in text
