#!/usr/bin/env python3
"""Speed vs accuracy of the RK4 and ngspice backends (measured; ~15 min on a 2-core machine).

Sections (all written to reports/speed_accuracy.json, charts reports/speed_accuracy_*.png and the
summary reports/speed_accuracy.md):
  accuracy   NOR gate (4 nominal input pairs) and chain(3): wall time vs error against RK4 at
             160 steps/period, for RK4 at 10..80 steps/period and ngspice at several max steps x
             {trap + prewarp, trap, gear} x two reltol values.  Error = max over probes (and input
             pairs) of |amplitude error| in u_R after settling (mean of the last 20 of 1500 periods),
             and of the phase error in degrees.
  stability  RK4 at 4..9 steps/period (where does it diverge or fall apart?).
  damping    one Q = 200 oscillator driven at resonance, then released: fitted Q of the ring-down and
             the free oscillation's frequency error (phase drift), per method and step.
  scaling    arrays of independent driven NOR gates (6 oscillators each) up to >= 2000 oscillators:
             wall time of RK4 (40 steps/period) and ngspice (defaults) for 50 periods.

usage: python benchmarks/speed_accuracy.py [--quick] [--out reports]
"""
from __future__ import annotations

import argparse
import json
import math
import platform
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from mech2spice import ngspice, nor, rk4
from mech2spice.errors import DivergenceError, Mech2SpiceError
from mech2spice.model import MechModel
from mech2spice.params import DEFAULT, NOMINAL0, NOMINAL1
from mech2spice.spice import SpiceOptions
from mech2spice.stimulus import Stimulus

MACHINE = "2-core Debian 12 sandbox"
P = DEFAULT
AVG = 20
PERIODS = {"nor_gate": 2500, "chain3": 1500}   # the gate's '11' case still beats at 1500 periods
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
PAIRS = [(NOMINAL0, NOMINAL0), (NOMINAL1, NOMINAL0), (NOMINAL0, NOMINAL1), (NOMINAL1, NOMINAL1)]
SKIP = 10          # trajectory error ignores the first periods (start-up from rest)


# --- designs -----------------------------------------------------------------------------------
def gate_design():
    m = nor.single_gate(P)
    lv = np.array(PAIRS) * P.f_r
    ch = {}
    for k, (ds, dd) in enumerate(m.meta["input_drives"]):
        ch[ds] = ch[dd] = lv[:, k]
    return m, Stimulus.from_levels(m, [(0.0, ch)], batch=len(PAIRS))


def designs() -> dict:
    return {"nor_gate": gate_design(), "chain3": (nor.chain(P, 3), None)}


def settled(amp: np.ndarray) -> np.ndarray:
    return amp[-AVG:].mean(axis=0)


def score(amp: np.ndarray, ref: np.ndarray) -> dict:
    """Settled amplitude/phase error (max over probes and cases) and the largest amplitude
    difference anywhere along the trajectory (delays, overshoots)."""
    a, r = settled(amp), settled(ref)
    return {"amp_err_ur": float(np.abs(np.abs(a) - np.abs(r)).max() / P.u_r),
            "phase_err_deg": float(np.abs(np.degrees(np.angle(a / r))).max()),
            "traj_err_ur": float(np.abs(np.abs(amp[SKIP:]) - np.abs(ref[SKIP:])).max() / P.u_r)}


def timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def run_rk4(model, st, steps, periods) -> dict:
    try:
        run, wall = timed(lambda: rk4.integrate(model, periods, steps_per_period=steps, stimulus=st))
    except (DivergenceError, Mech2SpiceError) as e:
        return {"failed": str(e)}
    return {"wall_s": wall, "amp": run.amp}


def run_ng(model, st, opts: SpiceOptions, periods) -> dict:
    """One ngspice process per case, two at a time (2 cores); wall_s is the SUM of the processes'
    own wall times, i.e. the one-core cost, comparable with RK4's single-process time."""
    try:
        run = ngspice.run_batch(model, periods, st, opts, workers=2)
    except Mech2SpiceError as e:
        return {"failed": str(e)}
    return {"wall_s": float(np.sum(run.extra["wall_s"])), "amp": run.amp,
            "uniform_fraction": float(np.min(run.extra["uniform_fraction"])),
            "points_per_case": int(np.mean(run.extra["points"]))}


