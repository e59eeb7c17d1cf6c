"""The processor's reports measure once into JSON and render anywhere (issue #28): `--render` from the JSON a
measuring run wrote gives that run's markdown and figures, byte for byte, in another folder."""
from __future__ import annotations

import json
import shutil

from mech2spice import reports


def _render_elsewhere(name: str, measured, elsewhere, files: list[str], json_name: str) -> None:
    """Copy the study's JSON to `elsewhere`, render there, and compare every file with the measuring run's."""
    elsewhere.mkdir()
    shutil.copy(measured / json_name, elsewhere / json_name)
    reports.module(name).write(elsewhere, render=True)
    for f in files:
        assert (elsewhere / f).read_bytes() == (measured / f).read_bytes(), f


def test_cpu_renders_its_measurement(tmp_path):
    measured = tmp_path / "measured"
    reports.module("cpu").write(measured, skip_slow=True)            # ~6 s: no logic-level Minsky run
    md = (measured / "cpu.md").read_text()
    assert "| ISS | 457 | True |" in md and "| logic level (synthesized NOR netlist) | 457 | True |" in md
    assert "not run (--skip-slow)" in md and "Not run yet: `mech2spice report cpu_physical`" in md
    _render_elsewhere("cpu", measured, tmp_path / "rendered", ["cpu.md", "cpu_sieve.png", "cpu_trace.png",
                                                                "cpu_tm.png"], "cpu.json")


def test_cpu_physical_renders_its_measurement(tmp_path):
    measured = tmp_path / "measured"
    reports.module("cpu_physical").write(measured, cycles=3)          # 6486 oscillators, envelope, 3 cycles
    res = json.loads((measured / "cpu_physical.json").read_text())
    assert [r["cycle"] for r in res["rows"]] == [0, 1, 2] and all(r["same"] for r in res["rows"])
    assert res["options"]["cycles"] == 3 and not res["halted"] and res["moments"] == []
    md = (measured / "cpu_physical.md").read_text()
    assert "did not halt after 3 cycles**" in md and "every cycle identical to the ISS;" in md
    _render_elsewhere("cpu_physical", measured, tmp_path / "rendered", ["cpu_physical.md", "cpu_physical_trace.png"],
                      "cpu_physical.json")
