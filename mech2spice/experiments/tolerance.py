"""Tolerance of the NOR gate to element spread: yield, margin quantiles, the largest sigma at 99 % yield.

A sample is the loaded gate (physics/loaded.py) with an independent relative Gaussian spread on every
element of its block (physics/spread.py).  It passes when its margin over the valid input region is
> 0: the worst, over the input grid of both bands (both inputs), of the distance of every stable steady
state to the edge of the band NOR asks for (fraction of a band width); an input point with no stable
steady state counts -1.  A second stable state outside the band therefore fails the point (the
multistability that leaves a band); two stable states both inside it do not.  This is
characterise.valid_region_margin, which scores every multistable point -1, except for that last case.
Steady states come from the batched all-roots scan (physics/steady_batch.py); `rk4_check` compares a
few samples with RK4 from rest.
"""
from __future__ import annotations

import math
import time

import numpy as np

from ..errors import Mech2SpiceError
from ..physics import context, loaded, spread, steady_batch
from ..physics.loaded import band_margin, input_grid, point_margins
from ..physics.params import GateParams

QUANTILES = (1, 5, 50, 95, 99)   # percent
TARGET_YIELD = 0.99
SIGMA_RANGE = (1e-7, 1e-1)       # the tolerance bisection's initial bracket
RESOLUTION = 1.1                 # the bisection stops when the bracket spans less than this ratio
Z95 = 1.959963984540054


class Sampler:
    """Loaded-gate samples with a fixed set of standard normal draws (common random numbers)."""

    def __init__(self, p: GateParams, samples: int, seed: int, per_band: int = loaded.PER_BAND,
                 n_grid: int = steady_batch.N_GRID, trim: str = "none", residual: float = 0.0, drift: float = 0.0):
        if samples < 1:
            raise Mech2SpiceError(f"--samples must be at least 1, got {samples}")
        spread.check_trim(trim, residual)
        self.p, self.seed, self.n_grid = p, seed, n_grid
        self.trim, self.residual, self.drift = trim, residual, drift
        self.base = loaded.build(p)
        self.elements = spread.elements(self.base.model, self.base.block_dofs)
        self.eps = spread.draws(len(self.elements), samples, seed)
        self.levels, self.expect = input_grid(per_band, p.levels)

    def model(self, sigma: float, i: int | None):
        """Sample i at spread sigma (None: the nominal gate)."""
        if i is None:
            return self.base.model
        return self.finished(self.base.model, self.elements, spread.scaled(self.base.model, self.elements,
                                                                           1.0 + sigma * self.eps[i]), i)

    def finished(self, nominal, elems, model, i: int):
        """Sample i's spread `model` trimmed (its own residual draws) and drifted, as in service."""
        model = spread.trimmed(model, nominal, elems, self.trim, self.residual, spread.trim_rng(self.seed, i),
                               params=self.p, balance_point=context.balance_point(self.p) if self.trim == "fcb" else None)
        return spread.drifted(model, self.drift)

    def margins(self, model) -> np.ndarray:
        """Per-point margins of one model of the loaded gate's topology."""
        st = steady_batch.stack([model], self.base.input_groups(), self.base.gate.channel)
        r = steady_batch.roots(st, 0, self.levels, self.n_grid)
        return point_margins(r, self.expect, self.p.u_r, self.p.levels)

    def run(self, sigma: float, max_failures: int | None = None) -> dict:
        """Margin of every sample at sigma; stops early once more than max_failures samples failed."""
        worst, at, fails = [], [], 0
        for i in range(self.eps.shape[0]):
            m = self.margins(self.model(sigma, i))
            worst.append(float(m.min()))
            at.append(int(m.argmin()))
            fails += worst[-1] <= 0
            if max_failures is not None and fails > max_failures:
                break
        return {"margins": np.array(worst), "worst_point": np.array(at), "complete": len(worst) == self.eps.shape[0]}