# --- sections ------------------------------------------------------------------------------------
def accuracy(quick: bool) -> dict:
    out = {}
    for name, (m, st) in designs().items():
        periods = PERIODS[name] // (3 if quick else 1)
        print(f"[accuracy] {name}: RK4 reference at {REF_STEPS} steps/period, {periods} periods", flush=True)
        ref = run_rk4(m, st, REF_STEPS, periods)
        rows = [{"backend": "rk4", "steps_per_period": REF_STEPS, "wall_s": ref["wall_s"], "reference": True}]
        for steps in RK4_STEPS[:3] if quick else RK4_STEPS:
            rows.append({"backend": "rk4", "steps_per_period": steps,
                         **_scored(run_rk4(m, st, steps, periods), ref["amp"])})
            print(f"  rk4 {steps:4d}/T {_fmt(rows[-1])}", flush=True)
        for label, kw in NG_METHODS.items():
            for reltol in RELTOLS[:1] if quick else RELTOLS:
                for ms in _ng_steps(label, reltol, quick):
                    r = run_ng(m, st, SpiceOptions(max_step_periods=ms, reltol=reltol, **kw), periods)
                    rows.append({"backend": "ngspice", "method": label, "reltol": reltol,
                                 "steps_per_period": round(1 / ms), **_scored(r, ref["amp"])})
                    print(f"  ngspice {label:12s} reltol={reltol:g} T/{round(1 / ms):<4d} {_fmt(rows[-1])}", flush=True)
        out[name] = {"probes": list(m.probes), "cases": len(PAIRS) if st is not None else 1, "periods": periods,
                     "reference_amp_ur": (np.abs(settled(ref["amp"])) / P.u_r).round(5).tolist(), "rows": rows}
    return out


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
    return (f"{row['wall_s']:6.2f} s  amp err {row['amp_err_ur']:.4f} u_R  phase err {row['phase_err_deg']:.2f} deg"
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
    m = MechModel(omega=w, meta={"params": P})
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
    m = nor.new_model(P)
    gates = []
    for k in range(n):
        g = nor.add_nor(m, P, f"g{k}")
        nor.drive_pair(m, P, g.inputs[0], NOMINAL0, f"a{k}")
        nor.drive_pair(m, P, g.inputs[1], NOMINAL0, f"b{k}")
        gates.append(g)
    m.meta["gates"] = gates
    return m


def scaling(quick: bool) -> dict:
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


# --- output ------------------------------------------------------------------------------------------------
def charts(res: dict, out: Path) -> list[str]:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    files = []
    fig, axes = plt.subplots(1, 2, figsize=(12, 5))
    styles = {("rk4", None): "k-o", ("ngspice", "trap+prewarp"): "g-s", ("ngspice", "trap"): "b-^",
              ("ngspice", "gear"): "r-v"}
    for ax, (name, d) in zip(axes, res["accuracy"].items()):
        for (backend, method), style in styles.items():
            for reltol in RELTOLS:
                rows = [r for r in d["rows"] if r["backend"] == backend and r.get("method") == method
                        and r.get("reltol", reltol) == reltol and "amp_err_ur" in r]
                if not rows or (backend == "rk4" and reltol != RELTOLS[0]):
                    continue
                lab = "RK4" if backend == "rk4" else f"ngspice {method}, reltol {reltol:g}"
                ax.loglog([r["wall_s"] for r in rows], [max(r["amp_err_ur"], 1e-6) for r in rows], style,
                          alpha=1.0 if reltol == RELTOLS[0] else 0.4, label=lab)
                for r in rows:
                    ax.annotate(f"{r['steps_per_period']}", (r["wall_s"], max(r["amp_err_ur"], 1e-6)),
                                fontsize=6, xytext=(2, 2), textcoords="offset points")
        ax.axhline(0.01, color="grey", ls="--", lw=0.8)
        ax.set(title=f"{name}: {d['periods']} periods (labels: steps/period)", xlabel="wall time [s]",
               ylabel="max amplitude error [u_R] vs RK4 @160")
        ax.legend(fontsize=7)
    fig.suptitle(f"speed vs accuracy, {MACHINE}")
    fig.tight_layout()
    files.append(_save(fig, out / "speed_accuracy_tradeoff.png"))

    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12, 5))
    rows = res["damping"]["rows"]
    exact_ppm = 1e6 * (1 - math.sqrt(1 - 1 / (4 * Q_TRUE ** 2)))
    for (backend, method), style in styles.items():
        sel = [r for r in rows if r["backend"] == backend and r.get("method") == method]
        if sel:
            lab = "RK4" if backend == "rk4" else f"ngspice {method}"
            ax.semilogx([r["steps_per_period"] for r in sel], [r["q_fit"] for r in sel], style, label=lab)
            ax2.loglog([r["steps_per_period"] for r in sel],
                       [max(abs(-r["freq_err_ppm"] - exact_ppm), 1e-3) for r in sel], style, label=lab)
    ax.axhline(Q_TRUE, color="grey", ls="--", lw=0.8, label="true Q")
    ax.set(xlabel="steps per period", ylabel="fitted Q of the ring-down", ylim=(0, 1.3 * Q_TRUE),
           title=f"numerical damping, lone Q={Q_TRUE:g} oscillator")
    ax2.set(xlabel="steps per period", ylabel="|frequency error - exact (-3.1 ppm)| [ppm]",
            title="phase drift (frequency error)")
    ax.legend(fontsize=8)
    ax2.legend(fontsize=8)
    fig.suptitle(MACHINE)
    fig.tight_layout()
    files.append(_save(fig, out / "speed_accuracy_damping.png"))

    fig, ax = plt.subplots(figsize=(7, 5))
    rows = res["scaling"]["rows"]
    n = [r["oscillators"] for r in rows]
    ax.loglog(n, [r["rk4_s"] for r in rows], "k-o",
              label=f"RK4 ({res.get('rk4_kernel', 'numpy')} kernel, {res['scaling']['rk4_steps_per_period']} steps/period)")
    ax.loglog(n, [r["ngspice_s"] for r in rows], "g-s", label="ngspice (defaults)")
    ax.set(xlabel="oscillators", ylabel=f"wall time for {SCALING_PERIODS} periods [s]",
           title=f"scaling, independent NOR gates ({MACHINE})")
    ax.legend()
    files.append(_save(fig, out / "speed_accuracy_scaling.png"))
    return files


