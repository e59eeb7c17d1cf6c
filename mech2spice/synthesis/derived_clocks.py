"""Flip-flops clocked by logic (a divided clock, a ripple counter): which ones have one meaning.

A simulator runs a flip-flop's block when its clock changes, and its clock, computed from registers, changes in
the update of the instant that changes those registers.  Every register updated in that same instant is new or
old to the block by the order of the simulator's events, which the language leaves open; registers updated in
any other instant are old, on every simulator and in the sampled network (a flip-flop there takes the data of
the cycle before its clock's samples change, docs/rtl.md, "Sampled clocks").  So a flip-flop on a computed
clock has one meaning, and the network's, unless it reads a register that can change in the instant its clock
does, before its block runs.

That order is counted by depth: registers clocked by input ports are updated at depth 0 (every input clock may
change in one testbench step), a flip-flop on a clock computed from registers of depths up to d at depth d + 1,
after them.  A flip-flop is refused where it reads a register of a smaller depth than its own (its clock's own
registers included: the block sees its clock's new value, the network the sample before; a ripple counter's
stages read only themselves), and where its clock follows an input port (such a clock also changes when the
data does).
"""
from __future__ import annotations

import re
from typing import Callable

_OUTPUT_PINS = ("Y", "Q")


def ambiguity(module: dict, flops: list[dict], names: dict) -> tuple[dict, str] | None:
    """The first flip-flop of `flops` (Yosys cells with a C pin) on a computed clock that has no one meaning,
    with the reason (register and port names from `names`, net id -> name); None when each has one."""
    inputs, out_of = _index(module)
    flops = sorted(flops, key=_source_order)        # the first one the source writes is the one named
    is_flop = {id(c) for c in flops}.__contains__
    cone = _Cone(inputs, out_of, lambda cell: is_flop(id(cell)))
    depth = _depths(flops, inputs, cone)
    for flop in flops:
        clock = flop["connections"]["C"][0]
        if clock in inputs:
            continue
        regs, ports = cone.of([clock])
        if ports:
            return flop, _follows_ports(sorted(ports), regs, names)
        if depth[id(flop)] is None:
            return flop, ("this flip-flop's clock is computed from its own value: each edge it takes makes the "
                          "next, in the same instant; clock it by an input port")
        data = [b for pin, bits in flop["connections"].items() if pin not in ("C", "Q") for b in bits]
        clashing = [r for r in cone.of(data)[0] if depth[id(r)] < depth[id(flop)]]
        if clashing:
            return flop, _clash(regs, clashing, names)
    return None


def _follows_ports(ports: list[str], regs: list[dict], names: dict) -> str:
    """Why a flip-flop on a clock computed from input ports (and maybe registers) has no one meaning."""
    listed = ", ".join(f"'{p}'" for p in ports)
    if regs:        # a clock multiplexer (oc_rtc's `lo_clk = EN ? div_clk : wb_clk_i`) or a gated clock
        held = ", ".join(f"'{n}'" for n in sorted({names.get(r["connections"]["Q"][0], "?") for r in regs}))
        return (f"this flip-flop's clock is computed from the input port{'s' * (len(ports) > 1)} {listed} and the "
                f"registers {held}, which change in the same instant as that port's edge: whether the computed "
                "clock then takes an edge (or a glitch) depends on the order of the simulator's events, which the "
                f"source leaves open; clock the flip-flop by {listed if len(ports) == 1 else 'one input port'} and "
                "use the registers as an enable")
    return (f"this flip-flop is clocked by logic of the input port{'s' * (len(ports) > 1)} {listed}: that clock "
            "has an edge when such an input changes, in the same instant as the data the flip-flop takes, and the "
            "source does not say which value it takes; clock it by one input port and use the "
            + ("others" if len(ports) > 1 else "logic on it") + " as an enable")


