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

from ..backends import make_engine, rk4
from ..run_result import Run
from ..errors import DivergenceError
from ..physics import loaded, nor, steady
from ..physics.envelope import Envelope
from ..physics.params import GateParams
from ..physics.stimulus import Stimulus
from .scenes import (FANOUT_CASES, PAIRS, Scene, cascade_edges, mid, chain_scene, fanout_scene, gate_scene,
                     input_amps, latch_scene, levels_stimulus, nominal_levels)

def _nor(a: int, b: int) -> int:
    return int(not (a or b))


def run_from_rest(model, p: GateParams, levels: np.ndarray, periods: int,
                  steps: int = rk4.DEFAULT_STEPS_PER_PERIOD, avg: int = 20, **kw):
    """RK4 from rest with constant input levels (B, 2); returns (run, amplitude per probe (n_probes, B) in u_R)."""
    run = rk4.integrate(model, periods, steps_per_period=steps, stimulus=levels_stimulus(model, p, [(0, levels)]), **kw)
    return run, np.abs(run.amp[-avg:]).mean(axis=0) / p.u_r


# --- steady-state side ---------------------------------------------------------
def gate_forcing(p: GateParams, x1: np.ndarray, x2: np.ndarray) -> tuple[Envelope, np.ndarray, int]:
    """Envelope of a single gate and its forcing for input levels x1, x2 (arrays), plus the channel's row."""
    m = nor.single_gate(p)
    env = Envelope(m)
    levels = np.stack([np.atleast_1d(x1), np.atleast_1d(x2)], axis=1)
    amps = np.repeat(m.arrays["drive_amp"][:, None], levels.shape[0], axis=1)
    for d, a in input_amps(m.design.input_drives, levels, p).items():
        amps[d] = a
    return env, env.forcing(amps), int(np.flatnonzero(env.fast == m.probes["g0"])[0])


def steady_outputs(p: GateParams, x1, x2) -> list[list[tuple[float, bool]]]:
    """For each input pair: [(channel amplitude in u_R, stable)] over all steady states."""
    env, F, ch = gate_forcing(p, x1, x2)
    if env.slow.size == 1 and not env.diagonal:       # a block with internal couplings (physics/blocks.py)
        return _coupled_steady_outputs(p, x1, x2)
    return [[(abs(s.A[ch]) / p.u_r, s.stable) for s in steady.steady_states(env, F[:, b])]
            for b in range(F.shape[1])]


def _coupled_steady_outputs(p: GateParams, x1, x2) -> list[list[tuple[float, bool]]]:
    """steady_outputs for a block whose oscillators are coupled inside it: the batched all-roots scan
    (physics/steady_batch.py, coupled fast DOFs, one insulator) over every input pair at once."""
    from ..physics import steady_batch
    m = nor.single_gate(p, 1.0, 1.0)
    groups = np.zeros(len(m.drives), int)
    for k, drives in enumerate(m.design.input_drives):
        groups[list(drives)] = k + 1
    x1, x2 = np.atleast_1d(x1).astype(float), np.atleast_1d(x2).astype(float)
    r = steady_batch.roots(steady_batch.stack([m], groups, m.probes["g0"]), 0,
                           np.stack([np.ones_like(x1), x1, x2], axis=1))
    return [[(a / p.u_r, bool(ok)) for a, ok in zip(r.amp[r.point == k], r.stable[r.point == k])]
            for k in range(x1.size)]


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
    lv = p.levels
    levels = loaded.band_levels(lv, per_band)
    X1, X2 = np.meshgrid(levels, levels, indexing="ij")
    x1, x2 = X1.ravel(), X2.ravel()
    res = steady_outputs(p, x1, x2)
    worst = {"min_margin": math.inf}
    multistable = 0
    for k, states in enumerate(res):
        st = [a for a, ok in states if ok]
        expect = _nor(lv.band_of(x1[k]), lv.band_of(x2[k]))
        if len(st) != 1:
            multistable += 1
            mg = -1.0
        else:
            mg = lv.margin(st[0], expect)
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
        nominal = np.array([p.levels.nominal0, p.levels.nominal1])
        outs = steady_outputs(q, nominal, nominal)
        amp00.append(max(a for a, _ in outs[0]))
        amp11.append(min(a for a, _ in outs[1]))
    amp00, amp11 = np.array(amp00), np.array(amp11)
    k = int(np.argmax(amp00 - amp11))
    return {"omega": omegas, "amp00": amp00, "amp11": amp11,
            "max_channel_amplitude": float(max(amp00.max(), amp11.max())),
            "max_switch_contrast": float(amp00[k] - amp11[k]), "at_omega": float(omegas[k])}


