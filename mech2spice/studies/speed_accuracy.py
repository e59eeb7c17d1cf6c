"""Speed vs accuracy of the RK4 and ngspice backends (measured; ~15 min on a 2-core machine for the small
designs, plus the adder's sweep, 15 min of CPU time: ~10 min on an idle 2-core machine, 19 min under a load
average of 3-5, and ~5 min for the analogy forms).

Sections (all written to reports/speed_accuracy.json, charts reports/speed_accuracy_*.png and the
summary reports/speed_accuracy.md):
  accuracy   NOR gate (4 nominal input pairs), chain(3) and the 2-bit adder (verilog/adder2.v, two input
             cases): wall time vs error against RK4 at 160 steps/period, for RK4 at 10..80 steps/period
             and ngspice at several max steps x {trap + prewarp, trap, gear} x reltol values (fewer points
             on the adder, reltol 1e-5 only).  Error = max over probes (and cases) of |amplitude error| in
             u_R after settling (mean of the last 20 periods), and of the phase error in degrees.
  stability  RK4 at 4..9 steps/period (where does it diverge or fall apart?).
  damping    one Q = 200 oscillator driven at resonance, then released: fitted Q of the ring-down and
             the free oscillation's frequency error (phase drift), per method and step.
  scaling    arrays of independent driven NOR gates (6 oscillators each) up to >= 2000 oscillators:
             wall time of RK4 (40 steps/period) and ngspice (defaults) for 50 periods.
  forms      the electrical analogy itself: the package's mobility form against two alternatives emitted
             by this module (impedance/force-voltage analogy; mobility with inductor springs), same
             ngspice options, wall time and error against the RK4 reference.
  envelope_spice  ngspice on the envelope equations (mech2spice/reports/envelope_spice.py: its sections accuracy,
             failures, scaling, also one at a time as envelope_spice.NAME), in envelope_spice.json and the
             last section of the .md.  mech2spice/reports/speed_accuracy.py renders speed_accuracy.md from the JSON.

usage: mech2spice report speed_accuracy [--quick] [--out reports] [--only SECTION ...] [--design NAME ...]
       mech2spice report speed_accuracy --only adder     # the adder's accuracy sweep only, merged into
                                                         # the existing JSON (same as --only accuracy
                                                         # --design adder2)
       mech2spice report speed_accuracy --render         # .md/.png from the JSONs, nothing measured
"""
from __future__ import annotations

import math
import os
import platform
import re
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict
from pathlib import Path

import numpy as np

from .. import data, simulation
from ..backends import rk4
from ..compare import AVG, settled, settled_agreement, trajectory
from ..errors import DivergenceError, Mech2SpiceError
from ..physics import network, nor
from ..physics.model import MechModel
from ..physics.params import DEFAULT, NOMINAL0, NOMINAL1
from ..physics.stimulus import Stimulus
from ..spice import runner as ngspice
from ..spice import num
from ..spice.oscillator_netlist import SpiceOptions, emit_with_probes
from ..synthesis import synth
from . import envelope_spice
from ._common import SANDBOX, conditions, load_average, read_json, timed, write_json

MACHINE = SANDBOX
P = DEFAULT
ADDER_V = data.verilog("adder2.v")
ADDER_CASES = [(3, 2), (1, 3)]     # 3+2 = 101 and 1+3 = 100 (carry from bit 0 through bit 1): two ngspice
                                   # processes, one per core
# the gate's '11' case still beats at 1500 periods; the adder gets simulation.period_budget (800 + 300 per
# level of logic depth 7): its outputs are within 1e-3 u_R of their final values by ~2150 periods (the
# measured settle_1e-3 in the JSON / md)
PERIODS = {"nor_gate": 2500, "chain3": 1500, "adder2": 2900}
SMALL = ("nor_gate", "chain3")     # the designs the tolerances and stability sections use
REF_STEPS = 160
RK4_STEPS = [10, 20, 25, 30, 40, 80]
RK4_UNSTABLE_SCAN = [4, 5, 6, 7, 8, 9]
NG_COARSE = [1 / 4, 1 / 6, 1 / 8]
NG_STEPS = [1 / 10, 1 / 20, 1 / 40, 1 / 80, 1 / 160, 1 / 320]
NG_METHODS = {"trap+prewarp": dict(method="trap", prewarp=True), "trap": dict(method="trap", prewarp=False),
              "gear": dict(method="gear", prewarp=False)}
RELTOLS = [1e-5, 1e-3]        # the default first; ngspice's own default second
SECOND_RELTOL_STEPS = [1 / 10, 1 / 40, 1 / 160]    # plain trap / gear at reltol 1e-5: fewer steps (their
                                                   # truncation-error control makes each run slow)
