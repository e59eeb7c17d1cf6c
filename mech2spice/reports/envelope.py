"""reports/envelope.md and envelope_*.png: where the envelope model agrees with RK4, why it differs, the step
bound; rendered from envelope.json in the report directory (mech2spice/studies/envelope.py measures it).

usage: mech2spice report envelope [--quick] [--cache DIR] [--render]
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..errors import Mech2SpiceError
from ..physics.params import DEFAULT
from ._common import measured_on, non_finite, out_dir, pyplot, save_figure, shade_bands, stored, write_json

plt = pyplot()
P = DEFAULT
# validate.compare's errors: +inf where they are undefined (a run crossed the threshold where the other did not,
# so crossing_count_mismatch > 0; or it diverged), null in the JSON
ERRORS = ("amp_err", "time_err", "traj_err", "first_rel", "last_rel", "max_abs_diff")


def write(directory="reports", quick: bool = False, cache=None, render: bool = False) -> Path:
    """Measure every scene into envelope.json (unless `render`; RK4 runs kept in `cache` if given) and write
    envelope.md and its figures from it."""
    out = out_dir(directory)
    if not render:
        from ..studies import envelope as study        # measuring loads the engines; rendering does not
        write_json(out / "envelope.json", study.measure(quick=quick, cache=cache))
    path = out / "envelope.json"
    try:
        return render_report(loaded(stored(path, "envelope")), out)
    except (KeyError, IndexError, TypeError, ValueError, AttributeError) as err:   # JSON is anyone's file
        raise Mech2SpiceError(f"{path} lacks what `report envelope` renders ({type(err).__name__}: "
                              f"{str(err)[:120]})") from None


def render_report(d: dict, out: Path) -> Path:
    """envelope.md and its figures from the loaded JSON."""
    by = {r["scene"]: r for r in d["scenes"]}
    tr = d["traces"]
    fig_chain(tr["chain3"], d["settings"], out / "envelope_chain.png")
    fig_adder(tr["adder2"], by["adder2"]["periods"] // 2, d["settings"], out / "envelope_adder.png")
    fig_latch(tr["latch"], out / "envelope_latch.png")
    fig_sweep(d["sweep"], d["settings"], out / "envelope_step_sweep.png")
    (out / "envelope.md").write_text(report(d, by))
    return out / "envelope.md"


def loaded(d: dict) -> dict:
    """The JSON with what JSON cannot key or hold put back: envelope steps (float) and periods (int) as keys,
    traces as arrays, the worst state's eigenvalues as complex numbers, an undefined error (null) as inf."""
    non_finite(d, ERRORS, math.inf)
    for r in d["scenes"]:
        r["env"] = {float(k): v for k, v in r["env"].items()}
    sw = d["sweep"]
    sw["two_omega"] = {int(k): v for k, v in sw["two_omega"].items()}
    sw["eigs_worst"] = np.asarray(sw["eigs_worst"]["re"]) + 1j * np.asarray(sw["eigs_worst"]["im"])
    for runs in d["traces"].values():
        for run in [v for v in runs.values() if isinstance(v, dict) and "amp" in v] + list(runs.get("sequence", {}).values()):
            run["t"], run["amp"] = np.asarray(run["t"], float), np.asarray(run["amp"], float)
    return d


def rk4_growth(z):
    """|R(z)| of classic RK4 (its amplification per step of h lambda = z): the stability region is |R| <= 1."""
    return np.abs(1 + z + z ** 2 / 2 + z ** 3 / 6 + z ** 4 / 24)


# --- figures ---------------------------------------------------------------------------------------
def _bands(ax, off=0.0):
    shade_bands(ax, off, alpha=0.08)


