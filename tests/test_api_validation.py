"""The Python API checks its arguments like the command line: the same caps, and only Mech2SpiceError (one
line) for a wrong type or value, before any work (issue #26)."""
import dataclasses
import math
import time
from pathlib import Path

import numpy as np
import pytest

import mech2spice as m2s
from mech2spice import simulation
from mech2spice.physics.params import PRESETS
from mech2spice.backends.envelope import EnvelopeOptions
from mech2spice.backends.rk4 import RK4Options
from mech2spice.errors import Mech2SpiceError
from mech2spice.inputs import MAX_CYCLES, MAX_PERIODS

REPO = Path(__file__).resolve().parent.parent
ADDER, DFF = str(REPO / "verilog" / "adder2.v"), str(REPO / "verilog" / "dff.v")


@pytest.fixture(autouse=True)
def no_runs(monkeypatch):
    """Every call here must be refused before it integrates anything (without the caps some would run for
    days): reaching an engine fails the test instead of hanging it."""
    def ran(*args, **kwargs):
        raise AssertionError("the call reached the simulation")
    for name in ("run_physical", "run_clocked_physical", "run_clocked_logic"):
        monkeypatch.setattr(simulation, name, ran)


def refused(call, needle: str) -> str:
    """`call` raises Mech2SpiceError (not TypeError, KeyError, ValueError ...) whose one line holds `needle`."""
    with pytest.raises(Exception) as info:
        call()
    assert type(info.value) is Mech2SpiceError, f"{type(info.value).__name__}: {info.value}"
    msg = str(info.value)
    assert needle in msg and "\n" not in msg
    return msg


SIMULATE = [
    # design
    ({"design": 123}, "design must be a file path"),
    ({"design": None}, "design must be a file path"),
    ({"design": ["adder2.v"]}, "design must be a file path"),
    ({"design": ""}, "the design path is empty"),
    ({"design": "no/such/file.v"}, "cannot read Verilog file"),
    # inputs
    ({"inputs": [("a", 1)]}, "inputs must map port names to integers, not a list"),
    ({"inputs": "a=1"}, "inputs must map port names to integers, not a string"),
    ({"inputs": {"a": "3"}}, "'a' -> a string"),
    ({"inputs": {"a": 1.0}}, "'a' -> a number"),
    ({"inputs": {"a": True}}, "'a' -> true/false"),
    ({"inputs": {"a": None}}, "'a' -> None"),
    ({"inputs": {1: 1}}, "the name 1 is not a string"),
    ({"inputs": {"zz": 1}, "backend": "logic"}, "unknown input port 'zz'"),
    ({"inputs": {"a": 4}, "backend": "logic"}, "does not fit input 'a'"),
    ({"inputs": {"a": -1}, "backend": "logic"}, "does not fit input 'a'"),
    # backend
    ({"backend": "spice"}, "unknown backend 'spice' (choose from logic, rk4"),
    ({"backend": 3}, "unknown backend 3"),
    ({"backend": None}, "unknown backend None"),
    ({"backend": ["rk4"]}, "unknown backend ['rk4']"),
    # options
    ({"options": {"steps_per_period": 80}}, "must be RK4Options (BACKENDS['rk4'].Options), not dict"),
    ({"options": EnvelopeOptions()}, "must be RK4Options"),
    ({"options": "fast", "backend": "logic"}, "must be NoOptions"),
    ({"options": RK4Options(), "backend": "envelope"}, "must be EnvelopeOptions"),
    # periods: the CLI's cap
    ({"periods": 10 ** 12}, f"periods must be from 1 to {MAX_PERIODS:,}"),
    ({"periods": 0}, "periods must be from 1"),
    ({"periods": -5}, "periods must be from 1"),
    ({"periods": 100.0}, "periods must be a whole number"),
    ({"periods": "100"}, "periods must be a whole number"),
    ({"periods": math.nan}, "periods must be a whole number"),
    ({"periods": True}, "periods must be a whole number"),
    # cycles and stimulus (checked before the design is known to be combinational)
    ({"cycles": 10 ** 12}, f"cycles must be from 1 to {MAX_CYCLES:,}"),
    ({"cycles": 20_000}, "the rk4 backend is limited to 10,000"),
    ({"cycles": 0}, "cycles must be from 1"),
    ({"cycles": 2.5}, "cycles must be a whole number"),
    ({"cycles": 3, "stimulus": [{"cycles": 1}]}, "give cycles or stimulus, not both"),
    ({"stimulus": {"set": {}, "cycles": 1}}, "stimulus (a list of steps or a JSON file) must be a file path"),
    ({"stimulus": 7}, "must be a file path"),
    ({"stimulus": [3]}, "stimulus, step 0: expected an object"),
    ({"stimulus": [{"set": {"d": "1"}}]}, "'set' must map port names to integers"),
    ({"stimulus": [{"set": {"d": 1}, "cycles": -1}]}, "'cycles' must be a whole number"),
    ({"stimulus": [{"cycles": 10 ** 9}]}, "stimulus asks for 1,000,000,000 clock cycles"),
    ({"stimulus": [{"hold": 3}]}, "unknown field(s) 'hold'"),
    ({"stimulus": "no/such/stimulus.json"}, "cannot read stimulus file"),
    # params
    ({"params": 3}, f"params must be a preset ({', '.join(PRESETS)}) or a JSON file path"),
    ({"params": {"q_g": 150}}, "params must be a preset"),
    ({"params": "no-such-preset"}, "cannot read parameter file no-such-preset"),
    ({"params": m2s.GateParams(q_g="150")}, "gate parameter q_g = '150' is not a finite number"),
    ({"params": m2s.GateParams(m_c=-6.0)}, "gate parameter m_c = -6.0 must be positive"),
    # wrong types that reached the engines as AttributeError / OverflowError, or ran (hostile-input pass, session 21)
    ({"params": m2s.GateParams(levels=[1, 2])}, "gate parameter levels = [1, 2] is not a Levels"),
    ({"params": m2s.GateParams(levels=None)}, "gate parameter levels = None is not a Levels"),
    ({"params": m2s.GateParams(block=5)}, "gate parameter block = 5 is not a BlockSpec"),
    ({"params": m2s.GateParams(m_g=10 ** 400)}, "gate parameter m_g = 1000"),
    ({"params": m2s.GateParams(m_g=True)}, "gate parameter m_g = True is not a finite number"),
    ({"params": m2s.GateParams(name=5)}, "gate parameter name = 5 is not one line of text"),
    ({"params": m2s.GateParams(name="a\nb")}, "is not one line of text"),
    # progress
    ({"progress": "yes"}, "progress must be True, False or a callable"),
]