SCALING_GATES = [1, 10, 50, 170, 350, 700]
SCALING_PERIODS = 50
SCALING_RK4_STEPS = 40       # the same step as ngspice's default
LEVEL_PAIRS = [(NOMINAL0, NOMINAL0), (NOMINAL1, NOMINAL0), (NOMINAL0, NOMINAL1), (NOMINAL1, NOMINAL1)]
SKIP = 10          # trajectory error ignores the first periods (start-up from rest)
# the adder (102 oscillators): ngspice at fine steps is slow on 2 cores, so fewer points, reltol 1e-5 only
ADDER_SWEEP = {"rk4": [20, 25, 30, 40, 80],
               "ngspice": {"trap+prewarp": [1 / 10, 1 / 20, 1 / 40, 1 / 80], "trap": [1 / 40, 1 / 80],
                           "gear": [1 / 40, 1 / 80]},
               "reltols": [1e-5]}


# --- designs -----------------------------------------------------------------------------------
def gate_design():
    """The lone NOR gate with its 4 nominal input pairs as one batch: (model, stimulus)."""
    m = nor.single_gate(P)
    return m, Stimulus.input_levels(m, LEVEL_PAIRS, P.f_r)


def adder_design():
    """verilog/adder2.v (17 NOR gates, 102 oscillators), ADDER_CASES as one batch from rest."""
    nl = synth.synthesize(ADDER_V)
    m = network.build(nl, P)
    st = network.stimulus(m, nl, P, [(0, [{"a": a, "b": b} for a, b in ADDER_CASES])])
    m.bench = {"logic_depth": network.logic_depth(nl), "period_budget": simulation.period_budget(nl),
                       "case_labels": [f"a={a}, b={b} (s={a + b:03b})" for a, b in ADDER_CASES]}
    return m, st


DESIGNS = {"nor_gate": gate_design, "chain3": lambda: (nor.chain(P, 3), None), "adder2": adder_design}


def designs(names=SMALL) -> dict:
    """The named designs, each built as (model, stimulus or None)."""
    return {n: DESIGNS[n]() for n in names}


def score(amp: np.ndarray, ref: np.ndarray) -> dict:
    """Settled amplitude/phase error (max over probes and cases) and the largest amplitude
    difference anywhere along the trajectory (delays, overshoots)."""
    s = settled_agreement(ref, amp, P.u_r)
    return {"amp_err_ur": s.amp, "phase_err_deg": s.phase_deg, "traj_err_ur": trajectory(ref, amp, P.u_r, SKIP)}


def cpu_seconds() -> float:
    """User + system CPU time of this process and of its finished children (the ngspice processes).
    On a shared machine this is the robust cost: wall times grow with other jobs' load, CPU time does not
    (much)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def run_rk4(model, st, steps, periods) -> dict:
    """RK4 at `steps` per period: wall and CPU time and the amplitudes, or its failure."""
    c0 = cpu_seconds()
    try:
        run, wall = timed(lambda: rk4.integrate(model, periods, steps_per_period=steps, stimulus=st))
    except (DivergenceError, Mech2SpiceError) as e:
        return {"failed": str(e)}
    return {"wall_s": wall, "cpu_s": cpu_seconds() - c0, "amp": run.amp}


def run_ng(model, st, opts: SpiceOptions, periods) -> dict:
    """One ngspice process per case, two at a time (2 cores); wall_s is the SUM of the processes'
    own wall times, i.e. the one-core cost, comparable with RK4's single-process time; cpu_s the CPU time
    of the ngspice processes and of this process (raw-file reading) over the batch."""
    c0 = cpu_seconds()
    try:
        run = ngspice.run_batch(model, periods, st, opts, workers=2)
    except Mech2SpiceError as e:
        return {"failed": str(e)}
    return {"wall_s": float(np.sum(run.extra["wall_s"])), "cpu_s": cpu_seconds() - c0, "amp": run.amp,
            "uniform_fraction": float(np.min(run.extra["uniform_fraction"])),
            "points_per_case": int(np.mean(run.extra["points"]))}


# --- sections ------------------------------------------------------------------------------------
def accuracy(quick: bool, names=tuple(DESIGNS)) -> dict:
    """The accuracy section: RK4 and ngspice sweeps on each design, scored against RK4 at 160 steps/T."""
    out = {}
    for name, (m, st) in designs(names).items():
        periods = PERIODS[name] // (3 if quick else 1)
        t0 = time.perf_counter()
        print(f"[accuracy] {name}: RK4 reference at {REF_STEPS} steps/period, {periods} periods", flush=True)
        ref = run_rk4(m, st, REF_STEPS, periods)
        rows = [{"backend": "rk4", "steps_per_period": REF_STEPS, "wall_s": ref["wall_s"], "cpu_s": ref["cpu_s"],
                 "reference": True}]
        sweep = ADDER_SWEEP if name == "adder2" else None
        rk_steps = sweep["rk4"] if sweep else RK4_STEPS
        for steps in rk_steps[:3] if quick else rk_steps:
            rows.append({"backend": "rk4", "steps_per_period": steps,
                         **_scored(run_rk4(m, st, steps, periods), ref["amp"])})
            print(f"  rk4 {steps:4d}/T {_fmt(rows[-1])}", flush=True)
        for label, kw in NG_METHODS.items():
            reltols = sweep["reltols"] if sweep else RELTOLS
            for reltol in reltols[:1] if quick else reltols:
                steps = sweep["ngspice"][label][:2] if sweep and quick else \
                    sweep["ngspice"][label] if sweep else _ng_steps(label, reltol, quick)
                for ms in steps:
                    r = run_ng(m, st, SpiceOptions(max_step_periods=ms, reltol=reltol, **kw), periods)
                    rows.append({"backend": "ngspice", "method": label, "reltol": reltol,
                                 "steps_per_period": round(1 / ms), **_scored(r, ref["amp"])})
                    print(f"  ngspice {label:12s} reltol={reltol:g} T/{round(1 / ms):<4d} {_fmt(rows[-1])}", flush=True)
        out[name] = {"probes": list(m.probes), "cases": st.batch if st is not None else 1, "periods": periods,
                     "oscillators": m.n,
                     "reference_amp_ur": (np.abs(settled(ref["amp"])) / P.u_r).round(5).tolist(),
                     "settle_period": {str(tol): settle_period(ref["amp"], tol) for tol in (1e-2, 1e-3)},
                     "wall_s": time.perf_counter() - t0, "rows": rows, **getattr(m, "bench", {})}
    return out


def settle_period(amp: np.ndarray, tol: float) -> int:
    """The last period (1-based) at which some probe's |A| is off its settled value by more than tol u_R."""
    off = np.abs(np.abs(amp) - np.abs(settled(amp))[None]) / P.u_r > tol
    bad = np.flatnonzero(off.reshape(off.shape[0], -1).any(axis=1))
    return int(bad[-1] + 1) if bad.size else 0


