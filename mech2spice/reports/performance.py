"""reports/performance.md and its charts, rendered from reports/performance.json (mech2spice/studies/performance.py
measures it; its module docstring lists the sections).  The sieve section is no measurement: it is estimated here
from the measured per-period costs and the clock schedule the study records (`clock`).

usage: mech2spice report performance [--only SECTION ...] [--out reports] [--quick] [--sqrt-rk4-full] [--render]
"""
from __future__ import annotations

import math
from pathlib import Path

from ._common import SANDBOX, log, out_dir, pyplot, read_json, save_figure, write_json

MACHINE = f"{SANDBOX}, shared"
BACKENDS = ("rk4", "rk4_numpy", "envelope", "ngspice")     # studies/performance.py's PLAN, in its order
LABEL = {"rk4": "RK4, numba kernel (80 steps/T)", "rk4_numpy": "RK4, numpy (80 steps/T)",
         "envelope": "envelope (step 2 T)", "envelope_sparse": "envelope, sparse slow block (prototype, step 2 T)",
         "envelope_dense": "envelope before c97a5be (dense slow block, step 2 T)",
         "ngspice": "ngspice (default SpiceOptions: trap+prewarp, T/40)"}
SIEVE = {"gates": 2000, "oscillators": 12000, "cycles": 700, "logic_depth": 40}   # the processor


SIEVE_CPU_CYCLES = 457     # programs/sieve.asm on verilog/cpu.v: cycles to halt (ISS and logic level, reports/cpu.md)


def _clocked_periods(clock: dict, depth: int, cycles: int) -> dict:
    """simulation.clock_timing's pulse and pause for a logic depth, and simulation.clocked_schedule's total, from
    its constants as the study recorded them (`clock`)."""
    pulse = int(1.6 * clock["latch_min_pulse"])
    pause = clock["latch_output_delay"] - pulse + clock["gate_delay_max"] * (depth + 1) + clock["settle_margin"]
    return {"pulse": pulse, "pause": pause, "periods_per_cycle": pulse + pause, "cycles": cycles,
            "logic_depth": depth, "total_periods": pause + cycles * (pulse + pause)}


def sieve_estimate(res: dict, directory: Path) -> dict:
    """Wall time of the sieve at every fidelity: (a) the issue's processor (12000 oscillators, 700 cycles,
    depth 40) from the 12000-oscillator chain measurements; (b) this repository's verilog/cpu.v (457 cycles,
    its own depth) from measurements on the cpu.v model itself, and the whole physical run from
    DIRECTORY/cpu_physical.json where there is one."""
    out = {}
    sc = res.get("scaling", {})
    a = _clocked_periods(res["clock"], SIEVE["logic_depth"], SIEVE["cycles"])
    est = {}
    for r in sc.get("rows", []):
        if r.get("oscillators") == SIEVE["oscillators"] and "s_per_period" in r:
            est[r["backend"] + ("_step2" if r["backend"].startswith("envelope") else "")] = {
                "s_per_period": r["s_per_period"], "how": f"measured, 12000-oscillator chain, {r['periods']} periods"}
    r = sc.get("envelope_step1")
    if r and "s_per_period" in r:
        est["envelope"] = {"s_per_period": r["s_per_period"], "how": f"measured, 12000-oscillator chain, {r['periods']} periods, step 1 T"}
    old = res.get("before_sparse_fix", {}).get("envelope_step1_12000")
    if old and "s_per_period" in old:
        est["envelope_dense"] = {"s_per_period": old["s_per_period"], "how": "measured before commit c97a5be "
                                 f"(dense slow block), 12000-oscillator chain, {old['periods']} periods, step 1 T"}
    if "ngspice" not in est and sc.get("stopped", {}).get("ngspice"):
        pts = [r for r in sc["rows"] if r.get("backend") == "ngspice" and "s_per_period" in r]
        k = sc["fits"].get("ngspice", {}).get("last_exponent", 1.5)
        est["ngspice"] = {"s_per_period": pts[-1]["s_per_period"] * (SIEVE["oscillators"] / pts[-1]["oscillators"]) ** k,
                          "how": f"extrapolated from {pts[-1]['oscillators']} oscillators with exponent {k:.2f}"}
    lg = res.get("sqrt", {}).get("logic")
    if lg and "s_per_cycle" in lg:
        est["logic"] = {"s_per_cycle": lg["s_per_cycle"] * SIEVE["gates"] / lg["gates"],
                        "how": f"sqrt.v per cycle ({lg['gates']} gates), scaled by gate count"}
    out["issue_processor"] = {**a, "oscillators": SIEVE["oscillators"], "estimates": _totals(est, a)}
    cpu = res.get("cpu")
    if cpu:
        b = _clocked_periods(res["clock"], cpu["logic_depth"], SIEVE_CPU_CYCLES)
        est = {}
        for r in cpu["rows"]:
            if "s_per_period" in r:
                est[r["backend"]] = {"s_per_period": r["s_per_period"],
                                     "how": f"measured on the cpu.v model, {r['periods']} periods"
                                            + (f", step {r['step_periods']:g} T" if "step_periods" in r else "")}
        lg = cpu.get("logic")
        if lg and "s_per_cycle" in lg:
            est["logic"] = {"s_per_cycle": lg["s_per_cycle"], "how": "measured on cpu.v, run_clocked_logic"}
        old = res.get("before_sparse_fix", {}).get("cpu_v_envelope_step1_s_per_period")
        if old:
            est["envelope_dense"] = {"s_per_period": old, "how": "measured on the cpu.v model before commit c97a5be "
                                     "(dense slow block), 300 periods, step 1 T"}
        out["cpu_v"] = {**b, "oscillators": cpu["oscillators"], "estimates": _totals(est, b)}
        r = read_json(Path(directory) / "cpu_physical.json", {})     # the whole run, measured (cpu_physical)
        if r.get("halted") and not r.get("resumed"):
            out["cpu_v"]["estimates"]["envelope_settle"] = {
                "total_s": r["wall_s"], "s_per_cycle": r["s_per_cycle"],
                "how": f"**measured**: the whole run to the halt ({r['cycles']} cycles, `{r['command']}`, "
                       f"reports/cpu_physical.md); {r['simulated_periods']:,} of {r['periods']:,} periods "
                       f"integrated"}
    return out


