"""The carrier engine (issue 15, backends/carrier.py: Lawson RK4) measured: accuracy against RK4 at 160 steps,
convergence against wall time beside RK4 and ngspice, its rate on the processor, a roofline of its kernel, and
the whole sieve at oscillator level against the envelope run, cycle by cycle.

Sections (`--only NAME ...`, each merged into reports/carrier.json; reports/carrier.md rebuilt from the whole
JSON, `--render` measures nothing):
  accuracy     carrier (12 steps) against rk4.integrate at 160 steps on the gate (nominal and band-edge inputs),
               the 3-gate chain and the adder's 16 inputs: worst |A| and phase difference, decoded bits.
  convergence  the gate (600 periods) and a short adder scene: error against RK4 at 640 steps vs steps per
               period and vs wall time, carrier, RK4 and (gate) ngspice; where each fails.
  processor    the processor model (rst = 1, from rest): periods/s and oscillator-steps/s of carrier (1 and 2
               threads), RK4's numpy path (N = 80, 160) and its compiled kernel forced (N = 80), alternated.
  roofline     this machine's measured FLOP/s and triad bandwidths (numba microbenchmarks), flops and bytes
               per oscillator-step of each kernel counted from the code and the processor's structure.
  cycles       (no integration) experiments.processor_check's JSON: carrier against RK4 at 160 steps on whole
               processor cycles continued from one carrier checkpoint (RK4 at 160 cannot run the sieve).
  sieve        (no integration) two `cpu run --trace` files, carrier and envelope, compared cycle by cycle.
  latency      (no integration) the sieve's `cpu run --trace` with per-gate latency against the carrier's without
               it and against the ISS, its cost per cycle; experiments.processor_check --latency's cycles against
               full pauses.

Blocks other reports append: `block` (speed_accuracy.md), `roofline_block` (performance.md), `sieve_block`
(fidelity.md).  ~10 min on an idle 2-core machine, `--quick` < 2 min.
"""
from __future__ import annotations

import json
import math
import os
import subprocess
import time
from pathlib import Path

import numpy as np

from ..compare import agreement, trajectory
from ..errors import DivergenceError, Mech2SpiceError
from ._common import SANDBOX, md_table, out_dir, pyplot, read_json, save_figure, write_json

SECTIONS = ("accuracy", "convergence", "processor", "roofline", "cycles", "sieve", "latency")
AMP_TOL, PHASE_TOL = 1e-3, 0.5          # the bounds against RK4 at 160 steps (u_R, degrees)
FAIL_UR = 0.1                           # an error above this (u_R) counts as a failed run
REF_STEPS, FINE_STEPS = 160, 640
CARRIER_N = (4, 5, 6, 8, 10, 12, 16, 24, 32)
RK4_N = (20, 24, 32, 40, 48, 64, 80, 120, 160, 240)
CARRIER_SCAN = (2, 3)                   # where it fails: below the engine's minimum of 4 (carrier.integrate
RK4_SCAN = (4, 6, 8, 12, 16)            # directly, as CarrierOptions refuses them); RK4's coarse steps
NG_STEPS = (1 / 20, 1 / 40, 1 / 80)     # ngspice max step (periods), gate only
REDUCED_TOL = 0.02                      # u_R: issue 6's agreement tolerance for reduced models
SIEVE_CYCLES = 457                      # the sieve halts after 457 cycles (reports/cpu.md)
CARRIER_TRACE = "build/carrier/sieve_carrier.jsonl"
PROCESSOR_CHECK = "build/carrier/processor_check.json"   # experiments.processor_check's output
ENVELOPE_TRACE = "build/carrier/sieve_envelope.jsonl"
LATENCY_TRACE = "build/carrier/sieve_latency.jsonl"     # cpu run --backend carrier (its default latency)
LATENCY_CHECKS = ("build/carrier/latency_check_c30.json", "build/carrier/latency_check_c200.json")


def _load() -> float:
    """The 1-minute load average (2 cores shared by several engineers)."""
    return round(os.getloadavg()[0], 2)


def _measured_on(extra: str = "") -> str:
    return f"{SANDBOX} (shared{extra})"


# --- accuracy --------------------------------------------------------------------------------------------
def _bits(run, scene) -> list:
    """Each window's decoded band per probe and member (None: between the bands)."""
    from ..physics.params import band_of
    u = scene.model.amplitude_unit
    return [[[band_of(a) for a in np.abs(run.amp[w - 10:w, j]).mean(0) / u] for j in range(len(scene.probes))]
            for w in scene.windows]


def compare_runs(ref, got, scene) -> dict:
    """Worst |A| difference (u_R) over every period, probe and member; worst phase difference (deg) where
    |A_ref| > 0.1 u_R; whether every decoded bit agrees."""
    a = agreement(ref.amp, got.amp, scene.model.amplitude_unit, floor=0.1)
    return {"amp_ur": a.amp, "phase_deg": a.phase_deg, "bits_equal": _bits(ref, scene) == _bits(got, scene)}


def accuracy_scenes(quick: bool) -> dict:
    """name -> scene: shorter scenes with --quick."""
    from ..experiments import scenes as S
    if quick:
        return {"gate (nominal)": S.gate_scene(periods=600), "gate (band edges)": S.gate_scene(which="edges", periods=600),
                "chain3": S.chain_scene(hold=400), "adder2 (16 inputs)": S.adder_scene(hold=400)}
    return {"gate (nominal)": S.gate_scene(), "gate (band edges)": S.gate_scene(which="edges"),
            "chain3": S.chain_scene(), "adder2 (16 inputs)": S.adder_scene()}


def accuracy(quick: bool = False, steps: int | None = None) -> dict:
    """carrier at its default steps against rk4.integrate at 160 steps, scene by scene."""
    from ..backends import carrier, rk4
    steps = steps or carrier.DEFAULT_STEPS_PER_PERIOD
    rows = []
    for name, sc in accuracy_scenes(quick).items():
        t0 = time.perf_counter()
        ref = rk4.integrate(sc.model, sc.periods, steps_per_period=REF_STEPS, stimulus=sc.stimulus, probes=sc.probes)
        t1 = time.perf_counter()
        got = carrier.integrate(sc.model, sc.periods, steps_per_period=steps, stimulus=sc.stimulus, probes=sc.probes)
        t2 = time.perf_counter()
        row = {"scene": name, "description": sc.description, "periods": sc.periods, "members": sc.stimulus.batch,
               "oscillators": sc.model.n, "rk4_wall_s": t1 - t0, "carrier_wall_s": t2 - t1,
               **compare_runs(ref, got, sc)}
        row["pass"] = row["amp_ur"] < AMP_TOL and row["phase_deg"] < PHASE_TOL and row["bits_equal"]
        rows.append(row)
        print(f"[accuracy] {name}: {row['amp_ur']:.2e} u_R, {row['phase_deg']:.3f} deg", flush=True)
    return {"steps": steps, "ref_steps": REF_STEPS, "quick": quick, "load": _load(), "rows": rows}


# --- convergence -----------------------------------------------------------------------------------------
def convergence_scenes(quick: bool) -> dict:
    from ..experiments import scenes as S
    return {"gate": S.gate_scene(periods=200 if quick else 600), "adder2": S.adder_scene(hold=150 if quick else 600)}


def _errors(ref, got, u) -> dict:
    """Worst |A| difference over every period and probe, and the final state's worst |x| difference (u_R)."""
    return {"err_ur": trajectory(ref.amp, got.amp, u),
            "final_ur": float(np.abs(got.x - ref.x).max() / u)}


def _timed_run(fn, ref, u) -> dict:
    """One run timed, scored against `ref`; a divergence or an error above FAIL_UR is marked as a failure."""
    t0 = time.perf_counter()
    try:
        got = fn()
    except DivergenceError as e:
        return {"wall_s": time.perf_counter() - t0, "failed": "diverged", "detail": str(e)[:160]}
    except Mech2SpiceError as e:
        return {"wall_s": time.perf_counter() - t0, "failed": "error", "detail": str(e)[:160]}
    row = {"wall_s": time.perf_counter() - t0, **_errors(ref, got, u)}
    if not np.isfinite(row["err_ur"]) or row["err_ur"] > FAIL_UR:
        row["failed"] = f"error > {FAIL_UR} u_R"
    return row


def _ngspice_rows(sc, ref, quick: bool) -> list[dict]:
    """ngspice (trap + prewarp, the package default) at NG_STEPS on the scene, timed as speed_accuracy does."""
    import shutil
    if quick or not shutil.which("ngspice"):
        return []
    from ..spice.carrier import SpiceOptions
    from ..studies import speed_accuracy
    rows = []
    for ms in NG_STEPS:
        r = speed_accuracy.run_ng(sc.model, sc.stimulus, SpiceOptions(max_step_periods=ms), sc.periods)
        row = {"method": "ngspice", "steps": round(1 / ms), "wall_s": r.get("wall_s", float("nan"))}
        if "failed" in r:
            row.update(failed="error", detail=r["failed"][:160])
        else:
            u = sc.model.amplitude_unit
            row["err_ur"] = trajectory(ref.amp, r["amp"], u)
            if row["err_ur"] > FAIL_UR:
                row["failed"] = f"error > {FAIL_UR} u_R"
        rows.append(row)
        print(f"[convergence] ngspice T/{row['steps']}: {row}", flush=True)
    return rows