def _ng_steps(label: str, reltol: float, quick: bool) -> list[float]:
    if quick:
        return NG_STEPS[:3]
    if label == "trap+prewarp":
        return [s for s in NG_STEPS if s >= 1 / 160]      # converged by T/160
    return NG_STEPS if reltol == 1e-3 else SECOND_RELTOL_STEPS


def _scored(r: dict, ref: np.ndarray) -> dict:
    if "amp" not in r:
        return dict(r)
    return {**{k: v for k, v in r.items() if k != "amp"}, **score(r["amp"], ref)}


def _fmt(row: dict) -> str:
    if "amp_err_ur" not in row:
        return f"FAILED: {row.get('failed')}"
    return (f"{row['wall_s']:6.2f} s (cpu {row.get('cpu_s', float('nan')):6.2f} s)  amp err {row['amp_err_ur']:.4f} u_R  phase err {row['phase_err_deg']:.2f} deg"
            f"  trajectory err {row['traj_err_ur']:.4f} u_R")


def tolerances() -> dict:
    """Newton tolerances at the default step: reltol x vntol (the accuracy section has vntol 1e-9 at
    reltol 1e-3 and 1e-5)."""
    out = {}
    for name, (m, st) in designs().items():
        periods = PERIODS[name]
        ref = run_rk4(m, st, REF_STEPS, periods)
        rows = []
        for reltol, vntol in ((1e-3, 1e-6), (1e-5, 1e-6), (1e-4, 1e-9), (1e-6, 1e-9)):
            r = run_ng(m, st, SpiceOptions(reltol=reltol, vntol=vntol), periods)
            rows.append({"backend": "ngspice", "method": "trap+prewarp", "reltol": reltol, "vntol": vntol,
                         "steps_per_period": round(1 / SpiceOptions().max_step_periods), **_scored(r, ref["amp"])})
            print(f"[tolerances] {name} reltol={reltol:g} vntol={vntol:g} {_fmt(rows[-1])}", flush=True)
        out[name] = {"periods": periods, "rows": rows}
    return out


