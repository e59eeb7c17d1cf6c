"""What limits the NOR block, measured: tolerance per element kind, with and without trimming, and the
elements that limit once trimmed (docs/robustness.md, "What limits the block"; issue #27).

For each block (--params, default: default robust), on the loaded gate (physics/loaded.py) over the
900-point valid input grid:

* linear: the margin gradients of every grid point (physics/sensitivity.py margin_gradients), mapped
  through the trim (physics/spread.py trim_map, sigmas); tolerance = min over points of
  margin / (2.326 ||sigmas * J^T g||), sigmas at a unit spread (trimmed coordinates 0: exact trim);
* sampled: the largest sigma with >= 99 % yield (experiments/tolerance.py bisection, same draws at every
  sigma), bracketed around the linear estimate ([lin / 4, 4 lin], ratio 1.3; once 16x lower if lin / 4
  fails), the kind alone spread by zeroing the other elements' draws;
* the limiting point after each trim and its largest contributions |sigma_j (J^T g)_j|;
* the residual a trim may leave (linear, spread 0) and the common-mode drift the nominal block survives
  (both signs, bisection on the steady-state margin).

    python scripts/robustness_decomposition.py [--params default robust] [--samples 20] [--json OUT]

Prints a markdown report; --json writes every number.  docs/robustness.md's tables: --samples 40, 19 min
for both blocks on the shared 2-core sandbox under a load of about 7; --samples 20 about half that.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time

import numpy as np

from mech2spice.experiments import tolerance
from mech2spice.physics import loaded, sensitivity, spread, steady_batch
from mech2spice.physics.params import load_params

Z99 = 2.3263478740408408            # one-sided 99 %
KINDS = {"all": None, "local k": "k", "m": "m", "local c": "c", "coupling springs": "spring",
         "coupling dashpots": "dashpot", "gammas": "gamma", "drive F_C": "drive"}
BRACKET, RESOLUTION = 4.0, 1.3      # sampled bisection: [lin / BRACKET, lin * BRACKET], stop at this ratio
TOP = 6                             # contributions listed per trim


def gradients(p) -> dict:
    """Margins and margin gradients (elements only, omega dropped) of every valid grid point."""
    lg = loaded.build(p)
    elems = sensitivity.spread_elements(lg)
    levels, expect = loaded.input_grid()
    g = sensitivity.margin_gradients(p, lg, elems, levels, expect, steady_batch.N_GRID)
    return {"lg": lg, "elems": elems, "levels": levels, "margin": g["margin"], "grad": g["margin_grad"][:, :-1]}


def unit_std(g: dict, mask: np.ndarray, trim: str) -> np.ndarray:
    """Per point: the margin's standard deviation at a unit spread of the masked elements, after `trim`
    (exact); the trimmed coordinates carry no spread."""
    J = spread.trim_map(g["lg"].model, g["elems"], trim)
    s = spread.sigmas(g["elems"], g["lg"].model, 1.0, trim, 0.0) * mask
    return np.linalg.norm((g["grad"] @ J) * s, axis=1)


def linear_tolerance(g: dict, mask: np.ndarray, trim: str = "none") -> float:
    """min over points of margin / (2.326 std)."""
    std = unit_std(g, mask, trim)
    with np.errstate(divide="ignore"):
        return float(np.min(np.where(std > 0, g["margin"] / (Z99 * std), np.inf)))


def residual_limit(g: dict, trim: str) -> float:
    """The largest trim residual the block keeps 99 % under with no other spread (linear)."""
    J = spread.trim_map(g["lg"].model, g["elems"], trim)
    s = spread.sigmas(g["elems"], g["lg"].model, 0.0, trim, 0.5) / 0.5    # 1 at the trimmed coordinates
    std = np.linalg.norm((g["grad"] @ J) * s, axis=1)
    return float(np.min(g["margin"] / (Z99 * std)))


def limiting(g: dict, trim: str) -> dict:
    """The limiting point after `trim` (all elements spread) and its largest contributions."""
    J = spread.trim_map(g["lg"].model, g["elems"], trim)
    contrib = (g["grad"] @ J) * spread.sigmas(g["elems"], g["lg"].model, 1.0, trim, 0.0)
    std = np.linalg.norm(contrib, axis=1)
    k = int(np.argmin(g["margin"] / std))
    order = np.argsort(-np.abs(contrib[k]))[:TOP]
    return {"inputs": g["levels"][k, 1:].round(4).tolist(), "margin": float(g["margin"][k]),
            "std_per_unit_sigma": float(std[k]),
            "top": [(g["elems"][j].name, float(contrib[k, j])) for j in order]}


def sampled_tolerance(p, samples: int, seed: int, mask: np.ndarray, trim: str, lin: float, log) -> dict:
    """The bisection of experiments/tolerance.py, draws of the unmasked elements zeroed."""
    s = tolerance.Sampler(p, samples, seed, trim=trim)
    s.eps[:, ~mask] = 0.0
    hi = min(lin * BRACKET, 0.5)
    res = tolerance.tolerance(s, lo=hi / BRACKET ** 2, hi=hi, resolution=RESOLUTION, log=log)
    if res["sigma"] is None:             # below the bracket: one more, a factor BRACKET^2 lower
        hi /= BRACKET ** 2
        res = tolerance.tolerance(s, lo=hi / BRACKET ** 2, hi=hi, resolution=RESOLUTION, log=log)
    return {"sigma": res["sigma"], "bracket": res["bracket"], "samples": samples,
            "allowed_failures": res["allowed_failures"], "note": res.get("note")}


def drift_window(p, log) -> dict:
    """The largest common-mode drift of each sign at which the nominal loaded gate keeps a positive margin
    (bisection on log |drift| from [1e-7, 1e-1] to a ratio of 1.05)."""
    def ok(d: float) -> bool:
        s = tolerance.Sampler(p, 1, 0, drift=d)
        s.eps[:] = 0.0                   # sample 0 with no spread: the nominal gate, drifted
        return float(s.margins(s.model(0.0, 0)).min()) > 0
    out = {}
    for sign, key in ((1, "+"), (-1, "-")):
        lo, hi = 1e-7, 1e-1
        if not ok(sign * lo) or ok(sign * hi):
            out[key] = None
            continue
        while hi / lo > 1.05:
            mid = math.sqrt(lo * hi)
            lo, hi = (mid, hi) if ok(sign * mid) else (lo, mid)
        out[key] = lo
        log(f"drift {key}: window {lo:.3g}")
    return out


def block(name: str, samples: int, seed: int, log) -> dict:
    """Every number of one block."""
    p = load_params(name)
    t0 = time.time()
    g = gradients(p)
    log(f"{name}: gradients of {g['margin'].size} points in {time.time() - t0:.0f} s")
    kinds = np.array([e.kind for e in g["elems"]])
    rows = {}
    for label, kind in KINDS.items():
        mask = np.ones(kinds.size, bool) if kind is None else kinds == kind
        lin = linear_tolerance(g, mask)
        log(f"{name} {label}: linear {lin:.3g}")
        rows[label] = {"count": int(mask.sum()), "linear": lin,
                       "sampled": sampled_tolerance(p, samples, seed, mask, "none", lin, log)}
    trims = {}
    everything = np.ones(kinds.size, bool)
    for trim in ("f", "fc"):
        lin = linear_tolerance(g, everything, trim)
        log(f"{name} trim {trim}: linear {lin:.3g}")
        trims[trim] = {"linear": lin, "sampled": sampled_tolerance(p, samples, seed, everything, trim, lin, log),
                       "limiting": limiting(g, trim), "residual_limit": residual_limit(g, trim)}
    return {"params": name, "nominal_margin": float(g["margin"].min()), "kinds": rows, "trims": trims,
            "untrimmed_limiting": limiting(g, "none"), "drift_window": drift_window(p, log),
            "wall_s": time.time() - t0}


def fmt(x) -> str:
    return "-" if x is None else f"{x:.2g}"


def sampled_text(s: dict) -> str:
    lo, hi = s["bracket"]
    if s["sigma"] is None:
        return f"< {fmt(hi)}"
    return f"> {fmt(lo)}" if hi is None else f"{fmt(lo)} .. {fmt(hi)}"


def markdown(res: list[dict], samples: int, seed: int) -> str:
    lines = [f"Loaded gate, 900-point valid grid; sampled: {samples} samples, seed {seed}, bisection ratio "
             f"{RESOLUTION} (a sampled bracket 'a .. b': a passes, b fails).", ""]
    head = " | ".join(f"{r['params']}: linear | {r['params']}: sampled" for r in res)
    lines += [f"| kind spread alone | {head} |", "|---" * (1 + 2 * len(res)) + "|"]
    for label in KINDS:
        cells = " | ".join(f"{fmt(r['kinds'][label]['linear'])} | {sampled_text(r['kinds'][label]['sampled'])}"
                           for r in res)
        lines.append(f"| {label} | {cells} |")
    lines += ["", "| block | no trim (linear) | f, linear | f, sampled | fc, linear | fc, sampled | "
                  "residual limit f / fc (linear) |", "|---|---|---|---|---|---|---|"]
    for r in res:
        t = r["trims"]
        lines.append(f"| {r['params']} | {fmt(r['kinds']['all']['linear'])} | {fmt(t['f']['linear'])} | "
                     f"{sampled_text(t['f']['sampled'])} | {fmt(t['fc']['linear'])} | "
                     f"{sampled_text(t['fc']['sampled'])} | {fmt(t['f']['residual_limit'])} / "
                     f"{fmt(t['fc']['residual_limit'])} |")
    lines.append("")
    for r in res:
        for trim, lim in (("none", r["untrimmed_limiting"]), ("f", r["trims"]["f"]["limiting"]),
                          ("fc", r["trims"]["fc"]["limiting"])):
            top = ", ".join(f"{n} {v:+.3g}" for n, v in lim["top"])
            lines.append(f"- {r['params']}, trim {trim}: limiting point {lim['inputs']} (margin "
                         f"{lim['margin']:+.3f}): {top}")
        d = r["drift_window"]
        lines.append(f"- {r['params']}: nominal margin {r['nominal_margin']:+.4f}; drift window "
                     f"+{fmt(d['+'])} / -{fmt(d['-'])} (no spread); {r['wall_s']:.0f} s")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--params", nargs="+", default=["default", "robust"])
    ap.add_argument("--samples", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", metavar="OUT")
    a = ap.parse_args(argv)
    log = lambda msg: print(msg, file=sys.stderr, flush=True)      # noqa: E731
    res = [block(name, a.samples, a.seed, log) for name in a.params]
    if a.json:
        with open(a.json, "w") as f:
            json.dump(res, f, indent=1)
    print(markdown(res, a.samples, a.seed))
    return 0


if __name__ == "__main__":
    sys.exit(main())
