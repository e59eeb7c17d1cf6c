"""speed_accuracy.md and its charts, rendered from reports/speed_accuracy.json (and the sections appended from
envelope_spice.json, vacask.json and carrier.json).  mech2spice/studies/speed_accuracy.py measures; its module
docstring lists the sections.  This module is the only writer of speed_accuracy.md.

usage: mech2spice report speed_accuracy [--quick] [--out reports] [--only SECTION ...] [--design NAME ...]
       mech2spice report speed_accuracy --only adder     # the adder's accuracy sweep only, merged into
                                                         # the existing JSON (same as --only accuracy
                                                         # --design adder2)
       mech2spice report speed_accuracy --render         # .md/.png from the JSONs, nothing measured
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from . import carrier as carrier_report, envelope_spice, vacask
from ..physics.params import DEFAULT as P
from ._common import SANDBOX, out_dir, pyplot, read_json, save_figure, write_json

MACHINE = SANDBOX        # where the checked-in numbers were measured


def charts(res: dict, out: Path) -> list[str]:
    """Draw the trade-off, damping and scaling charts; returns their file names."""
    plt, s = pyplot(), res["settings"]
    files = []
    acc = res["accuracy"]
    fig, axes = plt.subplots(1, len(acc), figsize=(6 * len(acc), 5), squeeze=False)
    axes = axes[0]
    styles = {("rk4", None): "k-o", ("ngspice", "trap+prewarp"): "g-s", ("ngspice", "trap"): "b-^",
              ("ngspice", "gear"): "r-v"}
    for ax, (name, d) in zip(axes, acc.items()):
        key = "cpu_s" if all("cpu_s" in r for r in d["rows"] if "amp_err_ur" in r) else "wall_s"
        for (backend, method), style in styles.items():
            for reltol in s["reltols"]:
                rows = [r for r in d["rows"] if r["backend"] == backend and r.get("method") == method
                        and r.get("reltol", reltol) == reltol and "amp_err_ur" in r]
                if not rows or (backend == "rk4" and reltol != s["reltols"][0]):
                    continue
                lab = "RK4" if backend == "rk4" else f"ngspice {method}, reltol {reltol:g}"
                ax.loglog([r[key] for r in rows], [max(r["amp_err_ur"], 1e-6) for r in rows], style,
                          alpha=1.0 if reltol == s["reltols"][0] else 0.4, label=lab)
                for r in rows:
                    ax.annotate(f"{r['steps_per_period']}", (r[key], max(r["amp_err_ur"], 1e-6)),
                                fontsize=6, xytext=(2, 2), textcoords="offset points")
        ax.axhline(0.01, color="grey", ls="--", lw=0.8)
        ax.set(title=f"{name}: {d['cases']} case(s), {d['periods']} periods (labels: steps/period)",
               xlabel=("CPU" if key == "cpu_s" else "wall") + " time [s] (ngspice: sum over cases)",
               ylabel="max amplitude error [u_R] vs RK4 @160")
        ax.legend(fontsize=7)
    fig.suptitle(f"speed vs accuracy, {MACHINE}")
    fig.tight_layout()
    files.append(_save(fig, out / "speed_accuracy_tradeoff.png"))

    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12, 5))
    rows = res["damping"]["rows"]
    exact_ppm = 1e6 * (1 - math.sqrt(1 - 1 / (4 * s["q_true"] ** 2)))
    for (backend, method), style in styles.items():
        sel = [r for r in rows if r["backend"] == backend and r.get("method") == method]
        if sel:
            lab = "RK4" if backend == "rk4" else f"ngspice {method}"
            ax.semilogx([r["steps_per_period"] for r in sel], [r["q_fit"] for r in sel], style, label=lab)
            ax2.loglog([r["steps_per_period"] for r in sel],
                       [max(abs(-r["freq_err_ppm"] - exact_ppm), 1e-3) for r in sel], style, label=lab)
    ax.axhline(s["q_true"], color="grey", ls="--", lw=0.8, label="true Q")
    ax.set(xlabel="steps per period", ylabel="fitted Q of the ring-down", ylim=(0, 1.3 * s["q_true"]),
           title=f"numerical damping, lone Q={s['q_true']:g} oscillator")
    ax2.set(xlabel="steps per period", ylabel="|frequency error - exact (-3.1 ppm)| [ppm]",
            title="phase drift (frequency error)")
    ax.legend(fontsize=8)
    ax2.legend(fontsize=8)
    fig.suptitle(MACHINE)
    fig.tight_layout()
    files.append(_save(fig, out / "speed_accuracy_damping.png"))

    fig, ax = plt.subplots(figsize=(7, 5))
    rows = res["scaling"]["rows"]
    n = [r["oscillators"] for r in rows]
    ax.loglog(n, [r["rk4_s"] for r in rows], "k-o",
              label=f"RK4 ({res.get('rk4_kernel', 'numpy')} kernel, {res['scaling']['rk4_steps_per_period']} steps/period)")
    ax.loglog(n, [r["ngspice_s"] for r in rows], "g-s", label="ngspice (defaults)")
    ax.set(xlabel="oscillators", ylabel=f"wall time for {s['scaling_periods']} periods [s]",
           title=f"scaling, independent NOR gates ({MACHINE})")
    ax.legend()
    files.append(_save(fig, out / "speed_accuracy_scaling.png"))
    return files


def _save(fig, path: Path) -> str:
    save_figure(fig, path, dpi=120, tight=False)
    return path.name


def _row_label(r: dict) -> str:
    if r["backend"] == "rk4":
        return "RK4"
    return f"ngspice {r['method']}" + (f", reltol {r['reltol']:g}" if "reltol" in r else "")


def _acc_table(name: str, d: dict, ref_steps: int) -> list[str]:
    out = [f"Design **{name}** ({d['cases']} case(s), {d['periods']} periods, probes {', '.join(d['probes'])}); "
           f"reference RK4 at {ref_steps} steps/period; machine {MACHINE}.", "",
           "| design | backend | step | wall [s] | CPU [s] | amp err [u_R] | phase err [deg] | trajectory err [u_R] "
           "| steps at max |", "|---|---|---|---|---|---|---|---|---|"]
    for r in d["rows"]:
        cpu = f"{r['cpu_s']:.2f}" if "cpu_s" in r else "-"
        if r.get("reference"):
            out.append(f"| {name} | RK4 (reference) | T/{r['steps_per_period']} | {r['wall_s']:.2f} | {cpu} | 0 | 0 | 0 | - |")
        elif "amp_err_ur" in r:
            uni = f"{r['uniform_fraction']:.0%}" if "uniform_fraction" in r else "-"
            out.append(f"| {name} | {_row_label(r)} | T/{r['steps_per_period']} | {r['wall_s']:.2f} | {cpu} | "
                       f"{r['amp_err_ur']:.4f} | {r['phase_err_deg']:.2f} | {r['traj_err_ur']:.4f} | {uni} |")
        else:
            out.append(f"| {name} | {_row_label(r)} | T/{r['steps_per_period']} | failed: {r['failed'][:80]} | | | | | |")
    return out + [""]


def _t(r: dict) -> str:
    """A row's cost: wall time, and CPU time where measured."""
    return f"{r['wall_s']:.2f} s" + (f" wall, {r['cpu_s']:.2f} s CPU" if "cpu_s" in r else "")