# --- time-domain side ----------------------------------------------------------
def truth_table(p: GateParams, periods: int = 3000, steps: int = rk4.DEFAULT_STEPS_PER_PERIOD) -> dict:
    """The four nominal input pairs on RK4 from rest, decoded (rows) and the run (to continue from)."""
    model = nor.single_gate(p)
    try:
        run, amp = run_from_rest(model, p, nominal_levels(p), periods, steps)
    except DivergenceError as e:
        return {"diverged": str(e), "rows": []}
    rows = []
    for b, (x1, x2) in enumerate(PAIRS):
        a = float(amp[0, b])
        expect = _nor(x1, x2)
        rows.append({"inputs": [x1, x2], "output_amplitude": a, "logic": p.levels.band_of(a), "expected": expect,
                     "margin": p.levels.margin(a, expect)})
    return {"rows": rows, "run": run}


def transient(p: GateParams, sequence=((0, 0), (1, 0), (0, 0), (0, 1), (1, 1), (0, 0), (1, 1), (1, 0), (0, 0)),
              hold: int = 1200) -> dict:
    """Single gate under changing inputs; also tests history independence (revisits give the same output)."""
    model = nor.single_gate(p)
    stim = levels_stimulus(model, p, [(k * hold, np.array([[p.levels.nominal(a), p.levels.nominal(b)]])) for k, (a, b) in enumerate(sequence)])
    run = rk4.integrate(model, hold * len(sequence), stimulus=stim)
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
    Other members: constant inputs at band edges, for level restoration (scenes.chain_scene)."""
    sc = chain_scene(p, hold)
    run = rk4.integrate(sc.model, sc.periods, stimulus=sc.stimulus)
    amp = np.abs(run.amp) / p.u_r                         # (P, 3 stages, B)
    lv = p.levels
    delays = [_crossings(amp[:, :, 0], start, mid(lv)) for start in (hold, 2 * hold)]
    per_gate = [d for ds in delays for d in np.diff([0.0] + ds)]
    restoration = []
    for b, (x1, x2) in enumerate(cascade_edges(lv), start=1):
        settled = amp[-20:, :, b].mean(axis=0)        # constant inputs: settle over all 3 holds
        expect = _nor(lv.band_of(x1), lv.band_of(x2))
        stage_margins = [lv.margin(float(a), (expect + k) % 2) for k, a in enumerate(settled)]
        restoration.append({"inputs": [x1, x2], "outputs": settled.tolist(), "stage_margins": stage_margins,
                            "input_margin": min(lv.margin(x1), lv.margin(x2))})
    return {"t_periods": np.arange(1, amp.shape[0] + 1), "amplitude": amp[:, :, 0], "hold": hold,
            "delays": delays, "delay_periods": float(np.mean(per_gate)), "delay_max": float(np.max(per_gate)),
            "restoration": restoration}


def _crossings(amp: np.ndarray, start: int, threshold: float) -> list[float]:
    """Periods after `start` at which each stage's amplitude first crosses the threshold between the bands."""
    out = []
    for k in range(amp.shape[1]):
        a = amp[start:, k] - threshold
        idx = np.flatnonzero(np.sign(a[:-1]) != np.sign(a[1:]))
        out.append(float(idx[0] + 1) if idx.size else math.nan)
    return out


def fanout_test(p: GateParams, n_loads: int, periods: int = 2500) -> dict:
    """Driver at 00 / 10 with every load's other input at 0 / 1: loads decode correctly and the
    driver's channel barely feels the loads switching (scenes.fanout_scene)."""
    sc = fanout_scene(p, n_loads, periods)
    run = rk4.integrate(sc.model, sc.periods, stimulus=sc.stimulus)
    amp = np.abs(run.amp[-20:]).mean(axis=0) / p.u_r        # (1 + n_loads, B)
    ok, worst = True, math.inf
    for b, (a, bb, c) in enumerate(FANOUT_CASES):
        d = _nor(a, bb)
        ok &= p.levels.band_of(amp[0, b]) == d
        for k in range(n_loads):
            ok &= p.levels.band_of(amp[1 + k, b]) == _nor(d, c)
            worst = min(worst, p.levels.margin(amp[1 + k, b], _nor(d, c)))
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
    levels = nominal_levels(p)
    base = run_from_rest(nor.single_gate(p), p, levels, periods)[1][0]
    worst = 0.0
    for th1, th2 in [(2.1, 0.7), (4.0, 5.5)]:
        m = nor.single_gate(p)
        for drives, th in zip(m.design.input_drives, (th1, th2)):     # every link of the input
            for d in drives:
                m.drives[d].phase += th
        m.invalidate()
        worst = max(worst, float(np.abs(run_from_rest(m, p, levels, periods)[1][0] - base).max()))
    return {"max_output_change": worst, "phases_tested": [[2.1, 0.7], [4.0, 5.5]]}


def convergence(p: GateParams, periods: int = 1500, steps: int = rk4.DEFAULT_STEPS_PER_PERIOD) -> float:
    """Change of the four outputs when the RK4 step is halved from `steps` per period (u_R)."""
    levels = nominal_levels(p)
    a1 = run_from_rest(nor.single_gate(p), p, levels, periods, steps, avg=1)[1][0]
    a2 = run_from_rest(nor.single_gate(p), p, levels, periods, 2 * steps, avg=1)[1][0]
    return float(np.abs(a1 - a2).max())


