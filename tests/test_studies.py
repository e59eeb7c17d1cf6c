"""Studies measure, reports render: reports/ imports no engine, netlist or simulation module, and what a report
states about a study's settings is the study's."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

from mech2spice.errors import Mech2SpiceError
from mech2spice.studies import _common

PACKAGE = Path(__file__).resolve().parent.parent / "mech2spice"
FORBIDDEN = ("backends", "spice", "simulation",                          # the engines and netlists
             "experiments", "cpu.run", "cpu.physical", "cpu.circuit", "cpu.machines")   # what runs them
# Report modules that still measure as well as render (issue #28: to move into studies/).  The list may only
# shrink: a module that no longer needs its entry fails test_not_yet_split_list_is_current.
NOT_YET_SPLIT: set[str] = set()


def _imported(path: Path, package: str = "reports") -> set[str]:
    """Every module `path` imports (relative imports resolved against mech2spice.PACKAGE), at any depth."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = "mech2spice" if node.level == 2 else f"mech2spice.{package}" if node.level == 1 else ""
            mod = ".".join(p for p in (base, node.module or "") if p)
            out |= {mod} | {f"{mod}.{a.name}" for a in node.names}
    return out


def _engine_imports(path: Path) -> list[str]:
    return sorted(m for m in _imported(path)
                  if any(m == f"mech2spice.{f}" or m.startswith(f"mech2spice.{f}.") for f in FORBIDDEN))


def _report_modules():
    return sorted(p for p in (PACKAGE / "reports").glob("*.py"))


@pytest.mark.parametrize("path", _report_modules(), ids=lambda p: p.stem)
def test_reports_import_no_engine(path):
    if path.stem in NOT_YET_SPLIT:
        pytest.skip(f"reports/{path.name} still measures (issue #28)")
    assert _engine_imports(path) == []


def test_not_yet_split_list_is_current():
    still = {p.stem for p in _report_modules() if _engine_imports(p)}
    assert still == NOT_YET_SPLIT


def test_the_scan_sees_relative_and_absolute_imports(tmp_path):
    f = tmp_path / "x.py"
    f.write_text("from ..backends import rk4\nimport mech2spice.simulation\nfrom ..spice.carrier import emit\n"
                 "from ._common import md_table\n")
    assert _engine_imports(f) == ["mech2spice.backends", "mech2spice.backends.rk4", "mech2spice.simulation",
                                  "mech2spice.spice.carrier", "mech2spice.spice.carrier.emit"]


def test_carrier_report_states_the_study_criteria():
    from mech2spice.reports import carrier as report
    from mech2spice.studies import carrier as study
    for name in ("AMP_TOL", "PHASE_TOL", "FAIL_UR", "FINE_STEPS", "REDUCED_TOL"):
        assert getattr(report, name) == getattr(study, name), name


def test_speed_accuracy_records_the_settings_its_report_states():
    from mech2spice.studies import speed_accuracy as study
    assert study.settings() == {"ref_steps": study.REF_STEPS, "reltols": study.RELTOLS, "q_true": study.Q_TRUE,
                                "scaling_periods": study.SCALING_PERIODS}


def test_sections_keep_order_and_refuse_unknown_names():
    assert _common.sections("s", ["b", "a"], ("a", "b", "c")) == ["b", "a"]
    assert _common.sections("s", None, ("a", "b")) == ["a", "b"]
    with pytest.raises(Mech2SpiceError, match=r"s: unknown section z \(choose from a, b\)"):
        _common.sections("s", ["z"], ("a", "b"))


def test_conditions_record_machine_load_and_versions():
    c = _common.conditions()
    assert "cores" in c["machine"] and len(c["load_avg"]) == 3 and c["versions"]["numpy"]


@pytest.mark.parametrize("name", ["gate", "spice", "cpu", "cpu_physical", "fidelity", "robustness", "design", "envelope",
                                  "domain"])
def test_render_without_its_json_is_one_line(capsys, tmp_path, name):
    from cli_helpers import run
    rc, _, err = run(capsys, "report", name, "--render", "--out", str(tmp_path))
    last = err.strip().splitlines()[-1]          # after the report's progress line
    assert rc == 2 and "Traceback" not in err and f"{name}.json does not exist" in last, err



@pytest.mark.parametrize("path", sorted((PACKAGE / "studies").glob("*.py")), ids=lambda p: p.stem)
def test_studies_import_no_report(path):
    """Measuring never needs a renderer: the JSON is the only link."""
    assert not [m for m in _imported(path, "studies") if m.startswith("mech2spice.reports")]


def test_performance_report_draws_the_study_backends_and_its_clock():
    from mech2spice import simulation
    from mech2spice.reports import performance as report
    from mech2spice.studies import performance as study
    assert report.BACKENDS == tuple(study.PLAN)
    clock = {"latch_min_pulse": simulation.LATCH_MIN_PULSE, "latch_output_delay": simulation.LATCH_OUTPUT_DELAY,
             "gate_delay_max": simulation.GATE_DELAY_MAX, "settle_margin": simulation.SETTLE_MARGIN}
    nl_free = report._clocked_periods(clock, 3, 10)
    assert nl_free["periods_per_cycle"] == nl_free["pulse"] + nl_free["pause"]
    assert nl_free["total_periods"] == nl_free["pause"] + 10 * nl_free["periods_per_cycle"]


REPORTS_DIR = PACKAGE.parent / "reports"