def _totals(est: dict, sched: dict) -> dict:
    for e in est.values():
        if "total_s" in e:          # measured whole
            continue
        e["total_s"] = e["s_per_period"] * sched["total_periods"] if "s_per_period" in e else \
            e["s_per_cycle"] * sched["cycles"]
    return est


def charts(res: dict, out: Path) -> list[str]:
    """Draw performance_scaling.png and performance_designs.png from the results; returns the names drawn."""
    plt = pyplot()
    made = []
    rows = res.get("scaling", {}).get("rows", [])
    if rows:
        fig, axs = plt.subplots(1, 3, figsize=(16, 4.5))
        for b in BACKENDS:
            pts = [r for r in rows if r.get("backend") == b and "s_per_period" in r]
            if not pts:
                continue
            n = [r["oscillators"] for r in pts]
            axs[0].loglog(n, [r["s_per_period"] for r in pts], "o-", label=LABEL[b])
            axs[1].loglog(n, [r["osc_periods_per_s"] for r in pts], "o-", label=LABEL[b])
            axs[2].loglog(n, [r["rss_peak_mb"] - r["rss_baseline_mb"] + 1e-1 for r in pts], "o-", label=LABEL[b] + " (python)")
            if b == "ngspice":
                axs[2].loglog(n, [r["ngspice_maxrss_mb"] for r in pts], "s--", label="ngspice process peak")
        old = [r for r in res.get("before_sparse_fix", {}).get("scaling_rows", []) if r["backend"] == "envelope"]
        if old:
            axs[0].loglog([r["oscillators"] for r in old], [r["s_per_period"] for r in old], "x--", color="grey",
                          label=LABEL["envelope_dense"])
            axs[1].loglog([r["oscillators"] for r in old], [r["osc_periods_per_s"] for r in old], "x--", color="grey",
                          label=LABEL["envelope_dense"])
        axs[0].set(xlabel="oscillators", ylabel="wall time per drive period [s]", title="cost per simulated period")
        axs[1].set(xlabel="oscillators", ylabel="oscillator-periods per second", title="throughput")
        axs[2].set(xlabel="oscillators", ylabel="MB", title="peak RSS above the import baseline")
        for ax in axs:
            ax.grid(True, which="both", alpha=0.3)
        axs[0].legend(fontsize=7)
        axs[2].legend(fontsize=7)
        fig.suptitle(f"chains of NOR gates, {MACHINE}")
        save_figure(fig, out / "performance_scaling.png", dpi=90)
        made.append("performance_scaling.png")
    ad = res.get("adder", {}).get("rows", {})
    sv = {f"{k} ({w})": v for w, blk in res.get("sieve", {}).items() for k, v in blk["estimates"].items()}
    if ad or sv:
        fig, axs = plt.subplots(1, 2, figsize=(13, 4.2))
        names = [k for k, v in ad.items() if "wall_s" in v]
        axs[0].barh(names, [ad[k]["wall_s"] for k in names])
        axs[0].set_xscale("log")
        axs[0].set(xlabel="wall time [s]", title="2-bit adder, 16 inputs, run_physical")
        for i, k in enumerate(names):
            axs[0].annotate(f"{ad[k]['wall_s']:.1f} s", (ad[k]["wall_s"], i), fontsize=8)
        names = [k for k in sv]
        axs[1].barh(names, [sv[k]["total_s"] / 86400 for k in names])
        axs[1].set_xscale("log")
        axs[1].set(xlabel="estimated wall time [days]", title="sieve on an 8-bit processor (estimate)")
        for i, k in enumerate(names):
            axs[1].annotate(_dur(sv[k]["total_s"]), (sv[k]["total_s"] / 86400, i), fontsize=8)
        save_figure(fig, out / "performance_designs.png", dpi=90)
        made.append("performance_designs.png")
    return made