def _first_ok(rows, backend, method=None, reltol=None, tol=0.01, phase=2.0, traj=math.inf):
    """The coarsest step meeting the tolerances (settled amplitude and phase, trajectory), or None."""
    ok = [r for r in rows if r["backend"] == backend and r.get("method") == method and "amp_err_ur" in r
          and (reltol is None or r.get("reltol") == reltol) and not r.get("reference")
          and r["amp_err_ur"] < tol and r["phase_err_deg"] < phase and r["traj_err_ur"] < traj]
    return min(ok, key=lambda r: r["steps_per_period"]) if ok else None


def _find(rows, **kw):
    return next((r for r in rows if all(r.get(k) == v for k, v in kw.items()) and "amp_err_ur" in r), None)


def _form(res: dict) -> list[str]:
    """The circuit form and why, with the numbers measured below."""
    pin = {(r["prewarp"], r["reltol"], r["trtol"]): r for r in res.get("pinning", {}).get("rows", [])}
    dmp = {(r.get("method"), r["steps_per_period"]): r for r in res.get("damping", {}).get("rows", [])}
    out = ["## Circuit form", "",
           "Mobility analogy, two nodes per oscillator: velocity node with C = m, conductance c_local and a VCCS "
           "k_local*V(x) to ground, drives as B current sources; displacement node = 1 F capacitor fed by a VCCS "
           "V(v); each coupling spring one VCCS k*(V(x_i)-V(x_j)) between v_i and v_j, each dashpot one "
           "conductance between v_i and v_j; quadratic couplings B sources in V(x). With method=trap every "
           "capacitor of an oscillating DOF is scaled by w = (omega h/2)/tan(omega h/2) (prewarp) and the step "
           "is pinned at h (trtol 1e4)."]
    a, b = pin.get((True, 1e-3, 1e4)), pin.get((False, 1e-3, 7.0))
    if a and b:
        out.append(f"- Linear 3-DOF chain with negative local k and c, T/40: phasor error {a['rel_err']:.1e} with "
                   f"prewarp, {b['rel_err']:.1e} without.")
    c = pin.get((True, 1e-6, 7.0))
    if c:
        out.append(f"- Without the pinned step (trtol 7, reltol 1e-6) only {c['uniform_fraction']:.0%} of the steps "
                   f"stay at h and the error is {c['rel_err']:.1e}.")
    p40, t40, g40 = dmp.get(("trap+prewarp", 40)), dmp.get(("trap", 40)), dmp.get(("gear", 40))
    if p40 and t40 and g40:
        out.append(f"- Lone Q=200 oscillator at T/40: free-oscillation frequency error {p40['freq_err_ppm']:.1f} ppm "
                   f"(prewarp; exact -3.1 ppm), {t40['freq_err_ppm']:.0f} ppm (plain trap), gear Q "
                   f"{g40['q_fit']:.0f} instead of 200. The prewarp's cost: envelope time scales stretched by "
                   f"omega h / sin(omega h) (fitted Q {p40['q_fit']:.1f} at T/40), visible as trajectory error.")
    return out + [""]


