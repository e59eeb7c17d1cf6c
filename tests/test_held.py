"""A block's register loops while they hold (experiments/held.py, issue #27): the centred blocks as centred
circle a Hopf point, the damped presets settle, and the damping lever moves no steady state."""
import math

import numpy as np
import pytest

from mech2spice.experiments import held
from mech2spice.physics import nor
from mech2spice.physics.envelope import Envelope
from mech2spice.physics.params import load_params
from mech2spice.physics.steady import steady_states

AS_CENTRED = {"centered": 0.8864340303142332, "centered_fc": 0.8680033880034401}   # Q_I before the damping


def _steady_channels(p, x1, x2) -> list[float]:
    m = nor.single_gate(p, x1, x2)
    env = Envelope.of(m)
    F = env.forcing(np.array([d.amplitude for d in m.drives]))[:, 0]
    ch = list(env.fast).index(m.design.gates[0].channel)
    return [abs(st.A[ch]) / p.u_r for st in steady_states(env, F, n_grid=4000)]


def test_insulator_q_moves_no_steady_state():
    p = load_params("centered")
    lv = p.levels
    other = held.with_insulator_q(p, 2.5 * held.insulator_q(p))
    assert held.insulator_q(other) != held.insulator_q(p) and other.levels == lv
    for x1, x2 in ((lv.band0[0], lv.band0[1]), (lv.band0[1], lv.band1[0]), (lv.band1[1], lv.band1[1])):
        a, b = _steady_channels(p, x1, x2), _steady_channels(other, x1, x2)
        assert a and np.allclose(a, b, rtol=1e-9, atol=1e-12), (x1, x2, a, b)


@pytest.mark.parametrize("name", ["centered", "centered_fc"])
def test_centred_block_as_centred_circles_while_holding(name):
    h = held.held_growth(held.with_insulator_q(load_params(name), AS_CENTRED[name]))
    assert h["growth"] > 0 and not h["valid"], h


@pytest.mark.parametrize("name", ["default", "centered", "centered_fc", "centered2", "centered_fc2"])
def test_shipped_blocks_settle_while_holding(name):
    h = held.held_growth(load_params(name))
    assert h["valid"] and h["outputs"] == [0, 1, 2, 2, 3], h
    assert h["growth"] <= -held.HELD_GROWTH_FLOOR and math.isfinite(h["growth"]), h


def test_damping_stops_at_the_floor():
    p = held.with_insulator_q(load_params("centered"), 0.5)
    damped, rec = held.damp_insulator(p)
    q = [t["q_insulator"] for t in rec["tried"]]
    assert rec["reached"] and len(q) >= 2 and held.insulator_q(damped) == q[-1] == pytest.approx(0.5 * held.Q_STEP ** (len(q) - 1))
    assert rec["tried"][-1]["growth"] <= -held.HELD_GROWTH_FLOOR < rec["tried"][-2]["growth"]


def test_center_damps_its_best_block(tmp_path):
    """`center` ends with the held check; robust's loops already settle, so its Q stays and one run is recorded."""
    import json, subprocess, sys
    r = subprocess.run([sys.executable, "-m", "mech2spice.cli", "center", "--from", "robust", "--steps", "0",
                        "--out", str(tmp_path), "--json"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    hd = json.loads(r.stdout)["held_damping"]
    assert hd["reached"] and len(hd["tried"]) == 1 and hd["tried"][0]["growth"] <= -held.HELD_GROWTH_FLOOR
    best = load_params(str(tmp_path / "best.json"))
    assert held.insulator_q(best) == held.insulator_q(load_params("robust"))