def _dur(s: float) -> str:
    if not math.isfinite(s):
        return "-"
    if s < 120:
        return f"{s:.1f} s"
    if s < 7200:
        return f"{s / 60:.1f} min"
    if s < 2 * 86400:
        return f"{s / 3600:.1f} h"
    if s < 2 * 365 * 86400:
        return f"{s / 86400:.1f} days"
    return f"{s / 86400 / 365:.1f} years"


def write(directory="reports", only=None, quick: bool = False, sqrt_rk4_full: bool = False,
          render: bool = False) -> Path:
    """Measure the sections in `only` (default: all but sqrt_rk4; `quick`: fewer points; `render`: none) into
    performance.json (studies/performance.py), then estimate the sieve and rebuild performance.md and its charts
    from the whole JSON."""
    out = out_dir(directory)
    if not render:
        from ..studies import performance as study      # measuring loads the engines; rendering does not
        study.measure(out, only, quick, sqrt_rk4_full)
    jf = out / "performance.json"
    res = read_json(jf, {})
    res["sieve"] = sieve_estimate(res, out)
    write_json(jf, res, default=float)
    made = charts(res, out)
    write_markdown(res, out, made)
    log(f"wrote {jf}, {out / 'performance.md'}")
    return out / "performance.md"


def write_markdown(res: dict, out: Path, charts_made: list[str]) -> None:
    """reports/performance.md from the JSON (filled in below)."""
    from . import carrier                   # the carrier kernel's roofline (carrier.json), appended
    text = markdown(res, charts_made).rstrip("\n")
    roof = carrier.roofline_block(out)
    (out / "performance.md").write_text(text + ("\n\n" + roof if roof else "\n"))


def _f(x, fmt="{:.3g}"):
    return "-" if x is None or (isinstance(x, float) and not math.isfinite(x)) else fmt.format(x)


def markdown(res: dict, charts_made: list[str]) -> str:
    """The text of performance.md from the results and the charts drawn."""
    L = ["# Performance: what every fidelity level costs", "",
         f"Generated by `mech2spice report performance` on the **{res['machine']}** (Python "
         f"{res['platform']['python']}, {res['platform']['cpus']} CPUs, numba kernel single-threaded, ngspice 39 "
         "without KLU). Section wall times: " + ", ".join(f"{k} {v / 60:.1f} min" for k, v in
                                                        res.get("section_wall_s", {}).items()) + ".",
         "Every measurement runs in a fresh worker process (peak memory = that process's `ru_maxrss`; ngspice's "
         "own process is reported separately from `RUSAGE_CHILDREN`). The machine is shared with other jobs, so "
         "repeated timings scatter by up to ~2x; ratios below are taken within one run.", ""]
    L += SUMMARY_HOOK(res)
    sc = res.get("scaling")
    if sc:
        L += ["## Scaling with circuit size", "",
              "Design: `nor.chain(p, gates)` (every gate's input 1 driven by the previous gate's channel through "
              "a spring and a dashpot, input 2 a constant '0'; 6 oscillators per gate), batch 1, from rest, "
              "constant drives. Periods measured per point are listed: fewer at large sizes so that each point "
              "takes seconds, never minutes. RK4 is timed after a warm-up period on the same model (numba kernel "
              "loaded from its cache); the envelope likewise after a warm-up call that builds and caches its "
              "`Envelope`, compiled kernel and step bound (that setup is `setup_s` in the JSON); ngspice's time is `runner.run` end to end (emit netlist, run, read raw "
              "file).", "",
              "| backend | oscillators | periods | wall per period | periods/s | oscillator-periods/s | "
              "oscillator-steps/s | peak RSS, python [MB] (above baseline) | ngspice process peak [MB] |",
              "|---|---|---|---|---|---|---|---|---|"]
        for r in sc["rows"]:
            if "s_per_period" not in r:
                L.append(f"| {LABEL[r['backend']]} | {r['oscillators']} | - | FAILED: {r.get('failed')} | | | | | |")
                continue
            L.append(f"| {LABEL[r['backend']]} | {r['oscillators']} | {r['periods']} | {_dur_ms(r['s_per_period'])} | "
                     f"{r['periods_per_s']:.3g} | {r['osc_periods_per_s']:.3g} | {r['osc_steps_per_s']:.3g} | "
                     f"{r['rss_peak_mb']:.0f} ({r['rss_peak_mb'] - r['rss_baseline_mb']:+.0f}) | "
                     f"{_f(r.get('ngspice_maxrss_mb'), '{:.0f}')} |")
        b = sc.get("baseline", {})
        L += ["", f"Baseline: a worker that imports numpy/scipy/mech2spice and builds a 1-gate model peaks at "
                  f"{_f(b.get('rss_peak_mb'), '{:.0f}')} MB; RK4 workers also load numba (its baseline is in the "
                  "'above baseline' column's reference). Oscillator-steps: RK4 80 per period, ngspice 40 per "
                  "period (T/40 pinned), envelope 4 right-hand-side evaluations per 2-period step.", ""]
        for k, lab in (("envelope_step1", "envelope, step 1 T"),):
            r = sc.get(k, {})
            if "s_per_period" in r:
                L.append(f"- {lab} (the clocked-design default) at {r['oscillators']} oscillators: "
                         f"{_dur_ms(r['s_per_period'])} per period ({r['periods']} periods).")
        L += ["", "Fitted exponents (wall time per period ~ oscillators^k, least squares over >= 300 oscillators; "
                  "'last' = between the two largest sizes):", ""]
        for b2, f in sc.get("fits", {}).items():
            if "exponent" in f:
                L.append(f"- {LABEL[b2]}: k = {f['exponent']:.2f} over {f['range'][0]}-{f['range'][1]} oscillators "
                         f"(last pair {f.get('last_exponent', float('nan')):.2f})")
        for b2, st in sc.get("stopped", {}).items():
            L.append(f"- {LABEL[b2]} not run at {st['at_oscillators']} oscillators and above: predicted "
                     f"{st['predicted_s_per_period']:.1f} s per period.")
        L.append("")
    L += DETAIL_HOOK(res)
    for c in charts_made:
        L.append(f"![{c}]({c})")
    return "\n".join(L) + "\n"


