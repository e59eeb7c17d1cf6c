"""reports/design.md: automated design of the NOR block (issue #13).

Reads the search record of `mech2spice design` (reports/design_search.json), adds per block (each
structure's best, today's default, the paper's printed set) its energy per operation and switching delay
(physics/energy.py), what limits its tolerance (physics/sensitivity.py: the limiting input point and the
elements its margin is most sensitive to), and the command-line checks of the best block (`--params
robust`): yield at 1 % spread, the six requirements, the adder, sqrt(2809) and the sieve.  Slow results are
cached in reports/design.json (a rerun only adds what is missing).  The grammar and objective: docs/design.md.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from ..errors import Mech2SpiceError
from ..studies._common import load_average
from ._common import MACHINE, md_table, out_dir, pyplot, read_json, save_figure, write_json

SEARCH = Path("reports/design_search.json")
CACHE_NAME = "design.json"
TOL_SAMPLES = 100
SIGMA = 0.01
CHECKS = {     # name -> argv after `mech2spice` (the issue's commands, on the robust preset and the default)
    "robust_spread": ["gate", "--params", "robust", "--spread", "0.01", "--samples", "1000", "--json"],
    "default_spread": ["gate", "--spread", "0.01", "--samples", "1000", "--json"],
    "robust_gate": ["gate", "--params", "robust", "--json"],
    "robust_sqrt": ["simulate", "verilog/sqrt.v", "--stimulus", "verilog/sqrt_2809.json", "--backend", "envelope",
                    "--params", "robust", "--json"],
    "robust_sieve": ["cpu", "run", "programs/sieve.asm", "--backend", "envelope", "--params", "robust", "--json"],
}
SLOW = ("robust_sieve",)
ADDER_BACKENDS = ("rk4", "envelope", "ngspice")   # the issue: the adder on RK4 and ngspice (carrier level)


def blocks(search: dict) -> dict:
    """name -> GateParams: the best block of every searched structure, the default and the printed set."""
    from ..physics.params import DEFAULT, PRINTED, block_params
    out = {"default": DEFAULT, "printed": PRINTED}
    for name, rec in search["structures"].items():
        out[name] = block_params(rec["block_file"], name)
    return out


def block_figures(name: str, p, rec: dict | None, log) -> dict:
    """Tolerance, margin, energy, delay and the limiting elements of one block."""
    from ..design.search import measure
    from ..experiments import energy
    from ..physics import sensitivity
    t0 = time.time()
    m = rec["measured"] if rec else measure(p, SIGMA, 200, TOL_SAMPLES, 0, log)
    e = energy.gate_energy(p)
    out = {"dofs_per_gate": p.structure.n_dofs, "nominal_margin": m["nominal_margin"], "tolerance": m["tolerance"],
           "tolerance_bracket": m["tolerance_bracket"], "yield_1pct": m["yield"],
           "q1_1pct": m["margin_quantiles"]["1%"], "yield_samples": m["samples"], "energy": e}
    sw = [v for v in e["switching"].values()]
    out["delay_periods"] = max(v["delay_periods"] for v in sw) if all(v["delay_periods"] for v in sw) else None
    out["energy_per_period"] = e["steady"]["00"]["per_period_model"] if e["steady"]["00"] else None
    out["energy_per_switch"] = max(v["energy_model"] for v in sw) if out["delay_periods"] else None
    out["threshold_gap"] = threshold_gap(p)
    if m["nominal_margin"] > 0:
        s = sensitivity.gate_sensitivity(p, per_band=8)
        lim = s["limiting"]
        top = np.argsort(-np.abs(lim["gradient"]))[:3]
        out["limiting"] = {"inputs": lim["inputs"], "margin": lim["margin"], "sigma_1": lim["sigma_1"],
                           "elements": [(s["elements"][k], float(lim["gradient"][k])) for k in top]}
    out["wall_s"] = time.time() - t0
    return out


def threshold_gap(p) -> dict:
    """The insulator position at the hardest '1' input point (both inputs at the top of band 0) and at the
    hardest '0' one (one input at the bottom of band 1, the other at the bottom of band 0): the relative
    change of the insulator's pull that has to separate the two output bands.  With equal input weights the
    pull goes as P = x1^2 + x2^2: 0.898 against 0.980, a 9 % window."""
    from ..physics import loaded, steady_batch
    from ..physics.params import BAND0, BAND1
    lg = loaded.build(p)
    pts = np.array([[1.0, BAND0[1], BAND0[1]], [1.0, BAND1[0], BAND0[0]]])
    st = steady_batch.stack([lg.model], lg.input_groups(), lg.gate.channel)
    r = steady_batch.roots(st, 0, pts)
    s = [r.s[(r.point == k) & r.stable] for k in range(2)]
    P = [float(x1 ** 2 + x2 ** 2) for _, x1, x2 in pts]
    out = {"P": P, "P_gap": P[1] / P[0] - 1}
    if all(v.size == 1 for v in s):
        out["s"] = [float(s[0][0]), float(s[1][0])]
    return out


def run_check(argv: list[str]) -> dict:
    """One command line run through `python -m mech2spice.cli`; its JSON, exit code and wall time."""
    t0, load0 = time.time(), load_average()[0]
    root = Path(__file__).resolve().parents[2]
    r = subprocess.run([sys.executable, "-m", "mech2spice.cli", *argv], capture_output=True, text=True, cwd=root,
                       env={**os.environ, "PYTHONPATH": str(root)})
    try:
        data = json.loads(r.stdout)
    except json.JSONDecodeError:
        data = {"stdout": r.stdout[-2000:], "stderr": r.stderr[-2000:]}
    return {"argv": argv, "rc": r.returncode, "wall_s": time.time() - t0, "json": data,
            "loadavg_1min": [load0, load_average()[0]]}


def adder_check(p, backend: str) -> dict:
    """The 2-bit adder's 16 sums in one batch from rest on `backend`, decoded against the logic oracle."""
    from .. import data, simulation
    from ..backends import logic
    from ..experiments.scenes import ADDER_INPUTS
    from ..synthesis import synth
    nl = synth.synthesize(data.verilog("adder2.v"))
    t0, load0 = time.time(), load_average()[0]
    res = simulation.run_physical(nl, p, list(ADDER_INPUTS), backend)
    rows = [{"inputs": v, "s": r["outputs"].get("s"), "expected": logic.evaluate(nl, v)["s"],
             "min_margin": r.get("min_margin")} for v, r in zip(ADDER_INPUTS, res)]
    return {"backend": backend, "correct": sum(r["s"] == r["expected"] for r in rows), "of": len(rows),
            "min_margin": min((r["min_margin"] for r in rows if r["min_margin"] is not None), default=None),
            "rows": rows, "wall_s": time.time() - t0, "loadavg_1min": [load0, load_average()[0]]}


