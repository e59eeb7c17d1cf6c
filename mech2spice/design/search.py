"""`mech2spice design`: search block structures for the most fabrication-tolerant NOR gate.

Per structure of the grammar (design/grammar.py), scipy's differential evolution maximises a
tolerance-aware score of the loaded gate (physics/loaded.py), built on q1(sigma): the 1st percentile,
over N samples, of the worst margin over the valid input region under relative spread sigma on every
element (the same standard normal draws for every candidate: common random numbers).

  * nominal gate fails (worst margin over the valid input region <= 0, which covers the truth table,
    the output bands, a missing stable state and the stability of every steady state):
        score = FAIL_OFFSET - log(1 + mean over the grid of max(-margin, 0))    <= -20
  * nominal gate passes: on the ladder sigma_k = 10^(-7 + k/2) (1e-7 ... 1e-1), bisection finds the
    largest sigma_k with q1 > 0; score = log10 of that sigma, plus the zero crossing of q1 interpolated
    towards the next rung (log-linear):                                         in [-7.5, -1]
    i.e. the tolerance (largest sigma at ~99 % yield) estimated on N samples.

Why not q1 at one sigma: at sigma = 1 % every candidate's q1 sits far below zero and the search has no
gradient toward tolerance (measured: docs/design.md).  The search runs on a coarse input grid and s grid
(SEARCH_GRID); the best point is then re-measured on the full grid: nominal margin, yield and margin
quantiles at SIGMA, and its tolerance by experiments/tolerance.py's bisection on more samples.  Each
finished structure is written to the checkpoint (tmp + os.replace), so an interrupted run resumes with
the next structure.  docs/design.md.
"""
from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path

import numpy as np

from ..errors import Mech2SpiceError
from ..experiments import tolerance as tol
from ..inputs import is_int, is_number, replace_file, strict_json
from . import grammar

SEARCH_GRID = {"per_band": 6, "n_grid": 1000}     # coarse: 144 input points, 1000 s points
FAIL_OFFSET = -20.0
INIT_SPREAD = 1e-4        # the initial population: the seed + normal steps of this fraction of each range (working
                          # gates are a thin set: +0.1 % of k_C alone takes the default margin to -3)
LADDER = 10.0 ** (-7 + 0.5 * np.arange(13))        # 1e-7 ... 1e-1


class Objective:
    """The search score of one structure (see the module docstring), with common random numbers."""

    def __init__(self, structure: grammar.Structure, samples: int, seed: int):
        self.structure = structure
        self.samples, self.seed = samples, seed
        self.evaluations = self.errors = 0

    def sampler(self, p, samples: int | None = None, **grid) -> tol.Sampler:
        """A Sampler of p's loaded gate whose draws are this objective's (same seed, same elements)."""
        return tol.Sampler(p, samples or self.samples, self.seed, **(grid or SEARCH_GRID))

    def score(self, x) -> float:
        """Score of parameter vector x (higher is better)."""
        self.evaluations += 1
        try:
            return self._score(x)
        except (Mech2SpiceError, np.linalg.LinAlgError, ValueError, IndexError):
            self.errors += 1                   # a candidate the model or the scan rejects: scored as failing
            return FAIL_OFFSET - 5.0

    def q1(self, s: tol.Sampler, sigma: float) -> float:
        """1st percentile of the samples' worst margins at sigma."""
        worst = [float(s.margins(s.model(sigma, i)).min()) for i in range(self.samples)]
        return float(np.percentile(worst, 1))

    def _score(self, x) -> float:
        p = self.structure.params(x)
        s = self.sampler(p)
        margins = s.margins(s.model(0.0, None))
        m0 = float(margins.min())
        if not m0 > 0:          # how far the nominal gate is from working: its mean violation over the grid
            return FAIL_OFFSET - math.log1p(float(np.mean(np.maximum(-margins, 0.0))))
        q = {-1: m0}                                   # rung -1: sigma 0, the nominal gate
        lo, hi = -1, len(LADDER)                       # q1 > 0 at lo; hi: not yet known to fail
        while hi - lo > 1:
            mid = (lo + hi) // 2
            q[mid] = self.q1(s, LADDER[mid])
            lo, hi = (mid, hi) if q[mid] > 0 else (lo, mid)
        if hi == len(LADDER):
            return float(math.log10(LADDER[-1]))
        base = math.log10(LADDER[lo]) if lo >= 0 else math.log10(LADDER[0]) - 0.5
        return base + 0.5 * q[lo] / (q[lo] - q[hi])

    def __call__(self, x) -> float:
        return -self.score(x)


