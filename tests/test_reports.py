"""The report registry and `mech2spice report`: every report is importable and listed, errors are one line."""
from __future__ import annotations

import inspect
import json
import subprocess
import sys

import pytest

from mech2spice import reports
from mech2spice.reports import cli as report_cli


def _cli(*args, cwd):
    return subprocess.run([sys.executable, "-m", "mech2spice.cli", *args], capture_output=True, text=True,
                          cwd=cwd, timeout=120)


@pytest.mark.parametrize("name", list(reports.REPORTS))
def test_every_report_imports_and_takes_its_declared_options(name):
    write = reports.module(name).write
    params = inspect.signature(write).parameters
    assert list(params)[0] == "directory" and write.__doc__
    assert set(reports.REPORTS[name].options) <= set(params)
    known = {dest for _, dest, _ in report_cli.OPTIONS}
    assert set(reports.REPORTS[name].options) <= known


def test_one_writer_per_file():
    written = [f for r in reports.REPORTS.values() for f in r.writes]
    assert len(written) == len(set(written))


def test_list_json_names_every_report(tmp_path):
    r = _cli("report", "--list", "--json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    listed = json.loads(r.stdout)
    assert [x["name"] for x in listed] == list(reports.REPORTS)
    assert all(x["description"] and x["cost"].startswith("~") for x in listed)


@pytest.mark.parametrize("args, message", [(("nosuch",), "unknown report nosuch"),
                                           (("adder", "--quick"), "report adder takes no --quick"),
                                           ((), "name a report"),
                                           # it wrote cpu_physical_failed.md, then exit 2 (hostile-input pass)
                                           (("cpu_physical", "--cycles", "-1"), "--cycles: must be from 0"),
                                           (("cpu_physical", "--step", "nan"), "--step: must be a finite")])
def test_usage_errors_are_one_line_and_exit_2(tmp_path, args, message):
    r = _cli("report", *args, "--out", str(tmp_path / "out"), cwd=tmp_path)
    assert r.returncode == 2
    assert r.stdout == ""
    assert r.stderr.count("\n") == 1 and message in r.stderr
    assert not (tmp_path / "out").exists()


def test_unknown_section_is_a_user_error(tmp_path):
    r = _cli("report", "fidelity", "--only", "nosuch", "--out", str(tmp_path), cwd=tmp_path)
    last = r.stderr.splitlines()[-1]         # after the progress line naming the report
    assert r.returncode == 2 and last.startswith("mech2spice: error: fidelity: unknown section nosuch")
