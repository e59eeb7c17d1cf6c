"""reports/carrier.md and its charts, rendered from reports/carrier.json (mech2spice/studies/carrier.py measures
it; its module docstring lists the sections).  `mech2spice report carrier [--only NAME ...] [--quick]`
measures and renders, `--render` only renders.

Blocks other reports append: `block` (speed_accuracy.md), `roofline_block` (performance.md), `sieve_block`
(fidelity.md).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ._common import SANDBOX, md_table, out_dir, pyplot, read_json, save_figure, write_json

# The criteria and settings the text states: studies/carrier.py's (tests/test_studies.py checks they agree).
AMP_TOL, PHASE_TOL = 1e-3, 0.5          # the bounds against RK4 at 160 steps (u_R, degrees)
FAIL_UR = 0.1                           # an error above this (u_R) counts as a failed run
FINE_STEPS = 640                        # the convergence section's reference, RK4 steps per period
REDUCED_TOL = 0.02                      # u_R: issue 6's agreement tolerance for reduced models


def _measured_on(extra: str = "") -> str:
    return f"{SANDBOX} (shared{extra})"


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
    """Measure the sections in `only` (default all; `render`: none) into carrier.json (studies/carrier.py),
    rewrite carrier.md and the charts from the whole JSON."""
    out = out_dir(directory)
    if not render:
        from ..studies import carrier as study      # measuring loads the engines; rendering does not
        study.measure(out, only, quick, carrier_trace=carrier_trace, envelope_trace=envelope_trace,
                      processor_check=processor_check, latency_trace=latency_trace)
    d = read_json(out / "carrier.json", {})
    d["machine"] = _measured_on()
    return render_all(d, out)