def search_structure(name: str, samples: int, seed: int, maxiter: int, popsize: int,
                     budget_s: float, log=lambda msg: None, progress: bool = False) -> dict:
    """Differential evolution on one structure; returns the search record and the best parameters."""
    from scipy.optimize import differential_evolution
    from ..backends import progress_bar
    st = grammar.Structure(name)
    obj = Objective(st, samples, seed)
    bounds = list(st.bounds.values())
    t0, load0 = time.time(), os.getloadavg()[0]
    x0, repair = repaired_seed(obj, grammar.x_default(name), bounds)
    log(f"{name}: seed score {repair['seed_score']:+.3f}, after repair {repair['score']:+.3f} "
        f"({repair['evaluations']} evaluations)")
    best = {"score": -math.inf}
    bar = progress_bar(maxiter, progress, unit="generation")

    def callback(xk, convergence=None):
        bar.update(1)
        return time.time() - t0 > budget_s            # True stops the search: the budget is spent

    res = differential_evolution(obj, bounds, seed=seed, maxiter=maxiter, tol=1e-6, polish=False,
                                 init=initial_population(x0, bounds, popsize, seed), workers=1,
                                 updating="immediate", callback=callback)
    bar.close()
    best = {"x": [float(v) for v in res.x], "score": -float(res.fun)}
    wall = time.time() - t0
    log(f"{name}: score {best['score']:+.4f} after {obj.evaluations} evaluations, {wall:.0f} s")
    return {"structure": name, "parameters": dict(zip(st.bounds, best["x"])), "score": best["score"],
            "search": {"optimizer": "scipy.optimize.differential_evolution", "seed": seed, "maxiter": maxiter,
                       "popsize": popsize, "budget_s": budget_s, "evaluations": obj.evaluations,
                       "rejected_candidates": obj.errors,
                       "generations": int(res.nit), "wall_s": wall, "stopped": res.message,
                       "loadavg_1min": [load0, os.getloadavg()[0]],          # at the start and the end
                       "objective": {"score": "log10 of the largest ladder sigma with q1 > 0, interpolated",
                                     "ladder": [float(v) for v in LADDER], "samples": samples,
                                     "quantile": "1%", **SEARCH_GRID},
                       "initial_population": f"default gate embedded in the structure (repaired by "
                                             f"Nelder-Mead where it fails) + normal steps of {INIT_SPREAD} x "
                                             "each range", "repair": repair}}


class _Repaired(Exception):
    pass


def repaired_seed(obj: Objective, x0: np.ndarray, bounds: list, max_evaluations: int = 600):
    """The seed, or, where the embedded default gate fails nominally, the first point Nelder-Mead finds on
    the failing score (mean violation: smooth and cheap) that works, so the population starts on working
    gates.  Returns (x, record)."""
    from scipy.optimize import minimize
    first = obj.score(x0)
    rec = {"seed_score": first, "score": first, "evaluations": 0}
    if first > FAIL_OFFSET:
        return x0, rec
    n0 = obj.evaluations

    def f(x):
        v = obj.score(x)
        if v > FAIL_OFFSET:
            raise _Repaired(np.array(x), v)
        return -v
    x = x0
    try:
        res = minimize(f, x0, method="Nelder-Mead", bounds=bounds,
                       options={"maxfev": max_evaluations, "initial_simplex": None})
        x, rec["score"] = res.x, -float(res.fun)
    except _Repaired as done:
        x, rec["score"] = done.args
    rec["evaluations"] = obj.evaluations - n0
    return x, rec


