"""Gate characterisation: the paper's six building-block requirements, measured.

Every figure comes from a simulation here: truth table, transients, cascade,
delay and fan-out from RK4; the input map and minimum margin from the
steady-state solver (whose agreement with RK4 is itself measured).
"""
from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from ..physics import nor, steady
from ..backends import rk4
from ..backends._base import Run
from ..physics.envelope import Envelope
from ..errors import DivergenceError
from ..physics.params import BAND0, BAND1, NOMINAL0, NOMINAL1, GateParams, band_of, margin
from ..physics.stimulus import Stimulus
from .. import data

PAIRS = [(0, 0), (1, 0), (0, 1), (1, 1)]
LEVEL = {0: NOMINAL0, 1: NOMINAL1}
MID = (BAND0[1] + BAND1[0]) / 2          # threshold between the bands, for delays


def _nor(a: int, b: int) -> int:
    return int(not (a or b))


def _input_amps(model, drives_of_inputs, levels: np.ndarray, p: GateParams) -> dict[int, np.ndarray]:
    """{drive index: (B,) amplitudes} for input pairs given levels (B, n_inputs) in units of F_R."""
    out = {}
    for k, (ds, dd) in enumerate(drives_of_inputs):
        out[ds] = out[dd] = levels[:, k] * p.f_r
    return out


def settle(model, p: GateParams, levels: np.ndarray, periods: int, steps: int = rk4.DEFAULT_STEPS_PER_PERIOD,
           avg: int = 20, **kw):
    """RK4 from rest with constant input levels (B, 2); returns (run, amplitude per probe (n_probes, B) in u_R)."""
    st = Stimulus.from_levels(model, [(0.0, _input_amps(model, model.design.input_drives, levels, p))],
                              batch=levels.shape[0])
    run = rk4.integrate(model, periods, steps_per_period=steps, stimulus=st, **kw)
    return run, np.abs(run.amp[-avg:]).mean(axis=0) / p.u_r


# --- steady-state side ---------------------------------------------------------
def gate_forcing(p: GateParams, x1: np.ndarray, x2: np.ndarray) -> tuple[Envelope, np.ndarray, int]:
    """Envelope of a single gate and its forcing for input levels x1, x2 (arrays), plus the channel's row."""
    m = nor.single_gate(p)
    env = Envelope(m)
    levels = np.stack([np.atleast_1d(x1), np.atleast_1d(x2)], axis=1)
    amps = np.repeat(m.arrays["drive_amp"][:, None], levels.shape[0], axis=1)
    for d, a in _input_amps(m, m.design.input_drives, levels, p).items():
        amps[d] = a
    return env, env.forcing(amps), int(np.flatnonzero(env.fast == m.probes["g0"])[0])


def steady_outputs(p: GateParams, x1, x2) -> list[list[tuple[float, bool]]]:
    """For each input pair: [(channel amplitude in u_R, stable)] over all steady states."""
    env, F, ch = gate_forcing(p, x1, x2)
    return [[(abs(s.A[ch]) / p.u_r, s.stable) for s in steady.steady_states(env, F[:, b])]
            for b in range(F.shape[1])]


def steady_map(p: GateParams, n: int = 61, lo: float = 0.2, hi: float = 1.15):
    """Output amplitude of the unique stable state on an n x n input grid (NaN: none or several)."""
    xs = np.linspace(lo, hi, n)
    X1, X2 = np.meshgrid(xs, xs, indexing="ij")
    res = steady_outputs(p, X1.ravel(), X2.ravel())
    out = np.full(X1.size, np.nan)
    nstable = np.zeros(X1.size, int)
    for k, states in enumerate(res):
        st = [a for a, ok in states if ok]
        nstable[k] = len(st)
        if len(st) == 1:
            out[k] = st[0]
    return xs, out.reshape(X1.shape), nstable.reshape(X1.shape)


def valid_region_margin(p: GateParams, per_band: int = 15) -> dict:
    """Worst output margin (fraction of band width) over every valid input pair; multistability or no stable
    state counts as failure at that point."""
    levels = np.concatenate([np.linspace(*BAND0, per_band), np.linspace(*BAND1, per_band)])
    X1, X2 = np.meshgrid(levels, levels, indexing="ij")
    x1, x2 = X1.ravel(), X2.ravel()
    res = steady_outputs(p, x1, x2)
    worst = {"min_margin": math.inf}
    multistable = 0
    for k, states in enumerate(res):
        st = [a for a, ok in states if ok]
        expect = _nor(band_of(x1[k]), band_of(x2[k]))
        if len(st) != 1:
            multistable += 1
            mg = -1.0
        else:
            mg = margin(st[0], expect)
        if mg < worst["min_margin"]:
            worst = {"min_margin": mg, "at_inputs": [float(x1[k]), float(x2[k])],
                     "output": st[0] if len(st) == 1 else None, "n_stable": len(st)}
    worst["multistable_points"] = multistable
    worst["grid_points"] = int(x1.size)
    return worst


