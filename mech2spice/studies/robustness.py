"""Yield of whole designs under per-element spread (Monte-Carlo, experiments/montecarlo.py), measured into
reports/robustness.json (mech2spice/reports/robustness.py renders robustness.md and its PNGs from it).

Yield against sigma with Wilson 95 % intervals for the NOR gate, a 3-gate chain and the 2-bit adder
(envelope engine, every input vector of each sample), which gates fail first, the per-gate failure rate
and the processor's gate count to extrapolate it, Dask throughput from 1 to 2 workers in one run, and the
large adder sweep (results kept in CACHE as resumable JSON lines: a rerun only adds missing samples);
the bit-error rate against thermal-noise temperature for the gate and the adder, and the three noise
implementations against linear response (experiments/noise_agreement.py).  One section, `all` (~30 min;
`--quick`: fewer samples).
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from ..experiments import mc_run
from ..experiments import montecarlo as mc
from ._common import conditions, load_average, write_json

SECTIONS = ("all",)

CACHE = Path("build/robustness")
SIGMAS = (1e-5, 3e-5, 6e-5, 1e-4, 1.5e-4, 2e-4, 3e-4, 1e-3)
SAMPLES = {"gate": 200, "chain": 100, "adder": 48}
QUICK_SAMPLES = {"gate": 24, "chain": 16, "adder": 8}
SEED = 2024
OTHER_PARAMS = ("robust",)      # parameter sets studied beside the default (the design search's best)
BIG = ("adder", 1e-4, 10_000)          # the large sweep: design, sigma, samples
SCALING_SAMPLES = 96
VERILOG = {
    "gate": "module nor1(input a, input b, output y);\n  assign y = ~(a | b);\nendmodule\n",
    "chain": "module chain3(input a, input b, input c, input d, output y);\n  wire n1 = ~(a | b);\n"
             "  wire n2 = ~(n1 | c);\n  assign y = ~(n2 | d);\nendmodule\n",
}


NOISE_TS = (1e-5, 3e-5, 6e-5, 1e-4, 1.5e-4, 2e-4, 3e-4, 5e-4, 1e-3)   # k_B T, model energy units
NOISE_SAMPLES = {"gate": 200, "adder": 48}
QUICK_NOISE_SAMPLES = {"gate": 8, "adder": 4}
RK4_NOISE = ("gate", NOISE_TS, 100)      # the gate's BER on RK4 too: design, temperatures, samples


def design_file(name: str) -> Path:
    """The Verilog of a studied design (the gate and chain are written to CACHE)."""
    if name == "adder":
        from .. import data
        return Path(data.verilog("adder2.v")).resolve()
    path = (CACHE / f"{name}.v").resolve()
    path.parent.mkdir(parents=True, exist_ok=True)
    if not path.exists() or path.read_text() != VERILOG[name]:
        path.write_text(VERILOG[name])
    return path


def job(name: str, sigma: float, backend: str = "envelope", params: str = "default") -> dict:
    """The montecarlo job of one design at one sigma (every input vector) with parameters `params`."""
    from ..physics import network
    from ..synthesis.synth import synthesize
    path = design_file(name)
    nl = synthesize(path, max_fanout=network.MAX_FANOUT)
    return {"design": str(path), "params": params, "vectors": mc.all_vectors(nl), "backend": backend,
            "spread": mc.spec_of(sigma).describe(), "seed": SEED, "periods": None, "union": 8}


def cache_file(name: str, sigma: float, j: dict) -> Path:
    """Where one curve point's samples live: by design and sigma, and for a block file by its values too."""
    if j["params"] == "default":
        return CACHE / f"{name}_{sigma:g}.jsonl"
    return CACHE / f"{name}_{j['params']}-{mc.job_key(j)[:8]}_{sigma:g}.jsonl"