def _save(fig, path: Path) -> str:
    fig.savefig(path, dpi=120)
    import matplotlib.pyplot as plt
    plt.close(fig)
    return path.name


# --- the report ---------------------------------------------------------------------------------------------
def _row_label(r: dict) -> str:
    if r["backend"] == "rk4":
        return "RK4"
    return f"ngspice {r['method']}" + (f", reltol {r['reltol']:g}" if "reltol" in r else "")


def _acc_table(name: str, d: dict) -> list[str]:
    out = [f"Design **{name}** ({d['cases']} case(s), {d['periods']} periods, probes {', '.join(d['probes'])}); "
           f"reference RK4 at {REF_STEPS} steps/period; machine {MACHINE}.", "",
           "| design | backend | step | wall [s] | amp err [u_R] | phase err [deg] | trajectory err [u_R] | steps at max |",
           "|---|---|---|---|---|---|---|---|"]
    for r in d["rows"]:
        if r.get("reference"):
            out.append(f"| {name} | RK4 (reference) | T/{r['steps_per_period']} | {r['wall_s']:.2f} | 0 | 0 | 0 | - |")
        elif "amp_err_ur" in r:
            uni = f"{r['uniform_fraction']:.0%}" if "uniform_fraction" in r else "-"
            out.append(f"| {name} | {_row_label(r)} | T/{r['steps_per_period']} | {r['wall_s']:.2f} | "
                       f"{r['amp_err_ur']:.4f} | {r['phase_err_deg']:.2f} | {r['traj_err_ur']:.4f} | {uni} |")
        else:
            out.append(f"| {name} | {_row_label(r)} | T/{r['steps_per_period']} | failed: {r['failed'][:80]} | | | | |")
    return out + [""]


