"""reports/robustness.md: yield of whole designs under per-element spread (Monte-Carlo, experiments/montecarlo.py).

Yield against sigma with Wilson 95 % intervals for the NOR gate, a 3-gate chain and the 2-bit adder
(envelope engine, every input vector of each sample), which gates fail first, the per-gate failure rate
and the processor's yield extrapolated from it, Dask throughput from 1 to 2 workers in one run, and the
large adder sweep (results kept in CACHE as resumable JSON lines: a rerun only adds missing samples);
the bit-error rate against thermal-noise temperature for the gate and the adder, and the three noise
implementations against linear response (experiments/noise_agreement.py).
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from ..experiments import mc_run
from ..experiments import montecarlo as mc
from ..studies._common import load_average
from ._common import MACHINE, SANDBOX, pyplot, save_figure

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
    base = {"params": params, "backend": "envelope", "spread": mc.spec_of(sigma).describe(), "seed": SEED,
            "union": 1}
    if name == "sqrt":
        return {"design": str(Path(data.verilog("sqrt.v")).resolve()),
                "steps": inputs.stimulus_steps(data.verilog("sqrt_2809.json"), {}, "envelope"), **base}
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
    path.write_text(json.dumps(out, indent=1))
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
    (CACHE / "scaling_amortised.json").write_text(json.dumps(rows, indent=1))
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
        path.write_text(json.dumps(scaling(), indent=1))
    return json.loads(path.read_text())


def write(directory, quick: bool = False, scheduler: str = "inline", big: bool = False, log=print) -> Path:
    """Run (or resume) the sweeps and write robustness.md with its PNG."""
    directory = Path(directory)
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
    data = {"curves": curves, "clocked": clocked, "noise": noise, "noise_agreement": noise_agreement(),
            "scaling": stored_scaling(), "scaling_amortised": stored_amortised_scaling(),
            "big": big_sweep(big, log), "cpu_gates": cpu_gates(), "machine": MACHINE, "wall_s": None}
    data["wall_s"] = time.time() - t0
    (directory / "robustness.json").write_text(json.dumps(data, indent=1, default=float))
    figure({**curves, **clocked}, directory / "robustness_yield.png")
    noise_figure(noise, directory / "robustness_noise.png")
    md = directory / "robustness.md"
    md.write_text(markdown(data))
    return md


def figure(curves: dict, path: Path) -> None:
    """Yield against sigma with Wilson intervals, one line per design."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(9, 4.5))
    designs = list(dict.fromkeys(name.split(", ")[0] for name in curves))
    for name, rows in curves.items():
        s = np.array([r["sigma"] for r in rows])
        y = np.array([r["yield"] for r in rows])
        lo, hi = np.array([r["yield_ci95"] for r in rows]).T
        what = f"{rows[0]['gates']} gates" if rows[0]["gates"] else f"{rows[0]['samples']} samples/point"
        other = any(name.endswith(f", {q}") for q in OTHER_PARAMS)     # dashed, the default's colour
        ax.errorbar(s, y, yerr=[np.maximum(y - lo, 0), np.maximum(hi - y, 0)], marker="s" if other else "o",
                    linestyle="--" if other else "-", capsize=3, label=f"{name} ({what})",
                    color=f"C{designs.index(name.split(', ')[0]) % 10}", alpha=0.8)
    ax.set_xscale("log")
    ax.set_xlabel("relative spread sigma (every element, independent)")
    ax.set_ylabel("yield (all outputs right, every input vector / cycle)")
    ax.set_title(f"envelope engine, default and {', '.join(OTHER_PARAMS)} parameters, seed {SEED}; {MACHINE}",
                 fontsize=8)
    ax.set_ylim(-0.03, 1.03)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    save_figure(fig, path)


