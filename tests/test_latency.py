"""The envelope's speed-ups (issue 18, docs/latency.md): per-gate latency and the exponential step agree
with the plain envelope within their stated tolerances and decode the same bits; bad settings are one-line
errors.  Measured numbers per option on the processor and the clocked designs: reports/fidelity.md."""

import numpy as np
import pytest
from conftest import run_main

from mech2spice import simulation
from mech2spice.backends import envelope
from mech2spice.backends.envelope import EnvelopeOptions, integrate
from mech2spice.errors import Mech2SpiceError
from mech2spice.experiments import clocking
from mech2spice.experiments import scenes as S
from mech2spice.physics.params import DEFAULT, band_of
from mech2spice.synthesis.synth import synthesize
from mech2spice import data

LATENCY = 0.1          # u_R: the threshold tested (the processor's default, reports/fidelity.md)
LATENCY_TOL = 0.01     # u_R: settled adder amplitudes, latency on vs off (measured 0.0007)
EXPO_TOL = 0.01        # u_R: settled chain amplitudes, exponential step 16 vs RK4 step 2 (measured 0.0052)


def settled(scene, run):
    """|A| / u_R averaged over the last 10 periods of each input setting: (settings, probes, batch)."""
    return np.stack([np.abs(run.amp[w - 10:w]).mean(0) for w in scene.windows]) / scene.model.amplitude_unit


@pytest.fixture(scope="module")
def adder():
    return S.adder_scene()


def test_latency_adder_agrees_and_skips_work(adder):
    """All 16 adder inputs in one batch: latency on vs off within LATENCY_TOL, the same bands, and
    frozen gates really skipped (fewer gate-block steps than the full envelope's)."""
    full = integrate(adder.model, adder.periods, step_periods=4, stimulus=adder.stimulus)
    lat = integrate(adder.model, adder.periods, step_periods=4, stimulus=adder.stimulus, latency=LATENCY)
    a, b = settled(adder, full), settled(adder, lat)
    assert np.abs(a - b).max() <= LATENCY_TOL
    assert [band_of(x) for x in a.ravel()] == [band_of(x) for x in b.ravel()]
    every_step = lat.extra["blocks"] * adder.periods // 4
    assert lat.extra["block_steps"] < 0.7 * every_step, lat.extra


def test_latency_state_continues(adder):
    """A run split in two (the latency record travels in the state) equals one run within LATENCY_TOL."""
    one = integrate(adder.model, adder.periods, step_periods=4, stimulus=adder.stimulus, latency=LATENCY)
    half = adder.periods // 2
    first = integrate(adder.model, half, step_periods=4, stimulus=adder.stimulus, latency=LATENCY)
    assert len(first.state) == 8
    second = integrate(adder.model, adder.periods - half, step_periods=4, stimulus=adder.stimulus,
                       latency=LATENCY, state=first.state, start_period=half)
    assert np.abs(np.abs(second.amp[-1]) - np.abs(one.amp[-1])).max() / adder.model.amplitude_unit <= LATENCY_TOL


def test_latency_counter_trace_equals_full():
    """The clocked counter: latency on vs off decode the same trace, amplitudes within 0.02 u_R at reads."""
    nl = synthesize(data.verilog("counter4.v"))
    cycles = simulation.expand_steps(S.COUNTER_STEPS)
    timing = clocking.clock_timing(nl)
    runs = [simulation.run_clocked_physical(nl, DEFAULT, cycles, "envelope", timing,
                                            options=EnvelopeOptions(latency=lat)) for lat in (None, LATENCY)]
    full, lat = ([e["outputs"] for e in r["trace"]] for r in runs)
    assert full == lat
    diff = max(abs(e["amplitudes"][k] - f["amplitudes"][k]) for e, f in zip(runs[0]["trace"], runs[1]["trace"])
               for k in e["amplitudes"])
    assert diff <= 0.02


def test_exponential_step_on_chain():
    """The 3-gate chain (switching both ways, band-edge members): the exponential step at 16 periods,
    beyond RK4's stability bound, stays within EXPO_TOL of RK4 at 2 periods at every settled point."""
    sc = S.chain_scene()
    assert envelope.max_step_periods(sc.model) < 16 < envelope.max_step_periods(sc.model, exponential=True)
    with pytest.raises(Mech2SpiceError, match="stability limit"):
        integrate(sc.model, sc.periods, step_periods=16, stimulus=sc.stimulus)
    ref = settled(sc, integrate(sc.model, sc.periods, step_periods=2, stimulus=sc.stimulus))
    got = settled(sc, integrate(sc.model, sc.periods, step_periods=16, stimulus=sc.stimulus, exponential=True))
    assert np.abs(got - ref).max() <= EXPO_TOL
    assert [band_of(x) for x in got.ravel()] == [band_of(x) for x in ref.ravel()]


