"""scripts/rtl_suite.py on a small manifest of its own: a row per design (accepted and verified, refused
with its class, a step out of time), the cache that makes a rerun free, the table it writes."""
import importlib.util
import json
import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.skipif(not (shutil.which("iverilog") and shutil.which("vvp")),
                                reason="Icarus Verilog (iverilog, vvp) is not installed")

DESIGNS = {
    "bus": "module bus(input s, input [1:0] a, input [1:0] b, output [1:0] y);\n  wire [1:0] w;\n"
           "  assign w = s ? a : 2'bz;\n  assign w = s ? 2'bz : b;\n  assign y = w;\nendmodule\n",
    "pad": "module pad(input a, input en,\n  inout p,\n  output y);\n  assign p = en ? a : 1'bz;\n"
           "  assign y = p;\nendmodule\n",
}


def _suite():
    spec = importlib.util.spec_from_file_location("rtl_suite", ROOT / "scripts" / "rtl_suite.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def bench(tmp_path, monkeypatch):
    rtl = tmp_path / "bench" / "rtl"
    designs = []
    for name, text in DESIGNS.items():
        (rtl / name).mkdir(parents=True)
        (rtl / name / f"{name}.v").write_text(text)
        designs.append({"name": name, "file": f"{name}/{name}.v", "top": name, "repo": "test", "paths": []})
    (rtl / "manifest.json").write_text(json.dumps({"designs": designs}))
    monkeypatch.setenv("MECH2SPICE_BENCHMARKS", str(tmp_path / "bench"))
    return tmp_path


def _run(suite, tmp, *argv):
    assert suite.main(["--out", str(tmp / "out"), "--cache", str(tmp / "cache"), "--envelope-gates", "0",
                       *argv]) == 0
    return json.loads((tmp / "out" / "rtl_suite.json").read_text())


def test_one_row_per_design_with_its_verdict_or_refusal(bench, monkeypatch):
    suite = _suite()
    table = _run(suite, bench)
    rows = {r["name"]: r for r in table["rows"]}
    assert rows["bus"]["accepted"] and rows["bus"]["verify"]["verdict"] == "pass"
    assert rows["bus"]["verify"]["equivalence"] == "proved" and rows["bus"]["envelope"]["verdict"] == "skipped"
    assert not rows["pad"]["accepted"] and "line 2: inout port 'p'" in rows["pad"]["refusal"]
    assert table["summary"]["refusal_classes"] == {"inout port": ["pad"]}
    assert table["summary"]["verify_pass"] == 1
    md = (bench / "out" / "rtl_suite.md").read_text()
    assert "$MECH2SPICE_BENCHMARKS/rtl/pad/pad.v, line 2" in md and str(bench) not in md

    def no_run(*_):
        raise AssertionError("a cached design was measured again")
    monkeypatch.setattr(suite, "_cli", no_run)
    assert _run(suite, bench)["rows"] == table["rows"]


def test_a_step_out_of_time_is_a_row_not_a_stop(bench):
    table = _run(_suite(), bench, "--timeout", "0.01", "--only", "bus")
    (row,) = [r for r in table["rows"] if r["name"] == "bus"]
    assert not row["accepted"] and row["refusal"].startswith("no result within")
    assert table["summary"]["refusal_classes"] == {"timeout": ["bus"]}


def test_a_cache_entry_that_is_not_a_row_is_measured_again(bench):
    suite = _suite()
    _run(suite, bench, "--only", "pad")
    (entry,) = (bench / "cache").glob("pad-*.json")
    entry.write_text(json.dumps({"name": "pad", "accepted": True}))
    (row,) = _run(suite, bench, "--only", "pad")["rows"]
    assert not row["accepted"] and "inout port 'p'" in row["refusal"]


def test_the_reset_and_its_level_come_from_the_design_not_the_manifest_name(tmp_path, monkeypatch):
    """A counter whose `rst_n` is active high (as the public GCD's is): the suite once passed the manifest's
    bare name, and `--reset rst_n` asserted it at 0, so the counter was never reset in the run."""
    rtl = tmp_path / "bench" / "rtl"
    (rtl / "cnt").mkdir(parents=True)
    (rtl / "cnt" / "cnt.v").write_text(
        "module cnt(input clk, input rst_n, output reg [1:0] q);\n"
        "  always @(posedge clk) if (rst_n) q <= 2'd0; else q <= q + 2'd1;\nendmodule\n")
    design = {"name": "cnt", "file": "cnt/cnt.v", "top": "cnt", "clock": "clk", "reset": "rst_n",
              "repo": "test", "paths": []}
    (rtl / "manifest.json").write_text(json.dumps({"designs": [design]}))
    monkeypatch.setenv("MECH2SPICE_BENCHMARKS", str(tmp_path / "bench"))
    (row,) = _run(_suite(), tmp_path)["rows"]
    assert row["verify"]["verdict"] == "pass"
    (reset,) = row["verify"]["resets"]
    assert reset.startswith("rst_n=1 (design (synchronous")


@pytest.mark.parametrize("detail, cause", [
    ("the proof found inputs on which the outputs differ from its all-zero start, but replayed from power-up the "
     "source (Icarus) and the network (logic backend) do not differ on any bit the source defines (...): the start "
     "state, not the mapping, made the difference; give the reset with --reset PORT=LEVEL",
     "start state: a counterexample the replay from power-up does not reproduce"),
    ("the proof found inputs on which the outputs differ from its all-zero start, but replayed from power-up the "
     "source (Icarus) and the network (logic backend) do not differ on any bit the source defines (...): the reset "
     "(rst=0) was applied in cycle 0 of both, so what made the difference is the source's own x (...)",
     "x in the source past its reset: a counterexample the replay from power-up does not reproduce"),
    ("the outputs differ on this input (sequence), read after 3 clock edges; replayed: Icarus and the network "
     "(logic backend) differ on done[0]", "equivalence counterexample"),
    ("the proof's time budget (120 s) ran out: the bounded check of 20 cycles from the start was not finished, "
     "and the induction had not closed (tried up to length 1)", "proof budget ran out"),
    ("no counterexample within 20 cycles of the start, but the induction did not close within 20 steps (29 s of "
     "the proof's 120 s budget used)", "induction did not close (bounded check found no difference)"),
])
def test_a_verify_unknown_is_classed_by_its_cause_not_by_a_phrase_it_shares(detail, cause):
    assert _suite()._verify_class({"verdict": "unknown", "detail": detail}) == cause