def _adder_recheck(res: dict) -> list[str]:
    """The recommended defaults rechecked on the adder, with its settling numbers."""
    dd = res.get("accuracy", {}).get("adder2")
    if not dd:
        return []
    d = res["default_options"]
    rows = dd["rows"]
    ng = _find(rows, backend="ngspice", method="trap+prewarp", reltol=d["reltol"],
               steps_per_period=round(1 / d["max_step_periods"]))
    rk = _find(rows, backend="rk4", steps_per_period=80)
    okp = _first_ok(rows, "ngspice", "trap+prewarp", d["reltol"])
    okr = _first_ok(rows, "rk4")
    st = dd.get("settle_period", {})
    out = ["", f"**Rechecked on the 2-bit adder** (`verilog/adder2.v`: {dd.get('oscillators', '?')} oscillators, "
           f"logic depth {dd.get('logic_depth', '?')}; cases {'; '.join(dd.get('case_labels', [])) or dd['cases']}; "
           f"probes {', '.join(dd['probes'])}; {dd['periods']} periods, `simulation.period_budget` "
           f"{dd.get('period_budget', '?')}; {MACHINE}). "
           f"In the RK4 reference every output is within 0.01 u_R of its settled value after period "
           f"{st.get('0.01', '?')} and within 0.001 u_R after period {st.get('0.001', '?')}, so the last "
           f"{res['avg']} periods are settled with a margin of {dd['periods'] - int(st.get('0.001', 0))} periods. "
           f"Sweep: {dd.get('wall_s', 0) / 60:.1f} min of wall time, "
           f"{sum(r.get('cpu_s', 0) for r in rows) / 60:.1f} min of CPU time (ngspice two processes at a time)."]
    if ng:
        good = ng["amp_err_ur"] < 0.01 and ng["phase_err_deg"] < 2
        out.append(f"- ngspice defaults (trap+prewarp, T/{ng['steps_per_period']}, reltol {d['reltol']:g}): "
                   f"{ng['amp_err_ur']:.4f} u_R / {ng['phase_err_deg']:.2f} deg settled, trajectory "
                   f"{ng['traj_err_ur']:.4f} u_R, {_t(ng)} for {dd['cases']} case(s): "
                   + ("within" if good else "NOT within") + " 0.01 u_R and 2 deg; the defaults "
                   + ("hold" if good else "do not hold") + " on the adder.")
    if okp:
        out.append(f"- coarsest trap+prewarp step within the criterion on the adder: T/{okp['steps_per_period']} "
                   f"({_t(okp)}, trajectory {okp['traj_err_ur']:.4f} u_R)"
                   + (f"; at the default T/{ng['steps_per_period']} the trajectory error is {ng['traj_err_ur']:.4f} "
                      "u_R" if ng else "") + ".")
    for method in ("trap", "gear"):
        sel = [r for r in rows if r.get("method") == method and "amp_err_ur" in r]
        if sel and ng:
            key = "cpu_s" if all("cpu_s" in r for r in sel + [ng]) else "wall_s"
            fails = all(r["amp_err_ur"] >= 0.01 or r["phase_err_deg"] >= 2 for r in sel)
            out.append(f"- ngspice {'plain trap (no prewarp)' if method == 'trap' else 'gear'} (reltol "
                       f"{sel[0]['reltol']:g}) on the adder" + (" misses at every step measured" if fails else "")
                       + ": " + "; ".join(
                           f"T/{r['steps_per_period']} {r['amp_err_ur']:.3f} u_R / {r['phase_err_deg']:.1f} deg at "
                           f"{r[key] / ng[key]:.1f}x the default's {'CPU' if key == 'cpu_s' else 'wall'} time, "
                           f"{r.get('uniform_fraction', 0):.0%} of steps at the max step" for r in sel)
                       + " (its truncation-error control, not the max step, sets the step).")
    if okr:
        out.append(f"- RK4: coarsest step within the criterion T/{okr['steps_per_period']} ({_t(okr)}, "
                   f"{okr['amp_err_ur']:.4f} u_R)" + (f"; the default T/80 {_t(rk)}, {rk['amp_err_ur']:.5f} "
                                                      f"u_R" if rk else "") + ".")
    return out