def _dur_ms(s: float) -> str:
    return f"{s * 1e3:.3g} ms" if s < 1 else f"{s:.3g} s"


ADDER_LABEL = {"rk4": "RK4, numba kernel (80 steps/T)", "rk4_numpy": "RK4, numpy (80 steps/T)",
               "envelope": "envelope (default step: `backends/envelope.default_step`, 4 T here)",
               "envelope_again": "envelope, run again after the others",
               "envelope_step4": "what-if: envelope with ENVELOPE_STEP = 4",
               "envelope_step4_cached": "what-if: ENVELOPE_STEP = 4 and one Envelope per run (not per chunk)",
               "ngspice": "ngspice (defaults), 16 processes, 2 at a time"}


def adder_md(res: dict) -> list[str]:
    """The adder section of performance.md as markdown lines ([] if not measured)."""
    ad = res.get("adder", {}).get("rows", {})
    if not ad:
        return []
    L = ["## The 2-bit adder: all 16 inputs, `simulation.run_physical`", "",
         "`verilog/adder2.v` (17 gates, 102 oscillators), the 16 input pairs as one batch from rest, each backend "
         "in its own worker, one after the other in this run; the settle rule is `run_physical`'s (chunks of 100 "
         "periods until every output moved < 0.002 u_R over 100 periods and sits in a band; ngspice has no cheap "
         "restart and always runs the whole 2900-period budget). RK4 workers load the numba kernel before the "
         "clock starts. Wall time = the `run_physical` call (model build and decoding included).", "",
         "| backend | wall [s] | periods simulated | correct | worst margin | peak RSS [MB] |", "|---|---|---|---|---|---|"]
    for k, r in ad.items():
        if "wall_s" not in r:
            L.append(f"| {ADDER_LABEL.get(k, k)} | FAILED: {r.get('failed')} | | | | |")
            continue
        L.append(f"| {ADDER_LABEL.get(k, k)} | {r['wall_s']:.2f} | {r['periods']} | {r['correct']}/16 | "
                 f"{r['min_margin']:+.3f} | {r['rss_peak_mb']:.0f} |")
    env = [ad[k]["wall_s"] for k in ("envelope", "envelope_again") if "wall_s" in ad.get(k, {})]
    if env and "wall_s" in ad.get("rk4", {}):
        e = sum(env) / len(env)
        L += ["", "Amplitude differences to RK4 (largest over the 48 decoded output amplitudes): " + ", ".join(
            f"{ADDER_LABEL.get(k, k)} {max(abs(x[n] - y[n]) for x, y in zip(ad['rk4']['amplitudes'], r['amplitudes']) for n in x):.4f} u_R"
            for k, r in ad.items() if k != "rk4" and "amplitudes" in r and "amplitudes" in ad.get("rk4", {})) + "."]
        L += ["", f"**Envelope vs RK4 on the adder: {ad['rk4']['wall_s'] / e:.1f}x faster** "
                  f"(RK4 {ad['rk4']['wall_s']:.1f} s / envelope {e:.2f} s, mean of the envelope's two runs "
                  f"{', '.join(f'{x:.2f}' for x in env)} s; the issue asks >= 20x)"
              + (f"; vs RK4 numpy {ad['rk4_numpy']['wall_s'] / e:.0f}x" if "wall_s" in ad.get("rk4_numpy", {}) else "")
              + (f"; vs ngspice {ad['ngspice']['wall_s'] / e:.0f}x" if "wall_s" in ad.get("ngspice", {}) else "") + "."]
        if all("amplitudes" in ad.get(k, {}) for k in ("rk4", "envelope")):
            d = max(abs(x[n] - y[n]) for x, y in zip(ad["rk4"]["amplitudes"], ad["envelope"]["amplitudes"]) for n in x)
            L.append(f"Largest difference of the 48 decoded output amplitudes, envelope vs RK4: {d:.4f} u_R "
                     f"(they stop at {ad['envelope']['periods']} and {ad['rk4']['periods']} periods).")
    L.append("")
    return L