def initial_population(x0: np.ndarray, bounds: list, popsize: int, seed: int) -> np.ndarray:
    """popsize x n_params members: the seed (the default gate embedded in the structure) and normal steps
    around it; a uniform start over the whole box almost never lands on a working gate (measured:
    docs/design.md)."""
    lo, hi = np.array(bounds, float).T
    rng = np.random.default_rng(seed)
    n = max(5, popsize * len(bounds))
    pop = x0 + INIT_SPREAD * (hi - lo) * rng.standard_normal((n, len(bounds)))
    pop[0] = x0
    return np.clip(pop, lo, hi)


def measure(p, sigma: float, samples: int, tol_samples: int, seed: int, log=lambda msg: None) -> dict:
    """Full-grid figures of one block: nominal margin, yield / quantiles at sigma, tolerance (bisection)."""
    t0 = time.time()
    s = tol.Sampler(p, samples, seed)
    nominal = float(s.margins(s.model(0.0, None)).min())
    y = tol.yield_at(s, sigma)
    t = tol.tolerance(tol.Sampler(p, tol_samples, seed), log=log)
    return {"nominal_margin": nominal, "sigma": sigma, "samples": samples, "yield": y["yield"],
            "yield_ci95": y["yield_ci95"], "margin_quantiles": y["margin_quantiles"],
            "tolerance": t["sigma"], "tolerance_bracket": t["bracket"], "tolerance_samples": tol_samples,
            "dofs_per_gate": p.structure.n_dofs, "elements_spread": len(s.elements), "wall_s": time.time() - t0}


def block_file(p, record: dict) -> dict:
    """The block file (--params FILE) of a found block, with how it was found and what was measured."""
    return {"name": p.name, "block": p.structure.to_dict(), "f_r": p.f_r, "u_r": p.u_r, "omega": p.omega,
            "levels": p.levels.to_dict(),
            "search": record["search"], "measured": record["measured"]}