def noise_figure(noise: dict, path: Path) -> None:
    """Bit-error rate against temperature with Wilson intervals; no error seen: the interval's top (v)."""
    from ..physics.noise import SCALE
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4))
    for name, rows in noise.items():
        T = np.array([r["T"] for r in rows])
        ber = np.array([r["ber"] for r in rows])
        lo, hi = np.array([r["ber_ci95"] for r in rows]).T
        seen = ber > 0
        line = ax.errorbar(T[seen], ber[seen], yerr=[ber[seen] - lo[seen], hi[seen] - ber[seen]], marker="o",
                           capsize=3, label=f"{name} ({rows[0]['samples']} samples/point)")
        ax.plot(T[~seen], hi[~seen], "v", color=line[0].get_color(), alpha=0.6)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("noise temperature k_B T (model energy units)")
    ax.set_ylabel("bit-error rate (output bits read wrong)")
    top = ax.secondary_xaxis("top", functions=(lambda t: t * SCALE.kelvin(1.0, _default()), lambda k: k / SCALE.kelvin(1.0, _default())))
    top.set_xlabel(f"kelvin ({SCALE.describe()})")
    ax.set_title(f"spread 0, seed {SEED}; envelope (1-period steps) and rk4 (80 steps/period); {MACHINE}\n"
                 "v: no error seen, the 95 % upper bound", fontsize=7, pad=30)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    save_figure(fig, path)


def _default():
    from ..physics.params import DEFAULT
    return DEFAULT


def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:.1f} %"


def markdown(d: dict) -> str:
    """The report text from the measured data."""
    out = ["# Robustness of whole designs: yield under per-element spread", "",
           f"Generated by `mech2spice report robustness` on {d['machine']} (the checked-in numbers: the shared "
           f"{SANDBOX}, other jobs running); seed {SEED}, envelope engine (default step), default parameters "
           f"(and, where a heading says so, the {', '.join(OTHER_PARAMS)} block of `mech2spice design`: "
           "reports/design.md), "
           "every input vector of each sample, each run until its outputs settle or the settle budget ends.", "",
           "A sample multiplies every element (each DOF's local k, m, c; each coupling spring and dashpot; each "
           "gamma; each drive) by 1 + sigma z, z independent standard normals (`--spread SIGMA`; "
           "`experiments/montecarlo.py` also takes per-kind sigmas and a wafer-level shift). It passes when "
           "every output decodes to the logic oracle's value for every input vector.", "",
           "![yield](robustness_yield.png)", ""]
    for name, rows in d["curves"].items():
        out += [f"## {name} ({rows[0]['gates']} NOR gates)", "",
                "| sigma | samples | failures | yield | 95 % CI (Wilson) | margin 1 % / 50 % | root gate failure rate | gates failing first |",
                "|---|---|---|---|---|---|---|---|"]
        for r in rows:
            q = r["margin_quantiles"]
            first = ", ".join(f"{g} {n}" for g, n in list(r["failing_gates"].items())[:3]) or "-"
            out.append(f"| {r['sigma']:g} | {r['samples']} | {r['failures']} | {_pct(r['yield'])} | "
                       f"{_pct(r['yield_ci95'][0])} - {_pct(r['yield_ci95'][1])} | "
                       f"{q.get('1%', float('nan')):+.3f} / {q.get('50%', float('nan')):+.3f} | "
                       f"{r['gate_failure_rate']:.2e} | {first} |")
        out.append("")
    out += clocked_section(d)
    out += comparison(d)
    out += extrapolation(d)
    out += noise_section(d)
    out += throughput(d)
    out += ["## What is not here yet", "",
            "* thermal noise on clocked designs and the processor in the report: `simulate --noise` runs clocked "
            "designs and `cpu montecarlo --noise T` the processor, but the noisy envelope steps one period and "
            "freezes no gate (one sieve cycle with its power-up: about 90 s here), so no curve is measured;",
            f"* more than {CLOCKED_SAMPLES['sieve']} whole sieves per sigma.", ""]
    return "\n".join(out)


