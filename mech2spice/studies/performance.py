"""What every fidelity level costs: RK4 (numba kernel), RK4 (numpy), envelope, ngspice (measured; the report,
mech2spice/reports/performance.py, renders performance.json).

Sections (each writes its part of reports/performance.json; reports/performance.md and the charts
reports/performance_*.png are rebuilt from the whole JSON every time):

  scaling   chains of NOR gates (nor.chain: 6 oscillators per gate, gate k+1 driven by gate k) from
            12 to 12000 oscillators: wall time per simulated period, oscillator-steps/s, peak memory
            (ru_maxrss of a fresh worker process per measurement; ngspice's own process separately).
  adder     verilog/adder2.v, all 16 input pairs from rest through simulation.run_physical (same settle
            rule for every backend), one worker per backend, run back to back.
  sqrt      verilog/sqrt.v (n = 2809, 7 clock cycles) through simulation.run_clocked_physical on the
            envelope backend; RK4 per-period cost measured on the same model and stimulus over the
            first periods, the whole run estimated from it (or run in full with --sqrt-rk4-full).
  profile   cProfile of envelope.integrate at 400 and 2000 oscillators (and 12000), a timing
            breakdown of the compiled RK4 kernel, and prototypes of the two fixes proposed in the report.
  sieve     (no measurement) the 8-bit processor running the sieve, estimated from the measured
            per-period costs at 12000 oscillators and simulation.clock_timing's formula.

  sqrt_rk4  (only when asked for) the whole sqrt schedule on RK4.

usage: mech2spice report performance [--only SECTION ...] [--out reports] [--quick] [--sqrt-rk4-full]
       (~15 min for all sections on a 2-core machine).  Each measurement runs in a worker process,
       `python -m mech2spice.studies.performance --worker SPEC`.
"""
from __future__ import annotations

import cProfile
import json
import math
import os
import platform
import pstats
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from .. import data
from ._common import SANDBOX, conditions, log, read_json, sections, write_json
from ..experiments.scenes import ADDER_INPUTS, sqrt_steps

MACHINE = f"{SANDBOX}, shared"
SECTIONS = ("scaling", "adder", "sqrt", "cpu", "profile")     # the default run
EXTRA_SECTIONS = ("sqrt_rk4",)                               # only when named
GATES = [2, 10, 50, 170, 500, 1000, 2000]           # x 6 oscillators: 12 ... 12000
SIEVE = {"gates": 2000, "oscillators": 12000, "cycles": 700, "logic_depth": 40}
NG_LIMIT_S = 240          # a single ngspice measurement predicted beyond this is not run

# target work per measurement, per backend: periods = clamp(target / oscillators, lo, hi)
PLAN = {
    "rk4": (650_000, 20, 20_000),
    "rk4_numpy": (250_000, 8, 400),
    "envelope": (6_000_000, 200, 40_000),
    "ngspice": (25_000, 10, 2_000),
}


# ==================================================================================================
# worker side: one measurement per fresh process
# ==================================================================================================
def _rss_mb(who=resource.RUSAGE_SELF) -> float:
    return resource.getrusage(who).ru_maxrss / 1024.0           # Linux: KiB


def _warm_rk4(compiled: bool = True) -> None:
    """Load (or compile) the numba kernel outside the timed region."""
    from ..physics import nor
    from ..backends import rk4
    from ..physics.params import DEFAULT
    rk4.integrate(nor.single_gate(DEFAULT), 1, compiled=compiled)


def _ngspice_with_peak_memory(tmp: Path) -> Path:
    """Make ngspice.run start ngspice under GNU time, which writes ngspice's own peak RSS (KiB) to a file.
    (RUSAGE_CHILDREN would report the forking Python's RSS: the child's high-water mark survives exec.)"""
    from ..spice import runner as ngspice
    exe = ngspice.find_ngspice()
    out = tmp / "ngspice_maxrss_kb"
    wrapper = tmp / "ngspice_timed.sh"
    wrapper.write_text(f'#!/bin/sh\nexec /usr/bin/time -f "%M" -o "{out}" "{exe}" "$@"\n')
    wrapper.chmod(0o755)
    ngspice.find_ngspice = lambda: str(wrapper)
    return out


