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