def convergence(quick: bool = False) -> dict:
    """Error against RK4 at FINE_STEPS vs steps per period and wall time, one scene at a time."""
    from ..backends import carrier, rk4
    _warm_up()
    out = {"reference": f"RK4 at {FINE_STEPS} steps per period", "fail_ur": FAIL_UR, "quick": quick,
           "load": [_load()], "scenes": {}}
    cn = CARRIER_SCAN + ((4, 6, 8, 12, 16) if quick else CARRIER_N)
    rn = RK4_SCAN + ((20, 40, 80, 160) if quick else RK4_N)
    for name, sc in convergence_scenes(quick).items():
        u = sc.model.amplitude_unit
        t0 = time.perf_counter()
        ref = rk4.integrate(sc.model, sc.periods, steps_per_period=FINE_STEPS, stimulus=sc.stimulus)
        rows = []
        for n in cn:
            rows.append({"method": "carrier", "steps": n, "scan": n in CARRIER_SCAN, **_timed_run(
                lambda: carrier.integrate(sc.model, sc.periods, steps_per_period=n, stimulus=sc.stimulus), ref, u)})
            print(f"[convergence] {name} carrier {n}: {rows[-1]}", flush=True)
        for n in rn:
            rows.append({"method": "rk4", "steps": n, "scan": n in RK4_SCAN, **_timed_run(
                lambda: rk4.integrate(sc.model, sc.periods, steps_per_period=n, stimulus=sc.stimulus), ref, u)})
            print(f"[convergence] {name} rk4 {n}: {rows[-1]}", flush=True)
        if name == "gate":
            rows += _ngspice_rows(sc, ref, quick)
        out["scenes"][name] = {"description": sc.description, "periods": sc.periods, "members": sc.stimulus.batch,
                               "oscillators": sc.model.n, "ref_wall_s": time.perf_counter() - t0, "rows": rows}
        out["load"].append(_load())
    return out


def _warm_up() -> None:
    """Compile (or load from numba's cache) both kernels outside every timing."""
    from ..backends import carrier, rk4
    from ..experiments import scenes as S
    sc = S.gate_scene(periods=2)
    carrier.integrate(sc.model, 2, stimulus=sc.stimulus)
    carrier.integrate(sc.model, 2, stimulus=sc.stimulus, threads=2)
    rk4.integrate(sc.model, 2, stimulus=sc.stimulus)


# --- processor -------------------------------------------------------------------------------------------
def processor_model():
    """The processor as oscillators, and its power-up stimulus (rst = 1, clock low), as cpu/physical.py."""
    from ..cpu.netlist import CPU_VERILOG, cpu_netlist
    from ..physics import network
    from ..physics.params import DEFAULT
    nl = cpu_netlist(str(CPU_VERILOG), max_fanout=network.MAX_FANOUT)
    model = network.build(nl, DEFAULT)
    return model, network.stimulus(model, nl, DEFAULT, [(0, [{"rst": 1}])], clock=[[0]])


def _processor_runs(model, stim):
    """label -> (steps per period, a function running `periods` periods)."""
    from ..backends import carrier, rk4

    def forced(periods):
        old = rk4.KERNEL_MAX_SIZE
        rk4.KERNEL_MAX_SIZE = 10 ** 9            # the compiled RK4 kernel, which the processor would not get
        try:
            return rk4.integrate(model, periods, steps_per_period=80, stimulus=stim)
        finally:
            rk4.KERNEL_MAX_SIZE = old
    return {"carrier N=12, 1 thread": (12, lambda p: carrier.integrate(model, p, steps_per_period=12, stimulus=stim)),
            "carrier N=12, 2 threads": (12, lambda p: carrier.integrate(model, p, steps_per_period=12,
                                                                       stimulus=stim, threads=2)),
            "rk4 numpy N=80": (80, lambda p: rk4.integrate(model, p, steps_per_period=80, stimulus=stim)),
            "rk4 numpy N=160": (160, lambda p: rk4.integrate(model, p, steps_per_period=160, stimulus=stim)),
            "rk4 compiled N=80": (80, forced)}


def processor(quick: bool = False) -> dict:
    """Each method's rate on the processor, alternated `repeats` times in one run; medians."""
    model, stim = processor_model()
    runs = _processor_runs(model, stim)
    periods, repeats = (20, 2) if quick else (200, 3)
    for _, fn in runs.values():
        fn(2)                                    # compile / build operators outside the timings
    walls = {k: [] for k in runs}
    load = [_load()]
    for r in range(repeats):
        for label, (_, fn) in runs.items():
            t0 = time.perf_counter()
            fn(periods)
            walls[label].append(time.perf_counter() - t0)
            print(f"[processor] repeat {r}: {label} {walls[label][-1]:.2f} s", flush=True)
        load.append(_load())
    rows = []
    for label, (n, _) in runs.items():
        wall = float(np.median(walls[label]))
        rows.append({"method": label, "steps": n, "walls_s": walls[label], "median_s": wall,
                     "periods_per_s": periods / wall, "osc_steps_per_s": model.n * n * periods / wall})
    return {"oscillators": model.n, "periods": periods, "repeats": repeats, "load": load, "quick": quick, "rows": rows}


def equal_accuracy(conv: dict | None, carrier_steps: int = 12, scene: str = "gate") -> dict | None:
    """The RK4 steps whose gate error (convergence section) is nearest carrier's at `carrier_steps` (in log).

    Chosen by the final-state error, the integrators' own: the amplitude metric also holds the readouts'
    difference (RK4 sums the period's end points, carrier uses the trapezoid rule, ~1e-4 u_R apart at 160
    steps on a switching gate; backends/carrier.py), and the reference reads like RK4.  The amplitude
    metric's choice is kept beside it."""
    rows = ((conv or {}).get("scenes", {}).get(scene) or {}).get("rows", [])
    mine = [r for r in rows if r["method"] == "carrier" and r["steps"] == carrier_steps and "err_ur" in r]
    rk = [r for r in rows if r["method"] == "rk4" and "err_ur" in r and "failed" not in r]
    if not mine or not rk:
        return None
    near = lambda key: min(rk, key=lambda r: abs(math.log(max(r[key], 1e-300)) - math.log(max(mine[0][key], 1e-300))))
    best, by_amp = near("final_ur"), near("err_ur")
    return {"scene": scene, "carrier_steps": carrier_steps, "carrier_err_ur": mine[0]["final_ur"], "rk4_steps": best["steps"],
            "rk4_err_ur": best["final_ur"], "by_amplitude": {"carrier_err_ur": mine[0]["err_ur"],
                                                              "rk4_steps": by_amp["steps"], "rk4_err_ur": by_amp["err_ur"]}}


def ratios(proc: dict, eq: dict | None) -> dict:
    """(a) oscillator-steps/s carrier over each RK4 path; (b) periods/s at equal accuracy: RK4's rate at
    N_eq steps taken from its measured oscillator-steps/s (at 160 steps where N_eq >= 120, else at 80)."""
    by = {r["method"]: r for r in proc["rows"]}
    out = {"a": {}, "b": {}}
    for c in ("carrier N=12, 1 thread", "carrier N=12, 2 threads"):
        for r in ("rk4 numpy N=80", "rk4 compiled N=80"):
            out["a"][f"{c} / {r}"] = by[c]["osc_steps_per_s"] / by[r]["osc_steps_per_s"]
        if eq:
            n = eq["rk4_steps"]
            for path, rate in (("rk4 numpy", by["rk4 numpy N=160" if n >= 120 else "rk4 numpy N=80"]),
                               ("rk4 compiled", by["rk4 compiled N=80"])):
                rk_periods = rate["osc_steps_per_s"] / (proc["oscillators"] * n)
                out["b"][f"{c} / {path} N={n}"] = by[c]["periods_per_s"] / rk_periods
    return out


# --- roofline --------------------------------------------------------------------------------------------
def _bench_kernels():
    """Numba microbenchmarks: FMA chains (four dependent FMAs per element per pass, so loads and stores do not
    bound it; FMA contraction only, no reassociation that could fold the chain) and the triad."""
    from numba import njit, prange
    flags = dict(fastmath={"contract"}, cache=True)

    @njit(**flags)
    def fma(x, reps, a, b):
        for _ in range(reps):
            for j in range(x.size):
                y = x[j]
                y = y * a + b
                y = y * a + b
                y = y * a + b
                x[j] = y * a + b

    @njit(parallel=True, **flags)
    def fma2(xs, reps, a, b):
        for t in prange(xs.shape[0]):
            fma(xs[t], reps, a, b)

    @njit(**flags)
    def triad(a, b, c, s, reps):
        for _ in range(reps):
            for j in range(a.size):
                a[j] = b[j] + s * c[j]

    @njit(parallel=True, **flags)
    def triad2(a, b, c, s, reps):
        half = a.size // 2
        for t in prange(2):
            for _ in range(reps):
                for j in range(t * half, (t + 1) * half):
                    a[j] = b[j] + s * c[j]
    return fma, fma2, triad, triad2


