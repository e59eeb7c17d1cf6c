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

Trimming (docs/robustness.md, "Trimming"): after fabrication each oscillating DOF's total k/m ("f"),
and optionally its total c/m ("fc"), is set back to nominal through its own local spring (dashpot),
with a relative Gaussian residual error.  Masses, couplings, gammas, drives and the slow (insulator)
DOFs keep their spread.  `trimmed` does it to one sampled model; `trim_map` and `sigmas` give the
same thing linearised, for worst-case distances: element changes t = J u with independent u_j of
standard deviation sigmas[j].  `drifted` is the common-mode temperature drift applied in service.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..errors import Mech2SpiceError
from .model import Drive, MechModel

PER_DOF = ("k", "m", "c")
TRIMS = ("none", "f", "fc", "fcb")   # nothing; total k/m; total k/m and c/m; fc plus each input pair's balance
LINEAR_TRIMS = ("none", "f", "fc")   # the trims trim_map linearises (design centering's)


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


# --- trimming and drift ------------------------------------------------------------------------------
def check_trim(mode: str, residual: float) -> None:
    """Refuse an unknown trim mode or a residual outside [0, 1) (or a residual with nothing trimmed)."""
    if mode not in TRIMS:
        raise Mech2SpiceError(f"trim must be one of {', '.join(TRIMS)}, got {mode!r}")
    if isinstance(residual, bool) or not isinstance(residual, (int, float)) or not 0 <= residual < 1:
        raise Mech2SpiceError(f"trim residual must be a number in [0, 1), got {residual!r}")
    if mode == "none" and residual:
        raise Mech2SpiceError("a trim residual needs a trim (f, fc or fcb)")


def trim_rng(seed: int, index: int) -> np.random.Generator:
    """Sample `index`'s generator for its trim residuals: apart from its spread draws, so a run without a
    trim draws exactly what it drew before trims existed."""
    return np.random.default_rng([seed, index, 0x7472])


def trimmed_dofs(model: MechModel, elems: list[Element]) -> list[int]:
    """The DOFs a trim adjusts: every oscillating (not slow) DOF whose local stiffness is among `elems`."""
    return [e.index for e in elems if e.kind == "k" and not model.slow[e.index]]


def trimmed(model: MechModel, nominal: MechModel, elems: list[Element], mode: str, residual: float,
            rng: np.random.Generator, params=None, balance_point: float | None = None) -> MechModel:
    """`model` (a spread copy of `nominal`) after trimming: each trimmed DOF's total k set so that k/m is
    nominal times (1 + residual z), with "fc" its total c likewise for c/m.  Totals minus the (spread)
    couplings are the local parts, so this sets the local spring and dashpot, as a trim would.

    "fcb" is "fc" with each input pair balanced at insulator position `balance_point` (`balanced`;
    physics/context.balance_point gives the block's; `params`: the block, where nominal.params is not set).

    Draws 2 x len(trimmed DOFs) normals from rng (k row, then c row) whatever the mode, so "f", "fc" and
    "fcb" share their k residuals ("fcb" draws its pairs' residuals after them)."""
    check_trim(mode, residual)
    if mode == "none":
        return model
    dofs = trimmed_dofs(model, elems)
    z = rng.standard_normal((2, len(dofs)))
    m, m0 = np.asarray(model.mass, float)[dofs], np.asarray(nominal.mass, float)[dofs]
    k = np.array(model.k_total, float)
    k[dofs] = m * np.asarray(nominal.k_total, float)[dofs] / m0 * (1 + residual * z[0])
    c = np.array(model.c_total, float)
    if mode in ("fc", "fcb"):
        c[dofs] = m * np.asarray(nominal.c_total, float)[dofs] / m0 * (1 + residual * z[1])
    out = _copy(model, k_total=list(k), c_total=list(c))
    if mode == "fcb":
        if balance_point is None:
            raise Mech2SpiceError("trim fcb needs the block's balance point (physics/context.balance_point)")
        out = balanced(out, nominal, set(dofs), residual, rng, k, balance_point, params)
    return out


# --- the input pairs' balance (trim "fcb", issue #36) ------------------------------------------------
@dataclass(frozen=True)
class InputPair:
    """One gate input: its spring-linked and dashpot-linked oscillators and their links' indices."""
    channel: int
    spring_dof: int
    dashpot_dof: int
    spring: int       # index into model.springs
    dashpot: int      # index into model.dashpots