def noise_section(d: dict) -> list[str]:
    """BER against temperature, the onset, and the agreement of the three implementations."""
    from ..physics.noise import SCALE
    out = ["## Thermal noise: bit-error rate against temperature", "",
           "`mech2spice montecarlo DESIGN --spread 0 --noise T`: a Langevin force on every dashpot at k_B T = T "
           "(model energy units), each sample its own noise (seed from (seed, sample)); every input vector from "
           "rest, outputs read at the last period of the run (the settle rule rarely stops a noisy run early, so "
           "runs last the design's period budget). A bit error is an output read in the wrong band or in neither. "
           f"Kelvin for one physical scaling ({SCALE.describe()}; docs/robustness.md): 1 model unit = "
           f"{SCALE.kelvin(1.0, _default()):.3g} K.", "", "![bit-error rate](robustness_noise.png)", ""]
    for name, rows in d["noise"].items():
        n = rows[0]["samples"]
        out += [f"### {name}, {n} samples per temperature ({rows[0]['reads'] // max(n, 1)} bit reads per sample)", "",
                "| k_B T | kelvin | wrong bits / reads | BER | 95 % CI (Wilson) | samples failing | median margin | gates failing first |",
                "|---|---|---|---|---|---|---|---|"]
        for r in rows:
            first = ", ".join(f"{g} {c}" for g, c in list(r["failing_gates"].items())[:3]) or "-"
            lo, hi = r["ber_ci95"]
            lo = lo if lo > 1e-12 else 0.0           # Wilson's bound at zero errors, not rounding noise
            out.append(f"| {r['T']:g} | {r['kelvin']:.3g} | {r['wrong_bits']} / {r['reads']} | {r['ber']:.2e} | "
                       f"{lo:.1e} - {hi:.1e} | {r['failures']} | {r['margin_quantiles'].get('50%', float('nan')):+.3f} | {first} |")
        onset = next((r for r in rows if r["wrong_bits"]), None)
        clean = [r for r in rows if not r["wrong_bits"] and (onset is None or r["T"] < onset["T"])]
        if onset:
            below = f"; at {clean[-1]['T']:g} ({clean[-1]['kelvin']:.3g} K) no error in {clean[-1]['reads']} reads " \
                    f"(BER < {clean[-1]['ber_ci95'][1]:.1e}, 95 %)" if clean else ""
            out += ["", f"Bits start to flip at k_B T = {onset['T']:g} ({onset['kelvin']:.3g} K): BER "
                    f"{onset['ber']:.2e}{below}."]
        out.append("")
    out += ["'Gates failing first' counts gates whose channel was read out of its band at the end while every "
            "gate feeding them was in band; the adder's internal gates have slimmer margins than its outputs, so "
            "they leave their bands at temperatures where no output bit is wrong yet.", "",
            "RK4 against the envelope on the gate: the same rise of the BER with T within the intervals from "
            "1.5e-4 up; RK4 sees its first errors at a higher T because its nominal margin is larger (median "
            "+0.10 vs +0.09 band widths at the lowest T, the two models' difference on this gate; reports/envelope.md compares them).",
            ""]
    out += agreement_section(d["noise_agreement"])
    return out


def agreement_section(a: dict) -> list[str]:
    """The noise implementations against linear response (the numbers tests/test_noise.py checks)."""
    out = ["### The three noise implementations against linear response", "",
           "Steady-state E|A - <A>|^2 of the probe's per-period complex amplitude at k_B T = 1e-4 "
           "(`experiments/noise_agreement.py`, seed 11). Prediction: the linear oscillator's equipartition "
           "<u^2> = T/k (E|A|^2 = 2T/k, times the one-period-average factor for carrier engines, whose amplitude is "
           "a period's demodulation; the envelope's amplitude is its state), the gate's the Lyapunov covariance "
           "of the envelope equations linearised at its '1' state. RK4 and the envelope: a batch of copies from "
           "the deterministic steady state, variance across the batch after 400 periods; ngspice: one transient "
           "from rest, variance over 6000 periods after settling.", "",
           "| scene | prediction | RK4 (batch) | envelope (batch) | ngspice (periods) |", "|---|---|---|---|---|"]
    for name, r in a.items():
        env_pred = r["envelope_prediction"] or r["prediction"]
        out.append(f"| {name} | {r['prediction']:.3e} | {r['rk4']:.3e} ({r['rk4'] / r['prediction'] - 1:+.1%}, "
                   f"{r['rk4_batch']}) | {r['envelope']:.3e} ({r['envelope'] / env_pred - 1:+.1%}, "
                   f"{r['envelope_batch']}) | {r['ngspice']:.3e} ({r['ngspice'] / r['prediction'] - 1:+.1%}, "
                   f"{r['ngspice_periods']}) |")
    out += ["", "Standard errors: about 1/sqrt(batch) across a batch; ngspice's time average has ~6000 / (2 x "
            "correlation time) independent samples (correlation time ~6 periods for the oscillator, ~60 for the "
            "gate channel: se ~4 % and ~15 %).", ""]
    return out


