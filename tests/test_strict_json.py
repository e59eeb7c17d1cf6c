"""Every JSON and JSON-lines file the tool writes is strict JSON (issue #37): no NaN, Infinity or -Infinity,
which `jq` and other strict readers refuse; a non-finite figure is null, with its reason beside it.

Each command that writes JSON runs on a small case and every file and stdout is parsed by a strict parser.
"""
import json
import math
import shutil
from pathlib import Path

import pytest

from cli_helpers import run

from mech2spice.inputs import finite, strict_json

ROOT = Path(__file__).resolve().parents[1]
ADDER, SIEVE = ROOT / "verilog/adder2.v", ROOT / "programs/sieve.asm"
NOR = "module t(input a, input b, output y);\n  assign y = ~(a | b);\nendmodule\n"


def _refuse(constant: str):
    raise ValueError(f"{constant} is not strict JSON")


def strict(text: str):
    """The parsed JSON; ValueError on NaN/Infinity."""
    return json.loads(text, parse_constant=_refuse)


def strict_lines(path: Path) -> list:
    lines = path.read_text().splitlines()
    assert lines, f"{path} is empty"
    return [strict(line) for line in lines]


def ok(capsys, *argv) -> str:
    code, out, err = run(capsys, *argv)
    assert code in (0, 1), (code, err[-2000:])
    return out


def test_the_writer_turns_non_finite_numbers_into_null():
    import numpy as np
    data = {"a": math.inf, "b": [-math.inf, math.nan, np.float32("nan"), np.array([1.0, np.inf])], "c": (1, 2)}
    assert strict(strict_json(data)) == {"a": None, "b": [None, None, None, [1.0, None]], "c": [1, 2]}
    assert finite({"n": np.int64(3), "t": np.bool_(True)}) == {"n": 3, "t": True}


def test_cpu_run_checkpoint_trace_and_output(capsys, tmp_path):
    ck, trace = tmp_path / "ck.json", tmp_path / "trace.jsonl"
    out = ok(capsys, "cpu", "run", SIEVE, "--checkpoint", ck, "--trace", trace, "--json")
    assert strict(out)["halted"]
    strict(ck.read_text())
    assert len(strict_lines(trace)) == strict(out)["cycles"]


def test_montecarlo_results_lines_and_summary(capsys, tmp_path):
    design, results = tmp_path / "t.v", tmp_path / "r.jsonl"
    design.write_text(NOR)
    out = ok(capsys, "montecarlo", design, "--samples", "2", "--spread", "0.01", "--scheduler", "inline",
             "--out", results, "--json")
    strict(out)
    assert [r["type"] for r in strict_lines(results)] == ["header", "sample", "sample"]


def test_a_failed_samples_margin_is_null_with_its_reason(tmp_path):
    """A diverged sample's margin (-inf in memory) is written as null beside its reason and read back."""
    from mech2spice.experiments import mc_run
    from mech2spice.experiments.mc_clocked import _failed
    path = tmp_path / "r.jsonl"
    with open(path, "w") as fh:
        mc_run._append(fh, [_failed(0, RuntimeError("simulation diverged"))])
    (line,) = strict_lines(path)
    assert line["margin"] is None and line["reason"] == "simulation diverged" and line["pass"] is False
    assert mc_run._record(path.read_bytes(), 2, path)["margin"] is None


def test_center_record_best_block_and_output(capsys, tmp_path):
    out = ok(capsys, "center", "--steps", "0", "--out", tmp_path / "c", "--json")
    strict(out)
    record = strict((tmp_path / "c/centering.json").read_text())
    assert record["steps"][0]["accepted"]
    strict((tmp_path / "c/best.json").read_text())


def test_design_record_writer(tmp_path):
    from mech2spice.design.search import write_atomic
    write_atomic(tmp_path / "rec.json", {"tolerance": math.inf, "margin": -math.inf})
    assert strict((tmp_path / "rec.json").read_text()) == {"tolerance": None, "margin": None}


@pytest.mark.parametrize("argv", [
    ["synth", ADDER, "--json"],
    ["simulate", ADDER, "--set", "a=1", "--set", "b=2", "--backend", "logic", "--json"],
    ["gate", "--quick", "--json"],
    ["report", "--list", "--json"],
], ids=["synth", "simulate", "gate", "report-list"])
def test_command_output(capsys, argv):
    strict(ok(capsys, *argv))


def test_emit_output(capsys, tmp_path):
    strict(ok(capsys, "emit", ADDER, "--set", "a=1", "-o", tmp_path / "a.cir", "--json"))
    strict(ok(capsys, "emit", ADDER, "--format", "veriloga", "-o", tmp_path / "m.va", "--json"))


@pytest.mark.skipif(not (shutil.which("iverilog") and shutil.which("vvp")), reason="Icarus Verilog not installed")
def test_verify_output(capsys):
    strict(ok(capsys, "verify", ADDER, "--json", "--no-equivalence", "--vectors", "4"))
