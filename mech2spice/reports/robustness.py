"""reports/robustness.md: yield of whole designs under per-element spread (Monte-Carlo, experiments/montecarlo.py).

Yield against sigma with Wilson 95 % intervals for the NOR gate, a 3-gate chain and the 2-bit adder
(envelope engine, every input vector of each sample), which gates fail first, the per-gate failure rate
and the processor's yield extrapolated from it, Dask throughput from 1 to 2 workers in one run, and the
large adder sweep (results kept in CACHE as resumable JSON lines: a rerun only adds missing samples).
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from ..experiments import mc_run
from ..experiments import montecarlo as mc
from ._common import MACHINE, SANDBOX, pyplot, save_figure

CACHE = Path("build/robustness")
SIGMAS = (1e-5, 3e-5, 6e-5, 1e-4, 1.5e-4, 2e-4, 3e-4, 1e-3)
SAMPLES = {"gate": 200, "chain": 100, "adder": 48}
QUICK_SAMPLES = {"gate": 24, "chain": 16, "adder": 8}
SEED = 2024
BIG = ("adder", 1e-4, 10_000)          # the large sweep: design, sigma, samples
SCALING_SAMPLES = 96
VERILOG = {
    "gate": "module nor1(input a, input b, output y);\n  assign y = ~(a | b);\nendmodule\n",
    "chain": "module chain3(input a, input b, input c, input d, output y);\n  wire n1 = ~(a | b);\n"
             "  wire n2 = ~(n1 | c);\n  assign y = ~(n2 | d);\nendmodule\n",
}


def design_file(name: str) -> Path:
    """The Verilog of a studied design (the gate and chain are written to CACHE)."""
    if name == "adder":
        return mc.design_path("adder2.v").resolve()
    path = (CACHE / f"{name}.v").resolve()
    path.parent.mkdir(parents=True, exist_ok=True)
    if not path.exists() or path.read_text() != VERILOG[name]:
        path.write_text(VERILOG[name])
    return path


def job(name: str, sigma: float, backend: str = "envelope") -> dict:
    """The montecarlo job of one design at one sigma (every input vector, default parameters)."""
    from ..physics import network
    from ..synthesis.synth import synthesize
    path = design_file(name)
    nl = synthesize(path, max_fanout=network.MAX_FANOUT)
    return {"design": str(path), "params": "default", "vectors": mc.all_vectors(nl), "backend": backend,
            "spread": mc.spec_of(sigma).describe(), "seed": SEED, "periods": None, "union": 8}


def curve(name: str, samples: int, scheduler: str, log) -> list[dict]:
    """Yield at every sigma of SIGMAS (results resumed from CACHE)."""
    rows = []
    for s in SIGMAS:
        res = mc_run.run(job(name, s), samples, CACHE / f"{name}_{s:g}.jsonl", scheduler=scheduler)
        log(f"{name} sigma {s:g}: yield {res['yield']:.3f} ({res['samples']} samples, {res['wall_s']:.0f} s)")
        rows.append({"sigma": s, **{k: res[k] for k in ("samples", "failures", "yield", "yield_ci95",
                                                         "margin_quantiles", "failing_bits", "gate_failure_rate",
                                                         "gate_failure_rate_ci95", "gates", "failing_gates",
                                                         "samples_per_s")}})
    return rows


def scaling(samples: int = SCALING_SAMPLES) -> list[dict]:
    """The same adder sweep on a LocalCluster of 1 then 2 workers, in one run (fresh result files)."""
    out = []
    for w in (1, 2):
        path = CACHE / f"scaling_{w}.jsonl"
        path.unlink(missing_ok=True)
        res = mc_run.run(job("adder", BIG[1]), samples, path, scheduler="local", workers=w)
        out.append({"workers": w, "samples": samples, "wall_s": res["wall_s"], "samples_per_s": res["samples_per_s"],
                    "worker_peak_rss_mb": res["worker_peak_rss_mb"], "driver_peak_rss_mb": res["driver_peak_rss_mb"]})
    return out


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
    from ..physics import network
    from ..synthesis.synth import synthesize
    return len(synthesize(mc.design_path("cpu.v"), max_fanout=network.MAX_FANOUT).gates())


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
    data = {"curves": curves, "scaling": stored_scaling(), "big": big_sweep(big, log),
            "cpu_gates": cpu_gates(), "machine": MACHINE, "wall_s": None}
    data["wall_s"] = time.time() - t0
    (directory / "robustness.json").write_text(json.dumps(data, indent=1, default=float))
    figure(curves, directory / "robustness_yield.png")
    md = directory / "robustness.md"
    md.write_text(markdown(data))
    return md


def figure(curves: dict, path: Path) -> None:
    """Yield against sigma with Wilson intervals, one line per design."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4))
    for name, rows in curves.items():
        s = np.array([r["sigma"] for r in rows])
        y = np.array([r["yield"] for r in rows])
        lo, hi = np.array([r["yield_ci95"] for r in rows]).T
        ax.errorbar(s, y, yerr=[np.maximum(y - lo, 0), np.maximum(hi - y, 0)], marker="o", capsize=3, label=f"{name} ({rows[0]['gates']} gates)")
    ax.set_xscale("log")
    ax.set_xlabel("relative spread sigma (every element, independent)")
    ax.set_ylabel("yield (all outputs right, every input vector)")
    ax.set_ylim(-0.03, 1.03)
    ax.legend()
    ax.grid(alpha=0.3)
    save_figure(fig, path)


def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:.1f} %"


def markdown(d: dict) -> str:
    """The report text from the measured data."""
    out = ["# Robustness of whole designs: yield under per-element spread", "",
           f"Generated by `mech2spice report robustness` on {d['machine']} (the checked-in numbers: the shared "
           f"{SANDBOX}, other jobs running); seed {SEED}, envelope engine (default step), default parameters, "
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
    out += extrapolation(d)
    out += throughput(d)
    out += ["## What is not here yet", "",
            "* thermal noise (`--noise T`): not implemented;",
            "* sqrt(2809), the processor and whole sieves: `montecarlo` runs combinational designs only; the "
            "processor's yield above is extrapolated, not measured;",
            "* presets other than `default`.", ""]
    return "\n".join(out)


def extrapolation(d: dict) -> list[str]:
    """The processor's yield from the adder's per-gate failure rate x the processor's gate count."""
    n = d["cpu_gates"]
    out = ["## The processor, extrapolated", "",
           f"A root gate failure is a gate out of its expected band while every gate feeding it is in band. "
           f"With p the measured root failure rate per gate and sample, a design of N gates yields about "
           f"(1 - p)^N if gates fail independently. The processor has N = {n} NOR gates; the adder's rate gives:", "",
           "| sigma | p (adder) | 95 % CI | processor yield (1-p)^N | adder measured | adder (1-p)^17 |", "|---|---|---|---|---|---|"]
    for r in d["curves"]["adder"]:
        p, (lo, hi) = r["gate_failure_rate"], r["gate_failure_rate_ci95"]
        out.append(f"| {r['sigma']:g} | {p:.2e} | {lo:.1e} - {hi:.1e} | {_pct((1 - p) ** n)} "
                   f"({_pct((1 - hi) ** n)} - {_pct((1 - lo) ** n)}) | {_pct(r['yield'])} | {_pct((1 - p) ** r['gates'])} |")
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
