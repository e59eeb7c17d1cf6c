"""The gate in its network context (physics/context.py): one load at rest is the loaded gate, N nominal loads cancel,
eliminating the held load pairs changes no steady state, insulator positions follow the logic states."""
from __future__ import annotations

import numpy as np
import pytest

from mech2spice.experiments import montecarlo as mc
from mech2spice.physics import context, loaded, spread, steady_batch
from mech2spice.physics.params import load_params

P = load_params("centered_fc2")


def _full_margin(cg, models, per_band=4):
    lv, ex = loaded.input_grid(per_band, P.levels)
    st = steady_batch.stack(models, cg.input_groups(), cg.gate.channel)
    return min(float(loaded.point_margins(steady_batch.roots(st, o, lv[ex == o]), ex[ex == o], P.u_r, P.levels).min())
               for o in (0, 1))


def test_one_load_at_rest_is_the_loaded_gate():
    lg, cg = loaded.build(P), context.build(P, 1)
    lv, ex = loaded.input_grid(4, P.levels)
    r = steady_batch.roots(steady_batch.stack([lg.model], lg.input_groups(), lg.gate.channel), 0, lv)
    want = float(loaded.point_margins(r, ex, P.u_r, P.levels).min())
    assert abs(context.margins(cg, [cg.model, cg.model], 4)[0] - want) < 1e-9


def test_nominal_loads_cancel_whatever_their_number_and_insulators():
    """Matched spring and dashpot links cancel their back-action: 12 loads held at any position and 11 more on
    each driver leave the nominal gate's margin as it is."""
    tab = context.insulator_positions(P)
    one = context.build(P, 1)
    base = context.margins(one, [one.model, one.model], 4)[0]
    cg = context.build(P, 12, (11, 11))
    held = [context.held(cg, cg.model, tab[(o, 1)], tab[(1, 1)]) for o in (0, 1)]
    assert abs(context.margins(cg, held, 4)[0] - base) < 1e-6


def test_eliminated_loads_keep_the_steady_states_of_the_full_model():
    """A spread sample (1 %, trimmed) with 2 loads and 1 more on each driver, held at logic positions: the
    reduced model's margin equals the full model's."""
    tab = context.insulator_positions(P)
    cg = context.build(P, 2, (1, 1))
    spec = mc.spec_of({"local": 0.01, "trim": "fc", "trim_residual": 1e-4})
    sm, _ = spec.sample(cg.model, spread.elements(cg.model, cg.block_dofs), 7, 1)
    held = [context.held(cg, sm, tab[(o, 1)], tab[(1, 1)]) for o in (0, 1)]
    assert abs(context.margins(cg, held, 4)[0] - _full_margin(cg, held)) < 1e-9
    assert context.reduced(cg, held[0]).n == max(cg.gate.dofs) + 1


def test_insulator_positions_follow_the_inputs():
    """A load's insulator moves with the amplitudes at its inputs: both '1' displace it most (of the
    driven states), one '1' is the same whichever input carries it."""
    tab = context.insulator_positions(P)
    # equal to rounding: the two inputs are different DOFs, so their sums run in different orders
    assert tab[(0, 1)] == pytest.approx(tab[(1, 0)], rel=1e-12, abs=0)
    assert abs(tab[(1, 1)]) > abs(tab[(1, 0)])
    assert np.isfinite(list(tab.values())).all()
