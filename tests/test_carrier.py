"""The carrier engine (issue 15, backends/carrier.py): Lawson RK4 with the linear oscillators propagated exactly.

Checked against the textbook RK4 at 160 steps per period with the issue's tolerances (1e-3 u_R, 0.5 deg),
for its order, for exactness on linear oscillators, and for what its layout must not change (threads,
chunking, batch members); idle skipping within its tolerance; bad settings as one-line errors; the
processor's per-cycle trace continuing across a resume."""
import json

import numpy as np
import pytest

from mech2spice.backends import carrier, make_engine, rk4
from mech2spice.backends.carrier import CarrierOptions
from mech2spice.compare import agreement
from mech2spice.cpu.run import run_program
from mech2spice.errors import Mech2SpiceError
from mech2spice.experiments import scenes as S
from mech2spice.physics.model import MechModel
from mech2spice.physics.params import band_of
from mech2spice.physics.stimulus import Stimulus
from pathlib import Path

AMP_TOL = 1e-3       # u_R, the bound against RK4 at 160 steps (measured: gate 2.1e-4, chain 2.2e-4, adder 3.8e-4)
PHASE_TOL = 0.5      # degrees (measured: 0.05 on each)
PROGRAMS = Path(__file__).resolve().parents[1] / "programs"


def differences(scene, steps: int = carrier.DEFAULT_STEPS_PER_PERIOD):
    """(largest |A| difference in u_R, largest phase difference in degrees) of carrier against RK4 at 160
    steps over every period of the scene (phases where the amplitude exceeds 0.1 u_R)."""
    ref = rk4.integrate(scene.model, scene.periods, steps_per_period=160, stimulus=scene.stimulus,
                        probes=scene.probes)
    out = carrier.integrate(scene.model, scene.periods, steps_per_period=steps, stimulus=scene.stimulus,
                            probes=scene.probes)
    d = agreement(ref.amp, out.amp, scene.model.amplitude_unit, floor=0.1)
    return d.amp, d.phase_deg


def test_gate_matches_rk4_at_160_steps():
    amp, phase = differences(S.gate_scene(periods=800))
    assert amp < AMP_TOL and phase < PHASE_TOL


def test_chain_matches_rk4_at_160_steps():
    amp, phase = differences(S.chain_scene(hold=500))
    assert amp < AMP_TOL and phase < PHASE_TOL


@pytest.mark.slow
def test_adder_matches_rk4_at_160_steps():
    """All 16 sums of the 2-bit adder (RK4 at 160 steps takes ~35 s)."""
    amp, phase = differences(S.adder_scene())
    assert amp < AMP_TOL and phase < PHASE_TOL


def test_fourth_order_on_a_switching_gate():
    """Final-state error against 64 steps: halving the step from T/8 divides it by ~14 (order ~3.8)."""
    sc = S.gate_scene(periods=300)
    run = lambda n: carrier.integrate(sc.model, 300, steps_per_period=n, stimulus=sc.stimulus).x
    ref = run(64)
    e8, e16 = np.abs(run(8) - ref).max(), np.abs(run(16) - ref).max()
    assert e8 / e16 > 10


def test_exact_on_uncoupled_linear_oscillators():
    """No couplings and no drive: the propagators alone, exact at 4 steps per period after 50 periods."""
    m = MechModel(omega=2.0)
    m.add_dof("a", 1.0, 4.2, 0.05)
    m.add_dof("b", 2.0, 3.0, 0.3)
    m.add_dof("ins", 1.0, 0.01, 0.5, slow=True)
    x0, v0 = np.array([[1.0], [0.5], [-0.2]]), np.array([[0.0], [1.0], [0.3]])
    run = carrier.integrate(m, 50, steps_per_period=4, state=(x0, v0), probes=["a"])
    t = 50 * m.period
    for i, (mass, k, c) in enumerate(zip(m.mass, m.k_total, m.c_total)):
        lam = np.roots([mass, c, k])                       # x = A e^{l1 t} + B e^{l2 t}
        A, B = np.linalg.solve([[1, 1], lam], [x0[i, 0], v0[i, 0]])
        exact = (A * np.exp(lam[0] * t) + B * np.exp(lam[1] * t)).real
        assert abs(run.x[i, 0] - exact) < 1e-12 * max(1.0, abs(x0[i, 0]))