def curve(name: str, samples: int, scheduler: str, log, params: str = "default") -> list[dict]:
    """Yield at every sigma of SIGMAS (results resumed from CACHE)."""
    rows = []
    for s in SIGMAS:
        j = job(name, s, params=params)
        res = mc_run.run(j, samples, cache_file(name, s, j), scheduler=scheduler)
        log(f"{name} ({params}) sigma {s:g}: yield {res['yield']:.3f} ({res['samples']} samples, {res['wall_s']:.0f} s)")
        rows.append({"sigma": s, **{k: res[k] for k in ("samples", "failures", "yield", "yield_ci95",
                                                         "margin_quantiles", "failing_bits", "gate_failure_rate",
                                                         "gate_failure_rate_ci95", "gates", "failing_gates",
                                                         "samples_per_s")}})
    return rows


CLOCKED_SIGMAS = {"sqrt": (3e-5, 6e-5, 1e-4, 2e-4), "processor": (3e-5, 6e-5, 8e-5, 1e-4), "sieve": (3e-5, 6e-5)}
CLOCKED_SAMPLES = {"sqrt": 12, "processor": 8, "sieve": 8}
QUICK_CLOCKED_SAMPLES = {"sqrt": 2, "processor": 1, "sieve": 1}
CPU_PROGRAM, CPU_CYCLES = "sieve.asm", 30
SIEVE_CYCLES = 457     # the sieve to its halt (the ISS halts after 457 cycles)


def clocked_job(name: str, sigma: float, params: str = "default") -> dict:
    """sqrt(2809) (its 7-cycle stimulus), the processor (the sieve, CPU_CYCLES cycles) or the whole sieve at one
    sigma, with parameters `params`."""
    import hashlib
    from .. import data, inputs
    from ..backends import engine_class
    base = {"params": params, "backend": "envelope", "spread": mc.spec_of(sigma).describe(), "seed": SEED,
            "union": 1}
    if name == "sqrt":
        return {"design": str(Path(data.verilog("sqrt.v")).resolve()),
                "steps": inputs.stimulus_steps(data.verilog("sqrt_2809.json"), {}, engine_class("envelope")), **base}
    prog = Path(data.program(CPU_PROGRAM)).resolve()
    return {"program": str(prog), "program_sha256": hashlib.sha256(prog.read_bytes()).hexdigest(),
            "cycles": SIEVE_CYCLES if name == "sieve" else CPU_CYCLES, **base}


def clocked_curve(name: str, samples: int, scheduler: str, log, params: str = "default") -> list[dict]:
    """Yield of sqrt or the processor at each of its sigmas (resumed from CACHE)."""
    rows = []
    for s in CLOCKED_SIGMAS[name]:
        j = clocked_job(name, s, params)
        res = mc_run.run(j, samples, cache_file(name, s, j), scheduler=scheduler)
        log(f"{name} ({params}) sigma {s:g}: yield {res['yield']:.3f} ({res['samples']} samples, {res['wall_s']:.0f} s)")
        rows.append({"sigma": s, "gates": None, **{k: res[k] for k in ("samples", "failures", "yield", "yield_ci95",
                                                                       "margin_quantiles", "failing_bits", "reasons",
                                                                       "samples_per_s")}})
    return rows


def noise_job(name: str, T: float, backend: str = "envelope") -> dict:
    """The montecarlo job of one design at noise temperature T, no spread."""
    return {**job(name, 0.0, backend), "noise": T}


def noise_curve(name: str, samples: int, scheduler: str, log, backend: str = "envelope",
                temps=NOISE_TS) -> list[dict]:
    """Yield and bit-error rate at every temperature (results resumed from CACHE)."""
    from ..experiments.tolerance import wilson
    from ..physics.noise import SCALE
    from ..physics.params import DEFAULT
    rows = []
    for T in temps:
        j = noise_job(name, T, backend)
        path = CACHE / f"noise_{name}_{backend}_{T:g}.jsonl"
        res = mc_run.run(j, samples, path, scheduler=scheduler)
        recs = [r for i, r in sorted(mc_run.read_results(path, j).items()) if i < samples]
        reads = len(recs) * len(j["vectors"]) * len(mc_run.design_for(j).outs)
        wrong = sum(sum(r.get("failing_bits", {}).values()) if r.get("margin") != -np.inf else
                    len(j["vectors"]) * len(mc_run.design_for(j).outs) for r in recs)
        log(f"{name} {backend} T {T:g}: {wrong} of {reads} bits wrong ({res['wall_s']:.0f} s)")
        rows.append({"T": T, "kelvin": SCALE.kelvin(T, DEFAULT), "reads": reads, "wrong_bits": wrong,
                     "ber": wrong / reads, "ber_ci95": list(wilson(wrong, reads)), "backend": backend,
                     **{k: res[k] for k in ("samples", "failures", "yield", "yield_ci95", "margin_quantiles",
                                            "failing_bits", "gate_failure_rate", "gates", "failing_gates",
                                            "samples_per_s")}})
    return rows