def _first_ok(rows, backend, method=None, reltol=None, tol=0.01, phase=2.0, traj=math.inf):
    """The coarsest step meeting the tolerances (settled amplitude and phase, trajectory), or None."""
    ok = [r for r in rows if r["backend"] == backend and r.get("method") == method and "amp_err_ur" in r
          and (reltol is None or r.get("reltol") == reltol) and not r.get("reference")
          and r["amp_err_ur"] < tol and r["phase_err_deg"] < phase and r["traj_err_ur"] < traj]
    return min(ok, key=lambda r: r["steps_per_period"]) if ok else None


def _find(rows, **kw):
    return next((r for r in rows if all(r.get(k) == v for k, v in kw.items()) and "amp_err_ur" in r), None)


def _form(res: dict) -> list[str]:
    """The circuit form and why, with the numbers measured below."""
    pin = {(r["prewarp"], r["reltol"], r["trtol"]): r for r in res.get("pinning", {}).get("rows", [])}
    dmp = {(r.get("method"), r["steps_per_period"]): r for r in res.get("damping", {}).get("rows", [])}
    out = ["## Circuit form", "",
           "Mobility analogy, two nodes per oscillator: velocity node with C = m, conductance c_local and a VCCS "
           "k_local*V(x) to ground, drives as B current sources; displacement node = 1 F capacitor fed by a VCCS "
           "V(v); each coupling spring one VCCS k*(V(x_i)-V(x_j)) between v_i and v_j, each dashpot one "
           "conductance between v_i and v_j; quadratic couplings B sources in V(x). With method=trap every "
           "capacitor of an oscillating DOF is scaled by w = (omega h/2)/tan(omega h/2) (prewarp) and the step "
           "is pinned at h (trtol 1e4)."]
    a, b = pin.get((True, 1e-3, 1e4)), pin.get((False, 1e-3, 7.0))
    if a and b:
        out.append(f"- Linear 3-DOF chain with negative local k and c, T/40: phasor error {a['rel_err']:.1e} with "
                   f"prewarp, {b['rel_err']:.1e} without.")
    c = pin.get((True, 1e-6, 7.0))
    if c:
        out.append(f"- Without the pinned step (trtol 7, reltol 1e-6) only {c['uniform_fraction']:.0%} of the steps "
                   f"stay at h and the error is {c['rel_err']:.1e}.")
    p40, t40, g40 = dmp.get(("trap+prewarp", 40)), dmp.get(("trap", 40)), dmp.get(("gear", 40))
    if p40 and t40 and g40:
        out.append(f"- Lone Q=200 oscillator at T/40: free-oscillation frequency error {p40['freq_err_ppm']:.1f} ppm "
                   f"(prewarp; exact -3.1 ppm), {t40['freq_err_ppm']:.0f} ppm (plain trap), gear Q "
                   f"{g40['q_fit']:.0f} instead of 200. The prewarp's cost: envelope time scales stretched by "
                   f"omega h / sin(omega h) (fitted Q {p40['q_fit']:.1f} at T/40), visible as trajectory error.")
    return out + [""]