def task_scale(backend: str, gates: int, periods: int, step: float = 2.0, design: str | None = None) -> dict:
    """One backend on nor.chain(p, gates), or on a synthesized design (a Verilog file of the package) with
    its drives at their model amplitudes (inputs '0', clock low): the cost per period does not depend on the
    values."""
    import numpy as np
    from ..backends import envelope
    from ..physics import network, nor
    from ..backends import rk4
    from ..physics.params import DEFAULT as p
    if backend.startswith("rk4"):
        _warm_rk4(backend == "rk4")
    nl = _design(design) if design else None
    t0 = time.perf_counter()
    if nl is not None:
        model = network.build(nl, p)
        gates = model.n // 6
    else:
        model = nor.chain(p, gates)
    model.check()
    build_s = time.perf_counter() - t0
    rss0 = _rss_mb()
    out = {"backend": backend, "gates": gates, "oscillators": model.n, "periods": periods, "build_s": build_s}
    if backend in ("rk4", "rk4_numpy"):
        rk4.integrate(model, 1, compiled=backend == "rk4")            # warm-up on this model
        t0 = time.perf_counter()
        r = rk4.integrate(model, periods, compiled=backend == "rk4")
        wall = time.perf_counter() - t0
        out.update(steps_per_period=rk4.DEFAULT_STEPS_PER_PERIOD, compiled=r.extra["compiled"],
                   final_amp_ur=float(np.abs(r.amp[-1]).max() / p.u_r))
        setup = 0.0
    elif backend == "envelope":
        t0 = time.perf_counter()                      # setup: Envelope.of, its compiled kernel, step bound
        envelope.integrate(model, max(1, int(step)), step_periods=step)
        setup = time.perf_counter() - t0
        t0 = time.perf_counter()
        r = envelope.integrate(model, periods, step_periods=step)   # reuses the cached Envelope and kernel
        A = r.state[0]
        wall = time.perf_counter() - t0 + setup                     # s_per_period subtracts setup again
        out.update(step_periods=step, final_amp_ur=float(np.abs(A).max() / p.u_r))
    elif backend == "ngspice":
        from ..spice import runner as ngspice
        with tempfile.TemporaryDirectory() as td:
            peak_file = _ngspice_with_peak_memory(Path(td)) if os.path.exists("/usr/bin/time") else None
            t0 = time.perf_counter()
            r = ngspice.run(model, periods)
            wall = time.perf_counter() - t0
            peak = float(peak_file.read_text().split()[-1]) / 1024 if peak_file and peak_file.exists() else None
        setup = 0.0
        out.update(ngspice_process_s=r.extra["wall_s"], points=r.extra["points"],
                   final_amp_ur=float(np.abs(r.amp[-1]).max() / p.u_r), ngspice_maxrss_mb=peak)
    else:
        raise ValueError(backend)
    out.update(wall_s=wall, setup_s=setup, s_per_period=(wall - setup) / periods,
               rss_baseline_mb=rss0, rss_peak_mb=_rss_mb())
    return out


def task_adder(backend: str, design: str) -> dict:
    """Worker task: the adder's 16 sums via run_physical on `backend`: wall, correct, margin, memory."""
    from .. import simulation
    # the private kernel: its numpy path is forced for the whole worker (warm-up and run), as the checked-in
    # numbers were measured; passing RK4Options(compiled=False) to run_physical would do it for the run alone
    from ..backends import logic, _rk4_kernel as rk4_kernel
    from ..physics.params import DEFAULT as p
    nl = _design(design)
    values = list(ADDER_INPUTS)
    if backend == "rk4_numpy":
        rk4_kernel.AVAILABLE = False            # rk4.integrate then takes its numpy path
    if backend in ("rk4", "rk4_numpy"):
        _warm_rk4(backend == "rk4")
    rss0 = _rss_mb()
    t0 = time.perf_counter()
    res = simulation.run_physical(nl, p, values, "rk4" if backend.startswith("rk4") else backend)
    wall = time.perf_counter() - t0
    correct = sum(r["valid"] and r["outputs"]["s"] == logic.evaluate(nl, v)["s"] for r, v in zip(res, values))
    return {"backend": backend, "wall_s": wall, "periods": res[0]["periods"], "correct": int(correct),
            "min_margin": min(r["min_margin"] for r in res), "rss_baseline_mb": rss0, "rss_peak_mb": _rss_mb(),
            "children_maxrss_mb": _rss_mb(resource.RUSAGE_CHILDREN),
            "amplitudes": [r["amplitudes"] for r in res]}


