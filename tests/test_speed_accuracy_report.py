"""benchmarks/speed_accuracy.py's markdown writer keeps the envelope-spice section another tool writes."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("speed_accuracy_bench", ROOT / "benchmarks" / "speed_accuracy.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


BLOCK = ("<!-- envelope-spice:begin -->\n## Envelope vs ngspice\n\n| a | b |\n|---|---|\n| 1 | 2 |\n\n"
         "text with  two spaces and a trailing space \n<!-- envelope-spice:end -->")


def test_block_is_carried_over_verbatim_at_the_end(bench, tmp_path, monkeypatch):
    monkeypatch.setattr(bench, "markdown", lambda res: "# Speed vs accuracy\n\nnew body\n")
    md = tmp_path / "speed_accuracy.md"
    md.write_text("# old title\n\nold body\n\n" + BLOCK + "\n\n## a section after it\n")
    text = bench.write_markdown(md, {})
    assert md.read_text() == text
    assert text.startswith("# Speed vs accuracy\n\nnew body\n")
    assert "old body" not in text and "a section after it" not in text
    assert text.endswith(BLOCK + "\n")
    assert text.count("<!-- envelope-spice:begin -->") == 1
    # idempotent: regenerating again keeps exactly one copy
    assert bench.write_markdown(md, {}) == text


def test_no_markers_no_block(bench, tmp_path, monkeypatch):
    monkeypatch.setattr(bench, "markdown", lambda res: "# Speed vs accuracy\n")
    md = tmp_path / "speed_accuracy.md"
    assert bench.write_markdown(md, {}) == "# Speed vs accuracy\n"          # no file yet
    md.write_text("# old\n<!-- envelope-spice:begin -->\nunterminated\n")
    assert "envelope-spice" not in bench.write_markdown(md, {})           # no end marker: nothing carried


def test_spice_md_states_the_form_choice_from_the_measurement(tmp_path):
    import json

    from mech2spice.reports.spice import UNMEASURED_WHY, why_this_form
    assert why_this_form(tmp_path / "missing.json") == UNMEASURED_WHY
    row = {"amp_err_ur": 1e-4, "phase_err_deg": 0.05, "traj_err_ur": 0.006, "uniform_fraction": 1.0}
    forms = {"nor_gate": {"periods": 2500, "cases": 4, "options": {"method": "trap", "max_step_periods": 0.025,
                                                                    "reltol": 1e-5},
                          "rows": [{"form": "mobility, VCCS springs (package)", "cpu_s": 10.0, "equations": 19,
                                    "cpus": [10.0, 10.5], **row},
                                   {"form": "impedance (force-voltage)", "cpu_s": 16.0, "equations": 63, **row},
                                   {"form": "mobility, inductor springs", "cpu_s": 10.2, "equations": 29, **row}]}}
    path = tmp_path / "speed_accuracy.json"
    path.write_text(json.dumps({"machine": "test box", "forms": forms}))
    text = " ".join(why_this_form(path).split())          # wrapped at 104 columns
    assert "1.60x on nor_gate (63 circuit equations against 19)" in text
    assert "no alternative was faster" in text and "fewest circuit equations" in text
    forms["nor_gate"]["rows"][2]["cpu_s"] = 7.0
    path.write_text(json.dumps({"machine": "test box", "forms": forms}))
    assert "an alternative was faster" in " ".join(why_this_form(path).split())