def wilson(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval for k successes in n trials."""
    if n == 0:
        return 0.0, 1.0
    ph = k / n
    c = (ph + z * z / (2 * n)) / (1 + z * z / n)
    half = z / (1 + z * z / n) * math.sqrt(ph * (1 - ph) / n + z * z / (4 * n * n))
    return max(0.0, c - half), min(1.0, c + half)


def yield_at(sampler: Sampler, sigma: float) -> dict:
    """Yield, its Wilson 95 % interval and margin quantiles at one sigma (every sample evaluated)."""
    res = sampler.run(sigma)
    m = res["margins"]
    k = int(np.sum(m > 0))
    return {"sigma": sigma, "yield": k / m.size, "yield_ci95": list(wilson(k, m.size)), "passed": k,
            "samples": int(m.size), "margin_quantiles": {f"{q}%": float(np.percentile(m, q)) for q in QUANTILES},
            "margins": m, "worst_point": res["worst_point"]}


def tolerance(sampler: Sampler, target: float = TARGET_YIELD, lo: float = SIGMA_RANGE[0],
              hi: float = SIGMA_RANGE[1], resolution: float = RESOLUTION, log=lambda msg: None) -> dict:
    """Largest sigma with yield >= target: bisection on log sigma, same draws at every sigma.

    Returns the bracket [sigma_pass, sigma_fail] with sigma_fail / sigma_pass <= resolution."""
    n = sampler.eps.shape[0]
    allowed = int(math.floor((1 - target) * n + 1e-9))        # failures a passing sigma may have
    steps = []

    def passes(sigma: float) -> bool:
        res = sampler.run(sigma, max_failures=allowed)
        fails = int(np.sum(res["margins"] <= 0))
        ok = res["complete"] and fails <= allowed
        steps.append({"sigma": sigma, "pass": ok, "failures_seen": fails, "evaluated": int(res["margins"].size)})
        log(f"sigma {sigma:.3e}: {'pass' if ok else 'fail'} ({fails} failures in {res['margins'].size})")
        return ok

    out = {"target_yield": target, "samples": n, "allowed_failures": allowed, "resolution": resolution,
           "steps": steps}
    if not passes(lo):
        return {**out, "sigma": None, "bracket": [0.0, lo], "note": f"yield < {target} already at sigma {lo:g}"}
    if passes(hi):
        return {**out, "sigma": hi, "bracket": [hi, None], "note": f"yield >= {target} up to sigma {hi:g}"}
    while hi / lo > resolution:
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if passes(mid) else (lo, mid)
    return {**out, "sigma": lo, "bracket": [lo, hi]}


def study(p: GateParams, sigma: float, samples: int, seed: int, per_band: int = loaded.PER_BAND,
          n_grid: int = steady_batch.N_GRID, with_tolerance: bool = True, log=lambda msg: None,
          trim: str = "none", residual: float = 0.0, drift: float = 0.0) -> dict:
    """Everything `mech2spice gate --spread` reports (spread, then trim, then drift: physics/spread.py)."""
    if not (sigma >= 0 and math.isfinite(sigma)):
        raise Mech2SpiceError(f"--spread must be a finite sigma >= 0, got {sigma}")
    t0 = time.time()
    sampler = Sampler(p, samples, seed, per_band, n_grid, trim, residual, drift)
    nominal = sampler.margins(sampler.model(0.0, None))
    log(f"nominal margin {nominal.min():+.4f}; {samples} samples at sigma {sigma:g}")
    y = yield_at(sampler, sigma)
    out = {"sigma": sigma, "samples": samples, "seed": seed, "trim": trim, "trim_residual": residual, "drift": drift,
           "yield": y["yield"], "yield_ci95": y["yield_ci95"],
           "margin_quantiles": y["margin_quantiles"], "nominal_margin": float(nominal.min()),
           "elements_spread": [e.name for e in sampler.elements],
           "method": {"model": "loaded gate (physics/loaded.py, load='pair')", "grid_points": int(nominal.size),
                      "s_grid": n_grid, "steady_state": "batched all-roots scan + envelope stability"}}
    if with_tolerance:
        log("tolerance: bisection on log sigma")
        out["tolerance"] = tolerance(sampler, log=log)
    out["wall_s"] = time.time() - t0
    return out


# --- time-domain spot checks ---------------------------------------------------------------
def union(models: list, prefixes: list[str]):
    """One MechModel holding independent copies (DOF names prefixed), so one RK4 run covers all."""
    from ..physics.model import MechModel
    out = MechModel(omega=models[0].omega)
    for m, pre in zip(models, prefixes):
        base = out.n
        for i, name in enumerate(m.names):
            out.add_dof(pre + name, m.mass[i], m.k_total[i], m.c_total[i], m.slow[i])
        for i, j, k in m.springs:
            out.add_spring(base + i, base + j, k)
        for i, j, c in m.dashpots:
            out.add_dashpot(base + i, base + j, c)
        for f, s, g in m.quads:
            out.add_quad(base + f, base + s, g)
        for d in m.drives:
            out.add_drive(base + d.dof, d.amplitude, d.phase, pre + d.name)
    return out


def sample_at_point(sampler: Sampler, sigma: float, i: int, point: int, load: str = "gate"):
    """Sample i of `sampler` as a loaded gate with the given load, its inputs set to input point `point`
    (elements matched by name, so load="gate" gets the same draws as the sampler's load="pair")."""
    lg = loaded.build(sampler.p, load)
    elems = {e.name: e for e in spread.elements(lg.model, lg.block_dofs)}
    mine = [elems[e.name] for e in sampler.elements]
    model = sampler.finished(lg.model, mine, spread.scaled(lg.model, mine, 1.0 + sigma * sampler.eps[i]), i)
    return loaded.at_inputs(lg, *sampler.levels[point, 1:], model)


def rk4_check(sampler: Sampler, sigma: float, picks: list[tuple[int, int]], periods: int,
              load: str = "gate") -> list[dict]:
    """RK4 from rest of samples (i, input point) side by side; output amplitude (mean of the last 20
    periods) against every stable steady state there, and both margins."""
    from ..backends import rk4
    models = [sample_at_point(sampler, sigma, i, k, load) for i, k in picks]
    big = union(models, [f"s{n}/" for n in range(len(picks))])
    probes = [f"s{n}/{loaded.GATE}.C" for n in range(len(picks))]
    run = rk4.integrate(big, periods, probes=probes, blowup=1e3 * sampler.p.u_r)
    amp = np.abs(run.amp[-20:, :, 0]).mean(axis=0) / sampler.p.u_r
    out = []
    for n, (i, k) in enumerate(picks):
        st = steady_batch.stack([sampler.model(sigma, i)], sampler.base.input_groups(), sampler.base.gate.channel)
        r = steady_batch.roots(st, 0, sampler.levels[k:k + 1], sampler.n_grid)
        e = sampler.expect[k:k + 1]
        out.append({"sample": i, "point": k, "inputs": sampler.levels[k, 1:].tolist(), "rk4": float(amp[n]),
                    "steady": (r.amp[r.stable] / sampler.p.u_r).tolist(),
                    "margin_steady": float(point_margins(r, e, sampler.p.u_r, sampler.p.levels)[0]),
                    "margin_rk4": float(band_margin(amp[n:n + 1], e, sampler.p.levels)[0])})
    return out


# --- `mech2spice gate --sens / --spread` -------------------------------------------------------
def sensitivity_report(p: GateParams, log=lambda msg: None) -> dict:
    """The `sensitivity` JSON field (element -> derivatives) and its context, with a finite-difference check."""
    from ..physics import sensitivity
    t0 = time.time()
    log("sensitivities (implicit-function theorem on the loaded gate)")
    s = sensitivity.gate_sensitivity(p)
    unstable = [case for case, a in s["amplitudes"].items() if not np.isfinite(a)]
    if unstable:                         # no steady state to differentiate: the table would be NaN
        raise Mech2SpiceError(f"parameters '{p.name}': the loaded gate has no stable steady state at inputs "
                              f"{', '.join(unstable)}, so its sensitivities are undefined (it does not work as "
                              "a NOR gate there: `mech2spice gate` shows its truth table)")
    table = {}
    for k, name in enumerate(s["elements"]):
        row = {case: float(v[k]) for case, v in s["outputs"].items()}
        row["worst_margin"] = float(s["worst"]["gradient"][k])
        row["limiting_margin"] = float(s["limiting"]["gradient"][k])
        table[name] = row
    log("finite-difference check")
    info = {"units": "outputs 00/10/01/11: d(amplitude, u_R)/d(relative change); worst_margin, limiting_margin: "
                     "d(margin, band widths)/d(relative change)",
            "amplitudes": s["amplitudes"], "grid_points": s["grid_points"],
            "worst": {k: v for k, v in s["worst"].items() if k != "gradient"},
            "limiting": {k: v for k, v in s["limiting"].items() if k != "gradient"},
            "model": "loaded gate (physics/loaded.py, load='pair')",
            "fd_check": fd_check(p, s), "wall_s": time.time() - t0}
    return {"sensitivity": table, "sensitivity_info": info}


def fd_check(p: GateParams, s: dict, top: int = 6, h: float = 1e-6) -> dict:
    """Central finite differences (relative step h) of the 00 and 11 outputs for the `top` largest elements:
    the largest relative disagreement with the implicit-function derivatives."""
    from dataclasses import replace
    from ..physics import sensitivity
    lg = loaded.build(p)
    elems = sensitivity.spread_elements(lg)
    worst = 0.0
    for case, (x1, x2) in (("00", (0.5, 0.5)), ("11", (0.97, 0.97))):
        base = loaded.at_inputs(lg, x1, x2)
        grad = s["outputs"][case]
        for j in np.argsort(-np.abs(grad))[:top]:
            amps = []
            for sign in (1, -1):
                if j == len(elems):
                    m = replace(base, omega=base.omega * (1 + sign * h))
                else:
                    m = spread.scaled(base, elems, 1 + sign * h * (np.arange(len(elems)) == j))
                st = steady_batch.stack([m], lg.input_groups(), lg.gate.channel)
                r = steady_batch.roots(st, 0, np.ones((1, 3)))
                amps.append(r.amp[r.stable][0] / p.u_r)
            fd = (amps[0] - amps[1]) / (2 * h)
            worst = max(worst, abs(fd - grad[j]) / abs(fd))
    return {"elements_checked": 2 * top, "step": h, "max_relative_error": worst}


# what extreme but finite parameters raise inside the linear algebra (a matrix overflowing to inf, a float
# power beyond the double range; numpy's overflow, 0/0 and x/0, raised instead of warned: the shipped blocks
# and spreads up to sigma 1 raise none): bad input, reported as such, not a bug
NUMERIC_FAILURES = (np.linalg.LinAlgError, OverflowError, FloatingPointError, ZeroDivisionError)


def robustness(p: GateParams, sens: bool, sigma: float | None, samples: int, seed: int,
               log=lambda msg: None, trim: tuple = ("none", 0.0, 0.0)) -> dict:
    """What `mech2spice gate --sens` and/or `--spread SIGMA` print; trim = (mode, residual, drift)."""
    out: dict = {"params": p.to_dict()}
    try:
        with np.errstate(over="raise", invalid="raise", divide="raise"):
            if sens:
                out.update(sensitivity_report(p, log))
            if sigma is not None:
                out.update(study(p, sigma, samples, seed, log=log, trim=trim[0], residual=trim[1], drift=trim[2]))
    except NUMERIC_FAILURES as err:
        raise Mech2SpiceError(f"parameters '{p.name}': the steady-state analysis failed numerically "
                              f"({type(err).__name__}: {err}); a parameter is far outside the range the gate "
                              "model can be computed in") from None
    return out


def text(out: dict, top: int = 12) -> str:
    """Human-readable summary of `robustness`."""
    lines = [f"parameters: {out['params']['name']}"]
    if "sensitivity" in out:
        info = out["sensitivity_info"]
        w, lim = info["worst"], info["limiting"]
        lines.append(f"worst margin {w['margin']:+.4f} at inputs {w['inputs']}; limiting point {lim['inputs']} "
                     f"(margin {lim['margin']:+.4f}, |gradient| {lim['gradient_norm']:.3g}, "
                     f"margin/|gradient| = {lim['sigma_1']:.2e})")
        lines.append(f"{'element':32s} {'00':>10s} {'10':>10s} {'01':>10s} {'11':>10s} {'worst':>10s} {'limiting':>10s}")
        rows = sorted(out["sensitivity"].items(), key=lambda kv: -abs(kv[1]["limiting_margin"]))
        for name, r in rows[:top]:
            lines.append(f"{name:32s} " + " ".join(f"{r[c]:+10.3g}" for c in
                                                   ("00", "10", "01", "11", "worst_margin", "limiting_margin")))
        lines.append(f"(amplitudes: u_R per relative change; margins: band widths per relative change; "
                     f"finite-difference check: max relative error {info['fd_check']['max_relative_error']:.1e})")
    if "yield" in out:
        lo, hi = out["yield_ci95"]
        q = out["margin_quantiles"]
        if out["trim"] != "none" or out["drift"]:
            lines.append(f"trim {out['trim']} (residual {out['trim_residual']:g}), drift {out['drift']:+g}")
        lines.append(f"sigma {out['sigma']:g}, {out['samples']} samples, seed {out['seed']}: yield {out['yield']:.3f} "
                     f"(95 % Wilson {lo:.3f} ... {hi:.3f}); nominal margin {out['nominal_margin']:+.4f}")
        lines.append("margin quantiles: " + ", ".join(f"{k} {v:+.3f}" for k, v in q.items()))
        t = out.get("tolerance")
        if t:
            lines.append(f"tolerance (yield >= {t['target_yield']:.0%}, {t['samples']} samples): "
                         + (f"sigma {t['sigma']:.3g} (bracket {t['bracket'][0]:.3g} ... {t['bracket'][1]:.3g})"
                            if t.get("sigma") and t["bracket"][1] else t.get("note", "")))
    return "\n".join(lines)