def plot_pareto(figs: dict, path: Path, machine: str) -> None:
    """Tolerance against margin, delay, energy per period and DOFs per gate, one point per block."""
    plt = pyplot()
    fig, axs = plt.subplots(1, 4, figsize=(15, 4), sharey=True)
    keys = (("nominal_margin", "nominal worst margin (band widths)"), ("delay_periods", "switching delay (periods)"),
            ("energy_per_period", "energy per drive period, '00' (model units)"), ("dofs_per_gate", "DOFs per gate"))
    colour = {name: f"C{k}" for k, name in enumerate(figs)}        # one colour per block in every panel
    for ax, (key, label) in zip(axs, keys):
        for name, f in figs.items():
            tol, x = f["tolerance"], f.get(key)
            if x is None:
                continue
            y = tol if tol else 1e-8
            mk = {"default": "s", "printed": "X"}.get(name, "o")
            ax.scatter([x], [y], marker=mk, s=60 if name in ("default", "printed") else 40, color=colour[name],
                       label=name if ax is axs[0] else None)
            ax.annotate(name, (x, y), fontsize=7, xytext=(3, 3), textcoords="offset points")
        ax.set_yscale("log")
        ax.set_xlabel(label)
        ax.grid(alpha=0.3)
    axs[0].set_ylabel("tolerance: largest sigma with >= 99 % yield\n(1e-8: none, nominal fails)")
    axs[0].axhline(0.01, color="k", lw=0.5, ls="--")
    fig.suptitle(f"Blocks searched by `mech2spice design`: tolerance of the loaded gate (steady-state scan, "
                 f"{TOL_SAMPLES}-sample bisection); delay and energy from RK4 (40 steps/period) on a free-standing "
                 f"gate\n{machine}; dashed: the issue's aim (1 %)", fontsize=9)
    axs[0].legend(fontsize=7)
    save_figure(fig, path)