def omega_scan(p: GateParams, omegas: np.ndarray) -> dict:
    """Steady channel amplitude for inputs 00 and 11 over drive frequencies (the printed set's failure)."""
    amp00, amp11 = [], []
    for w in omegas:
        q = replace(p, omega=float(w))
        outs = steady_outputs(q, np.array([NOMINAL0, NOMINAL1]), np.array([NOMINAL0, NOMINAL1]))
        amp00.append(max(a for a, _ in outs[0]))
        amp11.append(min(a for a, _ in outs[1]))
    amp00, amp11 = np.array(amp00), np.array(amp11)
    k = int(np.argmax(amp00 - amp11))
    return {"omega": omegas, "amp00": amp00, "amp11": amp11,
            "max_channel_amplitude": float(max(amp00.max(), amp11.max())),
            "max_switch_contrast": float(amp00[k] - amp11[k]), "at_omega": float(omegas[k])}


# --- time-domain side ----------------------------------------------------------
def truth_table(p: GateParams, periods: int = 3000, steps: int = rk4.DEFAULT_STEPS_PER_PERIOD) -> dict:
    levels = np.array([[LEVEL[a], LEVEL[b]] for a, b in PAIRS])
    model = nor.single_gate(p)
    try:
        run, amp = settle(model, p, levels, periods, steps)
    except DivergenceError as e:
        return {"diverged": str(e), "rows": []}
    rows = []
    for b, (x1, x2) in enumerate(PAIRS):
        a = float(amp[0, b])
        expect = _nor(x1, x2)
        rows.append({"inputs": [x1, x2], "output_amplitude": a, "logic": band_of(a), "expected": expect,
                     "margin": margin(a, expect)})
    return {"rows": rows, "run": run}


def transient(p: GateParams, sequence=((0, 0), (1, 0), (0, 0), (0, 1), (1, 1), (0, 0), (1, 1), (1, 0), (0, 0)),
              hold: int = 1200) -> dict:
    """Single gate under changing inputs; also tests history independence (revisits give the same output)."""
    model = nor.single_gate(p)
    segs = [(k * hold * p.period, _input_amps(model, model.design.input_drives,
                                               np.array([[LEVEL[a], LEVEL[b]]]), p))
            for k, (a, b) in enumerate(sequence)]
    run = rk4.integrate(model, hold * len(sequence), stimulus=Stimulus.from_levels(model, segs))
    amp = run.amplitude("g0")[:, 0] / p.u_r
    ends = {}
    for k, pair in enumerate(sequence):
        ends.setdefault(pair, []).append(float(amp[(k + 1) * hold - 10:(k + 1) * hold].mean()))
    spread = max(max(v) - min(v) for v in ends.values())
    return {"t_periods": np.arange(1, amp.size + 1), "amplitude": amp, "sequence": list(sequence),
            "hold": hold, "settled": {f"{a}{b}": v for (a, b), v in ends.items()}, "revisit_spread": spread}


