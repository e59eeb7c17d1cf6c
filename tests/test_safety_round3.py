"""Safe with anyone's files, round 3 (issue #37): one test per class of what a hostile user tried on `verify`,
`center`, `report --render`, blocks with their own levels and the processor's progress.

Lost inputs: every output refused before anything is written, each named file keeping its bytes and mtime.
Silent wrong answers: a block that cannot drive itself is refused on load; a non-finite centering is refused.
Tracebacks: each case is one line on stderr and exit 2 (or, where the input is fine, a run).
"""
import json
import math
import shutil
from pathlib import Path

import pytest

from cli_helpers import refused as refused_line, run
from test_output_paths import intact, keep, refused, write

from mech2spice import data
from mech2spice.design import centering
from mech2spice.errors import Mech2SpiceError
from mech2spice.physics import loaded
from mech2spice.physics.params import BLOCK_PRESETS, DEFAULT, PRESETS, load_params

ROOT = Path(__file__).resolve().parents[1]
ADDER, SIEVE = ROOT / "verilog/adder2.v", ROOT / "programs/sieve.asm"
NOR_INCLUDING = '`include "defs.vh"\nmodule t(input a, input b, output y);\n  assign y = ~(a | b);\nendmodule\n'
ICARUS = shutil.which("iverilog") and shutil.which("vvp")


@pytest.fixture
def no_centering(monkeypatch):
    """A centering run fails the test: a refusal must come before it."""
    def boom(*args, **kwargs):
        raise AssertionError("the centering started before its outputs were checked")
    monkeypatch.setattr(centering, "run", boom)


@pytest.fixture
def including(tmp_path):
    """A design that includes defs.vh beside it: (design, defs.vh)."""
    defs = write(tmp_path / "defs.vh", "`define UNUSED 1\n")
    return write(tmp_path / "d.v", NOR_INCLUDING), defs


# ------------------------------------------------------------------ lost inputs

def test_verify_junit_is_never_the_params_file(capsys, tmp_path):
    params = write(tmp_path / "p.json", json.dumps({"name": "mine"}))
    refused(capsys, keep(params), "verify", ADDER, "--junit", params, "--params", params, needle="--params file")


def test_verify_junit_is_never_a_file_the_design_includes(capsys, including):
    design, defs = including
    refused(capsys, keep(design, defs), "verify", design, "--junit", defs, needle="include")


def test_emit_and_montecarlo_never_write_over_an_included_file(capsys, including):
    design, defs = including
    kept = keep(design, defs)
    refused(capsys, kept, "emit", design, "-o", defs, needle="include")
    refused(capsys, kept, "montecarlo", design, "--samples", "1", "--spread", "0.01", "--scheduler", "inline",
            "--out", defs, needle="include")


def test_verify_junit_replaces_another_file_only_with_force(capsys, tmp_path):
    mine = write(tmp_path / "existing.xml", "<notes>mine</notes>\n")
    refused(capsys, keep(mine), "verify", ADDER, "--junit", mine, "--no-equivalence", needle="--force")


@pytest.mark.skipif(not ICARUS, reason="Icarus Verilog (iverilog, vvp) not installed")
def test_verify_junit_rewrites_its_own_report(capsys, tmp_path):
    junit = tmp_path / "j.xml"
    argv = ["verify", ADDER, "--junit", junit, "--no-equivalence", "--vectors", "4"]
    assert run(capsys, *argv)[0] == 0 and "<testsuite " in junit.read_text()
    assert run(capsys, *argv)[0] == 0                     # its own kind: replaced without --force
    mine = write(tmp_path / "mine.xml", "<notes/>")
    assert run(capsys, *argv[:3], mine, *argv[4:], "--force")[0] == 0 and "<testsuite " in mine.read_text()


def test_center_never_writes_over_its_seed(capsys, tmp_path, no_centering):
    u = tmp_path / "u"
    u.mkdir()
    seed = u / centering.BEST
    shutil.copy(data.path("blocks", "robust.json"), seed)
    refused(capsys, keep(seed), "center", "--from", seed, "--out", u, needle="--from block")


def test_center_never_replaces_a_users_best_json(capsys, tmp_path, no_centering):
    d = tmp_path / "d"
    d.mkdir()
    best = write(d / centering.BEST, json.dumps({"mine": 1}))
    refused(capsys, keep(best), "center", "--out", d, needle="--force")