def noise_agreement() -> dict:
    """The three noise implementations against linear response (experiments/noise_agreement.py), cached."""
    path = CACHE / "noise_agreement.json"
    if path.exists():
        return json.loads(path.read_text())
    from ..experiments import noise_agreement as na
    T, out = 1e-4, {}
    for name, model, pred in (("linear oscillator (Q 20)", na.linear_oscillator(), None), ("NOR gate, '1' state", na.gate(), None)):
        t0 = time.time()
        lin = name.startswith("linear")
        row = {"T": T, "prediction": na.linear_prediction(model, T) if lin else na.gate_prediction(model, T),
               "envelope_prediction": 2 * T / model.k_total[0] if lin else None,
               "rk4": na.rk4_variance(model, T, batch=480 if not lin else 2000, periods=400, seed=11),
               "rk4_batch": 480 if not lin else 2000,
               "envelope": na.envelope_variance(model, T, batch=8000, periods=400, seed=11), "envelope_batch": 8000,
               "ngspice": na.ngspice_variance(model, T, periods=6000, settle=1500 if not lin else 100, seed=11),
               "ngspice_periods": 6000}
        row["wall_s"] = time.time() - t0
        out[name] = row
    CACHE.mkdir(parents=True, exist_ok=True)
    write_json(path, out)
    return out


def scaling(samples: int = SCALING_SAMPLES, union: int = 8) -> list[dict]:
    """The same adder sweep on a LocalCluster of 1 then 2 workers, in one run (fresh result files), with the
    load average before each (other sessions share the machine)."""
    out = []
    for w in (1, 2):
        path = CACHE / f"scaling_{w}.jsonl"
        path.unlink(missing_ok=True)
        load = load_average()
        res = mc_run.run({**job("adder", BIG[1]), "union": union}, samples, path, scheduler="local", workers=w)
        out.append({"workers": w, "samples": samples, "union": union, "wall_s": res["wall_s"],
                    "samples_per_s": res["samples_per_s"], "steady_samples_per_s": res.get("steady_samples_per_s"),
                    "load_before": load, "load_after": load_average(),
                    "worker_peak_rss_mb": res["worker_peak_rss_mb"], "driver_peak_rss_mb": res["driver_peak_rss_mb"]})
    return out


AMORTISED = {"samples": 256, "union": 16}    # 16 tasks of 16 samples: ~2 s tasks, the cluster's start amortised


def stored_amortised_scaling() -> list[dict] | None:
    """The 1-vs-2-worker measurement with larger tasks (scaling(**AMORTISED)), if it was measured."""
    path = CACHE / "scaling_amortised.json"
    return json.loads(path.read_text()) if path.exists() else None


def measure_amortised_scaling() -> list[dict]:
    """Measure and store scaling(**AMORTISED) (run by hand: it wants the machine as quiet as it gets)."""
    rows = scaling(**AMORTISED)
    write_json(CACHE / "scaling_amortised.json", rows)
    return rows


