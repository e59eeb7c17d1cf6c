"""Issue #38: scripts/verdict_floor.py counts the verdict's search, product by product, without changing it: on
the 2-bit adder at rest, the counted search gives the dense spectrum's rightmost eigenvalue, its solves are part of
its time, and the verdict's own solver is back in place afterwards."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg as sla

from mech2spice.physics import insulators, params, stability

ROOT = Path(__file__).resolve().parents[1]


def _script(name: str):
    spec = importlib.util.spec_from_file_location(name, ROOT / "scripts" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def adder_at_rest():
    vs = _script("verdict_structure")
    run, _ = vs.combinational(ROOT / "verilog/adder2.v", None, params.DEFAULT)
    env, A, s = vs.recorded_fixed_points(run)[-1]
    return env, *stability.linearise(env, A, s)


def test_the_counted_search_is_the_verdicts_search(adder_at_rest):
    floor = _script("verdict_floor")
    env, E, J = adder_at_rest
    T = env.model.period
    solver = stability._shifted_solver
    found = floor.counted_search(E, J, T, insulators.fast_nets(env))
    assert stability._shifted_solver is solver
    lam = sla.eigvals(J.toarray(), E.toarray())
    rightmost = lam[np.isfinite(lam)].real.max() * T
    assert abs(found["growth"] - rightmost) < 1e-8
    assert found["products"] > stability.MODES
    assert 0 < found["solve_s"] < found["seconds"] and found["arpack_own_s"] > 0
    assert 0 < found["product_s"] < found["solve_s"]