@pytest.mark.parametrize("opts, msg", [(dict(latency=1.5), "latency threshold"),
                                       (dict(latency=-0.1), "latency threshold"),
                                       (dict(latency=float("nan")), "latency threshold"),
                                       (dict(latency=0.1, latency_wake=0.0), "latency wake threshold"),
                                       (dict(latency=0.1, latency_calm=-1.0), "latency calm time")])
def test_bad_options(opts, msg):
    with pytest.raises(Mech2SpiceError, match=msg):
        EnvelopeOptions(**opts).validate()


@pytest.mark.parametrize("args, msg", [
    (["simulate", "verilog/adder2.v", "--backend", "rk4", "--latency", "0.1"], "envelope backend options"),
    (["simulate", "verilog/adder2.v", "--backend", "envelope", "--latency", "2"], "--latency"),
    (["cpu", "run", "programs/sieve.asm", "--backend", "iss", "--exponential", "on"], "envelope backend only"),
])
def test_cli_refuses(args, msg):
    code, _, err = run_main(*args)
    assert code == 2
    assert msg in err and len(err.strip().splitlines()) == 1, err


def test_exponential_default_step_and_prepare():
    """With the exponential step the engine's default step rises to 16 periods where its bound allows;
    prepare() builds the cached operators, after which the run needs no new ones."""
    from mech2spice.backends import make_engine
    sc = S.chain_scene()
    rk4, expo = make_engine("envelope"), make_engine("envelope", EnvelopeOptions(exponential=True))
    assert rk4.step(sc.model) == envelope.DEFAULT_STEP and expo.step(sc.model) == 16.0
    expo.prepare(sc.model)
    cached = set(sc.model.derived)
    assert {"envelope", "envelope_kernel", "envelope_rate_fast"} <= cached
    expo.run(sc.model, 100, sc.stimulus)
    assert set(sc.model.derived) == cached


def test_latency_off_parses_to_none():
    from mech2spice import inputs
    parse = inputs.number_or_off(0, 1)
    assert parse("off") == 0.0 and parse("0.1") == 0.1
    with pytest.raises(Exception, match="'off' or a number"):
        parse("1")


def test_etd_step_on_the_centred_chain_agrees_with_a_fine_step(monkeypatch):
    """centered_fc2's 3-gate chain: RK4 with exact insulators is refused at 16 periods (the pairs' own rates
    bound it near 11); ETDRK4 (each amplitude's own rate exact) takes 16 and its settled amplitudes stay within
    0.005 u_R of the same integrator at step 1; at step 8 it agrees with the insulators-only step to 1e-3."""
    from mech2spice.physics.params import load_params
    sc = S.chain_scene(load_params("centered_fc2"))
    m, u = sc.model, sc.model.amplitude_unit
    with pytest.raises(Mech2SpiceError, match="stability limit"):
        integrate(m, 100, step_periods=16, stimulus=sc.stimulus, exponential=True, etd=False)
    assert not envelope.needs_etd(m, 8, True) and envelope.needs_etd(m, 16, True)
    monkeypatch.setattr(envelope, "needs_etd", lambda model, step, exponential, etd=True: exponential and etd)
    end = lambda st, etd=True: np.abs(integrate(m, sc.periods, step_periods=st, stimulus=sc.stimulus,
                                                exponential=True, etd=etd).amp[-1])
    fine = end(1)
    assert np.abs(end(16) - fine).max() / u < 5e-3
    assert np.abs(end(8) - end(8, etd=False)).max() / u < 1e-3


def test_a_frozen_gate_records_its_loads_oscillators_and_wakes_by_its_drivers_channels(adder):
    """The latency record of a gate block (docs/latency.md, "Per-gate latency") holds every other block's fast DOF
    its rates read: its drivers' channels and its loads' gate oscillators (their back-action; a record of the
    channels alone left a processor latch wrong after power-up, issue 36); the wake-up graph's edges are the
    channels it reads, the calm rule's input test marks exactly those."""
    from mech2spice.physics.envelope import Envelope
    model = adder.model
    env, b = Envelope.of(model), envelope.kernel(model).blocks
    pos = {int(d): q for q, d in enumerate(env.fast)}
    gates = model.design.gates
    owner = {pos[d]: k for k, g in enumerate(gates) for d in (g.channel, *[x for pair in g.inputs for x in pair])}
    channels = {pos[g.channel] for g in gates}
    watched = set(int(f) for f in env.watch)
    xp, xi = b.ext_f
    dp, di = b.dep
    with_loads = 0
    for k in range(len(gates)):
        rec = [int(f) for f in xi[xp[k]:xp[k + 1]]]
        assert rec and all(owner.get(f, b.always) != k for f in rec)
        assert list(b.ext_channel[xp[k]:xp[k + 1]]) == [int(f in watched) for f in rec]
        loads = [f for f in rec if f not in watched]
        assert all(f in owner and f not in channels for f in loads)       # other gates' gate oscillators
        with_loads += bool(loads)
        wakers = {a for a in range(b.n) if k in di[dp[a]:dp[a + 1]]}
        assert wakers == {owner.get(f, b.always) for f in rec if f in watched}
    assert with_loads > len(gates) // 2
