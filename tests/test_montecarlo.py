"""Monte-Carlo of whole designs (experiments/montecarlo.py, mc_run.py, `mech2spice montecarlo`):
the spread spec, spread 0 bit for bit, sampled netlists against RK4, resume after an interruption."""
from __future__ import annotations

import functools
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from mech2spice import simulation
from mech2spice.cli import main
from mech2spice.errors import Mech2SpiceError
from mech2spice.experiments import mc_run
from mech2spice.experiments import montecarlo as mc
from mech2spice.physics import network, spread
from mech2spice.physics.params import DEFAULT
from mech2spice.synthesis.synth import synthesize

ROOT = Path(__file__).resolve().parent.parent
ADDER = ROOT / "verilog/adder2.v"
AMP_TOL = 0.01          # u_R: the ngspice comparison suite's tolerance (tests/test_spice.py)


@functools.lru_cache(maxsize=None)
def netlist(path: str):
    return synthesize(path, max_fanout=network.MAX_FANOUT)


@pytest.fixture
def nor_v(tmp_path):
    path = tmp_path / "nor1.v"
    path.write_text("module nor1(input a, input b, output y);\n  assign y = ~(a | b);\nendmodule\n")
    return path


def job(path, sigma="3e-5", backend="envelope", union=2) -> dict:
    nl = netlist(str(path))
    return {"design": str(path), "params": "default", "vectors": mc.all_vectors(nl), "backend": backend,
            "spread": mc.parse_spread(sigma).describe(), "seed": 3, "periods": None, "union": union}


# --- the spread spec ---------------------------------------------------------------------
def test_spec_forms():
    assert mc.parse_spread("0").zero
    s = mc.parse_spread('{"local": {"*": 0.01, "k": 0.002}, "wafer": {"m": 0.005}, "wafer_rho": 0.5}')
    assert s.local["k"] == 0.002 and s.local["gamma"] == 0.01 and s.wafer["m"] == 0.005 and s.wafer["k"] == 0
    for bad in ('{"local": {"q": 0.1}}', '{"local": -0.1}', '{"wafer_rho": 2}', '{"sigma": 1}', "{oops"):
        with pytest.raises(Mech2SpiceError):
            mc.parse_spread(bad)


def test_draws_depend_only_on_seed_and_index():
    model = network.build(netlist(str(ADDER)), DEFAULT)
    el = spread.elements(model)
    s = mc.parse_spread("1e-3")
    assert np.array_equal(s.factors(el, 5, 7), s.factors(el, 5, 7))
    assert not np.array_equal(s.factors(el, 5, 7), s.factors(el, 5, 8))


def test_wafer_shift_is_shared_within_a_kind():
    model = network.build(netlist(str(ADDER)), DEFAULT)
    el = spread.elements(model)
    f = mc.parse_spread('{"wafer": {"k": 0.01, "gamma": 0.02}}').factors(el, 1, 0)
    kinds = np.array([e.kind for e in el])
    assert np.ptp(f[kinds == "k"]) == 0 and f[kinds == "k"][0] != 1
    assert np.ptp(f[kinds == "gamma"]) == 0 and np.all(f[kinds == "m"] == 1)


# --- spread 0 reproduces the deterministic result bit for bit ---------------------------
@pytest.mark.parametrize("backend", ["envelope", "rk4", "carrier"])
def test_spread_zero_is_the_deterministic_run_bit_for_bit(backend, nor_v):
    path = ADDER if backend == "envelope" else nor_v
    nl = netlist(str(path))
    vecs = mc.all_vectors(nl)
    d = mc.DesignMC(nl, DEFAULT, vecs, backend, mc.parse_spread("0"), 0)
    amps, used = d.amplitudes([0])
    ref = simulation.run_physical(nl, DEFAULT, vecs, backend)
    assert used == ref[0]["periods"]
    for b, r in enumerate(ref):
        assert [amps[0, k, b] for k in range(len(d.outs))] == [r["amplitudes"][o] for o in d.outs]
    # several samples as one union model: each copy is the nominal run, bit for bit
    many, _ = d.amplitudes([0, 1, 2])
    assert np.array_equal(many, np.repeat(amps, 3, axis=0))


def test_spread_zero_netlist_is_the_nominal_netlist():
    from mech2spice.spice.oscillator_netlist import emit
    nl = netlist(str(ADDER))
    d = mc.DesignMC(nl, DEFAULT, [{"a": 3, "b": 2}], "ngspice", mc.parse_spread("0"), 0)
    assert emit(*d.sample(5)[:1], 10, d.sample(5)[1]) == emit(d.model, 10, d.stim)