@pytest.mark.parametrize("kwargs, needle", SIMULATE, ids=[n[:40] for _, n in SIMULATE])
def test_simulate_refuses_wrong_types_and_values(kwargs, needle):
    kwargs = dict(kwargs)
    design = kwargs.pop("design", ADDER)
    inputs = kwargs.pop("inputs", {"a": 1})
    refused(lambda: m2s.simulate(design, inputs, **kwargs), needle)


def test_periods_beyond_the_cap_are_refused_at_once():
    """Without the cap, periods=10**12 ran without end; now it fails before synthesis."""
    t0 = time.perf_counter()
    refused(lambda: m2s.simulate(ADDER, {"a": 3, "b": 2}, periods=10 ** 12), "periods must be from 1 to")
    refused(lambda: m2s.emit(ADDER, {"a": 3}, periods=10 ** 12), "periods must be from 1 to")
    assert time.perf_counter() - t0 < 1.0


def test_numpy_integers_are_integers():
    """Values computed with numpy are accepted where Python integers are (the refusal here is the design's)."""
    refused(lambda: m2s.simulate("no/such.v", {"a": np.int64(1)}, periods=np.int32(5)), "cannot read Verilog")


def test_clocked_designs_need_cycles_and_combinational_ones_refuse_them():
    refused(lambda: m2s.simulate(DFF, {}), "give cycles=N or a stimulus")
    refused(lambda: m2s.simulate(ADDER, {"a": 1}, cycles=3), "has no flip-flops")


EMIT = [
    ({"design": 3.5}, "design must be a file path"),
    ({"inputs": ["a"]}, "inputs must map port names to integers"),
    ({"periods": "800"}, "periods must be a whole number"),
    ({"periods": 10 ** 12}, "periods must be from 1"),
    ({"options": RK4Options()}, "options for the ngspice backend must be SpiceOptions"),
    ({"options": 3}, "must be SpiceOptions"),
    ({"params": 2.0}, "params must be a preset"),
    ({"path": 42}, "path must be a file path"),
    ({"path": "no/such/dir/out.cir"}, "directory no/such/dir does not exist"),
]


@pytest.mark.parametrize("kwargs, needle", EMIT, ids=[n[:40] for _, n in EMIT])
def test_emit_refuses_wrong_types_and_values(kwargs, needle):
    kwargs = dict(kwargs)
    design = kwargs.pop("design", ADDER)
    inputs = kwargs.pop("inputs", {"a": 1})
    refused(lambda: m2s.emit(design, inputs, **kwargs), needle)


def test_emit_never_overwrites_its_design(tmp_path):
    design = tmp_path / "adder2.v"
    design.write_text(Path(ADDER).read_text())
    refused(lambda: m2s.emit(design, {"a": 1}, path=str(design)), "is the design")
    # nor given as the Netlist synthesized from it, even with force=True (it replaced the source: a Netlist did
    # not know its file; second hostile-input pass, session 21)
    refused(lambda: m2s.emit(m2s.synthesize(design), {"a": 1}, path=str(design), force=True), "is the design")
    assert design.read_text() == Path(ADDER).read_text()