def sqrt_md(res: dict) -> list[str]:
    """The sqrt section of performance.md as markdown lines ([] if not measured)."""
    sq = res.get("sqrt")
    if not sq:
        return []
    e, pr, lg = sq.get("envelope", {}), sq.get("rk4_probe", {}), sq.get("logic", {})
    L = ["## Square root of 2809 (`verilog/sqrt.v`, 7 clock cycles)", ""]
    if "wall_s" in e:
        L += [f"`simulation.run_clocked_physical` with `simulation.clock_timing(nl)` (pulse {e['timing']['pulse']}, "
              f"pause {e['timing']['pause']} periods, logic depth {e['timing']['logic_depth']}): "
              f"{e['periods']} periods.", "",
              "| backend | wall | per period | result | how |", "|---|---|---|---|---|",
              f"| envelope (step 1 T, the clocked default) | {_dur(e['wall_s'])} | {_dur_ms(e['s_per_period'])} | "
              f"root trace {e['root_trace']}, valid {e['valid']} | measured, whole run |"]
    if "s_per_period" in pr:
        L.append(f"| RK4, numba kernel (80 steps/T) | **{_dur(pr['estimate_s'])} (estimate)** | "
                 f"{_dur_ms(pr['s_per_period'])} | - | first {pr['periods_measured']} periods of the same "
                 f"schedule measured ({pr['oscillators']} oscillators), times {pr['total_periods']} periods |")
    if "rk4" in sq and "wall_s" in sq["rk4"]:
        r = sq["rk4"]
        L.append(f"| RK4, numba kernel, whole run | {_dur(r['wall_s'])} | {_dur_ms(r['s_per_period'])} | "
                 f"root trace {r['root_trace']}, valid {r['valid']} | measured |")
    old = res.get("sqrt_before_2bd32d8", {})
    if "wall_s" in old.get("rk4", {}) and "wall_s" in old.get("envelope", {}):
        L.append(f"| *previous `sqrt.v` (before commit 2bd32d8, {old['logic']['gates']} gates, "
                 f"{old['envelope']['periods']} periods)*: envelope step 1 T | {_dur(old['envelope']['wall_s'])} | "
                 f"{_dur_ms(old['envelope']['s_per_period'])} | root trace {old['envelope']['root_trace']} | "
                 "measured (envelope code as of commit c97a5be) |")
        L.append(f"| *previous `sqrt.v`*: RK4, numba kernel, whole run | {_dur(old['rk4']['wall_s'])} | "
                 f"{_dur_ms(old['rk4']['s_per_period'])} | root trace {old['rk4']['root_trace']}, valid "
                 f"{old['rk4']['valid']} | measured: **{old['rk4']['wall_s'] / old['envelope']['wall_s']:.0f}x the "
                 f"envelope**; its first-400-period estimate was {_dur(old['rk4_probe']['estimate_s'])} |")
    if "s_per_cycle" in lg:
        L.append(f"| logic (`run_clocked_logic`) | {_dur_ms(lg['wall_s'])} | {lg['s_per_cycle'] * 1e3:.2f} ms per "
                 f"cycle | root {lg['root']} | measured |")
    L.append("")
    return L