def stability() -> dict:
    """RK4 at 4..9 steps/period and ngspice at T/4..T/8: does either diverge, and how wrong is it?"""
    out = {}
    for name, (m, st) in designs().items():
        ref = run_rk4(m, st, REF_STEPS, 600)
        rows = []
        for steps in RK4_UNSTABLE_SCAN:
            rows.append({"backend": "rk4", "steps_per_period": steps, **_scored(run_rk4(m, st, steps, 600), ref["amp"])})
            print(f"[stability] {name} rk4 {steps}/T {_fmt(rows[-1])}", flush=True)
        for label, kw in NG_METHODS.items():
            for ms in NG_COARSE:
                r = run_ng(m, st, SpiceOptions(max_step_periods=ms, trtol=1e4, **kw), 600)   # pinned step
                rows.append({"backend": "ngspice", "method": label, "steps_per_period": round(1 / ms),
                             **_scored(r, ref["amp"])})
                print(f"[stability] {name} ngspice {label} T/{round(1 / ms)} {_fmt(rows[-1])}", flush=True)
        try:
            rk4.integrate(m, 1, steps_per_period=3, stimulus=st)
            below = "ran"
        except Mech2SpiceError as e:
            below = str(e)
        out[name] = {"periods": 600, "rows": rows, "rk4_3_steps": below}
    return out


# --- ring-down: numerical damping and phase drift ---------------------------------------------------
Q_TRUE, ON, OFF = 200.0, 300, 600        # driven for ON periods, released, observed until OFF


def lone_oscillator() -> tuple[MechModel, Stimulus]:
    """m = 1, resonant at the drive frequency, Q = 200; drive on for ON periods, then off."""
    w = P.omega
    m = MechModel(omega=w, params=P)
    i = m.add_dof("osc", 1.0, w * w, w / Q_TRUE)
    m.add_drive(i, w * w / Q_TRUE * P.u_r)           # steady amplitude 1 u_R
    m.add_probe("osc", i)
    st = Stimulus([0.0, ON * P.period], np.array([[[m.drives[0].amplitude]], [[0.0]]]))
    return m, st


def fit_ringdown(amp: np.ndarray) -> dict:
    """Q from the decay of |A| (|A| ~ exp(-pi k / Q) per period k) and the frequency error of the
    free oscillation from its phase drift against the drive's clock."""
    k = np.arange(ON + 10, OFF)
    a = amp[k]
    slope = np.polyfit(k, np.log(np.abs(a)), 1)[0]
    drift = np.polyfit(k, np.unwrap(np.angle(a)), 1)[0]          # rad per period
    return {"q_fit": float(-math.pi / slope), "freq_err_ppm": float(drift / (2 * math.pi) * 1e6),
            "phase_drift_deg_per_100T": float(np.degrees(drift) * 100)}


def damping(quick: bool) -> dict:
    """The damping section: Q and frequency error of a lone oscillator's ring-down per method and step."""
    m, st = lone_oscillator()
    rows = []
    for steps in RK4_STEPS:
        run, wall = timed(lambda: rk4.integrate(m, OFF, steps_per_period=steps, stimulus=st))
        rows.append({"backend": "rk4", "steps_per_period": steps, **fit_ringdown(run.amp[:, 0, 0])})
        print(f"[damping] rk4 {steps}/T {rows[-1]}", flush=True)
    for label, kw in NG_METHODS.items():
        for ms in NG_STEPS[:3] if quick else NG_STEPS:
            # trtol 1e4 pins every method's step at max_step: the rows are per step, not per tolerance
            run = ngspice.run(m, OFF, st, SpiceOptions(max_step_periods=ms, trtol=1e4, **kw))
            rows.append({"backend": "ngspice", "method": label, "steps_per_period": round(1 / ms),
                         **fit_ringdown(run.amp[:, 0, 0])})
            print(f"[damping] ngspice {label} T/{round(1 / ms)} {rows[-1]}", flush=True)
    return {"q_true": Q_TRUE, "driven_periods": ON, "fit_periods": [ON + 10, OFF], "rows": rows}


# --- why the step must stay pinned under prewarp ---------------------------------------------------
def pinning() -> dict:
    """Linear 3-DOF chain (negative local k, c) against its exact phasor solution: prewarp is exact
    only while every step equals max_step; ngspice's truncation-error control breaks that at tight
    reltol unless trtol is raised."""
    w = 3.0
    m = MechModel(omega=w)
    d = [m.add_dof(n, 1.0, 9.5, 0.5) for n in ("p", "q", "r")]
    for i, j in ((0, 1), (1, 2)):
        m.add_spring(d[i], d[j], 6.0)
        m.add_dashpot(d[i], d[j], 0.3)
    m.add_drive(d[0], 1.0, 0.3)
    for n in ("p", "q", "r"):
        m.add_probe(n, m.index(n))
    Z = m.K.toarray() - w ** 2 * np.eye(3) + 1j * w * m.C.toarray()
    exact = np.linalg.solve(Z, np.array([-1j * np.exp(0.3j), 0, 0]))
    rows = []
    for prewarp in (True, False):
        for reltol in (1e-3, 1e-6):
            for trtol in ((None, 7.0) if prewarp else (None,)):     # without prewarp None means 7
                o = SpiceOptions(reltol=reltol, trtol=trtol, prewarp=prewarp)
                run = ngspice.run(m, 400, options=o)
                err = float(np.abs(run.amp[-1, :, 0] - exact).max() / np.abs(exact).max())
                rows.append({"prewarp": prewarp, "reltol": reltol, "trtol": o.trtol_value(), "rel_err": err,
                             "uniform_fraction": run.extra["uniform_fraction"], "wall_s": run.extra["wall_s"]})
                print(f"[pinning] {rows[-1]}", flush=True)
    return {"model": "3 DOFs, m=1, k_total=9.5, c_total=0.5, springs 6.0, dashpots 0.3 (middle local k=-2.5, "
                     "c=-0.1), omega=3, 400 periods, step T/40", "rows": rows}


