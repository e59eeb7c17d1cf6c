"""One NOR gate loaded as in a network: the model the sensitivity and tolerance studies use.

    in1.C --spring+dashpot--> gate input 1 pair
    in2.C --spring+dashpot--> gate input 2 pair        gate.C --spring+dashpot--> load input pair

* Each input comes from an upstream channel (mass, total stiffness and damping of a channel), driven
  by its own source so that, in the nominal gate, its amplitude is the input level x u_R (drive
  amplitude x |k_C - m_C w^2 + i w c_C| u_R).  The gate's input oscillators then feel x F_R through
  the real coupling spring and dashpot, and a mismatch of that pair acts back on the upstream channel,
  as in a network.  The upstream channel has no insulator of its own: a stand-in with the channel's
  linear impedance for the logic level it carries.
* The output drives the input pair of one downstream gate.  load="pair": just that pair (two gate
  oscillators with the gate's totals) with the load's insulator held at rest, which keeps one slow DOF
  (the fast all-roots steady-state scan needs that).  load="gate": the whole downstream gate, its
  second input at a constant '0' (for time-domain checks of the "pair" reduction).
In the nominal gate every back-action cancels (spring and dashpot pairs are matched), so the gate's
steady states equal the free-standing `nor.single_gate`'s; spread breaks the cancellation.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import nor
from .model import MechModel
from .params import DEFAULT_LEVELS, LOAD_CHECKS, GateParams, Levels
from .steady_batch import Roots

GATE, INPUTS, LOAD = "gate", ("in1", "in2"), "load"
PER_BAND = 15           # input levels per band: the grid of characterise.valid_region_margin


@dataclass
class LoadedGate:
    """A gate wired as in a network: upstream channel stand-ins on its inputs, a load pair on its output."""
    model: MechModel
    gate: nor.GateBlock
    upstream: tuple[int, int]           # DOFs of the two upstream channels
    input_drives: tuple[int, int]      # their drives; amplitude = level x drive amplitude
    load_pair: tuple[int, int]         # the downstream (spring, dashpot) gate oscillators

    @property
    def block_dofs(self) -> list[int]:
        """DOFs whose elements the spread covers: the gate's own and the load pair's (with every link
        touching them); the upstream stand-ins and their sources are the inputs, not spread."""
        return [*self.gate.dofs, *self.load_pair]

    def input_groups(self) -> np.ndarray:
        """Per drive: 0 for constant drives, k for drives scaled by input level k (1, 2)."""
        groups = np.zeros(len(self.model.drives), int)
        groups[list(self.input_drives)] = [1, 2]
        return groups


def build(p: GateParams, load: str = "pair") -> LoadedGate:
    """The loaded gate with both upstream drives set for an input level of 1 (scale them per input)."""
    p.validate()
    m = MechModel(omega=p.omega)
    b = p.structure
    out = b.dof(b.output)               # the stand-in has the impedance of the block's output DOF
    z_c = abs(out.k - out.m * p.omega ** 2 + 1j * p.omega * out.c)
    ups, drives = [], []
    for name in INPUTS:
        ups.append(m.add_dof(f"{name}.C", out.m, out.k, out.c))
        drives.append(m.add_drive(ups[-1], z_c * p.u_r, 0.0, f"{name}.src"))
    gate = nor.add_nor(m, p, GATE)
    for u, pair in zip(ups, gate.inputs):
        nor.connect(m, p, u, pair)
    if load == "gate":
        lg = nor.add_nor(m, p, LOAD)
        nor.drive_pair(m, p, lg.inputs[1], p.levels.nominal0, f"{LOAD}.x2")
        pair = lg.inputs[0]
    elif load == "pair":
        pair = tuple(m.add_dof(f"{LOAD}.{d.name}", d.m, d.k, d.c) for d in (b.dof(a.dof) for a in b.inputs[0]))
    else:
        raise ValueError(f"load must be 'pair' or 'gate', not {load!r}")
    nor.connect(m, p, gate.channel, pair)
    return LoadedGate(m, gate, tuple(ups), tuple(drives), pair)


def at_inputs(lg: LoadedGate, x1: float, x2: float, model: MechModel | None = None) -> MechModel:
    """A copy of lg.model (or of `model`, same topology) with the inputs at levels x1, x2 (fractions of
    F_R / u_R)."""
    from .spread import Element, scaled
    ins = [Element("drive", d, "input") for d in lg.input_drives]
    return scaled(model if model is not None else lg.model, ins, np.array([x1, x2], float))


def band_levels(levels: Levels, per_band: int) -> np.ndarray:
    """per_band input levels across each of the two bands, band 0 first."""
    return np.concatenate([np.linspace(*levels.band0, per_band), np.linspace(*levels.band1, per_band)])


def input_grid(per_band: int = PER_BAND, levels: Levels = DEFAULT_LEVELS) -> tuple[np.ndarray, np.ndarray]:
    """Drive-group levels (P, 3) = (1, x1, x2) over both bands of both inputs, and NOR of each point."""
    lv = band_levels(levels, per_band)
    X1, X2 = np.meshgrid(lv, lv, indexing="ij")
    x1, x2 = X1.ravel(), X2.ravel()
    expect = np.array([int(not (levels.band_of(a) or levels.band_of(b))) for a, b in zip(x1, x2)])
    return np.stack([np.ones_like(x1), x1, x2], axis=1), expect


def band_edges(expect: np.ndarray, levels: Levels = DEFAULT_LEVELS) -> tuple[np.ndarray, np.ndarray]:
    """The low and high edges of band `expect` (per element)."""
    lo = np.where(expect == 1, levels.band1[0], levels.band0[0])
    hi = np.where(expect == 1, levels.band1[1], levels.band0[1])
    return lo, hi


def band_margin(a: np.ndarray, expect: np.ndarray, levels: Levels = DEFAULT_LEVELS) -> np.ndarray:
    """Levels.margin, vectorised: distance of amplitudes a (u_R) to the edge of band `expect`, in band widths."""
    lo, hi = band_edges(expect, levels)
    return np.minimum(a - lo, hi - a) / (hi - lo)


def point_margins(roots: Roots, expect: np.ndarray, u_r: float, levels: Levels = DEFAULT_LEVELS) -> np.ndarray:
    """Per input point: the smallest band margin over its stable states, -1 where none is stable."""
    m = np.where(roots.stable, band_margin(roots.amp / u_r, expect[roots.point], levels), np.inf)
    out = np.full(expect.size, np.inf)
    np.minimum.at(out, roots.point, m)
    out[np.isinf(out)] = -1.0
    return out


# --- a block can drive itself --------------------------------------------------------------------------
SELF_DRIVE_MARGIN = 0.05     # band widths: the least distance of a gate's output level to its band's edges
SELF_DRIVE_GRID = 1000       # steady_batch's scan points
_SELF_DRIVE: dict[str, float] = {}                 # digest of the block -> its margin (every command loads one)


def digest(p: GateParams) -> str:
    """A content key of a gate's parameters, structure and levels."""
    import hashlib
    import json
    return hashlib.sha256(json.dumps(p.to_dict(), sort_keys=True, default=str).encode()).hexdigest()