def task_sqrt(backend: str, design: str, probe_periods: int = 0) -> dict:
    """backend 'envelope': the whole run; 'rk4_probe': RK4 over the first `probe_periods` of the same schedule."""
    from .. import simulation
    from ..physics import network
    from ..backends import rk4
    from ..physics.params import DEFAULT as p
    nl = _design(design)
    cycles = simulation.expand_steps(sqrt_steps())
    timing = simulation.clock_timing(nl)
    rss0 = _rss_mb()
    if backend in ("envelope", "rk4"):
        if backend == "rk4":
            _warm_rk4()
        t0 = time.perf_counter()
        res = simulation.run_clocked_physical(nl, p, cycles, backend, timing)
        wall = time.perf_counter() - t0
        return {"backend": backend, "wall_s": wall, "periods": res["periods"], "valid": res["valid"],
                "root_trace": [t["outputs"].get("root") for t in res["trace"]], "timing": timing,
                "rss_baseline_mb": rss0, "rss_peak_mb": _rss_mb(),
                "s_per_period": wall / res["periods"]}
    # RK4 probe: same model and stimulus as run_clocked_physical, first periods only
    _warm_rk4()
    model = network.build(nl, p)
    segs, reads, total = simulation.clocked_schedule(cycles, timing)
    stim = network.stimulus(model, nl, p, [(t, [v]) for t, v, _ in segs], clock=[[c] for *_, c in segs])
    outs = list(model.probes)
    rk4.integrate(model, 2, stimulus=stim, probes=outs)
    t0 = time.perf_counter()
    rk4.integrate(model, probe_periods, stimulus=stim, probes=outs)
    wall = time.perf_counter() - t0
    return {"backend": "rk4_probe", "periods_measured": probe_periods, "wall_s": wall,
            "s_per_period": wall / probe_periods, "total_periods": total, "oscillators": model.n,
            "estimate_s": wall / probe_periods * total, "rss_peak_mb": _rss_mb()}


def task_profile(gates_list: list[int]) -> dict:
    """Worker task: per chain size, envelope.integrate profiled and timed by part; the RK4 kernel breakdown."""
    import numpy as np
    from ..backends import envelope
    from ..physics import nor
    from ..backends import rk4, _rk4_kernel as rk4_kernel   # the kernel's own parts are what this profile times
    from ..physics.params import DEFAULT as p
    out = {"envelope": [], "rk4": []}
    for gates in gates_list:
        model = nor.chain(p, gates)
        periods = 400 if gates < 1000 else 40
        pr = cProfile.Profile()
        t0 = time.perf_counter()
        pr.enable()
        envelope.integrate(model, periods, step_periods=2.0)
        pr.disable()
        wall = time.perf_counter() - t0
        st = pstats.Stats(pr)
        rows = []
        for (fn, line, name), (cc, nc, tt, ct, _) in st.stats.items():
            rows.append({"function": f"{Path(fn).name}:{line}({name})" if line else name, "calls": nc,
                         "tottime": tt, "cumtime": ct})
        rows.sort(key=lambda r: -r["tottime"])
        env = envelope.Envelope(model)
        s = np.full((env.slow.size, 1), 1e-3)
        A = np.full((env.fast.size, 1), 1e-3 + 0j)
        reps = 200 if gates < 1000 else 20
        parts = {}
        negK = -env.Ks
        for name, fn in {"`-self.Ks @ s` as written in rhs (negates the matrix every call)": lambda: -env.Ks @ s,
                         "`-(self.Ks @ s)`": lambda: -(env.Ks @ s), "`negK @ s` (negated once)": lambda: negK @ s,
                         "Cs @ sd": lambda: env.Cs @ s,
                         "B^-1 solve (SuperLU)": lambda: env.solve_rate(A),
                         "residual_fast": lambda: env.residual_fast(A, s, A),
                         "slow_force": lambda: env.slow_force(A),
                         "whole rhs": lambda: env.rhs(A, s, s, A)}.items():
            fn()
            t0 = time.perf_counter()
            for _ in range(reps):
                fn()
            parts[name] = (time.perf_counter() - t0) / reps
        out["envelope"].append({"gates": gates, "oscillators": model.n, "periods": periods, "step": 2.0,
                                "wall_s": wall, "rhs_calls": periods // 2 * 4, "top": rows[:10], "parts_s": parts,
                                "n_slow": int(env.slow.size), "slow_block_type": type(env.Ks).__name__})
        # --- compiled RK4: per-step time vs the force evaluation alone, and a 1-D prototype
        out["rk4"].append(_rk4_breakdown(model, rk4, rk4_kernel, np))
    return out


