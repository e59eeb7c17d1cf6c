"""The envelope-spice section of speed_accuracy.md and its chart speed_accuracy_envelope_spice.png, rendered from
envelope_spice.json (mech2spice/studies/envelope_spice.py measures it; its docstring lists the sections).

Not a report of its own: `mech2spice report speed_accuracy` is the one writer of speed_accuracy.md and puts
`block()` at its end.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ._common import SANDBOX, pyplot, read_json, save_figure, write_json

MACHINE = f"{SANDBOX}, shared"


BEGIN, END = "<!-- envelope-spice:begin -->", "<!-- envelope-spice:end -->"


def charts(res: dict, out: Path) -> str:
    """Draw speed_accuracy_envelope_spice.png (error vs wall time per scene, scaling); returns its name."""
    plt, st = pyplot(), res["settings"]
    acc = res["accuracy"]
    fig, axes = plt.subplots(2, 2, figsize=(12, 9.5))
    axes = axes.ravel()
    marker = {1e-3: "v", 1e-4: "o", 1e-5: "s"}
    color = {"trap": "tab:blue", "gear": "tab:orange"}
    for ax, (name, d) in zip(axes, acc.items()):
        for method in st['methods']:
            for rt in st['reltols']:
                pts = [r for r in d["spice"] if r["method"] == method and r["reltol"] == rt and "failed" not in r]
                if pts:
                    ax.plot([r["wall_s"] for r in pts], [max(r["traj_err_ur"], 1e-6) for r in pts],
                            marker=marker[rt], color=color[method], ls="-", lw=0.8,
                            label=f"ngspice-envelope {method}, reltol {rt:g}")
                    for r in pts:
                        ax.annotate(f"{r['max_step']:g}", (r["wall_s"], max(r["traj_err_ur"], 1e-6)), fontsize=6,
                                    xytext=(2, 2), textcoords="offset points")
        py = [r for r in d["python"] if "wall_s" in r]
        ax.plot([r["wall_s"] for r in py], [max(r["traj_err_ur"], 1e-6) for r in py], marker="D", color="tab:green",
                label="Python envelope (RK4)")
        for r in py:
            ax.annotate(f"{r['step']:g}", (r["wall_s"], max(r["traj_err_ur"], 1e-6)), fontsize=6,
                        xytext=(2, -8), textcoords="offset points", color="tab:green")
        ax.axhline(0.01, color="grey", ls=":", lw=0.8)
        ax.set(xscale="log", yscale="log", xlabel="wall time, one core [s] (labels: step / max step in T)",
               ylabel="trajectory error vs envelope at T/8 [u_R] (< 1e-6 drawn at 1e-6)",
               title=f"{name} ({d['oscillators']} osc, {len(d['members'])} cases, {d['periods']} T)")
        ax.grid(alpha=0.3, which="both")
    axes[0].legend(fontsize=6)
    ax = axes[-1]
    sc = res["scaling"]["rows"]
    n = [r["oscillators"] for r in sc]
    for key, lab, st in (("spice_50_s", "ngspice-envelope, 50 T", "o-"), ("spice_2500_s", "ngspice-envelope, 2500 T", "o--"),
                         ("python_50_s", "Python envelope, 50 T", "D-"), ("python_2500_s", "Python envelope, 2500 T", "D--"),
                         ("carrier_50_s", "ngspice carrier-level, 50 T (speed_accuracy.json)", "s-"),
                         ("carrier_2500_s_extrapolated", "ngspice carrier-level, 2500 T (x50, extrapolated)", "s:")):
        pts = [(x, r[key]) for x, r in zip(n, sc) if key in r]
        if pts:
            ax.plot(*zip(*pts), st, label=lab, ms=4)
    ax.set(xscale="log", yscale="log", xlabel="oscillators (independent NOR gates)", ylabel="wall time [s]",
           title=f"scaling ({MACHINE})")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=6)
    path = out / "speed_accuracy_envelope_spice.png"
    save_figure(fig, path)
    return path.name


def _best(rows, tol=0.01, key="traj_err_ur"):
    ok = [r for r in rows if "failed" not in r and r.get(key, math.inf) <= tol]
    return min(ok, key=lambda r: r["wall_s"]) if ok else None


def _lab(r):
    return f"{r['method']} reltol {r['reltol']:g} max step {r['max_step']:g} T"


def render(res: dict) -> str:
    """The envelope-spice section of speed_accuracy.md, markers included."""
    acc, fail, sc = res["accuracy"], res.get("failures", {}), res["scaling"]
    o, st = res["default_options"], res["settings"]     # as measured
    L = [BEGIN, "## SPICE on the envelope equations (ngspice-envelope)", "",
         f"Measured by `mech2spice report speed_accuracy --only envelope_spice` on the **{MACHINE}** (Python {res['python']}, ngspice 39, "
         f"no KLU); total script time {res['total_wall_s'] / 60:.1f} min; load average {res['load_before']} before, "
         f"{res['load_after']} after (other jobs shared the two cores: read wall times as +-25 %)"
         + (f"; sections {', '.join(res['rerun_sections'])} re-measured alone afterwards (last rerun "
            f"{res['partial_rerun_s']:.0f} s, load average {res.get('rerun_load_before', '?')} before)"
            if res.get("rerun_sections") else "") + ". Raw numbers: "
         "`reports/envelope_spice.json`; chart: `reports/speed_accuracy_envelope_spice.png`.", "",
         "### Circuit form", "",
         "`mech2spice/spice/envelope_netlist.py` writes the envelope equations (2iwM + C) A' = F - Z0 A - (G s) A and "
         "M_s s'' = -K_s s - C_s s' - H |A|^2 / 2 as a circuit in real time: two nodes per oscillating DOF "
         "(V = Re A, Im A in u_R), each row divided by its diagonal b_j = 2iw m_j + c_jj so that the left side "
         "is a 1 F capacitor per node (2iwM alone would couple Re and Im through the *derivatives*, which no "
         "capacitor can do); Z0/b_j and the drives are linear VCCS (G sources); the derivative couplings left "
         "by dashpots between oscillating DOFs are linear CCCS (F sources) reading 0 V sources in series with "
         "those DOFs' capacitors; only the quadratic terms are B sources (two per oscillating DOF with an "
         "insulator, one per insulator). Insulators keep the carrier-level mobility form (velocity node C = m, "
         "displacement node). Input changes are smooth tanh steps (time constant T/4) in B voltage sources, "
         "not PWL (see failure points). Backend `ngspice-envelope` in `simulate`/the CLI; per-period amplitudes "
         "are the node voltages interpolated at each period's end.", "",
         "Checks (tests/test_spice_envelope.py): a lone driven oscillator against A(t) = F/Z (1 - e^(-Zt/b)) and "
         "three dashpot/spring-coupled DOFs against the matrix exponential (relative error < 3e-4 at max step "
         "T/100); the gate's 4 input pairs against envelope.integrate; the adder 3+2 = 5 through `simulate`.", ""]
    L += ["### Speed vs accuracy", "",
          f"Errors against envelope.integrate at T/{int(1 / st['ref_step'])} (its difference from T/{int(1 / st['check_step'])}: "
          + ", ".join(f"{n} {d['reference']['traj_err_ur']:.1e} u_R" for n, d in acc.items())
          + "). *traj* = largest |amplitude| difference at any period end (u_R), *settled* = mean of the last 20 "
            "periods before each input change, *crossing* = worst relative error of a mid-band crossing time. "
            "Wall time: one-core cost (sum of the ngspice processes, one per input case, run two at a time; the "
            "Python integrator runs all cases in one vectorised call); ngspice-envelope time includes emission "
            "and raw-file reading.", ""]
    for name, d in acc.items():
        L += [f"**{name}**: {d['description']}; {d['oscillators']} oscillators; Python-envelope stability bound "
              f"{d['stability_bound_periods']:.1f} periods; reference wall {d['reference']['wall_s']:.2f} s.", ""]
        if "rk4_160" in d:
            v = d["rk4_160"]["vs_reference"]
            L += [f"The envelope model itself against RK4 at 160 steps/period ({d['rk4_160']['wall_s']:.2f} s): "
                  f"traj {v['traj_err_ur']:.4f} u_R, settled {v['amp_err_ur']:.4f} u_R, crossing {v['time_err']:.1%}. "
                  "The column *vs RK4-160* below is the total error of each run against that carrier-level reference.", ""]
        vs = "rk4_160" in d
        L += ["| backend | method | reltol | step [T] | wall [s] | points/case | traj [u_R] | settled [u_R] | crossing |"
              + (" vs RK4-160 traj [u_R] |" if vs else ""),
              "|---|---|---|---|---|---|---|---|---|" + ("---|" if vs else "")]
        for r in d["python"]:
            if "refused" in r:
                L.append(f"| Python envelope | RK4 | - | {r['step']:g} | refused ({r['refused']}) | | | | |" + (" |" if vs else ""))
                continue
            L.append(f"| Python envelope | RK4 | - | {r['step']:g} | {r['wall_s']:.2f} | {d['periods'] / r['step']:.0f} | "
                     f"{r['traj_err_ur']:.4f} | {r['amp_err_ur']:.5f} | {r['time_err']:.1%} |"
                     + (f" {r['vs_rk4_160']['traj_err_ur']:.4f} |" if vs else ""))
        for r in d["spice"]:
            if "failed" in r:
                L.append(f"| ngspice-envelope | {r['method']} | {r['reltol']:g} | {r['max_step']:g} | failed: "
                         f"{r['failed'][:80]} | | | | |" + (" |" if vs else ""))
                continue
            L.append(f"| ngspice-envelope | {r['method']} | {r['reltol']:g} | {r['max_step']:g} | {r['wall_s']:.2f} | "
                     f"{r['points']:.0f} | {r['traj_err_ur']:.4f} | {r['amp_err_ur']:.5f} | {r['time_err']:.1%} |"
                     + (f" {r['vs_rk4_160']['traj_err_ur']:.4f} |" if vs else ""))
        L.append("")
    # failure points
    L += ["### Failure points", ""]
    stalls = fail.get("pwl_stall", [])
    if stalls:
        bad = [s for s in stalls if s["stalled"]]
        good = [s for s in stalls if not s["stalled"] and s["form"].startswith("tanh")]
        L.append(f"- **Stall after a PWL breakpoint.** With the drive changes written as PWL sources (ramp 1e-3 T, "
                 f"as the carrier-level netlist does), {len(bad)} of {sum(s['form'].startswith('PWL') for s in stalls)} "
                 f"adder runs (members {', '.join(sorted({s['member'] for s in stalls}))}; max step / reltol "
                 f"{', '.join(sorted({'%g/%g' % (s['max_step'], s['reltol']) for s in bad}))}) never finished "
                 f"(killed after {st['stall_timeout']:.0f} s; a normal run takes < 4 s): right after the ramp's breakpoint "
                 "ngspice cut its step, point by point, down to delmin = 1e-11 x max step and stayed there "
                 "- no error message, no progress"
                 + (f" (e.g. {bad[0]['member']}, max step {bad[0]['max_step']:g} T: from period "
                    f"{bad[0].get('stall_from_period', float('nan')):.5f} on every step was "
                    f"{bad[0].get('last_step_periods', float('nan')):.1e} T; the steps into it, in T: "
                    + ", ".join(f"{x:.1e}" for x in bad[0].get("steps_into_stall_periods", [])) + ")" if bad else "")
                 + f". The same runs with the smooth tanh steps that spice/envelope_netlist.py writes: {len(good)} of "
                   f"{sum(s['form'].startswith('tanh') for s in stalls)} finished. At t ~ 2900 T = 374 s, delmin "
                   "(0.6 to 2.6 ps for max steps 0.5 to 2 T) is only 10 to 50 ulps of t: a step that small is "
                   "rounded by up to 10 %, the drive is evaluated at the rounded time, and the truncation-error "
                   "estimate, fed that noise, keeps asking for the minimum step. delmin = 1e-11 x max step is not "
                   "an ngspice option. "
                   "With reltol 1e-4 neither form stalled in these runs.")
    ls = fail.get("large_steps", {})
    if ls:
        nfail = sum("failed" in r for rows in ls.values() for r in rows)
        L.append(f"- **No step-size stability limit.** trap is A-stable: at max steps of "
                 f"{' and '.join(f'{x:g}' for x in st['large_steps'])} periods {'nothing' if not nfail else f'{nfail} runs'} "
                 "diverged or failed, and ngspice's truncation-error control (trtol 7) chose the steps itself (largest "
                 "step taken below); the error is then set by reltol alone - the max step is an accuracy knob, not a "
                 "stability one. trap, wall one-core:")
        L += ["", "  | design | max step [T] | reltol | wall [s] | largest step taken [T] | traj [u_R] | settled [u_R] |",
              "  |---|---|---|---|---|---|---|"]
        for name, rows in ls.items():
            for r in rows:
                L.append(f"  | {name} | {r['max_step']:g} | {r['reltol']:g} | " + (
                    f"failed: {r['failed'][:60]} | | | |" if "failed" in r else
                    f"{r['wall_s']:.2f} | {r['max_step_used']:.1f} | {r['traj_err_ur']:.4f} | {r['amp_err_ur']:.5f} |"))
        L.append("")
    refused = sum("refused" in r for d in acc.values() for r in d["python"])
    failed = sum("failed" in r for d in acc.values() for r in d["spice"])
    L.append(f"- **Divergence / 'timestep too small'**: {'none' if not failed else f'{failed} runs'} in the accuracy "
             "runs (the runner maps either to a DivergenceError naming the DOF). The Python integrator, explicit "
             "RK4, refuses steps beyond its stability bound"
             + (f" ({refused} rows marked refused)." if refused else
                " (" + ", ".join("%s %.1f T" % (n, d["stability_bound_periods"]) for n, d in acc.items())
                + "; none of the steps above reached it)."))
    pairs = []
    for d in acc.values():
        for g in d["spice"]:
            t = next((r for r in d["spice"] if r["method"] == "trap" and r["max_step"] == g["max_step"]
                      and r["reltol"] == g["reltol"]), None)
            if g["method"] == "gear" and t and "failed" not in g and "failed" not in t:
                pairs.append((g["traj_err_ur"] / max(t["traj_err_ur"], 1e-12), g["wall_s"] / t["wall_s"]))
    if pairs:
        worse = sum(e > 1 for e, _ in pairs)
        L.append(f"- **gear** (BDF2, numerically damped) against trap at the same max step and reltol: larger "
                 f"trajectory error in {worse} of {len(pairs)} runs (median ratio {np.median([e for e, _ in pairs]):.1f}x), "
                 f"median wall-time ratio {np.median([w for _, w in pairs]):.2f}.")
    L.append("")
    # defaults
    L += ["### Recommended defaults", "",
          f"`EnvelopeSpiceOptions(method=\"{o['method']}\", max_step_periods={o['max_step_periods']:g}, "
          f"reltol={o['reltol']:g}, abstol={o['abstol']:g}, vntol={o['vntol']:g}, chgtol={o['chgtol']:g}, "
          f"trtol={o['trtol']:g})` (the `ngspice-envelope` backend's default). Measured at these settings:", ""]
    for name, d in acc.items():
        r = next((r for r in d["spice"] if r["method"] == o["method"] and r["max_step"] == o["max_step_periods"]
                  and r["reltol"] == o["reltol"] and "failed" not in r), None)
        b = _best(d["spice"])
        if r:
            L.append(f"- {name}: {r['wall_s']:.2f} s, traj {r['traj_err_ur']:.4f} u_R, settled {r['amp_err_ur']:.5f} u_R, "
                     f"crossing {r['time_err']:.1%}" + (f"; fastest run within 0.01 u_R traj: {_lab(b)} ({b['wall_s']:.2f} s)"
                                                        if b else ""))
    def worst(method, rt, ms):
        rs = [next((r for r in d["spice"] if r["method"] == method and r["reltol"] == rt and r["max_step"] == ms
                    and "failed" not in r), None) for d in acc.values()]
        return None if None in rs else (max(r["traj_err_ur"] for r in rs), sum(r["wall_s"] for r in rs))
    ok_steps = [ms for ms in st['max_steps'] if (w := worst("trap", o["reltol"], ms)) and w[0] <= 0.01]
    dflt, fine, coarse = worst("trap", o["reltol"], o["max_step_periods"]), worst("trap", 1e-5, o["max_step_periods"]), \
        worst("trap", 1e-3, o["max_step_periods"])
    trap_rows = [r for name, d in acc.items() for r in d["spice"] + fail.get("large_steps", {}).get(name, [])
                 if r.get("method", "trap") == "trap" and "failed" not in r]
    any_step = {rt: max((r["traj_err_ur"] for r in trap_rows if r["reltol"] == rt), default=math.nan) for rt in st['reltols']}
    if dflt:
        L += ["", "Why (worst trajectory error over the three scenes / summed wall time): trap, because gear was "
                  "less accurate at the same cost (above). At reltol "
                  f"{o['reltol']:g} the largest max step keeping all three scenes within 0.01 u_R is "
                  f"{max(ok_steps) if ok_steps else 'none'} T ({dflt[0]:.4f} u_R, {dflt[1]:.1f} s). ngspice's own "
                  "truncation-error control holds the step below the maximum during switching, so at this reltol "
                  f"the error stays bounded whatever the max step ({any_step[o['reltol']]:.3f} u_R at worst, max "
                  f"steps up to 1000 T included); at reltol 1e-3 it does not ({any_step[1e-3]:.3f} u_R at worst): "
                  "there only the max step holds the error"
                  + (f", though at 2 T it is as accurate ({coarse[0]:.4f} u_R, {coarse[1]:.1f} s)" if coarse else "")
                  + ". Reltol 1e-5"
                  + (f" ({fine[0]:.4f} u_R, {fine[1]:.1f} s at 2 T)" if fine else "")
                  + " is the choice when a tighter trajectory matters; it was also where the PWL stall appeared.", ""]
        big_settled = [r for r in trap_rows if r["amp_err_ur"] > 0.002]
        L += [f"The settled amplitudes (what `simulate` decodes) are within "
              f"{max(r['amp_err_ur'] for r in trap_rows if r not in big_settled):.4f} u_R at every trap setting measured"
              + ("" if not big_settled else " except " + ", ".join(sorted({"reltol %g at %g T (%.3f u_R)" % (
                  r["reltol"], r["max_step"], r["amp_err_ur"]) for r in big_settled}))) + ".", ""]
    # scaling
    rows = sc["rows"]
    car = sc.get("carrier", {})
    L += ["### Scaling", "",
          f"Independent NOR gates (6 oscillators each, inputs '0'), from rest; ngspice-envelope at the defaults above "
          f"(one process); Python envelope (envelope.integrate, compiled loop where numba exists) at the backend's "
          f"step ({rows[0]['python_step']:g} T); ngspice carrier-level times from reports/speed_accuracy.json "
          f"(section 'scaling': {car.get('periods', '?')} periods at max step T/40, prewarped trap), its 2500-period "
          "cost extrapolated x50 (its step is pinned, so its cost is linear in periods). Wall times in s; "
          "ngspice-envelope's include emitting the netlist and reading the raw file, the Python envelope's do not "
          "include building the envelope operator and its stability bound (their own column; ngspice-envelope's emission reads the same "
          "operator, built once per model). The 50-period amplitudes differ by the start-up transient sampled "
          f"at different steps (Python {rows[0]['python_step']:g} T, ngspice <= 2 T); {MACHINE}.", "",
          "| oscillators | carrier 50 T | ngspice-env 50 T | Python env 50 T | carrier 2500 T (extrap.) | "
          "ngspice-env 2500 T | Python env 2500 T | carrier / ngspice-env (2500 T) | ngspice-env points (2500 T) | "
          "operator + step bound [s] | ngspice-env vs Python, 50 T / 2500 T [u_R] |",
          "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        c50, c25 = r.get("carrier_50_s"), r.get("carrier_2500_s_extrapolated")
        L.append(f"| {r['oscillators']} | {'-' if c50 is None else f'{c50:.2f}'} | {r['spice_50_s']:.2f} | "
                 f"{r['python_50_s']:.3f} | {'-' if c25 is None else f'{c25:.0f}'} | {r['spice_2500_s']:.2f} | "
                 f"{r['python_2500_s']:.3f} | {'-' if c25 is None else '%.0fx' % (c25 / r['spice_2500_s'])} | "
                 f"{r['spice_2500_points']} | {r['operator_s']:.2f} | {r['diff_50_ur']:.1e} / {r['diff_2500_ur']:.1e} |")
    big = rows[-1]
    ac = [r for r in rows if "acct" in r]
    L += ["", f"At {big['oscillators']} oscillators and 2500 periods ngspice-envelope took {big['spice_2500_s']:.1f} s "
              + (f"against ~{big['carrier_2500_s_extrapolated']:.0f} s extrapolated for the carrier-level netlist "
                 if 'carrier_2500_s_extrapolated' in big else "")
              + f"and {big['python_2500_s']:.2f} s for the Python envelope integrator: ngspice-envelope steps "
                f"~{st['scaling_periods'][-1] / big['spice_2500_points']:.1f} periods at a time (its max step 2 T; the "
                "carrier-level netlist takes 40 steps per period), but each of its steps costs far more than a "
                "compiled RK4 step over the same equations, and that cost grows faster than the circuit."]
    if ac:
        L += ["", "Where ngspice's time goes (`.options acct`, the same 2500-period runs repeated):", "",
              "| oscillators | B sources | timepoints | Newton iterations | analysis [s] | device load [s] | "
              "LU factor [s] | solve [s] | load per B source per iteration [us] |",
              "|---|---|---|---|---|---|---|---|---|"]
        for r in ac:
            a = r["acct"]
            per = 1e6 * a.get("load_s", 0) / max(a.get("iterations", 1) * a["b_sources"], 1)
            L.append(f"| {r['oscillators']} | {a['b_sources']} | {a.get('timepoints', 0):.0f} | "
                     f"{a.get('iterations', 0):.0f} | {a.get('analysis_s', 0):.2f} | {a.get('load_s', 0):.2f} | "
                     f"{a.get('factor_s', 0):.2f} | {a.get('solve_s', 0):.2f} | {per:.2f} |")
        nb = [(r["oscillators"], r["acct_without_b"]) for r in ac if "acct_without_b" in r]
        L += ["", "Device loading is the bulk of ngspice's time, and its cost per B source per iteration rises "
                  "with the circuit's size (cache misses, presumably; the LU factorisation stays small: the envelope circuit "
                  "is as sparse as the model). The B sources of the quadratic couplings are what costs: the same "
                  "netlists without them (a linear circuit, a cost probe only) took "
                  + ", ".join(f"{a['load_s']:.2f} s device load ({a['wall_s']:.1f} s wall) at {n} oscillators"
                              for n, a in nb)
                  + ". (During development, G-source POLY products in place of the B sources were slower, 20.7 s "
                    "against 16.7 s at 4200 oscillators and 1000 periods.) So the Python envelope integrator stays "
                    "the fast path; ngspice-envelope is the independent, exportable check, and it runs scenes two "
                    "orders of magnitude beyond the carrier-level netlist's reach."]
    L += ["", END]
    return "\n".join(L) + "\n"


def redraw(directory: Path, res: dict | None = None) -> dict | None:
    """The chart from the results (default: envelope_spice.json), recorded in the JSON."""
    jpath = Path(directory) / "envelope_spice.json"
    res = res if res is not None else read_json(jpath)
    if res is not None:
        res["chart"] = charts(res, Path(directory))
        write_json(jpath, res)
    return res


def block(directory: Path) -> str:
    """The speed_accuracy.md section between the envelope-spice markers, from envelope_spice.json; ''
    before the first run."""
    res = read_json(Path(directory) / "envelope_spice.json")
    return render(res) if res else ""
