"""Trim fcb (physics/spread.balanced, issue #36): each input pair balanced so that its two back-actions on the
channel driving it cancel where a failing load's insulator sits; the nominal design untouched; a gate in its
network context that fcb rescues."""
from __future__ import annotations

import numpy as np
import pytest

from mech2spice import Mech2SpiceError
from mech2spice.experiments import montecarlo as mc
from mech2spice.physics import context, spread
from mech2spice.physics.params import load_params

P = load_params("centered_fc2")
SPEC = {"local": 0.01, "trim_residual": 0.0}


def _sample(model, elems, trim, index=3):
    return mc.spec_of({**SPEC, "trim": trim}).sample(model, elems, 7, index)[0]


def _back_action(model, pair, s):
    """The pair's net reaction on its channel per unit channel amplitude, its insulator at s: the spring-linked
    oscillator gives k_l^2 / Z_s, the dashpot-linked one (i w c_l)^2 / Z_d (zero in a matched pair)."""
    w = model.omega
    gamma = {f: g for f, _, g in model.quads}
    z = {d: model.k_total[d] + 2 * gamma.get(d, 0.0) * s - model.mass[d] * w * w + 1j * w * model.c_total[d]
         for d in (pair.spring_dof, pair.dashpot_dof)}
    k_l, c_l = model.springs[pair.spring][2], model.dashpots[pair.dashpot][2]
    return k_l ** 2 / z[pair.spring_dof] + (1j * w * c_l) ** 2 / z[pair.dashpot_dof]


@pytest.fixture(scope="module")
def network():
    cg = context.build(P, 4, (3, 3))
    return cg, spread.elements(cg.model, cg.block_dofs)


def test_fcb_leaves_the_nominal_design_as_it_is(network):
    cg, elems = network
    out = spread.trimmed(cg.model, cg.model, elems, "fcb", 0.0, np.random.default_rng(0),
                         balance_point=context.balance_point(P))
    assert out.k_total == cg.model.k_total and out.springs == cg.model.springs and out.c_total == cg.model.c_total


def test_every_input_pair_is_found(network):
    """The gate's two inputs, its 4 loads and the drivers' 3 other loads each: 12 pairs, each a spring and a
    dashpot from one channel."""
    cg, _ = network
    pairs = spread.input_pairs(cg.model)
    assert len(pairs) == 2 + 4 + 6
    for q in pairs:
        assert cg.model.springs[q.spring][:2] == (q.channel, q.spring_dof)
        assert cg.model.dashpots[q.dashpot][:2] == (q.channel, q.dashpot_dof)


def test_fcb_cancels_each_pairs_back_action_at_the_balance_point(network):
    """Spread 1 %: after fc every pair leaves a reaction on its channel that moves with its insulator; after fcb
    (no residual) the reaction at the balance point s(0,0) is zero to rounding, and at rest it is smaller than
    fc's at s(0,0)."""
    cg, elems = network
    s_t = context.balance_point(P)
    nominal = abs(P.k_couple ** 2 / (P.structure.dof("G1s").k + 2 * context.pair_gammas(P)[0] * s_t
                                      - P.structure.dof("G1s").m * P.omega ** 2))
    fc, fcb = _sample(cg.model, elems, "fc"), _sample(cg.model, elems, "fcb")
    pairs = spread.input_pairs(cg.model)
    before = np.array([abs(_back_action(fc, q, s_t)) for q in pairs]) / nominal
    after = np.array([abs(_back_action(fcb, q, s_t)) for q in pairs]) / nominal
    assert np.median(before) > 5e-3
    assert after.max() < 1e-10


def test_fcb_rescues_context_gates_that_fc_fails():
    """The gate with 4 loads and 3 more on each driver, loads held at their logic positions: draws 5, 6 and 8
    fail after fc (a second state outside the band, or the '0' lifted) and keep a margin after fcb."""
    cg = context.build(P, 4, (3, 3))
    elems = spread.elements(cg.model, cg.block_dofs)
    tab = context.insulator_positions(P)
    held = lambda m, other: [context.held(cg, m, tab[(o, other)], tab[(1, other)]) for o in (0, 1)]
    for trim, sign in (("fc", -1), ("fcb", 1)):
        spec = mc.spec_of({"local": 0.01, "trim": trim, "trim_residual": 1e-4})
        for i in (5, 6, 8):
            sm = spec.sample(cg.model, elems, 7, i)[0]
            assert sign * context.margins(cg, held(sm, 0) + held(sm, 1), 4).min() > 0, (trim, i)


def test_fcb_is_not_linearised_for_centering(network):
    cg, elems = network
    with pytest.raises(Mech2SpiceError, match="not linearised"):
        spread.trim_map(cg.model, elems, "fcb")