def _best(fn, repeats: int = 3) -> float:
    """The fastest of `repeats` timings of fn() (the others are the shared machine's noise)."""
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return min(out)


FMA_WIDTH = 256        # doubles per chain array: 16 AVX-512 registers' worth, enough independent chains
WORKING_SETS = {"L1 (16 KB)": 16 << 10, "L2 (256 KB)": 256 << 10, "L3 (8 MB)": 8 << 20, "DRAM (256 MB)": 256 << 20}


def machine_peaks(quick: bool = False) -> dict:
    """FLOP/s of independent FMA chains (FMA_WIDTH doubles held in L1, 8 flops per element per pass; 1 thread
    and 2) and triad bandwidth a = b + s c at each working set (24 bytes per element: two loads and a store,
    write-allocate not counted)."""
    import numba
    fma, fma2, triad, triad2 = _bench_kernels()
    flops_target = 2e8 if quick else 4e9
    x, xs = np.ones(FMA_WIDTH), np.ones((2, FMA_WIDTH))
    reps = int(flops_target / (8 * x.size))
    fma(x, 1, 0.999999, 1e-6)
    fma2(xs, 1, 0.999999, 1e-6)
    out = {"fma_1t_gflops": 8 * x.size * reps / _best(lambda: fma(x, reps, 0.999999, 1e-6)) / 1e9,
           "fma_2t_gflops": 8 * xs.size * reps / _best(lambda: fma2(xs, reps, 0.999999, 1e-6)) / 1e9,
           "fma_width": FMA_WIDTH}
    threads = min(2, numba.config.NUMBA_NUM_THREADS)
    out["threads"] = threads
    bytes_target = 2e8 if quick else 2e9
    bw = {}
    for label, size in WORKING_SETS.items():
        if quick and size > 64 << 20:
            continue
        n = max(64, size // 24)
        a, b, c = np.zeros(n), np.ones(n), np.ones(n)
        reps = max(1, int(bytes_target / (24 * n)))
        triad(a, b, c, 0.5, 1)
        triad2(a, b, c, 0.5, 1)
        bw[label] = {"bytes": 24 * n, "gbs_1t": 24 * n * reps / _best(lambda: triad(a, b, c, 0.5, reps)) / 1e9,
                     "gbs_2t": 24 * n * reps / _best(lambda: triad2(a, b, c, 0.5, reps)) / 1e9}
        print(f"[roofline] triad {label}: {bw[label]}", flush=True)
    out["triad"] = bw
    return out


def lscpu_caches() -> dict:
    """lscpu's model name and cache lines (as printed)."""
    try:
        text = subprocess.run(["lscpu"], capture_output=True, text=True, timeout=10).stdout
    except (OSError, subprocess.SubprocessError):
        return {}
    keep = ("Model name", "L1d cache", "L2 cache", "L3 cache", "CPU(s)")
    return {k.strip(): v.strip() for k, v in (line.split(":", 1) for line in text.splitlines() if ":" in line)
            if k.strip() in keep}


def carrier_counts(model, N: int = 12) -> dict:
    """Flops and bytes per oscillator-step of the carrier kernel, counted from _carrier_kernel.py over the
    model's groups: per stage the gather loop (drive 3 flops; per coupling entry 2 FMAs = 4 flops and
    index 4 + two values 16 + gathered x, v 16 + f read/written 16 bytes; per quadratic entry 3 flops and
    index 4 + value 8 + gathered x 8 (+ own x 8 on a fast DOF) + f 16 bytes), then the four combine loops:
    45 flops (23 + 7 + 13 + 2) and 240 bytes (72 + 56 + 72 + 40) of unit-stride loads and stores per DOF per
    step."""
    from ..backends import carrier
    op = carrier.operator(model, N)
    flops = bytes_ = 0.0
    for lo, hi, wc, wq, _, _, slow, driven in op.groups:
        cnt = hi - lo
        f = (3 if driven else 0) + 4 * wc + 3 * wq
        b = 8 + (16 if driven else 0) + 52 * wc + (36 if slow else 44) * wq
        flops += 4 * f * cnt
        bytes_ += 4 * b * cnt
    n = model.n
    ws = sum(a.nbytes for a in op.ell) + op.groups.nbytes + 12 * n * 8      # x, v, 8 work arrays, P, Q
    return {"flops": flops / n + 45, "bytes": bytes_ / n + 240, "working_set_bytes": int(ws),
            "entries_per_dof": float(sum((g[1] - g[0]) * (g[2] + g[3]) for g in op.groups) / n)}


def rk4_counts(model) -> dict:
    """Flops and bytes per oscillator-step of RK4, counted from rk4.py: per stage one sparse product with
    force_matrix (2 flops per nonzero; bytes: value 8, index 4, gathered z 8 per nonzero, row pointer and
    output 12 per row), the quadratic products (2 per quad) and 1/m (1 per DOF); per step 26 elementwise
    flops per DOF (stage states and the final sums) and 3 per drive.  Numpy's bytes count each array once
    per elementwise operation (24 per binary op: its temporaries are arrays too); the compiled kernel's the
    loads and stores of its loops (its own CSR of K and C with 8-byte indices, 7 flops per quadratic coupling).
    Working sets: the matrices, and the state, stage and temporary arrays (~20 of n doubles for numpy, 10 for
    the kernel)."""
    from ..backends import rk4
    A = rk4.force_matrix(model)
    n, nq, nd = model.n, len(model.quads), len(model.drives)
    nnz = A.nnz
    flops = 4 * (2 * nnz + 2 * nq + n) + 26 * n + 3 * nd
    z = 2 * n + 2 * nq + nd
    stage_np = 20 * nnz + 12 * n + 16 * z + 4 * 24 * nq + 24 * n       # two gathers, two products: 4 per quad
    numpy_bytes = 4 * stage_np + 26 * 24 * n + 3 * 24 * nd
    kK, kC = model.K.nnz, model.C.nnz
    stage_c = 24 * (kK + kC) + 16 * n + 8 * n + 72 * nq + 40 * nd + 24 * n
    compiled_bytes = 4 * stage_c + 3 * 40 * n + 96 * n                 # 3 stage-state loops, the final sums
    compiled_flops = 4 * (2 * (kK + kC) + 7 * nq + 2 * nd + n) + 3 * 4 * n + 14 * n
    ws_np = 12 * nnz + 4 * n + 8 * z + 20 * 8 * n
    ws_c = 16 * (kK + kC) + 16 * n + 10 * 8 * n + 24 * nq
    return {"numpy": {"flops": flops / n, "bytes": numpy_bytes / n, "working_set_bytes": int(ws_np)},
            "compiled": {"flops": compiled_flops / n, "bytes": compiled_bytes / n, "working_set_bytes": int(ws_c)},
            "nnz": int(nnz)}


def roofline(quick: bool = False, proc: dict | None = None) -> dict:
    """Peaks measured here, counts per oscillator-step, achieved rates from the processor section."""
    model, _ = processor_model()
    peaks = machine_peaks(quick)
    cc, rc = carrier_counts(model), rk4_counts(model)
    out = {"lscpu": lscpu_caches(), "peaks": peaks, "load": _load(), "quick": quick, "oscillators": model.n,
           "counts": {"carrier": cc, "rk4 numpy": rc["numpy"], "rk4 compiled": rc["compiled"]},
           "force_matrix_nnz": rc["nnz"]}
    out["points"] = roofline_points(out, proc)
    return out


def _level_for(ws: int, lscpu: dict) -> str:
    """The benchmark level whose bandwidth bounds a kernel of working set `ws` bytes: the smallest of the
    machine's per-core caches it fits in (lscpu), else DRAM."""
    def size(key, default):
        txt = lscpu.get(key, "")
        try:
            num, unit = txt.split()[:2]
            inst = int(txt.split("(")[1].split()[0]) if "(" in txt else 1
            return float(num) * {"KiB": 1 << 10, "MiB": 1 << 20, "GiB": 1 << 30}.get(unit, 1) / inst
        except (ValueError, IndexError):
            return default
    for key, label, default in (("L1d cache", "L1 (16 KB)", 32 << 10), ("L2 cache", "L2 (256 KB)", 512 << 10),
                                ("L3 cache", "L3 (8 MB)", 16 << 20)):
        if ws <= size(key, default):
            return label
    return "DRAM (256 MB)"


def roofline_points(roof: dict, proc: dict | None) -> list[dict]:
    """Achieved GFLOP/s and GB/s of each measured kernel, its intensity and bound, and the distance."""
    if not proc:
        return []
    peaks, counts = roof["peaks"], roof["counts"]
    by = {r["method"]: r for r in proc["rows"]}
    pts = []
    for method, kernel, threads in (("carrier N=12, 1 thread", "carrier", 1), ("carrier N=12, 2 threads", "carrier", 2),
                                    ("rk4 numpy N=80", "rk4 numpy", 1), ("rk4 compiled N=80", "rk4 compiled", 1)):
        if method not in by:
            continue
        c, rate = counts[kernel], by[method]["osc_steps_per_s"]
        level = _level_for(c["working_set_bytes"], roof.get("lscpu", {}))
        bw = peaks["triad"].get(level) or next(iter(peaks["triad"].values()))
        flop_peak = peaks["fma_2t_gflops"] if threads == 2 else peaks["fma_1t_gflops"]
        mem_peak = bw["gbs_2t"] if threads == 2 else bw["gbs_1t"]
        ai = c["flops"] / c["bytes"]
        bound = min(flop_peak, ai * mem_peak)
        gf = c["flops"] * rate / 1e9
        pts.append({"method": method, "kernel": kernel, "threads": threads, "intensity": ai, "gflops": gf,
                    "gbs": c["bytes"] * rate / 1e9, "level": level, "bound_gflops": bound,
                    "limited_by": "flops" if flop_peak <= ai * mem_peak else f"{level} bandwidth",
                    "fraction_of_bound": gf / bound})
    return pts


# --- sieve -----------------------------------------------------------------------------------------------
def read_trace(path: Path) -> list[dict]:
    """A `cpu run --trace` file: one JSON object per cycle; a torn last line (a run still writing) is dropped."""
    rows = []
    path = Path(path)
    if not path.exists():
        raise Mech2SpiceError(f"sieve: no trace file {path} (make one with `mech2spice cpu run --trace FILE`)")
    for k, line in enumerate(path.read_text().splitlines()):
        if not line.strip():
            continue
        try:
            rows.append(json.loads(line))
        except json.JSONDecodeError:
            if k == len(path.read_text().splitlines()) - 1:
                break                              # the line being written
            raise Mech2SpiceError(f"sieve: {path} line {k + 1} is not JSON")
    return rows


def _result(trace: Path) -> dict | None:
    """The run's result JSON beside its trace (sieve_carrier.jsonl -> sieve_carrier.json), None if absent/empty."""
    p = Path(trace).with_suffix(".json")
    try:
        return json.loads(p.read_text()) if p.exists() and p.stat().st_size else None
    except json.JSONDecodeError:
        return None


def _per_cycle_periods(rows: list[dict]) -> list[int]:
    """Integrated periods per cycle from the cumulative `simulated_periods` (cycle 0 includes the power-up)."""
    sim = [r.get("simulated_periods", 0) for r in rows]
    return [sim[0]] + [b - a for a, b in zip(sim, sim[1:])]


def iss_registers(cycles: int) -> list[dict]:
    """The ISS's registers after each of the sieve's first `cycles` cycles (programs/sieve.asm)."""
    from .. import data
    from ..cpu import run as R
    from ..cpu.iss import ISS
    iss = ISS(R.make_memory(R.load_program(data.program("sieve.asm"))))
    out = []
    for _ in range(cycles):
        iss.step()
        out.append(iss.registers())
    return out


def compare_traces(a: list[dict], b: list[dict]) -> dict:
    """Per cycle of two traces: worst |amplitude difference| (u_R) and its probe, registers equal, each
    trace's smallest margin to a band edge."""
    from ..physics.params import margin
    n = min(len(a), len(b))
    out = {"worst_ur": [], "worst_probe": [], "registers_equal": [], "min_margin_a": [], "min_margin_b": []}
    for x, y in zip(a[:n], b[:n]):
        if x.get("cycle") != y.get("cycle"):
            raise Mech2SpiceError(f"sieve: the traces disagree on the cycle number ({x.get('cycle')} vs {y.get('cycle')})")
        keys = sorted(set(x["amps"]) & set(y["amps"]))
        d = {k: abs(x["amps"][k] - y["amps"][k]) for k in keys}
        k = max(d, key=d.get)
        out["worst_ur"].append(d[k])
        out["worst_probe"].append(k)
        out["registers_equal"].append(x.get("registers") == y.get("registers"))
        out["min_margin_a"].append(min(margin(v) for v in x["amps"].values()))
        out["min_margin_b"].append(min(margin(v) for v in y["amps"].values()))
    return out


def _iss_mismatches(rows: list[dict], iss: list[dict]) -> list[int]:
    return [r["cycle"] for r, w in zip(rows, iss) if r.get("registers") != w]


def sieve(carrier_trace=CARRIER_TRACE, envelope_trace=ENVELOPE_TRACE) -> dict:
    """Carrier against envelope per cycle: worst |amplitude difference|, registers equal, margins, periods."""
    car, env = read_trace(carrier_trace), read_trace(envelope_trace)
    n = min(len(car), len(env))
    c = compare_traces(car, env)
    worst = c["worst_ur"]
    iss = iss_registers(max(len(car), len(env)))
    rc, re_ = _result(carrier_trace), _result(envelope_trace)
    total = (re_ or {}).get("cycles") if (re_ or {}).get("halted") else None
    total = (rc or {}).get("cycles") if (rc or {}).get("halted") else (total or SIEVE_CYCLES)
    k = int(np.argmax(worst)) if worst else None
    return {"carrier_trace": str(carrier_trace), "envelope_trace": str(envelope_trace),
            "cycles_compared": n, "carrier_cycles": len(car), "envelope_cycles": len(env), "total_cycles": total,
            "complete": bool(rc and rc.get("halted") and len(car) == total),
            "worst_ur": worst, "worst_probe": c["worst_probe"], "registers_equal": c["registers_equal"],
            "min_margin_carrier": c["min_margin_a"], "min_margin_envelope": c["min_margin_b"],
            "periods_carrier": _per_cycle_periods(car[:n]), "periods_envelope": _per_cycle_periods(env[:n]),
            "schedule_end": [car[n - 1].get("period"), env[n - 1].get("period")] if n else None,
            "max_worst_ur": max(worst) if worst else None, "max_at_cycle": k,
            "max_probe": c["worst_probe"][k] if k is not None else None,
            "all_registers_equal": all(c["registers_equal"]), "carrier_result": _trim(rc), "envelope_result": _trim(re_),
            "carrier_iss_mismatches": _iss_mismatches(car, iss), "envelope_iss_mismatches": _iss_mismatches(env, iss)}


def latency(latency_trace=LATENCY_TRACE, carrier_trace=CARRIER_TRACE, envelope_trace=ENVELOPE_TRACE,
            checks=LATENCY_CHECKS) -> dict:
    """The sieve with per-gate latency: per cycle against the carrier without it and against the envelope
    (worst |amplitude difference|), registers against the ISS, integrated block-steps per cycle; and the processor_check --latency files found (cycles against full pauses)."""
    lat, car = read_trace(latency_trace), read_trace(carrier_trace)
    env = read_trace(envelope_trace) if Path(envelope_trace).exists() else []
    vs_car, vs_env = compare_traces(lat, car), compare_traces(lat, env)
    res = _result(latency_trace)
    steps = [r.get("block_steps", 0) for r in lat]
    worst = vs_car["worst_ur"]
    k = int(np.argmax(worst)) if worst else None
    return {"latency_trace": str(latency_trace), "carrier_trace": str(carrier_trace),
            "envelope_trace": str(envelope_trace), "cycles": len(lat), "carrier_cycles": len(car),
            "complete": bool(res and res.get("halted") and len(lat) == res.get("cycles")),
            "result": _trim(res), "vs_carrier": vs_car, "vs_envelope": vs_env["worst_ur"],
            "max_vs_carrier_ur": max(worst) if worst else None, "max_at_cycle": k,
            "max_probe": vs_car["worst_probe"][k] if k is not None else None,
            "iss_mismatches": _iss_mismatches(lat, iss_registers(len(lat))),
            "block_steps": [steps[0]] + [b - a for a, b in zip(steps, steps[1:])],
            "periods": _per_cycle_periods(lat),
            "carrier_result": _trim(_result(carrier_trace)), **processor_blocks(), "steps_per_period": round(1 / res["step"]) if res else _default_steps(),
            "checks": [read_json(Path(p)) | {"file": p} for p in checks if Path(p).exists()]}


def _default_steps() -> int:
    from ..backends.carrier import DEFAULT_STEPS_PER_PERIOD
    return DEFAULT_STEPS_PER_PERIOD


def processor_blocks() -> dict:
    """The processor model's gate blocks (what one step of full integration covers) and oscillators per block."""
    from ..cpu.netlist import CPU_VERILOG, cpu_netlist
    from ..physics.params import DEFAULT
    from ..simulation import network
    model = network.build(cpu_netlist(str(CPU_VERILOG), max_fanout=network.MAX_FANOUT), DEFAULT)
    return {"blocks": len(model.design.gates), "dofs_per_block": model.n / len(model.design.gates)}


def _trim(res: dict | None) -> dict | None:
    keys = ("backend", "cycles", "halted", "wall_s", "wall_s_total", "cpu_s_total", "periods", "simulated_periods",
            "step", "settle", "latency", "block_steps", "registers")
    return {k: res[k] for k in keys if k in res} if res else None


# --- charts ------------------------------------------------------------------------------------------------
MARK = {"carrier": ("tab:blue", "o"), "rk4": ("tab:orange", "s"), "ngspice": ("tab:green", "^")}


def chart_speed_accuracy(d: dict, out: Path) -> str | None:
    """Error against wall time per method (log-log), one column per scene, the amplitude error above and the
    final-state error below; failures drawn as x at the top."""
    conv = d.get("convergence")
    if not conv:
        return None
    plt = pyplot()
    scenes = conv["scenes"]
    fig, axes = plt.subplots(2, len(scenes), figsize=(5.2 * len(scenes), 8.0), squeeze=False)
    for col, (name, s) in enumerate(scenes.items()):
        for ax, key, what in ((axes[0, col], "err_ur", "max |A| difference over every period"),
                              (axes[1, col], "final_ur", "final-state max |x| difference")):
            _error_panel(ax, s, key)
            ax.set_ylabel(f"{what}\nvs RK4 T/{FINE_STEPS} [u_R]", fontsize=8)
        axes[0, col].set_title(f"{s['description']}\n{s['members']} members, {s['oscillators']} oscillators",
                               fontsize=8)
    load = ", ".join(f"{x:g}" for x in conv.get("load", []))
    fig.suptitle(f"carrier (Lawson RK4) vs RK4 vs ngspice; labels: steps per period; x: failed (diverged or > "
                 f"{FAIL_UR} u_R); dashed 1e-3 u_R\n{_measured_on(', load ' + load)}", fontsize=8)
    name = "carrier_speed_accuracy.png"
    save_figure(fig, out / name)
    return name


def _error_panel(ax, s: dict, key: str) -> None:
    ok = [r[key] for r in s["rows"] if "failed" not in r and r.get(key, 0) > 0]
    top = max([FAIL_UR] + ok) * 3
    for method, (color, marker) in MARK.items():
        rows = [r for r in s["rows"] if r["method"] == method]
        good = [r for r in rows if "failed" not in r and key in r]
        if good:
            ax.plot([r["wall_s"] for r in good], [max(r[key], 1e-12) for r in good], marker=marker,
                    color=color, label=method)
            for r in good:
                ax.annotate(str(r["steps"]), (r["wall_s"], max(r[key], 1e-12)), fontsize=6,
                            xytext=(3, 3), textcoords="offset points")
        bad = [r for r in rows if "failed" in r]
        if bad:
            ax.scatter([max(r["wall_s"], 1e-3) for r in bad], [top] * len(bad), marker="x", color=color,
                       label=f"{method} failed ({', '.join(str(r['steps']) for r in bad)} steps)")
    ax.axhline(AMP_TOL, color="0.5", ls="--", lw=0.8)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.xaxis.set_minor_formatter(pyplot().NullFormatter())
    ax.set_xlabel("wall time [s]")
    ax.legend(fontsize=6)


def chart_roofline(d: dict, out: Path) -> str | None:
    roof = d.get("roofline")
    if not roof or not roof.get("points"):
        return None
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    ai = np.logspace(-3, 1, 100)
    pk = roof["peaks"]
    for threads, style in ((1, "-"), (2, "--")):
        fl = pk["fma_1t_gflops" if threads == 1 else "fma_2t_gflops"]
        for k, (label, bw) in enumerate(pk["triad"].items()):
            g = bw["gbs_1t" if threads == 1 else "gbs_2t"]
            ax.plot(ai, np.minimum(fl, ai * g), style, color=f"C{k}", lw=0.9,
                    label=f"{label} triad, {threads} thread{'s' * (threads > 1)}")
    for k, p in enumerate(roof["points"]):
        ax.scatter(p["intensity"], p["gflops"], marker="o" if "carrier" in p["kernel"] else "s", s=40, zorder=5,
                   color=f"C{k + 4}", label=f"{p['method']}: {p['gflops']:.2f} GFLOP/s, "
                                           f"{p['fraction_of_bound']:.0%} of its bound")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("arithmetic intensity [flop/byte] (counted from the code)")
    ax.set_ylabel("GFLOP/s")
    ax.set_xlim(1e-3, 10)
    ax.legend(fontsize=5, loc="lower right", ncol=2)
    ax.set_title(f"roofline: processor model ({roof['oscillators']} oscillators), peaks by numba "
                 f"microbenchmarks;\n{_measured_on(', load %g' % roof['load'])}", fontsize=8)
    name = "carrier_roofline.png"
    save_figure(fig, out / name)
    return name


def chart_sieve(d: dict, out: Path) -> str | None:
    s = d.get("sieve")
    if not s or not s["cycles_compared"]:
        return None
    plt = pyplot()
    cyc = np.arange(s["cycles_compared"])
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(7.5, 5.6), sharex=True)
    a1.semilogy(cyc, np.maximum(s["worst_ur"], 1e-7), ".", ms=3)
    bad = [k for k, ok in enumerate(s["registers_equal"]) if not ok]
    if bad:
        a1.scatter(bad, np.maximum(np.array(s["worst_ur"])[bad], 1e-7), marker="x", color="tab:red",
                   label="registers differ")
        a1.legend(fontsize=7)
    a1.set_ylabel("worst |A_carrier - A_envelope| [u_R]")
    a2.plot(cyc, s["min_margin_carrier"], ".", ms=3, label="carrier")
    a2.plot(cyc, s["min_margin_envelope"], ".", ms=3, label="envelope")
    a2.set_ylabel("smallest margin to a band edge\n[band widths]")
    a2.set_xlabel("sieve cycle")
    a2.legend(fontsize=7)
    fig.suptitle(f"the sieve on the processor: carrier (oscillator level) vs envelope at each cycle's end,\n"
                 f"{s['cycles_compared']} of {s['total_cycles']} cycles; traces by `cpu run --trace`; {SANDBOX} (shared; "
                 f"the runs' load is not in the traces)",
                 fontsize=8)
    name = "carrier_sieve_fidelity.png"
    save_figure(fig, out / name)
    return name


