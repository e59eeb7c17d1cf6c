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

mech2spice/reports/carrier.py renders the JSON (and the blocks other reports append).  ~10 min on an idle 2-core machine, `--quick` < 2 min.
"""
from __future__ import annotations

import json
import subprocess
import time
from pathlib import Path

import numpy as np

from ..compare import agreement, trajectory
from ..errors import DivergenceError, Mech2SpiceError
from ._common import SANDBOX, conditions, load_average, read_json, sections, write_json

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
    return {"steps": steps, "ref_steps": REF_STEPS, "quick": quick, "load": load_average()[0], "rows": rows}


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
    from ..spice.oscillator_netlist import SpiceOptions
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
           "load": [load_average()[0]], "scenes": {}}
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
        out["load"].append(load_average()[0])
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
    load = [load_average()[0]]
    for r in range(repeats):
        for label, (_, fn) in runs.items():
            t0 = time.perf_counter()
            fn(periods)
            walls[label].append(time.perf_counter() - t0)
            print(f"[processor] repeat {r}: {label} {walls[label][-1]:.2f} s", flush=True)
        load.append(load_average()[0])
    rows = []
    for label, (n, _) in runs.items():
        wall = float(np.median(walls[label]))
        rows.append({"method": label, "steps": n, "walls_s": walls[label], "median_s": wall,
                     "periods_per_s": periods / wall, "osc_steps_per_s": model.n * n * periods / wall})
    return {"oscillators": model.n, "periods": periods, "repeats": repeats, "load": load, "quick": quick, "rows": rows}


# --- roofline --------------------------------------------------------------------------------------------
def _bench_kernels():
    """Numba microbenchmarks: FMA chains (four dependent FMAs per element per pass, so loads and stores do not
    bound it; FMA contraction only, no reassociation that could fold the chain) and the triad."""
    from numba import njit, prange
    flags = dict(fastmath={"contract"}, cache=False)     # compiled once per run, before the timings (warm calls)

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
    out = {"lscpu": lscpu_caches(), "peaks": peaks, "load": load_average()[0], "quick": quick, "oscillators": model.n,
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



def cycles(path=PROCESSOR_CHECK) -> dict:
    """experiments.processor_check's comparison (a separate ~20-minute run: RK4 at 160 steps on the processor)."""
    path = Path(path)
    if not path.exists():
        raise Mech2SpiceError(f"cycles: no {path} (make it with `python -m mech2spice.experiments.processor_check "
                              f"CHECKPOINT --out {path}`)")
    return {**read_json(path), "file": str(path)}


# --- entry point -------------------------------------------------------------------------------------------
def measure(out: Path, only=None, quick: bool = False, carrier_trace: str | None = None,
            envelope_trace: str | None = None, processor_check: str | None = None,
            latency_trace: str | None = None) -> dict:
    """Measure the sections in `only` (default all) and merge each into OUT/carrier.json as it finishes."""
    d = read_json(out / "carrier.json", {})
    d["machine"] = _measured_on()
    d["conditions"] = conditions()
    for name in sections("carrier", only, SECTIONS):
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
    return d
