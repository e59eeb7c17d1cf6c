"""`mech2spice design` (design/search.py): the objective's constraints, and resuming from the checkpoint."""
import json

import numpy as np
import pytest

from mech2spice.design import grammar, search
from mech2spice.errors import Mech2SpiceError

TINY = {"sigma": 0.01, "samples": 2, "seed": 0, "maxiter": 1, "popsize": 2, "budget_s": 1.0, "tol_samples": 100}


def test_objective_scores_failing_gates_below_passing_ones():
    obj = search.Objective(grammar.Structure("classic"), 4, 0)
    good = obj.score(grammar.x_default("classic"))           # the default gate: tolerance ~1e-6
    x = grammar.x_default("classic").copy()
    x[list(grammar.CORE).index("lf_c")] = 1.0                # 7.5x the source force: '1' far above its band
    bad = obj.score(x)
    assert -7 < good < -4.5                                  # log10 of its estimated tolerance
    assert bad <= search.FAIL_OFFSET < good


def test_design_resumes_without_redoing_a_finished_structure(tmp_path, monkeypatch):
    out = tmp_path / "design.json"
    first = search.run(["spring_only"], out, TINY)
    assert not list(tmp_path.glob("*.tmp"))                  # written through tmp + os.replace
    saved = json.loads(out.read_text())
    assert saved["structures"]["spring_only"]["search"]["evaluations"] > 0

    def boom(*a, **k):
        raise AssertionError("a finished structure was searched again")
    monkeypatch.setattr(search, "search_structure", boom)
    again = search.run(["spring_only"], out, TINY)
    assert again["structures"]["spring_only"] == first["structures"]["spring_only"]
    with pytest.raises(AssertionError):                      # other settings: searched afresh
        search.run(["spring_only"], out, {**TINY, "seed": 1})


def test_unknown_structure_is_one_line():
    with pytest.raises(Mech2SpiceError, match="unknown structure"):
        search.run(["triangle"], None, TINY)


def _record(tolerance, margin=0.02, budget=200.0, **settings):
    """A complete search record of one structure as `mech2spice design` writes it (every field the command
    reads: search.ENTRY_FIELDS; the block file a valid block, which read_record checks as --params does)."""
    from mech2spice import data
    block = json.loads(data.path("blocks", "classic.json").read_text())
    rec = {"structure": "classic", "score": -5.0, "parameters": {}, "block_file": block,
           "measured": {"nominal_margin": margin, "tolerance": tolerance, "tolerance_bracket": [tolerance, tolerance],
                        "yield": 1.0, "margin_quantiles": {"1%": margin}, "dofs_per_gate": 6},
           "search": {"budget_s": budget, "generations": 1, "evaluations": 10, "wall_s": budget}}
    return {"settings": {**TINY, **settings}, "structures": {"classic": rec}}


def test_merge_keeps_the_larger_tolerance_and_lists_every_run(tmp_path):
    out, worse, better = tmp_path / "out.json", tmp_path / "worse.json", tmp_path / "better.json"
    out.write_text(json.dumps(_record(2e-6)))
    worse.write_text(json.dumps(_record(1e-6, budget=900.0)))
    better.write_text(json.dumps(_record(3e-6, budget=900.0)))
    kept = search.merge(out, [worse])["structures"]["classic"]
    assert kept["measured"]["tolerance"] == 2e-6 and kept["source"] == str(out)
    won = search.merge(out, [better])["structures"]["classic"]
    assert won["measured"]["tolerance"] == 3e-6 and won["source"] == str(better)
    assert [r["tolerance"] for r in won["runs"]] == [2e-6, 1e-6, 3e-6]
    assert json.loads(out.read_text())["structures"]["classic"]["search"]["budget_s"] == 900.0


def test_merge_refuses_tolerances_from_another_bisection(tmp_path):
    out, other = tmp_path / "out.json", tmp_path / "other.json"
    out.write_text(json.dumps(_record(2e-6)))
    other.write_text(json.dumps(_record(3e-6, tol_samples=1000)))
    with pytest.raises(Mech2SpiceError, match="tol_samples"):
        search.merge(out, [other])