def chart_latency(d: dict, out: Path) -> str | None:
    s = d.get("latency")
    if not s or not s["cycles"]:
        return None
    plt = pyplot()
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(7.5, 5.6), sharex=True)
    vc = s["vs_carrier"]["worst_ur"]
    a1.semilogy(np.arange(len(vc)), np.maximum(vc, 1e-7), ".", ms=3, label="latency vs carrier without it")
    if s["vs_envelope"]:
        a1.semilogy(np.arange(len(s["vs_envelope"])), np.maximum(s["vs_envelope"], 1e-7), ".", ms=2, alpha=0.5,
                    color="tab:gray", label="latency vs envelope")
    a1.axhline(REDUCED_TOL, color="tab:red", lw=0.8, ls="--", label=f"{REDUCED_TOL} u_R")
    a1.set_ylabel("worst |A difference|\nat the cycle's end [u_R]")
    a1.legend(fontsize=7, loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=3, frameon=False)
    full = s["blocks"] * s["steps_per_period"]
    per = np.array(s["periods"], float)
    frac = np.array(s["block_steps"], float) / np.maximum(full * per, 1)
    a2.plot(np.arange(len(frac)), frac, ".", ms=3)
    a2.set_ylabel("active fraction: block-steps /\nall blocks x integrated periods", fontsize=8)
    a2.set_xlabel("sieve cycle")
    res = s.get("result") or {}
    fig.suptitle(f"the sieve at oscillator level with per-gate latency {res.get('latency', '(running)')} u_R: "
                 f"{s['cycles']} cycles,\n"
                 f"compared with the carrier without latency; {SANDBOX} (shared)", fontsize=8, y=1.0)
    name = "carrier_latency_sieve.png"
    save_figure(fig, out / name)
    return name