# --- scaling ------------------------------------------------------------------------------------------
def gate_array(n: int) -> MechModel:
    """n independent NOR gates, both inputs at a constant '0' (each gate's output a '1')."""
    return nor.gate_array(P, n, NOMINAL0)


def scaling(quick: bool) -> dict:
    """The scaling section: RK4 and ngspice wall time for 50 periods on arrays of independent NOR gates."""
    rows = []
    for n in SCALING_GATES[:3] if quick else SCALING_GATES:
        m = gate_array(n)
        r, t_rk4 = timed(lambda: rk4.integrate(m, SCALING_PERIODS, steps_per_period=SCALING_RK4_STEPS))
        s, t_ng = timed(lambda: ngspice.run(m, SCALING_PERIODS))
        diff = float(np.abs(np.abs(r.amp[-1]) - np.abs(s.amp[-1])).max() / P.u_r)
        rows.append({"gates": n, "oscillators": m.n, "rk4_s": t_rk4, "ngspice_s": t_ng, "max_diff_ur": diff})
        print(f"[scaling] {m.n:5d} oscillators: rk4 {t_rk4:.2f} s, ngspice {t_ng:.2f} s", flush=True)
    return {"periods": SCALING_PERIODS, "rk4_steps_per_period": SCALING_RK4_STEPS,
            "ngspice_options": asdict(SpiceOptions()), "rows": rows}


# --- the analogy form: the package's against two alternatives ------------------------------------------
# Each form is a small standalone emitter here (not in the package).  All three get the same .options and
# .tran line (spice.SpiceOptions defaults: trap, max step T/40 pinned by trtol 1e4, reltol 1e-5, vntol
# 1e-9) and the same prewarp: every reactive element of an oscillating DOF scaled by w (C -> wC, L -> wL),
# which makes each one's trapezoidal admittance exact at omega.  `.options acct` is appended to every
# netlist (the circuit-equation count comes from ngspice's own statistics).
FORM_DESIGNS = ("nor_gate", "chain3", "adder2")
FORM_REPEAT = 2          # the run with the least CPU time of two is kept (the machine is shared)


def _form_analysis(model: MechModel, periods: int, o: SpiceOptions, saves: list[str]) -> list[str]:
    """The same .options/.tran/.save lines as spice._Emitter.analysis."""
    T = 2 * math.pi / model.omega
    h = o.max_step_periods * T
    opts = (f".options method={o.method} reltol={num(o.reltol)} abstol={num(o.abstol)} chgtol={num(o.chgtol)} "
            f"vntol={num(o.vntol)} trtol={num(o.trtol_value())}") + (f" maxord={o.maxord}" if o.method == "gear" else "")
    out = [opts, f".tran {num(h)} {num((periods + 0.25) * T)} 0 {num(h)} uic"]
    out += [".save " + " ".join(saves[k:k + 8]) for k in range(0, len(saves), 8)]
    return out


def _form_amplitudes(model: MechModel, periods: int, st: Stimulus | None, b: int) -> tuple[dict, list[str]]:
    """{drive: amplitude node} and one DC/PWL voltage source per drive (the package's schedule rules)."""
    T = 2 * math.pi / model.omega
    nodes, lines = {}, []
    for d, drv in enumerate(model.drives):
        sched, last = [], None
        for t, a in ([(0.0, drv.amplitude)] if st is None else zip(st.times, st.amps[:, d, b])):
            if t < periods * T and a != last:
                sched.append((float(t), float(a)))
                last = a
        if len(sched) == 1:
            src = f"DC {num(sched[0][1])}"
        else:
            ramp, pts = 1e-3 * T, [f"0 {num(sched[0][1])}"]
            for (_, a0), (t1, a1) in zip(sched, sched[1:]):
                pts += [f"{num(t1 - ramp / 2)} {num(a0)}", f"{num(t1 + ramp / 2)} {num(a1)}"]
            src = "PWL(" + " ".join(pts) + ")"
        nodes[d] = f"amp{d}"
        lines.append(f"Vamp{d} amp{d} 0 {src}")
    return nodes, lines


