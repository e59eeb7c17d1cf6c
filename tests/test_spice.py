"""ngspice backend: library, netlists, agreement with RK4, names, failures.

The fast set (no `slow` mark) takes about a minute on a 2-core machine: RK4 references are computed
once per module and ngspice runs two processes at a time.
"""
from __future__ import annotations

import functools
import math
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from mech2spice.spice import runner as ngspice
from mech2spice.physics import nor
from mech2spice.backends import rk4
from mech2spice.compare import agreement, settled
from mech2spice.backends import Run
from mech2spice.errors import DivergenceError, Mech2SpiceError, ToolMissingError
from mech2spice.experiments import scenes
from mech2spice.physics.model import MechModel
from mech2spice.physics.params import DEFAULT, NOMINAL0, NOMINAL1
from mech2spice.spice import Namer
from mech2spice.spice.oscillator_netlist import SpiceOptions, emit, emit_with_probes, subckt_library, write_subckt_library
from mech2spice.physics.stimulus import Stimulus

ROOT = Path(__file__).resolve().parent.parent
P = DEFAULT
U_R = P.u_r
AMP_TOL = 0.01          # u_R
PHASE_TOL = 2.0         # degrees
LEVEL_PAIRS = scenes.nominal_levels()   # the truth table's input pairs as drive levels (fraction of F_R)
PERIODS = 1500          # all three designs settle to < 0.002 u_R/100 periods by then (RK4)

needs_ngspice = pytest.mark.skipif(shutil.which("ngspice") is None, reason="ngspice not installed")
pytestmark = [pytest.mark.ngspice, needs_ngspice]


# --- helpers ---------------------------------------------------------------------------------
def levels_stimulus(model: MechModel, pairs) -> Stimulus:
    """Constant input levels (fractions of F_R) on the model's two external inputs, one batch member each."""
    return Stimulus.input_levels(model, pairs, P.f_r)


def assert_agree(ref: Run, got: Run, label: str) -> None:
    a, b = settled(ref.amp), settled(got.amp)
    d = agreement(a, b, U_R)
    msg = f"{label}: rk4 {np.round(np.abs(a) / U_R, 4).tolist()} ngspice {np.round(np.abs(b) / U_R, 4).tolist()}"
    assert d.amp < AMP_TOL, msg + f" amplitude error {d.amp:.4f} u_R"
    assert d.phase_deg < PHASE_TOL, msg + f" phase error {d.phase_deg:.2f} deg"


@functools.lru_cache(maxsize=None)
def design(name: str, periods: int = PERIODS):
    """(model, stimulus, RK4 run at 40 steps/period) for a named design, computed once."""
    if name == "gate":
        m = nor.single_gate(P)
        st = levels_stimulus(m, LEVEL_PAIRS)
    else:
        m = nor.chain(P, 3) if name == "chain3" else nor.fanout(P, 2)
        st = None
    return m, st, rk4.integrate(m, periods, steps_per_period=40, stimulus=st)


# --- (1) library ---------------------------------------------------------------------------
def test_library_regenerates_byte_identical(tmp_path):
    written = write_subckt_library(tmp_path, DEFAULT)
    checked_in = sorted(p.name for p in (ROOT / "subckts").iterdir() if p.name != "README.md")
    assert sorted(p.name for p in written) == checked_in
    for path in written:
        assert path.read_bytes() == (ROOT / "subckts" / path.name).read_bytes(), path.name
    assert set(subckt_library(DEFAULT)) == set(checked_in)