# --- markdown ---------------------------------------------------------------------------------------------
def _e(x) -> str:
    return "-" if x is None else f"{x:.1e}"


def accuracy_md(a: dict) -> list[str]:
    rows = [[r["scene"], f"{r['members']} x {r['periods']}", r["oscillators"], _e(r["amp_ur"]), f"{r['phase_deg']:.3f}",
             "yes" if r["bits_equal"] else "**no**", f"{r['rk4_wall_s']:.1f} / {r['carrier_wall_s']:.1f}",
             "PASS" if r["pass"] else "**FAIL**"] for r in a["rows"]]
    return ["## Accuracy against RK4 at 160 steps per period", "",
            f"`carrier` at {a['steps']} steps per period against `rk4.integrate` at {a['ref_steps']} on the scenes of "
            f"`experiments/scenes.py`, from rest: the worst |amplitude| difference over every period, probe and "
            f"member, the worst phase difference where |A| > 0.1 u_R, and the bands decoded at each read window. "
            f"Bounds (issue 15): {AMP_TOL:g} u_R and {PHASE_TOL:g} deg. {_measured_on(', load %g' % a['load'])}"
            + (", `--quick` (shorter scenes)" if a.get("quick") else "") + ".", "",
            *md_table(["scene", "members x periods", "oscillators", "max amplitude diff [u_R]", "max phase [deg]",
                       "bits equal", "wall RK4 160 / carrier [s]", "verdict"], rows), ""]