def input_pairs(model: MechModel, params=None) -> list[InputPair]:
    """Every gate input of `model` linked by one spring and one dashpot from the same channel (the classic
    input pair), found by the structure's DOF names (prefix.G1s / prefix.G1d) of `params` (default
    model.params)."""
    p = params or model.params
    if p is None:
        return []
    pins = [tuple(a.dof for a in pin) for pin in p.structure.inputs]
    kinds = [tuple(a.link for a in pin) for pin in p.structure.inputs]
    spring_of = {j: (e, i) for e, (i, j, _) in enumerate(model.springs)}
    dashpot_of = {j: (e, i) for e, (i, j, _) in enumerate(model.dashpots)}
    index = {name: i for i, name in enumerate(model.names)}
    out = []
    for pin, kind in zip(pins, kinds):
        if sorted(kind) != ["dashpot", "spring"]:
            continue
        s_name, d_name = (pin if kind[0] == "spring" else pin[::-1])
        for name, i in index.items():
            prefix, _, local = name.rpartition(".")
            if local != s_name or f"{prefix}.{d_name}" not in index:
                continue
            d = index[f"{prefix}.{d_name}"]
            if i in spring_of and d in dashpot_of and spring_of[i][1] == dashpot_of[d][1]:
                out.append(InputPair(spring_of[i][1], i, d, spring_of[i][0], dashpot_of[d][0]))
    return out


def balanced(model: MechModel, nominal: MechModel, trimmed_set: set[int], residual: float,
             rng: np.random.Generator, k_target: np.ndarray, s_t: float, params=None) -> MechModel:
    """`model` (spread and fc-trimmed to totals `k_target`) with every input pair balanced, so that the pair's
    two back-actions on the channel that drives it cancel at the detuning its own gate's insulator gives it
    (docs/robustness.md, "The balance trim"):
      * each pair oscillator's k/m is trimmed with its insulator held at s_t (context.balance_point: the block's
        position with both inputs '0', where a load's insulator sits when it fails its driver), not at rest
        (`_detuned_totals`);
      * the spring link is trimmed so that k_link^2 / m_s = (omega c_link)^2 / m_d as in the nominal pair
        (`_matched_springs`), through the link's own beam; the two oscillators' totals stay trimmed.
    Each pair draws one normal from rng for its link, in pair order."""
    p = params or nominal.params
    pairs = input_pairs(nominal, p)
    if not pairs:
        raise Mech2SpiceError("trim fcb balances input pairs linked by one spring and one dashpot; "
                              "this model has none")
    z_link = rng.standard_normal(len(pairs))
    k = _detuned_totals(model, nominal, pairs, trimmed_set, k_target, s_t)
    return _copy(model, k_total=list(k), springs=_matched_springs(model, nominal, pairs, residual * z_link))


def _detuned_totals(model, nominal, pairs, trimmed_set, k_target, s_t) -> np.ndarray:
    """k_target with each trimmed pair oscillator's total k set so that (k + 2 gamma s_t) / m is nominal's,
    gamma its own coupling to its insulator, keeping the fc trim's residual (k_target = m k0 / m0 (1 + r))."""
    gamma, gamma0 = _pair_gammas(model, nominal)
    m, m0 = np.asarray(model.mass, float), np.asarray(nominal.mass, float)
    k0 = np.asarray(nominal.k_total, float)
    k = np.array(k_target, float)
    for d in {d for q in pairs for d in (q.spring_dof, q.dashpot_dof)} & trimmed_set:
        error = k[d] * m0[d] / (m[d] * k0[d])            # the fc trim's 1 + residual z
        k[d] = error * m[d] * (k0[d] + 2 * gamma0[d] * s_t) / m0[d] - 2 * gamma[d] * s_t
    return k


def _matched_springs(model, nominal, pairs, errors) -> list:
    """model.springs with each pair's spring link set to omega c_link sqrt(m_s / m_d) times nominal's ratio
    (1 for the classic block) times (1 + error): the two branches' reactions k_l^2 / (m_s z) and
    (omega c_l)^2 / (m_d z) then cancel wherever the two oscillators' z = Z / m agree."""
    m, m0, w = np.asarray(model.mass, float), np.asarray(nominal.mass, float), model.omega
    springs = list(model.springs)
    for q, err in zip(pairs, errors):
        i, j, k_link0 = nominal.springs[q.spring]
        ratio0 = k_link0 * np.sqrt(m0[q.dashpot_dof] / m0[q.spring_dof]) / (w * nominal.dashpots[q.dashpot][2])
        c_link = model.dashpots[q.dashpot][2]
        springs[q.spring] = (i, j, ratio0 * w * c_link * np.sqrt(m[q.spring_dof] / m[q.dashpot_dof]) * (1 + err))
    return springs