def test_gate_report_never_writes_over_its_params(capsys, tmp_path):
    params = tmp_path / "gate.json"
    shutil.copy(data.path("blocks", "robust.json"), params)
    refused(capsys, keep(params), "gate", "--params", params, "--report", tmp_path, needle="--params file")


def test_subckts_never_writes_over_its_params(capsys, tmp_path):
    params = tmp_path / "m2s_couple.subckt"                # a block file under the name of a library file
    shutil.copy(data.path("blocks", "robust.json"), params)
    refused(capsys, keep(params), "subckts", "-o", tmp_path, "--params", params, needle="--params file")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m2s_couple.subckt"]


def test_subckts_replaces_only_its_own_files(capsys, tmp_path):
    """`subckts -o DIR` wrote over any file that had a library file's name, and through a link out of DIR
    (hostile-input pass, session 21): now a link is refused, another's file needs --force, its own are replaced."""
    out, outside = tmp_path / "lib", write(tmp_path / "outside.txt", "keep\n")
    out.mkdir()
    (out / "m2s_drive.subckt").symlink_to(outside)
    refused(capsys, keep(outside), "subckts", "-o", out, needle="is a link")
    (out / "m2s_drive.subckt").unlink()
    notes = write(out / "m2s_osc.subckt", "my notes\n")
    refused(capsys, keep(notes), "subckts", "-o", out, needle="--force")
    assert [p.name for p in out.iterdir()] == ["m2s_osc.subckt"]          # nothing written before the refusal
    for argv in (["--force"], []):                                         # then its own files need no --force
        assert run(capsys, "subckts", "-o", out, *argv)[0] == 0
        assert {p.name: p.read_bytes() for p in out.iterdir()} == \
            {p.name: p.read_bytes() for p in (ROOT / "subckts").iterdir() if p.name != "README.md"}


def test_report_name_stays_inside_out(capsys, tmp_path):
    sub = tmp_path / "sub"
    sub.mkdir()
    outside = write(tmp_path / "x.md", "mine\n")
    kept = keep(outside)
    for name in ("../x", str(tmp_path / "x"), "..", ""):
        refused(capsys, kept, "report", "cpu_physical", "--render", "--out", sub, "--name", name, needle="--name")
    assert not any(sub.iterdir())


# ------------------------------------------------------------------ silent wrong answers

def test_a_block_whose_outputs_miss_its_own_bands_is_refused_on_load(capsys, tmp_path):
    bands = write(tmp_path / "bands.json", json.dumps({"levels": {"band0": [0, 0.995], "band1": [0.996, 1.1]}}))
    refused_line(capsys, "simulate", ADDER, "--set", "a=3", "--set", "b=3", "--params", bands, "--backend",
                 "envelope", needle="cannot drive itself")
    block = json.loads(data.path("blocks", "robust.json").read_text())
    block["levels"] = {"band0": [0, 0.995], "band1": [0.996, 1.1]}
    with pytest.raises(Mech2SpiceError, match="cannot drive itself"):
        load_params(str(write(tmp_path / "blk.json", json.dumps(block))))


def test_the_check_is_in_place_whatever_was_imported_first(tmp_path):
    """load_params imported alone (no model builder imported yet) still refuses: the physics package hands
    the check to params.LOAD_CHECKS on its own import."""
    import subprocess
    import sys
    bands = write(tmp_path / "bands.json", json.dumps({"levels": {"band0": [0, 0.995], "band1": [0.996, 1.1]}}))
    code = f"from mech2spice.physics.params import load_params; load_params({str(bands)!r})"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode != 0 and "cannot drive itself" in r.stderr


@pytest.mark.parametrize("name", ["default", *BLOCK_PRESETS])
def test_every_shipped_block_drives_itself(name):
    assert loaded.self_drive_margin(load_params(name)) >= loaded.SELF_DRIVE_MARGIN


def test_the_self_drive_check_is_measured_once_per_block(monkeypatch):
    p = load_params("robust")
    loaded.self_drive_margin(p)
    monkeypatch.setattr(loaded, "build", lambda *a, **k: pytest.fail("measured again"))
    assert loaded.self_drive_margin(p) == loaded._SELF_DRIVE[loaded.digest(p)]


def test_a_spread_too_small_for_a_finite_beta_writes_nothing(capsys, tmp_path):
    out = tmp_path / "c"
    refused_line(capsys, "center", "--spread", "1e-300", "--steps", "0", "--out", out, needle="too small")
    assert not out.exists() or not any(out.iterdir())