def sieve_md(res: dict) -> list[str]:
    """The sieve's estimated wall times per fidelity as markdown lines ([] if none)."""
    sv = res.get("sieve", {})
    if not sv:
        return []
    L = ["## The sieve on an 8-bit processor: estimated wall time per fidelity", "",
         "Clock schedule from `simulation.clock_timing`'s formula: pulse = 1.6 x 500 = 800 periods, pause = "
         "1640 - pulse + 225 x (depth + 1) + 600, total = pause + cycles x (pulse + pause) "
         "(`simulation.clocked_schedule`). Cost per period measured at the design's size (batch 1) and multiplied "
         "out; memory for every backend stays far below the machine's (see the scaling table).", ""]
    names = {"issue_processor": "the issue's processor: 12000 oscillators (~2000 NOR blocks), 700 cycles, depth 40",
             "cpu_v": "this repository's `verilog/cpu.v` running `programs/sieve.asm`"}
    for key, blk in sv.items():
        L += [f"### {names.get(key, key)}", "",
              f"{blk['oscillators']} oscillators, logic depth {blk['logic_depth']}, {blk['cycles']} cycles of "
              f"{blk['pulse']} + {blk['pause']} periods: **{blk['total_periods']:,} drive periods**.", "",
              "| fidelity | cost | wall time for the sieve | how measured |", "|---|---|---|---|"]
        for b, e in sorted(blk["estimates"].items(), key=lambda kv: kv[1]["total_s"]):
            cost = _dur_ms(e["s_per_period"]) + " per period" if "s_per_period" in e else \
                f"{e['s_per_cycle'] * 1e3:.0f} ms per cycle"
            L.append(f"| {SIEVE_LABEL.get(b, b)} | {cost} | **{_dur(e['total_s'])}** | {e['how']} |")
        L.append("")
    return L


SIEVE_LABEL = {"rk4": "RK4, numba kernel (80 steps/T)", "rk4_numpy": "RK4, numpy (80 steps/T)",
               "envelope": "envelope, step 1 T, fixed pauses", "envelope_step2": "envelope, step 2 T",
               "envelope_settle": "envelope, compiled, with settle detection (`cpu run --backend envelope`, measured)",
               "envelope_sparse": "envelope step 1 T, sparse slow block (proposed fix, prototype)",
               "envelope_dense": "envelope step 1 T, before c97a5be (dense slow block)",
               "envelope_sparse_step2": "envelope step 2 T, sparse slow block (prototype)",
               "ngspice": "ngspice (defaults, T/40)", "logic": "logic level (NOR netlist, cycle by cycle)"}


def cpu_md(res: dict) -> list[str]:
    """The cpu.v per-backend cost section of performance.md as markdown lines ([] if not measured)."""
    cpu = res.get("cpu")
    if not cpu:
        return []
    L = ["## The processor model (`verilog/cpu.v`) per backend", "",
         f"`network.build` of `verilog/cpu.v`: {cpu['logic_gates']} logic NOR gates + {cpu['latches']} latches = "
         f"{cpu['gate_blocks']} gate blocks, {cpu['oscillators']} oscillators, logic depth {cpu['logic_depth']}. "
         "Drives at their model amplitudes (every input and the clock at '0'): the cost per period does not depend "
         "on the values.", "",
         "| backend | periods measured | wall per period | peak RSS python [MB] | ngspice peak [MB] |", "|---|---|---|---|---|"]
    for r in cpu["rows"]:
        if "s_per_period" not in r:
            L.append(f"| {LABEL.get(r.get('backend'), r.get('backend'))} | FAILED {r.get('failed')} | | | |")
            continue
        lab = LABEL[r["backend"]].replace("step 2 T", f"step {r.get('step_periods', 2):g} T")
        L.append(f"| {lab} | {r['periods']} | {_dur_ms(r['s_per_period'])} | {r['rss_peak_mb']:.0f} | "
                 f"{_f(r.get('ngspice_maxrss_mb'), '{:.0f}')} |")
    L.append("")
    return L


def profile_md(res: dict) -> list[str]:
    """The 'where the time goes' section of performance.md as markdown lines ([] if not measured)."""
    pf = res.get("profile")
    if not pf or "envelope" not in pf:
        return []
    L = ["## Where the time goes", "", "### Envelope (`envelope.integrate`, step 2 T, chains of NOR gates)", ""]
    for e in pf["envelope"]:
        L += [f"**{e['oscillators']} oscillators** ({e['n_slow']} slow DOFs, slow block stored as "
              f"`{e.get('slow_block_type', '?')}`): {e['periods']} periods, {e['rhs_calls']} right-hand sides, "
              f"{e['wall_s']:.2f} s under cProfile. Top functions by own time:", "",
              "| function | calls | own time [s] | cumulative [s] |", "|---|---|---|---|"]
        for t in e["top"][:7]:
            L.append(f"| `{t['function']}` | {t['calls']} | {t['tottime']:.3f} | {t['cumtime']:.3f} |")
        L += ["", "One right-hand side, by part (timed separately, batch 1):", "",
              "| part | time |", "|---|---|"]
        for k, v in e["parts_s"].items():
            L.append(f"| {k} | {v * 1e6:.0f} us |")
        L.append("")
    L += ["### Compiled RK4 kernel (`rk4_kernel.run_periods`, batch 1)", "",
          "| oscillators | per step | ns per oscillator-step | oscillator-steps/s | share of a step in the 4 force evaluations (`_accel`) | prototype (batch 1, one fused CSR): ns per oscillator-step | speed-up | max rel. difference after 3 periods |",
          "|---|---|---|---|---|---|---|---|"]
    for r in pf["rk4"]:
        L.append(f"| {r['oscillators']} | {r['step_s'] * 1e6:.1f} us | {r['ns_per_osc_step']:.1f} | "
                 f"{r['osc_steps_per_s']:.3g} | {100 * r['accel_share_of_step']:.0f} % | "
                 f"{r['fused_ns_per_osc_step']:.1f} | {r['fused_speedup']:.2f}x | {r['fused_rel_diff_after_3_periods']:.1e} |")
    L.append("")
    return L