def test_threads_chunks_and_members_do_not_change_the_result():
    """Two threads, a run split in two, and one member alone give bit-identical states."""
    sc = S.gate_scene(periods=200)
    whole = carrier.integrate(sc.model, 200, stimulus=sc.stimulus)
    two = carrier.integrate(sc.model, 200, stimulus=sc.stimulus, threads=2)
    first = carrier.integrate(sc.model, 120, stimulus=sc.stimulus)
    rest = carrier.integrate(sc.model, 80, stimulus=sc.stimulus, state=first.state, start_period=120)
    alone = carrier.integrate(sc.model, 200, stimulus=Stimulus(sc.stimulus.times, sc.stimulus.amps[:, :, 2:3]))
    assert np.array_equal(whole.x, two.x) and np.array_equal(whole.x, rest.x)
    assert np.array_equal(whole.x[:, 2:3], alone.x)
    assert np.array_equal(whole.amp[120:], rest.amp)


def test_truth_table_decoded_from_amplitudes():
    sc = S.gate_scene(periods=1500)
    run = make_engine("carrier").run(sc.model, sc.periods, sc.stimulus, probes=sc.probes)
    bands = [band_of(a) for a in run.final_amplitudes(["g0"], sc.model.amplitude_unit, 10)[0]]
    assert bands == [int(not (a or b)) for a, b in S.PAIRS]


def test_settle_skips_idle_time_within_its_tolerance():
    """The chain's three input settings with settle 0.1 u_R: periods are skipped, and the held amplitudes
    at the end of each setting stay within that tolerance of the full run's."""
    sc = S.chain_scene(hold=1500, edges=False)
    full = carrier.integrate(sc.model, sc.periods, stimulus=sc.stimulus, probes=sc.probes)
    fast = carrier.integrate(sc.model, sc.periods, stimulus=sc.stimulus, probes=sc.probes, settle_tol=0.1)
    assert fast.settled_periods > 1000
    u = sc.model.amplitude_unit
    for w in sc.windows:
        assert np.abs(np.abs(fast.amp[w - 1]) - np.abs(full.amp[w - 1])).max() / u < 0.1


@pytest.mark.parametrize("options, message", [
    (dict(steps_per_period=3), "at least 4 steps"),
    (dict(steps_per_period=12.5), "whole number"),
    (dict(threads=0), "carrier threads 0"),
    (dict(settle_tol=-1.0), "settle tolerance"),
    (dict(latency=1.5), "latency threshold"),
    (dict(latency=0.05, threads=2), "choose latency or threads"),
])
def test_bad_options_are_one_line_errors(options, message):
    with pytest.raises(Mech2SpiceError, match=message):
        make_engine("carrier", CarrierOptions(**options))


def test_latency_freezes_settled_gates_within_its_threshold():
    """Per-gate latency (0.05 u_R) on the chain's three settings, band-edge members included: at each
    setting's end every gate within the threshold of the full run (measured: 0.031 u_R at most, on a
    band-edge member), with under half the block-steps integrated (measured: 30 %)."""
    sc = S.chain_scene(hold=1500)
    full = carrier.integrate(sc.model, sc.periods, stimulus=sc.stimulus, probes=sc.probes)
    lat = carrier.integrate(sc.model, sc.periods, stimulus=sc.stimulus, probes=sc.probes, latency=0.05)
    u, blocks, B = sc.model.amplitude_unit, len(sc.model.design.gates), sc.stimulus.batch
    for w in sc.windows:
        assert np.abs(np.abs(lat.amp[w - 1]) - np.abs(full.amp[w - 1])).max() / u < 0.05
    assert 0 < lat.extra["block_steps"] < 0.5 * blocks * B * sc.periods * carrier.DEFAULT_STEPS_PER_PERIOD


def test_latency_record_continues_across_runs_and_members():
    """The latency record rides in the state: a run split in two equals the whole, bit for bit, and a
    member run alone equals the same member in a batch (activity is per member)."""
    sc = S.chain_scene(hold=300)
    kw = dict(latency=0.05, probes=sc.probes)
    whole = carrier.integrate(sc.model, 900, stimulus=sc.stimulus, **kw)
    first = carrier.integrate(sc.model, 450, stimulus=sc.stimulus, **kw)
    rest = carrier.integrate(sc.model, 450, stimulus=sc.stimulus, state=first.state, start_period=450, **kw)
    alone = carrier.integrate(sc.model, 900, stimulus=Stimulus(sc.stimulus.times, sc.stimulus.amps[:, :, 1:2]), **kw)
    assert np.array_equal(whole.x, rest.x) and np.array_equal(whole.amp[450:], rest.amp)
    assert np.array_equal(whole.x[:, 1:2], alone.x) and np.array_equal(whole.amp[:, :, 1:2], alone.amp)
    assert len(whole.state) > 2 and first.extra["block_steps"] + rest.extra["block_steps"] == whole.extra["block_steps"]


def test_truth_table_with_latency():
    sc = S.gate_scene(periods=1500)
    run = make_engine("carrier", CarrierOptions(latency=0.05)).run(sc.model, sc.periods, sc.stimulus, probes=sc.probes)
    bands = [band_of(a) for a in run.final_amplitudes(["g0"], sc.model.amplitude_unit, 10)[0]]
    assert bands == [int(not (a or b)) for a, b in S.PAIRS]


