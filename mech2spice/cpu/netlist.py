"""The synthesized processor (verilog/cpu.v) and how its latches map onto the architectural registers."""
from __future__ import annotations

import functools

from .. import data
from ..errors import Mech2SpiceError
from .iss import FETCH, LDNX, LOAD, REGISTERS

CPU_VERILOG = data.verilog("cpu.v")


@functools.lru_cache(maxsize=2)
def cpu_netlist(path: str = str(CPU_VERILOG), max_fanout: int | None = None):
    """The synthesized processor (cached: Yosys takes a few seconds)."""
    from ..synthesis.synth import synthesize
    return synthesize(path, max_fanout=max_fanout)


def register_map(netlist) -> dict[str, tuple[str, int]]:
    """latch -> (register, bit), read from the net each latch's D input carries (next_<reg>[i])."""
    g = netlist.graph
    out = {}
    for q in netlist.latches():
        pins = {g.edges[src, q].get("pin", "D"): src for src in g.predecessors(q)}
        if set(pins) != {"D"}:
            raise Mech2SpiceError(f"latch {q} has a set/reset input ({', '.join(sorted(set(pins) - {'D'}))}); "
                                  "the processor's state is read from plain D latches")
        src = pins["D"]
        net = str(g.nodes[src].get("net", ""))
        name, _, idx = net.partition("[")
        if not name.startswith("next_"):
            raise Mech2SpiceError(f"latch {q} is fed by net '{net}', not a next_<register> net; "
                                  "cannot read the processor state")
        out[q] = (name[5:], int(idx.rstrip("]") or 0))
    return out


def registers_from_latches(regmap: dict[str, tuple[str, int]], latch_bit) -> dict:
    """The architectural registers (pc, a, b, c, d, ov, phase) from each latch's bit, `latch_bit(q)`."""
    vals = dict.fromkeys(("pc", "a", "b", "c", "d", "ov", "ld", "nx"), 0)
    for q, (reg, bit) in regmap.items():
        vals[reg] |= latch_bit(q) << bit
    ld, nx = vals.pop("ld"), vals.pop("nx")
    return {**{r: vals[r] for r in REGISTERS if r != "phase"}, "phase": LOAD if ld else LDNX if nx else FETCH}


def registers_from_amplitudes(regmap: dict[str, tuple[str, int]], levels, amps, cycle: int) -> dict:
    """The architectural registers decoded from the latch outputs' amplitudes `amps` ('latch.Q' -> u_R) in the
    bands `levels` (physics.params.Levels); a latch outside both bands is one Mech2SpiceError naming cycle
    `cycle`, the register and the bit (an invalid bit stops a processor run)."""
    def bit(q: str) -> int:
        b = levels.band_of(amps[f"latch.{q}"])
        if b is None:
            reg, i = regmap[q]
            raise Mech2SpiceError(f"cycle {cycle}: register {reg} bit {i} (latch {q}) is invalid "
                                  f"(amplitude {amps[f'latch.{q}']:.3f} u_R)")
        return b
    return registers_from_latches(regmap, bit)


def latches_from_registers(regmap: dict[str, tuple[str, int]], regs: dict) -> dict[str, int]:
    """Each latch's bit for the architectural registers `regs` (the inverse of registers_from_latches)."""
    vals = {r: regs[r] for r in REGISTERS if r != "phase"}
    vals.update(ld=int(regs["phase"] == LOAD), nx=int(regs["phase"] == LDNX))
    return {q: (vals[reg] >> bit) & 1 for q, (reg, bit) in regmap.items()}
