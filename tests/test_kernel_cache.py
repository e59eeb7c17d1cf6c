"""The compiled kernels are compiled once per machine (issue 26): a process after the first loads every
kernel from numba's on-disk cache and writes nothing to it.

Each test copies the package to a temporary folder, so it owns a fresh cache (mech2spice/backends/
__pycache__), and runs separate processes: within one process numba never reads its cache back.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("numba")

PACKAGE = Path(__file__).resolve().parents[1] / "mech2spice"
ENVELOPE_KERNELS = {"_envelope_kernel.run_steps", "_envelope_latency.run_latent"}
ALL_KERNELS = ENVELOPE_KERNELS | {"_rk4_kernel.run_periods", "_carrier_kernel.run_periods",
                                  "_carrier_latency.run_periods"}


def _fresh_copy(tmp_path: Path) -> Path:
    shutil.copytree(PACKAGE, tmp_path / "mech2spice", ignore=shutil.ignore_patterns("__pycache__"))
    return tmp_path


def _cache(root: Path) -> tuple[int, int]:
    """(bytes, files) of numba's cache files (index .nbi, data .nbc) in the copy."""
    files = list((root / "mech2spice" / "backends" / "__pycache__").glob("*.nb[ic]"))
    return sum(f.stat().st_size for f in files), len(files)


def _run(root: Path, index: int, engines: list[str]) -> dict:
    """One process of kernel_cache's exercise; its report with the cache's size after it."""
    env = {n: v for n, v in os.environ.items() if not n.startswith("NUMBA_")}    # the copy's own cache
    env["PYTHONPATH"] = str(root)
    out = root / f"stats{index}.json"
    p = subprocess.run([sys.executable, "-m", "mech2spice.backends.kernel_cache", "--out", str(out), *engines],
                       cwd=root, env=env, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-2000:]
    report = json.loads(out.read_text())
    report["cache"] = _cache(root)
    return report


def _check(reports: list[dict], kernels: set[str]) -> None:
    first, later = reports[0], reports[1:]
    assert first["compiled"] > 0, "the first process found a cache: the test does not own a fresh one"
    for r in reports:
        assert r["function_arguments"] == [], f"a cached kernel takes a compiled function: {r['function_arguments']}"
        assert kernels <= set(r["kernels"]), f"kernels not run: {kernels - set(r['kernels'])}"
    for k, r in enumerate(later, 2):
        missed = {n: s for n, s in r["kernels"].items() if s["compiled"]}
        assert not missed, f"process {k} compiled {missed}"
        assert all(s["loaded"] for s in r["kernels"].values()), r["kernels"]
        assert r["cache"] == first["cache"], f"process {k}: cache (bytes, files) {first['cache']} -> {r['cache']}"


def test_envelope_kernels_compiled_once(tmp_path):
    """Three processes of every compiled envelope path: the second and third compile nothing."""
    root = _fresh_copy(tmp_path)
    _check([_run(root, k, ["envelope"]) for k in range(3)], ENVELOPE_KERNELS)


@pytest.mark.slow
def test_every_kernel_compiled_once_in_many_processes(tmp_path):
    """Envelope, RK4 and carrier kernels in six processes: only the first compiles, the cache stays put."""
    root = _fresh_copy(tmp_path)
    _check([_run(root, k, ["envelope", "rk4", "carrier"]) for k in range(6)], ALL_KERNELS)