def render(res: dict) -> str:
    acc, dmp, sc, pin = res.get("accuracy", {}), res.get("damping", {}), res.get("scaling", {}), res.get("pinning", {})
    d = res["default_options"]
    L = [f"# Speed vs accuracy: RK4 and ngspice backends", "",
         f"All numbers measured by `benchmarks/speed_accuracy.py` on the **{MACHINE}** (Python {res['python']}, "
         f"ngspice 39, no KLU), total script time {res.get('total_wall_s', 0) / 60:.1f} min. Amplitudes in u_R = "
         f"{P.u_r}; errors against RK4 at {REF_STEPS} steps/period (converged: RK4 at 80 differs from it by "
         f"< 0.0002 u_R). ngspice wall times are one-core times (sum over cases of each process's wall time).", ""]
    if res.get("note"):
        L += [f"Provenance: {res['note']}", ""]
    L += _form(res) + [f"RK4 runs the project's {res.get('rk4_kernel', 'numpy')} kernel; ngspice runs as a subprocess "
          "(`ngspice -b -n -r`), time including netlist emission and raw-file reading.", ""]
    L += ["## Recommended defaults", "",
          f"`SpiceOptions(method=\"{d['method']}\", max_step_periods=1/{round(1 / d['max_step_periods'])}, "
          f"reltol={d['reltol']:g}, abstol={d['abstol']:g}, chgtol={d['chgtol']:g}, vntol={d['vntol']:g}, "
          f"prewarp=True, trtol=auto (1e4 with prewarp))`.", ""]
    for name, dd in acc.items():
        rows = dd["rows"]
        r40 = _find(rows, backend="rk4", steps_per_period=40)
        ng = _find(rows, backend="ngspice", method="trap+prewarp", reltol=d["reltol"],
                   steps_per_period=round(1 / d["max_step_periods"]))
        if r40 and ng:
            L.append(f"- {name}: ngspice at its defaults took {ng['wall_s'] / r40['wall_s']:.0f}x the time of RK4 at "
                     f"T/40 ({res.get('rk4_kernel', 'numpy')} kernel): ngspice is the independent check and the "
                     "exportable netlist, not the fast path.")
            L.append(f"- {name}, {dd['periods']} periods, {MACHINE}: ngspice defaults {ng['wall_s']:.2f} s, "
                     f"error {ng['amp_err_ur']:.4f} u_R / {ng['phase_err_deg']:.2f} deg (trajectory "
                     f"{ng['traj_err_ur']:.4f} u_R); RK4 at T/40 {r40['wall_s']:.2f} s, error {r40['amp_err_ur']:.4f} "
                     f"u_R / {r40['phase_err_deg']:.2f} deg (trajectory {r40['traj_err_ur']:.4f} u_R).")
    L += ["", "## Failure points", ""]
    for name, dd in acc.items():
        rows = dd["rows"]
        for label, backend, method in (("RK4", "rk4", None), ("ngspice trap+prewarp", "ngspice", "trap+prewarp"),
                                       ("ngspice trap (no prewarp)", "ngspice", "trap"),
                                       ("ngspice gear", "ngspice", "gear")):
            reltol = None if backend == "rk4" else d["reltol"] if method == "trap+prewarp" else 1e-3
            cell = []
            for what, traj in (("settled", math.inf), ("settled and whole trajectory", 0.01)):
                ok = _first_ok(rows, backend, method, reltol, traj=traj)
                cell.append(f"{what}: " + (f"T/{ok['steps_per_period']} ({ok['wall_s']:.2f} s, {ok['amp_err_ur']:.4f} u_R, "
                                           f"{ok['phase_err_deg']:.2f} deg, trajectory {ok['traj_err_ur']:.4f} u_R)"
                                           if ok else "none of the steps measured"))
            L.append(f"- {name}, {label}" + (f" (reltol {reltol:g})" if reltol else "")
                     + " - coarsest step within 0.01 u_R and 2 deg, " + "; ".join(cell))
    L += ["", "## Stability limits", ""]
    st = res.get("stability", {})
    for name, dd in st.items():
        div = [r for r in dd["rows"] if "failed" in r]
        rk = [r for r in dd["rows"] if r["backend"] == "rk4" and "amp_err_ur" in r]
        L.append(f"- {name}, RK4 at 4..9 steps/period ({dd['periods']} periods): "
                 + (f"diverged at {', '.join(str(r['steps_per_period']) for r in div)}" if div else
                    "no divergence; the error instead grows to " + ", ".join(
                        f"{r['amp_err_ur']:.2f} u_R at T/{r['steps_per_period']}" for r in rk[:3]))
                 + f"; 3 steps/period: {dd['rk4_3_steps']}")
        ngc = [r for r in dd["rows"] if r["backend"] == "ngspice"]
        L.append(f"- {name}, ngspice at T/4..T/8 (600 periods, step pinned by trtol 1e4): " + "; ".join(
            f"{r['method']} T/{r['steps_per_period']}: " + (f"{r['amp_err_ur']:.3f} u_R, {r['phase_err_deg']:.1f} deg"
                                                            if "amp_err_ur" in r else f"failed ({r['failed'][:60]})")
            for r in ngc))
    tol = res.get("tolerances", {})
    if tol:
        L += ["", "## Newton tolerances at the default step", "",
              f"Settled and trajectory errors against RK4 at {REF_STEPS} steps/period; trap+prewarp at "
              f"T/{round(1 / d['max_step_periods'])}; the accuracy tables hold vntol 1e-9 at reltol 1e-3 and 1e-5; "
              f"{MACHINE}.", "",
              "| design | backend | step | reltol | vntol | wall [s] | amp err [u_R] | phase err [deg] | trajectory err [u_R] |",
              "|---|---|---|---|---|---|---|---|---|"]
        for name, dd in tol.items():
            rows = dd["rows"] + [r | {"vntol": d["vntol"]} for r in acc.get(name, {}).get("rows", [])
                                 if r.get("method") == "trap+prewarp" and "amp_err_ur" in r
                                 and r["steps_per_period"] == round(1 / d["max_step_periods"])]
            for r in sorted(rows, key=lambda r: (r["vntol"], -r["reltol"])):
                if "amp_err_ur" in r:
                    L.append(f"| {name} | ngspice trap+prewarp | T/{r['steps_per_period']} | {r['reltol']:g} | "
                             f"{r['vntol']:g} | {r['wall_s']:.2f} | {r['amp_err_ur']:.4f} | {r['phase_err_deg']:.2f} | "
                             f"{r['traj_err_ur']:.4f} |")
    if pin:
        L += ["", "## Prewarp needs every step at max_step", "",
              f"{pin['model']}; error = max |A - A_exact| / max |A_exact| of the steady phasors; {MACHINE}.", "",
              "| backend | prewarp | reltol | trtol | rel. error | steps at max step |", "|---|---|---|---|---|---|"]
        for r in pin["rows"]:
            L.append(f"| ngspice trap T/40 | {r['prewarp']} | {r['reltol']:g} | {r['trtol']:g} | {r['rel_err']:.2e} | "
                     f"{r['uniform_fraction']:.0%} |")
    if dmp:
        L += ["", "## Numerical damping and phase drift (lone oscillator)", "",
              f"One oscillator (m = 1, resonant at the drive, Q = {dmp['q_true']:g}) driven for "
              f"{dmp['driven_periods']} periods, then released; fit over periods {dmp['fit_periods'][0]}-"
              f"{dmp['fit_periods'][1]} of |A| (Q) and of the phase against the drive clock (frequency error); "
              f"ngspice at the default reltol {d['reltol']:g} with every step pinned at the max step (trtol 1e4); "
              f"{MACHINE}.", "",
              "| design | backend | step | fitted Q | Q error | free-oscillation freq. error [ppm] | phase drift [deg / 100 T] |",
              "|---|---|---|---|---|---|---|"]
        exact = -1e6 * (1 - math.sqrt(1 - 1 / (4 * dmp["q_true"] ** 2)))
        L.append(f"| lone Q=200 oscillator | exact (omega_d = omega sqrt(1 - 1/4Q^2)) | - | {dmp['q_true']:.1f} | 0 | "
                 f"{exact:.1f} | {np.degrees(2 * math.pi * exact * 1e-6) * 100:.2f} |")
        for r in dmp["rows"]:
            L.append(f"| lone Q=200 oscillator | {_row_label(r)} | T/{r['steps_per_period']} | {r['q_fit']:.1f} | "
                     f"{r['q_fit'] / dmp['q_true'] - 1:+.1%} | {r['freq_err_ppm']:.1f} | {r['phase_drift_deg_per_100T']:.2f} |")
    if sc:
        L += ["", "## Scaling", "",
              f"Independent NOR gates (6 oscillators each, inputs '0'), {sc['periods']} periods; RK4 at "
              f"{sc['rk4_steps_per_period']} steps/period ({res.get('rk4_kernel', 'numpy')} kernel), ngspice with "
              f"the default options "
              f"(emission + run + read); {MACHINE}.", "",
              "| design | oscillators | RK4 [s] | ngspice [s] | ngspice / RK4 | max |A| difference [u_R] |", "|---|---|---|---|---|---|"]
        for r in sc["rows"]:
            L.append(f"| {r['gates']} independent NOR gates | {r['oscillators']} | {r['rk4_s']:.2f} | "
                     f"{r['ngspice_s']:.2f} | {r['ngspice_s'] / r['rk4_s']:.2f} | {r['max_diff_ur']:.4f} |")
    L += ["", "## Accuracy tables", ""]
    for name, dd in acc.items():
        L += _acc_table(name, dd)
    L += ["## Charts", ""] + [f"![{c}]({c})" for c in res.get("charts", [])] + [""]
    return "\n".join(L)