# ------------------------------------------------------------------ tracebacks

def report_refused(capsys, *argv, needle: str) -> None:
    """`report` says which report it writes on stderr first; then one error line, exit 2, no traceback."""
    code, _, err = run(capsys, *argv)
    lines = err.splitlines()
    assert code == 2 and "Traceback" not in err and lines[-1].startswith("mech2spice: error:"), err
    assert len(lines) <= 2 and needle in lines[-1], err


def _record(steps: list) -> dict:
    """A centering record with the settings of `center --out DIR` (defaults) around `steps`."""
    settings = centering.Settings("robust", centering.TrimmedSpread(0.01, "none", 0.0))
    return {"format": centering.FORMAT, "version": 1, "settings": settings.to_dict(), "steps": steps}


def _step(**over) -> dict:
    x = centering.Design(load_params("robust"), True).x0().tolist()
    return {"step": 0, "x": x, "trust_next": 1.0, "accepted": True, "nominal_margin": 0.07,
            "tolerance_linear": 0.01, "beta_target": 2.0, **over}


@pytest.mark.parametrize("steps, needle", [
    ([], "no steps"),
    ([_step(accepted=False)], "no accepted step"),
    ([{k: v for k, v in _step().items() if k != "tolerance_linear"}], "$.steps[0].tolerance_linear: missing"),
    ([_step(nominal_margin="0.07")], "$.steps[0].nominal_margin: a string"),
    ([_step(beta_target="big")], "$.steps[0].beta_target: a string"),
    ([_step(step=True)], "$.steps[0].step: true/false"),
    ([_step(), _step(beta_target=math.nan)], "$.steps[1].beta_target: nan"),
    ([_step(x=[0.1])], "$.steps[0].x: 1 numbers, not the block's"),
    ([_step(limiting_target={"margin": -math.inf})], "$.steps[0].limiting_target.margin: not a finite number"),
    ([_step(trust_next=0)], "$.steps[0].trust_next: a whole number, not a number > 0"),
], ids=["empty", "none-accepted", "missing-field", "figure-string", "beta-string", "step-bool", "beta-nan",
        "x-short", "infinity-inside", "trust-zero"])
def test_a_damaged_centering_record_is_one_line(capsys, tmp_path, steps, needle):
    out = tmp_path / "run"
    record = write(out.mkdir() or out / centering.RECORD, json.dumps(_record(steps)))
    kept = keep(record)
    refused_line(capsys, "center", "--out", out, "--steps", "1", needle=needle)
    intact(kept)


@pytest.mark.parametrize("content, needle", [
    ("[]", "$: a list, not an object"), ("{}", "$: an empty object"), ('"x"', "$: a string, not an object"),
    ("cycles", "$.cycles: a string, not a whole number >= 0"),
], ids=["list", "empty", "string", "count-string"])
def test_stored_report_json_of_another_shape_is_one_line(capsys, tmp_path, content, needle):
    if content == "cycles":
        stored = json.loads((ROOT / "reports/cpu_physical.json").read_text())
        content = json.dumps({**stored, "cycles": "many"})
    write(tmp_path / "cpu_physical.json", content)
    report_refused(capsys, "report", "cpu_physical", "--render", "--out", tmp_path, needle=needle)
    assert not (tmp_path / "cpu_physical.md").exists()


def test_a_renderer_failing_on_the_stored_shape_is_one_line(capsys, tmp_path):
    stored = json.loads((ROOT / "reports/gate.json").read_text())
    first = next(k for k, v in stored.items() if isinstance(v, dict))
    write(tmp_path / "gate.json", json.dumps({**stored, first: "x"}))
    report_refused(capsys, "report", "gate", "--render", "--out", tmp_path,
                   needle=f"$.{first}: a string, not an object")


@pytest.mark.skipif(not ICARUS, reason="Icarus Verilog (iverilog, vvp) not installed")
@pytest.mark.parametrize("source", ["module c(output y);\n  assign y = 1'b1;\nendmodule\n",
                                    "module k(input clk, output reg q);\n  always @(posedge clk) q <= ~q;\n"
                                    "endmodule\n"], ids=["no-inputs", "clock-only"])
def test_verify_a_design_without_data_inputs(capsys, tmp_path, source):
    code, out, err = run(capsys, "verify", write(tmp_path / "d.v", source), "--json")
    assert code == 0 and "Traceback" not in err, err
    assert json.loads(out)["cosim"]["agree"]


