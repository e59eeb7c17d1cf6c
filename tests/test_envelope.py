"""The envelope model against RK4 (80 steps/period): settled amplitudes within 0.02 u_R, threshold-crossing
(switching) times within 10 %, the same number of crossings, the same decoded logic.  Full numbers per
scene: reports/envelope.md (`mech2spice report envelope`)."""
import math

import numpy as np
import pytest

from mech2spice import simulation
from mech2spice.experiments import characterise
from mech2spice.backends import envelope
from mech2spice.experiments import validate as V
from mech2spice.experiments import scenes as S
from mech2spice.errors import Mech2SpiceError
from mech2spice.physics.params import band_of

STEP = envelope.DEFAULT_STEP          # what run_physical uses


def both(scene, step=STEP):
    ref = V.run_rk4(scene)
    env = V.run_envelope(scene, step)
    return ref, env, V.compare(scene, ref, env)


def assert_agrees(c, min_crossings):
    assert c["amp_err"] <= V.AMP_TOL, c["windows"]
    assert c["n_crossings"] >= min_crossings
    assert c["crossing_count_mismatch"] == 0, [x for x in c["crossings"] if x["n_ref"] != x["n_test"]]
    bad = [x for x in c["crossings"] if max(x["first_rel"], x["last_rel"]) > V.TIME_TOL]
    assert not bad, bad


def test_band_edge_gate_inputs(p):
    """All 16 pairs of band-edge input levels on one gate, from rest."""
    sc = S.gate_scene(p, "edge")
    ref, env, c = both(sc)
    assert_agrees(c, min_crossings=4)
    a_ref = V.settled(ref["amp"], ref["t"], sc.periods)[0]
    a_env = V.settled(env["amp"], env["t"], sc.periods)[0]
    assert [band_of(a) for a in a_env] == [band_of(a) for a in a_ref]
    # every member is in its band except (0.67, 0.67), still creeping towards '1' at 2500 periods on both
    assert [m for m, a in zip(sc.members, a_ref) if band_of(a) is None] == ["0.67,0.67"]


def test_chain_switching_times(p):
    """3-gate chain, inputs 00 -> 10 -> 00: every stage's crossing time within 10 % (both directions),
    and the band-edge members' level restoration within 0.02 u_R."""
    sc = S.chain_scene(p)
    ref, env, c = both(sc)
    assert_agrees(c, min_crossings=20)
    switched = [x for x in c["crossings"] if x["member"] == "00->10->00" and x["event"] > 0]
    assert len(switched) == 6                  # 3 stages x 2 input changes
    for x in switched:
        assert abs(x["first_test"] - x["first_ref"]) <= V.TIME_TOL * x["first_ref"], x
    # the delays the gate report quotes: cumulative crossing times per stage, as characterise._crossings
    for event in (1500, 3000):
        r = [x["first_ref"] for x in switched if x["event"] == event]
        e = [x["first_test"] for x in switched if x["event"] == event]
        assert np.all(np.diff(r) > 0) and np.all(np.diff(e) > 0)
        assert np.allclose(e, r, rtol=V.TIME_TOL)


def test_fanout2(p):
    sc = S.fanout_scene(p, 2)
    ref, env, c = both(sc)
    assert_agrees(c, min_crossings=4)
    a_ref = V.settled(ref["amp"], ref["t"], sc.periods)
    a_env = V.settled(env["amp"], env["t"], sc.periods)
    assert [[band_of(a) for a in row] for row in a_env] == [[band_of(a) for a in row] for row in a_ref]


def test_latch_sequence_decoded_identically(p):
    r = characterise.latch_sequence(p, "rk4")
    try:
        e = characterise.latch_sequence(p, "envelope")
    except KeyError as ex:
        pytest.fail(f"characterise.latch_sequence(p, 'envelope') cannot read probe {ex}: envelope.integrate resolves "
                    "probe names through model.probes only, rk4.integrate also through model.index")
    res = V.latch_compare(p, env_result=e, rk4_result=r)
    assert res["identical"], (res["decoded_rk4"], res["decoded_env"])
    assert None not in res["decoded_rk4"][1:]
    assert res["max_output_diff"] <= V.AMP_TOL
    assert len(res["delays_rk4"]) == 2 and all(math.isfinite(d) for d in res["delays_env"])
    assert max(res["delay_rel"]) <= V.TIME_TOL, (res["delays_rk4"], res["delays_env"])


def test_step_beyond_bound_is_refused(p):
    sc = S.gate_scene(p, "nominal", periods=200)
    limit = envelope.max_step_periods(sc.model)
    with pytest.raises(Mech2SpiceError, match="stability limit"):
        envelope.integrate(sc.model, 200, step_periods=float(math.ceil(limit + 1)), stimulus=sc.stimulus)
    # just inside the bound it is stable and still accurate: the settled gate within 0.02 u_R of step 1/4
    long = S.gate_scene(p, "nominal", periods=2000)
    r = envelope.integrate(long.model, 2000, step_periods=float(math.floor(limit)), stimulus=long.stimulus)
    ref = envelope.integrate(long.model, 2000, step_periods=0.25, stimulus=long.stimulus)
    assert np.abs(np.abs(r.amp[-1]) - np.abs(ref.amp[-1])).max() / p.u_r < V.AMP_TOL