def cascade(p: GateParams, hold: int = 1500) -> dict:
    """3-gate chain ((x1 NOR x2) NOR 0) NOR 0.

    Member 0: inputs 00 -> 10 -> 00, for the delay per gate in both directions.
    Other members: constant inputs at band edges, for level restoration."""
    edges = [(0.365, 0.365), (0.67, 0.365), (0.67, 0.67), (0.92, 0.365), (1.025, 0.67), (1.025, 1.025), (0.92, 0.92)]
    model = nor.chain(p, 3)
    B = 1 + len(edges)
    lv0 = np.array([[NOMINAL0, NOMINAL0]] + [list(e) for e in edges])
    lv1 = lv0.copy()
    lv1[0] = [NOMINAL1, NOMINAL0]
    drives = model.design.input_drives
    segs = [(0.0, _input_amps(model, drives, lv0, p)), (hold * p.period, _input_amps(model, drives, lv1, p)),
            (2 * hold * p.period, _input_amps(model, drives, lv0, p))]
    run = rk4.integrate(model, 3 * hold, stimulus=Stimulus.from_levels(model, segs, batch=B))
    amp = np.abs(run.amp) / p.u_r                         # (P, 3 stages, B)
    delays = [_crossings(amp[:, :, 0], start) for start in (hold, 2 * hold)]
    per_gate = [d for ds in delays for d in np.diff([0.0] + ds)]
    restoration = []
    for b, (x1, x2) in enumerate(edges, start=1):
        settled = amp[-20:, :, b].mean(axis=0)        # constant inputs: settle over all 3 holds
        expect = _nor(band_of(x1), band_of(x2))
        stage_margins = [margin(float(a), (expect + k) % 2) for k, a in enumerate(settled)]
        restoration.append({"inputs": [x1, x2], "outputs": settled.tolist(), "stage_margins": stage_margins,
                            "input_margin": min(margin(x1), margin(x2))})
    return {"t_periods": np.arange(1, amp.shape[0] + 1), "amplitude": amp[:, :, 0], "hold": hold,
            "delays": delays, "delay_periods": float(np.mean(per_gate)), "delay_max": float(np.max(per_gate)),
            "restoration": restoration}


def _crossings(amp: np.ndarray, start: int) -> list[float]:
    """Periods after `start` at which each stage's amplitude first crosses the mid threshold."""
    out = []
    for k in range(amp.shape[1]):
        a = amp[start:, k] - MID
        idx = np.flatnonzero(np.sign(a[:-1]) != np.sign(a[1:]))
        out.append(float(idx[0] + 1) if idx.size else math.nan)
    return out


def fanout_test(p: GateParams, n_loads: int, periods: int = 2500) -> dict:
    """Driver at 00 / 10 with every load's other input at 0 / 1: loads decode correctly and the
    driver's channel barely feels the loads switching."""
    cases = [(0, 0, 0), (0, 0, 1), (1, 0, 0), (1, 0, 1)]      # (drv x1, drv x2, load x2)
    model = nor.fanout(p, n_loads)
    lv = np.array([[LEVEL[a], LEVEL[b]] for a, b, _ in cases])
    amps = _input_amps(model, model.design.input_drives, lv, p)
    for pair in model.design.load_drives:
        amps.update(_input_amps(model, [pair], np.array([[LEVEL[c]] for *_, c in cases]), p))
    run = rk4.integrate(model, periods, stimulus=Stimulus.from_levels(model, [(0.0, amps)], batch=len(cases)))
    amp = np.abs(run.amp[-20:]).mean(axis=0) / p.u_r        # (1 + n_loads, B)
    ok, worst = True, math.inf
    for b, (a, bb, c) in enumerate(cases):
        d = _nor(a, bb)
        ok &= band_of(amp[0, b]) == d
        for k in range(n_loads):
            ok &= band_of(amp[1 + k, b]) == _nor(d, c)
            worst = min(worst, margin(amp[1 + k, b], _nor(d, c)))
    load_swing = float(max(abs(amp[0, 0] - amp[0, 1]), abs(amp[0, 2] - amp[0, 3])))
    branch_spread = float(np.ptp(amp[1:], axis=0).max()) if n_loads > 1 else 0.0
    return {"n_loads": n_loads, "correct": bool(ok), "driver": amp[0].tolist(), "loads": amp[1:].tolist(),
            "min_margin": float(worst), "driver_swing_with_load_state": load_swing, "branch_spread": branch_spread}


def spectrum_purity(run: Run, p: GateParams, periods: int = 20) -> float:
    """Largest fraction of a probe's RMS displacement that is not at omega, over the last `periods`."""
    x = run.traces                                          # (S, n_probes, B), one sample per step
    n = x.shape[0] // periods * periods
    seg = x[-n:]
    spec = np.abs(np.fft.rfft(seg, axis=0)) ** 2
    fund = spec[periods]
    return float(np.sqrt(1 - fund / spec.sum(axis=0)).max())


def phase_insensitivity(p: GateParams, periods: int = 2500) -> dict:
    """Shift each input pair's phase; the steady output must not change."""
    levels = np.array([[LEVEL[a], LEVEL[b]] for a, b in PAIRS])
    base = settle(nor.single_gate(p), p, levels, periods)[1][0]
    worst = 0.0
    for th1, th2 in [(2.1, 0.7), (4.0, 5.5)]:
        m = nor.single_gate(p)
        for (ds, dd), th in zip(m.design.input_drives, (th1, th2)):
            m.drives[ds].phase += th
            m.drives[dd].phase += th
        m.invalidate()
        worst = max(worst, float(np.abs(settle(m, p, levels, periods)[1][0] - base).max()))
    return {"max_output_change": worst, "phases_tested": [[2.1, 0.7], [4.0, 5.5]]}