def fig_chain(tr: dict, st: dict, path: Path) -> None:
    """The chain's 00 -> 10 -> 00 transient and its (0.67, 0.67) band-edge member: RK4 vs envelope."""
    sc_name, E = "chain3", st["default_step"]
    r, e, r160 = tr["rk4_80"], tr["envelope"], tr["rk4_160"]
    fig, axs = plt.subplots(1, 2, figsize=(13, 4.2))
    for j, col in enumerate(["tab:blue", "tab:orange", "tab:green"]):
        axs[0].plot(r["t"], r["amp"][:, j, 0], color=col, lw=1.2, label=f"g{j} RK4 80/T")
        axs[0].plot(e["t"], e["amp"][:, j, 0], color="k", lw=0.8, ls="--")
    axs[0].plot([], [], "k--", lw=0.8, label=f"envelope, step {E:g} T")
    _bands(axs[0])
    axs[0].axhline(st["mid"], color="grey", lw=0.5, ls=":")
    axs[0].set(xlabel="drive periods", ylabel="|A| [u_R]", title=f"{sc_name}: inputs 00 -> 10 -> 00 (member 0)")
    axs[0].legend(fontsize=8)
    b = 1                  # the traces' second member, 3 of the scene: (0.67, 0.67), the slowest, most marginal switch
    for j, col in enumerate(["tab:blue", "tab:orange", "tab:green"]):
        axs[1].plot(r["t"], r["amp"][:, j, b], color=col, lw=1.2, label=f"g{j} RK4 80/T")
        axs[1].plot(r160["t"], r160["amp"][:, j, b], color=col, lw=0.8, ls=":", label=f"g{j} RK4 160/T")
        axs[1].plot(e["t"], e["amp"][:, j, b], color="k", lw=0.8, ls="--")
    _bands(axs[1])
    axs[1].axhline(st["mid"], color="grey", lw=0.5, ls=":")
    axs[1].set(xlim=(0, 3000), xlabel="drive periods",
               title="band-edge member: inputs held at (0.67, 0.67) F_R; dashed = envelope")
    axs[1].legend(fontsize=7, ncol=2)
    save_figure(fig, path, dpi=100)


