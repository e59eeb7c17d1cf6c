"""Sensitivity (implicit-function theorem vs finite differences), per-element spread, the batched all-roots
steady states (vs the package's solver and envelope Jacobian), yield statistics, tolerance bisection, RK4
spot checks of Monte-Carlo samples, and the `gate --sens / --spread` command line."""
import json
from dataclasses import replace

import numpy as np
import pytest

from mech2spice import cli
from mech2spice.experiments import characterise, tolerance
from mech2spice.physics import loaded, params, sensitivity, spread, steady, steady_batch
from mech2spice.physics.envelope import Envelope


@pytest.fixture(scope="module")
def p():
    return params.DEFAULT


@pytest.fixture(scope="module")
def lg(p):
    return loaded.build(p)


def _amp(lg, model, p):
    st = steady_batch.stack([model], lg.input_groups(), lg.gate.channel)
    r = steady_batch.roots(st, 0, np.ones((1, 3)))
    assert r.stable.sum() == 1
    return r.amp[r.stable][0] / p.u_r


def _shift(model, elems, j, h):
    if j == len(elems):
        return replace(model, omega=model.omega * (1 + h))
    return spread.scaled(model, elems, 1 + h * (np.arange(len(elems)) == j))


# --- spread ------------------------------------------------------------------------------------
def test_scaled_by_one_is_identity_and_couplings_move_both_totals(lg):
    m = lg.model
    elems = spread.elements(m, lg.block_dofs)
    assert len(elems) == 36 and len({e.name for e in elems}) == 36
    same = spread.scaled(m, elems, np.ones(len(elems)))
    assert np.allclose(same.K.toarray(), m.K.toarray(), rtol=1e-15) and np.allclose(same.C.toarray(), m.C.toarray())
    j = next(k for k, e in enumerate(elems) if e.name == "spring gate.C-load.G1s")
    (i, jj, k0) = m.springs[elems[j].index]
    twice = spread.scaled(m, elems, 1 + (np.arange(len(elems)) == j))
    assert np.isclose(twice.k_total[i] - m.k_total[i], k0) and np.isclose(twice.k_total[jj] - m.k_total[jj], k0)
    assert np.allclose(twice.k_local, m.k_local)                  # local parts untouched


def test_perturb_is_reproducible_and_spares_the_inputs(lg):
    a = spread.perturb(lg.model, 1e-3, np.random.default_rng(5), lg.block_dofs)
    b = spread.perturb(lg.model, 1e-3, np.random.default_rng(5), lg.block_dofs)
    assert a.k_total == b.k_total and a.k_total != lg.model.k_total
    for u in lg.upstream:                                        # the stand-in sources are not spread
        assert a.mass[u] == lg.model.mass[u]
    assert [d.amplitude for d in a.drives][:2] == [d.amplitude for d in lg.model.drives][:2]


# --- batched steady states -------------------------------------------------------------------
def test_nominal_loaded_gate_equals_single_gate_margin(p, lg):
    levels, expect = loaded.input_grid(8)
    st = steady_batch.stack([lg.model], lg.input_groups(), lg.gate.channel)
    r = steady_batch.roots(st, 0, levels)
    pm = loaded.point_margins(r, expect, p.u_r)
    vm = characterise.valid_region_margin(p, per_band=8)
    assert abs(pm.min() - vm["min_margin"]) < 1e-9
    assert list(levels[pm.argmin(), 1:]) == vm["at_inputs"]
    ss = characterise.steady_outputs(p, np.array([0.67, 1.025]), np.array([0.67, 0.365]))
    for x, states in zip([(0.67, 0.67), (1.025, 0.365)], ss):
        k = int(np.flatnonzero(np.all(np.isclose(levels[:, 1:], x), axis=1))[0])
        got = sorted(r.amp[r.point == k] / p.u_r)
        assert np.allclose(got, sorted(a for a, _ in states), atol=1e-10)


def test_batched_stability_matches_envelope_jacobian(p, lg):
    m = spread.perturb(lg.model, 1e-4, np.random.default_rng(2), lg.block_dofs)
    m = loaded.at_inputs(lg, 0.67, 0.5, m)
    st = steady_batch.stack([m], lg.input_groups(), lg.gate.channel)
    r = steady_batch.roots(st, 0, np.ones((1, 3)))
    env = Envelope(m)
    F = env.forcing(np.array([d.amplitude for d in m.drives]))[:, 0]
    for k in range(r.s.size):
        A = env.fast_response(r.s[k:k + 1], F)
        g_env, _ = steady.stability(env, A, r.s[k:k + 1], F)
        assert abs(r.growth[k] - g_env) < 1e-6 * max(1.0, abs(g_env))


# --- sensitivity -------------------------------------------------------------------------------
def test_output_sensitivities_match_finite_differences(p, lg):
    """Every element and omega, inputs 00 and 11: implicit-function theorem vs central differences (1 %)."""
    elems = sensitivity.spread_elements(lg)
    for (x1, x2), expect in (((0.5, 0.5), 1), ((0.97, 0.97), 0)):
        g = sensitivity.margin_gradients(p, lg, elems, np.array([[1.0, x1, x2]]), np.array([expect]), 4000)
        ift = g["amp_grad"][0]
        base = loaded.at_inputs(lg, x1, x2)
        h = 1e-6
        fd = np.array([(_amp(lg, _shift(base, elems, j, h), p) - _amp(lg, _shift(base, elems, j, -h), p)) / (2 * h)
                       for j in range(len(elems) + 1)])
        scale = np.abs(fd).max()
        assert np.all(np.abs(ift - fd) <= 0.01 * np.abs(fd) + 1e-6 * scale), np.abs(ift - fd).max()


