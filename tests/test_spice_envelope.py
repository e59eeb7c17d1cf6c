"""ngspice on the envelope equations (spice_envelope.py): signs against closed forms, the netlist's names,
agreement with envelope.integrate on the NOR gate, and the adder through `simulate`."""
from __future__ import annotations

import json
from pathlib import Path
import re
import shutil
import subprocess
import sys

import numpy as np
import pytest
import scipy.linalg as sl

from mech2spice import simulation
from mech2spice.physics import nor
from mech2spice.backends import envelope
from mech2spice.synthesis import synth
from mech2spice.spice import envelope_netlist as se
from mech2spice.spice import failure
from mech2spice.experiments import clocking
from mech2spice.experiments import scenes as S
from mech2spice.errors import DivergenceError, Mech2SpiceError
from mech2spice.physics.model import MechModel
from mech2spice.physics.params import DEFAULT as P
from mech2spice.physics.stimulus import Stimulus

REPO = Path(__file__).resolve().parent.parent

needs_ngspice = pytest.mark.skipif(shutil.which("ngspice") is None, reason="ngspice not installed")
pytestmark = [pytest.mark.ngspice, needs_ngspice]


def exact_linear(model: MechModel, amps: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Closed-form envelope of a linear model from rest: B A' = F - Z0 A."""
    env = envelope.Envelope(model)
    B, Z = env.Bop.toarray(), env.Z0.toarray()
    F = env.forcing(amps)[:, 0]
    L, Ainf = -np.linalg.solve(B, Z), np.linalg.solve(Z, F)
    return np.array([Ainf - sl.expm(L * x) @ Ainf for x in t])


def test_single_oscillator_matches_closed_form():
    """Sign check: one driven damped oscillator, A(t) = F/Z (1 - exp(-Z t / b))."""
    w = 3.0
    m = MechModel(omega=w)
    i = m.add_dof("osc", 1.0, 9.3, 0.05)
    m.add_drive(i, 0.7, 0.3, "drive")
    m.add_probe("osc", i)
    run = se.run_envelope_spice(m, 200, opts=se.EnvelopeSpiceOptions(max_step_periods=0.05))
    F, Z, b = -0.7j * np.exp(0.3j), 9.3 - w * w + 1j * w * 0.05, 2j * w + 0.05
    want = F / Z * (1 - np.exp(-Z / b * run.t_end))
    got = run.amp[:, 0, 0]
    assert np.abs(got - want).max() < 1e-3 * np.abs(want).max()
    assert np.angle(got[-1] / want[-1]) == pytest.approx(0, abs=1e-3)


def test_dashpot_coupled_dofs_match_closed_form():
    """Fast-fast dashpots are the derivative couplings (sense sources + CCCS); springs, a second mass,
    two drives with phases."""
    m = MechModel(omega=3.0)
    a, b, c = m.add_dof("a", 1.0, 9.5, 0.5), m.add_dof("b", 1.0, 9.5, 0.5), m.add_dof("c", 2.0, 18.5, 0.3)
    m.add_spring(a, b, 6.0)
    m.add_dashpot(a, b, 0.3)
    m.add_dashpot(b, c, 0.2)
    m.add_drive(a, 0.7, 0.3, "d1")
    m.add_drive(c, 0.2, 1.0, "d2")
    for n, i in (("a", a), ("b", b), ("c", c)):
        m.add_probe(n, i)
    run = se.run_envelope_spice(m, 100, opts=se.EnvelopeSpiceOptions(max_step_periods=0.01))
    want = exact_linear(m, np.array([0.7, 0.2]), run.t_end)
    assert np.abs(run.amp[:, :, 0] - want).max() < 3e-4 * np.abs(want).max()


def test_netlist_names_sanitised_and_ngspice_reads_it(tmp_path):
    """Odd DOF and drive names, a slow DOF with a quadratic coupling and a scheduled drive: every node
    is [a-z0-9_], and ngspice runs the netlist standalone (exit 0, no error line)."""
    m = MechModel(omega=P.omega, params=P)
    f = m.add_dof("Gate 1.C/out", P.m_c, P.k_c, P.c_c)
    g = m.add_dof("2nd gate (in)", P.m_g, P.k_g, P.c_g)
    s = m.add_dof("Ins-ulator#1", P.m_i, P.k_i, P.c_i, slow=True)
    m.add_quad(f, s, -P.gamma_ic)
    m.add_quad(g, s, P.gamma_ig)
    m.add_spring(f, g, P.k_couple)
    m.add_dashpot(f, g, P.c_couple)
    m.add_drive(f, P.f_c, 0.0, "SRC: main")
    d = m.add_drive(g, 0.3, 1.2, "in put")
    m.add_probe("Out.Put", f)
    st = Stimulus.from_levels(m, [(0.0, {}), (50 * P.period, {d: 0.6})])
    text = se.emit_envelope(m, st, 120)
    cards = [ln for ln in text.splitlines() if ln and ln[0] not in "*.+"]
    for ln in cards:
        head = ln.split("=")[0].split()
        nodes = head[1:3] if ln[0] in "CGFVB" else []
        for node in nodes:
            assert re.fullmatch(r"[a-z0-9_]+", node), ln
    for v in re.findall(r"V\(([^)]*)\)", "\n".join(cards)):
        assert re.fullmatch(r"[a-z0-9_]+", v), v
    assert any(ln.startswith("F") for ln in cards)          # the dashpot's derivative coupling
    assert any("tanh" in ln for ln in cards)                 # the scheduled drive
    cir = tmp_path / "env.cir"
    cir.write_text(text, encoding="ascii")
    r = subprocess.run(["ngspice", "-b", "-n", str(cir)], capture_output=True, text=True, cwd=tmp_path)
    # exit 1: the probe's amplitude is in no band (the .control block's verdict), not an ngspice failure
    assert r.returncode == 1, r.stderr[-500:]
    assert re.search(r"^Out\?Put = [0-9.]+ u_R -> invalid$", r.stdout, re.M), r.stdout[-500:]
    assert not re.search(r"^\s*error|timestep too small", r.stdout + r.stderr, re.I | re.M)
    run = se.run_envelope_spice(m, 120, st)
    assert run.amp.shape == (120, 1, 1) and np.all(np.isfinite(run.amp))


def test_gate_four_pairs_agree_with_envelope_integrate():
    """The gate's 4 nominal input pairs from rest, 2500 periods: settled amplitudes within 0.01 u_R of
    envelope.integrate (step 1/4 period, converged), the whole trajectory within 0.02 u_R."""
    sc = S.gate_scene(P, "nominal")
    ref = envelope.integrate(sc.model, sc.periods, step_periods=0.25, stimulus=sc.stimulus, probes=sc.probes)
    run = se.run_envelope_spice(sc.model, sc.periods, sc.stimulus)
    a, r = np.abs(run.amp) / P.u_r, np.abs(ref.amp) / P.u_r
    settled = np.abs(a[-20:].mean(axis=0) - r[-20:].mean(axis=0))
    assert settled.max() < 0.01, settled
    assert np.abs(a - r).max() < 0.02
    assert run.extra["backend"] == "ngspice-envelope" and len(run.extra["wall_s"]) == 4


def test_adder_3_plus_2_through_simulate():
    nl = synth.synthesize(str(REPO / "verilog" / "adder2.v"))
    res = simulation.run_physical(nl, P, [{"a": 3, "b": 2}], backend="ngspice-envelope")[0]
    assert res["outputs"] == {"s": 5} and res["valid"], res
    assert res["backend"] == "ngspice-envelope" and res["periods"] == clocking.period_budget(nl)


def test_cli_simulate_ngspice_envelope_json():
    r = subprocess.run([sys.executable, "-m", "mech2spice.cli", "simulate", str(REPO / "verilog" / "adder2.v"), "--set", "a=1",
                        "--set", "b=1", "--backend", "ngspice-envelope", "--max-step", "4", "--json"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["outputs"] == {"s": 2} and d["valid"]
    assert d["ngspice_options"]["max_step_periods"] == 4 and d["ngspice_options"]["method"] == "trap"


def test_options_are_validated():
    with pytest.raises(Mech2SpiceError, match="method"):
        se.emit_envelope(nor.single_gate(P), None, 10, se.EnvelopeSpiceOptions(method="euler"))
    with pytest.raises(Mech2SpiceError, match="max_step"):
        se.EnvelopeSpiceOptions(max_step_periods=0).validate()


def test_timestep_failure_names_the_dof():
    m = nor.single_gate(P)
    err = Mech2SpiceError('ngspice failed (exit 1): doAnalyses: TRAN:  Timestep too small; time = 12.5, '
                          'timestep = 1e-13: trouble with node "ar_g0_g1s"')
    out = failure(m, err, lambda names, data: None, se.NODE_PREFIXES)
    assert isinstance(out, DivergenceError) and out.dof == "g0.G1s"