def _rk4_breakdown(model, rk4, rk4_kernel, np) -> dict:
    N = rk4.DEFAULT_STEPS_PER_PERIOD
    T = 2 * np.pi / model.omega
    h = T / N
    a = model.arrays
    ph = a["drive_phase"][None, :]
    j = np.arange(N + 1)[:, None]
    sin_full = np.sin(model.omega * j * h + ph)[..., None]
    sin_half = np.sin(model.omega * (j[:-1] + 0.5) * h + ph)[..., None]
    demod = np.exp(-1j * model.omega * (np.arange(1, N + 1) * h))
    k = rk4_kernel.Kernel(model, N, h, sin_full, sin_half, demod, np.array(list(model.probes.values())), 1e3)
    rng = np.random.default_rng(0)
    x = np.ascontiguousarray(rng.random((model.n, 1)) * 1e-2)
    v = np.ascontiguousarray(rng.random((model.n, 1)) * 1e-2)
    amps = np.ascontiguousarray(a["drive_amp"][:, None])
    k.run(x.copy(), v.copy(), amps, 1)
    nper = max(2, int(2e6 / (model.n * N)))
    t0 = time.perf_counter()
    k.run(x.copy(), v.copy(), amps, nper)
    step_s = (time.perf_counter() - t0) / (nper * N)
    out = np.empty_like(x)
    args = (x, v, out, *k.K, *k.C, k.inv_m, *k.q, k.ddof, amps, k.sin_full[0])
    rk4_kernel._accel(*args)
    reps = max(50, int(4e6 / model.n))
    t0 = time.perf_counter()
    for _ in range(reps):
        rk4_kernel._accel(*args)
    accel_s = (time.perf_counter() - t0) / reps
    # prototype: batch-1 arrays and one fused CSR (rk4.force_matrix, the matrix the numpy path uses)
    A = rk4.force_matrix(model).tocsr()
    pargs = (A.indptr.astype(np.int64), A.indices.astype(np.int64), A.data, 1.0 / a["mass"],
             a["quad_fast"].astype(np.int64), a["quad_slow"].astype(np.int64), np.ascontiguousarray(amps[:, 0]),
             np.ascontiguousarray(sin_full[:, :, 0]), np.ascontiguousarray(sin_half[:, :, 0]))
    proto = _fused_run()
    proto(np.zeros(model.n), np.zeros(model.n), 1, N, h, *pargs)
    xk, vk = x.copy(), v.copy()
    k.run(xk, vk, amps, 3)
    xp, vp = x[:, 0].copy(), v[:, 0].copy()
    proto(xp, vp, 3, N, h, *pargs)
    same = float(np.abs(xk[:, 0] - xp).max() / np.abs(xk).max())
    t0 = time.perf_counter()
    proto(np.zeros(model.n), np.zeros(model.n), nper, N, h, *pargs)
    proto_s = (time.perf_counter() - t0) / (nper * N)
    # an empty njit call: the Python -> numba dispatch cost included in the per-call timings above
    noop = _noop()
    noop(x)
    t0 = time.perf_counter()
    for _ in range(reps):
        noop(x)
    disp = (time.perf_counter() - t0) / reps
    return {"oscillators": model.n, "step_s": step_s, "ns_per_osc_step": step_s / model.n * 1e9,
            "osc_steps_per_s": model.n / step_s, "accel_s": accel_s - disp, "accel_share_of_step": 4 * (accel_s - disp) / step_s,
            "fused_step_s": proto_s, "fused_ns_per_osc_step": proto_s / model.n * 1e9, "fused_speedup": step_s / proto_s,
            "fused_rel_diff_after_3_periods": same, "dispatch_s": disp}


def _noop():
    from numba import njit

    @njit(cache=False)
    def noop(x):
        return x.shape[0]
    return noop


