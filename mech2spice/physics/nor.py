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
from .params import NOMINAL0, GateParams

SPRING_PHASE = 0.0
DASHPOT_PHASE = math.pi / 2     # a dashpot's force leads the spring's by 90 degrees


@dataclass
class GateBlock:
    """The DOF indices of one NOR gate: its channel, insulator and (spring, dashpot) gate pair per input."""
    name: str
    channel: int
    insulator: int
    inputs: list[tuple[int, int]] = field(default_factory=list)   # (spring gate, dashpot gate) per input


def new_model(p: GateParams) -> MechModel:
    """Validate `p` and return an empty model at its drive frequency."""
    p.validate()
    return MechModel(omega=p.omega, params=p)


def add_nor(model: MechModel, p: GateParams, name: str) -> GateBlock:
    """Add one free-standing NOR block; its channel is driven by the source."""
    ch = model.add_dof(f"{name}.C", p.m_c, p.k_c, p.c_c)
    ins = model.add_dof(f"{name}.I", p.m_i, p.k_i, p.c_i, slow=True)
    model.add_quad(ch, ins, -p.gamma_ic)
    model.add_drive(ch, p.f_c, 0.0, f"{name}.src")
    block = GateBlock(name, ch, ins)
    for pin in (1, 2):
        pair = []
        for kind in ("s", "d"):                      # spring-coupled, dashpot-coupled
            g = model.add_dof(f"{name}.G{pin}{kind}", p.m_g, p.k_g, p.c_g)
            model.add_quad(g, ins, p.gamma_ig)
            pair.append(g)
        block.inputs.append(tuple(pair))
    model.add_probe(name, ch)
    return block


def connect(model: MechModel, p: GateParams, channel: int, pair: tuple[int, int]) -> None:
    """Wire an upstream channel to a downstream gate pair: one spring + one dashpot."""
    model.add_spring(channel, pair[0], p.k_couple)
    model.add_dashpot(channel, pair[1], p.c_couple)


def drive_pair(model: MechModel, p: GateParams, pair: tuple[int, int], level: float,
               name: str) -> tuple[int, int]:
    """Drive an input pair externally at `level` (fraction of F_R); returns the two drive indices."""
    a = p.force(level)
    return (model.add_drive(pair[0], a, SPRING_PHASE, f"{name}.s"),
            model.add_drive(pair[1], a, DASHPOT_PHASE, f"{name}.d"))


# --- small circuits used by characterisation, tests and benchmarks ----------
def single_gate(p: GateParams, x1: float = NOMINAL0, x2: float = NOMINAL0) -> MechModel:
    """One NOR gate with its two inputs driven externally at levels x1, x2 (fractions of F_R)."""
    m = new_model(p)
    g = add_nor(m, p, "g0")
    m.design.input_drives = [drive_pair(m, p, g.inputs[0], x1, "x1"),
                              drive_pair(m, p, g.inputs[1], x2, "x2")]
    m.design.gates = [g]
    return m


def chain(p: GateParams, n: int = 3, x1: float = NOMINAL0, x2: float = NOMINAL0) -> MechModel:
    """((x1 NOR x2) NOR 0) NOR 0 ...: n gates, each later gate's second input a constant '0'."""
    m = new_model(p)
    gates = [add_nor(m, p, f"g{k}") for k in range(n)]
    m.design.input_drives = [drive_pair(m, p, gates[0].inputs[0], x1, "x1"),
                              drive_pair(m, p, gates[0].inputs[1], x2, "x2")]
    for k in range(1, n):
        connect(m, p, gates[k - 1].channel, gates[k].inputs[0])
        drive_pair(m, p, gates[k].inputs[1], NOMINAL0, f"zero{k}")
    m.design.gates = gates
    return m


def fanout(p: GateParams, n_loads: int, x1: float = NOMINAL0, x2: float = NOMINAL0,
           load_x2: float = NOMINAL0) -> MechModel:
    """One driver gate whose channel feeds input 1 of n_loads gates (their input 2 at load_x2)."""
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