def test_library_example_runs_and_is_a_logical_one(tmp_path):
    """The README's hand-written netlist (library via .include) gives the '00' -> '1' output."""
    readme = (ROOT / "subckts" / "README.md").read_text()
    example = re.search(r"```spice\n(.*?)```", readme, re.S).group(1)
    write_subckt_library(tmp_path, DEFAULT)
    (tmp_path / "ex.cir").write_text(example)
    proc = subprocess.run(["ngspice", "-b", "-r", "ex.raw", "ex.cir"], cwd=tmp_path, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    names, data = ngspice.read_raw(tmp_path / "ex.raw")
    x = data[:, names.index("v(xc)")]
    amp, _ = ngspice.demodulate(data[:, 0], x[:, None], P.omega, 1500)
    assert abs(abs(amp[-1, 0]) / U_R - 0.987) < 0.005


# --- (2) emitted netlists run under plain ngspice -b --------------------------------------------
@pytest.mark.parametrize("build", [lambda: nor.single_gate(P), lambda: nor.chain(P, 3), lambda: nor.fanout(P, 2)],
                         ids=["single_gate", "chain3", "fanout2"])
def test_netlist_runs_standalone(tmp_path, build):
    model = build()
    (tmp_path / "c.cir").write_text(emit(model, 30, title="standalone check"))
    proc = subprocess.run(["ngspice", "-b", "c.cir"], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert proc.returncode in (0, 1), proc.stdout + proc.stderr      # 1: some probe in no band (30 periods)
    # the .control block makes a bare batch run print each probe's amplitude at omega, in u_R, and its band
    for name in model.probes:
        assert re.search(rf"^{re.escape(name)} = [0-9.e+-]+ u_R -> (0|1|invalid)$", proc.stdout, re.M), name
    assert "error" not in proc.stderr.lower()


def test_emission_is_hierarchical():
    text = emit(nor.chain(P, 3), 10)
    gates = [ln for ln in text.splitlines() if ln.startswith("xg_")]
    assert len(gates) == 3 and all(" m2s_nor2" in ln for ln in gates)
    assert sum(".subckt m2s_" in ln for ln in text.splitlines()) == 5
    body = text.split("* --- circuit")[1]
    assert body.count("m2s_couple") == 2 and body.count("m2s_pairdrive") == 4
    assert "m2s_osc" not in body            # every DOF lives in a gate block
    # a gate's locals differ from the defaults only where couplings attach: g1's input-1 spring
    # gate (k - k_couple) and dashpot gate (c - c_couple, negative), g0's and g1's channels
    g1 = next(ln for ln in body.splitlines() if ln.startswith("xg_g1 "))
    assert f"k1s={P.k_g - P.k_couple!r}" in g1 and f"c1d={P.c_g - P.c_couple!r}" in g1
    assert P.c_g - P.c_couple < 0


def test_generic_model_uses_oscillator_subckts(generic_model):
    m = generic_model
    body = emit(m, 5).split("* --- circuit")[1]
    assert body.count("m2s_osc") == 3 and "w=1" in body          # the slow DOF is not prewarped
    assert re.search(r"^Gk_0 v_a v_b x_a x_b 1\.0$", body, re.M)
    assert re.search(r"^Gc_0 v_a v_b v_a v_b 0\.2$", body, re.M)
    assert "Bqf_0 v_a 0 I = 0.6*V(x_a)*V(x_s)" in body


def test_gate_touched_inside_is_emitted_dof_by_dof():
    """A drive on a gate's insulator (a hidden node of m2s_nor2) makes the emitter fall back to
    m2s_osc per DOF, and the circuit still is the model."""
    m = nor.single_gate(P)
    g = m.design.gates[0]
    m.add_drive(g.insulator, 1e-3, 0.0, "poke")
    m.add_probe("ins", g.insulator)
    body = emit(m, 10).split("* --- circuit")[1]
    assert "m2s_nor2" not in body and body.count(" m2s_osc ") == 6
    ref, got = rk4.integrate(m, 300), ngspice.run(m, 300)
    assert np.abs(np.abs(ref.amp[-1, 0]) - np.abs(got.amp[-1, 0])).max() / U_R < AMP_TOL
    # the insulator's static displacement, still rising at 300 periods (hence 1 %)
    assert np.abs(ref.mean[-1, 1] - got.mean[-1, 1]).max() < 1e-2 * np.abs(ref.mean[-1, 1]).max()


def test_internal_probes_use_hierarchical_names():
    m = nor.single_gate(P)
    g = m.design.gates[0]
    m.add_probe("ins", g.insulator)
    m.add_probe("g1d", g.inputs[0][1])
    _, vecs = emit_with_probes(m, 5)
    assert vecs == ["v(x_g0_c)", "v(xg_g0.xi)", "v(xg_g0.x1d)"]
    run = ngspice.run(m, 40)
    ref = rk4.integrate(m, 40, steps_per_period=160)        # the same probes, named the same way
    assert run.amp.shape == (40, 3, 1) and ref.probe_names == run.probe_names
    # per probe, 5 %: a probe on the wrong DOF would be off by its whole size (the slow insulator's small
    # omega component differs most, 2 %: its phasor is dominated by integration error on both sides)
    scale = np.abs(ref.amp[-1])
    assert np.all(np.abs(run.amp[-1] - ref.amp[-1]) < 0.05 * scale)


# --- (3) agreement with RK4 ------------------------------------------------------------------------
def test_negative_locals_give_model_totals():
    """A linear 3-DOF chain whose local k and c are negative: the circuit's steady phasors equal the
    exact solution of (K - w^2 M + i w C) A = F with the model's total K, C (prewarped trap is exact
    at the drive frequency)."""
    w = 3.0
    m = MechModel(omega=w)
    d = [m.add_dof(n, 1.0, 9.5, 0.5) for n in ("p", "q", "r")]
    for i, j in ((0, 1), (1, 2)):
        m.add_spring(d[i], d[j], 6.0)                 # q's local k = 9.5 - 12 < 0
        m.add_dashpot(d[i], d[j], 0.3)                # q's local c = 0.5 - 0.6 < 0
    m.add_drive(d[0], 1.0, 0.3)
    for n in ("p", "q", "r"):
        m.add_probe(n, m.index(n))
    assert m.k_local[1] < 0 and m.c_local[1] < 0
    run = ngspice.run(m, 400, options=SpiceOptions(reltol=1e-6))   # also: tight reltol keeps the step
    assert run.extra["uniform_fraction"] > 0.99
    Z = m.K.toarray() - w ** 2 * np.eye(3) + 1j * w * m.C.toarray()
    F = np.array([-1j * np.exp(0.3j), 0, 0])          # a sin(wt + phase) = Re(-i a e^{i phase} e^{iwt})
    exact = np.linalg.solve(Z, F)
    got = run.amp[-1, :, 0]
    assert np.abs(got - exact).max() < 1e-9 * np.abs(exact).max()


def test_single_gate_all_inputs_match_rk4():
    m, st, ref = design("gate")
    got = ngspice.run_batch(m, PERIODS, stimulus=st)
    assert_agree(ref, got, "single gate")
    # and the logic itself: 00 -> '1', the others -> '0'
    out = np.abs(settled(got.amp))[0] / U_R
    assert out[0] > 0.92 and (out[1:] < 0.67).all()


def test_chain3_matches_rk4():
    m, st, ref = design("chain3")
    assert_agree(ref, ngspice.run(m, PERIODS), "chain(3)")


def test_fanout2_matches_rk4():
    m, st, ref = design("fanout2")
    got = ngspice.run(m, PERIODS)
    assert_agree(ref, got, "fan-out 2")
    assert abs(abs(settled(got.amp)[1, 0]) - abs(settled(got.amp)[2, 0])) < 1e-9   # identical loads


def test_without_prewarp_trap_is_detuned():
    """Why prewarp is the default: plain trap at the same (pinned) step misses the '1' by ~0.2 u_R, 24 deg."""
    m, st, ref = design("gate")
    got = ngspice.run(m, PERIODS, options=SpiceOptions(prewarp=False, trtol=1e4))
    a, b = settled(ref.amp)[0, 0], settled(got.amp)[0, 0]
    assert abs(abs(b) - abs(a)) / U_R > 0.1
    assert abs(np.degrees(np.angle(b / a))) > 10


def test_switching_stimulus_matches_rk4():
    """Piecewise-constant inputs (PWL amplitude sources): 00 -> 10 -> 11 -> 00 on one gate."""
    m = nor.single_gate(P)
    (s1, d1), (s2, d2) = m.design.input_drives
    T, lv = P.period, lambda x: x * P.f_r
    st = Stimulus.from_levels(m, [(0.0, {}), (300 * T, {s1: lv(NOMINAL1), d1: lv(NOMINAL1)}),
                                  (600 * T, {s2: lv(NOMINAL1), d2: lv(NOMINAL1)}),
                                  (900 * T, {s1: lv(NOMINAL0), d1: lv(NOMINAL0), s2: lv(NOMINAL0),
                                             d2: lv(NOMINAL0)})])
    ref = rk4.integrate(m, 1200, stimulus=st)
    got = ngspice.run(m, 1200, stimulus=st)
    ra, ga = np.abs(ref.amp[:, 0, 0]) / U_R, np.abs(got.amp[:, 0, 0]) / U_R
    assert np.abs(ra - ga)[10:].max() < 0.02          # transients included
    for end in (299, 599, 899, 1199):                 # each hold's last period
        assert abs(ra[end] - ga[end]) < AMP_TOL, end


@pytest.mark.slow
@pytest.mark.parametrize("name", ["gate", "chain3", "fanout2"])
def test_long_runs_match_rk4(name):
    """Fully settled (4000 periods) agreement, every probe."""
    m, st, ref = design(name, 4000)
    assert_agree(ref, ngspice.run_batch(m, 4000, stimulus=st), name)


@pytest.mark.slow
def test_band_edge_inputs_match_rk4():
    m = nor.single_gate(P)
    edges = [(0.365, 0.365), (0.92, 0.365), (1.025, 1.025), (0.67, 0.365)]
    st = levels_stimulus(m, edges)
    ref = rk4.integrate(m, 3000, stimulus=st)
    assert_agree(ref, ngspice.run_batch(m, 3000, stimulus=st), "band edges")


@pytest.mark.slow
def test_pyspice_shared_mode_matches_subprocess():
    pytest.importorskip("PySpice")
    m = nor.chain(P, 2)
    a, b = ngspice.run(m, 300), ngspice.run_pyspice(m, 300)
    assert np.abs(a.amp - b.amp).max() < 1e-9 * U_R
    c = ngspice.run_pyspice(m, 300)                   # repeated runs do not interfere
    assert np.abs(c.amp - b.amp).max() == 0


def test_pyspice_shared_mode_runs():
    pytest.importorskip("PySpice")
    m = nor.single_gate(P)
    a, b = ngspice.run(m, 200), ngspice.run_pyspice(m, 200)
    assert np.abs(a.amp - b.amp).max() < 1e-9 * U_R
    with pytest.raises(Mech2SpiceError, match="unknown subckt: xfoo a b nonexist"):
        ngspice.run_netlist_shared("* bad\nXfoo a b nonexist\n.tran 1m 1\n.end\n", [])
    c = ngspice.run_pyspice(m, 200)                    # the library recovers after an error
    assert np.abs(c.amp - b.amp).max() == 0


# --- (4) hostile names ----------------------------------------------------------------------
HOSTILE = ["a b", "x\n.end", "*", "ünïcødé", "A", "a", "0", "gnd", ".tran 1 2", "+x", "", "v(x)",
           "x" * 200, "{p}", "a;b$c"]


def test_namer_makes_safe_unique_stems():
    namer = Namer()
    stems = [namer(n) for n in HOSTILE]
    assert len(set(stems)) == len(stems)
    assert all(re.fullmatch(r"[a-z][a-z0-9_]*", s) and len(s) <= 44 for s in stems), stems


def test_hostile_names_cannot_break_the_netlist(tmp_path):
    m = MechModel(omega=2.0)
    for k, name in enumerate(HOSTILE):
        m.add_dof(name, 1.0, 4.0 + 0.1 * k, 0.05)
        m.add_drive(k, 0.1, 0.0, name=name)
        m.add_probe(name, k)
    for k in range(len(HOSTILE) - 1):
        m.add_spring(k, k + 1, 0.5)
    text, vecs = emit_with_probes(m, 40, title="t\n.end\n.tran 1 1")
    lines = text.splitlines()
    assert lines[-1] == ".end" and sum(ln.strip().lower() == ".end" for ln in lines) == 1
    assert not any(ln.lower().startswith(".tran 1") for ln in lines)
    card = re.compile(r"^(\*.*|\.\w+.*|\+ .*|[A-Za-z]\w*( [\w.()={}*+/\-]+| I = .*)*)$")
    bad = [ln for ln in lines if not card.match(ln) or not ln.isascii()]
    assert not bad, bad
    (tmp_path / "h.cir").write_text(text)
    proc = subprocess.run(["ngspice", "-b", "-r", "h.raw", "h.cir"], cwd=tmp_path, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    names, _ = ngspice.read_raw(tmp_path / "h.raw")
    assert names[1:] == vecs and len(set(vecs)) == len(HOSTILE)
    # and the circuit is the model: same phasors as RK4
    got, ref = ngspice.run(m, 40), rk4.integrate(m, 40)
    assert np.abs(got.amp[-1] - ref.amp[-1]).max() < 2e-3 * np.abs(ref.amp[-1]).max()


# --- (5)-(7) failures ---------------------------------------------------------------------------
def test_missing_ngspice_is_a_clear_error(monkeypatch, tmp_path):
    monkeypatch.setenv("PATH", str(tmp_path))           # an empty directory: no ngspice anywhere
    with pytest.raises(ToolMissingError, match=r"ngspice not found: apt-get install -y ngspice libngspice0"):
        ngspice.run(nor.single_gate(P), 5)


def test_malformed_netlist_reports_ngspice_message():
    with pytest.raises(Mech2SpiceError) as exc:
        ngspice.run_netlist("* bad\nR1 a 0 1\nXfoo a b nonexist\n.tran 1m 1\n.end\n")
    msg = str(exc.value)
    assert "unknown subckt: xfoo a b nonexist" in msg and "\n" not in msg
    assert "exit 1" in msg


def test_divergence_names_the_dof():
    m = nor.single_gate(P)
    m.drives[0].amplitude = 1e6                          # the source drive, on the channel
    m.invalidate()
    with pytest.raises(DivergenceError) as exc:
        ngspice.run(m, 20)
    assert exc.value.dof == "g0.C" and 0 < exc.value.t < 20 * P.period


def test_divergence_from_data_bound():
    """A linear oscillator driven far beyond the bound (1e3 u_R) is caught from the saved samples."""
    m = MechModel(omega=1.0, params=P)
    i = m.add_dof("big", 1.0, 1.0, 0.01)
    m.add_drive(i, 10.0)
    m.add_probe("big", i)
    with pytest.raises(DivergenceError) as exc:
        ngspice.run(m, 30)
    assert exc.value.dof == "big" and exc.value.value > 1e3 * U_R


# --- the reader ------------------------------------------------------------------------------------
def test_demodulation_is_exact_on_a_uniform_grid():
    w, N = 3.0, 40
    T = 2 * math.pi / w
    t = 0.123 * T / N + np.arange(10 * N + 7) * T / N    # arbitrary grid offset
    A = 0.7 * np.exp(0.4j)
    x = (A * np.exp(1j * w * t)).real + 0.05
    amp, mean = ngspice.demodulate(t, x[:, None], w, 10)
    assert np.abs(amp[1:-1, 0] - A).max() < 1e-12 and np.abs(mean[1:-1, 0] - 0.05).max() < 1e-12


def test_raw_reader_keeps_whole_rows_of_a_cut_file(tmp_path):
    m = nor.single_gate(P)
    text, vecs = emit_with_probes(m, 10)
    (tmp_path / "c.cir").write_text(text)
    subprocess.run(["ngspice", "-b", "-r", "o.raw", "c.cir"], cwd=tmp_path, capture_output=True, check=True)
    names, full = ngspice.read_raw(tmp_path / "o.raw")
    assert names == ["time", *vecs] and full.shape[0] > 400
    raw = (tmp_path / "o.raw").read_bytes()
    (tmp_path / "cut.raw").write_bytes(raw[:-13])
    _, cut = ngspice.read_raw(tmp_path / "cut.raw")
    assert cut.shape[0] == full.shape[0] - 1 and np.array_equal(cut, full[:-1])