def emit_mobility(model, periods, st, b, o):
    """The package's form (mech2spice.spice.oscillator_netlist): velocity node with C = m, conductance c_local and a VCCS
    k_local V(x) to ground; displacement node x = 1 F capacitor fed by the VCCS V(v); coupling springs
    VCCS k (V(x_i) - V(x_j)), dashpots conductances, quadratic couplings and drives B current sources."""
    text, vecs = emit_with_probes(model, periods, st, b, o)
    return text, vecs, [1.0] * len(vecs)


def emit_impedance(model, periods, st, b, o):
    """Force-voltage (impedance) analogy: force = voltage, velocity = current.  Per DOF one series loop,
    loop current = velocity: 0 V ammeter -> force sources -> L = m -> R = c_total -> C = 1/k_total -> ground,
    so V(C) = k_total u.  Couplings are controlled voltage sources in the loop (a coupling element shared
    by two meshes needs the dual graph, which a general network need not have): spring +k_ij u_j a VCVS of
    the other loop's capacitor, dashpot +c_ij v_j a CCVS of its ammeter; quadratic forces and drives B
    voltage sources.  The probe vector V(C) is scaled by 1/k_total to give u."""
    w = o.warp(model.omega)
    kt, ct = np.array(model.k_total), np.array(model.c_total)
    forces = [[] for _ in range(model.n)]
    for i, j, k in model.springs:
        forces[i].append(f"E {{}} {{}} c{j} 0 {num(k / kt[j])}")
        forces[j].append(f"E {{}} {{}} c{i} 0 {num(k / kt[i])}")
    for i, j, c in model.dashpots:
        forces[i].append(f"H {{}} {{}} Vam{j} {num(c)}")
        forces[j].append(f"H {{}} {{}} Vam{i} {num(c)}")
    quad = [[] for _ in range(model.n)]
    for f, s_, g in model.quads:
        quad[f].append(f"{num(-2 * g / (kt[f] * kt[s_]))}*V(c{f})*V(c{s_})")
        quad[s_].append(f"{num(-g / kt[f] ** 2)}*V(c{f})*V(c{f})")
    amp, amp_lines = _form_amplitudes(model, periods, st, b)
    for d, drv in enumerate(model.drives):
        forces[drv.dof].append(f"B {{}} {{}} V = V({amp[d]})*sin({num(model.omega)}*time+{num(drv.phase)})")
    for i in range(model.n):
        if quad[i]:
            forces[i].append("B {} {} V = " + " + ".join(quad[i]))
    lines = [f"* impedance (force-voltage) analogy, {model.n} DOFs, prewarp w = {num(w)}"]
    for i in range(model.n):
        wi = 1.0 if model.slow[i] else w
        lines.append(f"Vam{i} 0 a{i}_0 DC 0")          # current 0 -> a0 through it = the loop current
        node = f"a{i}_0"
        for k, spec in enumerate(forces[i]):
            kind, rest = spec.split(" ", 1)
            lines.append(f"{kind}f{i}_{k} " + rest.format(f"a{i}_{k + 1}", node))
            node = f"a{i}_{k + 1}"
        lines += [f"L{i} {node} q{i} {num(model.mass[i] * wi)}", f"R{i} q{i} c{i} {num(ct[i])}",
                  f"C{i} c{i} 0 {num(wi / kt[i])}"]
    probes = list(model.probes.values())
    saves = [f"v(c{i})" for i in probes]
    text = "\n".join(lines + amp_lines + _form_analysis(model, periods, o, saves) + [".end"]) + "\n"
    return text, saves, [1 / kt[i] for i in probes]