def _row(res, backend, n):
    return next((r for r in res.get("scaling", {}).get("rows", []) if r.get("backend") == backend
                 and r.get("oscillators") == n and "s_per_period" in r), None)


def SUMMARY_HOOK(res):
    """The Summary's markdown lines: adder ratio, 12000 oscillators, exponents, sqrt, sieve, profile."""
    L = ["## Summary", ""]
    ad = res.get("adder", {}).get("rows", {})
    env = [ad[k]["wall_s"] for k in ("envelope", "envelope_again") if "wall_s" in ad.get(k, {})]
    if env and "wall_s" in ad.get("rk4", {}):
        e = sum(env) / len(env)
        L.append(f"- **Adder, 16 inputs, `run_physical`: envelope {e:.2f} s, RK4 (numba) {ad['rk4']['wall_s']:.1f} s "
                 f"-> {ad['rk4']['wall_s'] / e:.1f}x** (issue: >= 20x). RK4 numpy {ad.get('rk4_numpy', {}).get('wall_s', float('nan')):.1f} s, "
                 f"ngspice {ad.get('ngspice', {}).get('wall_s', float('nan')):.0f} s (2 processes at a time). "
                 + _adder_history(res))
    big = {b: _row(res, b, 12000) for b in BACKENDS}
    if big.get("rk4"):
        parts = [f"{LABEL[b].split(' (')[0]} {_dur_ms(r['s_per_period'])}" for b, r in big.items() if r]
        L.append("- **12000 oscillators, per drive period (batch 1):** " + "; ".join(parts) + ".")
        old = {r["oscillators"]: r for r in res.get("before_sparse_fix", {}).get("scaling_rows", [])
               if r["backend"] == "envelope"}
        if big.get("envelope") and 12000 in old:
            o = old[12000]
            L.append(f"- **Found and fixed during this work (commit c97a5be): the envelope's dense slow block.** Before "
                     f"it, the envelope took {_dur_ms(o['s_per_period'])} per period at 12000 oscillators (step 2 T), "
                     f"only {big['rk4']['s_per_period'] / o['s_per_period']:.1f}x faster than RK4, against "
                     f"{_old_ratio(res, old, 1020):.0f}x at 1020 oscillators: `Envelope` kept the slow block's "
                     "stiffness and damping as dense n_slow x n_slow arrays and `rhs` evaluated `-self.Ks @ s` (a copy "
                     "of the negated dense matrix, then a dense mat-vec) and `self.Cs @ sd` on every call, O(n_slow^2) "
                     f"time and memory (2 x 31 MB at 2000 gates; peak RSS +{o['rss_peak_mb'] - o['rss_baseline_mb']:.0f} MB). "
                     f"Kept sparse: {_dur_ms(big['envelope']['s_per_period'])} per period now "
                     f"({o['s_per_period'] / big['envelope']['s_per_period']:.0f}x faster at 12000 oscillators).")
    fits = res.get("scaling", {}).get("fits", {})
    if fits:
        L.append("- **Scaling exponents** (time per period ~ n^k, 300-12000 oscillators): " + "; ".join(
            f"{LABEL[b].split(' (')[0]} {f['exponent']:.2f}" for b, f in fits.items() if "exponent" in f)
            + ". RK4 (numba) is linear at a constant ~1e7 oscillator-steps/s; numpy RK4 and the envelope are "
              "overhead-bound (Python per step) at small sizes, hence exponents below 1; ngspice jumps by ~15x between "
              "1020 and 3000 oscillators and is then roughly linear.")
    sq = res.get("sqrt", {})
    if "wall_s" in sq.get("envelope", {}):
        t = (f"- **sqrt(2809)** (`verilog/sqrt.v`, {sq['logic'].get('gates', '?')} gates), {sq['envelope']['periods']} "
             f"periods: envelope {_dur(sq['envelope']['wall_s'])} (root trace ends at {sq['envelope']['root_trace'][-1]})")
        if "wall_s" in sq.get("rk4", {}):
            t += f", RK4 {_dur(sq['rk4']['wall_s'])} measured ({sq['rk4']['wall_s'] / sq['envelope']['wall_s']:.0f}x)"
        if "estimate_s" in sq.get("rk4_probe", {}):
            t += f", RK4 estimated {_dur(sq['rk4_probe']['estimate_s'])} from its first 400 periods"
        old = res.get("sqrt_before_2bd32d8", {})
        if "wall_s" in old.get("rk4", {}):
            t += (f". On the previous sqrt.v ({old['logic']['gates']} gates) both ran in full: RK4 "
                  f"{_dur(old['rk4']['wall_s'])} vs envelope {_dur(old['envelope']['wall_s'])}, "
                  f"{old['rk4']['wall_s'] / old['envelope']['wall_s']:.0f}x")
        L.append(t + ".")
    sv = res.get("sieve", {})
    for key, lab in (("issue_processor", "issue's 12000-oscillator processor, 700 cycles"),
                     ("cpu_v", "`verilog/cpu.v`, 457 cycles")):
        if key in sv:
            est = sv[key]["estimates"]
            L.append(f"- **Sieve, {lab}** ({sv[key]['total_periods']:,} periods): " + "; ".join(
                f"{SIEVE_LABEL.get(b, b).split(' (')[0]} {_dur(e['total_s'])}" for b, e in
                sorted(est.items(), key=lambda kv: kv[1]["total_s"])) + " (estimates from measured per-period costs).")
    pf = res.get("profile", {})
    if pf.get("envelope"):
        e0 = pf["envelope"][0]["parts_s"]
        k_as = next((v for k, v in e0.items() if k.startswith("`-self.Ks")), None)
        k_fix = e0.get("`-(self.Ks @ s)`")
        if k_as and k_fix:
            L.append(f"- **Small designs after the sparse fix**: `rhs` writes `-self.Ks @ s`, which with a sparse `Ks` "
                     f"builds a negated copy of the matrix on every call: {k_as * 1e6:.0f} us against "
                     f"{k_fix * 1e6:.0f} us for `-(self.Ks @ s)`, out of {e0['whole rhs'] * 1e6:.0f} us per right-hand "
                     f"side at {pf['envelope'][0]['oscillators']} oscillators (~{100 * (k_as - k_fix) / e0['whole rhs']:.0f} %). "
                     "One pair of brackets in `Envelope.rhs` (or storing the slow block's diagonal, which is all it has "
                     "in every network built here) removes it.")
    if pf.get("rk4"):
        sp = [r["fused_speedup"] for r in pf["rk4"]]
        L.append(f"- **Compiled RK4 kernel**: ~{min(r['ns_per_osc_step'] for r in pf['rk4']):.0f} ns per oscillator-step, "
                 "slower than the numpy path's single scipy CSR product at >= 3000 oscillators. A batch-1 loop with "
                 f"one fused CSR (the matrix `rk4.force_matrix` already builds) is {min(sp):.1f}-{max(sp):.1f}x faster "
                 "with identical results (prototype below).")
    L.append("")
    return L


