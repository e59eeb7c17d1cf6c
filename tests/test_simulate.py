"""Verilog -> mechanical network -> RK4, decoded and compared with the logic-level oracle; the CLI contract."""
import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from conftest import run_main

from mech2spice import simulation
from mech2spice.errors import Mech2SpiceError
from mech2spice.backends import logic
from mech2spice.physics import network
from mech2spice.synthesis import synth
from mech2spice.experiments import clocking
from mech2spice.experiments.scenes import ADDER_INPUTS

REPO = Path(__file__).resolve().parent.parent


def cli(*args):
    return run_main(*args)        # in this process (conftest.run_main): the command's own handler, no new interpreter


@pytest.fixture(scope="module")
def adder():
    return synth.synthesize(str(REPO / "verilog" / "adder2.v"))


def test_adder_counts_match_paper_convention(adder, p):
    m = network.build(adder, p)
    n = len(adder.gates())
    assert n <= 17
    c = m.counts()
    assert c["oscillators"] == 6 * n and c["nonlinear_springs"] == 5 * n
    g = adder.graph
    links = sum(1 for u, v in g.edges if g.nodes[u]["kind"] == "nor" and g.nodes[v]["kind"] == "nor")
    assert c["linear_springs"] == c["dashpots"] == links


def test_adder_all_16_sums_rk4_and_envelope(adder, p):
    vals = list(ADDER_INPUTS)
    res = simulation.run_physical(adder, p, vals, "rk4")
    env = simulation.run_physical(adder, p, vals, "envelope")
    for r, e in zip(res, env):
        assert e["outputs"] == r["outputs"] and e["valid"]
        for bit, a in r["amplitudes"].items():
            assert abs(e["amplitudes"][bit] - a) < 0.02, (bit, a, e["amplitudes"][bit])
    for v, r in zip(vals, res):
        assert r["valid"], (v, r["amplitudes"])
        assert r["outputs"]["s"] == v["a"] + v["b"]
        assert r["min_margin"] > 0.05
        want = logic.evaluate_bits(adder, v)
        assert all(r["bits"][b] == want[b] for b in r["bits"])


@pytest.mark.parametrize("design,vectors", [
    (str(REPO / "verilog" / "mux4.v"), [{"d": d, "sel": s} for d, s in [(0b0101, 0), (0b0101, 1), (0b1010, 3), (0b0110, 2)]]),
    (str(REPO / "verilog" / "mult2.v"), [{"a": a, "b": b} for a, b in [(3, 3), (2, 3), (1, 2), (0, 3)]]),
])
def test_rk4_matches_logic_on_other_designs(design, vectors, p):
    nl = synth.synthesize(design)
    res = simulation.run_physical(nl, p, vectors, "rk4")
    for v, r in zip(vectors, res):
        assert r["valid"], (design, v, r["amplitudes"])
        assert r["outputs"] == logic.evaluate(nl, v), (design, v)


@pytest.mark.parametrize("design", [str(REPO / "verilog" / "comparator4.v"), str(REPO / "verilog" / "parity8.v")])
def test_rk4_matches_logic_large(design, p):
    nl = synth.synthesize(design)
    rng = np.random.default_rng(1)
    vectors = [{port: int(rng.integers(0, 2 ** w)) for port, w in nl.inputs.items()} for _ in range(6)]
    for v, r in zip(vectors, simulation.run_physical(nl, p, vectors, "rk4")):
        assert r["valid"] and r["outputs"] == logic.evaluate(nl, v)


def test_decode_reports_invalid_bits_instead_of_rounding(adder):
    amps = {"s[0]": 0.97, "s[1]": 0.8, "s[2]": 0.5}      # s[1] sits between the bands
    d = simulation.decode(adder, amps, {})
    assert d["bits"]["s[1]"] is None and d["valid"] is False and d["outputs"]["s"] is None
    assert d["min_margin"] < 0


def test_cli_synth_json(adder):
    rc, out, _ = cli("synth", str(REPO / "verilog" / "adder2.v"), "--json")
    assert rc == 0
    d = json.loads(out)
    assert d["top"] == "adder2" and d["gates"] <= 17 and d["latches"] == 0
    assert d["oscillators"] == 6 * d["gates"] and d["nonlinear_springs"] == 5 * d["gates"]
    assert d["inputs"] == {"a": 2, "b": 2} and d["outputs"] == {"s": 3}
    assert d["linear_springs"] == d["dashpots"]


def test_cli_simulate_logic_json():
    rc, out, _ = cli("simulate", str(REPO / "verilog" / "adder2.v"), "--set", "a=3", "--set", "b=2", "--backend", "logic", "--json")
    d = json.loads(out)
    assert rc == 0 and d["outputs"] == {"s": 5} and d["bits"] == {"s[0]": 1, "s[1]": 0, "s[2]": 1}
    for key in ("backend", "amplitudes", "valid", "min_margin", "periods", "wall_s"):
        assert key in d


