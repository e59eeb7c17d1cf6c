"""Automated design of the NOR block (issue #13), measured into reports/design.json
(mech2spice/reports/design.py renders reports/design.md from it).

Reads the search record of `mech2spice design` (reports/design_search.json) and measures per block (each
structure's best, today's default, the paper's printed set) its energy per operation and switching delay
(physics/energy.py), what limits its tolerance (physics/sensitivity.py: the limiting input point and the
elements its margin is most sensitive to); the same for the design centering's presets; and the command-line
checks of the presets in CHECKED (robust and the centred ones that meet issue #27's figures): yield under the
spread (trimmed where the preset was centred for trimming), the six requirements, the adder on three engines,
sqrt(2809), the sieve and the processor's Monte-Carlo.  design.json is a cache: a rerun only adds what is
missing (a block whose search entry or preset file changed, checks of another block file are measured
again).  The grammar and objective: docs/design.md.  One section, `all` (~20 min).
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from pathlib import Path

import numpy as np

from ..errors import Mech2SpiceError
from ._common import conditions, load_average, read_json, write_json

SECTIONS = ("all",)
SEARCH = Path("reports/design_search.json")
TOL_SAMPLES = 100
SIGMA = 0.01
CHECKED = ("robust", "centered2", "centered_fc2")   # presets whose network checks the report shows
CENTRED = ("centered", "centered_fc", "centered2", "centered_fc2")   # design centering's presets (docs/design.md)
TRIM = ["--trim", "fc", "--trim-residual", "1e-4"]     # the trimmed presets' fabrication: trim fc, residual 1e-4


def preset_checks(name: str) -> dict:
    """Check name -> argv after `mech2spice`: the issue's commands on preset `name` (a trimmed preset, *_fc*, spread
    at 1 % and trimmed; centered2 at 1e-3, the spread it was centred for; robust at 1 %)."""
    spread = (["--spread", "0.01", *TRIM] if "_fc" in name else
              ["--spread", "0.001" if name in CENTRED else "0.01"])
    out = {f"{name}_spread": ["gate", "--params", name, *spread, "--samples", "1000", "--json"],
           f"{name}_gate": ["gate", "--params", name, "--json"],
           f"{name}_sqrt": ["simulate", "verilog/sqrt.v", "--stimulus", "verilog/sqrt_2809.json", "--backend",
                            "envelope", "--params", name, "--json"],
           f"{name}_sieve": ["cpu", "run", "programs/sieve.asm", "--backend", "envelope", "--params", name, "--json"]}
    if "_fc" in name:
        out[f"{name}_cpu_montecarlo"] = ["cpu", "montecarlo", "programs/sieve.asm", "--params", name, "--spread",
                                         "0.01", *TRIM, "--samples", "8", "--cycles", "30", "--json"]
    return out


CHECKS = {k: v for name in CHECKED for k, v in preset_checks(name).items()}
CHECKS["default_spread"] = ["gate", "--spread", "0.01", "--samples", "1000", "--json"]
SLOW = tuple(k for k in CHECKS if k.endswith(("_sieve", "_cpu_montecarlo")))
ADDER_BACKENDS = ("rk4", "envelope", "ngspice")   # the issue: the adder on RK4 and ngspice (carrier level)


def search_record(search: str | None = None) -> dict:
    """The record `mech2spice design` wrote (default reports/design_search.json); none is one error line."""
    rec = read_json(Path(search) if search else SEARCH)
    if rec is None:
        raise Mech2SpiceError(f"no search record at {search or SEARCH}: run `mech2spice design` first")
    return rec


def block_names(search: dict) -> list[str]:
    """The blocks the report shows: the default, the printed set, every searched structure's best and the
    centred presets."""
    return ["default", "printed", *search["structures"], *CENTRED]


def blocks(search: dict) -> dict:
    """name -> GateParams: the best block of every searched structure, the default, the printed set and the
    centred presets."""
    from ..physics.params import DEFAULT, PRINTED, block_params, load_params
    out = {"default": DEFAULT, "printed": PRINTED}
    for name, rec in search["structures"].items():
        out[name] = block_params(rec["block_file"], name)
    return {**out, **{name: load_params(name) for name in CENTRED}}


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


def same_block(fig: dict, rec: dict | None, name: str | None = None) -> bool:
    """Whether cached figures were measured on this search entry (its measured margin and tolerance), or on
    this preset file (its digest)."""
    if name in CENTRED:
        return fig.get("block_sha256") == block_digest(name)
    if rec is None:
        return True                         # default / printed: not from the search
    m = rec["measured"]
    return fig["nominal_margin"] == m["nominal_margin"] and fig["tolerance"] == m["tolerance"]


def block_digest(name: str) -> str:
    """sha256 of a shipped block file: its figures and checks are valid for this content only."""
    import hashlib
    from .. import data
    return hashlib.sha256(Path(data.path("blocks", f"{name}.json")).read_bytes()).hexdigest()


def _log(msg: str) -> None:
    print(f"[design] {msg}", file=sys.stderr, flush=True)


def measure_blocks(rec: dict, cache: dict, save) -> None:
    """Figures of every block the cache lacks or holds for another search entry, saved after each."""
    figs = cache.setdefault("blocks", {})
    for name, p in blocks(rec).items():
        if name in figs and not same_block(figs[name], rec["structures"].get(name), name):
            del figs[name]                  # a new best for this structure, or a changed preset: measure it
        if name not in figs:
            _log(f"block {name}")
            figs[name] = block_figures(name, p, rec["structures"].get(name), _log)
            if name in CENTRED:
                figs[name]["block_sha256"] = block_digest(name)
            save()


def _preset_of(check: str) -> str | None:
    return next((n for n in sorted(CHECKED, key=len, reverse=True) if check.startswith(n + "_")), None)


def measure_checks(cache: dict, skip_slow: bool, save) -> None:
    """The command-line checks and the adder runs the cache lacks for today's preset files, saved after each."""
    from ..physics.params import load_params
    checks = cache.setdefault("checks", {})
    digest = {n: block_digest(n) for n in CHECKED}
    cache.pop("robust_sha256", None)          # an earlier layout kept one digest for all checks
    for v in checks.values():                 # ... and then one per check under the robust block's name
        if "robust_sha256" in v:
            v["block_sha256"] = v.pop("robust_sha256")
    stale = [k for k, v in checks.items() if _preset_of(k) and v.get("block_sha256") != digest[_preset_of(k)]]
    if stale:                          # checks of another block file (or of one not recorded): run again
        _log(f"the block files differ from the ones {', '.join(stale)} ran on: rerunning them")
        checks = cache["checks"] = {k: v for k, v in checks.items() if k not in stale}
    todo = [n for n in CHECKS if n not in checks and not (skip_slow and n in SLOW)]
    with ThreadPoolExecutor(max_workers=2) as pool:     # the command checks are subprocesses: two at a time
        futures = {pool.submit(run_check, CHECKS[n]): n for n in todo}
        for n in todo:
            _log(f"check {n}: mech2spice {' '.join(CHECKS[n])}")
        for name in CHECKED:
            for backend in ADDER_BACKENDS:
                key = f"{name}_adder_{backend}"
                if key not in checks:
                    _log(f"check {key}")
                    checks[key] = {**adder_check(load_params(name), backend), "block_sha256": digest[name]}
                    save()
        for f in as_completed(futures):
            n = futures[f]
            checks[n] = {**f.result(), **({"block_sha256": digest[_preset_of(n)]} if _preset_of(n) else {})}
            _log(f"check {n} done ({checks[n]['wall_s']:.0f} s)")
            save()


def measure_into(path: Path, search: str | None = None, skip_slow: bool = False) -> dict:
    """Add what design.json at `path` lacks for the search record (blocks, checks) and save it."""
    rec = search_record(search)
    cache = read_json(path, {})
    save = lambda: write_json(path, cache)      # noqa: E731 (after every slow result: an interrupted run resumes)
    measure_blocks(rec, cache, save)
    measure_checks(cache, skip_slow, save)
    cache["conditions"] = conditions()
    cache["machine"] = cache["conditions"]["machine"]     # the load of each search and check is recorded with it
    save()
    return cache
