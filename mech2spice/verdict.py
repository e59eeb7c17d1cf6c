"""The one rule that makes a physical run's bits `valid`: inside a band, at a stable fixed point, settled onto it.

After a run, and after each clock cycle, the network's state is refined by Newton's method to the nearest
fixed point of the envelope equations, and the leading eigenvalues of the equations linearised there are
computed (physics/stability.py).  A bit is valid only if

1. its amplitude now lies inside a logic band,
2. the fixed point is stable (no eigenvalue with a positive real part: no self-oscillating mode), and
3. the fixed point's amplitude lies inside the same band: the run did not stop while drifting out of it.

So a run that froze a snapshot of a self-oscillating network, or stopped while an output was still moving
towards another band, is not valid, whatever its amplitude reads.  Every physical engine goes through this
rule; the circuit simulators, which return no state, are judged at the envelope's state for the same
stimulus (`stability_from`).  docs/stability.md: the physics and the case that needed it (ISCAS-89 s344).
"""
from __future__ import annotations

import numpy as np

from .physics import stability
from .physics.params import DEFAULT_LEVELS, Levels

SETTLED_BW = 0.005     # band widths: an output with less than this still to come has settled (its margin
                       # is then within this of the long run's)
AVERAGING_ERROR = 2.5e-3   # u_R: how far an oscillator-level steady state may lie from the envelope's fixed
                           # point (1.8e-3 at the steepest inputs, docs/vacask.md; 0.9-2.3e-3 measured on the
                           # 3-input majority)


def band_width(x: float, levels: Levels = DEFAULT_LEVELS) -> float:
    """The width of the band x lies in (u_R), or of the narrower band when x lies in neither."""
    w0, w1 = levels.width(0), levels.width(1)
    b = levels.band_of(x)
    return w0 if b == 0 else w1 if b == 1 else min(w0, w1)


def judge(model, A: np.ndarray, s: np.ndarray, F: np.ndarray, outs: list[str],
          start: np.ndarray | None = None) -> stability.Verdict:
    """The stability verdict of one batch member's state (A (n_fast,), s, forcing F), watching `outs` and
    every gate's channel; `start`: the member's previous verdict's eigenvectors (stability.verdict)."""
    watch = {n: model.probes[n] for n in outs}
    watch.update({f"{g.name}.C": g.channel for g in model.design.gates})
    return stability.verdict(model, A, s, F, watch, start=start)


def drift(v: stability.Verdict, amplitudes: dict[str, float], levels: Levels = DEFAULT_LEVELS) -> float:
    """Largest distance of an output from its fixed point, in band widths."""
    return max((abs(a - v.fixed[n]) / band_width(a, levels) for n, a in amplitudes.items() if n in v.fixed), default=0.0)


def still_to_come(v: stability.Verdict, amplitudes: dict[str, float], swing: dict[str, float],
                  step: dict[str, float], lag: float, levels: Levels = DEFAULT_LEVELS) -> float:
    """Largest change still to come of an output, in band widths, from its own recent motion: the larger of
    its swing over the last `lag` periods (a ringing mode: what is left is at most that) and its drift,
    the change of its `lag`-period mean from the one before, carried on by the slowest decaying mode
    (the geometric tail r / (1 - r), r = e^(-lag / decay))."""
    if not np.isfinite(v.slowest_decay):
        return float("inf")
    r = np.exp(-lag / max(v.slowest_decay, 1e-9))
    return max((max(swing[n], step[n] * r / (1 - r)) / band_width(a, levels) for n, a in amplitudes.items()
                if n in swing), default=0.0)


def settled(v: stability.Verdict, amplitudes: dict[str, float], swing: dict[str, float], step: dict[str, float],
            lag: float, on_fixed_point: bool, held: bool = False, levels: Levels = DEFAULT_LEVELS) -> bool:
    """Stable, and less than SETTLED_BW band widths still to come on every output.  An engine that rests
    exactly on the envelope equations' fixed points (`on_fixed_point`: their RK4 steps) is as far from
    settled as its distance from the fixed point (and a run that held a snapshot of a moving network is far
    from it); an oscillator-level run's steady state differs from that fixed point by the averaging error
    (~2e-3 u_R), and an exponential step's by its local error, so for those the trend of their own
    amplitudes is used, unless idle skipping `held` the state (a held state's trend is flat whatever it is):
    then it must lie within the averaging error of the fixed point."""
    if not v.stable:
        return False
    if on_fixed_point:
        return drift(v, amplitudes, levels) <= SETTLED_BW
    if held:          # idle skipping held the state: its flat trend says nothing, so how far it is from rest
        return all(abs(a - v.fixed[n]) <= SETTLED_BW * band_width(a, levels) + AVERAGING_ERROR
                   for n, a in amplitudes.items() if n in v.fixed)
    return still_to_come(v, amplitudes, swing, step, lag, levels) <= SETTLED_BW


def apply(decoded: dict, amplitudes: dict[str, float], v: stability.Verdict | None, settled_now: bool,
          source: str = "run", levels: Levels = DEFAULT_LEVELS) -> dict:
    """`decoded` (bits, valid, min_margin) with the rule applied and the verdict's fields added."""
    if v is None:
        return decoded
    band_of = levels.band_of
    same = all(band_of(v.fixed[n]) == band_of(a) for n, a in amplitudes.items() if n in v.fixed)
    fixed_margin = [levels.margin(v.fixed[n], band_of(a)) for n, a in amplitudes.items()
                    if n in v.fixed and band_of(a) is not None]
    fields = {**v.to_json(), "settled": settled_now,
              "fixed_point_margin": float(min(fixed_margin)) if fixed_margin else None,
              "output_drift_bw": drift(v, amplitudes, levels), "stability_from": source}
    return {**decoded, "valid": bool(decoded["valid"] and v.stable and same), "stable": v.stable,
            "settled": settled_now, "stability": fields}
