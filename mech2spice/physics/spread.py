"""Per-element spread of a mechanical model: the elements, a scaled copy, a random copy.

An *element* is one physical part a fabricated device could get wrong, each with its own value:
  * per DOF: its local stiffness (its spring to ground: total minus attached coupling springs),
    its mass, and its local damping (total minus attached coupling dashpots);
  * each coupling spring and each coupling dashpot;
  * each quadratic coupling gamma;
  * each drive amplitude.
Local values may be negative (reports/gate.md): a relative change scales them all the same way.
Totals are rebuilt from the scaled local parts and couplings, so changing one coupling spring moves
the total stiffness of both DOFs it joins, as it would in a device.

Used by the single-gate tolerance study (experiments/tolerance.py) and meant for a Monte-Carlo of
whole designs: `perturb(model, sigma, rng)` with no `dofs` spreads every element of the model.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..errors import Mech2SpiceError
from .model import Drive, MechModel

PER_DOF = ("k", "m", "c")


@dataclass(frozen=True)
class Element:
    """One physical part that fabrication can get wrong: its kind, its index in the model, a stable name."""
    kind: str        # "k", "m", "c" (per DOF), "spring", "dashpot", "gamma", "drive"
    index: int       # DOF index, or index into springs / dashpots / quads / drives
    name: str        # stable across models built the same way, e.g. "k gate.C", "spring in1.C-gate.G1s"


def elements(model: MechModel, dofs: list[int] | None = None) -> list[Element]:
    """Every element of `model`, or only those of the DOFs `dofs` (links touching one of them, quadratic
    couplings whose both ends are in it, drives on them), in build order."""
    keep = set(range(model.n)) if dofs is None else set(dofs)
    nm = model.names
    out = [Element(kind, i, f"{kind} {nm[i]}") for i in sorted(keep) for kind in PER_DOF]
    for kind, links in (("spring", model.springs), ("dashpot", model.dashpots)):
        out += [Element(kind, e, f"{kind} {nm[i]}-{nm[j]}") for e, (i, j, _) in enumerate(links)
                if i in keep or j in keep]
    out += [Element("gamma", e, f"gamma {nm[f]}-{nm[s]}") for e, (f, s, _) in enumerate(model.quads)
            if f in keep and s in keep]
    out += [Element("drive", e, f"drive {d.name}") for e, d in enumerate(model.drives) if d.dof in keep]
    return out


def scaled(model: MechModel, elems: list[Element], factors: np.ndarray) -> MechModel:
    """A copy of `model` with element elems[k] multiplied by factors[k] (the rest unchanged)."""
    factors = np.asarray(factors, float)
    if factors.shape != (len(elems),):
        raise Mech2SpiceError(f"spread: {len(elems)} elements but {factors.size} factors")
    f = {kind: np.ones(n) for kind, n in (("k", model.n), ("m", model.n), ("c", model.n),
                                         ("spring", len(model.springs)), ("dashpot", len(model.dashpots)),
                                         ("gamma", len(model.quads)), ("drive", len(model.drives)))}
    for el, x in zip(elems, factors):
        f[el.kind][el.index] *= x
    springs = [(i, j, k * x) for (i, j, k), x in zip(model.springs, f["spring"])]
    dashpots = [(i, j, c * x) for (i, j, c), x in zip(model.dashpots, f["dashpot"])]
    return replace(
        model, names=list(model.names), slow=list(model.slow), probes=dict(model.probes),
        mass=list(np.asarray(model.mass) * f["m"]),
        k_total=list(_totals(model.k_local * f["k"], springs)),
        c_total=list(_totals(model.c_local * f["c"], dashpots)),
        springs=springs, dashpots=dashpots,
        quads=[(a, b, g * x) for (a, b, g), x in zip(model.quads, f["gamma"])],
        drives=[Drive(d.dof, d.amplitude * x, d.phase, d.name) for d, x in zip(model.drives, f["drive"])])


def _totals(local: np.ndarray, links) -> np.ndarray:
    """Totals = local part + every coupling attached (the inverse of MechModel._local)."""
    total = np.array(local, float)
    for i, j, k in links:
        total[i] += k
        total[j] += k
    return total


def draws(n_elements: int, samples: int, seed: int) -> np.ndarray:
    """Standard normal draws (samples, n_elements) from `seed`: one row per sample, so a sample keeps its
    draws whatever sigma it is scaled by (common random numbers across sigmas)."""
    return np.random.default_rng(seed).standard_normal((samples, n_elements))


def perturb(model: MechModel, sigma: float, rng: np.random.Generator,
            dofs: list[int] | None = None) -> MechModel:
    """A copy with an independent relative Gaussian spread (standard deviation `sigma`) on every element
    (or every element of `dofs`)."""
    elems = elements(model, dofs)
    return scaled(model, elems, 1.0 + sigma * rng.standard_normal(len(elems)))