def _clash(regs: list[dict], clashing: list[dict], names: dict) -> str:
    """Why a flip-flop on a clock computed from `regs` cannot read `clashing` (registers of the same depth)."""
    name = lambda r: names.get(r["connections"]["Q"][0], "?")          # noqa: E731
    sources = ", ".join(f"'{n}'" for n in sorted({name(r) for r in regs}))
    others = sorted({name(r) for r in clashing if all(r is not s for s in regs)})
    if others:
        reads = ", ".join(f"'{n}'" for n in others)
        return (f"this flip-flop is clocked by logic of {sources} and reads {reads}, which can change in the same "
                "instant, before that clock's edge: a simulator gives it the new value (or either, by the order of "
                "its events), the network (its clocks sampled) the value before; clock it by an input port (a "
                "divided clock as an enable on the fast one)")
    reads = ", ".join(f"'{n}'" for n in sorted({name(r) for r in clashing}))
    return (f"this flip-flop is clocked by logic of {sources} and reads {reads}, which its clock is computed from: "
            "a simulator gives it the value after the clock's edge, the network (its clocks sampled) the value "
            "before; clock it by an input port (a divided clock as an enable on the fast one)")
    return None


def _source_order(cell: dict) -> tuple:
    """A cell's place in the source (line, column of its src attribute 'FILE:L.C-L.C'); cells without one last."""
    attrs = cell.get("attributes")
    m = re.search(r":(\d+)\.(\d+)", attrs.get("src", "") if isinstance(attrs, dict) and isinstance(
        attrs.get("src"), str) else "")
    return (0, int(m[1]), int(m[2])) if m else (1, 0, 0)


def _index(module: dict) -> tuple[dict, dict]:
    """(input bit -> its port, net bit -> the cell driving it) of a Yosys JSON module."""
    inputs = {bit: port for port, info in module["ports"].items() if info.get("direction") == "input"
              for bit in info["bits"]}
    out_of = {bits[0]: cell for cell in module["cells"].values()
              for pin, bits in cell["connections"].items() if pin in _OUTPUT_PINS and bits}
    return inputs, out_of


class _Cone:
    """The registers and input ports a set of nets is computed from, through logic (not through registers)."""

    def __init__(self, inputs: dict, out_of: dict, is_flop: Callable[[dict], bool]):
        self.inputs, self.out_of, self.is_flop = inputs, out_of, is_flop

    def of(self, bits: list) -> tuple[list[dict], set]:
        regs, ports, seen, stack = {}, set(), set(), list(bits)
        while stack:
            bit = stack.pop()
            if isinstance(bit, str) or bit in seen:         # a constant "0"/"1"/"x"/"z"
                continue
            seen.add(bit)
            if bit in self.inputs:
                ports.add(self.inputs[bit])
                continue
            cell = self.out_of.get(bit)
            if cell is None:
                continue
            if self.is_flop(cell):
                regs[id(cell)] = cell
                continue
            stack += [b for pin, bs in cell["connections"].items() if pin not in _OUTPUT_PINS for b in bs]
        return list(regs.values()), ports


def _depths(flops: list[dict], inputs: dict, cone: _Cone) -> dict:
    """id(flip-flop) -> its update depth (module docstring); None where its clock depends on itself."""
    depth: dict = {}

    def visit(flop: dict, path: frozenset):
        key = id(flop)
        if key in depth:
            return depth[key]
        clock = flop["connections"]["C"][0]
        if clock in inputs or isinstance(clock, str):
            depth[key] = 0
            return 0
        if key in path:
            return None
        below = [visit(r, path | {key}) for r in cone.of([clock])[0]]
        depth[key] = None if any(d is None for d in below) else 1 + max(below, default=-1)
        return depth[key]

    for flop in flops:
        visit(flop, frozenset())
    return depth


def clock_read(module: dict, flops: list[dict], latches: list[dict], clocks: tuple) -> tuple[dict, str] | None:
    """The first flip-flop (or level-sensitive latch) whose data reads one of the sampled `clocks`, with that
    clock's name; None when none does.  At an edge a simulator has already changed every clock the testbench
    changed, so the block reads their new values (either value, where logic stands between, by the order of
    its events); the network, its clocks sampled, takes the data sampled before the edge."""
    inputs, out_of = _index(module)
    held = {id(c) for c in flops + latches}
    cone = _Cone(inputs, out_of, lambda cell: id(cell) in held)
    for cell in flops + latches:        # the data only: an asynchronous reset or set is a level either way
        read = sorted(set(clocks) & cone.of(list(cell["connections"].get("D", [])))[1])
        if read:
            return cell, read[0]
    return None