def convergence(p: GateParams, periods: int = 1500, steps: int = rk4.DEFAULT_STEPS_PER_PERIOD) -> float:
    """Change of the four outputs when the RK4 step is halved from `steps` per period (u_R)."""
    levels = np.array([[LEVEL[a], LEVEL[b]] for a, b in PAIRS])
    a1 = settle(nor.single_gate(p), p, levels, periods, steps, avg=1)[1][0]
    a2 = settle(nor.single_gate(p), p, levels, periods, 2 * steps, avg=1)[1][0]
    return float(np.abs(a1 - a2).max())


def characterise(p: GateParams, quick: bool = False, log=lambda msg: None) -> dict:
    """Everything `mech2spice gate` reports.  quick=True shortens runs (tests)."""
    t0 = time.time()
    scale = 0.6 if quick else 1.0
    out: dict = {"params": p.to_dict()}
    log("truth table (RK4)")
    tt = truth_table(p, periods=int(3000 * scale))
    if "diverged" in tt:
        out.update(truth_table=[], diverged=tt["diverged"], switches=False)
        return out
    run = rk4.integrate(nor.single_gate(p), 20, stimulus=truth_table_stimulus(p), state=(tt["run"].x, tt["run"].v),
                        start_period=int(3000 * scale), trace_every=1)
    out["truth_table"] = tt["rows"]
    out["switches"] = all(r["logic"] == r["expected"] for r in tt["rows"])
    log("steady states and RK4 agreement")
    ss = steady_outputs(p, np.array([LEVEL[a] for a, _ in PAIRS]), np.array([LEVEL[b] for _, b in PAIRS]))
    out["steady_states"] = [[{"amplitude": a, "stable": ok} for a, ok in s] for s in ss]
    log("step halving")
    out["step_halving_change"] = convergence(p, periods=int(1500 * scale))
    out["steps_per_period"] = rk4.DEFAULT_STEPS_PER_PERIOD
    out["rk4_vs_steady"] = float(max(min(abs(a - r["output_amplitude"]) for a, ok in s if ok) if any(
        ok for _, ok in s) else math.inf for s, r in zip(ss, tt["rows"])))
    log("valid-region margin (steady state)")
    vm = valid_region_margin(p, per_band=8 if quick else 15)
    out["min_margin"] = vm["min_margin"]
    out["min_margin_detail"] = vm
    if not out["switches"]:
        log("frequency scan")
        scan = omega_scan(p, np.linspace(0.3, 60, 300 if quick else 1200))
        out["omega_scan"] = {k: v for k, v in scan.items() if not isinstance(v, np.ndarray)}
        out["wall_s"] = time.time() - t0
        out["requirements"] = {}
        return out
    log("cascade and delay")
    cas = cascade(p, hold=int(1500 * scale))
    out["delay_periods"] = cas["delay_periods"]
    out["delay_max_periods"] = cas["delay_max"]
    out["cascade"] = {"delays": cas["delays"], "restoration": cas["restoration"]}
    log("fan-out 2 and 3")
    fo = [fanout_test(p, n, periods=int(2500 * scale)) for n in (2, 3)]
    out["fanout"] = fo
    log("phase insensitivity")
    ph = phase_insensitivity(p, periods=int(2500 * scale))
    log("history independence")
    tr = transient(p, hold=int(1200 * scale))
    out["history_spread"] = tr["revisit_spread"]
    out["requirements"] = requirements(out, vm, fo, ph, cas, tr, spectrum_purity(run, p))
    out["wall_s"] = time.time() - t0
    out["_figures"] = {"transient": tr, "cascade": cas}
    return out


def truth_table_stimulus(p: GateParams) -> Stimulus:
    m = nor.single_gate(p)
    levels = np.array([[LEVEL[a], LEVEL[b]] for a, b in PAIRS])
    return Stimulus.from_levels(m, [(0.0, _input_amps(m, m.design.input_drives, levels, p))], batch=4)