def stability(p: GateParams, per_band: int = 8, periods: int = 3000) -> dict:
    """The block's least damped mode (issue #25, docs/stability.md): over every valid input pair of the
    single gate (its steady states' linearisation), and in the 3-gate chain at the four nominal input pairs
    (an envelope run settled, then the network's verdict).  Growth per drive period: < 0 decays."""
    from ..backends import make_engine
    from ..physics import stability as stab
    levels = loaded.band_levels(p.levels, per_band)
    worst = {"growth_rate": -math.inf}
    x1, x2 = (g.ravel() for g in np.meshgrid(levels, levels, indexing="ij"))
    env, F, ch = gate_forcing(p, x1, x2)
    T = env.model.period
    for k in range(F.shape[1]):
        for st in steady.steady_states(env, F[:, k]) if env.slow.size == 1 and env.diagonal else []:
            mode = stab.leading_modes(env, st.A, st.s, k=1)[0][0]
            if mode.growth > worst["growth_rate"]:
                worst = {"growth_rate": mode.growth, "mode_period": mode.period,
                         "at_inputs": [float(x1[k]), float(x2[k])]}
    chain = []
    for a, b in PAIRS:
        m = nor.chain(p, 3, p.levels.nominal(a), p.levels.nominal(b))
        run = make_engine("envelope").run(m, periods)
        v = stab.verdict(m, run.state[0][:, 0], run.state[1][:, 0],
                         Envelope.of(m).forcing(np.array([[d.amplitude] for d in m.drives]))[:, 0])
        chain.append({"inputs": [a, b], **v.to_json()})
    lead = max(c["growth_rate"] if c["growth_rate"] is not None else math.inf for c in chain)
    return {"single_gate": worst, "chain": chain,
            "stable": worst["growth_rate"] < stab.STABLE_MARGIN and all(c["stable"] for c in chain),
            "worst_growth_rate": max(worst["growth_rate"], lead)}


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
    ss = steady_outputs(p, np.array([p.levels.nominal(a) for a, _ in PAIRS]), np.array([p.levels.nominal(b) for _, b in PAIRS]))
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
    log("stability (the least damped mode)")
    out["stability"] = stability(p, per_band=4 if quick else 8)
    out["requirements"] = requirements(out, vm, fo, ph, cas, tr, spectrum_purity(run, p))
    out["wall_s"] = time.time() - t0
    out["_figures"] = {"transient": tr, "cascade": cas}
    return out


def truth_table_stimulus(p: GateParams) -> Stimulus:
    """The four nominal input pairs as one batch on a single gate."""
    return gate_scene(p).stimulus


def requirements(out, vm, fo, ph, cas, tr, impurity) -> dict:
    """Pass/fail and a one-line figure for each of the gate's six requirements, from the measurements."""
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
def latch_sequence(p: GateParams, backend: str = "rk4", pulse: int = 800, hold: int = 2500) -> dict:
    """verilog/dff.v through scenes.latch_phases: store 1, hold while d toggles, store 0, hold while d toggles.

    Returns the output amplitude per period, the decoded output at the end of each phase, and when
    the output crossed the threshold relative to each storing pulse (it must wait out the pulse)."""
    sc = latch_scene(p, pulse, hold)
    # each engine's defaults (the envelope's: 4-period steps on the latch, as accurate as 1/2, reports/envelope.md)
    run = make_engine(backend).run(sc.model, sc.periods, sc.stimulus, probes=sc.probes)
    return latch_decode(sc, np.abs(run.amp[:, :, 0]) / p.u_r) | {"backend": backend}


def latch_decode(scene: Scene, amp: np.ndarray) -> dict:
    """The latch's output at the end of each phase (mean of its last 10 periods) and the threshold crossing
    after each storing pulse starts, from per-period amplitudes (P, probes) of a latch_scene run."""
    phases, starts = scene.extra["phases"], [0] + scene.windows
    lv = scene.model.levels
    decoded = [{"phase": name, "d": d, "clock": c, "output": float(amp[t1 - 10:t1, 0].mean()),
                "logic": lv.band_of(float(amp[t1 - 10:t1, 0].mean()))}
               for (name, d, c, _), t1 in zip(phases, starts[1:])]
    delays = []
    for k, (_, _, c, _) in enumerate(phases):
        if c:
            x = amp[starts[k]:, 0] - mid(lv)
            idx = np.flatnonzero(np.sign(x[:-1]) != np.sign(x[1:]))
            delays.append(float(idx[0] + 1) if idx.size else math.nan)
    return {"amplitude": amp, "starts": starts, "phases": phases, "decoded": decoded, "output_delays": delays,
            "pulse": phases[1][3]}