def big_sweep(run_it: bool, log) -> dict | None:
    """The large adder sweep's summary: what CACHE holds (run to completion with run_it)."""
    name, sigma, n = BIG
    path = CACHE / f"{name}_{n}.jsonl"
    if run_it:
        res = mc_run.run(job(name, sigma), n, path, scheduler="local", workers=2, log=log)
        return {k: v for k, v in res.items() if k != "margin_quantiles"}
    if not path.exists():
        return None
    j = job(name, sigma)
    recs = list(mc_run.read_results(path, j).values())
    timing = CACHE / "big_summary.json"           # the throughput and memory of the run that completed it
    kept = ("samples_per_s", "wall_s", "ran", "resumed", "workers", "worker_peak_rss_mb", "driver_peak_rss_mb")
    measured = {k: v for k, v in json.loads(timing.read_text()).items() if k in kept} if timing.exists() else {}
    return {**mc.summary(recs, len(mc_run.design_for(j).gates)), **measured, "complete": len(recs) >= n}


def cpu_gates() -> int:
    """NOR gates of the processor netlist (verilog/cpu.v)."""
    from .. import data
    from ..physics import network
    from ..synthesis.synth import synthesize
    return len(synthesize(data.verilog("cpu.v"), max_fanout=network.MAX_FANOUT).gates())


def stored_scaling() -> list[dict]:
    """The 1-vs-2-worker measurement, kept in CACHE (measured once: it needs an otherwise idle machine)."""
    path = CACHE / "scaling.json"
    if not path.exists():
        write_json(path, scaling())
    return json.loads(path.read_text())


def settings() -> dict:
    """What the report states about how the curves were run: seed, sample counts, the clocked engines' settings
    and the designed blocks' clock stretch (simulation.block_slowdown)."""
    from .. import simulation
    from ..cpu import physical
    from ..physics.params import load_params
    return {"seed": SEED, "other_params": list(OTHER_PARAMS), "cache": str(CACHE), "big": list(BIG),
            "scaling_samples": SCALING_SAMPLES, "clocked_samples": CLOCKED_SAMPLES, "cpu_cycles": CPU_CYCLES,
            "sieve_cycles": SIEVE_CYCLES, "clocked_settle_tol": simulation.CLOCKED_SETTLE_TOL,
            "processor": {"step": physical.PROCESSOR_STEP, "exponential": physical.EXPONENTIAL,
                          "settle": physical.SETTLE_TOL, "latency": physical.LATENCY},
            "slowdown": {q: simulation.block_slowdown(load_params(q)) for q in OTHER_PARAMS}}


def measure(section: str = "all", quick: bool = False, scheduler: str = "inline", big: bool = False,
            log=print) -> dict:
    """Run (or resume from CACHE) every sweep: the robustness.json the report renders."""
    t0 = time.time()
    counts = QUICK_SAMPLES if quick else SAMPLES
    curves = {name: curve(name, counts[name], scheduler, log) for name in ("gate", "chain", "adder")}
    for params in OTHER_PARAMS:      # the blocks `mech2spice design` produced, beside the default
        curves.update({f"{name}, {params}": curve(name, counts[name], scheduler, log, params)
                       for name in ("gate", "chain", "adder")})
    ccounts = QUICK_CLOCKED_SAMPLES if quick else CLOCKED_SAMPLES
    clocked = {name: clocked_curve(name, ccounts[name], scheduler, log) for name in CLOCKED_SIGMAS}
    for params in OTHER_PARAMS:      # sqrt, the processor's 30 cycles and whole sieves with the designed block
        clocked.update({f"{name}, {params}": clocked_curve(name, ccounts[name], scheduler, log, params)
                        for name in CLOCKED_SIGMAS})
    ncounts = QUICK_NOISE_SAMPLES if quick else NOISE_SAMPLES
    noise = {name: noise_curve(name, ncounts[name], scheduler, log) for name in ("gate", "adder")}
    name, temps, n = RK4_NOISE
    noise[f"{name} (rk4)"] = noise_curve(name, 4 if quick else n, scheduler, log, backend="rk4", temps=temps)
    c = conditions()
    data = {"curves": curves, "clocked": clocked, "noise": noise, "noise_agreement": noise_agreement(),
            "scaling": stored_scaling(), "scaling_amortised": stored_amortised_scaling(),
            "big": big_sweep(big, log), "cpu_gates": cpu_gates(), "machine": c["machine"], "wall_s": None,
            "settings": settings(), "conditions": c}
    data["wall_s"] = time.time() - t0
    return data