def markdown(res: dict) -> str:
    return render(res)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer points (a smoke run, ~2 min)")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent.parent / "reports"))
    ap.add_argument("--render", action="store_true", help="only rewrite the .md/.png from the .json")
    ap.add_argument("--only", choices=["pinning", "accuracy", "tolerances", "stability", "damping", "scaling"],
                    action="append")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    _warm_up()
    t0 = time.perf_counter()
    res = {"machine": MACHINE, "python": platform.python_version(), "periods": PERIODS, "avg": AVG,
           "rk4_kernel": "numba" if _numba() else "numpy",
           "reference": f"RK4 at {REF_STEPS} steps/period", "default_options": asdict(SpiceOptions())}
    jpath = out / "speed_accuracy.json"
    if args.render:
        res = json.loads(jpath.read_text())
        res["charts"] = charts(res, out)
        (out / "speed_accuracy.md").write_text(markdown(res))
        return 0
    if args.only and jpath.exists():                 # refresh some sections, keep the others
        res = {**json.loads(jpath.read_text()), **{k: v for k, v in res.items()}}
    sections = {"pinning": pinning, "accuracy": lambda: accuracy(args.quick), "tolerances": tolerances,
                "stability": stability,
                "damping": lambda: damping(args.quick), "scaling": lambda: scaling(args.quick)}
    for name, fn in sections.items():
        if not args.only or name in args.only:
            res[name] = fn()
    res["partial_rerun_s" if args.only else "total_wall_s"] = time.perf_counter() - t0
    jpath.write_text(json.dumps(res, indent=1, default=_json))
    res = json.loads(jpath.read_text())
    res["charts"] = charts(res, out)
    jpath.write_text(json.dumps(res, indent=1))
    (out / "speed_accuracy.md").write_text(markdown(res))
    print(f"wrote {jpath}, {out / 'speed_accuracy.md'}, charts {res['charts']} in {res['total_wall_s']:.0f} s")
    return 0


def _numba() -> bool:
    try:
        from mech2spice import rk4_kernel
        return bool(rk4_kernel.AVAILABLE)
    except ImportError:
        return False


def _warm_up() -> None:
    """Compile RK4's kernel (numba caches it) and start ngspice once, outside every timing."""
    m, st = gate_design()
    rk4.integrate(m, 2, steps_per_period=40, stimulus=st)
    ngspice.run(m, 2)


def _json(o):
    if isinstance(o, np.ndarray):
        return np.abs(o).tolist() if np.iscomplexobj(o) else o.tolist()
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    raise TypeError(type(o))


if __name__ == "__main__":
    raise SystemExit(main())
