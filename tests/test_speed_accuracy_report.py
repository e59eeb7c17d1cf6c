"""speed_accuracy.md has one writer: the report itself, with the envelope-spice section rendered last."""
from __future__ import annotations

import json

from mech2spice.reports import envelope_spice, speed_accuracy

BLOCK = ("<!-- envelope-spice:begin -->\n## Envelope vs ngspice\n\n| a | b |\n|---|---|\n| 1 | 2 |\n\n"
         "text with  two spaces and a trailing space \n<!-- envelope-spice:end -->")


def test_envelope_section_is_written_last_and_the_old_file_is_not_kept(tmp_path, monkeypatch):
    monkeypatch.setattr(speed_accuracy, "markdown", lambda res: "# Speed vs accuracy\n\nnew body\n")
    md = tmp_path / "speed_accuracy.md"
    md.write_text("# old title\n\nold body\n\n" + BLOCK.replace("| 1 | 2 |", "| stale |") + "\n\n## after it\n")
    text = speed_accuracy.write_markdown(md, {"any": 1}, BLOCK)
    assert md.read_text() == text
    assert text == "# Speed vs accuracy\n\nnew body\n\n" + BLOCK + "\n"
    assert "old body" not in text and "stale" not in text and "after it" not in text
    assert speed_accuracy.write_markdown(md, {"any": 1}, BLOCK) == text          # idempotent


def test_no_envelope_results_no_section(tmp_path, monkeypatch):
    monkeypatch.setattr(speed_accuracy, "markdown", lambda res: "# Speed vs accuracy\n")
    assert envelope_spice.block(tmp_path) == ""                                    # no envelope_spice.json
    assert speed_accuracy.write_markdown(tmp_path / "s.md", {"any": 1}, "") == "# Speed vs accuracy\n"


def test_render_only_composes_both_results(tmp_path, monkeypatch):
    """--render measures nothing: both JSONs in, one .md out (charts stubbed)."""
    (tmp_path / "speed_accuracy.json").write_text(json.dumps({"body": "main"}))
    (tmp_path / "envelope_spice.json").write_text(json.dumps({"body": "env"}))
    monkeypatch.setattr(speed_accuracy, "charts", lambda res, out: [])
    monkeypatch.setattr(speed_accuracy, "markdown", lambda res: f"# {res['body']}\n")
    monkeypatch.setattr(envelope_spice, "charts", lambda res, out: "chart.png")
    monkeypatch.setattr(envelope_spice, "render", lambda res: f"{envelope_spice.BEGIN}\n{res['body']}\n"
                                                              f"{envelope_spice.END}\n")
    path = speed_accuracy.write(tmp_path, render=True)
    assert path.read_text() == f"# main\n\n{envelope_spice.BEGIN}\nenv\n{envelope_spice.END}\n"


def test_spice_md_states_the_form_choice_from_the_measurement(tmp_path):
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
