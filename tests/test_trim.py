"""Trimming and drift (physics/spread.py trimmed / drifted / trim_map / sigmas; experiments/trim.py flags):
what a trim restores and what it leaves, `--trim none` unchanged, the gain in yield, the drift, bad input."""
from __future__ import annotations

import json

import numpy as np
import pytest

from mech2spice.errors import Mech2SpiceError
from mech2spice.experiments import montecarlo as mc
from mech2spice.experiments import tolerance
from mech2spice.physics import loaded, spread
from mech2spice.physics.params import DEFAULT

from cli_helpers import refused, run, verilog

SIGMA = 1e-2            # a spread far beyond the gate's untrimmed tolerance (~2e-6, docs/robustness.md)


@pytest.fixture(scope="module")
def gate():
    lg = loaded.build(DEFAULT)
    return lg.model, spread.elements(lg.model, lg.block_dofs)


def spread_copy(model, elems, seed=1):
    return spread.scaled(model, elems, 1 + SIGMA * np.random.default_rng(seed).standard_normal(len(elems)))


def ratio(model, key):
    return np.asarray(getattr(model, key)) / np.asarray(model.mass)


@pytest.mark.parametrize("mode", ["f", "fc"])
def test_trim_restores_each_trimmed_dof_within_the_residual(gate, mode):
    nominal, elems = gate
    residual = 1e-4
    dofs = spread.trimmed_dofs(nominal, elems)
    assert dofs and all(not nominal.slow[i] for i in dofs)
    t = spread.trimmed(spread_copy(nominal, elems), nominal, elems, mode, residual, np.random.default_rng(2))
    for key in ("k_total", "c_total") if mode == "fc" else ("k_total",):
        err = ratio(t, key)[dofs] / ratio(nominal, key)[dofs] - 1
        assert np.all(np.abs(err) < 5 * residual) and np.any(np.abs(err) > residual / 100), err
    exact = spread.trimmed(spread_copy(nominal, elems), nominal, elems, mode, 0.0, np.random.default_rng(2))
    assert np.allclose(ratio(exact, "k_total")[dofs], ratio(nominal, "k_total")[dofs], rtol=1e-14, atol=0)


@pytest.mark.parametrize("mode", ["f", "fc"])
def test_trim_leaves_couplings_gammas_drives_masses_and_insulators(gate, mode):
    nominal, elems = gate
    s = spread_copy(nominal, elems)
    t = spread.trimmed(s, nominal, elems, mode, 1e-3, np.random.default_rng(3))
    assert (t.springs, t.dashpots, t.quads, t.drives, t.mass) == (s.springs, s.dashpots, s.quads, s.drives, s.mass)
    slow = np.flatnonzero(nominal.slow)
    assert slow.size and np.array_equal(np.asarray(t.k_total)[slow], np.asarray(s.k_total)[slow])
    assert np.array_equal(np.asarray(t.c_total)[slow], np.asarray(s.c_total)[slow])
    assert not np.array_equal(np.asarray(t.k_total)[slow], np.asarray(nominal.k_total)[slow])   # still spread
    if mode == "f":                       # damping is not trimmed: still the spread copy's
        assert t.c_total == s.c_total


@pytest.mark.parametrize("mode", ["none", "f", "fc"])
def test_trim_map_is_the_linearised_trim(gate, mode):
    """scaled(J u) equals spread-then-trim to second order, u zero at the trimmed coordinates (residual 0)."""
    nominal, elems = gate
    u = 1e-6 * np.random.default_rng(4).standard_normal(len(elems)) * (spread.sigmas(elems, nominal, 1.0, mode) > 0)
    exact = spread.trimmed(spread.scaled(nominal, elems, 1 + u), nominal, elems, mode, 0.0, np.random.default_rng(0))
    lin = spread.scaled(nominal, elems, 1 + spread.trim_map(nominal, elems, mode) @ u)
    for key in ("k_total", "c_total"):
        a, b = np.asarray(getattr(exact, key)), np.asarray(getattr(lin, key))
        assert np.max(np.abs(a - b) / np.abs(a)) < 1e-10


def test_sigmas_put_the_residual_on_the_trimmed_coordinates(gate):
    nominal, elems = gate
    dofs = set(spread.trimmed_dofs(nominal, elems))
    s = spread.sigmas(elems, nominal, 1e-3, "f", 1e-5)
    for e, x in zip(elems, s):
        assert x == (1e-5 if e.kind == "k" and e.index in dofs else 1e-3), e.name
    fc = spread.sigmas(elems, nominal, 1e-3, "fc", 1e-5)
    assert sum(x == 1e-5 for x in fc) == 2 * len(dofs)
    assert np.all(spread.sigmas(elems, nominal, 1e-3) == 1e-3)