def _forms_section(res: dict) -> list[str]:
    fm = res.get("forms")
    if not fm:
        return []
    first = next(iter(fm.values()))
    o = first["options"]
    out = ["## Analogy form, measured", "",
           "The package's form against two alternatives emitted by the report module itself (`emit_impedance`, "
           "`emit_inductor_springs`): the impedance (force-voltage) analogy - per DOF a series loop, 0 V "
           "ammeter, force sources, L = m, R = c_total, C = 1/k_total, loop current = velocity, couplings as "
           "controlled voltage sources (VCVS from the other loop's capacitor for springs, CCVS from its ammeter "
           "for dashpots), quadratic forces and drives as B voltage sources - and the mobility analogy with "
           "textbook springs, inductors L = 1/k (local to ground, coupling ones between velocity nodes), with a "
           "displacement node only where a quadratic coupling or a probe reads u. Same `.options`/`.tran` for all "
           f"three (method {o['method']}, max step T/{round(1 / o['max_step_periods'])} pinned by trtol 1e4, reltol "
           f"{o['reltol']:g}, vntol {o['vntol']:g}), every reactive element of an oscillating DOF prewarped (C -> wC, "
           "L -> wL), `.options acct` added to read ngspice's circuit-equation count. Each form ran "
           f"{first['repeat']} times; the run with the least CPU time is shown (CPU time of the ngspice processes "
           "plus raw-file reading; wall = the sum over cases of the processes' own wall times, all runs listed); "
           f"errors against RK4 at {res['settings']['ref_steps']} steps/period as in the accuracy tables; {MACHINE}.", "",
           "| design | form | circuit equations | CPU [s] (runs) | CPU / package form | wall [s] (runs) | amp err [u_R] "
           "| phase err [deg] | trajectory err [u_R] | steps at max |", "|---|---|---|---|---|---|---|---|---|---|"]
    verdict = []
    for name, dd in fm.items():
        base = next((r for r in dd["rows"] if "package" in r["form"] and "cpu_s" in r), None)
        for r in dd["rows"]:
            if "amp_err_ur" not in r:
                out.append(f"| {name} ({dd['cases']} case(s), {dd['periods']} T) | {r['form']} | | failed: "
                           f"{r.get('failed', '')[:80]} | | | | | | |")
                continue
            cpus = ", ".join(f"{x:.2f}" for x in r.get("cpus", []))
            walls = ", ".join(f"{x:.2f}" for x in r.get("walls", []))
            rel = f"{r['cpu_s'] / base['cpu_s']:.2f}" if base else "-"
            out.append(f"| {name} ({dd['cases']} case(s), {dd['periods']} T) | {r['form']} | {r.get('equations', '-')} | "
                       f"{r['cpu_s']:.2f} ({cpus}) | {rel} | {r['wall_s']:.2f} ({walls}) | {r['amp_err_ur']:.4f} | "
                       f"{r['phase_err_deg']:.2f} | {r['traj_err_ur']:.4f} | {r['uniform_fraction']:.0%} |")
        if base:
            others = [r for r in dd["rows"] if r is not base and "cpu_s" in r]
            verdict.append(f"{name}: " + ", ".join(f"{r['form']} {r['cpu_s'] / base['cpu_s']:.2f}x" for r in others))
    out += ["", "CPU time relative to the package's form - " + "; ".join(verdict) + ". The choice these numbers "
            "support is stated in `spice.md` (\"Why this form (measured)\").", ""]
    return out


