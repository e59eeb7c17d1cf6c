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


# --------------------------------------------------------------------------- the reports' measured JSON
REPORTS = ROOT / "reports"


def test_every_checked_in_report_json_is_strict():
    """reports/*.json and the records kept under it (the studies' JSON and saved command output)."""
    paths = sorted(REPORTS.rglob("*.json"))
    assert len(paths) > 20
    for path in paths:
        try:
            strict(path.read_text())
        except ValueError as err:
            pytest.fail(f"{path.relative_to(ROOT)}: {err}")


def test_the_studies_writer_is_strict_and_keeps_its_layout(tmp_path):
    import numpy as np
    from mech2spice.studies import write_json
    data = {"time_err": math.inf, "margin_quantiles": {"50%": np.float64("nan")}, "output_delays": [1316.0, math.nan],
            "x": np.float32(0.5), "a": np.arange(2), "t": (1, -math.inf)}
    write_json(tmp_path / "r.json", data)
    assert strict((tmp_path / "r.json").read_text()) == {
        "time_err": None, "margin_quantiles": {"50%": None}, "output_delays": [1316.0, None], "x": 0.5,
        "a": [0, 1], "t": [1, None]}
    same = {"step": 0.5, "n": 3, "s": "é", "rows": [[1.25, None, True]]}    # finite data: the layout it always had
    write_json(tmp_path / "f.json", same)
    assert (tmp_path / "f.json").read_text() == json.dumps(same, indent=1)


def _envelope_figures(d):
    scene = d["scenes"][2]
    return [(v[run], "time_err") for v in scene["variants"].values() for run in ("vs80", "vs160")] + \
        [(d["scenes"][0]["env"]["4"]["vs160"], "traj_err"), (d["sweep"]["sweep"][0]["vs80"], "time_err")]


def _robustness_figures(d):
    return [(d["curves"]["adder"][0]["margin_quantiles"], q) for q in ("1%", "50%")] + \
        [(d["noise"]["gate"][0]["margin_quantiles"], "50%"), (d["clocked"]["processor"][2]["margin_quantiles"], "1%")]


def _sequential_figures(d):
    return [(d["latch"]["output_delays"], 1), (d["latch_envelope"]["output_delays"], 0),
            (d["short_pulse"]["output_delays"], 1)]


@pytest.mark.parametrize("name, figures, value", [
    ("envelope", _envelope_figures, math.inf),
    ("robustness", _robustness_figures, math.nan),
    ("sequential", _sequential_figures, math.nan),
])
def test_a_renderer_reads_null_as_the_number_it_stood_for(tmp_path, name, figures, value):
    """`report NAME --render` writes the same markdown and figures, byte for byte, from the strict JSON (null)
    as from the JSON with NaN/Infinity the study wrote before; the figures set are ones the report prints."""
    from mech2spice import reports
    data = json.loads((REPORTS / f"{name}.json").read_text())
    places = figures(data)
    for nulled in (False, True):
        for container, key in places:
            container[key] = None if nulled else value
        folder = tmp_path / ("null" if nulled else "non_finite")
        folder.mkdir()
        text = json.dumps(data, indent=1)
        (strict if nulled else json.loads)(text)
        (folder / f"{name}.json").write_text(text)
        reports.module(name).write(folder, render=True)
    old, new = tmp_path / "non_finite", tmp_path / "null"
    written = sorted(f.name for f in old.iterdir() if f.suffix in (".md", ".png"))
    assert written and written == sorted(f.name for f in new.iterdir() if f.suffix in (".md", ".png"))
    for f in written:
        assert (new / f).read_bytes() == (old / f).read_bytes(), f