def _conv_table(s: dict) -> list[str]:
    rows = []
    for r in s["rows"]:
        err = "-" if "err_ur" not in r else _e(r["err_ur"])
        rows.append([r["method"], f"{r['steps']}" + (" (scan)" if r.get("scan") else ""), err,
                     _e(r.get("final_ur")), f"{r['wall_s']:.3f}",
                     r.get("failed", "") or "ok"])
    return md_table(["method", "steps / period", "max amplitude diff [u_R]", "final state [u_R]", "wall [s]",
                     "status"], rows)


def convergence_md(c: dict, chart: str | None, heading: str = "##") -> list[str]:
    L = [f"{heading} Convergence: error against steps and wall time", "",
         f"Against a fine reference, {c['reference']} (not the 160-step reference of the accuracy table). "
         f"*max amplitude diff*: the worst |A| difference over every period, probe and member; *final state*: the "
         f"worst |x| difference at the end (the integrators' own error: RK4 reads amplitudes by the period's end "
         f"points, carrier by the trapezoid rule, ~1e-4 u_R apart at 160 steps). A run fails where it diverges "
         f"(`DivergenceError`) or its amplitude error exceeds {c['fail_ur']} u_R; *(scan)* rows look for those "
         f"points (carrier below its minimum of 4 steps, run through `carrier.integrate`). The gate's runs take "
         f"milliseconds, so its wall times are mostly call overhead; the adder's measure the integrators. ngspice "
         f"(trap + prewarp, reltol 1e-5: the package default) runs on the gate only, where installed and not "
         f"with --quick (the adder's 16 members would be 16 processes). "
         f"Wall times are ratios within this run (one run after another; {_measured_on(', load ' + ', '.join(f'{x:g}' for x in c['load']))}"
         f"{', --quick' if c.get('quick') else ''}); ngspice's is the sum of its processes' wall times.", ""]
    for name, s in c["scenes"].items():
        L += [f"**{name}**: {s['description']} ({s['members']} members, {s['oscillators']} oscillators; the "
              f"reference took {s['ref_wall_s']:.1f} s).", "", *_conv_table(s), ""]
        L += _where_equal(s) + [""]
    if chart:
        L += [f"![error against wall time]({chart})", ""]
    return L


def _where_equal(s: dict) -> list[str]:
    """The cheapest run of each method within 1e-3 u_R, and the coarsest each method survives."""
    out = []
    for m in ("carrier", "rk4", "ngspice"):
        rows = [r for r in s["rows"] if r["method"] == m]
        ok = [r for r in rows if "failed" not in r and r["err_ur"] < AMP_TOL]
        bad = [r for r in rows if "failed" in r]
        if not rows:
            continue
        line = f"- {m}: " + (f"fewest steps within {AMP_TOL:g} u_R: {min(ok, key=lambda r: r['steps'])['steps']} "
                             f"({min(ok, key=lambda r: r['steps'])['wall_s']:.2f} s)" if ok else f"none within {AMP_TOL:g} u_R")
        line += "; fails at " + (", ".join(f"{r['steps']} ({r['failed']})" for r in bad) if bad else
                                 "none of the steps run")
        out.append(line)
    return out


def processor_md(p: dict, r: dict, eq: dict | None, conv: dict | None = None) -> list[str]:
    rows = [[x["method"], x["steps"], " / ".join(f"{w:.2f}" for w in x["walls_s"]), f"{x['median_s']:.2f}",
             f"{x['periods_per_s']:.1f}", f"{x['osc_steps_per_s']:.2e}"] for x in p["rows"]]
    L = ["## Rate on the processor", "",
         f"The processor model (`cpu.netlist.cpu_netlist`, {p['oscillators']} oscillators) from rest with rst = 1, "
         f"{p['periods']} periods per run; the methods alternated {p['repeats']} times in one run, medians. "
         f"`rk4.integrate` takes its numpy sparse path here (above {3000} oscillator-copies); *compiled* forces "
         f"its numba kernel. Two threads need both cores free: each of a step's four passes ends at a barrier, "
         f"so a thread the other jobs deschedule stalls its partner. "
         f"{_measured_on(', load ' + ', '.join(f'{x:g}' for x in p['load']))}"
         f"{', --quick' if p.get('quick') else ''}.", "",
         *md_table(["method", "steps / period", "walls [s]", "median [s]", "periods/s", "oscillator-steps/s"], rows), "",
         "(a) oscillator-steps/s, carrier over RK4: " + "; ".join(f"{k}: **{v:.2f}x**" for k, v in r["a"].items()) + ".", ""]
    if eq:
        ba = eq.get("by_amplitude", {})
        L += [f"(b) periods/s at equal accuracy: carrier at {eq['carrier_steps']} steps has a final-state error of "
              f"{eq['carrier_err_ur']:.1e} u_R on the gate (convergence section); the RK4 step nearest it is "
              f"{eq['rk4_steps']} ({eq['rk4_err_ur']:.1e} u_R)" +
              (f" (by the amplitude metric, which also holds the two readouts' difference: carrier "
               f"{ba['carrier_err_ur']:.1e}, nearest RK4 {ba['rk4_steps']} at {ba['rk4_err_ur']:.1e} u_R)" if ba else "") +
              f". RK4's periods/s there = its measured oscillator-steps/s / "
              f"({p['oscillators']} x {eq['rk4_steps']}): " +
              "; ".join(f"{k}: **{v:.1f}x**" for k, v in r["b"].items()) +
              ". The issue's bar: >= 10x.", ""]
        other = equal_accuracy(conv, eq["carrier_steps"], "adder2")
        if other:
            rb = ratios(p, other)["b"]
            L += [f"By the adder's errors instead (its convergence scene) the RK4 step nearest carrier's "
                  f"({other['carrier_err_ur']:.1e} u_R final state) is {other['rk4_steps']} "
                  f"({other['rk4_err_ur']:.1e} u_R): " + "; ".join(f"{k}: {v:.1f}x" for k, v in rb.items()) + ".", ""]
    else:
        L += ["(b) periods/s at equal accuracy: needs the convergence section (not measured yet).", ""]
    return L


def roofline_md(roof: dict, chart: str | None, heading: str = "##") -> list[str]:
    pk = roof["peaks"]
    L = [f"{heading} Roofline: the kernels against this machine's measured peaks", "",
         f"Peaks by numba microbenchmarks (`mech2spice/reports/carrier.py`, best of 3): independent FMA chains (four "
         f"dependent FMAs per element per pass over {pk.get('fma_width', 64)} doubles held in L1), and the triad a = b + s c (24 bytes per element: write-allocate not counted) at "
         f"each working set. {_measured_on(', load %g' % roof['load'])}; lscpu: " +
         ", ".join(f"{k} {v}" for k, v in roof.get("lscpu", {}).items()) + ".", "",
         f"FMA: **{pk['fma_1t_gflops']:.1f} GFLOP/s** on 1 thread, **{pk['fma_2t_gflops']:.1f}** on {pk['threads']}.", "",
         *md_table(["working set", "triad 1 thread [GB/s]", f"triad {pk['threads']} threads [GB/s]"],
                   [[k, f"{v['gbs_1t']:.1f}", f"{v['gbs_2t']:.1f}"] for k, v in pk["triad"].items()]), "",
         f"Per oscillator-step on the processor model ({roof['oscillators']} oscillators; force_matrix has "
         f"{roof['force_matrix_nnz']} nonzeros), counted from the code (`carrier_counts`, `rk4_counts`: the "
         "loops' loads and stores, so bytes from L1 up, not DRAM traffic):", "",
         *md_table(["kernel", "flops", "bytes", "flop/byte"],
                   [[k, f"{c['flops']:.0f}", f"{c['bytes']:.0f}", f"{c['flops'] / c['bytes']:.3f}"]
                    for k, c in roof["counts"].items()]), ""]
    if roof.get("points"):
        L += ["Achieved (the processor section's rates) and the bound min(FMA peak, intensity x triad bandwidth "
              "of the cache level the kernel's working set fits in, by lscpu's per-core sizes):", "",
              *md_table(["run", "GFLOP/s", "GB/s", "level", "bound [GFLOP/s]", "limited by", "distance: achieved / bound"],
                        [[p["method"], f"{p['gflops']:.2f}", f"{p['gbs']:.1f}", p["level"], f"{p['bound_gflops']:.1f}",
                          p["limited_by"], f"**{p['fraction_of_bound']:.0%}**"] for p in roof["points"]]), ""]
        L += ["Working sets on the processor: " + ", ".join(f"{k} {c['working_set_bytes'] / 1024:.0f} KiB"
                                                           for k, c in roof["counts"].items()) + ".", ""]
    if chart:
        L += [f"![roofline]({chart})", ""]
    return L