def write_atomic(path: Path, data) -> None:
    """Write JSON to path through a temporary file and os.replace (an interrupted write leaves the old file)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    replace_file(path, (strict_json(data, indent=1) + "\n").encode("utf-8"), durable=True)


# What summary(), best(), merge() and --install-robust read from each structure's entry: checked when a
# record is read, so that a damaged or hand-edited file is one line, not a traceback after the search.
_NUMBER, _OBJECT = (is_number, "a number"), (lambda v: isinstance(v, dict), "an object")
ENTRY_FIELDS = {
    "structure": (lambda v: isinstance(v, str), "a string"), "score": _NUMBER, "block_file": _OBJECT,
    "parameters": (lambda v: isinstance(v, dict) and all(map(is_number, v.values())), "an object of numbers"),
    **{f"search.{k}": _NUMBER for k in ("budget_s", "generations", "evaluations", "wall_s")},
    "measured.nominal_margin": _NUMBER, "measured.yield": _NUMBER, "measured.margin_quantiles.1%": _NUMBER,
    "measured.tolerance": (lambda v: v is None or is_number(v), "a number or null"),
    "measured.tolerance_bracket": (lambda v: isinstance(v, list), "a list"),
    "measured.dofs_per_gate": (is_int, "a whole number"),
}


def is_record(path) -> bool:
    """Whether `path` holds a design search record (an object of settings and structures)."""
    try:
        data = json.loads(Path(path).read_bytes())
    except (OSError, ValueError, RecursionError):
        return False
    return isinstance(data, dict) and isinstance(data.get("settings"), dict) and \
        isinstance(data.get("structures"), dict)


RECORD_KIND = ("a design search record", is_record)


def read_record(path: Path) -> dict:
    """The design search record at `path`, every field the command reads checked (one line if not)."""
    from ..physics.params import block_params
    try:
        state = json.loads(Path(path).read_bytes())
    except OSError as e:
        raise Mech2SpiceError(f"cannot read search record {path}: {e.strerror or e}") from None
    except (ValueError, RecursionError) as e:         # not UTF-8, not JSON, nested too deep
        raise Mech2SpiceError(f"search record {path} is damaged (not JSON: {e})") from None
    if not (isinstance(state, dict) and isinstance(state.get("settings"), dict)
            and isinstance(state.get("structures"), dict)):
        raise Mech2SpiceError(f"{path} is not a design search record (an object of 'settings' and "
                              "'structures')")
    for key in SETTINGS:
        if not is_number(state["settings"].get(key)):
            raise Mech2SpiceError(f"search record {path}: settings '{key}' is missing or not a number")
    for name, rec in state["structures"].items():
        if name not in grammar.STRUCTURES:
            raise Mech2SpiceError(f"search record {path}: {ascii(name)[:40]} is not a structure of the grammar")
        for field, (ok, what) in ENTRY_FIELDS.items():
            if not ok(_field(rec, field)):
                raise Mech2SpiceError(f"search record {path}: structure '{name}': '{field}' is missing or not {what}")
        block_params(rec["block_file"], f"search record {path}: {name}'s block_file")   # checked as --params is
    return state


def _field(rec, dotted: str):
    """rec["a"]["b"] for "a.b"; _MISSING where a key is absent (null is a value)."""
    for key in dotted.split("."):
        if not isinstance(rec, dict) or key not in rec:
            return _MISSING
        rec = rec[key]
    return rec


_MISSING = object()


SETTINGS = ("sigma", "samples", "seed", "maxiter", "popsize", "budget_s", "tol_samples")


def settings_key(settings: dict) -> dict:
    """The settings a finished structure must share to be reused on resume."""
    return {k: settings[k] for k in SETTINGS}


def run(structures: list[str], out: Path, settings: dict, log=lambda msg: None, progress: bool = False) -> dict:
    """Search every structure not yet in the checkpoint `out` (same settings); returns the whole record."""
    unknown = [s for s in structures if s not in grammar.STRUCTURES]
    if unknown:
        raise Mech2SpiceError(f"unknown structure(s) {', '.join(unknown)} (known: {', '.join(grammar.STRUCTURES)})")
    state = {"settings": settings, "structures": {}}
    if out.exists() and out.stat().st_size:
        old = read_record(out)
        if settings_key(old["settings"]) == settings_key(settings):
            state["structures"] = old.get("structures", {})
        else:
            log(f"{out}: other settings, searching afresh")
    for name in structures:
        if name in state["structures"]:
            log(f"{name}: finished in the checkpoint, skipped")
            continue
        rec = search_structure(name, settings["samples"], settings["seed"], settings["maxiter"],
                               settings["popsize"], settings["budget_s"], log, progress)
        p = grammar.Structure(name).params(list(rec["parameters"].values()))
        log(f"{name}: measuring the best point on the full grid")
        rec["measured"] = measure(p, settings["sigma"], settings["samples"], settings["tol_samples"],
                                  settings["seed"], log)
        rec["block_file"] = block_file(p, rec)
        state["structures"][name] = rec
        write_atomic(out, state)
    return state


def best(state: dict) -> dict | None:
    """The structure with the largest tolerance (then the best score)."""
    recs = [r for r in state["structures"].values() if r["measured"]["nominal_margin"] > 0]
    if not recs:
        return None
    return max(recs, key=lambda r: (r["measured"]["tolerance"] or 0.0, r["score"]))


def summary(state: dict) -> dict:
    """The --json output: per structure its best parameters, tolerance, margin and DOFs per gate."""
    b = best(state)
    return {"settings": state["settings"], "best": b["structure"] if b else None,
            "structures": {n: {"parameters": r["parameters"], "score": r["score"],
                               "tolerance": r["measured"]["tolerance"],
                               "tolerance_bracket": r["measured"]["tolerance_bracket"],
                               "nominal_margin": r["measured"]["nominal_margin"],
                               "yield": r["measured"]["yield"], "margin_quantiles": r["measured"]["margin_quantiles"],
                               "dofs_per_gate": r["measured"]["dofs_per_gate"], "search": r["search"]}
                           for n, r in state["structures"].items()}}


def run_summary(rec: dict, source: str) -> dict:
    """One search run of a structure, as listed under its entry's "runs" in a merged record."""
    srch, m = rec["search"], rec["measured"]
    return {"source": source, "budget_s": srch["budget_s"], "generations": srch["generations"],
            "evaluations": srch["evaluations"], "wall_s": srch["wall_s"], "loadavg_1min": srch.get("loadavg_1min"),
            "score": rec["score"], "nominal_margin": m["nominal_margin"], "tolerance": m["tolerance"],
            "tolerance_bracket": m["tolerance_bracket"]}


