"""Is a block stable in a clocked network while its latches hold?  And the insulator damping that makes it so.

A latch that holds does not cut its feedback loop: its D-side gate is held at '0' by the enable's inverse,
but its output still moves a little with D, and a gate's insulator mode (a slow resonance, ~100 drive
periods) amplifies a slow modulation near its period.  Around a register's loop (latch, delay line, the
logic back to D) a block whose slowest state decays too slowly has a loop gain above 1 there: the held
network's fixed point is a Hopf point, and the amplitudes circle it at the insulator mode's period (the
centred blocks of issue #27: counter4 at 108 periods, docs/design.md "In networks").  A single loaded gate
does not see it: every open chain and fan-out of the same block is stable.

`held_growth` measures it on counter4 (the smallest shipped design with a register loop through logic;
every cycle's held state is judged by the stability verdict, docs/stability.md).  The insulator's Q is the
lever that moves no steady state (the slow DOF's rest displacement -H|A|^2 / (2 K_s) does not depend on its
damping), so margins, bands and folds stay as they are; `damp_insulator` lowers it until the held network
decays at least at HELD_GROWTH_FLOOR.  What it costs is switching delay (docs/design.md).
"""
from __future__ import annotations

import math

from .. import simulation
from ..data import verilog
from ..physics.params import GateParams, block_params
from ..synthesis import synth
from . import clocking

# counter4 reset, counting, holding, counting: the held states of every stored value 0-3 (q = 2 was the
# least damped on every block measured)
HELD_STEPS = [{"set": {"rst": 1}, "cycles": 1}, {"set": {"rst": 0, "en": 1}, "cycles": 2},
              {"set": {"en": 0}, "cycles": 1}, {"set": {"en": 1}, "cycles": 1}]
# Per drive period.  The default block's held counter4 decays at -1.1e-3 .. -1.3e-3, robust's at -2.4e-3
# (measured, scripts/held_damping.py); a centred block must do about as well as the default.
HELD_GROWTH_FLOOR = 1.0e-3
Q_STEP = 0.85             # each damping step multiplies the insulator's Q by this
Q_MIN = 0.2               # where the search gives up (0.25, the lowest measured on centered_fc, still helped)


def held_growth(p: GateParams) -> dict:
    """counter4 through HELD_STEPS on the envelope: the largest growth rate (per drive period) of any cycle's
    held state (inf where a cycle found no fixed point: the network circles it), per cycle (None for inf),
    and whether every read was valid."""
    nl = synth.synthesize(str(verilog("counter4.v")))
    cycles = simulation.expand_steps(HELD_STEPS)
    run = simulation.run_clocked_physical(nl, p, cycles, "envelope", clocking.clock_timing(nl, p=p))
    rates = [_growth(e["stability"]) for e in run["trace"]]
    return {"growth": max(rates), "per_cycle": [json_rate(r) for r in rates], "valid": run["valid"],
            "outputs": [e["outputs"]["q"] for e in run["trace"]]}


def _growth(stability: dict) -> float:
    """A read's leading growth rate; inf where no fixed point was found near the state."""
    g = stability.get("growth_rate")
    return math.inf if g is None or not stability.get("fixed_point_found") else float(g)


def json_rate(rate: float) -> float | None:
    """A growth rate for JSON: None for inf (no fixed point found)."""
    return None if math.isinf(rate) else rate


def with_insulator_q(p: GateParams, q: float) -> GateParams:
    """Block p with its slow DOFs' Q set to q (nothing else changes)."""
    block = p.structure.to_dict()
    for dof in block["dofs"].values():
        if dof.get("slow"):
            dof["q"] = q
    return block_params({"block": block, "name": p.name, "f_r": p.f_r, "u_r": p.u_r, "omega": p.omega,
                         "levels": p.levels.to_dict()}, "held damping")


def insulator_q(p: GateParams) -> float:
    """The Q of the block's (first) slow DOF."""
    return p.structure.dof(p.structure.slow_dofs[0]).q


def damp_insulator(p: GateParams, floor: float = HELD_GROWTH_FLOOR, log=lambda msg: None) -> tuple[GateParams, dict]:
    """(block, record): p with its insulator's Q lowered in Q_STEP steps until the held counter4 decays at
    least at `floor` per period (p itself if it already does).  The record lists each Q tried and its
    growth; `reached` is False where Q_MIN came first."""
    q, tried = insulator_q(p), []
    while True:
        h = held_growth(p)
        tried.append({"q_insulator": q, "growth": json_rate(h["growth"]), "valid": h["valid"]})
        log(f"insulator Q {q:.3f}: held counter4 growth {h['growth']:+.2e} per period")
        if h["growth"] <= -floor or q * Q_STEP < Q_MIN:
            return p, {"floor": floor, "reached": h["growth"] <= -floor, "q_insulator": q, "tried": tried}
        q *= Q_STEP
        p = with_insulator_q(p, q)