def _adder_history(res) -> str:
    h = res.get("adder_before_5c6b8d2", {}).get("rows", {})
    if not ("wall_s" in h.get("rk4", {}) and "wall_s" in h.get("envelope", {})):
        return ""
    e = (h["envelope"]["wall_s"] + h.get("envelope_again", h["envelope"])["wall_s"]) / 2
    out = (f"Before commit 5c6b8d2 (envelope step 2 T, `Envelope` rebuilt for every 100-period chunk) the same "
           f"measurement gave {h['rk4']['wall_s'] / e:.1f}x (RK4 {h['rk4']['wall_s']:.1f} s / envelope {e:.2f} s)")
    if "wall_s" in h.get("envelope_step4_cached", {}):
        out += (f"; this script's what-if runs with step 4 and one `Envelope` per run gave "
                f"{h['rk4']['wall_s'] / h['envelope_step4_cached']['wall_s']:.0f}x, which 5c6b8d2 then adopted")
    return out + "."


def _old_ratio(res, old, n):
    a = _row(res, "rk4", n)
    return a["s_per_period"] / old[n]["s_per_period"] if a and n in old else float("nan")


def _ratio(res, n):
    a, b = _row(res, "rk4", n), _row(res, "envelope", n)
    return a["s_per_period"] / b["s_per_period"] if a and b else float("nan")


def DETAIL_HOOK(res):
    """The markdown lines of the adder, sqrt, cpu.v, sieve and profile sections."""
    return adder_md(res) + sqrt_md(res) + cpu_md(res) + sieve_md(res) + profile_md(res)