def requirements(out, vm, fo, ph, cas, tr, impurity) -> dict:
    last_stage = min(min(r["stage_margins"][2] for r in cas["restoration"]), 1.0)
    return {
        "no_multistability": {"pass": vm["multistable_points"] == 0 and tr["revisit_spread"] < 0.01,
                              "figure": f"{vm['multistable_points']} of {vm['grid_points']} valid input pairs "
                                        f"multistable; revisits of an input differ by {tr['revisit_spread']:.1e} u_R"},
        "single_frequency": {"pass": impurity < 0.01,
                             "figure": f"{impurity:.2e} of the RMS displacement is off omega"},
        "fanout": {"pass": all(f["correct"] and f["min_margin"] > 0 for f in fo),
                   "figure": "; ".join(f"fan-out {f['n_loads']}: loads correct={f['correct']}, min margin "
                                       f"{f['min_margin']:.3f}, branch spread {f['branch_spread']:.1e} u_R"
                                       for f in fo)},
        "easy_to_drive": {"pass": max(f["driver_swing_with_load_state"] for f in fo) < 0.01,
                          "figure": "driver amplitude changes by at most "
                                    f"{max(f['driver_swing_with_load_state'] for f in fo):.1e} u_R when its loads "
                                    "switch"},
        # paper: deviations self-correct. Criterion: every band-edge input (margin 0) ends >= 0.1 band
        # widths inside the correct band after three gates.
        "level_restoration": {"pass": all(r["stage_margins"][2] >= r["input_margin"] + 0.1
                                          for r in cas["restoration"]),
                              "figure": f"band-edge inputs (margin 0) reach margin >= {last_stage:.2f} after 3 gates "
                                        "(criterion: >= 0.10)"},
        "phase_insensitivity": {"pass": ph["max_output_change"] < 1e-3,
                                "figure": f"output changes by {ph['max_output_change']:.1e} u_R under input "
                                          "phase shifts"},
    }


# --- the latch (paper Fig. 5b, 5d) -----------------------------------------------------------
def latch_sequence(p: GateParams, backend: str = "rk4", pulse: int = 800, settle: int = 2500) -> dict:
    """verilog/dff.v through a pulse sequence: store 1, hold while d toggles, store 0, hold while d toggles.

    Returns the output amplitude per period, the decoded output at the end of each phase, and when
    the output crossed the threshold relative to each storing pulse (it must wait out the pulse)."""
    from pathlib import Path
    from ..physics import network
    from ..backends import envelope
    from ..synthesis import synth
    nl = synth.synthesize(data.verilog("dff.v"))
    model = network.build(nl, p)
    phases = [("power-up d=0", 0, 0, settle), ("store 1", 1, 1, pulse), ("settle", 1, 0, settle),
              ("hold, d=0", 0, 0, settle), ("hold, d=1", 1, 0, settle), ("hold, d=0", 0, 0, settle),
              ("store 0", 0, 1, pulse), ("settle", 0, 0, settle), ("hold, d=1", 1, 0, settle),
              ("hold, d=0", 0, 0, settle)]
    starts = np.cumsum([0] + [ph[3] for ph in phases])
    stim = network.stimulus(model, nl, p, [(int(t), [{"d": d}]) for t, (_, d, _, _) in zip(starts, phases)],
                            clock=[[c] for _, _, c, _ in phases])
    probes = ["q[0]", "q0.m.C"]                  # the output, and the loop node's channel
    if backend == "rk4":
        run = rk4.integrate(model, int(starts[-1]), stimulus=stim, probes=probes)
    else:                       # 4-period steps: same accuracy as 1/2 (reports/envelope.md), 8x faster
        run = envelope.integrate(model, int(starts[-1]), step_periods=4.0, stimulus=stim, probes=probes)
    amp = np.abs(run.amp[:, :, 0]) / p.u_r
    decoded = [{"phase": name, "d": d, "clock": c, "output": float(amp[int(t1) - 10:int(t1), 0].mean()),
                "logic": band_of(float(amp[int(t1) - 10:int(t1), 0].mean()))}
               for (name, d, c, _), t1 in zip(phases, starts[1:])]
    delays = []
    for k, (name, _, c, _) in enumerate(phases):
        if c:
            x = amp[starts[k]:, 0] - MID
            idx = np.flatnonzero(np.sign(x[:-1]) != np.sign(x[1:]))
            delays.append(float(idx[0] + 1) if idx.size else math.nan)
    return {"amplitude": amp, "starts": starts.tolist(), "phases": phases, "decoded": decoded,
            "output_delays": delays, "pulse": pulse, "backend": backend}