# --- sampled netlists: ngspice agrees with RK4 on a sampled adder -----------------------
@pytest.mark.ngspice
@pytest.mark.skipif(shutil.which("ngspice") is None, reason="ngspice not installed")
def test_sampled_adder_ngspice_matches_rk4():
    from mech2spice.spice.oscillator_netlist import emit
    nl = netlist(str(ADDER))
    got = {}
    for be in ("rk4", "ngspice"):
        d = mc.DesignMC(nl, DEFAULT, [{"a": 3, "b": 2}], be, mc.parse_spread("5e-5"), 7, periods=1000)
        got[be], _ = d.amplitudes([3])
    model, stim = d.sample(3)
    def instances(text):
        return [x for x in text.splitlines() if x.startswith("xg_")]
    assert all(" mi=" in x for x in instances(emit(model, 10, stim)))          # each element's own value
    assert not any(" mi=" in x for x in instances(emit(d.model, 10, d.stim)))  # the library's defaults
    assert np.abs(got["rk4"] - got["ngspice"]).max() < AMP_TOL


# --- the sweep: records, resume, Dask ----------------------------------------------------
def _records(path: Path) -> list[dict]:
    return [json.loads(x) for x in path.read_text().splitlines()[1:]]


def test_interrupted_sweep_resumes_each_sample_once(tmp_path):
    j = job(ADDER, "1.5e-4")
    whole = mc_run.run(j, 8, tmp_path / "whole.jsonl", scheduler="inline")
    part = tmp_path / "part.jsonl"
    with pytest.raises(mc_run.Interrupted):
        mc_run.run(j, 8, part, scheduler="inline", stop_after=2)
    assert len(_records(part)) == 4
    with open(part, "a") as fh:                      # killed while writing a record
        fh.write('{"type": "sample", "i": 5, "pa')
    res = mc_run.run(j, 8, part, scheduler="inline")
    recs = _records(part)
    assert sorted(r["i"] for r in recs) == list(range(8)) and res["ran"] == 4 and res["resumed"] == 4
    assert {r["i"]: r for r in recs} == {r["i"]: r for r in _records(tmp_path / "whole.jsonl")}
    assert {k: res[k] for k in ("failures", "yield", "failing_bits")} == \
        {k: whole[k] for k in ("failures", "yield", "failing_bits")}
    with pytest.raises(Mech2SpiceError, match="another job"):
        mc_run.run({**j, "seed": 4}, 8, part, scheduler="inline")


def test_results_file_is_keyed_by_parameter_values_not_file_names(tmp_path):
    """A parameter file edited between two runs must not resume the first run's samples."""
    params = tmp_path / "p.json"
    params.write_text(json.dumps({"q_c": 210.0}))
    j = {"design": "x.v", "params": str(params), "seed": 1}
    before = mc.job_key(j)
    params.write_text(json.dumps({"q_c": 190.0}))
    assert mc.job_key(j) != before
    import hashlib                       # a built-in preset keys by name: older results files still resume
    plain = {**j, "params": "default"}
    assert mc.job_key(plain) == hashlib.sha256(json.dumps(plain, sort_keys=True).encode()).hexdigest()[:16]

def test_dask_local_cluster_matches_inline(tmp_path, nor_v):
    j = job(nor_v, "1e-3")
    a = mc_run.run(j, 4, tmp_path / "a.jsonl", scheduler="inline")
    b = mc_run.run(j, 4, tmp_path / "b.jsonl", scheduler="local", workers=1)
    assert b["workers"] == 1 and b["worker_peak_rss_mb"] > 0
    # Equal except the last bits of the margins, which a Dask worker (its own process, BLAS on one thread,
    # other allocations) reproduced only to 4e-16 once in CI (0.04436496685341719 against ...737)
    inline, dask = _records(tmp_path / "a.jsonl"), sorted(_records(tmp_path / "b.jsonl"), key=lambda r: r["i"])
    margins = ("margin", "gate_margin")
    assert [{k: v for k, v in r.items() if k not in margins} for r in inline] == \
        [{k: v for k, v in r.items() if k not in margins} for r in dask]
    for r, q in zip(inline, dask):
        assert all(r[k] == pytest.approx(q[k], rel=1e-12, abs=1e-15) for k in margins if k in r)
    assert a["yield_ci95"] == b["yield_ci95"]