def test_worst_margin_sensitivity_matches_finite_differences(p, lg):
    s = sensitivity.gate_sensitivity(p, per_band=4)
    levels, expect = loaded.input_grid(4)
    elems = sensitivity.spread_elements(lg)

    def worst(m):
        st = steady_batch.stack([m], lg.input_groups(), lg.gate.channel)
        return loaded.point_margins(steady_batch.roots(st, 0, levels), expect, p.u_r).min()

    assert abs(worst(lg.model) - s["worst"]["margin"]) < 1e-12
    g = s["worst"]["gradient"]
    h = 1e-6
    fd = np.array([(worst(_shift(lg.model, elems, j, h)) - worst(_shift(lg.model, elems, j, -h))) / (2 * h)
                   for j in range(len(elems) + 1)])
    assert np.all(np.abs(g - fd) <= 0.01 * np.abs(fd) + 1e-6 * np.abs(fd).max())
    assert np.abs(g).max() > 100                                 # the gate is sensitive: a real check


# --- statistics and tolerance ---------------------------------------------------------------------
def test_wilson_interval():
    lo, hi = tolerance.wilson(0, 10)
    assert lo == 0.0 and abs(hi - 0.2775) < 1e-4
    lo, hi = tolerance.wilson(5, 10)
    assert abs(lo - 0.2366) < 1e-4 and abs(hi - 0.7634) < 1e-4


def test_tolerance_bisection_brackets_the_99_percent_point(p):
    sampler = tolerance.Sampler(p, samples=4, seed=3, per_band=4, n_grid=1000)
    t = tolerance.tolerance(sampler, lo=1e-7, hi=1e-3, resolution=2.0)
    lo, hi = t["bracket"]
    assert hi / lo <= 2.0 and t["sigma"] == lo
    assert (sampler.run(lo)["margins"] > 0).all() and not (sampler.run(hi)["margins"] > 0).all()


def test_steady_state_pass_fail_matches_rk4(p):
    """Monte-Carlo samples at sigma 1e-5 (two failing, two passing; seed 1 of 40), RK4 from rest at each
    sample's worst input point: same pass/fail, same amplitude."""
    sampler = tolerance.Sampler(p, samples=40, seed=1)
    picks = []
    for i in (21, 23, 34, 11):
        m = sampler.margins(sampler.model(1e-5, i))
        picks.append((i, int(m.argmin())))
        assert (m.min() > 0) == (i in (34, 11))
    for c in tolerance.rk4_check(sampler, 1e-5, picks, periods=12000, load="pair"):
        assert (c["margin_rk4"] > 0) == (c["margin_steady"] > 0), c
        assert abs(c["rk4"] - min(c["steady"])) < 0.002, c


# --- command line ------------------------------------------------------------------------------
def test_cli_spread_json(capsys):
    assert cli.main(["gate", "--spread", "1e-5", "--samples", "3", "--seed", "4", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("yield", "yield_ci95", "margin_quantiles", "tolerance", "samples", "sigma", "seed"):
        assert key in out
    assert out["samples"] == 3 and out["seed"] == 4 and out["sigma"] == 1e-5
    assert set(out["margin_quantiles"]) == {"1%", "5%", "50%", "95%", "99%"}
    t = out["tolerance"]
    assert t["bracket"][1] / t["bracket"][0] <= t["resolution"]


@pytest.mark.parametrize("argv, msg", [
    (["gate", "--spread", "-1"], "argument --spread: must be a finite number above 0"),
    (["gate", "--spread", "1e-4", "--samples", "0"], "argument --samples: must be from 1"),
    (["gate", "--samples", "5"], "apply to --spread"),
    (["gate", "--sens", "--report", "x"], "--quick and --report"),
])
def test_cli_bad_robustness_input(argv, msg, capsys):
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert msg in err and err.count("\n") == 1


@pytest.mark.parametrize("fields, mode, msg", [
    ({"k_c": 1e300}, "--sens", "failed numerically (FloatingPointError: overflow"),
    ({"q_g": 1e300}, "--sens", "no stable steady state at inputs 00, 10, 01, 11"),
    ({"omega": 1e300}, "--spread", "failed numerically (OverflowError"),
    ({"u_r": 1e-300}, "--spread", "failed numerically (FloatingPointError: overflow"),
    ({"m_c": 1e-300}, "--sens", "the steady-state scan overflowed"),
])
def test_cli_extreme_finite_parameters_are_one_line(fields, mode, msg, tmp_path, capsys):
    """Parameters valid by type and sign but far outside the gate's range: one line, exit 2, no traceback
    and no numpy warning (they gave IndexError, LinAlgError, OverflowError tracebacks)."""
    f = tmp_path / "extreme.json"
    f.write_text(json.dumps(fields))
    argv = ["gate", "--params", str(f), mode] + (["0.01", "--samples", "2"] if mode == "--spread" else []) + ["--json"]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert msg in err and err.count("\n") == 1 and err.startswith("mech2spice: error: ")