def write(directory="reports", skip_slow: bool = False, render: bool = False, search: str | None = None) -> Path:
    """Write design.md and design_pareto.png from the search record; cache slow results in design.json
    (render=True: measure nothing, use what the cache holds)."""
    d = out_dir(directory)
    log = lambda msg: print(f"[design] {msg}", file=sys.stderr, flush=True)   # noqa: E731
    rec = read_json(Path(search) if search else SEARCH)
    if rec is None:
        raise Mech2SpiceError(f"no search record at {search or SEARCH}: run `mech2spice design` first")
    cache_path = d / CACHE_NAME
    cache = read_json(cache_path, {})
    figs = cache.setdefault("blocks", {})
    for name, p in blocks(rec).items():
        if name in figs and not _same_block(figs[name], rec["structures"].get(name)):
            del figs[name]                  # the search record has a new best for this structure: measure it
        if name not in figs and not render:
            log(f"block {name}")
            figs[name] = block_figures(name, p, rec["structures"].get(name), log)
            write_json(cache_path, cache)
    checks = cache.setdefault("checks", {})
    robust = _robust_digest()
    cache.pop("robust_sha256", None)          # an earlier layout kept one digest for all checks
    stale = [k for k, v in checks.items() if k.startswith("robust") and v.get("robust_sha256") != robust]
    if stale and not render:           # checks of another robust.json (or of one not recorded): run again
        log(f"robust.json differs from the one {', '.join(stale)} ran on: rerunning them")
        checks = cache["checks"] = {k: v for k, v in checks.items() if k not in stale}
    todo = [n for n in CHECKS if n not in checks and not (skip_slow and n in SLOW) and not render]
    from concurrent.futures import ThreadPoolExecutor, as_completed
    with ThreadPoolExecutor(max_workers=2) as pool:     # the command checks are subprocesses: two at a time
        futures = {pool.submit(run_check, CHECKS[n]): n for n in todo}
        for n in todo:
            log(f"check {n}: mech2spice {' '.join(CHECKS[n])}")
        from ..physics.params import load_params
        for backend in ADDER_BACKENDS:
            key = f"robust_adder_{backend}"
            if key not in checks and not render:
                log(f"check {key}")
                checks[key] = {**adder_check(load_params("robust"), backend), "robust_sha256": robust}
                write_json(cache_path, cache)
        for f in as_completed(futures):
            checks[futures[f]] = {**f.result(), "robust_sha256": robust}
            log(f"check {futures[f]} done ({checks[futures[f]]['wall_s']:.0f} s)")
            write_json(cache_path, cache)
    cache["machine"] = MACHINE         # the load of each search and check is recorded with it
    write_json(cache_path, cache)
    figs = {n: f for n, f in figs.items() if n in blocks(rec)}
    plot_pareto(figs, d / "design_pareto.png", cache["machine"])
    md = d / "design.md"
    md.write_text(markdown(rec, figs, checks, cache["machine"]))
    return md


def _same_block(fig: dict, rec: dict | None) -> bool:
    """Whether cached figures were measured on this search entry (its measured margin and tolerance)."""
    if rec is None:
        return True                         # default / printed: not from the search
    m = rec["measured"]
    return fig["nominal_margin"] == m["nominal_margin"] and fig["tolerance"] == m["tolerance"]


def _robust_digest() -> str:
    """sha256 of the shipped robust block file: its checks are valid for this content only."""
    import hashlib
    from .. import data
    return hashlib.sha256(Path(data.path("blocks", "robust.json")).read_bytes()).hexdigest()


def _load(x) -> str:
    """A recorded 1-minute load average pair (start, end), or that none was recorded."""
    return f"load {x[0]:.1f} .. {x[1]:.1f}" if x else "load not recorded"


def search_cell(search: dict | None) -> str:
    """The search column: evaluations, generations, wall time, budget, machine load."""
    if not search:
        return "(not searched)"
    return (f"{search['evaluations']} ev., {search['generations']} gen., {search['wall_s']:.0f} s "
            f"(budget {search['budget_s']:.0f} s, {_load(search.get('loadavg_1min'))})")


def _fmt(x, f="{:.3g}"):
    return "-" if x is None else f.format(x)