def test_cli_summary_fields(tmp_path, nor_v, capsys):
    out = tmp_path / "r.jsonl"
    code = main(["montecarlo", str(nor_v), "--samples", "3", "--spread", "1e-5", "--scheduler", "inline",
                 "--out", str(out), "--json"])
    res = json.loads(capsys.readouterr().out)
    assert code == 0 and res["samples"] == 3 and res["yield"] == 1.0
    for key in ("failures", "yield_ci95", "margin_quantiles", "failing_bits", "gate_failure_rate",
                "samples_per_s", "wall_s"):
        assert key in res
    assert main(["montecarlo", str(nor_v), "--samples", "3", "--spread", "1e-5", "--scheduler", "inline",
                 "--out", str(out), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["ran"] == 0


def test_a_results_file_of_an_edited_design_does_not_resume(tmp_path, capsys):
    """The file named the design by its path only: editing `y = ~a` into `y = a` and asking for one sample more
    resumed the first design's samples beside the second's, exit 0 (hostile-input pass, session 21)."""
    src, out = tmp_path / "d.v", tmp_path / "r.jsonl"
    run = ["montecarlo", str(src), "--spread", "1e-5", "--scheduler", "inline", "--out", str(out), "--json"]
    src.write_text("module d(input a, output y);\n  assign y = ~a;\nendmodule\n")
    assert main([*run, "--samples", "2"]) == 0
    capsys.readouterr()
    src.write_text("module d(input a, output y);\n  assign y = a;   // edited\nendmodule\n")
    assert main([*run, "--samples", "3"]) == 2
    err = capsys.readouterr().err
    assert "another job" in err and len(err.strip().splitlines()) == 1
    src.write_text("module d(input a, output y);\n  // a comment moves no wire\n  assign y = ~a;\nendmodule\n")
    assert main([*run, "--samples", "3"]) == 0
    assert json.loads(capsys.readouterr().out)["resumed"] == 2


@pytest.mark.parametrize("address", ["foo", "tcp://", "host:port", "tcp://host", "host:0", "host:70000",
                                     "tcp://host:8786/x", "", "local "])
@pytest.mark.parametrize("command", [["montecarlo", str(ADDER)], ["cpu", "montecarlo", "programs/sieve.asm"]])
def test_scheduler_that_is_not_an_address_is_one_line_before_work(command, address, capsys, tmp_path):
    """It reached dask.distributed.Client, which failed with a ValueError traceback after the synthesis."""
    out = tmp_path / "r.jsonl"
    assert main([*command, "--samples", "1", "--spread", "0.01", "--scheduler", address, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "argument --scheduler: scheduler" in err and "HOST:PORT" in err and err.count("\n") == 1
    with pytest.raises(Mech2SpiceError, match="expected local, inline"):
        mc_run.run({"design": "x"}, 1, out, scheduler=address)
    assert not out.exists()


@pytest.mark.parametrize("address", ["local", "inline", "host:8786", "tcp://10.0.0.5:8786", "[::1]:8786",
                                     "tls://sched.example.org:8786"])
def test_scheduler_addresses_are_taken(address):
    assert mc_run.check_scheduler(address) == address


def test_cli_errors_are_one_line(nor_v, capsys):
    assert main(["montecarlo", str(nor_v), "--samples", "2", "--spread", '{"local": {"x": 1}}']) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("mech2spice: error: spread spec") and "\n" not in err
    assert main(["montecarlo", str(ROOT / "verilog/counter4.v"), "--samples", "2", "--spread", "0"]) == 2


def test_local_workers_keep_glibc_malloc_thresholds_and_no_profiler():
    """A LocalCluster's workers run without the Nanny's MALLOC_TRIM_THRESHOLD_ (which made every compiled call's
    scratch arrays fresh pages: 10x the system time) and without the 10 ms statistical profiler; the thread
    limits Dask sets stay."""
    import dask
    from mech2spice.experiments.mc_run import _worker_config
    with dask.config.set(_worker_config()):
        environ = dask.config.get("distributed.nanny.pre-spawn-environ")
        assert "MALLOC_TRIM_THRESHOLD_" not in environ and int(environ["OMP_NUM_THREADS"]) == 1
        assert dask.config.get("distributed.worker.profile.enabled") is False
    assert "MALLOC_TRIM_THRESHOLD_" in dask.config.get("distributed.nanny.pre-spawn-environ")   # only inside