def emit_inductor_springs(model, periods, st, b, o):
    """Mobility analogy with the textbook spring: velocity nodes with C = m and conductance c_local as in
    the package, but every spring an inductor L = 1/k (local ones to ground, coupling ones between the
    velocity nodes; negative L for negative k_local); a displacement node (1 F fed by V(v)) only for DOFs
    in a quadratic coupling or probed."""
    w = o.warp(model.omega)
    need_x = {f for f, _, _ in model.quads} | {s_ for _, s_, _ in model.quads} | set(model.probes.values())
    lines = [f"* mobility analogy, springs as inductors, {model.n} DOFs, prewarp w = {num(w)}"]
    for i in range(model.n):
        wi = 1.0 if model.slow[i] else w
        lines.append(f"Cm{i} v{i} 0 {num(model.mass[i] * wi)}")
        if model.c_local[i] != 0:
            lines.append(f"Gc{i} v{i} 0 v{i} 0 {num(model.c_local[i])}")
        if model.k_local[i] != 0:
            lines.append(f"Lk{i} v{i} 0 {num(wi / model.k_local[i])}")
        if i in need_x:
            lines += [f"Cx{i} x{i} 0 {num(wi)}", f"Gx{i} 0 x{i} v{i} 0 1"]
    for n, (i, j, k) in enumerate(model.springs):
        lines.append(f"Lc{n} v{i} v{j} {num((1.0 if model.slow[i] else w) / k)}")
    for n, (i, j, c) in enumerate(model.dashpots):
        lines.append(f"Gd{n} v{i} v{j} v{i} v{j} {num(c)}")
    for n, (f, s_, g) in enumerate(model.quads):
        lines += [f"Bqf{n} v{f} 0 I = {num(2 * g)}*V(x{f})*V(x{s_})", f"Bqs{n} v{s_} 0 I = {num(g)}*V(x{f})*V(x{f})"]
    amp, amp_lines = _form_amplitudes(model, periods, st, b)
    for d, drv in enumerate(model.drives):
        lines.append(f"Bd{d} 0 v{drv.dof} I = V({amp[d]})*sin({num(model.omega)}*time+{num(drv.phase)})")
    probes = list(model.probes.values())
    saves = [f"v(x{i})" for i in probes]
    text = "\n".join(lines + amp_lines + _form_analysis(model, periods, o, saves) + [".end"]) + "\n"
    return text, saves, [1.0] * len(probes)


FORMS = {"mobility, VCCS springs (package)": emit_mobility, "impedance (force-voltage)": emit_impedance,
         "mobility, inductor springs": emit_inductor_springs}


def run_form(emitter, model: MechModel, st: Stimulus | None, o: SpiceOptions, periods: int) -> dict:
    """Every case as its own `ngspice -b -r` process, two at a time; wall_s = sum of the processes' own
    times (subprocess + raw-file read, as ngspice.run measures), as in run_ng."""
    def one(b):
        text, vecs, scale = emitter(model, periods, st, b, o)
        text = text.replace("\n.end\n", "\n.options acct\n.end\n")
        t0 = time.perf_counter()
        names, data, log = ngspice.run_netlist(text)
        wall = time.perf_counter() - t0
        data = data.copy()
        for v, k in zip(vecs, scale):
            data[:, names.index(v)] *= k
        eq = re.search(r"Circuit Equations\s*=\s*(\d+)", log)
        run = ngspice.to_run(model, periods, names, data, vecs, o, {"wall_s": wall})
        return run, wall, int(eq.group(1)) if eq else None, len(text.splitlines())
    B = st.batch if st is not None else 1
    c0 = cpu_seconds()
    try:
        with ThreadPoolExecutor(2) as pool:
            runs = list(pool.map(one, range(B)))
    except Mech2SpiceError as e:
        return {"failed": str(e)}
    return {"wall_s": float(sum(r[1] for r in runs)), "cpu_s": cpu_seconds() - c0, "amp": np.concatenate([r[0].amp for r in runs], axis=2),
            "uniform_fraction": float(min(r[0].extra["uniform_fraction"] for r in runs)),
            "equations": runs[0][2], "netlist_lines": runs[0][3]}


def forms(quick: bool) -> dict:
    """The forms section: each analogy form on ngspice against the RK4 reference (least CPU of the runs)."""
    out = {}
    o = SpiceOptions()
    for name, (m, st) in designs(FORM_DESIGNS[:2] if quick else FORM_DESIGNS).items():
        periods = PERIODS[name] // (3 if quick else 1)
        ref = run_rk4(m, st, REF_STEPS, periods)
        rows = []
        for label, emitter in FORMS.items():
            runs = [run_form(emitter, m, st, o, periods) for _ in range(1 if quick else FORM_REPEAT)]
            ok = [r for r in runs if "wall_s" in r]
            best = min(ok, key=lambda r: r["cpu_s"]) if ok else runs[0]
            rows.append({"form": label, **_scored(best, ref["amp"]), "walls": [r["wall_s"] for r in ok],
                         "cpus": [r["cpu_s"] for r in ok]})
            print(f"[forms] {name} {label}: {_fmt(rows[-1])}, equations {rows[-1].get('equations')}, "
                  f"runs {[round(x, 2) for x in rows[-1].get('walls', [])]}", flush=True)
        out[name] = {"periods": periods, "cases": st.batch if st is not None else 1, "oscillators": m.n,
                     "options": asdict(o), "repeat": 1 if quick else FORM_REPEAT, "rows": rows}
    return out


# --- output ------------------------------------------------------------------------------------------------


# --- the report ---------------------------------------------------------------------------------------------