def markdown(rec: dict, figs: dict, checks: dict, machine: str) -> str:
    """The markdown of design.md."""
    from ..physics.energy import Scaling
    s = rec["settings"]
    best = max((n for n in rec["structures"] if figs[n]["nominal_margin"] > 0),
               key=lambda n: figs[n]["tolerance"] or 0, default=None)
    lines = ["# Automated design of the NOR block", "",
             "Generated by `mech2spice report design` from `mech2spice design` "
             f"(settings of the first run: {json.dumps(s)}; each structure's budget and the 1-min load average during "
             f"its search, and of each check, are given with it), machine: {machine}. Grammar, objective and how to read this: "
             "docs/design.md.", "",
             "![Pareto](design_pareto.png)", "",
             "## Blocks", "",
             "Tolerance: largest relative sigma with >= 99 % yield of the loaded gate (every element of the block "
             f"spread, {TOL_SAMPLES} samples, bisection to a factor 1.1); yield and 1st-percentile margin at sigma "
             f"{SIGMA:g} on the samples given in brackets (the robust block's 1000-sample figure is below); delay: "
             "periods from "
             "the input step until the output stays in its new band (00->10 and 10->00, the larger); energy: "
             "dissipated per drive period at inputs 00, and during the slower switching event "
             "(physics/energy.py).", ""]
    rows = []
    for name, f in figs.items():
        search = rec["structures"].get(name, {}).get("search")
        rows.append([name, f["dofs_per_gate"], _fmt(f["nominal_margin"], "{:+.4f}"),
                     _fmt(f["tolerance"]) + (f" ({_fmt(f['tolerance_bracket'][0])} .. "
                                              f"{_fmt(f['tolerance_bracket'][1])})" if f["tolerance"] else ""),
                     _fmt(f["yield_1pct"], "{:.3f}") + f" ({f.get('yield_samples')})", _fmt(f["q1_1pct"], "{:+.2f}"), _fmt(f["delay_periods"], "{}"),
                     _fmt(f["energy_per_period"]), _fmt(f["energy_per_switch"]),
                     search_cell(search)])
    lines += md_table(["block", "DOFs", "nominal margin", "tolerance (bracket)", "yield at 1 %", "q1 at 1 %",
                       "delay", "E/period", "E/switch", "search"], rows)
    lines += search_runs(rec)
    lines += ["", "## What limits each block", "",
              "The limiting input point is the one with the smallest margin / |gradient| (physics/sensitivity.py, "
              "implicit-function derivatives of the steady state); sigma_1 = margin / |gradient| is the spread at "
              "which a one-sigma draw along the gradient closes that margin.  The three largest derivatives "
              "(band widths per relative change) name the elements that limit it.", ""]
    rows = []
    for name, f in figs.items():
        lim = f.get("limiting")
        if not lim:
            rows.append([name, "nominal gate fails: no margin to limit", "", ""])
            continue
        rows.append([name, f"({lim['inputs'][0]:.3f}, {lim['inputs'][1]:.3f}), margin {lim['margin']:+.4f}",
                     f"{lim['sigma_1']:.2e}", "; ".join(f"{e} {g:+.3g}" for e, g in lim["elements"])])
    lines += md_table(["block", "limiting inputs", "sigma_1", "largest derivatives"], rows)
    g = figs["default"]["threshold_gap"]
    lines += ["", f"The structural window: every block of the grammar sums its inputs in one insulator, whose pull "
              f"goes as P = x1^2 + x2^2 for equal input weights.  The hardest '1' input (both inputs at the top "
              f"of band 0) has P = {g['P'][0]:.3f}, the hardest '0' input (one at the bottom of band 1, the other "
              f"at the bottom of band 0) P = {g['P'][1]:.3f}: the threshold must sit inside a {100 * g['P_gap']:.1f} % "
              "window, so the spread of everything that sets it (gammas, gate responses, insulator stiffness, "
              "source) must stay well inside about half of that at the 1 % tail.  The insulator's steady position "
              "at those two points, per block (a sign change: the insulator snaps between them):", ""]
    rows = [[n, *(f"{v:+.4g}" for v in f["threshold_gap"]["s"])]
            for n, f in figs.items() if "s" in f.get("threshold_gap", {})]
    lines += md_table(["block", "s at (0.67, 0.67)", "s at (0.92, 0.365)"], rows)
    e0 = figs["default"]["energy"]
    lines += ["", "## Energy per operation", "",
              f"Scaling: {Scaling().describe()} ({e0['joule_per_model_unit']:.3g} J per model energy unit for the "
              f"classic block); kT ln 2 = {e0['kT_ln2_J']['300K']:.3g} J at 300 K, {e0['kT_ln2_J']['4K']:.3g} J "
              "at 4 K.", ""]
    rows = []
    for name, f in figs.items():
        e = f["energy"]
        st, sw = e["steady"]["00"], e["switching"]
        kt = e["kT_ln2_J"]["300K"]
        rows.append([name, _fmt(st and st["power_model"]), _fmt(st and st["per_period_J"]),
                     _fmt(st and st["per_period_J"] / kt, "{:.2e}")]
                    + [_fmt(v["energy_J"]) + f" ({_fmt(v['delay_periods'], '{}')} periods)" for v in sw.values()])
    lines += md_table(["block", "P at 00 (model)", "E/period at 00 (J)", "E/period / kT ln 2 (300 K)",
                       "E 00->10 (J, delay)", "E 10->00 (J, delay)"], rows)
    lines += ["", "## The best block as `--params robust`", ""]
    lines += [f"Best structure by tolerance: **{best}**." if best else "No structure has a positive nominal margin.", ""]
    lines += render_checks(checks)
    return "\n".join(lines) + "\n"