def test_a_stimulus_change_inside_a_period_is_refused():
    sc = S.gate_scene(periods=10)
    st = Stimulus([0.0, 2.5 * sc.model.period], np.repeat(sc.stimulus.amps, 2, axis=0))
    with pytest.raises(Mech2SpiceError, match="whole drive periods"):
        carrier.integrate(sc.model, 10, stimulus=st)


def test_trace_continues_across_a_resume(tmp_path):
    """cpu run --trace: a resumed run drops the lines past its checkpoint, so each cycle appears once, in order."""
    ck, trace = tmp_path / "ck.json", tmp_path / "trace.jsonl"
    run_program(PROGRAMS / "sieve.asm", "iss", 25, checkpoint=ck, checkpoint_every=10, trace=trace)
    assert len(trace.read_text().splitlines()) == 25          # the checkpoint is at cycle 25 (written at the end)
    trace.write_text(trace.read_text() + json.dumps({"cycle": 25, "pc": 0}) + "\n")   # a line a kill left behind
    run_program(PROGRAMS / "sieve.asm", "iss", 40, checkpoint=ck, resume=True, trace=trace)
    rows = [json.loads(line) for line in trace.read_text().splitlines()]
    assert [r["cycle"] for r in rows] == list(range(40))
    assert rows[-1]["registers"] == run_program(PROGRAMS / "sieve.asm", "iss", 40)["registers"]


def test_rk4_skips_idle_time_by_the_same_rule():
    """RK4 with settle 0.1 u_R (the processor's pauses): the same periods skipped as the carrier, the
    compiled loop and the numpy path alike, amplitudes within 1e-3 u_R of the carrier's."""
    sc = S.chain_scene(hold=1500, edges=False)
    kw = dict(stimulus=sc.stimulus, probes=sc.probes, settle_tol=0.1)
    c = carrier.integrate(sc.model, sc.periods, **kw)
    r = rk4.integrate(sc.model, sc.periods, steps_per_period=80, **kw)
    r_np = rk4.integrate(sc.model, 1500, steps_per_period=80, compiled=False, **kw)
    assert c.settled_periods == r.settled_periods > 1000 and r_np.settled_periods == 700
    assert np.abs(np.abs(c.amp) - np.abs(r.amp)).max() / sc.model.amplitude_unit < AMP_TOL
    with pytest.raises(Mech2SpiceError, match="thermal noise"):
        make_engine("rk4", rk4.RK4Options(settle_tol=0.1, noise_temperature=1e-4))


def test_run_cost_adds_up_over_resumed_parts(tmp_path):
    """A resumed run reports the wall and CPU seconds of all its parts: its own plus the checkpoint's."""
    ck = tmp_path / "ck.json"
    first = run_program(PROGRAMS / "sieve.asm", "iss", 30, checkpoint=ck)
    prior = json.loads(ck.read_text())
    assert 0 < prior["wall_s_total"] <= first["wall_s"] and prior["cpu_s_total"] > 0
    done = run_program(PROGRAMS / "sieve.asm", "iss", 100_000, checkpoint=ck, resume=True)
    assert done["halted"] and done["wall_s_total"] - done["wall_s"] == pytest.approx(prior["wall_s_total"], abs=0.01)
    assert done["cpu_s_total"] > prior["cpu_s_total"]


@pytest.mark.slow
def test_processor_with_latency_resumes_exactly_and_matches_the_iss(tmp_path):
    """`cpu run --backend carrier` (per-gate latency by default): four sieve cycles equal the ISS, and a run
    checkpointed after two and resumed ends bit for bit where the unbroken run does (the latency record is
    part of the saved state; ~2 min here)."""
    sieve, ck = PROGRAMS / "sieve.asm", tmp_path / "ck.json"
    whole = run_program(sieve, "carrier", 4, trace=tmp_path / "whole.jsonl")
    run_program(sieve, "carrier", 2, checkpoint=ck, checkpoint_every=2)
    resumed = run_program(sieve, "carrier", 4, checkpoint=ck, resume=True, trace=tmp_path / "part.jsonl")
    assert whole["latency"] == 0.05 and whole["block_steps"] > 0
    assert resumed["registers"] == whole["registers"] == run_program(sieve, "iss", 4)["registers"]
    a = [json.loads(line) for line in open(tmp_path / "whole.jsonl")][2:]
    b = [json.loads(line) for line in open(tmp_path / "part.jsonl")]
    assert [r["amps"] for r in a] == [r["amps"] for r in b] and a[-1]["block_steps"] == b[-1]["block_steps"]
