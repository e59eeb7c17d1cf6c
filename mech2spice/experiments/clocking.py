"""The clock schedule and period budgets, from measured latch and gate delays.

A combinational design gets `period_budget` periods to settle; a clocked design gets `clock_timing`'s
pulse and pause.  Both rest on delays measured on the default block; `block_slowdown` stretches them for a
slower block by measuring its 3-gate chain on RK4 (experiments/characterise.cascade).
"""
from __future__ import annotations

import json
import math

from ..errors import Mech2SpiceError
from ..physics import network
from ..physics.params import DEFAULT, GateParams
from ..synthesis.synth import Netlist

# Measured on verilog/dff.v (reports/sequential.md, RK4 and envelope agree within 4 periods): a 300-period
# enable pulse does not capture a 0, 500 does; the latch output (3 delay pairs) moves 1282 (storing 1)
# to 1648 (storing 0) periods after the pulse starts. Gate delays are at most 225 periods (reports/gate.md).
LATCH_MIN_PULSE = 500
LATCH_OUTPUT_DELAY_MIN = 1280
LATCH_OUTPUT_DELAY = 1650
GATE_DELAY_MAX = 225
SETTLE_MARGIN = 600


def period_budget(netlist: Netlist) -> int:
    """Enough periods for the slowest measured gate delay (~225) through the deepest path, plus settling."""
    return 800 + 300 * network.logic_depth(netlist)


def block_slowdown(p: GateParams | None) -> float:
    """How much slower this block's gates switch than the default block's, >= 1: the largest gate delay of
    the 3-gate chain on RK4 (experiments/characterise.cascade, the measurement GATE_DELAY_MAX comes from),
    against the default's.  The schedule's latch and gate delays were measured on the default block; a
    slower block needs them stretched (the robust block: 340 against 224 periods, 1.52x).  Cached."""
    if p is None or p == DEFAULT:
        return 1.0
    return max(1.0, _largest_delay(p) / _largest_delay(DEFAULT))


def _largest_delay(p: GateParams) -> float:
    """The 3-gate chain's largest gate delay (periods, RK4), cached per parameter set."""
    key = json.dumps(p.to_dict(), sort_keys=True, default=str)
    if key not in _DELAY:
        # imported here: simulation reads period_budget from this module without loading the experiments
        from .characterise import cascade
        _DELAY[key] = cascade(p)["delay_max"]
    return _DELAY[key]


_DELAY: dict[str, float] = {}


def clock_timing(netlist: Netlist, pulse: int | None = None, pause: int | None = None,
                 p: GateParams | None = None) -> dict:
    """Pulse and pause (drive periods) from the measured latch and gate delays and the logic depth, the
    delays stretched by `block_slowdown(p)` for a block slower than the default."""
    s = block_slowdown(p)
    min_pulse, out_min = int(math.ceil(s * LATCH_MIN_PULSE)), int(s * LATCH_OUTPUT_DELAY_MIN)
    pulse = pulse or int(1.6 * min_pulse)
    if pulse >= out_min:
        raise Mech2SpiceError(f"a {pulse}-period clock pulse outlasts the latch's shortest output delay "
                              f"({out_min} periods): outputs would change while it latches")
    if pulse < min_pulse:
        raise Mech2SpiceError(f"a {pulse}-period clock pulse is shorter than the {min_pulse} periods "
                              "the latch was measured to need")
    depth = network.logic_depth(netlist)
    odd = any(netlist.graph.nodes[q].get("inverted") for q in netlist.latches())   # an odd delay line: one more gate
    need = int(math.ceil(s * (LATCH_OUTPUT_DELAY + GATE_DELAY_MAX * (depth + odd + 1) + SETTLE_MARGIN))) - pulse
    return {"pulse": pulse, "pause": pause or need, "derived_pause": need, "logic_depth": depth,
            "block_slowdown": s}
