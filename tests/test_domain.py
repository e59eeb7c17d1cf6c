"""The operating domain (experiments/domain.py, `mech2spice domain`, `report domain`): the operating point
moves the model as it says, the maps find where designs work and fail, the command obeys the house rules."""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from mech2spice.errors import Mech2SpiceError
from mech2spice.experiments import domain
from mech2spice.experiments.domain import Point
from mech2spice.physics.params import load_params

REPO = Path(__file__).resolve().parent.parent
BLOCK = "centered_fc2"


def cli(*args):
    r = subprocess.run([sys.executable, "-m", "mech2spice.cli", *args], capture_output=True, text=True)
    return r.returncode, r.stdout, r.stderr


def test_sweeps_parse_and_refuse():
    assert domain.parse_sweep("freq=-1e-3:1e-3:3") == ("freq", [-1e-3, 0.0, 1e-3])
    assert domain.parse_sweep("drift=2e-4") == ("drift", [2e-4])
    x, y, fixed = domain.grid_axes(["amp=-0.1:0.1:5", "freq=-1e-3:1e-3:3", "drift=1e-4"])
    assert x[0] == "amp" and len(x[1]) == 5 and y[0] == "freq" and fixed == {"drift": 1e-4}
    for bad in (["temp=0:1:3", "freq=0:1:3"], ["freq=-1:1:3"], ["freq=0:1e-3:3"], ["freq=0:1e-3:3", "freq=0:1:2"],
                ["freq=0:1e-3:3", "amp=0:0.1:3", "drift=0:1e-3:3"], ["freq=0:1e-3:x", "amp=0:0.1:3"]):
        with pytest.raises(Mech2SpiceError):
            domain.grid_axes(bad)


def test_the_shifted_model_moves_only_what_the_point_says():
    from mech2spice import data
    from mech2spice.physics import network
    from mech2spice.synthesis import synth
    nl = synth.synthesize(str(data.verilog("adder2.v")))
    m = network.build(nl, load_params("default"))
    supply = domain.supply_drives(m)
    assert len(supply) == len(m.design.gates) and all(m.drives[k].name.endswith(".src") for k in supply)
    s = domain.shifted(m, Point(freq=1e-3, amp=0.1, drift=2e-3), supply)
    assert s.omega == pytest.approx(m.omega * 1.001)
    assert s.k_total == pytest.approx([k * 1.002 for k in m.k_total])
    assert [k for *_, k in s.springs] == pytest.approx([k * 1.002 for *_, k in m.springs])
    assert s.c_total == m.c_total and s.mass == m.mass and s.dashpots == m.dashpots
    for k, (a, b) in enumerate(zip(m.drives, s.drives)):
        assert b.amplitude == pytest.approx(a.amplitude * (1.1 if k in supply else 1.0))
    assert domain.shifted(m, Point(), supply).k_total == m.k_total     # the original is untouched
    with pytest.raises(Mech2SpiceError):
        Point(freq=1.5).validate()


def test_the_gate_works_nominally_fails_off_tune_and_a_retuned_drive_follows_a_drift():
    """A stiffness drift d moves every natural frequency by sqrt(1 + d): the gate fails at the drifted point
    and works again, with the nominal margin, when the drive follows (damping aside, the model scales)."""
    g = domain.GateDomain(load_params(BLOCK))
    nominal = g.evaluate(Point())
    assert nominal["pass"] and nominal["margin"] > 0.05
    assert not g.evaluate(Point(freq=1e-3))["pass"] and not g.evaluate(Point(amp=0.1))["pass"]
    drift = 2e-3
    assert not g.evaluate(Point(drift=drift))["pass"]
    retuned = g.evaluate(Point(drift=drift, freq=math.sqrt(1 + drift) - 1))
    assert retuned["pass"] and retuned["margin"] == pytest.approx(nominal["margin"], abs=0.01)


def test_gate_spread_samples_are_the_same_at_every_point():
    g = domain.GateDomain(load_params(BLOCK), sigma=0.01, samples=3, seed=7, trim="fc", residual=1e-4)
    a, b = g.evaluate(Point()), g.evaluate(Point())
    assert a["spread"] == b["spread"] and a["spread"]["samples"] == 3
    assert g.evaluate(Point(freq=1e-3))["spread"]["passed"] == 0


def test_the_adder_works_at_nominal_and_fails_at_a_higher_supply():
    from mech2spice import data
    from mech2spice.experiments.montecarlo import all_vectors
    from mech2spice.synthesis import synth
    nl = synth.synthesize(str(data.verilog("adder2.v")))
    d = domain.DesignDomain(nl, load_params(BLOCK), all_vectors(nl))
    assert d.evaluate(Point())["pass"]
    assert not d.evaluate(Point(amp=0.2))["pass"]


@pytest.mark.slow
def test_the_processor_runs_at_nominal_and_fails_off_tune():
    d = domain.CpuDomain(str(REPO / "programs" / "sieve.asm"), 3, load_params(BLOCK))
    assert d.evaluate(Point())["pass"]
    off = d.evaluate(Point(freq=-1e-3))
    assert not off["pass"] and "invalid" in off["reason"]


def test_domain_command_map_json_and_files(tmp_path):
    png = tmp_path / "map.png"
    rc, out, err = cli("domain", "gate", "--params", BLOCK, "--sweep", "freq=-1e-3:1e-3:3", "--sweep",
                       "amp=-0.1:0.1:2", "--json", "-o", str(png))
    assert rc == 0, err
    m = json.loads(out)
    assert (m["x"]["name"], m["y"]["name"], m["fixed"]) == ("freq", "amp", {"drift": 0.0})
    assert len(m["cells"]) == 2 and len(m["cells"][0]) == 3 and m["nominal_works"] is None   # 0 not on the amp axis
    assert png.read_bytes()[:4] == b"\x89PNG" and json.loads(png.with_suffix(".json").read_text())["cells"] == m["cells"]


def test_domain_command_refuses_in_one_line(tmp_path, capsys):
    from mech2spice.cli import main                 # in this process: eight refusals, not eight interpreters
    notes = tmp_path / "notes.png"
    notes.write_text("mine")
    for args, message in ((["gate", "--sweep", "freq=0:1e-3:2"], "exactly two axes"),
                          (["gate", "--sweep", "heat=0:1:2", "--sweep", "amp=0:0.1:2"], "NAME one of"),
                          (["gate", "--sweep", "freq=0:1e-3:2", "--sweep", "amp=0:0.1:2", "--samples", "3"],
                           "apply to --spread"),
                          (["gate", "--sweep", "freq=0:1e-3:2", "--sweep", "amp=0:0.1:2", "-o", str(notes)],
                           "not a PNG image"),
                          ([str(REPO / "verilog" / "counter4.v"), "--sweep", "freq=0:1e-3:2", "--sweep", "amp=0:0.1:2"],
                           "is clocked"),
                          # flags this kind of design has no use for were ignored, exit 0 (hostile-input pass)
                          (["gate", "--sweep", "freq=0:1e-3:2", "--sweep", "amp=0:0.1:2", "--top", "x"], "--top"),
                          (["gate", "--sweep", "freq=0:1e-3:2", "--sweep", "amp=0:0.1:2", "--backend", "rk4"],
                           "--backend applies"),
                          ([str(REPO / "verilog" / "adder2.v"), "--sweep", "freq=0:1e-3:2", "--sweep", "amp=0:0.1:2",
                            "--cycles", "5"], "--cycles applies")):
        rc = main(["domain", *args])
        err = capsys.readouterr().err
        assert rc == 2 and message in err and err.count("\n") == 1, (args, err)
    assert notes.read_text() == "mine"