@pytest.mark.parametrize("args,needle", [
    (["synth", str(REPO / "verilog" / "bad_syntax.v")], "line 5"),
    (["synth", str(REPO / "verilog" / "adder2.v"), "--top", "nope"], "nope"),
    (["synth", "missing.v"], "cannot read"),
    (["synth", str(REPO / "verilog" / "loop.v")], "combinational loop"),
    (["simulate", str(REPO / "verilog" / "adder2.v"), "--set", "c=1", "--backend", "logic"], "unknown input port 'c'"),
    (["simulate", str(REPO / "verilog" / "adder2.v"), "--set", "a=4", "--backend", "logic"], "does not fit"),
    (["simulate", str(REPO / "verilog" / "adder2.v"), "--set", "a=x", "--backend", "logic"], "is not a whole number"),
])
def test_cli_errors_are_one_line(args, needle):
    rc, out, err = cli(*args)
    assert rc == 2
    assert needle in err
    assert err.count("\n") == 1 and "Traceback" not in err


@pytest.mark.ngspice
def test_cli_emit_runs_standalone_and_ngspice_matches_rk4(tmp_path):
    cir = tmp_path / "add.cir"
    rc, _, err = cli("emit", str(REPO / "verilog" / "adder2.v"), "--set", "a=3", "--set", "b=2", "-o", str(cir))
    assert rc == 0, err
    r = subprocess.run(["ngspice", "-b", str(cir)], capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-500:]
    common = ["simulate", str(REPO / "verilog" / "adder2.v"), "--set", "a=3", "--set", "b=2", "--json", "--periods", "2900"]
    rc1, out1, err1 = cli(*common, "--backend", "ngspice")
    rc2, out2, _ = cli(*common, "--backend", "rk4")
    assert rc1 == 0 and rc2 == 0, err1
    ng, rk = json.loads(out1), json.loads(out2)
    assert ng["outputs"]["s"] == 5 and ng["valid"] and "ngspice_options" in ng
    for bit, a in rk["amplitudes"].items():
        assert abs(ng["amplitudes"][bit] - a) < 0.01


@pytest.mark.parametrize("backend", ["ngspice", "ngspice-envelope"])
def test_clocked_ngspice_runs_honour_method(monkeypatch, backend):
    """`simulate CLOCKED.v --backend ngspice --method gear` hands gear to ngspice (it used to run trap)."""
    from mech2spice import cli
    from mech2spice.backends import ngspice as engines
    seen = {}

    def capture(model, periods, stimulus=None, options=None, opts=None, **kw):
        seen["options"] = options or opts
        raise Mech2SpiceError("captured")
    monkeypatch.setattr(engines.runner, "run_batch", capture)
    monkeypatch.setattr(engines, "run_envelope_spice", capture)
    dff = Path(__file__).resolve().parent.parent / "verilog" / "dff.v"
    assert cli.main(["simulate", str(dff), "--backend", backend, "--method", "gear", "--max-step", "0.02",
                     "--cycles", "1", "--set", "d=1"]) == 2
    assert seen["options"].method == "gear" and seen["options"].max_step_periods == 0.02


def test_engine_flags_belong_to_their_engines():
    """--method is an ngspice setting, --steps a time-stepping one: given to another engine they are refused."""
    from mech2spice import cli
    adder = str(Path(__file__).resolve().parent.parent / "verilog" / "adder2.v")
    assert cli.main(["simulate", adder, "--backend", "rk4", "--method", "gear"]) == 2
    assert cli.main(["simulate", adder, "--backend", "ngspice", "--steps", "100"]) == 2
    # the logic oracle has no time: these were ignored with exit 0 (hostile-input pass, session 21)
    counter = str(Path(__file__).resolve().parent.parent / "verilog" / "counter4.v")
    for argv in ([adder, "--steps", "5"], [adder, "--periods", "5"], [adder, "--pulse", "5"],
                 [counter, "--cycles", "2", "--pause", "5"], [counter, "--cycles", "2", "--noise", "1"]):
        assert cli.main(["simulate", *argv, "--backend", "logic"]) == 2, argv


def test_long_runs_say_how_long_they_will_take_before_starting(adder, p):
    """A run estimated past ESTIMATE_LOG_S announces its size and duration before any integration."""
    said = []

    class Announced(Exception):
        pass

    def log(msg):
        said.append(msg)
        raise Announced
    with pytest.raises(Announced):
        simulation.run_physical(adder, p, [{"a": 1}], "rk4", periods=10 ** 6, log=log)
    assert "102 oscillators" in said[0] and "estimated" in said[0] and "min" in said[0]
    quiet = []
    simulation.run_physical(adder, p, [{"a": 1}], "envelope", periods=200, log=quiet.append)
    assert quiet == []                                   # short runs say nothing


def test_a_clocked_trace_too_large_for_memory_is_refused(p):
    """The per-period amplitude trace is bounded: a schedule that would need more is refused up front."""
    nl = synth.synthesize(str(REPO / "verilog" / "counter4.v"))
    cycles = simulation.expand_steps([{"set": {"rst": 0, "en": 1}, "cycles": 40_000}])
    with pytest.raises(Mech2SpiceError, match="GB of amplitudes"):
        simulation.run_clocked_physical(nl, p, cycles, "envelope", clocking.clock_timing(nl))