def _pair_gammas(model: MechModel, nominal: MechModel) -> tuple[np.ndarray, np.ndarray]:
    """Per DOF: its coupling to an insulator in `model` and in `nominal` (0 where it has none)."""
    out = []
    for m in (model, nominal):
        g = np.zeros(m.n)
        for f, _, v in m.quads:
            g[f] = v
        out.append(g)
    return out[0], out[1]


def check_drift(rel: float) -> None:
    """Refuse a drift that is not a relative change in (-1, 1)."""
    if isinstance(rel, bool) or not isinstance(rel, (int, float)) or not -1 < rel < 1:
        raise Mech2SpiceError(f"drift must be a relative change in (-1, 1), got {rel!r}")


def drifted(model: MechModel, rel: float) -> MechModel:
    """Every stiffness (each DOF's local spring, slow ones included, and each coupling spring) times
    (1 + rel): a common-mode temperature drift of the Young's modulus."""
    check_drift(rel)
    if not rel:
        return model
    return _copy(model, k_total=[k * (1 + rel) for k in model.k_total],
                 springs=[(i, j, k * (1 + rel)) for i, j, k in model.springs])


def _copy(model: MechModel, **changes) -> MechModel:
    """A copy with its own lists (nothing shared with `model`) and the given fields replaced."""
    base = dict(names=list(model.names), slow=list(model.slow), probes=dict(model.probes), mass=list(model.mass),
                k_total=list(model.k_total), c_total=list(model.c_total), springs=list(model.springs),
                dashpots=list(model.dashpots), quads=list(model.quads), drives=list(model.drives))
    return replace(model, **{**base, **changes})


def trim_map(model: MechModel, elems: list[Element], mode: str) -> np.ndarray:
    """J with element relative changes t = J u, linearised about `model` (nominal).  u is t except at
    a trimmed DOF's "k" element (u: the relative error of its total k/m) and, with "fc", its "c"
    element (of c/m): there the local part is what the trim leaves,
        t_k = (K (u_k + u_m) - sum of the DOF's spread springs k_s u_s) / k_local,  likewise c."""
    check_trim(mode, 0.0)
    if mode not in LINEAR_TRIMS:
        raise Mech2SpiceError(f"trim {mode!r} is not linearised (design centering takes {', '.join(LINEAR_TRIMS)})")
    n = len(elems)
    J = np.eye(n)
    if mode == "none":
        return J
    pos = {(e.kind, e.index): j for j, e in enumerate(elems)}
    kinds = (("k", "spring", model.k_total, model.springs, model.k_local),) + (
        (("c", "dashpot", model.c_total, model.dashpots, model.c_local),) if mode == "fc" else ())
    for i in trimmed_dofs(model, elems):
        for own, link, total, links, local in kinds:
            if (own, i) in pos:
                J[pos[(own, i)]] = _trim_row(model, pos, i, own, link, total[i], links, local[i], n)
    return J


def _trim_row(model, pos, i, own, link, total, links, local, n) -> np.ndarray:
    """One row of trim_map: the trimmed local part's relative change in terms of u."""
    if abs(local) <= 1e-12 * abs(total):
        raise Mech2SpiceError(f"cannot trim DOF '{model.names[i]}': it has no local {own} to adjust")
    row = np.zeros(n)
    row[pos[(own, i)]] = total
    if ("m", i) in pos:
        row[pos[("m", i)]] = total
    for e, (a, b, v) in enumerate(links):
        if i in (a, b) and (link, e) in pos:
            row[pos[(link, e)]] -= v
    return row / local


def sigmas(elems: list[Element], model: MechModel, spread: float, trim: str = "none",
           residual: float = 0.0) -> np.ndarray:
    """The standard deviation of each coordinate u of trim_map: `residual` at a trimmed k (and, with
    "fc", c) element, `spread` everywhere else.  A margin with gradient g in t has, linearised, the
    standard deviation ||sigmas * (J^T g)||."""
    check_trim(trim, residual)
    if trim not in LINEAR_TRIMS:
        raise Mech2SpiceError(f"trim {trim!r} is not linearised (design centering takes {', '.join(LINEAR_TRIMS)})")
    out = np.full(len(elems), float(spread))
    dofs = set(trimmed_dofs(model, elems)) if trim != "none" else set()
    own = {"k"} | ({"c"} if trim == "fc" else set())
    for j, e in enumerate(elems):
        if e.kind in own and e.index in dofs:
            out[j] = residual
    return out