def fig_adder(tr: dict, hold: int, st: dict, path: Path) -> None:
    """The adder's three sum amplitudes for all 16 inputs: RK4 at 80 steps/period vs the envelope."""
    r, e = tr["rk4_80"], tr["envelope"]
    fig, axs = plt.subplots(4, 4, figsize=(13, 9), sharex=True, sharey=True)
    for b in range(16):
        ax = axs[b // 4, b % 4]
        for k in range(3):
            off = 2.4 * (2 - k)
            _bands(ax, off)
            ax.plot(r["t"] - hold, off + r["amp"][:, k, b], lw=1.1, color=f"C{k}")
            ax.plot(e["t"] - hold, off + e["amp"][:, k, b], lw=0.7, color="k", ls="--")
        ax.set_xlim(-100, 1600)
        ax.set_title(f"a={b // 4} b={b % 4}", fontsize=9)
        ax.set_yticks([])
    for ax in axs[-1]:
        ax.set_xlabel("periods after the inputs change")
    fig.suptitle(f"2-bit adder: |s[0]| (top), |s[1]|, |s[2]| [u_R]; RK4 80 steps/period (colour) vs envelope "
                 f"step {st['default_step']:g} periods (black dashed)")
    save_figure(fig, path, dpi=90)


def fig_latch(tr: dict, path: Path) -> None:
    """The latch pulse sequence on RK4 and on the envelope, and their difference."""
    r, e = tr["rk4_80"], tr["envelope_1"]
    ra, ea = tr["sequence"]["rk4"]["amp"], tr["sequence"]["env"]["amp"]
    fig, axs = plt.subplots(2, 1, figsize=(13, 6), sharex=True)
    t = tr["sequence"]["rk4"]["t"]
    axs[0].plot(t, ra[:, 0], lw=1.2, label="q[0] RK4 80/T (latch_sequence)")
    axs[0].plot(t, ea[:, 0], "k--", lw=0.8, label="q[0] envelope, step 1/2 T (latch_sequence)")
    axs[0].plot(t, ra[:, 1], lw=1.0, color="tab:green", label="q0.m (loop node) RK4")
    axs[0].plot(t, ea[:, 1], ls="--", color="tab:olive", lw=0.8, label="q0.m envelope")
    _bands(axs[0])
    for s in tr["starts"]:
        axs[0].axvline(s, color="grey", lw=0.4)
    axs[0].set(ylabel="|A| [u_R]", title="latch pulse sequence (verilog/dff.v)")
    axs[0].legend(fontsize=8, ncol=2)
    axs[1].plot(t, ea[:, 0] - ra[:, 0], lw=0.8, label="envelope (1/2 T) - RK4 80, q[0]")
    axs[1].plot(e["t"], e["amp"][:, 0, 0] - np.interp(e["t"], r["t"], r["amp"][:, 0, 0]), lw=0.6,
                label="envelope (1 T) - RK4 80, q[0]")
    axs[1].set(xlabel="drive periods", ylabel="difference [u_R]")
    axs[1].legend(fontsize=8)
    save_figure(fig, path, dpi=90)


def fig_sweep(sw: dict, st: dict, path: Path) -> None:
    """The adder's error against envelope step and wall time; the RK4 stability region and the eigenvalues."""
    fig, axs = plt.subplots(1, 3, figsize=(15, 4.2))
    rows = [r for r in sw["sweep"]]
    free = [r for r in sw["free"] if r["finite"]]
    ax = axs[0]
    ax.semilogy([r["step"] for r in rows], [100 * r["vs80"]["time_err"] for r in rows], "o-", label="switching-time error [%]")
    ax.semilogy([r["step"] for r in rows], [r["vs80"]["traj_err"] for r in rows], "s-", label="max trajectory diff [u_R]")
    ax.semilogy([r["step"] for r in rows], [r["vs80"]["amp_err"] for r in rows], "^-", label="settled amp diff [u_R]")
    ax.semilogy([r["step"] for r in free], [100 * r["vs80"]["time_err"] for r in free], "o:", color="C0", alpha=0.5)
    ax.semilogy([r["step"] for r in free], [r["vs80"]["traj_err"] for r in free], "s:", color="C1", alpha=0.5)
    ax.semilogy([r["step"] for r in free], [r["vs80"]["amp_err"] for r in free], "^:", color="C2", alpha=0.5)
    ax.axvline(sw["bound"], color="r", lw=1, label=f"enforced bound {sw['bound']:.2f} T")
    blow = min((r["step"] for r in sw["free"] if not r["finite"]), default=None)
    lin = min(s["rk4_stable_step_periods"] for s in sw["stability"])
    ax.axvline(lin, color="purple", ls="--", lw=1, label=f"linearised onset {lin:.1f} T")
    if blow:
        ax.axvline(blow, color="k", ls=":", lw=1, label=f"first blow-up {blow:g} T")
    ax.set(xlabel="envelope step [periods]", title="adder (16 inputs) vs RK4 80/T; dotted: no bound check")
    ax.legend(fontsize=7)
    ax = axs[1]
    ax.loglog([r["wall_s"] for r in rows], [100 * r["vs80"]["time_err"] for r in rows], "o-", label="time error [%]")
    ax.loglog([r["wall_s"] for r in rows], [r["vs80"]["traj_err"] for r in rows], "s-", label="trajectory [u_R]")
    for r in rows:
        ax.annotate(f"{r['step']:g} T", (r["wall_s"], r["vs80"]["traj_err"]), fontsize=7)
    ax.set(xlabel="wall time [s] (5800 periods x 16 inputs)", title="error vs wall time (envelope.integrate)")
    ax.legend(fontsize=7)
    ax = axs[2]
    x, y = np.meshgrid(np.linspace(-3.5, 1, 400), np.linspace(-3.5, 3.5, 400))
    ax.contour(x, y, rk4_growth(x + 1j * y), levels=[1.0], colors="k")
    T = sw["T"]
    ev = sw["eigs_worst"]
    for h, c in ((sw["bound"], "r"), (lin, "purple")):
        z = ev * h * T
        ax.plot(z.real, z.imag, ".", ms=3, color=c, label=f"h lambda, h = {h:.1f} T")
    ax.set(xlabel="Re(h lambda)", ylabel="Im(h lambda)", title="RK4 stability region, adder eigenvalues")
    ax.set_aspect("equal")
    ax.legend(fontsize=7)
    save_figure(fig, path, dpi=90)


# --- report ------------------------------------------------------------------------------------------
def fmt_pct(x: float) -> str:
    """A fraction as a percentage ('-' for None, 'inf' if not finite)."""
    return "-" if x is None else ("inf" if not math.isfinite(x) else f"{100 * x:.2f} %")


def scene_rows(results: list[dict]) -> str:
    """Markdown rows: each scene at each envelope step against RK4 80 and 160, pass or FAIL."""
    out = []
    for r in results:
        for st, e in r["env"].items():
            c80, c160 = e["vs80"], e["vs160"]
            ok = c80["amp_ok"] and c80["time_ok"] and c80["crossing_count_mismatch"] == 0
            out.append(f"| {r['scene']} | {r['oscillators']} x {r['batch']} | {r['periods']} | {st:g} T | "
                       f"{c80['amp_err']:.1e} | {fmt_pct(c80['time_err'])} | {c80['n_crossings']} "
                       f"({c80['crossing_count_mismatch']}) | {c80['traj_err']:.3f} | {c160['amp_err']:.1e} | "
                       f"{fmt_pct(c160['time_err'])} | {r['rk4_80_vs_160']['amp_err']:.1e} | "
                       f"{fmt_pct(r['rk4_80_vs_160']['time_err'])} | {e['wall_s']:.1f} / {r['wall_rk4_80']:.1f} | "
                       f"{'**pass**' if ok else 'FAIL'} |")
    return "\n".join(out)


def worst_crossings(r: dict, step: float, k: int = 3) -> str:
    """Markdown rows: the k threshold crossings of a scene with the largest relative time error at `step`."""
    c = r["env"][step]["vs80"]["crossings"]
    c160 = {(x["event"], x["probe"], x["member"]): x for x in r["env"][step]["vs160"]["crossings"]}
    rows = sorted(c, key=lambda x: -max(x["first_rel"], x["last_rel"]))[:k]
    out = []
    for x in rows:
        y = c160.get((x["event"], x["probe"], x["member"]), {})
        out.append(f"| {r['scene']} | {x['member']} | {x['probe']} | {x['event']} | {x['first_ref']:.1f} / "
                   f"{x['last_ref']:.1f} | {y.get('first_ref', float('nan')):.1f} / {y.get('last_ref', float('nan')):.1f} | "
                   f"{x['first_test']:.1f} / {x['last_test']:.1f} | {fmt_pct(max(x['first_rel'], x['last_rel']))} | "
                   f"{fmt_pct(max(y.get('first_rel', math.nan), y.get('last_rel', math.nan)))} |")
    return "\n".join(out)


def variant_rows(results: list[dict]) -> str:
    """Markdown rows: each variant of the envelope equations on each scene against RK4 160 and 80."""
    out = []
    for r in results:
        for name, v in r["variants"].items():
            c = v["vs160"]
            out.append(f"| {r['scene']} | {name} | {v['step']:g} T | {c['amp_err']:.1e} | {fmt_pct(c['time_err'])} | "
                       f"{c['traj_err']:.4f} | {v['vs80']['amp_err']:.1e} | {fmt_pct(v['vs80']['time_err'])} |")
    return "\n".join(out)


def report(d: dict, by: dict) -> str:
    """The text of envelope.md."""
    results, latch, sw, total, st = d["scenes"], d["latch"], d["sweep"], d["total_s"], d["settings"]
    E = st["default_step"]
    worst_amp = max(r["env"][E]["vs80"]["amp_err"] for r in results)
    worst_time = max(r["env"][E]["vs80"]["time_err"] for r in results)
    worst_scene = max(results, key=lambda r: r["env"][E]["vs80"]["time_err"])
    mism = sum(r["env"][E]["vs80"]["crossing_count_mismatch"] for r in results)
    ncross = sum(r["env"][E]["vs80"]["n_crossings"] for r in results)
    all_pass = all(r["env"][st]["vs80"]["amp_ok"] and r["env"][st]["vs80"]["time_ok"]
                   and r["env"][st]["vs80"]["crossing_count_mismatch"] == 0 for r in results for st in r["env"])
    chain = by["chain3"]
    marg = [x for x in chain["env"][E]["vs80"]["crossings"] if x["member"] == "0.67,0.67" and x["event"] == 1500
            and x["probe"] == "g1"][0]
    marg160 = [x for x in chain["env"][E]["vs160"]["crossings"] if x["member"] == "0.67,0.67" and x["event"] == 1500
               and x["probe"] == "g1"][0]
    var_rows = variant_rows(results)
    traj_env = max(r["variants"]["envelope"]["vs160"]["traj_err"] for r in results)
    traj_a2 = max(r["variants"]["+A''"]["vs160"]["traj_err"] for r in results)
    traj_both = max(r["variants"]["+2w+A''"]["vs160"]["traj_err"] for r in results)
    time_env = max(r["variants"]["envelope"]["vs160"]["time_err"] for r in results)
    both = {r["scene"]: r["variants"]["+2w+A''"]["vs160"] for r in results}
    time_both = max((v["time_err"] for v in both.values() if not v["crossing_count_mismatch"]), default=0.0)
    uneven = {n: v["crossing_count_mismatch"] for n, v in both.items() if v["crossing_count_mismatch"]}
    uneven_note = "" if not uneven else (
        " where it crosses the threshold as often as RK4-160 (" + ", ".join(
            f"{k} (output, input change, member) case{'s' if k > 1 else ''} on {n}" for n, k in uneven.items())
        + " cross it a different number of times, so no time difference is defined there: the table's 'inf')")
    gn = by["gate_nominal"]
    fo = by["fanout2"]
    rk_self = max(r["rk4_80_vs_160"]["traj_err"] for r in results)
    rk_self_t = max(r["rk4_80_vs_160"]["time_err"] for r in results)
    lin = min(s["rk4_stable_step_periods"] for s in sw["stability"])
    lin_at = min(sw["stability"], key=lambda s: s["rk4_stable_step_periods"])
    rad = max(s["max_abs_eig"] for s in sw["stability"])
    fin = [r for r in sw["free"] if r["finite"]]
    blown = [r for r in sw["free"] if not r["finite"]]
    last_ok = max(r["step"] for r in fin)
    first_bad = min(r["step"] for r in blown) if blown else None
    sweep_rows = "\n".join(
        f"| {r['step']:g} | {r['path']} | {r['wall_s']:.2f} | {r['vs80']['amp_err']:.1e} | {fmt_pct(r['vs80']['time_err'])} | "
        f"{r['vs80']['traj_err']:.3f} | {r['vs80']['crossing_count_mismatch']} | finite |" for r in sw["sweep"])
    sweep_rows += "\n" + "\n".join(
        f"| {r['step']:g} | {r['path']} | {r['wall_s']:.2f} | "
        + (f"{r['vs80']['amp_err']:.1e} | {fmt_pct(r['vs80']['time_err'])} | {r['vs80']['traj_err']:.3f} | "
           f"{r['vs80']['crossing_count_mismatch']} | finite |" if r["finite"] else
           f"- | - | - | - | **blew up** (|A| > 50 u_R at period {r['blowup_period']:.0f}) |") for r in sw["free"])
    refused = "\n".join(f"- step {r['step']:g}: " + (f"refused, `Mech2SpiceError: {r['message']}`" if r["refused"]
                                                    else "**not refused**") for r in sw["refused"])
    stab_rows = "\n".join(f"| {s['period']} | {s['max_abs_eig']:.3f} | {s['rk4_stable_step_periods']:.2f} | "
                          f"{s['max_growth']:+.3f} |" for s in sw["stability"])
    two = sw["two_omega"]
    s_amp = two[5800]["channel_2w_force_max"] / sw["Zs2"]
    lat = latch
    lat_env = by["latch"]
    latch_note = ("" if not lat.get("envelope_error") else
                  f"**`characterise.latch_sequence(p, 'envelope')` failed in this run** (`{lat['envelope_error']}`: "
                  "`network.build` now clears `model.probes` and `latch_sequence` asks for the DOF name 'q0.m.C', "
                  "which `rk4.integrate` resolves through `model.index` but `envelope.integrate` does not). The "
                  "envelope column is therefore the identical model, schedule, step (1/2 period) and decoding run "
                  "through `validate.latch_scene` + `validate.latch_decode`, which reproduce `latch_sequence`'s RK4 "
                  "result exactly.\n\n")
    step_acc = [r for r in sw["sweep"] if r["step"] <= 4]
    step_err_spread = max(r["vs80"]["traj_err"] for r in step_acc) - min(r["vs80"]["traj_err"] for r in step_acc)
    speed = {r["step"]: r["wall_s"] for r in sw["sweep"]}
    a2 = [r["variants"]["+A''"]["wall_s"] / r["variants"]["envelope"]["wall_s"] for r in results]
    a2_lo, a2_hi = min(a2), max(a2)
    lines = f"""# The envelope model against RK4

Generated by `mech2spice report envelope` (scenes and comparisons in `mech2spice/experiments/validate.py`) on
the **{d['machine']}**: {measured_on(d['conditions'])}, {total / 60:.1f} min in all. The machine is shared with
other jobs, so the wall times here are indicative only; `reports/performance.md` measures speed properly.

## Verdict

**Every scene meets both criteria at the default envelope step ({E:g} drive periods, `envelope.DEFAULT_STEP`;
`backends/envelope.default_step` would lower it below a model's stability bound, which does not bind in any scene here),
at 2 periods (the default when this study started) and at 1/2 period**: settled amplitudes within {worst_amp:.1e} u_R of RK4 at 80 steps/period (criterion
{st['amp_tol']} u_R), threshold-crossing times within {100 * worst_time:.2f} % (criterion {100 * st['time_tol']:.0f} %;
worst: {worst_scene['scene']}), the same number of crossings in all {ncross} (output, input change, batch member)
cases that cross the threshold ({mism} mismatches), and the latch sequence decoded identically
({'all pass' if all_pass else 'NOT all pass'}).

- The largest switching-time difference is a band-edge member of the chain (inputs held at 0.67, 0.67 F_R: a
  slow, marginal switch). There RK4 itself is not converged at 80 steps/period: the second gate (g1) crosses at
  {marg['first_ref']:.1f} periods on RK4-80, {marg160['first_ref']:.1f} on RK4-160, {marg['first_test']:.1f} on
  the envelope, i.e. the envelope is {100 * marg160['first_rel']:.1f} % from RK4-160 while RK4-80 is
  {100 * abs(marg['first_ref'] - marg160['first_ref']) / marg160['first_ref']:.1f} % from it.
- Against RK4-160 the largest trajectory difference of the plain envelope anywhere (transients included) is
  {traj_env:.3f} u_R; keeping the M A'' term the envelope equations drop brings it to {traj_a2:.4f} u_R
  (both corrections: {traj_both:.4f}). That term is the main thing the envelope model loses; the 2-omega part of
  u^2 moves settled amplitudes by ~1e-5 to 1e-4 u_R only. Evidence below.
- The enforced step bound (`envelope.max_step_periods`) is {sw['bound']:.2f} periods on the adder (the
  largest |eigenvalue| of the linear part at rest x {sw['rate_safety']}), where the linearised envelope
  equations along the trajectory allow RK4 steps up to {lin:.1f} periods and the measured onset lies between
  {last_ok:g} (finite) and {first_bad:g} periods (blew up): **safe, {lin / sw['bound']:.1f}x below the onset**. The
  Gershgorin bound used before allowed {st['rk4_stability'] / sw['gershgorin_rate'] / sw['T']:.2f} periods
  ({lin * sw['gershgorin_rate'] * sw['T'] / st['rk4_stability']:.1f}x conservative). Accuracy, not stability,
  limits the step: errors are flat up to 4 periods and grow beyond (switching times within 2 % up to 8).

## Scenes

All from rest; RK4 at 80 steps/period is the reference the criteria use, RK4 at 160 shows the reference's own
error. 'time err' = largest relative difference of the first and of the last threshold crossing (the midpoint
between the bands, `scenes.MID` = {st['mid']:.4f} u_R) after each input change, over every output and batch
member that crosses it; 'crossings' counts those cases (in brackets: cases where the two backends cross a
different number of times, i.e. a hazard one of them misses). 'traj' = largest |envelope - RK4| anywhere on the
per-period amplitude trajectory (envelope interpolated to RK4's period midpoints), transients included; it has
no criterion. Settled = mean of the {st['avg']} periods before each input change and before the end.

| scene | oscillators x batch | periods | envelope step | settled diff vs RK4-80 [u_R] | time err vs RK4-80 | crossings (mismatch) | traj vs RK4-80 [u_R] | settled diff vs RK4-160 | time err vs RK4-160 | RK4-80 vs RK4-160 settled | RK4-80 vs RK4-160 time | wall envelope / RK4-80 [s] | criteria |
|---|---|---|---|---|---|---|---|---|---|---|---|---|---|
{scene_rows(results)}

Scenes: gate_nominal = the 4 nominal input pairs; gate_edge = all 16 pairs of band-edge levels (0.365, 0.67,
0.92, 1.025 F_R); chain3 = `characterise.cascade` (member 0: inputs 00 -> 10 -> 00 at 1500-period holds;
members 1-7: band-edge inputs held); fanoutN = `characterise.fanout_test` (driver 00/10, loads' second input
0/1); adder2 = `mech2spice/reports/adder.py` (16 members: inputs 0 for 2900 periods, then (a, b)); latch = the model and
schedule of `characterise.latch_sequence` (its 'settled' windows include the ends of the two 800-period store
pulses, where the output is mid-flight; every other window is settled).

Largest switching-time differences per scene (first / last crossing, periods after the input change):

| scene | member | output | input change at | RK4-80 | RK4-160 | envelope ({E:g} T) | err vs RK4-80 | err vs RK4-160 |
|---|---|---|---|---|---|---|---|---|
""" + "\n".join(worst_crossings(r, E) for r in results) + f"""

![chain](envelope_chain.png)

![adder](envelope_adder.png)

### The latch pulse sequence (`characterise.latch_sequence`, envelope at its default step of 1/2 period)

| | RK4 (80/T) | envelope |
|---|---|---|
| decoded output after each phase | {lat['decoded_rk4']} | {lat['decoded_env']} |
| output delay after the store-1 / store-0 pulse starts [periods] | {lat['delays_rk4']} | {lat['delays_env']} |
| wall time [s] | {lat['wall_rk4']:.1f} | {lat['wall_env']:.1f} |

{latch_note}Decoded identically: **{lat['identical']}**; largest difference of the decoded phase-end amplitudes
{lat['max_output_diff']:.4f} u_R; delays differ by {100 * max(lat['delay_rel']):.2f} % at most; largest
trajectory difference {lat['traj_err']:.4f} u_R. The same schedule at the clocked default step (1 period,
`run_clocked_physical`) and at 2 and {E:g} periods is in the scene table (rows 'latch').

Note the wall times: on this 60-oscillator, single-member model the envelope at 1/2 period is *not* faster
than the compiled RK4 kernel ({lat['wall_env']:.1f} s vs {lat['wall_rk4']:.1f} s): every envelope step costs
four right-hand sides of ~10 sparse/numpy calls each, ~0.1 ms of Python overhead regardless of size, while the
numba kernel pays nothing per step. At {E:g} periods (same accuracy, table) it is {lat_env['env'][E]['wall_s']:.1f} s.

![latch](envelope_latch.png)

## Why they differ: what the averaging drops, measured

`mech2spice/experiments/validate.py` puts back, one at a time, what `envelope.py`'s derivation drops, and runs the same
scenes against RK4-160 (the converged reference; RK4-80 differs from it by up to {rk_self:.3f} u_R along
trajectories and {100 * rk_self_t:.1f} % in crossing times, comparable to the envelope's own differences):

* **+2w**: the 2-omega part of u^2. Each insulator really moves as s + Re(S e^(2 i omega t)) with
  Z_s(2 omega) S = -(sum gamma A_f^2)/2, and the product -2 gamma u_f s then has an omega part
  -gamma S conj(A_f), which `Envelope2w` adds to the fast equations.
* **+A''**: the M A'' term. With u = Re(A e^(i omega t)) exactly, M A'' + (2 i omega M + C) A' = F - Z0 A - (G s) A;
  `envelope.py` keeps only (2 i omega M + C) A'. `EnvelopeA2` keeps the next order,
  A' = B^-1 (R - M d/dt[B^-1 R]).
* **+2w+A''**: both.

| scene | model | step | settled diff vs RK4-160 [u_R] | time err vs RK4-160 | traj vs RK4-160 [u_R] | settled vs RK4-80 | time vs RK4-80 |
|---|---|---|---|---|---|---|---|
{var_rows}

What this shows:

1. **Transients: the dropped M A'' term is the leading error.** Keeping it cuts the largest trajectory difference
   from {traj_env:.3f} to {traj_a2:.4f} u_R (every scene), and the 'settled' differences that are really slow
   transients (gate_edge's (1.025, 1.025) member still ringing at 2500 periods; the latch windows at the end of a
   store pulse) by 10-20x. Mechanism: a component of the motion at omega + delta has the true response
   Z(omega + delta) = Z0 - 2 m omega delta + i c delta - m delta^2; the envelope equations give everything but the
   last term. Transients here ring at the insulators' frequency, delta ~ sqrt(k_I/m_I) =
   {math.sqrt(P.k_i / P.m_i):.3f} rad/s (the fastest envelope eigenvalues, table below): m delta^2 is
   {P.m_g * P.k_i / P.m_i:.2f} for a gate oscillator, against its detuning m_G omega^2 - k_G =
   {P.m_g * P.omega ** 2 - P.k_g:.2f} ({100 * P.m_g * P.k_i / P.m_i / (P.m_g * P.omega ** 2 - P.k_g):.0f} %), and
   {P.m_c * P.k_i / P.m_i:.1f} for a channel, against k_C - m_C omega^2 = {P.k_c - P.m_c * P.omega ** 2:.0f}
   ({100 * P.m_c * P.k_i / P.m_i / (P.k_c - P.m_c * P.omega ** 2):.0f} %). So the ringing sidebands (the wiggles in
   the chain figure) come out a few % wrong, ~0.01-0.02 u_R of amplitude, while the settled state (delta = 0) is
   untouched. Switching times move by well under 1 % either way.
2. **Steady states: the 2-omega part of u^2 is a 1e-5 u_R effect.** A channel's u_C^2 always has a 2-omega part
   (the 2-omega force on its insulator has amplitude {two[5800]['channel_2w_force_max']:.3f} in the adder's
   final state, model force units, comparable to the mean force {two[5800]['mean_force_max']:.3f}), but the insulator, far below
   2 omega (|Z_s(2 omega)| = {sw['Zs2']:.0f}), answers with |S| ~ {s_amp:.1e}, against a static deflection of
   order 0.1-0.3. A gate pair's two 2-omega parts cancel because its two drives are equal and 90 degrees apart
   (external pairs by construction; connected pairs because spring k and dashpot k/omega carry the same force
   magnitude): in the adder the pairs' net 2-omega forcing is {two[5800]['pair_cancellation']:.1e} of its
   parts when settled, {two[3100]['pair_cancellation']:.1e} 200 periods after the inputs change (the pair's
   gates differ only by c A'), i.e. {two[3100]['gates_over_channel']:.1e} of the channel's. Adding the term
   moves the settled gate outputs by ~1e-5 u_R (gate_nominal: {gn['variants']['envelope']['vs160']['amp_err']:.1e}
   -> {gn['variants']['+2w']['vs160']['amp_err']:.1e} u_R vs RK4-160, dominated by the '11' member's slow ringing;
   fanout2: {fo['variants']['envelope']['vs160']['amp_err']:.1e} -> {fo['variants']['+2w']['vs160']['amp_err']:.1e}).
3. **RK4-80 is the larger error in steady states.** RK4 at 80 steps/period sits {gn['rk4_80_vs_160']['amp_err']:.1e} u_R
   from RK4-160 on the nominal gate, more than the envelope does; the issue's 'settled within 0.02 u_R' is met
   by three orders of magnitude either way.
4. **Near-marginal inputs amplify everything.** The chain member with both inputs at 0.67 F_R (the top of the
   '0' band) switches its second gate ~700 periods after the input change instead of ~200: the state creeps
   past a fold slowly, and any small shift of the effective detuning (RK4's step, the A'' term, the 2-omega
   term) moves the crossing by 1-2 %. All variants and RK4-160/320 land within 2.3 % of each other there.

After both corrections the largest time difference against RK4-160 is {100 * time_both:.2f} %{uneven_note} (plain envelope:
{100 * time_env:.2f} %) and trajectories agree to {traj_both:.4f} u_R; what is left is RK4-160's own error,
higher harmonics (3 omega) and sampling (RK4 demodulates over a whole period, the envelope is a point value).
Neither correction is needed for the issue's criteria, so `envelope.py` stays as it is; the A'' correction costs
two extra sparse solves per right-hand side (x{a2_lo:.1f}-{a2_hi:.1f} wall time in these runs).

## The envelope step on the adder, and the enforced bound

The adder scene (16 inputs, 5800 periods) at every step. Steps up to 12 go through `envelope.integrate` (the
enforced bound applies); 'validate.integrate_free' is the same RK4-on-envelope scheme without the check, to find
where it really fails. A step that does not divide the 2900-period input change applies it up to one step late
(6: 4 periods late), which is part of the error at 6 and 12.

| step [periods] | path | wall [s] | settled diff [u_R] | time err | traj [u_R] | crossing mismatches | |
|---|---|---|---|---|---|---|---|
{sweep_rows}

Errors are flat from 1/4 to 4 periods (trajectory difference changes by {step_err_spread:.1e} u_R): the
envelope's own step error is invisible under the model error there, and wall time falls in proportion to the
step ({speed[0.25]:.1f} s at 1/4 -> {speed[4]:.1f} s at 4, on the shared machine). Beyond ~6 periods the switching
times degrade (5-9 % at 16-23 periods) long before anything diverges.

Steps beyond the bound through `envelope.integrate`:

{refused}

**Is the bound right?** It is {sw['rate_safety']} x the largest |eigenvalue| of the envelope equations' linear
part at rest (`envelope.spectral_rate`: ARPACK on -Bop^-1 Z0 for the amplitudes, exact roots for the insulators):
{sw['spectral_rate']:.3f} 1/s -> {st['rk4_stability']} / ({sw['rate_safety']} x rate) = {sw['bound']:.2f} periods
on the adder ({sw['gate_bound']:.2f} on a lone gate, {sw['chain_bound']:.2f} on the chain). Until this version it
was a Gershgorin bound, rate {sw['gershgorin_rate']:.3f} 1/s. The eigenvalues of the
linearised envelope equations (Jacobian at the actual states, every batch member) along the adder's trajectory:

| period | max abs(eigenvalue) [1/s] | largest stable RK4 step [periods] | largest Re(eigenvalue) [1/s] |
|---|---|---|---|
{stab_rows}

(Positive real parts during switching are the gates' own instability that makes them switch, not a property of
the step.) The largest |lambda| is {rad:.3f} 1/s, within {100 * abs(rad / sw['spectral_rate'] - 1):.0f} % of the rate at rest,
and the most restrictive state (period {lin_at['period']}) allows {lin:.1f} periods. Measured: finite at {last_ok:g}
periods, blew up at {first_bad:g} (and at every longer step tried, sooner the longer the step). **The measured onset
agrees with the linearised prediction to within a period, and the enforced bound is {lin / sw['bound']:.1f}x below
it** (lone gate: bound {sw['gate_bound']:.1f} vs linearised {min(s['rk4_stable_step_periods'] for s in sw['gate_stability']):.1f};
chain: {sw['chain_bound']:.1f} vs {min(s['rk4_stable_step_periods'] for s in sw['chain_stability']):.1f}).
Why the Gershgorin bound was so conservative: its worst row is a gate oscillator's, where the coupling spring
k = F_R/u_R = {P.k_couple:.1f} is divided by the gate's small |2 i omega m_G| = {2 * P.omega * P.m_g:.1f}, giving
~2 1/s; the channel on the other side of that spring has 30x the mass, so the coupled mode is slow. The fastest
real mode is the insulator's ringing ({math.sqrt(P.k_i / P.m_i):.3f} rad/s plus damping), whose eigenvalues sit
near the imaginary axis, where RK4's region reaches 2.83. The longer steps this allows matter for the processor,
whose sieve runs at 8 periods per step (reports/fidelity.md measures what that costs).

![step sweep](envelope_step_sweep.png)
"""
    return lines