def _fused_run():
    """A batch-1 RK4 loop whose force evaluation is one CSR product over z = [x, v, u_f u_s, u_f^2, drives]
    (rk4.force_matrix): the prototype of the rk4_kernel change proposed in reports/performance.md."""
    from numba import njit
    import numpy as np

    @njit(cache=False)
    def force(x, v, out, z, Ap, Ai, Ad, inv_m, qf, qs, damp, dsin, n, nq, nd):
        for i in range(n):
            z[i] = x[i]
            z[n + i] = v[i]
        o = 2 * n
        for q in range(nq):
            uf = x[qf[q]]
            z[o + q] = uf * x[qs[q]]
            z[o + nq + q] = uf * uf
        o += 2 * nq
        for d in range(nd):
            z[o + d] = damp[d] * dsin[d]
        for i in range(n):
            acc = 0.0
            for k in range(Ap[i], Ap[i + 1]):
                acc += Ad[k] * z[Ai[k]]
            out[i] = acc * inv_m[i]

    @njit(cache=False)
    def run(x, v, nper, N, h, Ap, Ai, Ad, inv_m, qf, qs, damp, sin_full, sin_half):
        n, nq, nd = x.size, qf.size, damp.size
        z = np.empty(2 * n + 2 * nq + nd)
        k1, k2, k3, k4 = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
        xs, v2, v3, v4 = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
        for _ in range(nper):
            for s in range(N):
                force(x, v, k1, z, Ap, Ai, Ad, inv_m, qf, qs, damp, sin_full[s], n, nq, nd)
                for i in range(n):
                    xs[i] = x[i] + 0.5 * h * v[i]
                    v2[i] = v[i] + 0.5 * h * k1[i]
                force(xs, v2, k2, z, Ap, Ai, Ad, inv_m, qf, qs, damp, sin_half[s], n, nq, nd)
                for i in range(n):
                    xs[i] = x[i] + 0.5 * h * v2[i]
                    v3[i] = v[i] + 0.5 * h * k2[i]
                force(xs, v3, k3, z, Ap, Ai, Ad, inv_m, qf, qs, damp, sin_half[s], n, nq, nd)
                for i in range(n):
                    xs[i] = x[i] + h * v3[i]
                    v4[i] = v[i] + h * k3[i]
                force(xs, v4, k4, z, Ap, Ai, Ad, inv_m, qf, qs, damp, sin_full[s + 1], n, nq, nd)
                for i in range(n):
                    x[i] += (h / 6.0) * (v[i] + 2.0 * v2[i] + 2.0 * v3[i] + v4[i])
                    v[i] += (h / 6.0) * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
        return x
    return run


def task_logic(design: str, steps: list | None = None) -> dict:
    """Worker task: the sqrt schedule (or `steps`) through run_clocked_logic, mean wall over 20 runs."""
    from .. import simulation
    nl = _design(design)
    cycles = simulation.expand_steps(steps or sqrt_steps())
    t0 = time.perf_counter()
    reps = 20
    for _ in range(reps):
        res = simulation.run_clocked_logic(nl, cycles)
    wall = (time.perf_counter() - t0) / reps
    return {"backend": "logic", "wall_s": wall, "cycles": len(cycles), "s_per_cycle": wall / len(cycles),
            "gates": len(nl.gates()), "latches": len(nl.latches()), "root": res["outputs"].get("root")}


TASKS = {"scale": task_scale, "adder": task_adder, "sqrt": task_sqrt, "profile": task_profile, "logic": task_logic}


def worker(spec: str) -> None:
    """Run the task named in the JSON `spec` (in a worker process) and print its result after @@RESULT@@."""
    kw = json.loads(spec)
    fn = TASKS[kw.pop("task")]
    res = fn(**kw)
    print("@@RESULT@@" + json.dumps(res, default=float))


def spawn(task: str, timeout: float = 1500, **kw) -> dict:
    """Run one measurement in a fresh interpreter (so ru_maxrss is that measurement's own peak)."""
    spec = json.dumps({"task": task, **kw})
    t0 = time.perf_counter()
    try:
        r = subprocess.run([sys.executable, "-m", "mech2spice.studies.performance", "--worker", spec],
                           capture_output=True, text=True, timeout=timeout, env=_worker_env())
    except subprocess.TimeoutExpired:
        return {"failed": f"timed out after {timeout:.0f} s", **kw}
    line = next((ln for ln in r.stdout.splitlines()[::-1] if ln.startswith("@@RESULT@@")), None)
    if r.returncode != 0 or line is None:
        return {"failed": (r.stderr or r.stdout).strip().splitlines()[-1:] or ["?"], **kw}
    out = json.loads(line[len("@@RESULT@@"):])
    out["process_wall_s"] = time.perf_counter() - t0
    return out