def render(res: dict) -> str:
    """The text of speed_accuracy.md from `res`, without the envelope-spice section."""
    acc, dmp, sc, pin = res.get("accuracy", {}), res.get("damping", {}), res.get("scaling", {}), res.get("pinning", {})
    d = res["default_options"]
    conv = [r["amp_err_ur"] for dd in acc.values() for r in dd["rows"]
            if r["backend"] == "rk4" and r["steps_per_period"] == 80 and "amp_err_ur" in r]
    sect = res.get("section_wall_s", {})
    loads = res.get("section_load_avg", {})
    later = [f"{k} {v / 60:.1f} min" + (f" (1-min load average {loads[k][0]:.1f} at the start, {loads[k][1]:.1f} at the "
                                         "end: other jobs shared the 2 cores, so compare CPU times there)"
                                         if k in loads else "") for k, v in sect.items()]
    L = ["# Speed vs accuracy: RK4 and ngspice backends", "",
         f"All numbers measured by `mech2spice report speed_accuracy` on the **{MACHINE}** (Python {res['python']}, "
         f"ngspice 39, no KLU), total script time {res.get('total_wall_s', 0) / 60:.1f} min"
         + (f"; sections run on their own since (`--only ...`): {', '.join(later)}" if later else "") + ". "
         f"Amplitudes in u_R = {P.u_r}; errors against RK4 at {res['settings']['ref_steps']} steps/period"
         + (f" (converged: RK4 at 80 differs from it by at most {max(conv):.4f} u_R on the designs below)" if conv else "")
         + ". ngspice wall times are one-core times (sum over cases of each process's wall time).", ""]
    if res.get("note"):
        L += [f"Provenance: {res['note']}", ""]
    L += _form(res) + _forms_section(res) + [
        f"RK4 runs the project's {res.get('rk4_kernel', 'numpy')} kernel; ngspice runs as a subprocess "
        "(`ngspice -b -n -r`), time = the subprocess plus reading its raw file (netlist emission, a few ms, "
        "is outside it).", ""]
    L += ["## Recommended defaults", "",
          f"`SpiceOptions(method=\"{d['method']}\", max_step_periods=1/{round(1 / d['max_step_periods'])}, "
          f"reltol={d['reltol']:g}, abstol={d['abstol']:g}, chgtol={d['chgtol']:g}, vntol={d['vntol']:g}, "
          f"prewarp=True, trtol=auto (1e4 with prewarp))`.", ""]
    for name, dd in acc.items():
        rows = dd["rows"]
        r40 = _find(rows, backend="rk4", steps_per_period=40)
        ng = _find(rows, backend="ngspice", method="trap+prewarp", reltol=d["reltol"],
                   steps_per_period=round(1 / d["max_step_periods"]))
        if r40 and ng:
            key = "cpu_s" if "cpu_s" in r40 and "cpu_s" in ng else "wall_s"
            L.append(f"- {name}: ngspice at its defaults took {ng[key] / r40[key]:.0f}x the "
                     f"{'CPU' if key == 'cpu_s' else 'wall'} time of RK4 at "
                     f"T/40 ({res.get('rk4_kernel', 'numpy')} kernel): ngspice is the independent check and the "
                     "exportable netlist, not the fast path.")
            L.append(f"- {name}, {dd['periods']} periods, {MACHINE}: ngspice defaults {_t(ng)}, "
                     f"error {ng['amp_err_ur']:.4f} u_R / {ng['phase_err_deg']:.2f} deg (trajectory "
                     f"{ng['traj_err_ur']:.4f} u_R); RK4 at T/40 {_t(r40)}, error {r40['amp_err_ur']:.4f} "
                     f"u_R / {r40['phase_err_deg']:.2f} deg (trajectory {r40['traj_err_ur']:.4f} u_R).")
    L += _adder_recheck(res)
    L += ["", "## Failure points", "",
          "Criterion: settled amplitude within 0.01 u_R and phase within 2 deg of the reference (the issue's), "
          "optionally also the whole trajectory within 0.01 u_R. 'Misses' lists every measured step that fails "
          f"the settled criterion, with its error; {MACHINE}.", ""]
    for name, dd in acc.items():
        rows = dd["rows"]
        for label, backend, method in (("RK4", "rk4", None), ("ngspice trap+prewarp", "ngspice", "trap+prewarp"),
                                       ("ngspice trap (no prewarp)", "ngspice", "trap"),
                                       ("ngspice gear", "ngspice", "gear")):
            reltol = None if backend == "rk4" else d["reltol"] if method == "trap+prewarp" else \
                (1e-3 if any(r.get("reltol") == 1e-3 for r in rows) else d["reltol"])
            cell = []
            for what, traj in (("settled", math.inf), ("settled and whole trajectory", 0.01)):
                ok = _first_ok(rows, backend, method, reltol, traj=traj)
                cell.append(f"{what}: " + (f"T/{ok['steps_per_period']} ({_t(ok)}, {ok['amp_err_ur']:.4f} u_R, "
                                           f"{ok['phase_err_deg']:.2f} deg, trajectory {ok['traj_err_ur']:.4f} u_R)"
                                           if ok else "none of the steps measured"))
            miss = [r for r in rows if r["backend"] == backend and r.get("method") == method
                    and not r.get("reference") and (reltol is None or r.get("reltol") == reltol)
                    and ("amp_err_ur" not in r or r["amp_err_ur"] >= 0.01 or r["phase_err_deg"] >= 2.0)]
            cell.append("misses: " + (", ".join(
                f"T/{r['steps_per_period']} ({r['amp_err_ur']:.4f} u_R, {r['phase_err_deg']:.2f} deg)"
                if "amp_err_ur" in r else f"T/{r['steps_per_period']} (failed)" for r in miss) or "none"))
            L.append(f"- {name}, {label}" + (f" (reltol {reltol:g})" if reltol else "")
                     + " - coarsest step within 0.01 u_R and 2 deg, " + "; ".join(cell))
    L += ["", "## Stability limits", ""]
    st = res.get("stability", {})
    for name, dd in st.items():
        div = [r for r in dd["rows"] if "failed" in r]
        rk = [r for r in dd["rows"] if r["backend"] == "rk4" and "amp_err_ur" in r]
        L.append(f"- {name}, RK4 at 4..9 steps/period ({dd['periods']} periods): "
                 + (f"diverged at {', '.join(str(r['steps_per_period']) for r in div)}" if div else
                    "no divergence; the error instead grows to " + ", ".join(
                        f"{r['amp_err_ur']:.2f} u_R at T/{r['steps_per_period']}" for r in rk[:3]))
                 + f"; 3 steps/period: {dd['rk4_3_steps']}")
        ngc = [r for r in dd["rows"] if r["backend"] == "ngspice"]
        L.append(f"- {name}, ngspice at T/4..T/8 (600 periods, step pinned by trtol 1e4): " + "; ".join(
            f"{r['method']} T/{r['steps_per_period']}: " + (f"{r['amp_err_ur']:.3f} u_R, {r['phase_err_deg']:.1f} deg"
                                                            if "amp_err_ur" in r else f"failed ({r['failed'][:60]})")
            for r in ngc))
    tol = res.get("tolerances", {})
    if tol:
        L += ["", "## Newton tolerances at the default step", "",
              f"Settled and trajectory errors against RK4 at {res['settings']['ref_steps']} steps/period; trap+prewarp at "
              f"T/{round(1 / d['max_step_periods'])}; the accuracy tables hold vntol 1e-9 at reltol 1e-3 and 1e-5; "
              f"{MACHINE}.", "",
              "| design | backend | step | reltol | vntol | wall [s] | amp err [u_R] | phase err [deg] | trajectory err [u_R] |",
              "|---|---|---|---|---|---|---|---|---|"]
        for name, dd in tol.items():
            rows = dd["rows"] + [r | {"vntol": d["vntol"]} for r in acc.get(name, {}).get("rows", [])
                                 if r.get("method") == "trap+prewarp" and "amp_err_ur" in r
                                 and r["steps_per_period"] == round(1 / d["max_step_periods"])]
            for r in sorted(rows, key=lambda r: (r["vntol"], -r["reltol"])):
                if "amp_err_ur" in r:
                    L.append(f"| {name} | ngspice trap+prewarp | T/{r['steps_per_period']} | {r['reltol']:g} | "
                             f"{r['vntol']:g} | {r['wall_s']:.2f} | {r['amp_err_ur']:.4f} | {r['phase_err_deg']:.2f} | "
                             f"{r['traj_err_ur']:.4f} |")
    if pin:
        L += ["", "## Prewarp needs every step at max_step", "",
              f"{pin['model']}; error = max |A - A_exact| / max |A_exact| of the steady phasors; {MACHINE}.", "",
              "| backend | prewarp | reltol | trtol | rel. error | steps at max step |", "|---|---|---|---|---|---|"]
        for r in pin["rows"]:
            L.append(f"| ngspice trap T/40 | {r['prewarp']} | {r['reltol']:g} | {r['trtol']:g} | {r['rel_err']:.2e} | "
                     f"{r['uniform_fraction']:.0%} |")
    if dmp:
        L += ["", "## Numerical damping and phase drift (lone oscillator)", "",
              f"One oscillator (m = 1, resonant at the drive, Q = {dmp['q_true']:g}) driven for "
              f"{dmp['driven_periods']} periods, then released; fit over periods {dmp['fit_periods'][0]}-"
              f"{dmp['fit_periods'][1]} of |A| (Q) and of the phase against the drive clock (frequency error); "
              f"ngspice at the default reltol {d['reltol']:g} with every step pinned at the max step (trtol 1e4); "
              f"{MACHINE}.", "",
              "| design | backend | step | fitted Q | Q error | free-oscillation freq. error [ppm] | phase drift [deg / 100 T] |",
              "|---|---|---|---|---|---|---|"]
        exact = -1e6 * (1 - math.sqrt(1 - 1 / (4 * dmp["q_true"] ** 2)))
        L.append(f"| lone Q=200 oscillator | exact (omega_d = omega sqrt(1 - 1/4Q^2)) | - | {dmp['q_true']:.1f} | 0 | "
                 f"{exact:.1f} | {np.degrees(2 * math.pi * exact * 1e-6) * 100:.2f} |")
        for r in dmp["rows"]:
            L.append(f"| lone Q=200 oscillator | {_row_label(r)} | T/{r['steps_per_period']} | {r['q_fit']:.1f} | "
                     f"{r['q_fit'] / dmp['q_true'] - 1:+.1%} | {r['freq_err_ppm']:.1f} | {r['phase_drift_deg_per_100T']:.2f} |")
    if sc:
        L += ["", "## Scaling", "",
              f"Independent NOR gates (6 oscillators each, inputs '0'), {sc['periods']} periods; RK4 at "
              f"{sc['rk4_steps_per_period']} steps/period ({res.get('rk4_kernel', 'numpy')} kernel), ngspice with "
              f"the default options "
              f"(emission + run + read); {MACHINE}.", "",
              "| design | oscillators | RK4 [s] | ngspice [s] | ngspice / RK4 | max |A| difference [u_R] |", "|---|---|---|---|---|---|"]
        for r in sc["rows"]:
            L.append(f"| {r['gates']} independent NOR gates | {r['oscillators']} | {r['rk4_s']:.2f} | "
                     f"{r['ngspice_s']:.2f} | {r['ngspice_s'] / r['rk4_s']:.2f} | {r['max_diff_ur']:.4f} |")
    L += ["", "## Accuracy tables", ""]
    for name, dd in acc.items():
        L += _acc_table(name, dd, res['settings']['ref_steps'])
    L += ["## Charts", ""] + [f"![{c}]({c})" for c in res.get("charts", [])] + [""]
    return "\n".join(L)