def test_a_quality_factor_of_1e300_is_refused(capsys, tmp_path):
    block = json.loads(data.path("blocks", "classic.json").read_text())
    block["block"]["dofs"]["C"]["q"] = 1e300
    refused_line(capsys, "gate", "--quick", "--params", write(tmp_path / "blk.json", json.dumps(block)),
                 needle="blk.json")
    from dataclasses import replace
    from mech2spice.experiments import characterise
    with pytest.raises(Mech2SpiceError, match="not finite"):             # the root finder, reached directly
        characterise.characterise(replace(DEFAULT, q_g=1e300), quick=True)


def test_emit_veriloga_refuses_what_it_would_ignore(capsys, tmp_path):
    lib = tmp_path / "lib.va"
    refused_line(capsys, "emit", "/nonexistent/design.v", "--format", "veriloga", "--set", "a=9", "-o", lib,
                 needle="--set")
    refused_line(capsys, "emit", "/nonexistent/design.v", "--format", "veriloga", "-o", lib, needle="no such file")
    assert not lib.exists()


# ------------------------------------------------------------------ progress that knows its end

def _progress_lines(monkeypatch, lookahead_s: float) -> list[str]:
    from mech2spice.backends import _base
    from mech2spice.cpu import run as cpu_run
    monkeypatch.setattr(_base, "PROGRESS_EVERY_S", 0.0)
    monkeypatch.setattr(cpu_run, "ISS_LOOKAHEAD_S", lookahead_s)
    lines = []
    cpu_run.run_program(str(SIEVE), "logic", max_cycles=100_000, progress=lines.append)
    return lines


def test_a_processor_runs_progress_is_against_the_programs_length(monkeypatch):
    lines = _progress_lines(monkeypatch, 2.0)
    assert lines and all("/457 cycles" in line for line in lines), lines[:3]
    assert lines[-1].startswith("457/457 cycles (100%)")


def test_a_processor_runs_progress_without_a_known_end_has_no_percentage(monkeypatch):
    lines = _progress_lines(monkeypatch, -1.0)          # the ISS gets no time: the length is unknown
    assert lines and not any("%" in line or "to go" in line or "100,000" in line for line in lines), lines[:3]
    assert lines[-1].startswith("457 cycles,") and "s elapsed" in lines[-1]


# ------------------------------------------------------------------ Monte-Carlo lines read back on resume

@pytest.mark.parametrize("sample, ok", [
    ({"margin": None, "reason": "simulation diverged"}, True),           # what the strict writer writes
    ({"margin": "-Infinity"}, False), ({"failing_bits": ["s[0]"]}, False), ({"failing_gates": [3]}, False),
    ({"reason": 5}, False), ({"margin": -math.inf}, False), ({"gate_margin": math.nan}, False),
    ({"worst_gate": 3}, False), ({"extra": [math.inf]}, False),
], ids=["null-margin", "margin-string", "bits-list", "gate-number", "reason-number", "margin-infinity",
        "gate-margin-nan", "worst-gate-number", "infinity-elsewhere"])
def test_montecarlo_lines_are_checked_before_a_resume_counts_them(tmp_path, monkeypatch, sample, ok):
    from mech2spice.experiments import mc_run
    monkeypatch.setattr(mc_run.mc, "job_key", lambda job: "k")
    out = tmp_path / "mc.jsonl"
    out.write_text('{"type": "header", "key": "k"}\n' + json.dumps({"type": "sample", "i": 0, "pass": False,
                                                                     **sample}) + "\n")
    if ok:
        assert mc_run.read_results(out, {})[0]["margin"] is None
    else:
        field = next(iter(sample))
        with pytest.raises(Mech2SpiceError, match=rf"line 2: not a Monte-Carlo results record \(\$\.{field}\b"):
            mc_run.read_results(out, {})


def test_install_robust_checks_the_block_as_params_will_load_it(tmp_path):
    from mech2spice.design import search
    block = json.loads(data.path("blocks", "robust.json").read_text())
    path = write(tmp_path / "b.json", json.dumps({**block, "levels": {"band0": [0, 0.995], "band1": [0.996, 1.1]}}))
    with pytest.raises(Mech2SpiceError, match="cannot drive itself"):
        search._check_self_drive(path, "classic")
    search._check_self_drive(write(tmp_path / "ok.json", json.dumps(block)), "classic")