SECTIONS = ("pinning", "accuracy", "tolerances", "stability", "damping", "scaling", "forms")
ENVELOPE_SECTIONS = ("envelope_spice",) + tuple(f"envelope_spice.{s}" for s in envelope_spice.SECTIONS)
ALL_SECTIONS = SECTIONS + ("adder",) + ENVELOPE_SECTIONS


def measure_sections(out: Path, only, design, quick: bool) -> None:
    """Measure what `only` and `design` name (default: every section, envelope_spice's too) into
    speed_accuracy.json and envelope_spice.json."""
    main, env = _split_sections(only, design)
    if main is not None:
        measure(out, main, design, quick)
    if env is not None:
        envelope_spice.measure(out, env, quick)


def _split_sections(only, design) -> tuple[list | None, list | None]:
    """`only` as (this module's sections, envelope_spice's): None = not run, [] = all of them."""
    only = list(only or [])
    bad = [s for s in only if s not in ALL_SECTIONS]
    if bad:
        raise Mech2SpiceError(f"speed_accuracy: unknown section {', '.join(bad)} "
                              f"(choose from {', '.join(ALL_SECTIONS)})")
    if not only:
        return ([], None) if design else ([], [])           # --design alone: those accuracy rows only
    main = [s for s in only if s in SECTIONS or s == "adder"]
    env = [s.split(".", 1)[1] for s in only if s.startswith("envelope_spice.")]
    return main or None, ([] if "envelope_spice" in only else env or None)


def measure(out: Path, only: list, design, quick: bool) -> dict:
    """Run this module's sections (`only` empty: all, from scratch) and write speed_accuracy.json."""
    jpath = out / "speed_accuracy.json"
    if design and not only:
        only = ["accuracy"]                   # --design alone: those designs' accuracy rows, merged
    acc_designs = tuple(design or DESIGNS)
    if "adder" in only:
        only = [x for x in only if x != "adder"] + ["accuracy"]
        acc_designs = tuple(dict.fromkeys([*(design or []), "adder2"]))
    _warm_up()
    t0 = time.perf_counter()
    res = {"machine": MACHINE, "python": platform.python_version(), "periods": PERIODS, "avg": AVG,
           "rk4_kernel": "numba" if _numba() else "numpy",
           "reference": f"RK4 at {REF_STEPS} steps/period", "default_options": asdict(SpiceOptions()),
           "settings": settings(), "conditions": conditions()}
    if only and jpath.exists():                 # refresh some sections, keep the others
        res = {**read_json(jpath), **res}
    sections = {"pinning": pinning, "accuracy": lambda: accuracy(quick, acc_designs), "tolerances": tolerances,
                "stability": stability, "damping": lambda: damping(quick), "scaling": lambda: scaling(quick),
                "forms": lambda: forms(quick)}
    for name, fn in sections.items():
        if not only or name in only:
            _run_section(res, name, fn, only, acc_designs)
    if not only:
        res["total_wall_s"] = time.perf_counter() - t0
        res.pop("section_wall_s", None)
    write_json(jpath, res)
    print(f"wrote {jpath} in {time.perf_counter() - t0:.0f} s")
    return read_json(jpath)


def settings() -> dict:
    """The measurement's settings the report states (it reads them from the JSON, not from this module)."""
    return {"ref_steps": REF_STEPS, "reltols": RELTOLS, "q_true": Q_TRUE, "scaling_periods": SCALING_PERIODS}


def _run_section(res: dict, name: str, fn, only: list, acc_designs: tuple) -> None:
    """Run one section into `res`; a rerun (`only`) also records its wall time and load average."""
    t1, load0 = time.perf_counter(), load_average()[0]
    new = fn()
    if name == "accuracy" and only:             # merge per design, in DESIGNS order
        merged = {**res.get("accuracy", {}), **new}
        new = {k: merged[k] for k in sorted(merged, key=lambda k: list(DESIGNS).index(k)
                                            if k in DESIGNS else len(DESIGNS))}
    res[name] = new
    if only:
        key = name if name != "accuracy" or set(acc_designs) == set(DESIGNS) else \
            f"accuracy ({', '.join(acc_designs)})"
        res.setdefault("section_wall_s", {})[key] = time.perf_counter() - t1
        res.setdefault("section_load_avg", {})[key] = [load0, load_average()[0]]


def _numba() -> bool:
    try:
        from ..backends import _rk4_kernel as rk4_kernel    # which RK4 path ran is the kernel's to say
        return bool(rk4_kernel.AVAILABLE)
    except ImportError:
        return False


def _warm_up() -> None:
    """Compile RK4's kernel (numba caches it) and start ngspice once, outside every timing."""
    m, st = gate_design()
    rk4.integrate(m, 2, steps_per_period=40, stimulus=st)
    ngspice.run(m, 2)
