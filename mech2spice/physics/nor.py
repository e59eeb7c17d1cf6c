"""The NOR gate block (paper Fig. 3c) and the ways blocks are wired together.

One gate = 6 DOFs: a channel (driven by the source at F_C), an insulator (slow),
and two gate oscillators per logical input.  Of each input pair, one gate is
coupled to the upstream channel by a spring k = F_R/u_R, the other by a dashpot
k/omega; their back-actions on the upstream channel cancel at the drive
frequency, so the input is "easy to drive" whatever the insulator does.
An external (or constant) input drives the pair directly: a*sin on the spring
gate, a*cos on the dashpot gate, which is what an upstream channel would do.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from .model import MechModel
from .params import GateParams

SPRING_PHASE = 0.0
DASHPOT_PHASE = math.pi / 2     # a dashpot's force leads the spring's by 90 degrees


@dataclass
class GateBlock:
    """The DOF indices of one NOR gate: its output ("channel"), insulator and the DOFs each input links to.

    For the classic block inputs[pin] = (spring gate, dashpot gate); for others, the DOFs of that input's
    links in the structure's order (the structure's inputs give their link kinds)."""
    name: str
    channel: int
    insulator: int
    inputs: list[tuple[int, ...]] = field(default_factory=list)
    structure: str = "classic"
    dofs: tuple[int, ...] = ()                 # every DOF of the block, in structure order
    source: int = -1                           # the source-driven DOF (the channel in the classic block)


def new_model(p: GateParams) -> MechModel:
    """Validate `p` and return an empty model at its drive frequency."""
    p.validate()
    return MechModel(omega=p.omega, params=p)


def add_nor(model: MechModel, p: GateParams, name: str) -> GateBlock:
    """Add one free-standing NOR block built from p's structure; its source DOF is driven by the source."""
    b = p.structure
    idx = {d.name: model.add_dof(f"{name}.{d.name}", d.m, d.k, d.c, slow=d.slow) for d in b.dofs}
    for a, c, k in b.springs:
        model.add_spring(idx[a], idx[c], k)
    for a, c, v in b.dashpots:
        model.add_dashpot(idx[a], idx[c], v)
    for f, s, g in b.quads:
        model.add_quad(idx[f], idx[s], g)
    model.add_drive(idx[b.source], b.source_force, 0.0, f"{name}.src")
    block = GateBlock(name, idx[b.output], idx[b.slow_dofs[0]],
                      [tuple(idx[a.dof] for a in pin) for pin in b.inputs], b.name,
                      tuple(idx.values()), idx[b.source])
    model.add_probe(name, block.channel)
    return block


def _links(p: GateParams) -> list[str]:
    """The link kind of each DOF an input attaches to, in the order of GateBlock.inputs[pin]
    (the same for both inputs: BlockSpec.validate asks for symmetric inputs)."""
    return [a.link for a in p.structure.inputs[0]]


def connect(model: MechModel, p: GateParams, channel: int, pair: tuple[int, ...]) -> None:
    """Wire an upstream output to a downstream input's DOFs by the structure's links (classic: one
    spring k = F_R/u_R + one dashpot k/omega).  Springs first, then dashpots, as the classic block did."""
    links = list(zip(pair, _links(p)))
    for dof, kind in links:
        if kind == "spring":
            model.add_spring(channel, dof, p.k_couple)
    for dof, kind in links:
        if kind == "dashpot":
            model.add_dashpot(channel, dof, p.c_couple)


def drive_pair(model: MechModel, p: GateParams, pair: tuple[int, ...], level: float,
               name: str) -> tuple[int, ...]:
    """Drive an input's DOFs externally at `level` (fraction of F_R): what an upstream output at level
    x u_R would exert through each link; returns the drive indices (classic: spring, dashpot)."""
    a = p.force(level)
    tags = {"spring": (SPRING_PHASE, "s"), "dashpot": (DASHPOT_PHASE, "d")}
    links = _links(p)
    unique = len(set(links)) == len(links)      # classic: ".s", ".d"
    out = []
    for k, (dof, kind) in enumerate(zip(pair, links)):
        phase, tag = tags[kind]
        out.append(model.add_drive(dof, a, phase, f"{name}.{tag if unique else f'{tag}{k}'}"))
    return tuple(out)


def gate_array(p: GateParams, n: int, level: float, declare: bool = True) -> MechModel:
    """n independent NOR gates, both inputs of each driven at `level`; `declare`: listed as the design's gate
    blocks (block devices in the circuit simulators, the envelope's latency blocks)."""
    m = new_model(p)
    for k in range(n):
        g = add_nor(m, p, f"g{k}")
        drive_pair(m, p, g.inputs[0], level, f"a{k}")
        drive_pair(m, p, g.inputs[1], level, f"b{k}")
        if declare:
            m.design.gates.append(g)
    return m


# --- small circuits used by characterisation, tests and benchmarks ----------
def _zero(p: GateParams, x: float | None) -> float:
    """x, or the block's nominal '0' where not given."""
    return p.levels.nominal0 if x is None else x


def single_gate(p: GateParams, x1: float | None = None, x2: float | None = None) -> MechModel:
    """One NOR gate with its two inputs driven externally at levels x1, x2 (fractions of F_R; default the
    block's nominal '0')."""
    x1, x2 = _zero(p, x1), _zero(p, x2)
    m = new_model(p)
    g = add_nor(m, p, "g0")
    m.design.input_drives = [drive_pair(m, p, g.inputs[0], x1, "x1"),
                              drive_pair(m, p, g.inputs[1], x2, "x2")]
    m.design.gates = [g]
    return m


def chain(p: GateParams, n: int = 3, x1: float | None = None, x2: float | None = None) -> MechModel:
    """((x1 NOR x2) NOR 0) NOR 0 ...: n gates, each later gate's second input a constant '0'."""
    x1, x2 = _zero(p, x1), _zero(p, x2)
    m = new_model(p)
    gates = [add_nor(m, p, f"g{k}") for k in range(n)]
    m.design.input_drives = [drive_pair(m, p, gates[0].inputs[0], x1, "x1"),
                              drive_pair(m, p, gates[0].inputs[1], x2, "x2")]
    for k in range(1, n):
        connect(m, p, gates[k - 1].channel, gates[k].inputs[0])
        drive_pair(m, p, gates[k].inputs[1], p.levels.nominal0, f"zero{k}")
    m.design.gates = gates
    return m


def fanout(p: GateParams, n_loads: int, x1: float | None = None, x2: float | None = None,
           load_x2: float | None = None) -> MechModel:
    """One driver gate whose channel feeds input 1 of n_loads gates (their input 2 at load_x2)."""
    x1, x2, load_x2 = _zero(p, x1), _zero(p, x2), _zero(p, load_x2)
    m = new_model(p)
    drv = add_nor(m, p, "drv")
    m.design.input_drives = [drive_pair(m, p, drv.inputs[0], x1, "x1"),
                              drive_pair(m, p, drv.inputs[1], x2, "x2")]
    loads = []
    m.design.load_drives = []
    for k in range(n_loads):
        g = add_nor(m, p, f"load{k}")
        connect(m, p, drv.channel, g.inputs[0])
        m.design.load_drives.append(drive_pair(m, p, g.inputs[1], load_x2, f"lx{k}"))
        loads.append(g)
    m.design.gates = [drv, *loads]
    return m