def markdown(res: dict) -> str:
    """The report's markdown from `res` (see render)."""
    return render(res)


def write_markdown(path: Path, res: dict | None, envelope_block: str = "", vacask_block: str = "",
                   carrier_block: str = "") -> str:
    """Write the .md: this report from `res`, then the envelope-spice section (`envelope_spice.block`), the
    VACASK section (`vacask.block`, from vacask.json) and the carrier engine's (`carrier.block`, from
    carrier.json); nothing of the old file is kept."""
    parts = [markdown(res).rstrip("\n")] if res else []
    for extra in (envelope_block, vacask_block, carrier_block):
        if extra:
            parts.append(extra.rstrip("\n"))
    text = "\n\n".join(parts) + "\n"
    Path(path).write_text(text)
    return text


def write(directory="reports", only=None, design=None, quick: bool = False, render: bool = False) -> Path:
    """Measure the sections in `only` (default: all, envelope_spice included; `quick`: fewer points;
    `design`: the accuracy section for these designs only; `render`: nothing measured), merge them into
    speed_accuracy.json / envelope_spice.json and write speed_accuracy.md and its charts."""
    out = out_dir(directory)
    jpath, mpath = out / "speed_accuracy.json", out / "speed_accuracy.md"
    if not render:
        from ..studies import speed_accuracy as study      # measuring loads the engines; rendering does not
        study.measure_sections(out, only, design, quick)
    envelope_spice.redraw(out)
    res = read_json(jpath)
    if res is not None:
        res["charts"] = charts(res, out)
        write_json(jpath, res, default=None)
    write_markdown(mpath, res, envelope_spice.block(out), vacask.block(out), carrier_report.block(out))
    return mpath