def test_trim_none_is_the_untrimmed_sample_bit_for_bit(gate):
    nominal, elems = gate
    s = tolerance.Sampler(DEFAULT, 3, 5, per_band=2, n_grid=64)
    assert s.model(1e-3, 2) == spread.scaled(s.base.model, s.elements, 1 + 1e-3 * s.eps[2])
    spec = mc.parse_spread("1e-3")
    model, f = spec.sample(nominal, elems, 7, 4)
    assert f.tolist() == spec.factors(elems, 7, 4).tolist() and model == spread.scaled(nominal, elems, f)
    assert spec.describe() == {"local": spec.local, "wafer": spec.wafer, "wafer_rho": 0.0}   # results-file keys


def test_trim_raises_the_gate_yield_where_untrimmed_yield_is_zero():
    """At 3e-5 (10x the untrimmed tolerance) no untrimmed sample passes; trimming k/m rescues them."""
    none = tolerance.yield_at(tolerance.Sampler(DEFAULT, 8, 0), 3e-5)
    trimmed = tolerance.yield_at(tolerance.Sampler(DEFAULT, 8, 0, trim="f"), 3e-5)
    assert none["passed"] == 0 and trimmed["passed"] >= 7, (none["passed"], trimmed["passed"])


def test_drift_scales_every_stiffness_and_nothing_else(gate):
    nominal, _ = gate
    d = spread.drifted(nominal, -2e-3)
    assert np.allclose(d.k_total, np.asarray(nominal.k_total) * (1 - 2e-3), rtol=1e-15, atol=0)
    assert np.allclose(d.k_local, nominal.k_local * (1 - 2e-3), rtol=1e-12, atol=0)
    assert [k for *_, k in d.springs] == [k * (1 - 2e-3) for *_, k in nominal.springs]
    assert (d.mass, d.c_total, d.dashpots, d.quads, d.drives) == (nominal.mass, nominal.c_total, nominal.dashpots,
                                                                  nominal.quads, nominal.drives)
    assert spread.drifted(nominal, 0.0) is nominal


def test_spread_spec_carries_trim_and_drift(gate):
    nominal, elems = gate
    spec = mc.parse_spread('{"local": 1e-3, "trim": "fc", "trim_residual": 1e-5, "drift": 1e-3}')
    assert spec.describe()["trim"] == "fc" and mc.spec_of(spec.describe()) == spec
    model, _ = spec.sample(nominal, elems, 1, 0)
    dofs = spread.trimmed_dofs(nominal, elems)
    err = ratio(model, "k_total")[dofs] / ratio(nominal, "k_total")[dofs] - 1 - 1e-3     # drift after the trim
    assert np.all(np.abs(err) < 1e-4)
    assert not mc.parse_spread('{"local": 0, "drift": 1e-3}').zero


@pytest.mark.parametrize("bad, needle", [('{"trim": "k"}', "trim must be one of"),
                                         ('{"trim": "f", "trim_residual": 1.5}', "residual"),
                                         ('{"trim_residual": 1e-3}', "needs a trim"),
                                         ('{"drift": -1}', "drift"), ('{"trim": 1}', "trim")])
def test_bad_spread_spec_trims_are_refused(bad, needle):
    with pytest.raises(Mech2SpiceError, match=needle):
        mc.parse_spread(bad)


@pytest.mark.parametrize("argv, needle", [
    (["--trim", "fc"], "apply to --spread"),
    (["--drift", "1e-3"], "apply to --spread"),
    (["--sens", "--trim", "f"], "apply to --spread"),
    (["--spread", "1e-3", "--trim-residual", "1e-4"], "--trim-residual needs --trim"),
    (["--spread", "1e-3", "--trim", "f", "--trim-residual", "1"], "--trim-residual must be below 1"),
    (["--spread", "1e-3", "--drift", "1"], "--drift must be"),
    (["--spread", "1e-3", "--trim", "fk"], "--trim"),
    (["--spread", "1e-3", "--trim-residual", "-1e-3", "--trim", "f"], "--trim-residual"),
])
def test_gate_refuses_bad_trim_flags(capsys, argv, needle):
    refused(capsys, "gate", *argv, needle=needle)


def test_montecarlo_refuses_bad_trim_flags(capsys, tmp_path):
    v = verilog(tmp_path, "module n(input a, output y);\n  assign y = ~a;\nendmodule\n")
    refused(capsys, "montecarlo", v, "--samples", 1, "--spread", 1e-3, "--trim-residual", 1e-3,
            needle="--trim-residual needs --trim")
    refused(capsys, "montecarlo", v, "--samples", 1, "--spread", '{"trim": "f"}', "--trim", "fc",
            needle="not both")
    refused(capsys, "cpu", "montecarlo", "x.asm", "--samples", 1, "--spread", 1e-3, "--drift", "2",
            needle="--drift")


def test_gate_json_has_the_trim_fields(capsys):
    rc, out, _ = run(capsys, "gate", "--spread", "3e-5", "--trim", "f", "--drift=-1e-6", "--samples", 2, "--json")
    res = json.loads(out)
    assert rc == 0 and (res["trim"], res["trim_residual"], res["drift"]) == ("f", 0.0, -1e-6)
    assert res["yield"] == 1.0 and "tolerance" in res and "margin_quantiles" in res