def test_emit_refuses_a_clocked_design(tmp_path):
    """One input vector and no clock edges would only read the flip-flops' power-up values (it wrote such a
    netlist with exit 0: hostile-input pass, session 21)."""
    out = tmp_path / "dff.cir"
    refused(lambda: m2s.emit(DFF, {"d": 1}, path=str(out)), "is clocked by 'clk'")
    assert not out.exists()


@pytest.mark.parametrize("args, kwargs, needle", [
    ((7,), {}, "design must be a file path"),
    ((None,), {}, "design must be a file path"),
    ((ADDER,), {"top": 3}, "top must be a module name"),
    ((ADDER,), {"max_fanout": "12"}, "max_fanout must be a whole number from 2 to 1,000,000"),
    ((ADDER,), {"max_fanout": 1}, "max_fanout must be from 2"),
    ((ADDER,), {"max_fanout": 12.0}, "max_fanout must be a whole number"),
])
def test_synthesize_refuses_wrong_types(args, kwargs, needle):
    refused(lambda: m2s.synthesize(*args, **kwargs), needle)


@pytest.mark.parametrize("spec", [3, 1.5, b"default", ["default"], {"q_g": 1}, True])
def test_load_params_refuses_wrong_types(spec):
    refused(lambda: m2s.load_params(spec), "params must be a preset")


def test_load_params_takes_a_path_object(tmp_path):
    f = tmp_path / "q.json"
    f.write_text('{"q_g": 150}')
    assert m2s.load_params(f).q_g == 150


# --- every engine's Options: checked at construction ------------------------------------------------
def _bad_values(field) -> list:
    """Values the field's annotation refuses: the wrong type always; NaN, inf and -1 for numbers."""
    kinds = {k.strip() for k in str(field.type).split("|")}
    bad = [object(), [1]] + (["1"] if "str" not in kinds else [3])
    if kinds & {"int", "float"}:
        bad += [math.nan, math.inf, -1, True]
    if "bool" in kinds:
        bad += [1, "yes"]
    return bad


def _case_id(value):
    """A test id that is the same in every process (pytest-xdist compares them): no object addresses."""
    return "object()" if type(value) is object else repr(value)


OPTION_CASES = [(name, f.name, v) for name, engine in m2s.BACKENDS.items()
                for f in dataclasses.fields(engine.Options) for v in _bad_values(f)]


@pytest.mark.parametrize("backend, field, value", OPTION_CASES,
                         ids=[f"{b}.{f}={_case_id(v)}"[:50] for b, f, v in OPTION_CASES])
def test_engine_options_refuse_bad_values_at_construction(backend, field, value):
    """Every registered engine's Options: a wrong type, NaN, inf or a negative number fails where it is set
    (not later, inside a run) with one line naming the field's class."""
    refused(lambda: m2s.BACKENDS[backend].Options(**{field: value}), "")


def test_every_engine_has_checked_options():
    """The table above covers every registered engine that has settings (logic has none to get wrong)."""
    with_fields = {b for b, _, _ in OPTION_CASES}
    assert with_fields == {b for b, e in m2s.BACKENDS.items() if dataclasses.fields(e.Options)}
    assert {"rk4", "carrier", "envelope", "ngspice", "vacask"} <= with_fields
    assert dataclasses.fields(m2s.BACKENDS["logic"].Options) == ()


@pytest.mark.parametrize("make, needle", [
    (lambda: RK4Options(steps_per_period=2), "at least 4 steps"),
    (lambda: RK4Options(steps_per_period=80.0), "RK4Options.steps_per_period = 80.0: must be a whole number"),
    (lambda: EnvelopeOptions(step_periods=0.0), "must be a positive number"),
    (lambda: EnvelopeOptions(compiled="no"), "EnvelopeOptions.compiled = 'no': must be True or False"),
    (lambda: m2s.BACKENDS["ngspice"].Options(method="euler"), "method 'euler' unknown"),
    (lambda: m2s.BACKENDS["ngspice"].Options(noise_seed=-1), "noise_seed -1: must be an integer >= 0"),
    (lambda: m2s.BACKENDS["vacask"].Options(relref="global-ish"), "relref 'global-ish' unknown"),
    (lambda: m2s.BACKENDS["carrier"].Options(threads=2, latency=0.01), "choose latency or threads"),
    (lambda: dataclasses.replace(RK4Options(), settle_tol=-0.1), "settle tolerance -0.1"),
])
def test_options_fail_where_they_are_set(make, needle):
    refused(make, needle)