def sieve_md(s: dict, chart: str | None, heading: str = "##") -> list[str]:
    n, total = s["cycles_compared"], s["total_cycles"]
    so_far = "" if s["complete"] else f" ({s['carrier_cycles']} of {total} cycles so far: the carrier run has not halted yet)"
    L = [f"{heading} The whole sieve: envelope against oscillator level", "",
         f"Two `mech2spice cpu run --trace` files of the sieve compared cycle by cycle: `carrier` (Lawson RK4, "
         f"oscillator level) and the envelope, the amplitudes each cycle is decoded from (mean of "
         f"its last 10 periods) for every probe (output bits and latch outputs). Compared: **{n} cycles**{so_far}. Traces: `{s['carrier_trace']}`, `{s['envelope_trace']}`; "
         f"{SANDBOX}.", ""]
    if n:
        L += [f"- worst amplitude difference over all compared cycles: **{s['max_worst_ur']:.4f} u_R** (cycle "
              f"{s['max_at_cycle']}, `{s['max_probe']}`); median per cycle {np.median(s['worst_ur']):.4f} u_R; "
              f"cycles above the 0.02 u_R tolerance of reduced models (reports/fidelity.md): "
              f"{sum(w > REDUCED_TOL for w in s['worst_ur'])}",
              f"- registers equal at every compared cycle: **{'yes' if s['all_registers_equal'] else 'no'}**"
              + ("" if s["all_registers_equal"] else
                 f" (differ at {sum(not x for x in s['registers_equal'])} cycles, first "
                 f"{s['registers_equal'].index(False)})"),
              f"- against the ISS (programs/sieve.asm), registers after every traced cycle: carrier "
              f"{_iss_line(s, 'carrier')}, envelope {_iss_line(s, 'envelope')}",
              f"- smallest margin to a band edge: carrier {min(s['min_margin_carrier']):+.3f}, envelope "
              f"{min(s['min_margin_envelope']):+.3f} band widths",
              f"- integrated periods per cycle (median; cycle 0 includes the power-up): carrier "
              f"{np.median(s['periods_carrier'][1:] or s['periods_carrier']):.0f}, envelope "
              f"{np.median(s['periods_envelope'][1:] or s['periods_envelope']):.0f}; over the compared cycles "
              f"{sum(s['periods_carrier']):,} and {sum(s['periods_envelope']):,}"]
        if s.get("schedule_end") and None not in s["schedule_end"]:
            L.append(f"- schedules: by the end of cycle {n - 1} the carrier run had simulated "
                     f"{s['schedule_end'][0]:,} periods and the envelope {s['schedule_end'][1]:,} (the envelope rounds "
                     f"each pulse and pause up to whole steps), so the two are compared at slightly different times")
        for name, res in (("carrier", s.get("carrier_result")), ("envelope", s.get("envelope_result"))):
            if res:
                setting = (f"step {res['step']:g} periods" if res.get("step") else "") + \
                    (f", settle {res['settle']:g} u_R" if res.get("settle") else "")
                wall = (f"wall {res['wall_s_total']:.0f} s and {res['cpu_s_total']:.0f} CPU-s over all its parts"
                        if "wall_s_total" in res else
                        f"wall {res.get('wall_s', float('nan')):.0f} s of its last process (the parts before a "
                        "resume not included)")
                L.append(f"- {name} run ({setting or 'settings not recorded'}): {res.get('cycles')} cycles, halted "
                         f"{res.get('halted')}, {wall}, {res.get('simulated_periods', 0):,} of "
                         f"{res.get('periods', 0):,} periods integrated")
        L.append("")
    if chart:
        L += [f"![worst difference and margins per cycle]({chart})", ""]
    return L


def latency_md(s: dict, chart: str | None, heading: str = "##") -> list[str]:
    res, n = s.get("result") or {}, s["cycles"]
    vc = s["vs_carrier"]
    m = min(n, s["carrier_cycles"])
    full = s["blocks"] * s["steps_per_period"] * (res.get("periods") or 0)
    L = [f"{heading} Per-gate latency at oscillator level: the whole sieve", "",
         f"`mech2spice cpu run programs/sieve.asm --backend carrier --trace` with per-gate latency at "
         f"{res.get('latency')} u_R (backends/_carrier_latency.py, docs/carrier.md): a gate block whose channel "
         "stayed settled is frozen, its neighbours reading one recorded period of its orbit, until an input "
         f"channel moves by the threshold. Trace `{s['latency_trace']}`, compared with the carrier run without "
         f"latency (`{s['carrier_trace']}`, the same settle rule) at each cycle's end; {SANDBOX}.", ""]
    if res:
        L.append(f"- the run: {res.get('cycles')} cycles, halted **{res.get('halted')}**, wall "
                 f"**{res.get('wall_s_total', res.get('wall_s', 0)) / 60:.1f} min** and "
                 f"{res.get('cpu_s_total', 0) / 60:.1f} CPU-min (one thread; other jobs shared the machine, so "
                 f"the CPU time is the figure for a free core)")
    else:
        L.append(f"- the run has not finished: {n} cycles traced so far")
    car = s.get("carrier_result") or {}
    if full:
        L.append(f"- integrated: {sum(s['block_steps']):,} block-steps, {sum(s['block_steps']) / full:.1%} of "
                 f"all {s['blocks']} blocks over all {res['periods']:,} periods of the schedule"
                 + (f"; the carrier without latency integrates every block over "
                    f"{car['simulated_periods'] / car['periods']:.1%} of them (its pauses end once all channels "
                    "settle)" if car.get("periods") else "")
                 + (f", {car['cpu_s_total'] / 60:.0f} CPU-min" if car.get("cpu_s_total") else ""))
        if res.get("cpu_s_total") and s.get("dofs_per_block"):
            ns = res["cpu_s_total"] / sum(s["block_steps"]) / s["dofs_per_block"] * 1e9
            L.append(f"- cost per oscillator-step integrated: {ns:.0f} ns (the run's CPU time over block-steps x "
                     "oscillators per block, decisions and replay included; the full-range kernel's is in the "
                     "processor section)")
    L += [f"- against the ISS, registers after every cycle: **{n - len(s['iss_mismatches'])} of {n} equal**"
          + (f" (first differing cycle {s['iss_mismatches'][0]})" if s["iss_mismatches"] else ""),
          f"- against the carrier without latency ({m} cycles): worst **{s['max_vs_carrier_ur']:.4f} u_R** (cycle "
          f"{s['max_at_cycle']}, `{s['max_probe']}`), median {np.median(vc['worst_ur']):.4f} u_R, "
          f"{sum(w > REDUCED_TOL for w in vc['worst_ur'])} cycles above {REDUCED_TOL} u_R; registers equal at "
          f"{sum(vc['registers_equal'])} of {m}"]
    if s["vs_envelope"]:
        L.append(f"- against the envelope run: worst {max(s['vs_envelope']):.4f} u_R, median "
                 f"{np.median(s['vs_envelope']):.4f} u_R (the carrier without latency against it is in the "
                 "section above)")
    L.append("")
    if s["checks"]:
        L += ["Whole cycles continued from one carrier checkpoint against the carrier with **full pauses** (no "
              "idle skipping at all; `python -m mech2spice.experiments.processor_check CHECKPOINT --latency TOL`): "
              "the worst amplitude and phase difference at a cycle's end over the cycles run, and the work.", ""]
        rows = []
        for c in s["checks"]:
            cyc = f"{c['settle_vs_full'][0]['cycle']}-{c['settle_vs_full'][-1]['cycle']}"
            rows.append([cyc, "idle skipping alone (settle 0.1)", f"{max(r['amp_diff'] for r in c['settle_vs_full']):.4f}",
                         f"{max(r['phase_diff_deg'] for r in c['settle_vs_full']):.2f}",
                         "yes" if all(r["registers_equal"] for r in c["settle_vs_full"]) else "**no**",
                         f"{c['settle_periods']:,}", f"{c['settle_wall_s']:.0f}"])
            for lat in c["latency"]:
                rows.append([cyc, f"+ latency {lat['tol']:g}", f"{max(r['amp_diff'] for r in lat['vs_full']):.4f}",
                             f"{max(r['phase_diff_deg'] for r in lat['vs_full']):.2f}",
                             "yes" if all(r["registers_equal"] for r in lat["vs_full"]) else "**no**",
                             f"{lat['periods']:,}", f"{lat['wall_s']:.0f}"])
            rows.append([cyc, "full pauses (the reference)", "-", "-", "-", f"{c['full_periods']:,}",
                         f"{c['full_wall_s']:.0f}"])
        L += [*md_table(["cycles", "carrier", "max amplitude diff [u_R]", "max phase [deg]", "registers equal",
                         "periods integrated", "wall [s]"], rows),
              "", "Periods integrated count a period with any block active; wall times shared the machine with "
              "other jobs.", ""]
    if chart:
        L += [f"![latency against the carrier per cycle]({chart})", ""]
    return L