def test_rk4_stability_region():
    """The step rule used in reports/envelope.md: RK4's region reaches 2.785 on the real axis, 2.828 on
    the imaginary one."""
    assert V.rk4_stable_step(np.array([-1.0])) == pytest.approx(2.7853, abs=1e-3)
    assert V.rk4_stable_step(np.array([-1e-6 + 1j])) == pytest.approx(2 * math.sqrt(2), abs=1e-3)


def _chain_scene(p):
    """chain(3), input 1 at four levels (a batch), reversed at 2000 periods."""
    from mech2spice.physics import nor
    from mech2spice.physics.params import NOMINAL0, NOMINAL1
    from mech2spice.physics.stimulus import Stimulus
    m = nor.chain(p, 3)
    T = 2 * np.pi / p.omega
    d1 = m.design.input_drives[0]
    lv = np.array([NOMINAL0, NOMINAL1, 0.45, 0.95]) * p.f_r
    stim = Stimulus.from_levels(m, [(0.0, {d: lv for d in d1}), (2000 * T, {d: lv[::-1] for d in d1})], batch=4)
    return m, stim


@pytest.mark.parametrize("step", [0.5, 4.0])
def test_compiled_kernel_equals_numpy_path(p, step):
    """envelope_kernel.py computes the numpy path's equations (block-inverse solve vs SuperLU) to rounding,
    across a stimulus change, with sub-period and multi-period steps."""
    m, stim = _chain_scene(p)
    if envelope.kernel(m) is None:
        pytest.skip("numba missing")
    fast = envelope.integrate(m, 2400, step_periods=step, stimulus=stim)
    slow = envelope.integrate(m, 2400, step_periods=step, stimulus=stim, compiled=False)
    assert np.abs(fast.amp - slow.amp).max() < 1e-9 * p.u_r
    assert np.abs(fast.amp).max() > 0.5 * p.u_r


def test_settle_skips_idle_time_within_tolerance(p):
    """settle= ends a constant-stimulus stretch once the channels are steady: the held state stays within
    the tolerance of the full integration, the next stimulus change is still simulated, and the compiled
    and numpy paths stop at the same step."""
    m, stim = _chain_scene(p)
    full = envelope.integrate(m, 4000, step_periods=4.0, stimulus=stim)
    runs = [envelope.integrate(m, 4000, step_periods=4.0, stimulus=stim, settle_tol=0.02, compiled=c)
            for c in (True, False)]
    assert runs[0].settled_periods == runs[1].settled_periods > 1500
    assert np.abs(runs[0].amp - runs[1].amp).max() < 1e-9 * p.u_r
    err = np.abs(np.abs(runs[0].amp) - np.abs(full.amp)).max() / p.u_r
    assert err < 0.02
    # each stretch switched the chain (the output changed band), so the skip did not swallow the change
    out = np.abs(runs[0].amp[:, -1, :]) / p.u_r
    assert [band_of(x) for x in out[1990]] == [band_of(x) for x in out[-1]][::-1]


def test_step_bound_is_the_spectral_rate_with_margin(p):
    """max_step_periods comes from the largest |eigenvalue| of the linear part at rest (ARPACK, checked
    here against a dense eigensolve) times RATE_SAFETY, below the RK4 onset the report measures."""
    from mech2spice.physics import nor
    m = nor.single_gate(p)
    env = envelope.Envelope.of(m)
    nf = env.fast.size
    dense = -np.column_stack([env.solve_rate(env.Z0 @ e) for e in np.eye(nf, dtype=complex)])
    k, c, ms = env.Ks.diagonal(), env.Cs.diagonal(), env.ms
    slow = np.abs(np.roots([ms[0], c[0], k[0]])).max()
    want = max(np.abs(np.linalg.eigvals(dense)).max(), slow)
    assert envelope.spectral_rate(env) == pytest.approx(want, rel=1e-6)
    assert envelope.rate_bound(m) == pytest.approx(envelope.RATE_SAFETY * want)
    assert envelope.rate_bound(m) < envelope.gershgorin_rate(env)



@pytest.mark.parametrize("keep", [7, 2300, 5000])
def test_a_run_keeping_its_last_periods_keeps_exactly_those(p, keep):
    """keep_periods: the Run holds the full record's last periods (integrated and held alike), the same
    final state and the matching times; more than the run keeps everything."""
    m, stim = _chain_scene(p)
    opts = dict(step_periods=4.0, stimulus=stim, settle_tol=0.02, latency=0.05)
    full = envelope.integrate(m, 4000, **opts)
    last = envelope.integrate(m, 4000, keep_periods=keep, **opts)
    assert full.settled_periods > 0            # the held stretch is inside what a small keep covers
    n = min(keep, 4000)
    assert last.amp.shape[0] == n
    np.testing.assert_array_equal(last.amp, full.amp[-n:])
    np.testing.assert_array_equal(last.t_end, full.t_end[-n:])
    np.testing.assert_array_equal(last.state[0], full.state[0])