def clocked_section(d: dict) -> list[str]:
    """sqrt(2809) and the processor: yield with Wilson intervals (small sample counts, stated)."""
    from .. import simulation
    from ..cpu import physical as cpu_physical
    out = ["## Clocked designs: sqrt(2809) and the processor", "",
           "`mech2spice montecarlo verilog/sqrt.v --stimulus verilog/sqrt_2809.json --spread S` (7 clock cycles, every "
           "cycle's outputs against the clocked logic oracle) and `mech2spice cpu montecarlo programs/sieve.asm "
           f"--cycles {CPU_CYCLES} --spread S` (every cycle's pc, phase, read address and data, write enable, and write "
           "address and data where it writes, against the instruction-set simulator; the memory's data forces and the clock/reset drives stay nominal, every "
           "element of the oscillator network is spread). Envelope engine at the defaults (sqrt: the envelope "
           f"engine's default step (4 periods on sqrt), settle {simulation.CLOCKED_SETTLE_TOL} u_R; the processor: cpu/physical.py's "
           f"{cpu_physical.PROCESSOR_STEP:g}-period steps, exponential insulator step {cpu_physical.EXPONENTIAL}, "
           f"settle {cpu_physical.SETTLE_TOL} u_R, latency {cpu_physical.LATENCY} u_R). **Small samples**: a sample "
           "builds and powers up its own 6486-oscillator processor (tens of seconds here), so the intervals are "
           "wide; no per-gate rate is measured on clocked runs (only outputs are kept). *sieve*: the same as "
           f"*processor*, to the program's halt ({SIEVE_CYCLES} cycles, every one against the ISS). "
           f"Headings with {', '.join(OTHER_PARAMS)}: the designed block, on a clock schedule stretched by its "
           "slower switching (`simulation.block_slowdown`: "
           + ", ".join(f"{q} {_slowdown(q):.2f}x" for q in OTHER_PARAMS)
           + "; on the default schedule it failed by timing, docs/robustness.md).", ""]
    for name, rows in d["clocked"].items():
        out += [f"### {name}", "", "| sigma | samples | failures | yield | 95 % CI (Wilson) | failing (samples) |",
                "|---|---|---|---|---|---|"]
        for r in rows:
            why = ", ".join(f"{b} {n}" for b, n in list(r["failing_bits"].items())[:4])
            why = "; ".join(x for x in (why, ", ".join(f"{k[:80]} ({n})" for k, n in r["reasons"].items())) if x) or "-"
            out.append(f"| {r['sigma']:g} | {r['samples']} | {r['failures']} | {_pct(r['yield'])} | "
                       f"{_pct(r['yield_ci95'][0])} - {_pct(r['yield_ci95'][1])} | {why} |")
        out.append("")
    return out


def comparison(d: dict) -> list[str]:
    """Per design: the largest sigma measured at which every sample passed, default block against each
    designed block (the same sigmas and samples for both)."""
    out = ["## Default block against the designed block", "",
           "Largest sigma of the sweep at which every sample passed (and the yield at the next sigma):", "",
           "| design | " + " | ".join(["default", *OTHER_PARAMS]) + " |", "|---|" + "---|" * (1 + len(OTHER_PARAMS))]
    rows = {**d["curves"], **d["clocked"]}

    def cell(name: str) -> str:
        pts = rows.get(name)
        if not pts:
            return "-"
        clean = [r["sigma"] for r in pts if r["failures"] == 0]
        top = max(clean, default=None)
        nxt = next((r for r in pts if top is not None and r["sigma"] > top), None)
        return (f"{top:g}" if top is not None else "none") + (f" ({_pct(nxt['yield'])} at {nxt['sigma']:g})" if nxt else "")
    for name in ("gate", "chain", "adder", *CLOCKED_SIGMAS):
        out.append(f"| {name} | " + " | ".join(cell(n) for n in [name, *[f"{name}, {q}" for q in OTHER_PARAMS]]) + " |")
    return out + [""]


def _slowdown(params: str) -> float:
    from .. import simulation
    from ..physics.params import load_params
    return simulation.block_slowdown(load_params(params))