def search_runs(rec: dict) -> list[str]:
    """Every search run merged into the record (`mech2spice design --merge`), per structure."""
    rows = [[name, r["source"], f"{r['budget_s']:.0f}", r["generations"], r["evaluations"], f"{r['wall_s']:.0f}",
             _load(r.get("loadavg_1min")), _fmt(r["nominal_margin"], "{:+.4f}"),
             _fmt(r["tolerance"]) + (f" ({_fmt(r['tolerance_bracket'][0])} .. {_fmt(r['tolerance_bracket'][1])})"
                                     if r["tolerance"] else ""),
             "yes" if r["source"] == e.get("source") else "no"]
            for name, e in rec["structures"].items() for r in e.get("runs", [])]
    if not rows:
        return []
    return ["", "Search runs merged into the record (`mech2spice design --merge`; same seed, 16 CRN samples, "
            f"popsize 6; tolerance by the same {TOL_SAMPLES}-sample bisection); the run with the larger tolerance "
            "is the structure's entry above:", "",
            *md_table(["structure", "record", "budget s", "generations", "evaluations", "wall s", "1-min load",
                       "nominal margin", "tolerance (bracket)", "entry"], rows)]


def render_checks(checks: dict) -> list[str]:
    """The command-line checks of the robust block, as found."""
    out = []
    for name in ("robust_spread", "default_spread"):
        c = checks.get(name)
        if not c:
            out.append(f"- `mech2spice {' '.join(CHECKS[name])}`: not measured on this robust.json (not in the cache)")
            continue
        j = c["json"]
        t = j.get("tolerance", {})
        if "yield" not in j:
            out.append(f"- `mech2spice {' '.join(c['argv'])}`: exit {c['rc']}, {j}")
            continue
        lo, hi = j["yield_ci95"]
        out.append(f"- `mech2spice {' '.join(c['argv'])}`: yield {j['yield']:.3f} ({j['samples']} samples, 95 % "
                   f"Wilson {lo:.4f} .. {hi:.4f}), margin quantiles "
                   f"{json.dumps({k: round(v, 3) for k, v in j['margin_quantiles'].items()})}, tolerance "
                   f"{_fmt(t.get('sigma'))} (bracket {' .. '.join(_fmt(b) for b in t.get('bracket', []))}), nominal "
                   f"margin {j['nominal_margin']:+.4f}; {c['wall_s']:.0f} s ({_load(c.get('loadavg_1min'))})")
    c = checks.get("robust_gate")
    if c:
        req = c["json"].get("requirements", {})
        out.append(f"- `mech2spice {' '.join(c['argv'])}` (RK4 at nominal): switches {c['json'].get('switches')}; "
                   + "; ".join(f"{k}: {'pass' if v['pass'] else 'FAIL'}" for k, v in req.items())
                   + f"; {c['wall_s']:.0f} s ({_load(c.get('loadavg_1min'))})")
    for backend in ADDER_BACKENDS:
        c = checks.get(f"robust_adder_{backend}")
        if c:
            out.append(f"- adder, 16 sums on {backend}: {c['correct']}/{c['of']} correct; {c['wall_s']:.0f} s "
                       f"({_load(c.get('loadavg_1min'))})")
    c = checks.get("robust_sqrt")
    if c:
        j = c["json"]
        out.append(f"- `mech2spice {' '.join(c['argv'])}`: exit {c['rc']}, outputs {j.get('outputs')}, valid "
                   f"{j.get('valid')}, min margin {j.get('min_margin')}; {c['wall_s']:.0f} s ({_load(c.get('loadavg_1min'))})")
    c = checks.get("robust_sieve")
    if c:
        j = c["json"]
        out.append(f"- `mech2spice {' '.join(c['argv'])}`: exit {c['rc']}, halted {j.get('halted')} after "
                   f"{j.get('cycles')} cycles; {c['wall_s']:.0f} s ({_load(c.get('loadavg_1min'))})")
    else:
        out.append("- the sieve on the envelope with `--params robust`: not run (skip_slow)")
    return out