def _worker_env() -> dict:
    """This environment, with the directory holding this mech2spice package first on PYTHONPATH, so the
    worker imports the same code whatever its working directory."""
    root = str(Path(__file__).resolve().parents[2])
    return {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")]))}


# ==================================================================================================
# driver side
# ==================================================================================================

def periods_for(backend: str, n_osc: int, quick: bool) -> int:
    """Periods to measure: PLAN's work target over `n_osc`, clamped to its range (a tenth if `quick`)."""
    target, lo, hi = PLAN[backend]
    if quick:
        target, hi = target / 10, max(lo, hi // 10)
    return int(min(hi, max(lo, target // n_osc)))


def section_scaling(quick: bool) -> dict:
    """The scaling section: each backend on chains of GATES gates (ngspice stops when too slow), fits."""
    gates = GATES[:4] if quick else GATES
    rows, stopped = [], {}
    log("baseline memory: interpreter + imports + smallest model, nothing run")
    base = spawn("scale", backend="envelope", gates=1, periods=1)
    for backend in ("rk4", "rk4_numpy", "envelope", "ngspice"):
        prev = None
        for g in gates:
            n = 6 * g
            P = periods_for(backend, n, quick)
            if backend == "ngspice" and prev is not None:
                # predict from the last two points; skip when one measurement would exceed NG_LIMIT_S
                pts = [r for r in rows if r.get("backend") == "ngspice" and "s_per_period" in r]
                if len(pts) >= 2:
                    e = math.log(pts[-1]["s_per_period"] / pts[-2]["s_per_period"]) / math.log(
                        pts[-1]["oscillators"] / pts[-2]["oscillators"])
                    pred = pts[-1]["s_per_period"] * (n / pts[-1]["oscillators"]) ** max(e, 1.0)
                    if pred * P > NG_LIMIT_S:
                        P = max(2, int(NG_LIMIT_S / pred))
                        if pred * P > NG_LIMIT_S:
                            stopped[backend] = {"at_oscillators": n, "predicted_s_per_period": pred}
                            log(f"  {backend}: stop at {n} oscillators (predicted {pred:.1f} s/period)")
                            break
            log(f"scaling {backend:16s} {n:6d} oscillators, {P} periods")
            r = spawn("scale", backend=backend, gates=g, periods=P)
            if backend == "ngspice" and "failed" not in r:
                # ngspice's fixed cost (emit, parse, set up) is not per period: run 2P as well, take the slope
                r2 = spawn("scale", backend=backend, gates=g, periods=2 * P)
                if "failed" not in r2:
                    slope = (r2["wall_s"] - r["wall_s"]) / P
                    r2["fixed_s"] = r["wall_s"] - P * slope if slope > 0 else None
                    r2["s_per_period_incl_setup"] = r2["wall_s"] / (2 * P)
                    r2["s_per_period"] = slope if slope > 0 else r2["wall_s"] / (2 * P)
                    r2["periods_short_run"] = P
                    r = r2
            if "failed" in r:
                log(f"  FAILED: {r['failed']}")
                rows.append({"backend": backend, "oscillators": n, **r})
                break
            r["osc_periods_per_s"] = r["oscillators"] / r["s_per_period"]
            r["periods_per_s"] = 1 / r["s_per_period"]
            if backend.startswith("rk4"):
                r["osc_steps_per_s"] = r["oscillators"] * 80 / r["s_per_period"]
            elif backend == "ngspice":
                r["osc_steps_per_s"] = r["oscillators"] * 40 / r["s_per_period"]
            else:
                r["osc_steps_per_s"] = r["oscillators"] * 4 / 2.0 / r["s_per_period"]   # 4 rhs per 2-period step
            log(f"  {r['s_per_period'] * 1e3:.3f} ms/period, {r['osc_periods_per_s']:.3g} osc-periods/s, "
                f"peak {r['rss_peak_mb']:.0f} MB" + (f", ngspice {r.get('ngspice_maxrss_mb', 0):.0f} MB"
                                                      if backend == "ngspice" else ""))
            rows.append(r)
            prev = r
    # the clocked-design default envelope step (1 period) at the largest size, for the sieve
    g = gates[-1]
    log(f"scaling envelope step 1 at {6 * g} oscillators")
    e1 = spawn("scale", backend="envelope", gates=g, periods=periods_for("envelope", 6 * g, quick) // 2, step=1.0)
    return {"rows": rows, "baseline": base, "stopped": stopped, "envelope_step1": e1, "fits": fits(rows)}


def fits(rows: list[dict]) -> dict:
    """Exponent of wall time per period vs oscillators, least squares in log-log over >= 300 oscillators."""
    import numpy as np
    out = {}
    for b in PLAN:
        pts = [(r["oscillators"], r["s_per_period"]) for r in rows if r.get("backend") == b and "s_per_period" in r
               and r["oscillators"] >= 300]
        if len(pts) >= 2:
            x, y = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
            k, c = np.polyfit(x, y, 1)
            out[b] = {"exponent": float(k), "range": [pts[0][0], pts[-1][0]]}
        top = [(r["oscillators"], r["s_per_period"]) for r in rows if r.get("backend") == b and "s_per_period" in r]
        if len(top) >= 2:
            (n1, t1), (n2, t2) = top[-2], top[-1]
            out.setdefault(b, {})["last_exponent"] = float(math.log(t2 / t1) / math.log(n2 / n1))
    return out


def _design(name: str):
    """The synthesized netlist of a Verilog file shipped with the package (a worker synthesizes it itself,
    from the Yosys cache: only its name crosses the process boundary, never a serialized object)."""
    from ..synthesis import synth
    return synth.synthesize(data.verilog(name))


def section_adder() -> dict:
    """The adder section: the 16 sums on each backend, the envelope first and again last."""
    rows = {}
    # envelope first and last: the ratio to RK4 is taken against their mean (shared machine)
    for backend in ("envelope", "rk4", "rk4_numpy", "ngspice", "envelope"):
        log(f"adder, 16 inputs, run_physical on {backend}")
        r = spawn("adder", backend=backend, design="adder2.v")
        if "failed" in r:
            log(f"  FAILED {r['failed']}")
        else:
            log(f"  {r['wall_s']:.1f} s, {r['periods']} periods, {r['correct']}/16 correct")
        key = backend if backend not in rows else backend + "_again"
        rows[key] = r
    return {"rows": rows}


def section_sqrt(full_rk4: bool) -> dict:
    """The sqrt section: envelope, RK4 over 400 periods (an estimate), logic; RK4 in full if asked."""
    log("sqrt on the envelope backend (whole run)")
    env = spawn("sqrt", backend="envelope", design="sqrt.v")
    log(f"  {env.get('wall_s', float('nan')):.1f} s, roots {env.get('root_trace')}")
    log("sqrt on RK4: per-period cost over the first 400 periods")
    probe = spawn("sqrt", backend="rk4_probe", design="sqrt.v", probe_periods=400)
    log(f"  {probe.get('s_per_period', float('nan')) * 1e3:.1f} ms/period -> estimate "
        f"{probe.get('estimate_s', float('nan')) / 60:.1f} min for {probe.get('total_periods')} periods")
    out = {"envelope": env, "rk4_probe": probe}
    log("sqrt on the logic backend")
    out["logic"] = spawn("logic", design="sqrt.v")
    if full_rk4:
        log("sqrt on RK4 (whole run)")
        out["rk4"] = spawn("sqrt", backend="rk4", design="sqrt.v", timeout=3000)
    return out


def section_cpu(quick: bool) -> dict:
    """Per-period cost of every backend on the real processor model (verilog/cpu.v), for the sieve estimate."""
    from ..physics import network
    from ..synthesis import synth
    from ..physics.params import DEFAULT as p
    nl = _design("cpu.v")
    model = network.build(nl, p)
    from .. import simulation
    timing = simulation.clock_timing(nl)
    out = {"oscillators": model.n, "gate_blocks": model.n // 6, "logic_gates": len(nl.gates()),
           "latches": len(nl.latches()), "logic_depth": timing["logic_depth"], "timing": timing, "rows": []}
    del synth
    plan = {"rk4": 30, "rk4_numpy": 4, "envelope": 1000, "ngspice": 6}
    for b, P in plan.items():
        if quick:
            P = max(2, P // 5)
        for step in ((1.0,) if b.startswith("envelope") else (2.0,)):
            log(f"cpu.v ({model.n} oscillators) on {b}, {P} periods")
            r = spawn("scale", backend=b, gates=0, periods=P, step=step, design="cpu.v")
            if b == "ngspice" and "failed" not in r:
                r2 = spawn("scale", backend=b, gates=0, periods=2 * P, step=step, design="cpu.v")
                if "failed" not in r2:
                    slope = (r2["wall_s"] - r["wall_s"]) / P
                    r2["fixed_s"] = r["wall_s"] - P * slope if slope > 0 else None
                    r2["s_per_period_incl_setup"] = r2["wall_s"] / (2 * P)
                    r2["s_per_period"] = slope if slope > 0 else r2["wall_s"] / (2 * P)
                    r = r2
            if "failed" in r:
                log(f"  FAILED {r['failed']}")
            else:
                log(f"  {r['s_per_period'] * 1e3:.1f} ms/period, peak {r['rss_peak_mb']:.0f} MB")
            out["rows"].append(r)
    log("cpu.v on the logic backend (run_clocked_logic, inputs 0, 50 cycles)")
    out["logic"] = spawn("logic", design="cpu.v", steps=[{"set": {}, "cycles": 50}])
    return out


def section_profile() -> dict:
    """The profile section: task_profile at 402, 1998 and 12000 oscillators, in a worker."""
    log("profile: envelope (cProfile) and compiled RK4 at 402, 1998, 12000 oscillators")
    return spawn("profile", gates_list=[67, 333, 2000])


# ==================================================================================================
# report
# ==================================================================================================


def measure(out: Path, only=None, quick: bool = False, sqrt_rk4_full: bool = False) -> dict:
    """Measure the sections in `only` (default: all but sqrt_rk4) and merge each into OUT/performance.json as
    it finishes, with where it ran and the clock schedule's constants the sieve estimate reads."""
    from .. import simulation
    jf = out / "performance.json"
    res = read_json(jf, {})
    res["machine"] = MACHINE
    res["platform"] = {"python": platform.python_version(), "cpus": os.cpu_count(), "machine": platform.machine()}
    res["conditions"] = conditions()
    res["clock"] = {"latch_min_pulse": simulation.LATCH_MIN_PULSE, "latch_output_delay": simulation.LATCH_OUTPUT_DELAY,
                    "gate_delay_max": simulation.GATE_DELAY_MAX, "settle_margin": simulation.SETTLE_MARGIN}
    for sec in sections("performance", only, SECTIONS + EXTRA_SECTIONS, default=SECTIONS):
        t0 = time.perf_counter()
        res.update(_section(sec, res, quick, sqrt_rk4_full))
        res.setdefault("section_wall_s", {})[sec] = time.perf_counter() - t0
        write_json(jf, res, default=float)
    return res


def _section(sec: str, res: dict, quick: bool, sqrt_rk4_full: bool) -> dict:
    """One section's measurements, as the JSON keys they replace."""
    if sec == "scaling":
        return {"scaling": section_scaling(quick)}
    if sec == "adder":
        return {"adder": section_adder()}
    if sec == "sqrt":
        return {"sqrt": section_sqrt(sqrt_rk4_full)}
    if sec == "profile":
        return {"profile": section_profile()}
    if sec == "cpu":
        return {"cpu": section_cpu(quick)}
    log("sqrt on RK4 (whole run)")                 # sqrt_rk4
    rk = spawn("sqrt", backend="rk4", design="sqrt.v", timeout=2400)
    log(f"  {rk.get('wall_s', float('nan')) / 60:.1f} min")
    return {"sqrt": {**res.get("sqrt", {}), "rk4": rk}}


if __name__ == "__main__":             # a measurement worker: python -m mech2spice.studies.performance --worker SPEC
    if len(sys.argv) != 3 or sys.argv[1] != "--worker":
        sys.exit("usage: python -m mech2spice.studies.performance --worker SPEC (reports: mech2spice report performance)")
    worker(sys.argv[2])