def extrapolation(d: dict) -> list[str]:
    """The processor's yield from the adder's per-gate failure rate x the processor's gate count."""
    n = d["cpu_gates"]
    out = ["## The processor, extrapolated", "",
           f"A root gate failure is a gate out of its expected band while every gate feeding it is in band. "
           f"With p the measured root failure rate per gate and sample, a design of N gates yields about "
           f"(1 - p)^N if gates fail independently. The processor has N = {n} NOR gates; the adder's rate gives:", "",
           "| sigma | p (adder) | 95 % CI | processor yield (1-p)^N | processor measured (30 cycles) | adder measured | adder (1-p)^17 |",
           "|---|---|---|---|---|---|---|"]
    cpu = {r["sigma"]: r for r in d.get("clocked", {}).get("processor", [])}
    for r in d["curves"]["adder"]:
        p, (lo, hi) = r["gate_failure_rate"], r["gate_failure_rate_ci95"]
        m = cpu.get(r["sigma"])
        meas = f"{m['samples'] - m['failures']} of {m['samples']} ({_pct(m['yield_ci95'][0])} - {_pct(m['yield_ci95'][1])})" if m else "-"
        out.append(f"| {r['sigma']:g} | {p:.2e} | {lo:.1e} - {hi:.1e} | {_pct((1 - p) ** n)} "
                   f"({_pct((1 - hi) ** n)} - {_pct((1 - lo) ** n)}) | {meas} | {_pct(r['yield'])} | {_pct((1 - p) ** r['gates'])} |")
    out += ["", "A gate out of band is not always a wrong output (the next gate restores levels), so (1-p)^N "
            "is a pessimistic estimate where the adder's measured yield exceeds (1-p)^17.", ""]
    return out


def throughput(d: dict) -> list[str]:
    """Dask scaling and the large sweep."""
    out = ["## Throughput on Dask", ""]
    if d["scaling"]:
        out += [f"The adder at sigma {BIG[1]:g} ({SCALING_SAMPLES} samples, 8 per task as one union model, "
                "LocalCluster of single-threaded worker processes; wall time includes starting the cluster):", "",
                "| workers | wall s | samples/s | worker peak RSS MB | driver peak RSS MB |", "|---|---|---|---|---|"]
        out += [f"| {s['workers']} | {s['wall_s']:.1f} | {s['samples_per_s']:.2f} | {s['worker_peak_rss_mb']:.0f} | "
                f"{s['driver_peak_rss_mb']:.0f} |" for s in d["scaling"]]
        a, b = d["scaling"]
        out += ["", f"Speed-up 1 -> 2 workers: {b['samples_per_s'] / a['samples_per_s']:.2f}x, measured while other "
                "sessions loaded the shared 2-core machine (load average ~8): the second core was not free, and "
                "each worker's start (synthesis, compiled-kernel load, ~5 s) weighs on 96 samples.", ""]
    am = d.get("scaling_amortised")
    if am:
        a, b = am
        out += [f"Again with tasks that amortise the cluster's start: {a['samples']} adder samples at sigma {BIG[1]:g}, "
                f"{a['union']} per task, 1 then 2 workers in one run; load average (1 min) before each: "
                f"{a['load_before'][0]:.1f} and {b['load_before'][0]:.1f} on 2 cores (other sessions' jobs).", "",
                "| workers | wall s | samples/s (incl. start) | samples/s after the first task | worker peak RSS MB |",
                "|---|---|---|---|---|"]
        out += [f"| {s['workers']} | {s['wall_s']:.1f} | {s['samples_per_s']:.2f} | "
                f"{s['steady_samples_per_s'] or float('nan'):.2f} | {s['worker_peak_rss_mb']:.0f} |" for s in am]
        steady = (b["steady_samples_per_s"] or float("nan")) / (a["steady_samples_per_s"] or float("nan"))
        out += ["", f"Speed-up 1 -> 2 workers: {b['samples_per_s'] / a['samples_per_s']:.2f}x overall, "
                f"{steady:.2f}x after every worker's first task. The difference is the cluster's start (worker "
                "processes, each synthesising the adder and loading the compiled kernels, slow under this load); "
                "after it a second worker process added its share of a machine whose cores the OS divides among "
                "every runnable process of every session.", ""]
    big = d["big"]
    if big:
        lo, hi = big["yield_ci95"]
        out += [f"Large sweep: adder, sigma {BIG[1]:g}, {big['samples']} of {BIG[2]} samples in "
                f"`{CACHE}/adder_{BIG[2]}.jsonl`: {big['failures']} failures, yield {_pct(big['yield'])} "
                f"({_pct(lo)} - {_pct(hi)}), root gate failure rate {big['gate_failure_rate']:.2e}."]
        if "samples_per_s" in big:
            out += [f"The run that completed it: {big['ran']} samples in {big['wall_s']:.0f} s, "
                    f"{big['samples_per_s']:.2f} samples/s on {big['workers']} workers (LocalCluster, machine "
                    f"shared with other jobs), worker peak RSS {big['worker_peak_rss_mb']:.0f} MB, driver "
                    f"{big['driver_peak_rss_mb']:.0f} MB: memory is bounded by the tasks in flight, not by the "
                    "sample count."]
        out.append("")
    return out