@pytest.mark.parametrize("name, inputs, outputs, options", [
    ("gate", ["gate.json"], ["gate.md"], {}),
    ("adder", ["adder.json"], ["adder.md"], {}),
    ("sequential", ["sequential.json"], ["sequential.md", "sqrt.md"], {}),
    ("spice", ["spice.json", "speed_accuracy.json"], ["spice.md"], {}),
    ("envelope", ["envelope.json"], ["envelope.md"], {}),
    ("cpu_circuit", ["cpu_circuit.json"], ["cpu_circuit.md"], {}),
    ("cpu", ["cpu.json", "cpu_physical.json", "cpu_physical_tm_increment.json"], ["cpu.md"], {}),
    ("cpu_physical", ["cpu_physical.json", "fidelity.json"], ["cpu_physical.md"], {}),
    ("cpu_physical", ["cpu_physical_tm_increment.json", "fidelity.json"], ["cpu_physical_tm_increment.md"],
     {"name": "cpu_physical_tm_increment"}),
    ("speed_accuracy", ["speed_accuracy.json", "envelope_spice.json", "vacask.json", "carrier.json"],
     ["speed_accuracy.md"], {}),
    ("fidelity", ["fidelity.json", "carrier.json"], ["fidelity.md"], {}),
    ("robustness", ["robustness.json"], ["robustness.md"], {}),
    ("performance", ["performance.json", "cpu_physical.json", "carrier.json"], ["performance.md"], {}),
    ("carrier", ["carrier.json"], ["carrier.md"], {}),
    ("design", ["design.json"], ["design.md"], {"search": str(REPORTS_DIR / "design_search.json")}),
    ("domain", ["domain.json"], ["domain.md"], {}),
])
def test_render_rebuilds_the_checked_in_report_from_its_json(tmp_path, name, inputs, outputs, options):
    """`--render` from the stored JSON alone gives the checked-in markdown, byte for byte."""
    import shutil
    from mech2spice import reports
    for f in inputs:
        shutil.copy(REPORTS_DIR / f, tmp_path / f)
    reports.module(name).write(tmp_path, render=True, **options)
    assert [f.read_text() for f in sorted(tmp_path.glob("*.json"))] == \
        [(REPORTS_DIR / f.name).read_text() for f in sorted(tmp_path.glob("*.json"))], "rendering wrote a JSON"
    for f in outputs:
        assert (tmp_path / f).read_text() == (REPORTS_DIR / f).read_text(), f


def _without(d, key):
    """`d` with every entry named `key` removed, at any depth."""
    if isinstance(d, dict):
        return {k: _without(v, key) for k, v in d.items() if k != key}
    return [_without(v, key) for v in d] if isinstance(d, list) else d


def test_cpu_physical_render_refuses_a_json_without_its_rows(capsys, tmp_path):
    """A cpu_physical.json written before the study kept its per-cycle rows: --render says to measure again."""
    import json
    from cli_helpers import run
    old = _without(json.loads((REPORTS_DIR / "cpu_physical.json").read_text()), "rows")
    (tmp_path / "cpu_physical.json").write_text(json.dumps(old))
    rc, _, err = run(capsys, "report", "cpu_physical", "--render", "--out", str(tmp_path))
    last = err.strip().splitlines()[-1]
    assert rc == 2 and "Traceback" not in err and "has no per-cycle rows" in last, err
    assert not (tmp_path / "cpu_physical.md").exists()


def test_cpu_circuit_unknown_section_is_one_line_before_measuring(capsys, tmp_path):
    from cli_helpers import run
    rc, _, err = run(capsys, "report", "cpu_circuit", "--only", "nosuch", "--out", str(tmp_path))
    last = err.strip().splitlines()[-1]
    assert rc == 2 and "cpu_circuit: unknown section nosuch" in last, err
    assert not (tmp_path / "cpu_circuit.json").exists()


def test_envelope_json_round_trips_what_json_cannot_key_or_hold():
    """The envelope study's steps and periods as keys, complex eigenvalues and trace arrays come back as the
    renderer reads them; traces keep about one sample per `every` periods inside their window."""
    import json
    import numpy as np
    from mech2spice.reports.envelope import loaded
    from mech2spice.studies.envelope import _sweep_json, _trace
    tr = _trace(np.arange(100) + 0.5, np.arange(300.0).reshape(100, 3, 1) / 7, 8, window=(10, 50))
    assert list(tr["t"]) == [10.5, 18.5, 26.5, 34.5, 42.5] and tr["amp"].shape == (5, 3, 1)
    sw = _sweep_json({"sweep": [{"vs80": {"amp_err": 1.0, "crossings": [1]}}], "free": [{"finite": False}],
                      "eigs_worst": np.array([1 + 2j, -3j]), "two_omega": {5800: {"x": 1.5}}})
    assert sw["sweep"] == [{"vs80": {"amp_err": 1.0}}]
    d = loaded(json.loads(json.dumps({"scenes": [{"env": {"4": {}, "0.5": {}}}], "sweep": sw,
                                      "traces": {"adder2": {"rk4_80": tr}}}, default=_common.json_default)))
    assert list(d["scenes"][0]["env"]) == [4.0, 0.5] and d["sweep"]["two_omega"] == {5800: {"x": 1.5}}
    assert list(d["sweep"]["eigs_worst"]) == [1 + 2j, -3j]
    assert np.array_equal(d["traces"]["adder2"]["rk4_80"]["amp"], tr["amp"])
