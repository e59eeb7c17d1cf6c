"""A non-editable install runs from any directory: the data the package reads at run time ships with it."""
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """`pip install .` (not editable) into a fresh virtual environment that sees this one's dependencies."""
    root = tmp_path_factory.mktemp("pkg")
    src = root / "src"
    shutil.copytree(REPO, src, ignore=shutil.ignore_patterns(".git", "__pycache__", "*.egg-info", "build", "reports",
                                                             ".pytest_cache", ".hypothesis"), symlinks=True)
    venv = root / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", str(venv)], check=True)
    pip = subprocess.run([venv / "bin" / "python", "-m", "pip", "install", "-q", "--no-deps",
                          str(src)], capture_output=True, text=True)
    assert pip.returncode == 0, pip.stderr[-2000:]
    shutil.rmtree(src)                               # nothing may be read from the source tree
    work = root / "elsewhere"
    work.mkdir()
    return venv / "bin" / "mech2spice", work


def run(installed, *args):
    exe, work = installed
    r = subprocess.run([str(exe), *args], capture_output=True, text=True, cwd=work)
    assert r.returncode in (0, 1), r.stderr
    return json.loads(r.stdout)


def test_installed_package_runs_the_adder_on_its_own_data(installed):
    exe, _ = installed
    verilog = exe.parent.parent / "lib"
    adder = next(verilog.rglob("mech2spice/data/verilog/adder2.v"))
    out = run(installed, "simulate", str(adder), "--set", "a=3", "--set", "b=2", "--backend", "envelope", "--json")
    assert out["outputs"] == {"s": 5} and out["valid"]


def test_installed_package_runs_the_processor_and_the_gate(installed):
    exe, _ = installed
    sieve = next((exe.parent.parent / "lib").rglob("mech2spice/data/programs/sieve.asm"))
    out = run(installed, "cpu", "run", str(sieve), "--backend", "iss", "--json")
    assert out["halted"] and out["cycles"] == 457
    gate = run(installed, "gate", "--quick", "--json")
    assert gate["switches"] and [r["logic"] for r in gate["truth_table"]] == [1, 0, 0, 0]


def test_installed_package_reads_its_shipped_blocks(installed):
    exe, _ = installed
    adder = next((exe.parent.parent / "lib").rglob("mech2spice/data/verilog/adder2.v"))
    out = run(installed, "simulate", str(adder), "--set", "a=1", "--set", "b=2", "--backend", "envelope",
              "--params", "robust", "--json")
    assert out["outputs"] == {"s": 3} and out["valid"]