def _iss_line(s: dict, which: str) -> str:
    bad = s.get(f"{which}_iss_mismatches")
    n = s[f"{which}_cycles"]
    if bad is None:
        return "not checked"
    return f"**{n - len(bad)} of {n} equal**" + (f" (first differing cycle {bad[0]})" if bad else "")


def markdown(d: dict) -> str:
    L = ["# The carrier engine: Lawson RK4 at oscillator level", "",
         "Generated by `mech2spice report carrier` (sections: `--only accuracy|convergence|processor|roofline|sieve`, "
         "`--render`). The engine (`--backend carrier`, backends/carrier.py) propagates every oscillator's linear "
         "part exactly and takes couplings, quadratic terms and drives in classical RK4 on the transformed "
         "variable (Lawson 1967; Hochbruck & Ostermann 2010, Sec. 2.6).", ""]
    charts = d.get("charts", {})
    if "accuracy" in d:
        L += accuracy_md(d["accuracy"])
    if "convergence" in d:
        L += convergence_md(d["convergence"], charts.get("speed_accuracy"))
    if "processor" in d:
        eq = equal_accuracy(d.get("convergence"))
        L += processor_md(d["processor"], ratios(d["processor"], eq), eq, d.get("convergence"))
    if "roofline" in d:
        L += roofline_md(d["roofline"], charts.get("roofline"))
    if "cycles" in d:
        L += cycles_md(d["cycles"])
    if "sieve" in d:
        L += sieve_md(d["sieve"], charts.get("sieve"))
    if "latency" in d:
        L += latency_md(d["latency"], charts.get("latency"))
    return "\n".join(L) + "\n"


def cycles(path=PROCESSOR_CHECK) -> dict:
    """experiments.processor_check's comparison (a separate ~20-minute run: RK4 at 160 steps on the processor)."""
    path = Path(path)
    if not path.exists():
        raise Mech2SpiceError(f"cycles: no {path} (make it with `python -m mech2spice.experiments.processor_check "
                              f"CHECKPOINT --out {path}`)")
    return {**read_json(path), "file": str(path)}


def cycles_md(c: dict) -> list[str]:
    rows = [[r["cycle"], r["instr"] or "(data cycle)", _e(r["amp_diff"]), f"{r['phase_diff_deg']:.3f}",
             "yes" if r["registers_equal"] else "**no**",
             "PASS" if r["amp_diff"] < AMP_TOL and r["phase_diff_deg"] < PHASE_TOL else "**FAIL**"]
            for r in c.get("cycles", [])]
    L = ["## Processor cycles against RK4 at 160 steps per period", "",
         f"Both engines continue the same `cpu run --backend carrier` checkpoint ({Path(c['checkpoint']).name}) for "
         f"{len(rows)} whole cycles under the same rules (pulses in full, pauses ending once the channels settle "
         f"within 0.1 u_R), and every probed amplitude (output ports and latch outputs) is compared at the end of "
         f"each cycle (`python -m mech2spice.experiments.processor_check`). RK4 at {c['steps']} steps costs "
         f"{c['rk4_wall_s']:.0f} s for these {c['rk4_periods']:,} periods against the carrier's "
         f"{c['carrier_wall_s']:.0f} s for {c['carrier_periods']:,} ({SANDBOX}, shared with other jobs), "
         "which is why the whole sieve is not checked against it.", "",
         *md_table(["cycle", "instruction", "max amplitude diff [u_R]", "max phase [deg]", "registers equal",
                    "verdict"], rows), ""]
    if "settle_vs_full" in c:
        rows = c["settle_vs_full"]
        worst, phase = max(r["amp_diff"] for r in rows), max(r["phase_diff_deg"] for r in rows)
        L += [f"What ending the pauses early costs (the carrier with idle skipping against full pauses, on "
              f"{len(rows)} of the cycles above, {', '.join(str(r['cycle']) for r in rows)}): at most {worst:.3f} u_R and {phase:.1f} deg at the end of a cycle, every "
              f"register equal; {c.get('settle_periods', c['carrier_periods']):,} against {c['full_periods']:,} "
              "integrated periods. The phase is not part of the rule (it watches amplitudes) and not of the "
              "decoding; the difference is the slow ringing the rule ignores (docs/carrier.md).", ""]
    return L


# --- blocks other reports append ---------------------------------------------------------------------------
def _json(directory) -> dict:
    return read_json(Path(directory) / "carrier.json") or {}


def block(directory) -> str:
    """speed_accuracy.md's section from DIRECTORY/carrier.json ('' before the convergence section ran)."""
    d = _json(directory)
    if "convergence" not in d:
        return ""
    L = ["## Carrier-level Lawson RK4 beside RK4 and ngspice", "",
         "`--backend carrier` (reports/carrier.md): each oscillator's linear part propagated exactly, couplings "
         "and quadratic terms explicit in RK4."]
    if "accuracy" in d:
        a = d["accuracy"]
        L[-1] += (f" Against RK4 at 160 steps at its default {a['steps']} steps: " +
                  "; ".join(f"{r['scene']} {r['amp_ur']:.1e} u_R, {r['phase_deg']:.2f} deg" for r in a["rows"]) + ".")
    L.append("")
    return "\n".join(L + convergence_md(d["convergence"], d.get("charts", {}).get("speed_accuracy"), "###")) + "\n"


def roofline_block(directory) -> str:
    """performance.md's roofline section from DIRECTORY/carrier.json ('' before it was measured)."""
    d = _json(directory)
    if "roofline" not in d:
        return ""
    return "\n".join(roofline_md(d["roofline"], d.get("charts", {}).get("roofline"))) + "\n"


def sieve_block(directory) -> str:
    """fidelity.md's whole-sieve section from DIRECTORY/carrier.json ('' before it was read)."""
    d = _json(directory)
    if "sieve" not in d:
        return ""
    return "\n".join(sieve_md(d["sieve"], d.get("charts", {}).get("sieve"))) + "\n"


# --- entry point -------------------------------------------------------------------------------------------
def _sections(only) -> list[str]:
    wanted = list(only or SECTIONS)
    bad = [s for s in wanted if s not in SECTIONS]
    if bad:
        raise Mech2SpiceError(f"carrier: unknown section {', '.join(bad)} (choose from {', '.join(SECTIONS)})")
    return wanted


def render_all(d: dict, out: Path) -> Path:
    """Charts and carrier.md from the results `d` (written back with the chart names)."""
    d["charts"] = {k: v for k, v in (("speed_accuracy", chart_speed_accuracy(d, out)),
                                     ("roofline", chart_roofline(d, out)), ("sieve", chart_sieve(d, out)),
                                     ("latency", chart_latency(d, out))) if v}
    write_json(out / "carrier.json", d)
    (out / "carrier.md").write_text(markdown(d))
    return out / "carrier.md"


def write(directory="reports", only=None, quick: bool = False, render: bool = False,
          carrier_trace: str | None = None, envelope_trace: str | None = None,
          processor_check: str | None = None, latency_trace: str | None = None) -> Path:
    """Measure the sections in `only` (default all; `render`: none), merge them into carrier.json, rewrite
    carrier.md and the charts from the whole JSON."""
    sections = [] if render else _sections(only)
    out = out_dir(directory)
    d = read_json(out / "carrier.json", {})
    d["machine"] = _measured_on()
    for name in sections:
        t0 = time.perf_counter()
        if name == "sieve":
            traces = (carrier_trace or CARRIER_TRACE, envelope_trace or ENVELOPE_TRACE)
            if not only and not all(Path(t).exists() for t in traces):
                print(f"[carrier] sieve: skipped, no trace files {traces[0]}, {traces[1]}", flush=True)
                continue                                  # `all`: the traces come from a separate ~1 h run
            d[name] = sieve(*traces)
        elif name == "latency":
            traces = (latency_trace or LATENCY_TRACE, carrier_trace or CARRIER_TRACE, envelope_trace or ENVELOPE_TRACE)
            if not only and not all(Path(t).exists() for t in traces[:2]):
                print(f"[carrier] latency: skipped, no trace files {traces[0]}, {traces[1]}", flush=True)
                continue
            d[name] = latency(*traces)
        elif name == "roofline":
            d[name] = roofline(quick, d.get("processor"))
        elif name == "cycles":
            if not only and not Path(processor_check or PROCESSOR_CHECK).exists():
                print(f"[carrier] cycles: skipped, no {processor_check or PROCESSOR_CHECK}", flush=True)
                continue
            d[name] = cycles(processor_check or PROCESSOR_CHECK)
        else:
            d[name] = globals()[name](quick)
        if name == "processor" and "roofline" in d:       # new rates: new achieved points
            d["roofline"]["points"] = roofline_points(d["roofline"], d[name])
        d.setdefault("section_s", {})[name] = time.perf_counter() - t0
        write_json(out / "carrier.json", d)
        print(f"[carrier] {name}: {d['section_s'][name]:.0f} s", flush=True)
    return render_all(d, out)