def self_drive_margin(p: GateParams) -> float:
    """The smallest band margin (band widths) of the loaded gate's output levels, every stable steady state
    with its inputs at its own nominal levels (00, 01, 10, 11): > 0 when each lies in the band of NOR of the
    inputs, so that one such gate drives the next; -1 where an input has no stable state; NaN where the states
    are not finite.  Memoised by `digest` (every command loads a block; ~0.02-0.3 s each)."""
    key = digest(p)
    if key not in _SELF_DRIVE:
        from . import steady_batch
        lg = build(p)
        lv = p.levels
        levels = np.array([[1.0, lv.nominal(a), lv.nominal(b)] for a in (0, 1) for b in (0, 1)])
        st = steady_batch.stack([lg.model], lg.input_groups(), lg.gate.channel)
        with np.errstate(all="ignore"):
            r = steady_batch.roots(st, 0, levels, SELF_DRIVE_GRID)
            m = point_margins(r, np.array([1, 0, 0, 0]), p.u_r, lv)
        _SELF_DRIVE[key] = float(m.min()) if np.isfinite(m).all() else float("nan")
    return _SELF_DRIVE[key]


def check_self_drive(p: GateParams, where: str) -> None:
    """Refuse a block whose output levels do not lie inside its own input bands with SELF_DRIVE_MARGIN (a
    network of it would decode wrong bits as valid: docs/architecture.md)."""
    from ..errors import Mech2SpiceError
    try:
        m = self_drive_margin(p)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError) as err:
        raise Mech2SpiceError(f"{where}: the gate's steady states cannot be computed "
                              f"({str(err).splitlines()[0][:100] or type(err).__name__}): not a usable block") from None
    if not m >= SELF_DRIVE_MARGIN:
        why = ("its steady states are not finite" if m != m else
               "an input has no stable state" if m == -1.0 else
               f"its worst output level lies {m:+.3f} band widths inside its band (negative: outside)")
        raise Mech2SpiceError(f"{where}: the gate cannot drive itself: at its own nominal inputs "
                              f"({p.levels.nominal0:g}, {p.levels.nominal1:g} u_R; bands {p.levels.band0[0]:g}-"
                              f"{p.levels.band0[1]:g}, {p.levels.band1[0]:g}-{p.levels.band1[1]:g}), {why} "
                              f"(at least {SELF_DRIVE_MARGIN} needed)")


if check_self_drive not in LOAD_CHECKS:
    LOAD_CHECKS.append(check_self_drive)