def merge(out: Path, sources: list[Path], log=lambda msg: None) -> dict:
    """Merge other runs' records (e.g. longer searches of some structures) into the record `out`: per
    structure, a run's best replaces the entry when its tolerance, measured by the same bisection (same
    tolerance samples and seed), is larger.  Every run compared is listed under the entry's "runs"."""
    state = read_record(out)
    for src in sources:
        other = read_record(src)
        for key in ("tol_samples", "seed", "sigma", "samples"):
            if other["settings"][key] != state["settings"][key]:
                raise Mech2SpiceError(f"{src}: {key} {other['settings'][key]} differs from {out}'s "
                                      f"{state['settings'][key]}: tolerances not comparable")
        for name, rec in other["structures"].items():
            old = state["structures"].get(name)
            runs = (old or {}).get("runs") or ([run_summary(old, str(out))] if old else [])
            new_tol, old_tol = rec["measured"]["tolerance"] or 0.0, old and (old["measured"]["tolerance"] or 0.0)
            better = old is None or (rec["measured"]["nominal_margin"] > 0 and new_tol > old_tol)
            log(f"{name}: {src} tolerance {new_tol:.3g} against {old_tol or 0:.3g}: "
                + ("replaces the entry" if better else "entry kept"))
            source = str(src) if better else old.get("source", str(out))
            state["structures"][name] = {**(rec if better else old), "source": source,
                                         "runs": runs + [run_summary(rec, str(src))]}
    write_atomic(out, state)
    return state


def install_block(rec: dict, target: Path, name: str = "robust") -> None:
    """Install a structure's found block as the package's `target` (--params robust) only once the exact
    file to be installed loads as --params does and its nominal gate works (worst margin > 0, best()'s
    test); written beside it and renamed over it, so a failure leaves the installed block untouched."""
    data = {**rec["block_file"], "name": name, "note": f"best of `mech2spice design` ({rec['structure']})"}
    tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(strict_json(data, indent=1) + "\n")
        margin = _nominal_margin(tmp, rec["structure"])
        if not margin > 0:
            raise Mech2SpiceError(f"--install-robust: the {rec['structure']} block fails its own check (nominal "
                                  f"worst margin {margin:+.4f}): not installed")
        _check_stable(tmp, rec["structure"])
        _check_self_drive(tmp, rec["structure"])
        os.replace(tmp, target)
    finally:
        tmp.unlink(missing_ok=True)


def _check_self_drive(path: Path, structure: str) -> None:
    """Refuse a block that --params would refuse on load (params.LOAD_CHECKS: its output levels inside its
    own bands), so an installed --params robust always loads."""
    from ..inputs import read_json
    from ..physics.params import block_params, self_driving
    self_driving(block_params(read_json(path, "block file"), f"of the {structure} entry"),
                 f"--install-robust: the {structure} block (not installed)")


def _check_stable(path: Path, structure: str) -> None:
    """Refuse a block with a growing mode over its valid inputs or in the 3-gate chain (the block-level part
    of the stability verdict, experiments/characterise.stability; docs/stability.md)."""
    from ..experiments.characterise import stability
    from ..inputs import read_json
    from ..physics.params import block_params
    st = stability(block_params(read_json(path, "block file"), f"of the {structure} entry"))
    if not st["stable"]:
        raise Mech2SpiceError(f"--install-robust: the {structure} block has a growing mode (growth "
                              f"{st['worst_growth_rate']:+.2e} per drive period): not installed")


def _nominal_margin(path: Path, structure: str) -> float:
    """The worst margin over the valid input region of the block file at `path` without spread (read as
    load_params reads a block file, named by its entry in messages)."""
    from ..inputs import read_json
    from ..physics.params import block_params
    try:
        s = tol.Sampler(block_params(read_json(path, "block file"), f"of the {structure} entry"), 1, 0)
        return float(s.margins(s.model(0.0, None)).min())
    except (Mech2SpiceError, np.linalg.LinAlgError, ValueError, IndexError) as err:    # as Objective.score
        raise Mech2SpiceError(f"--install-robust: the {structure} block does not build ({err}): "
                              "not installed") from None
