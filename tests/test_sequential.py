"""Latches and clocked designs: the latch's pulse sequence on RK4, clocked traces identical across
backends, and refusal of clocking the mechanical latch cannot honour."""
import json
from pathlib import Path

import pytest

from conftest import run_main

from mech2spice import simulation
from mech2spice.experiments import characterise, clocking
from mech2spice.synthesis import synth

REPO = Path(__file__).resolve().parent.parent

COUNTER_STEPS = [{"set": {"rst": 1}, "cycles": 1}, {"set": {"rst": 0, "en": 1}, "cycles": 2},
                 {"set": {"en": 0}, "cycles": 1}, {"set": {"en": 1}, "cycles": 1}]


def cli(*args):
    return run_main(*args)        # in this process (conftest.run_main): the command's own handler, no new interpreter


def test_latch_pulse_sequence_rk4(p):
    res = characterise.latch_sequence(p, "rk4")
    seen = [(ph["phase"], ph["logic"]) for ph in res["decoded"]]
    assert all(ph["logic"] is not None for ph in res["decoded"][1:]), seen
    # after storing 1 the output is 1 through every hold, whatever d does; then 0 after storing 0
    after_store1 = [ph["logic"] for ph in res["decoded"][2:6]]
    after_store0 = [ph["logic"] for ph in res["decoded"][7:]]
    assert after_store1 == [1, 1, 1, 1] and after_store0 == [0, 0, 0], seen
    assert res["decoded"][0]["logic"] == 0                    # powers up at 0 with d = 0
    # the output only moves once the enable pulse is over
    assert all(d > res["pulse"] for d in res["output_delays"] if d == d), res["output_delays"]


def test_counter_traces_identical_logic_and_rk4(tmp_path):
    stim = tmp_path / "stim.json"
    stim.write_text(json.dumps(COUNTER_STEPS))
    runs = {}
    for backend in ("logic", "rk4"):
        rc, out, err = cli("simulate", str(REPO / "verilog" / "counter4.v"), "--stimulus", str(stim), "--backend", backend, "--json")
        assert rc == 0, err
        runs[backend] = json.loads(out)
    logic_q = [e["outputs"]["q"] for e in runs["logic"]["trace"]]
    assert logic_q == [0, 1, 2, 2, 3]
    assert [e["outputs"]["q"] for e in runs["rk4"]["trace"]] == logic_q
    assert all(e["valid"] for e in runs["rk4"]["trace"])
    assert [e["cycle"] for e in runs["rk4"]["trace"]] == list(range(5))


def test_counter_envelope_matches_logic(p):
    nl = synth.synthesize(str(REPO / "verilog" / "counter4.v"))
    cycles = simulation.expand_steps(COUNTER_STEPS + [{"set": {"en": 1}, "cycles": 3}])
    env = simulation.run_clocked_physical(nl, p, cycles, "envelope", clocking.clock_timing(nl))
    log = simulation.run_clocked_logic(nl, cycles)
    assert [e["outputs"] for e in env["trace"]] == [e["outputs"] for e in log["trace"]]
    assert env["valid"]


def test_sqrt_logic_reaches_53(tmp_path):
    stim = tmp_path / "sqrt.json"
    stim.write_text('[{"set": {"rst": 1, "n": 2809}, "cycles": 1}, {"set": {"rst": 0}, "cycles": 6}]')
    rc, out, err = cli("simulate", str(REPO / "verilog" / "sqrt.v"), "--stimulus", str(stim), "--backend", "logic", "--json")
    assert rc == 0, err
    roots = [e["outputs"]["root"] for e in json.loads(out)["trace"]]
    assert roots == [0, 32, 48, 48, 52, 52, 53]     # one result bit decided per cycle, from the top
    # the form: inputs held, clock pulsed; the all-zero power-up state is the start state
    rc, out, err = cli("simulate", str(REPO / "verilog" / "sqrt.v"), "--set", "n=2809", "--clock", "clk", "--cycles", "8",
                       "--backend", "logic", "--json")
    assert rc == 0, err
    assert [e["outputs"]["root"] for e in json.loads(out)["trace"]] == [32, 48, 48, 52, 52, 53, 53, 53]


def test_fsm_detects_sequence():
    nl = synth.synthesize(str(REPO / "verilog" / "fsm.v"))
    xs = [1, 1, 0, 1, 1, 0, 1, 0, 1, 1, 0, 1]
    steps = [{"set": {"rst": 1}, "cycles": 1}] + [{"set": {"rst": 0, "x": x}, "cycles": 1} for x in xs]
    trace = simulation.run_clocked_logic(nl, simulation.expand_steps(steps))["trace"]
    assert [e["outputs"]["found"] for e in trace] == [0, 0, 0, 0, 1, 0, 0, 1, 0, 0, 0, 0, 1]
    assert trace[8]["outputs"]["state"] == 1                  # "1" then 0 returns to idle
    assert all(bin(e["outputs"]["state"]).count("1") == 1 for e in trace)   # always one-hot


@pytest.mark.parametrize("args,needle", [
    (["simulate", str(REPO / "verilog" / "inferred_latch.v"), "--backend", "logic"], "level-sensitive latch"),
    (["simulate", str(REPO / "verilog" / "counter4.v"), "--backend", "logic"], "--cycles"),
    (["simulate", str(REPO / "verilog" / "adder2.v"), "--cycles", "2", "--backend", "logic"], "no flip-flops"),
    (["simulate", str(REPO / "verilog" / "counter4.v"), "--cycles", "2", "--pulse", "5000"], "outlasts"),
    (["simulate", str(REPO / "verilog" / "counter4.v"), "--cycles", "2", "--pulse", "100"], "shorter"),
])
def test_clocking_errors(args, needle):
    rc, _, err = cli(*args)
    assert rc == 2 and needle in err and err.count("\n") == 1, err


def test_the_clock_schedule_stretches_with_a_slower_block():
    """The schedule's latch and gate delays were measured on the default block: a block whose gates switch
    more slowly (the robust preset: 340 against 224 periods, the 3-gate chain's largest delay on RK4) gets
    a proportionally longer pulse and pause; the default's schedule is unchanged."""
    from mech2spice import data
    from mech2spice.physics.params import DEFAULT, load_params
    from mech2spice.synthesis.synth import synthesize
    nl = synthesize(data.verilog("sqrt.v"))
    base, same = clocking.clock_timing(nl), clocking.clock_timing(nl, p=DEFAULT)
    assert base == same and base["pulse"] == int(1.6 * clocking.LATCH_MIN_PULSE)
    assert base["pause"] == (clocking.LATCH_OUTPUT_DELAY - base["pulse"] + clocking.SETTLE_MARGIN
                             + clocking.GATE_DELAY_MAX * (base["logic_depth"] + 1))
    slow = clocking.clock_timing(nl, p=load_params("robust"))
    s = slow["block_slowdown"]
    assert 1.4 < s < 1.7
    assert slow["pulse"] >= s * clocking.LATCH_MIN_PULSE and slow["pulse"] < s * clocking.LATCH_OUTPUT_DELAY_MIN
    assert slow["pause"] + slow["pulse"] >= s * (base["pause"] + base["pulse"]) - 1


def test_adder_scene_holds_for_its_period_budget():
    """scenes.ADDER_HOLD is a constant (scenes import no clocking); it must stay adder2.v's period budget."""
    from mech2spice import data
    from mech2spice.experiments.scenes import ADDER_HOLD
    assert ADDER_HOLD == clocking.period_budget(synth.synthesize(data.verilog("adder2.v")))
