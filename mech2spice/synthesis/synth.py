"""Verilog -> Yosys -> a networkx netlist of 2-input NOR gates, plus netlist hygiene.

Graph conventions (nodes are strings, attribute ``kind``):

* ``input``  -- one per input port bit, named ``p[i]`` (attrs ``port``, ``bit``).
* ``const``  -- exactly ``const0`` / ``const1``, present only while something uses them.
* ``nor``    -- a 2-input NOR gate ``g<N>``; exactly two in-edges with edge attr ``pin`` 0 and 1.
  A NOT is ``NOR(x, const0)``.  Optional attr ``net``: the Yosys net it drives (for messages).
* ``latch``  -- a flip-flop bit ``q<N>`` (Yosys ``$_DFF_P_``, or ``$_DFF_P[NP][01]_`` with an asynchronous
  reset/set; ``$_DFF_N*`` when every flip-flop captures on the falling edge, ``Netlist.clock_edge``); in-edge
  pin ``"D"``, and pin ``"F"`` (the forcing input, active high) when it has an asynchronous reset or set; attr ``inverted`` (1, absent = 0): the mechanical loop stores the complement of the
  register, so the register powers up at ``inverted`` and ``F`` forces it to ``inverted``.  Clocked by the
  port ``Netlist.clock`` (not an edge of the graph).  Mechanically it is the paper's NOR latch
  (network.py); logically a register (backends/logic.py).  The D-side gates that make the forcing and the
  inversion work (``D & !F``, ``!D & !F``) are ordinary NOR nodes of the graph; see docs/rtl.md.
* ``output`` -- one per output port bit, named ``p[i]`` (attrs ``port``, ``bit``); one in-edge.

Edges run driver -> sink.  Bit ``i`` of a port is bit ``i`` of its value (LSB = 0), i.e.
Yosys's bit order; for an ascending range such as ``[0:3]`` that is HDL index ``3 - i``.

Documented choices: Yosys's ``x`` constants become 0 (any value is a valid refinement of "don't
care"), but a net that nothing drives is refused; a register's power-up value comes from its declaration
initialiser or a constant `initial` assignment (docs/rtl.md, "programming by initial conditions"); constant
nodes are not subject to the fan-out limit (they are the mechanical ground/bias, not a driven signal).  Memories
map to latches and multiplexers; a tri-state bus becomes a multiplexer, its released and contended states
don't-cares; a top-level inout is refused (docs/rtl.md).
"""

from __future__ import annotations

import hashlib
import itertools
import json
import os
import re
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import networkx as nx
import numpy as np

from .. import identifiers
from ..errors import Mech2SpiceError
from ..inputs import read_input
from . import derived_clocks, dialect, maps, races, refusals, yosys
from .verilog_text import (blanked as _blanked, line_of, link_readmem_files, process_at, readmem_calls,
                           readmem_problem, statement_or_block_end, translate_off_regions)

__all__ = ["Netlist", "synthesize", "build_netlist", "clean", "observe", "propagate_constants", "latch_inputs",
           "remove_dead_gates", "check_loops", "buffer_feedthroughs", "limit_fanout"]


@dataclass
class Netlist:
    """A synthesized design: its NOR/latch graph (conventions above), ports and clock."""

    top: str
    graph: nx.DiGraph
    inputs: dict[str, int]    # port name -> width, in declaration order
    outputs: dict[str, int]   # port name -> width, in declaration order
    clock: str | None = None  # the flip-flops' clock port, if any
    signed: frozenset = frozenset()   # ports declared signed: their values are two's complement
    races: tuple = ()                 # races.Race: clocked blocks passing a value through `=` on one edge
    source: str | None = field(default=None, compare=False)   # the Verilog file synthesized: never an output
    systemverilog: bool = field(default=False, compare=False)  # Yosys read it so (a .sv, or a .v only that reads)
    clock_edge: str = "posedge"       # the edge every flip-flop captures on (the source's; one pulse either way)
    # the source's clock ports where its flip-flops use several of them or both edges: each is then an input
    # sampled once a cycle of the mechanical clock, its edges found between samples (`_flow`, docs/rtl.md,
    # "Sampled clocks"); `clock` is None and every latch captures on the one pulse
    sampled: tuple = ()
    # source register bits without a power-up value that synthesis made 0 or 1, or left undriven (read as 0):
    # (path, index, value), named as the latches' `registers` (verify starts them on Icarus)
    constant_registers: tuple = field(default=(), compare=False)
    # source register bits with a power-up value, (path, index, value) as above: where a sampled design's
    # registers are put back after the testbench's first clock values, an edge the network does not have
    initial_registers: tuple = field(default=(), compare=False)
    # the source's `translate_off` regions, (first line, last line): text a simulator runs and synthesis not
    translate_off: tuple = field(default=(), compare=False)
    # output bits nothing drives in the source (`port[i]`): Verilog reads z there, the network a constant 0
    undriven: tuple = field(default=(), compare=False)

    @property
    def clocked(self) -> bool:
        """Whether the network holds state: a clock port, or sampled clocks."""
        return self.clock is not None or bool(self.sampled)

    def clock_text(self) -> str:
        """The clock as a message names it: `'clk'`, or `'wclk', 'rclk' (sampled inputs)`."""
        if self.sampled:
            return ", ".join(f"'{c}'" for c in self.sampled) + " (sampled inputs)"
        return f"'{self.clock}'"

    def gates(self) -> list[str]:
        """NOR gates in topological order (level by level, by gate number within a level); latch
        outputs count as sources, so clocked designs order too.  Cached per graph object: a finished
        netlist's graph is not edited in place (the hygiene passes build a new one)."""
        return self._order()[0]

    def latches(self) -> list[str]:
        """Latch (flip-flop) nodes sorted by number."""
        return self._order()[1]

    def _order(self) -> tuple[list[str], list[str]]:
        cache = self.__dict__.get("_order_cache")
        if cache is None or cache[0] is not self.graph:
            g = combinational_view(self.graph)
            gates = [n for level in nx.topological_generations(g)
                     for n in sorted(level, key=_gate_key) if g.nodes[n]["kind"] == "nor"]
            latches = sorted((n for n in g if g.nodes[n]["kind"] == "latch"), key=_gate_key)
            cache = self.__dict__["_order_cache"] = (self.graph, gates, latches)
        return cache[1], cache[2]

    def forced(self) -> list[str]:
        """Latches with an asynchronous forcing input (pin F), sorted by number.  Cached like gates()."""
        cache = self.__dict__.get("_forced_cache")
        if cache is None or cache[0] is not self.graph:
            forced = [q for q in self.latches() if latch_inputs(self.graph, q)[1] is not None]
            cache = self.__dict__["_forced_cache"] = (self.graph, forced)
        return cache[1]

    def schedule(self) -> list[str]:
        """Gates and latches in an order where each follows everything it reads combinationally (a forced
        latch after its F source): the evaluation order when some latch is forced.  Cached like gates()."""
        cache = self.__dict__.get("_schedule_cache")
        if cache is None or cache[0] is not self.graph:
            g = combinational_view(self.graph)
            order = [n for level in nx.topological_generations(g) for n in sorted(level, key=_gate_key)
                     if g.nodes[n]["kind"] in ("nor", "latch")]
            cache = self.__dict__["_schedule_cache"] = (self.graph, order)
        return cache[1]

    def fanout(self, node) -> int:
        """How many sinks `node` drives (its out-edges: gates, latches, output bits)."""
        return self.graph.out_degree(node)


def combinational_view(g: nx.DiGraph) -> nx.DiGraph:
    """The graph without the D edges into latches: what must be loop-free and is evaluated in order.  A
    latch's forcing input F stays: it acts on the output at once, without the clock."""
    return nx.subgraph_view(g, filter_edge=lambda u, v: g.nodes[v]["kind"] != "latch" or g.edges[u, v]["pin"] == "F")


def latch_inputs(g: nx.DiGraph, q: str) -> tuple[str, str | None]:
    """(the node on a latch's D pin, the node on its forcing pin F or None)."""
    pins = {d["pin"]: u for u, _, d in g.in_edges(q, data=True)}
    return pins["D"], pins.get("F")


def synthesize(path, top: str | None = None, *, max_fanout: int | None = None) -> Netlist:
    """Synthesize the Verilog file ``path`` into a clean Netlist of 2-input NOR gates (and latches)."""
    path = Path(path)
    identifiers.yosys_path(path.resolve(), "Verilog file")      # quoted in the Yosys script: checked first
    source = dialect.standard_text(path, _read_source(path))    # VIS's dialect as SystemVerilog, lines kept
    _check_source(path, source)
    skipped = _warn_translate_off(path, source)
    if top is not None:                 # any Verilog name, escaped ones too; one the script cannot hold is refused
        if not isinstance(top, str) or not top:
            raise Mech2SpiceError(f"invalid top module name {top!r}")
        try:
            identifiers.yosys_module(top)
        except Mech2SpiceError as err:
            raise Mech2SpiceError(f"invalid top module name: {err}") from None
    name, module, found, released, sv, aliased = _run_yosys(path, top, source)
    try:
        netlist = build_netlist(name, module, path)
    except _Sampled as need:            # several clocks, both edges, a clock read as data: sample them
        _refuse_clock_reads(name, module, need.clocks, path)
        # the source's power-up values, as its flip-flops carry them (clk2fflogic moves them to its samples)
        initial = _source_registers(module, _initial_values(module))[2]
        name, module, found, released, sv, aliased = _run_yosys(path, top, source, sampled=True)
        try:
            netlist = build_netlist(name, module, path, sampled=need.clocks)
        except _Sampled as again:       # nothing clocked is left to sample: not expected, said plainly
            raise Mech2SpiceError(f"{path}: {again} even with its clocks sampled") from None
        netlist.initial_registers = initial
    for race in found:                  # warned, not refused: the network is Yosys's (flip-flop) reading
        _warn(races.warning(race, path))
    for read in aliased:                # warned: the network computes the block as @*, as Icarus runs it
        _warn(refusals.alias_warning(read, path))
    for port in released:               # warned: where Verilog reads z the network reads the bus's multiplexer
        _warn(f"{path}: output {port} is driven only through tri-state drivers: where none is enabled Verilog "
              "reads z and the network a 0 or 1 (the bus as a multiplexer); `verify` names such input vectors")
    undriven = _undriven_outputs(module)
    for port in dict.fromkeys(b.split("[")[0] for b in undriven):
        _warn(f"{path}: output {port} is driven by nothing (or set to x), in part or whole: Verilog reads z (or "
              "x) there and the network a constant 0; `verify` leaves those bits out of its comparison")
    netlist.undriven = undriven
    netlist.races, netlist.source, netlist.systemverilog = tuple(found), str(path), sv
    netlist.translate_off = skipped
    return clean(netlist, max_fanout=max_fanout)


def _undriven_outputs(module: dict) -> tuple[str, ...]:
    """The top's output bits (`port[i]`) nothing drives (an x in Yosys's netlist: `_check_drivers` let through
    only outputs nothing inside reads) or the source sets to x."""
    return tuple(f"{p}[{i}]" for p, row in module["ports"].items() if row["direction"] == "output"
                 for i, b in enumerate(row["bits"]) if b == "x")


def clean(netlist: Netlist, *, max_fanout: int | None = None) -> Netlist:
    """Apply the hygiene passes in order and renumber gates g0.. in topological order."""
    g = netlist.graph
    propagate_constants(g)
    remove_dead_gates(g)
    check_loops(g, netlist.top)
    buffer_feedthroughs(g)
    limit_fanout(g, max_fanout)
    netlist.graph = _renumbered(g)
    return netlist


def observe(netlist: Netlist, ports: list[str]) -> Netlist:
    """Keep only the output ports named (cone pruning): every gate and latch outside their fan-in cones
    goes, so a scene models what it observes.  The kept gates lose the loads of pruned ones; the cost of
    that in amplitude is measured in reports/fidelity.md."""
    unknown = [p for p in ports if p not in netlist.outputs]
    if unknown:
        raise Mech2SpiceError(f"--observe {', '.join(unknown)}: {netlist.top} has no such output "
                              f"(outputs: {', '.join(netlist.outputs)})")
    g = netlist.graph.copy()
    g.remove_nodes_from([n for n, d in g.nodes(data=True) if d["kind"] == "output" and d["port"] not in ports])
    remove_dead_gates(g)
    outputs = {p: w for p, w in netlist.outputs.items() if p in ports}
    held = any(d["kind"] == "latch" for _, d in g.nodes(data=True))
    return Netlist(netlist.top, _renumbered(g), dict(netlist.inputs), outputs, netlist.clock if held else None,
                   netlist.signed, netlist.races, netlist.source, netlist.systemverilog, netlist.clock_edge,
                   netlist.constant_registers, netlist.sampled if held else ())


# --------------------------------------------------------------------------- running Yosys

def _warn_translate_off(path: Path, text: str) -> tuple[tuple[int, int], ...]:
    """Say where synthesis and a simulator read different text: a `translate_off` region (often a power-up
    value or a check meant for simulation only) is in Icarus's run of the source and not in the network.
    Its (first line, last line) each."""
    lines = tuple((line_of(text, a), line_of(text, b)) for a, b in translate_off_regions(text))
    for first, last in lines:
        _warn(f"{path}, lines {first}-{last}: a `translate_off` region: synthesis, and so the network, leaves "
              "it out, while a simulator (Icarus, in `verify`) runs it; a value it gives a register shows in "
              "verify as a difference")
    return lines


def _read_source(path: Path) -> str:
    return read_input(path, "Verilog file").decode("utf-8", errors="replace")


# What an `initial` block may not hold: each is an event in simulated time, and a power-up value is the state
# the network is prepared in before time starts (docs/rtl.md, "programming by initial conditions").
_NOT_AN_INITIAL_VALUE = [
    (re.compile(r"#"), "a delay (`#`)", "a delay is an event after time zero, not a power-up value"),
    (re.compile(r"@|\bwait\b"), "an event control (`@`, `wait`)",
     "waiting for an event is behaviour over time, not a power-up value"),
    (re.compile(r"\$[A-Za-z_]\w*"), "a system task", "it acts while a simulation runs (printing, stopping, "
     "reading time) and builds no hardware"),
    (re.compile(r"\b(?:forever|while|repeat|fork|disable)\b|->"), "a loop or process over time",
     "it runs as simulated time passes; only a `for` loop with constant bounds, unrolled into constant "
     "assignments, is a power-up value"),
]


# Severity and stopping tasks: Yosys refuses each one in an `initial` block it elaborates (`_yosys_task`), so
# one that only guards a generate branch never built (alexforencich's `$error; $finish` on a bad parameter)
# is left to it rather than refused as text.
_ELABORATION_TASKS = {"$error", "$fatal", "$warning", "$info", "$finish", "$stop"}
_YOSYS_TASK = re.compile(r"line (?P<line>\d+): (?:Can't resolve task name|System task) `(?P<task>\$\w+)'")


def _only_elaboration_tasks(body: str) -> bool:
    """Every system task in an `initial` block's text is one Yosys refuses where it elaborates the block."""
    return set(re.findall(r"\$[A-Za-z_]\w*", body)) <= _ELABORATION_TASKS


def _yosys_task(msg: str, path: Path, source: str) -> str | None:
    """Yosys's refusal of a severity or stopping task: in an elaborated `initial` block as `_check_source`'s;
    in an `always` block (only the stopping ones reach Yosys there: dialect._severity_as_print) as a stop."""
    m = _YOSYS_TASK.search(msg)
    if not m or m["task"] not in _ELABORATION_TASKS:
        return None
    blanked = _blanked(source)
    line_start = sum(len(t) + 1 for t in blanked.split("\n")[:int(m["line"]) - 1])
    at = blanked.find(m["task"], line_start)
    kind = process_at(blanked, at if at >= 0 else line_start)
    if kind and kind.startswith("always"):
        return (f"{path}, line {m['line']}: a system task (`{m['task']}`) in an `{kind}` block: it stops the "
                "simulation, which a network of gates cannot do (it has no end); remove it or guard it with "
                "`ifndef SYNTHESIS`")
    what, why = next(row[1:] for row in _NOT_AN_INITIAL_VALUE if row[1] == "a system task")
    return f"{path}, line {m['line']}: {what} (`{m['task']}`) in an `initial` block: {why}"


_EVENT_LIST = re.compile(r"\balways\s*@\s*\(([^()]*)\)")
_EDGE = re.compile(r"\b(posedge|negedge)\s+([A-Za-z_][\w$]*)")
_FIRST_IF = re.compile(r"\s*(?:begin\b(?:\s*:\s*[A-Za-z_][\w$]*)?\s*)?if\s*\(")


def _untested_edge(msg: str, path: Path, source: str) -> str | None:
    """Yosys's "Multiple edge sensitive events found" (no line, no reason) as the block it means: one whose
    event list has several edges and whose first `if` tests none of their signals, so no edge reads as an
    asynchronous reset or set and each is a clock (RTLLM's synchronizer: `negedge arstn`, `if (!brstn)`)."""
    if "Multiple edge sensitive events found" not in msg:
        return None
    text = _blanked(source)
    for m in _EVENT_LIST.finditer(text):
        edges = _EDGE.findall(m.group(1))
        first_if = _FIRST_IF.match(text, m.end())
        tested = set(re.findall(r"[A-Za-z_][\w$]*", _parenthesised(text, first_if.end() - 1))) if first_if else set()
        if len(edges) < 2 or any(sig in tested for _, sig in edges):
            continue
        line = text.count("\n", 0, m.start()) + 1
        listed = " or ".join(f"{e} {s}" for e, s in edges)
        edge, sig = edges[-1]
        return (f"{path}, line {line}: the block's events are `{listed}`, but its first `if` tests none of "
                f"{', '.join(sorted({s for _, s in edges}))}: an edge the block does not test is a clock, so this is "
                "a flip-flop on several clocks; an asynchronous reset or set is tested by its own signal "
                f"(`if ({'!' if edge == 'negedge' else ''}{sig})` for `{edge} {sig}`)")
    return None


def _parenthesised(text: str, open_at: int) -> str:
    """What the parenthesis at `open_at` encloses (to the end of the text if it is never closed)."""
    depth = 0
    for k in range(open_at, len(text)):
        depth += {"(": 1, ")": -1}.get(text[k], 0)
        if depth == 0:
            return text[open_at + 1:k]
    return text[open_at + 1:]


# Switch-level primitives and the charge-storing net (IEEE 1364-2005 7.7-7.11, 4.6.4): reserved words, so a
# match outside comments, strings and escaped names is one.
_SWITCH_LEVEL = re.compile(r"(?<![\w$])(?:r?[npc]mos|r?tran(?:if[01])?|trireg|pullup|pulldown)\b")


def _check_source(path: Path, text: str) -> None:
    """Names are ASCII; no switch-level primitive; `initial` blocks may only give constant values (power-up
    values and ROM contents): anything that happens in simulated time is refused with its line.  A
    `translate_off` region is left out, as synthesis leaves it out (`_warn_translate_off` says so)."""
    blanked = _blanked(text)
    for a, b in translate_off_regions(text):
        blanked = blanked[:a] + re.sub(r"[^\n]", " ", blanked[a:b]) + blanked[b:]
    wide = re.search(r"[^\x00-\x7f]", blanked)
    if wide:
        line = blanked.count("\n", 0, wide.start()) + 1
        raise Mech2SpiceError(f"{path}, line {line}: the character {wide.group()!r} outside comments and strings: "
                              "Verilog names are ASCII (an escaped identifier holds printable ASCII characters, "
                              "IEEE 1364-2005 3.7.1), and Yosys writes any other character garbled")
    switch = _SWITCH_LEVEL.search(re.sub(r"\\\S+", lambda m: " " * len(m.group()), blanked))
    if switch:
        line = blanked.count("\n", 0, switch.start()) + 1
        raise Mech2SpiceError(f"{path}, line {line}: `{switch.group()}` is a switch-level primitive (a transistor, "
                              "a bidirectional switch, a pull or a charge-storing net): it models conduction, "
                              "drive strength and stored charge, which a network of logic gates has no "
                              "counterpart for; write the logic it implements (a flip-flop as `always @(posedge "
                              "clk)`)")
    for m in re.finditer(r"\binitial\b", blanked):
        body_start, body_end = m.end(), statement_or_block_end(blanked, m.end())
        body = _data_reads_and_prints_blanked(path, text, blanked, body_start, body_end)
        for pattern, what, why in _NOT_AN_INITIAL_VALUE:
            if what == "a system task" and _only_elaboration_tasks(body):
                continue                    # Yosys decides, where it builds the block
            hit = pattern.search(body)
            if hit:
                line = blanked.count("\n", 0, body_start + hit.start()) + 1
                raise Mech2SpiceError(f"{path}, line {line}: {what} in an `initial` block: {why}")


_PRINT_CALL = re.compile(r"\$(?:display|write)\b\s*(?:\([^;]*\))?\s*;")


def _data_reads_and_prints_blanked(path: Path, text: str, blanked: str, start: int, end: int) -> str:
    """An `initial` body with what it may hold besides constants blanked: `$readmemh`/`$readmemb` of a file in
    the design's folder (the ROM's contents, read as data by every tool), refused with its line and reason
    otherwise; and `$display`/`$write`, a print, left out as in an always block (build_netlist warns)."""
    body = blanked[start:end]
    for a, b, name in readmem_calls(text):
        if not start <= a < end:
            continue
        problem = readmem_problem(name, path.parent, hexadecimal=text[a + 8] == "h")
        if problem:
            raise Mech2SpiceError(f"{path}, line {line_of(text, a)}: `$readmemh`/`$readmemb` in an `initial` "
                                  f"block: {problem}")
        body = body[:a - start] + " " * (b - a) + body[b - start:]
    return _PRINT_CALL.sub(lambda x: " " * len(x.group()), body)


_NON_CONSTANT_INIT = re.compile(r"Failed to get a constant init value for \\?(\S+?): \\?(\S+)")


def _non_constant_init(msg: str, path: Path) -> str | None:
    """Yosys's 'Failed to get a constant init value for \\q: \\a' as a message with the file and line."""
    m = _NON_CONSTANT_INIT.search(msg)
    if not m:
        return None
    text = _blanked(_read_source(path))
    hit = re.search(rf"(?<![\w$]){re.escape(m[1])}\s*(?:\[[^\]]*\]\s*)*=(?!=)[^;]*(?<![\w$]){re.escape(m[2])}(?![\w$])",
                    text)
    where = f"{path}, line {text.count(chr(10), 0, hit.start()) + 1}" if hit else str(path)
    return (f"{where}: the power-up value of '{m[1]}' is given as '{m[2]}', not a constant: a power-up value is "
            "the state the network is prepared in before any input is applied, so it must be a constant")


# The attribute the flow marks the source's register wires with (`_flow`).
REGISTER_ATTR = "m2s_register"


def _read_flow(source: str, include: str | None, sv: bool | None) -> list[str]:
    """The Yosys commands that read the source: its parse in ast.txt, every module as read in read.il.
    -defer: each module is elaborated by `hierarchy`, once, at the parameters its instance gives; read without
    it, every module was first elaborated at its defaults, where a library module's constant functions can
    take Yosys minutes or never end (verilog-lfsr's lfsr_mask at its default width 31, public RTL pass 8)."""
    read = "read_verilog -sv" if (source.endswith(".sv") if sv is None else sv) else "read_verilog"
    read += identifiers.yosys_include(include)
    return [f'tee -o ast.txt {read} -defer -dump_ast1 {identifiers.yosys_path(source)}',   # not -q: its errors must reach the log
            "write_rtlil read.il"]


def _one_module(source: str) -> bool:
    """Whether the source declares one module and includes no file (its top needs no search)."""
    return "`include" not in source and len(re.findall(r"(?<![\w$`])(?:macro)?module\b", _blanked(source))) == 1


def _find_top(tmp: str, rel: str, include: str | None, sv: bool, path: Path) -> str | None:
    """The top module of a source given without --top, from its parse alone (refusals.single_top: several
    candidates are refused), so that `hierarchy` elaborates only what that top instantiates: its -auto-top
    elaborates every module at its defaults first.  None where the source does not read here (the flow then
    reads it again and reports the error as it does) or where the top is a name a script cannot hold."""
    for reading in (sv, True) if not sv else (True,):
        if yosys.run_script("\n".join(_read_flow(rel, include, reading) + [""]), tmp).returncode == 0:
            top = refusals.single_top(Path(tmp), path)
            try:
                return top if top is None else (identifiers.yosys_module(top) and top)
            except Mech2SpiceError:
                return None
    return None


def _flow(source: str, top: str | None, include: str | None = None, sv: bool | None = None,
          sampled: bool = False) -> str:
    """The Yosys script: NOR/NOT mapping per the toolchain notes (NOT -> NOR(A,0) is done in Python).
    `include`: a folder to search for `include files (the original's, when Yosys reads a rewritten copy);
    `sv`: read as SystemVerilog (default: a `.sv` file); `sampled`: every flip-flop sampled once a mechanical
    cycle (`yosys.SAMPLE_CLOCKS`)."""
    return "\n".join([                             # ast.txt, *.il: for refusals.py
        *_read_flow(source, include, sv),
        f"hierarchy -check -top {identifiers.yosys_module(top)}" if top else "hierarchy -check -auto-top",
        # hierarchy has made each wired-OR/AND net (`wor`, `wand`) an OR/AND of its drivers; left on the wire,
        # the mark would make synth's own `hierarchy` do it again after the mapping, unmapped
        "setattr -unset wor -unset wand w:*",
        yosys.COMB_AS_STAR,
        "proc -noopt",                              # `proc` less its opt_expr, which can fold away one of
        "write_rtlil drivers.il",                   # two conflicting drivers: the nets as written
        "opt_expr -keepdc",                         # the rest of `proc`
        "tee -q -o init.txt select -list a:init",   # declaration initialisers (`reg q = 1`)
        "tee -q -o check.txt check",                # undriven nets, before synth folds them to constants
        "flatten",
        # the source's registers, marked on their wires (hdlname: the instance path) before synthesis merges
        # and renames them: verify starts the ones without a power-up value where the network starts them
        f"setattr -set {REGISTER_ATTR} 1 t:$*dff* %co:+[Q] t:* %d",
        maps.MAP_POW,                               # `a ** b`, b not constant (synthesis/maps.py)
        "tribuf -formal",                           # tri-state buses -> multiplexers (docs/rtl.md) ...
        "delete n:$tribuf_conflict*",               # ... less its no-two-drivers checks: Icarus co-simulates
        # sampled clocks: the flip-flops only; a level-sensitive latch stays one, for `_check_dlatches`
        *(("memory", "opt_clean", "clk2fflogic t:$*dff*", *yosys.SAMPLE_CLOCKS[1:]) if sampled else ()),
        # -nofsm: a state register keeps the source's encoding, so the network powers up in a state the source
        # has and every register keeps its name (verify starts it on Icarus); docs/rtl.md, "State machines"
        "synth -flatten -nofsm" + (f" -top {identifiers.yosys_module(top)}" if top else ""),   # (memories: `memory` + `memory_map` in it)
        "dffunmap",                                 # enables/resets -> plain flip-flops + logic
        "abc -g NOR", "opt_clean",
        "abc -g NOR", "opt_clean",                  # a 2nd pass trims e.g. comparator4 39 -> 36
        "write_json netlist.json", ""])


def _run_yosys(path: Path, top: str | None, source: str, sampled: bool = False) -> tuple[str, dict, list, list, bool, list]:
    """(top module name, its Yosys JSON module, the source's races, the top's output ports a tri-state driver
    may release, whether it was read as SystemVerilog, the always blocks accepted with an alias left out of
    their sensitivity lists): from the cache when this source went through this flow
    and this Yosys before, else from a run of the flow in a scratch folder (`_yosys_run`)."""
    key = _cache_key(source, top, path.suffix == ".sv", path.name, sampled, _data_digest(source, path))
    cached = _cache_read(key)
    if cached is not None:
        return cached
    result = _yosys_run(path, top, source, sampled)
    _cache_write(key, *result)
    return result


def _data_digest(source: str, path: Path) -> str:
    """A digest of the files the source's `$readmem` calls read (its ROMs' contents are part of the design)."""
    names = [n for _, _, n in readmem_calls(source) if n is not None and readmem_problem(n, path.parent, None) is None]
    if not names:
        return ""                       # the key of a design without ROM files is what it was
    h = hashlib.sha256()
    for name in names:
        h.update(name.encode() + b"\0" + read_input(path.parent / name, "$readmem file") + b"\0")
    return h.hexdigest()


def _cache_key(source: str, top: str | None, sv: bool = False, name: str = "", sampled: bool = False,
               data: str = "") -> str | None:
    """A content key of (flow, source, its file name, Yosys build, refusal checks); None for a source with
    `include (other files take part).  The name: Yosys's src attributes carry it, and messages give a cell's
    line only where that name is the design's (refusals.src_line)."""
    if "`include" in source:
        return None
    text = json.dumps([_flow("SOURCE", top, sv=sv, sampled=sampled), maps.POW_MAP, source, name, yosys.identity(),
                       refusals.VERSION, data])
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def _cache_path(key: str) -> Path:
    from .._cache import cache_dir
    return cache_dir() / "yosys" / f"{key}.json"


def _cache_read(key: str | None) -> tuple[str, dict, list, list, bool, list] | None:
    """The cached (top, module); None (Yosys runs again and replaces the entry) when there is none or it is
    not a Yosys JSON module in the shape build_netlist reads: the cache is rebuildable data, anyone's."""
    if key is None:
        return None
    try:
        data = json.loads(_cache_path(key).read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError):
        return None
    if not (isinstance(data, dict) and isinstance(data.get("top"), str) and _is_module(data.get("module"))):
        return None
    found, released = _cached_races(data.get("races")), data.get("released")
    if found is None or not (isinstance(released, list) and all(isinstance(p, str) for p in released)):
        return None
    aliased = _cached_aliases(data.get("aliased"))
    if not isinstance(data.get("sv"), bool) or aliased is None:
        return None
    return data["top"], data["module"], found, released, data["sv"], aliased


def _cached_aliases(rows) -> list | None:
    """The alias reads a cache entry lists; None when it is no list of them (the entry is then rebuilt)."""
    try:
        found = [refusals.AliasRead(row["line"], tuple(row["names"]), tuple(row["listed"])) for row in rows]
    except (TypeError, KeyError):
        return None
    ok = all((r.line is None or type(r.line) is int) and len(r.names) == len(r.listed)
             and all(isinstance(v, str) for v in r.names + r.listed) for r in found)
    return found if ok else None


def _cached_races(rows) -> list | None:
    """The races a cache entry lists; None when it is no list of them (the entry is then rebuilt)."""
    try:
        found = [races.Race(**row) for row in rows]
    except TypeError:
        return None
    text = all(isinstance(v, str) for r in found for v in (r.module, r.variable, r.edge))
    lines = all(v is None or type(v) is int for r in found for v in (r.write_line, r.read_line))
    return found if text and lines else None


def _is_module(module) -> bool:
    """Ports, cells and net names with the fields and types build_netlist uses."""
    def table(key: str, fields: dict) -> bool:
        rows = module.get(key)
        return isinstance(rows, dict) and all(
            isinstance(name, str) and isinstance(row, dict) and all(ok(row.get(f)) for f, ok in fields.items())
            for name, row in rows.items())

    def bits(v) -> bool:
        return isinstance(v, list) and all(isinstance(b, (int, str)) and not isinstance(b, bool) for b in v)

    def pins(v) -> bool:
        return isinstance(v, dict) and all(isinstance(p, str) and bits(b) and b for p, b in v.items())
    return isinstance(module, dict) and table("ports", {"direction": lambda v: isinstance(v, str), "bits": bits}) \
        and table("cells", {"type": lambda v: isinstance(v, str), "connections": pins}) \
        and table("netnames", {"hide_name": lambda v: isinstance(v, int), "bits": bits})


def _cache_write(key: str | None, name: str, module: dict, found: list, released: list, sv: bool,
                 aliased: list) -> None:
    """Keep a synthesised module (atomically; a cache that cannot be written is skipped)."""
    if key is None:
        return
    path = _cache_path(key)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
        tmp.write_text(json.dumps({"top": name, "module": module, "races": [r.as_dict() for r in found],
                                   "released": released, "sv": sv,
                                   "aliased": [{"line": a.line, "names": list(a.names), "listed": list(a.listed)}
                                               for a in aliased]}))
        os.replace(tmp, path)
    except OSError:
        pass


# Yosys's errors on a `.v` that holds SystemVerilog (then read again as SystemVerilog, as Icarus reads it): a
# syntax error, or its own word for a construct only SystemVerilog has (nandland's `localparam` list whose
# later names have no keyword).
_SV_ONLY = ("syntax error", "In pure Verilog (not SystemVerilog)")


def _yosys_run(path: Path, top: str | None, source: str, sampled: bool = False) -> tuple[str, dict, list, list, bool, list]:
    """Run the flow in a scratch folder; return what `_run_yosys` does.  `source` is the
    text to read: the file's own, or its standard rewriting (dialect.py), which then is read from the folder."""
    with tempfile.TemporaryDirectory(prefix="mech2spice_yosys_") as tmp:
        # A relative path works for both yowasp (which maps /tmp elsewhere) and `include`s.
        rel = Path(os.path.relpath(path.resolve(), Path(tmp).resolve())).as_posix()
        include = None
        if source != _read_source(path):
            rel = f"src/{path.name}"
            (Path(tmp) / "src").mkdir()
            (Path(tmp) / rel).write_text(source, encoding="utf-8")
            link_readmem_files(source, path.resolve().parent, Path(tmp) / "src")
            include = Path(os.path.relpath(path.resolve().parent, Path(tmp).resolve())).as_posix()
        sv = path.suffix == ".sv"
        maps.write_maps(tmp)
        if top is None and not _one_module(source):
            top = _find_top(tmp, rel, include, sv, path)
        result = yosys.run_script(_flow(rel, top, include, sv=sv, sampled=sampled), tmp)
        if result.returncode != 0 and not sv and any(m in yosys.error_line(result) for m in _SV_ONLY):
            # a `.v` written with SystemVerilog constructs (`for (int i = 0; ...; i++)`), as Icarus reads it
            # in verify (verify.generations): the first reading's error stands if this one fails too
            retry = yosys.run_script(_flow(rel, top, include, sv=True, sampled=sampled), tmp)
            result, sv = (retry, True) if retry.returncode == 0 else (result, False)
        _refuse_real(result, rel, path)
        _refuse_net_in_block(result, rel, path)
        if result.returncode != 0:
            msg = yosys.error_line(result).replace(rel, str(path))
            for known in (_non_constant_init(msg, path), _yosys_task(msg, path, source), _untested_edge(msg, path, source)):
                if known is not None:
                    raise Mech2SpiceError(known)
            if top is not None and top.startswith("\\") and "not found" in msg:    # `\my.top ` as written
                msg += f"; an escaped name is given without its backslash and trailing space (--top {top[1:]})"
            if "Assert `" in msg:           # WangXuan95's fxp_add (public RTL pass 10): Yosys's own defect
                msg = msg.rstrip(".") + ("; this is an internal check of Yosys failing, a defect of Yosys's reading, not a "
                        "refusal of the source (Icarus may well run it)")
            raise Mech2SpiceError(f"yosys error: {msg}" if str(path) in msg
                                  else f"yosys error: {path}: {msg}")
        released, aliased = refusals.check(Path(tmp), path, source, top)
        found = races.find((Path(tmp) / "ast.txt").read_text(), path)
        out = Path(tmp) / "netlist.json"
        if not out.exists():
            raise Mech2SpiceError(f"yosys wrote no netlist for {path} (its run stopped early)")
        modules = json.loads(out.read_text())["modules"]
        name, module = _pick_top(modules, top, path)
        _check_drivers(Path(tmp), path, name, module)
    outputs = {p for p, row in module["ports"].items() if row["direction"] == "output"}
    return name, module, found, [p for p in released.get(name, []) if p in outputs], sv, aliased


_REAL = re.compile(r"^(?P<file>\S+?):(?P<line>\d+): Warning: "
                   r"converting real value (?P<real>\S+) to binary (?P<bin>-?\d+)(?:'(?P<bits>[01]+))?", re.M)


def _refuse_real(result, rel: str, path: Path) -> None:
    """Refuse a real number that became logic: Yosys rounds it (`a * 1.5` is `a * 2`, or its cell fails)
    where Icarus computes with the real value, so the network would answer differently."""
    for m in _REAL.finditer(result.stdout + "\n" + result.stderr):
        # width'bits (`8'00000010`): the real given to a sized parameter, which the language itself converts
        # (rounded, as Icarus does), not a real in arithmetic
        sized = m["bits"] is not None
        value = int(m["bits"], 2) if sized else int(m["bin"])
        exact = sized or float(m["real"]).is_integer()         # 8.0 is 8 to both readers
        if exact and result.returncode == 0:
            continue
        where = f"{path}, line {m['line']}" if m["file"] == rel else str(path)
        why = "Yosys cannot build logic from it" if exact else \
            f"Yosys rounds it to {value} while a simulator computes with {float(m['real']):g}"
        raise Mech2SpiceError(f"{where}: the real number {float(m['real']):g} in logic: {why}; the network "
                              "computes with bits: write an integer (or scale to fixed point)")


_NET_IN_BLOCK = re.compile(r"Warning: wire '\\?(?P<net>[^']+)' is assigned in a block at (?P<file>\S+?):(?P<line>\d+)\.")


def _refuse_net_in_block(result, rel: str, path: Path) -> None:
    """Refuse a procedural assignment to a net (`output out; always @(posedge clk) out <= d;`, VTR's
    multiclock_reader_writer.v): IEEE 1364 10.2 and 1800 10.4 allow it to variables only, Icarus and every
    simulator refuse the file, and Yosys alone builds logic from it (with a warning), so the network would
    stand for a source nothing can check it against."""
    # a function's own variables (`name$func$...`): a function may assign its inputs, Yosys warns all the same
    m = next((m for m in _NET_IN_BLOCK.finditer(result.stdout + "\n" + result.stderr) if "$func$" not in m["net"]),
             None)
    if m:
        where = f"{path}, line {m['line']}" if m["file"] == rel else str(path)
        raise Mech2SpiceError(f"{where}: '{m['net']}' is a net (a wire or a port without `reg`) assigned in an "
                              "always block, which Verilog allows only for variables and no simulator accepts: "
                              f"declare it `reg` (`output reg {m['net']}`) or `logic`")


_UNDRIVEN = re.compile(r"Wire (?P<mod>[^.\s]+)\.\\?(?P<net>.+?) is used but has no driver")


def _check_drivers(tmp: Path, path: Path, top: str, module: dict) -> None:
    """Refuse nets nothing drives (Yosys reads them as x, and synthesis would silently fold x into a
    constant), except the top's output ports that nothing inside reads: there z stays where Verilog puts it,
    on the output (`_undriven_outputs` names them).  Declaration initialisers are power-up values
    (build_netlist reads them)."""
    undriven = [m for m in map(_UNDRIVEN.search, (tmp / "check.txt").read_text().splitlines()) if m]
    outputs = {p for p, row in module["ports"].items() if row["direction"] == "output"}
    alone = {m["net"].split(" [")[0] for m in undriven if m["mod"] == top} & outputs
    alone -= _read_inside(tmp, top, alone)
    for m in undriven:
        if m["mod"] != top or m["net"].split(" [")[0] not in alone:
            net = m["net"].replace(" ", "")
            raise Mech2SpiceError(f"{path}: in module {m['mod']}, '{net}' is used but nothing drives it: "
                                  "Verilog reads it as z (a wire) or x (a reg or memory word never assigned), "
                                  "which synthesis would fold into a constant no simulator shows; assign it a value")


_PLAIN_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_$]*")


def _read_inside(tmp: Path, top: str, ports: set[str]) -> set[str]:
    """The output ports among `ports` that a cell of the top module reads, directly or through wires joined to
    them (Yosys's output cone of the wire, every step, before flattening: any cell in it reads the port).
    A name a Yosys pattern cannot hold plainly counts as read (the refusal stands)."""
    plain = sorted(p for p in ports if _PLAIN_NAME.fullmatch(p)) if _PLAIN_NAME.fullmatch(top) else []
    if not plain:
        return set(ports)
    mod = identifiers.yosys_module(top)
    script = ["read_rtlil drivers.il"] + [f"tee -q -o readers{k}.txt select -list {mod}/w:{identifiers.yosys(p)} %co* "
                                          f"{mod}/t:* %i" for k, p in enumerate(plain)]
    result = yosys.run_script("\n".join(script) + "\n", tmp)
    if result.returncode != 0:
        return set(ports)
    read = {p for k, p in enumerate(plain) if (tmp / f"readers{k}.txt").read_text().strip()}
    return read | (ports - set(plain))


def _pick_top(modules: dict, top: str | None, path: Path) -> tuple[str, dict]:
    """(the top's name as the source spells it, its Yosys JSON module)."""
    name, module = _top_module(modules, top, path)
    return (name[1:] if name.startswith("\\$") else name), module    # JSON keeps `\$add`'s backslash


def _top_module(modules: dict, top: str | None, path: Path) -> tuple[str, dict]:
    if top is not None and top in modules:
        return top, modules[top]
    for name, mod in modules.items():
        if int(str(mod.get("attributes", {}).get("top", "0")), 2) == 1:
            return name, mod
    if not modules:
        raise Mech2SpiceError(f"{path}: no Verilog module found")
    if len(modules) == 1:
        return next(iter(modules.items()))
    raise Mech2SpiceError(f"{path}: cannot tell the top module; pass top=")


# --------------------------------------------------------------------------- JSON -> graph

# Cell type -> (node kind, input pins in pin order, output pin).  None = tied to const0.
_CELLS = {
    "$_NOR_": ("nor", ("A", "B"), "Y"),
    "$_NOT_": ("nor", ("A", None), "Y"),
    "$_DFF_P_": ("latch", ("D",), "Q"),
    "$_DFF_N_": ("latch", ("D",), "Q"),         # every flip-flop on the falling edge: the same one pulse
    "$_FF_": ("latch", ("D",), "Q"),            # a register of the mechanical clock itself (sampled clocks)
    # a level-sensitive latch: a multiplexer before a latch of the clock (`_connect_dlatch`), where its enable
    # changes only at clock edges (`_check_dlatches`)
    "$_DLATCH_P_": ("dlatch", ("E", "D"), "Q"),
    "$_DLATCH_N_": ("dlatch", ("E", "D"), "Q"),
}
# Flip-flops (on the rising or falling edge) with an asynchronous reset (value 0) or set (value 1), active
# high (P) or low (N).
_FORCED = re.compile(r"^\$_DFF_(?P<edge>[PN])(?P<polarity>[NP])(?P<value>[01])_$")
# A level-sensitive latch with a reset or set (E polarity, R polarity, value): Yosys's reading of a branch
# that assigns a constant, Q = R ? value : (E ? D : Q).
_FORCED_DLATCH = re.compile(r"^\$_DLATCH_(?P<enable>[NP])(?P<polarity>[NP])(?P<value>[01])_$")
_SEQUENTIAL = re.compile(r"^\$_?(?:\w*dff\w*|\w*dlatch\w*|sr|ff|mem\w*)(?:_|$)", re.I)
_NAMED = {"$check": "assert/assume/cover"}
# Why it is refused rather than dropped: dropping would silently change what the source says it does.
_NOT_LOGIC = {
    "$check": "states a property for a simulator or a formal tool to check, not a value to compute: a NOR "
              "network cannot stop or flag a run when it fails; remove it or guard it with `ifndef SYNTHESIS`"}
# $display/$write in an always block: text for whoever watches a simulation, no value any output depends on,
# so the network leaves it out (as every synthesis tool does; $strobe/$monitor Yosys drops itself), saying so.
_PRINT = "$print"


def map_cell(cell_type: str, top: str) -> tuple[str, tuple, str] | None:
    """The graph node kind and pin layout for one Yosys cell type (None: skip); errors for the rest."""
    if cell_type in _CELLS:
        return _CELLS[cell_type]
    if _FORCED.match(cell_type):
        return "latch", ("D", "R"), "Q"
    if cell_type in ("$scopeinfo", _PRINT):     # flatten's record of the hierarchy; a print (_PRINT): no logic
        return None
    if re.match(r"^\$_DFFSRE?_\w+_$", cell_type):
        raise Mech2SpiceError(
            f"module {top}: a flip-flop with both an asynchronous set and an asynchronous reset ({cell_type}) "
            "has no one meaning: a simulator re-evaluates it only on their edges (releasing the reset while "
            "the set is held leaves Q at 0 until the next clock), synthesis treats both as levels (Q goes to 1 "
            "at once), so no network can agree with the source in every sequence; keep one of the two "
            "asynchronous, make the other synchronous")
    if re.match(r"^\$_ALDFFE?_\w+_$", cell_type):
        raise Mech2SpiceError(
            f"module {top}: an asynchronous load of a signal ({cell_type}) makes the register transparent to "
            "a second data input whenever the load is asserted, a level-sensitive latch on a data path; "
            "reset or set it to a constant instead")
    if _FORCED_DLATCH.match(cell_type):        # a listed branch's constant, folded into a reset or set pin
        return "dlatch", ("E", "D", "R"), "Q"
    if "DLATCH" in cell_type.upper():          # both a reset and a set
        raise Mech2SpiceError(f"module {top}: Yosys inferred a level-sensitive latch ({cell_type}); "
                              "assign every signal on every path of combinational always blocks")
    if _SEQUENTIAL.match(cell_type):
        raise Mech2SpiceError(f"module {top}: sequential cell {cell_type} has no mechanical counterpart: the "
                              "latch is a flip-flop capturing on the one clock pulse, optionally forced by one "
                              "asynchronous set or reset")
    if cell_type in _NAMED:
        raise Mech2SpiceError(f"module {top}: {_NAMED[cell_type]} {_NOT_LOGIC[cell_type]}")
    raise Mech2SpiceError(f"module {top}: Yosys cell type {cell_type} has no NOR-gate mapping in this flow "
                          "(only logic, posedge flip-flops and their resets reach the mechanical network)")


def build_netlist(top: str, module: dict, path: Path | None = None, sampled: tuple = ()) -> Netlist:
    """Build the raw (pre-hygiene) graph from a Yosys JSON module (`path`: its Verilog, for messages;
    `sampled`: the source's clock ports, where the flow sampled them)."""
    g = nx.DiGraph()
    _refuse_inout(top, module, path)
    inputs, outputs, driver = _add_inputs(g, top, module)
    if not outputs:
        raise Mech2SpiceError(f"module {top} has no output ports: nothing to synthesize")
    cells = _add_cells(g, top, module, driver, path)
    names = _net_names(module)
    clock = _clock_port(g, top, module, driver, path)
    power_up = _initial_values(module)
    registers, constant, initial = _source_registers(module, power_up)
    # a register bit left with no driver at all (its flip-flop dropped) reads as 0 here (`_source`)
    constant += tuple((path, index, 0) for bit, regs in registers.items() if bit not in driver for path, index in regs)
    for node, (pins, out_net) in cells.items():
        g.nodes[node]["net"] = names.get(out_net, f"${out_net}")
        sources = [_source(g, b, driver, top) for b in pins]
        if g.nodes[node]["kind"] == "latch":
            try:
                _connect_latch(g, node, sources, power_up.get(out_net))
            except _Sampled as need:
                raise _Sampled(str(need), (clock,)) from None
            # sampled: a register's wire is logic of the cycle's samples, and a latch fed from it holds it
            held = registers.get(out_net) or (registers.get(pins[0]) if sampled else None)
            if held:
                g.nodes[node]["registers"] = held
        elif g.nodes[node]["kind"] == "dlatch":
            _connect_dlatch(g, node, sources, names.get(out_net, f"${out_net}"))
        else:
            _connect_gate(g, node, sources)
    _check_dlatches(g, clock, tuple(sampled))
    for port, bits in _ports(module, "output"):
        for i, bit in enumerate(bits):
            if not isinstance(bit, str) and bit not in driver:      # 'x' is a chosen don't-care: 0
                raise Mech2SpiceError(f"module {top}: output {port}[{i}] is not driven by anything: assign it")
            if bit == "z":
                raise Mech2SpiceError(f"{_port_where(module, port, path, top)}: output {port}[{i}] is tied to "
                                      "'z' (released, with no enable that ever drives it): a mechanical output "
                                      "always carries an amplitude; assign it a value")
            node = f"{port}[{i}]"
            g.add_node(node, kind="output", port=port, bit=i)
            g.add_edge(_source(g, bit, driver, top), node)
    if clock is not None:
        for n in [f"{clock}[0]"]:
            if g.out_degree(n):             # its level matters between edges: sample it as an input
                raise _Sampled(f"module {top}: the clock '{clock}' is also used as data", (clock,))
            g.remove_node(n)
        inputs = {p: w for p, w in inputs.items() if p != clock}
    signed = frozenset(p for p, info in module["ports"].items() if info.get("signed") and p != clock)
    return Netlist(top, g, inputs, outputs, clock, signed, clock_edge=clock_edge(module) if clock else "posedge",
                   constant_registers=constant if clock or sampled else (), sampled=tuple(sampled),
                   initial_registers=initial if clock or sampled else ())


def _initial_values(module: dict) -> dict:
    """Net id -> power-up value 0/1 from the `init` attributes Yosys keeps on register outputs (declaration
    initialisers and constant `initial` assignments); x bits and malformed entries are left out."""
    out = {}
    for info in module["netnames"].values():
        init = _init_string(info)
        for bit, v in zip(info["bits"], reversed(init or "")):      # the attribute is written MSB first
            if v in "01" and not isinstance(bit, str):
                out[bit] = int(v)
    return out


def _init_string(info: dict) -> str | None:
    """A netname's `init` attribute as one character per bit, MSB first; None when it has none (or a malformed
    one: a cached module is anyone's data)."""
    attrs = info.get("attributes")
    init = attrs.get("init") if isinstance(attrs, dict) else None
    if isinstance(init, int) and not isinstance(init, bool):
        init = format(init % (1 << len(info["bits"])), f"0{len(info['bits'])}b")
    return init if isinstance(init, str) and len(init) == len(info["bits"]) else None


def _source_registers(module: dict, power_up: dict) -> tuple[dict, tuple, tuple]:
    """The source register bits that have no power-up value, each as (hierarchical path, bit index or None):
    the path is the instance names (Yosys's `hdlname`) then the register's name in its module, the index as
    declared (`reg [8:1] r`: r[1] is the first bit).  Returned: net id -> those it carries (several where
    synthesis merged equal registers), (path, index, value) for those synthesis made 0 or 1, and (path, index,
    value) for the bits that have a power-up value.  Read only from well-formed entries: a cached module is
    anyone's data."""
    out, constant, initial = {}, [], []
    for name, info in module["netnames"].items():
        attrs = info.get("attributes")
        if not isinstance(attrs, dict) or info.get("hide_name") or not (
                REGISTER_ATTR in attrs or _memory_word(name, attrs)):
            continue
        hdl = attrs.get("hdlname")
        path = tuple(hdl.split(" ")) if isinstance(hdl, str) and hdl.strip() else (name,)
        bits, offset = info["bits"], info.get("offset", 0)
        offset = offset if isinstance(offset, int) and not isinstance(offset, bool) else 0
        init = _init_string(info) or "x" * len(bits)
        for i, bit in enumerate(bits):
            index = None if len(bits) == 1 and offset == 0 else \
                offset + (len(bits) - 1 - i if info.get("upto") else i)
            if bit in power_up or init[-1 - i] in "01":
                initial.append((path, index, int(init[-1 - i]) if init[-1 - i] in "01" else power_up[bit]))
                continue
            if bit in ("0", "1"):
                constant.append((path, index, int(bit)))
            elif not isinstance(bit, str):      # an x bit is Yosys's don't care, read as it likes per use: no start
                out.setdefault(bit, []).append((path, index))
    return ({bit: tuple(sorted(regs)) for bit, regs in out.items()}, tuple(sorted(constant, key=repr)),
            tuple(sorted(initial, key=repr)))


def _memory_word(name: str, attrs: dict) -> bool:
    """Whether a netname is a word of a source memory as Yosys's memory_map names it (`mem[5]`, `u.mem[5]`): a
    name ending in an address, and no attribute at all, where every wire of the source has its `src`.  A name
    taken wrongly for one is tried on Icarus and left out there (verify._bind_start)."""
    return not attrs and re.fullmatch(r".+\[\d+\]", name) is not None


def _connect_latch(g: nx.DiGraph, q: str, sources: list[str], init: int | None) -> None:
    """Wire a latch: D, and for an asynchronous reset/set the forcing input F (active high) with the D-side
    gates that keep D low while F holds (docs/rtl.md).  The loop powers up storing 0 and F can only force it
    to 0 (a NOR input forces its output low, never high), so a register that powers up at 1 or is set to 1
    stores its complement (`inverted`).  One that powers up at 1 but resets to 0 (or at 0 and is set) raises
    `_Sampled`: sampled, its reset is logic before a plain latch that powers up at 1."""
    cell, where = g.nodes[q].pop("cell")
    forced = _FORCED.match(cell)
    inverted = int(forced["value"]) if forced else (init or 0)
    net = g.nodes[q]["net"]
    if forced and init is not None and init != inverted:     # the loop powers up at 0 and is forced to 0:
        raise _Sampled(f"{where}: register '{net}' powers up at {init} and is forced to {inverted}", ())
    if inverted:
        g.nodes[q]["inverted"] = 1
    d = sources[0]
    if not forced:
        g.add_edge(_not(g, d) if inverted else d, q, pin="D")
        return
    f = sources[1] if forced["polarity"] == "P" else _not(g, sources[1])
    g.add_edge(_nor(g, d if inverted else _not(g, d), f), q, pin="D")   # !D & !F  /  D & !F
    g.add_edge(f, q, pin="F")


def _connect_dlatch(g: nx.DiGraph, node: str, sources: list[str], net: str) -> None:
    """A level-sensitive latch Q = E ? D : held, `held` a latch of the clock that takes Q at every pulse:
    while E holds still between edges (`_check_dlatches`), that is the value Q had when E last closed.  The
    cell's node becomes the multiplexer's output gate; the latch powers up at 0 (the source's x refined)."""
    cell, what = g.nodes[node].pop("cell")
    enable, d = sources[:2]
    if cell[9] == "N":                                           # $_DLATCH_N_, $_DLATCH_N?V_
        enable = _not(g, enable)
    forced = _FORCED_DLATCH.match(cell)
    if forced:      # open while forced, taking the value: E' = E | R, D' = R ? value : D
        r = sources[2] if forced["polarity"] == "P" else _not(g, sources[2])
        enable = _not(g, _nor(g, enable, r))
        d = _not(g, _nor(g, r, d)) if forced["value"] == "1" else _nor(g, r, _not(g, d))
    number = g.graph.get("next_latch")
    if number is None:
        number = 1 + max((_gate_key(x)[0] for x in g if _kind(g, x) == "latch"), default=-1)
    g.graph["next_latch"] = number + 1
    held = f"q{number}"
    g.add_node(held, kind="latch", net=f"{net}$held", held=1, dlatch=(what, enable))
    g.add_edge(node, held, pin="D")
    both = _nor(g, _not(g, enable), _not(g, d))                  # E & D
    kept = _nor(g, enable, _not(g, held))                        # !E & held
    g.nodes[node].update(kind="nor")
    _connect_gate(g, node, [_nor(g, both, kept), _const(g, 0)])  # their OR


def _check_dlatches(g: nx.DiGraph, clock: str | None, sampled: tuple = ()) -> None:
    """Refuse a level-sensitive latch whose enable can close between clock edges: its held value would be the
    one at that moment, which no latch of the clock captures.  Between edges only inputs change, and registers
    an asynchronous reset or set forces: the enable may follow neither, except to open when a reset forces
    (`_closes_when_forced`).  Sampled clocks (`sampled`) change only at edges: an enable may follow them."""
    plain = nx.subgraph_view(g, filter_edge=lambda u, v: g.nodes[v]["kind"] != "latch")   # cut at every latch
    warned = set()
    for q, attrs in list(g.nodes(data=True)):
        if "dlatch" not in attrs:
            continue
        what, enable = attrs.pop("dlatch")
        cone = nx.ancestors(plain, enable) | {enable}
        ports = sorted({g.nodes[n]["port"] for n in cone if g.nodes[n]["kind"] == "input"} - set(sampled))
        if clock is not None and clock in ports:     # verilog-eval's `always @(*) if (clock) p = a;`
            raise Mech2SpiceError(
                f"{what}: its enable follows the clock '{clock}' itself, so it is transparent for a whole phase of "
                "the clock and its output follows its input within the cycle, which no latch of the network does "
                "(each captures once a cycle, on the pulse, and holds that to the next); where the value is read "
                "only once the latch has closed, a flip-flop on the clock edge that closes it holds the same value")
        unclocked = clock is None and not sampled
        why = f"its enable follows input{'s' * (len(ports) > 1)} {', '.join(ports)}" if ports \
            else "the design has no clock" if unclocked else _closes_when_forced(g, plain, cone, enable)
        if why:
            when = "at any moment (the design has no clock)" if unclocked and ports else "between clock edges"
            raise Mech2SpiceError(
                f"{what}: {why}, so it can close {when} and hold what it had at that moment, which no latch of the "
                "network does (each captures once a cycle, on the pulse); if the latch is not meant, assign every "
                "signal on every path of combinational always blocks")
        word = re.sub(r"\[\d+\]' \(", "' (", what)          # one warning per variable, not per bit
        if word not in warned:
            warned.add(word)
            _warn(f"{word}: its enable closes only at clock edges, so the network holds it in a latch of the clock "
                  "(what it held at the last edge): the source's meaning wherever it holds across edges, as a "
                  "case without a default in states never reached; `verify` checks it against Icarus")


def _closes_when_forced(g: nx.DiGraph, plain, cone: set, enable: str) -> str | None:
    """Why a latch's enable may close when an asynchronous reset or set forces registers it reads (None: it
    is open, whatever the registers not forced hold, for each forcing input and each set of them at once)."""
    regs = sorted(n for n in cone if g.nodes[n]["kind"] == "latch")
    force = {q: latch_inputs(g, q)[1] for q in regs}
    sources = sorted({f for f in force.values() if f is not None})
    ports = sorted({g.nodes[n]["port"] for f in sources for n in nx.ancestors(g, f) | {f}
                    if g.nodes[n]["kind"] == "input"})
    too_many = f"its enable reads registers that {', '.join(ports)} force between clock edges"
    if len(sources) > 3:
        return too_many
    for k in range(1, len(sources) + 1):
        for held in itertools.combinations(sources, k):
            free = [q for q in regs if force[q] not in held]
            if len(free) > 12:                  # every value of the free registers is tried: 4096 at most
                return too_many
            grid = np.array(list(itertools.product((False, True), repeat=len(free))), bool)
            grid = grid.reshape(2 ** len(free), len(free))
            values = {q: grid[:, i] for i, q in enumerate(free)}
            values.update({q: np.full(len(grid), bool(g.nodes[q].get("inverted", 0)))        # forced
                           for q in regs if q not in values})
            if not _evaluate(g, plain, cone, values, len(grid))[enable].all():
                return f"its enable closes when {', '.join(ports)} forces the registers it reads, between clock edges"
    return None


def _evaluate(g: nx.DiGraph, plain, cone: set, values: dict, width: int) -> dict:
    """The cone's NOR gates over `width` columns of register values (numpy bool arrays, one per latch)."""
    out = dict(values)
    for n in nx.topological_sort(plain.subgraph(cone)):
        kind = g.nodes[n]["kind"]
        if kind == "const":
            out[n] = np.full(width, n == "const1")
        elif kind == "nor":
            ins = [out[u] for u, _ in plain.in_edges(n)]
            out[n] = ~np.logical_or.reduce(ins) if ins else np.full(width, bool(g.nodes[n].get("fixed", 1)))
    return out


def _nor(g: nx.DiGraph, a: str, b: str) -> str:
    """A new NOR(a, b) gate; returns its name."""
    gate = _new_gate(g)
    g.add_node(gate, kind="nor")
    _connect_gate(g, gate, [a, b])
    return gate


def _not(g: nx.DiGraph, a: str) -> str:
    """NOR(a, 0), one per source node (an active-low reset is inverted once for all its latches)."""
    made = g.graph.setdefault("inverters", {})
    if a not in made:
        made[a] = _nor(g, a, _const(g, 0))
    return made[a]


def _edge_flops(module: dict) -> list[dict]:
    """The module's flip-flop cells (a clock pin), plain or with an asynchronous reset or set."""
    return [c for c in module["cells"].values() if c["type"] in _EDGE_FLOPS or _FORCED.match(c["type"])]


def _refuse_clock_reads(top: str, module: dict, clocks: tuple, path: Path) -> None:
    """Refuse a flip-flop (or latch) that takes a clock to be sampled as data (`derived_clocks.clock_read`)."""
    flops = _edge_flops(module)
    latches = [c for c in module["cells"].values() if "DLATCH" in c["type"].upper()]
    found = derived_clocks.clock_read(module, flops, latches, clocks)
    if found:
        cell, clock = found
        where = _where(cell, top, path)
        what = "latch" if cell in latches else "flip-flop"
        raise Mech2SpiceError(
            f"{where + ': ' if ', line ' in where else ''}module {top}: this {what} takes the clock '{clock}' as "
            f"data: at an edge a simulator gives it the clock's value after the edge (or either value where logic "
            "stands between, by the order of its events), the network, its clocks sampled, the value before; "
            "write the value the edge implies (1 after a rising edge of that clock), or read the clock through a "
            "register")


class _Sampled(Mech2SpiceError):
    """A design one pulse per cycle cannot clock as written, that sampling its clock ports can (`clocks`):
    several of them, both edges, or a clock also read as data.  `synthesize` synthesizes it again, sampled."""

    def __init__(self, message: str, clocks: tuple):
        super().__init__(message)
        self.clocks = clocks


def _clock_port(g: nx.DiGraph, top: str, module: dict, driver: dict, path: Path | None = None) -> str | None:
    """The single 1-bit input port clocking every flip-flop on one edge (None for combinational designs).
    Raises `_Sampled` where input ports clock them otherwise (several ports, both edges, a bit of a bus)."""
    flops = _edge_flops(module)
    if not flops:
        return None
    source = {id(c): driver.get(c["connections"]["C"][0]) for c in flops}
    by_port = {id(c) for c in flops if source[id(c)] is not None and g.nodes[source[id(c)]]["kind"] == "input"}
    derived = next((c for c in flops if id(c) not in by_port), None)
    found = derived and derived_clocks.ambiguity(module, flops, _net_names(module))
    if found:
        cell, why = found
        where = _where(cell, top, path)
        raise Mech2SpiceError(f"{where + ': ' if ', line ' in where else ''}module {top}: {why}")
    ports = [p for p in module["ports"] if p in {g.nodes[source[k]]["port"] for k in by_port}]
    if derived is not None and ports:   # one meaning (derived_clocks): sampled, edges found between samples
        raise _Sampled(f"module {top}: a clock computed in the circuit", tuple(ports))
    if derived is not None:
        where = _where(derived, top, path)
        raise Mech2SpiceError(
            f"{where + ': ' if ', line ' in where else ''}module {top}: this flip-flop is clocked by logic, not "
            "by an input port: a clock computed in the circuit changes in the same instant as the registers "
            "clocked with it, and a flip-flop on it reading them takes their new values on a simulator, their "
            "old ones wherever that clock lags: the source does not say which; clock it by an input port (a "
            "divided clock as an enable on the fast one)")
    nodes = set(source.values())
    ports = [p for p in module["ports"] if p in {g.nodes[n]["port"] for n in nodes}]
    (node, *_), port = sorted(nodes), ports[0]
    wide = g.nodes[node]["bit"] != 0 or sum(1 for n in g if g.nodes[n].get("port") == port) != 1
    if len(ports) > 1 or len({c["type"][6] for c in flops}) > 1 or wide:    # $_DFF_P... / $_DFF_N...
        raise _Sampled(f"module {top}: several clocks, both edges or a clock in a bus", tuple(ports))
    return port


_EDGE_FLOPS = ("$_DFF_P_", "$_DFF_N_")


def clock_edge(module: dict) -> str:
    """'negedge' when the flip-flops capture on the clock's falling edge (all of them: `_clock_port`), else
    'posedge'.  Either is the one pulse per cycle of the mechanical clock; only the testbench and the
    written-back network (verify) read it."""
    return "negedge" if any(c["type"].startswith("$_DFF_N") for c in module["cells"].values()) else "posedge"


def _ports(module: dict, direction: str):
    return [(p, info["bits"]) for p, info in module["ports"].items()
            if info["direction"] == direction]


def _refuse_inout(top: str, module: dict, path: Path | None) -> None:
    """A top-level inout port, with its line: it would be an input and an output on one wire."""
    bad = [p for p, info in module["ports"].items() if info["direction"] not in ("input", "output")]
    if not bad:
        return
    port = bad[0]
    raise Mech2SpiceError(f"{_port_where(module, port, path, top)}: inout port '{port}' of the top module {top}: a mechanical port is either "
                          "driven from outside (an input's drive) or read from a gate (an output's amplitude), "
                          f"never both on one wire; declare it as an input ({port}_in) and two outputs "
                          f"(the value {port}_out and its enable {port}_oe)")


def _port_where(module: dict, port: str, path: Path | None, top: str) -> str:
    """'FILE, line N' of a port's declaration (from its netname's src attribute), else what is known."""
    src = module.get("netnames", {}).get(port, {}).get("attributes", {}).get("src")
    line = path and refusals.src_line(src, path)
    return f"{path}, line {line}" if line else str(path or f"module {top}")


def _refuse_dollar_ports(top: str, module: dict) -> None:
    """A port whose Verilog name begins with `$` (`\\$a `): Yosys keeps such names apart as its own (`\\$a` in
    its JSON, where any other escaped name loses the backslash), so every tool downstream would name the port
    otherwise than the source does (--set, the testbench, the waveform)."""
    bad = next((p for p in module["ports"] if p.startswith("\\$")), None)
    if bad is not None:
        raise Mech2SpiceError(f"module {top}: port '{bad[1:]}' (written `{bad} `) begins with `$`, the prefix "
                              "Yosys keeps for its own names, so the tools that read the network would each "
                              "name it differently: rename the port")


def _add_inputs(g: nx.DiGraph, top: str, module: dict):
    """Input nodes; port widths in declaration order; net id -> driving node."""
    _refuse_dollar_ports(top, module)
    driver: dict[int, str] = {}
    for port, bits in _ports(module, "input"):
        for i, bit in enumerate(bits):
            g.add_node(f"{port}[{i}]", kind="input", port=port, bit=i)
            driver[bit] = f"{port}[{i}]"
    inputs = {p: len(b) for p, b in _ports(module, "input")}
    outputs = {p: len(b) for p, b in _ports(module, "output")}
    return inputs, outputs, driver


def _add_cells(g: nx.DiGraph, top: str, module: dict, driver: dict, path: Path | None) -> dict:
    """One node per cell (named g<N>); returns node -> (input bits, output net)."""
    cells = {}
    for cell in module["cells"].values():
        try:
            mapped = map_cell(cell["type"], top)
        except Mech2SpiceError as err:          # say where: the latch, async reset, ... came from
            line = path and refusals.src_line(cell.get("attributes", {}).get("src"), path)
            msg = _latch_named(str(err), cell, module)
            raise Mech2SpiceError(f"{path}, line {line}: {msg}" if line else msg) from None
        if cell["type"] == _PRINT:
            _warn(f"{_where(cell, top, path)}: a print ($display, $write, or $error/$warning/$info, which in an "
                  "always block only print) left out: it prints while a simulator runs and "
                  "no output depends on it, so the network computes the same without it")
        if mapped is None:
            continue
        kind, pins, out_pin = mapped
        node = f"{'q' if kind == 'latch' else 'g'}{len(cells)}"
        out_net = cell["connections"][out_pin][0]
        if out_net in driver:
            raise Mech2SpiceError(f"module {top}: net {out_net} has more than one driver")
        if kind == "dlatch":
            where = _where(cell, top, path)
            msg = _latch_named(f"module {top}: Yosys inferred a level-sensitive latch ({cell['type']})", cell, module)
            g.add_node(node, kind=kind, cell=(cell["type"], f"{where}: {msg}" if ", line " in where else msg))
        else:
            cell_of = {"cell": (cell["type"], _where(cell, top, path))} if kind == "latch" else {}
            g.add_node(node, kind=kind, **cell_of)
        driver[out_net] = node
        cells[node] = ([cell["connections"][p][0] if p else "0" for p in pins], out_net)
    return cells


def _latch_named(msg: str, cell: dict, module: dict) -> str:
    """An inferred latch's refusal with the variable it holds (`next[1]`): a block assigning several says
    which one a path leaves unassigned."""
    q = cell.get("connections", {}).get("Q")
    name = _net_names(module).get(q[0]) if isinstance(q, list) and q else None
    if "level-sensitive latch (" not in msg or not name or name.startswith("$"):
        return msg
    return msg.replace("level-sensitive latch (", f"level-sensitive latch on '{name}' (", 1)


def _warn(message: str) -> None:
    """One line on stderr: what synthesis left out of the network and why (the network is still the source's)."""
    print(f"mech2spice: warning: {message}", file=sys.stderr)


def _where(cell: dict, top: str, path: Path | None) -> str:
    """'FILE, line N' of a cell from its src attribute, else 'module TOP' (for a latch's messages)."""
    attrs = cell.get("attributes")
    src = attrs.get("src") if isinstance(attrs, dict) else None      # a cached module is anyone's data
    line = path and isinstance(src, str) and refusals.src_line(src, path)
    return f"{path}, line {line}" if line else f"module {top}"


def _net_names(module: dict) -> dict:
    """Net id -> readable name, public (user) names winning over Yosys's generated ones."""
    names = {}
    for name, info in sorted(module["netnames"].items(), key=lambda kv: -kv[1]["hide_name"]):
        for i, bit in enumerate(info["bits"]):
            names[bit] = name if len(info["bits"]) == 1 else f"{name}[{i}]"
    return names


def _source(g: nx.DiGraph, bit, driver: dict, top: str) -> str:
    """The node driving a JSON bit: a net id or one of the constants '0', '1', 'x', 'z'."""
    if bit == "z":
        raise Mech2SpiceError(f"module {top}: a net is tied to 'z' (released, with no enable that ever drives "
                              "it): a mechanical net always carries an amplitude; assign it a value")
    if bit == "1":
        return _const(g, 1)
    return driver.get(bit) or _const(g, 0)     # '0', 'x' and undriven nets read as 0


def _const(g: nx.DiGraph, value: int) -> str:
    name = f"const{value}"
    if name not in g:
        g.add_node(name, kind="const")
    return name


def _connect_gate(g: nx.DiGraph, node: str, sources: list[str]) -> None:
    """Wire a NOR; NOR(x, x) becomes NOR(x, 0), and NOR(0, 0) is marked fixed at 1."""
    a, b = sources
    if a == b:
        b = _const(g, 0)
    if a == b:                                  # both const0: a DiGraph cannot hold it
        g.nodes[node]["fixed"] = 1
        return
    g.add_edge(a, node, pin=0)
    g.add_edge(b, node, pin=1)


# --------------------------------------------------------------------------- hygiene

def _kind(g: nx.DiGraph, node) -> str:
    return g.nodes[node]["kind"]


def _fixed(g: nx.DiGraph, node) -> int | None:
    """A NOR's constant output if its inputs force one, else None."""
    if "fixed" in g.nodes[node]:
        return g.nodes[node]["fixed"]
    return 0 if g.has_edge("const1", node) else None


def propagate_constants(g: nx.DiGraph) -> None:
    """Replace NOR gates with a fixed output by const nodes: NOR(x,1)=0, NOR(0,0)=1."""
    todo = [n for n in g if _kind(g, n) == "nor" and _fixed(g, n) is not None]
    while todo:
        node = todo.pop()
        if node not in g or _fixed(g, node) is None:
            continue
        value = _fixed(g, node)
        sinks = [(s, attrs) for s, attrs in g[node].items() if s != node]
        g.remove_node(node)
        const = _const(g, value)
        for sink, attrs in sinks:
            if g.has_edge(const, sink):         # NOR(c, c): the sink is fixed at 1 - c
                g.remove_edges_from(list(g.in_edges(sink)))
                g.nodes[sink]["fixed"] = 1 - value
            else:
                g.add_edge(const, sink, **attrs)
            if _kind(g, sink) == "nor":
                todo.append(sink)


def remove_dead_gates(g: nx.DiGraph) -> None:
    """Drop gates and constants outside every output's fan-in cone (inputs always stay)."""
    live = set()
    stack = [n for n in g if _kind(g, n) == "output"]
    while stack:
        node = stack.pop()
        if node not in live:
            live.add(node)
            stack.extend(g.predecessors(node))
    g.remove_nodes_from([n for n in list(g) if _kind(g, n) in ("nor", "const", "latch") and n not in live])


def check_loops(g: nx.DiGraph, top: str = "") -> None:
    """Raise if the gates form a combinational loop (one not broken by a latch), naming gates and nets."""
    try:
        cycle = [u for u, _ in nx.find_cycle(combinational_view(g))]
    except nx.NetworkXNoCycle:
        return
    hops = [f"{n} (net {g.nodes[n]['net']})" if not g.nodes[n].get("net", "$").startswith("$")
            else n for n in cycle]
    raise Mech2SpiceError(f"combinational loop in module {top}: " + " -> ".join(hops)
                          + f" -> {cycle[0]}; break it with a register or remove the feedback")


def _new_gate(g: nx.DiGraph) -> str:
    n = g.graph.get("next_gate")
    if n is None:
        n = 1 + max((_gate_key(x)[0] for x in g if str(x).startswith("g")), default=-1)   # a cell still mapping too
    g.graph["next_gate"] = n + 1
    return f"g{n}"


def _buffer(g: nx.DiGraph, src: str) -> str:
    """Add NOR(NOR(src, 0), 0), a non-inverting copy of src; returns its output gate."""
    first, second = _new_gate(g), _new_gate(g)
    for gate, a in ((first, src), (second, first)):
        g.add_node(gate, kind="nor")
        g.add_edge(a, gate, pin=0)
        g.add_edge(_const(g, 0), gate, pin=1)
    return second


def buffer_feedthroughs(g: nx.DiGraph) -> None:
    """Outputs wired straight to an input port get a buffer (one shared per input bit)."""
    copies: dict[str, str] = {}
    for out in [n for n in g if _kind(g, n) == "output"]:
        (src,) = g.predecessors(out)
        if _kind(g, src) == "input":
            if src not in copies:
                copies[src] = _buffer(g, src)
            g.remove_edge(src, out)
            g.add_edge(copies[src], out)


def limit_fanout(g: nx.DiGraph, max_fanout: int | None) -> None:
    """Give every input/gate driving more than max_fanout sinks a tree of buffer pairs."""
    if max_fanout is None:
        return
    if max_fanout < 2:
        raise Mech2SpiceError(f"max_fanout must be at least 2 (got {max_fanout}): "
                              "a buffer pair cannot widen a fan-out of 1")
    for node in [n for n in g if _kind(g, n) in ("input", "nor", "latch")]:
        if g.out_degree(node) > max_fanout:
            sinks = list(g[node].items())
            g.remove_edges_from([(node, s) for s, _ in sinks])
            _fan_out(g, node, sinks, max_fanout)


def _fan_out(g: nx.DiGraph, src: str, sinks: list, k: int) -> None:
    """Drive sinks from src, at most k per driver: split into k groups, buffer the big ones."""
    if len(sinks) <= k:
        g.add_edges_from((src, s, attrs) for s, attrs in sinks)
        return
    for i in range(k):
        group = sinks[i * len(sinks) // k:(i + 1) * len(sinks) // k]
        if len(group) == 1:
            g.add_edge(src, group[0][0], **group[0][1])
        else:
            _fan_out(g, _buffer(g, src), group, k)


def _gate_key(name: str) -> tuple:
    m = re.fullmatch(r"[gq](\d+)", str(name))
    return (int(m.group(1)), "") if m else (-1, str(name))


def _renumbered(g: nx.DiGraph) -> nx.DiGraph:
    """Copy with gates named g0.. in Netlist.gates() order; nodes listed inputs, consts, gates, outputs."""
    order = Netlist("", g, {}, {}).gates()
    latches = Netlist("", g, {}, {}).latches()
    mapping = {old: f"g{i}" for i, old in enumerate(order)}
    mapping.update({old: f"q{i}" for i, old in enumerate(latches)})
    h = nx.DiGraph()
    for kind in ("input", "const", "latch", "nor", "output"):
        nodes = order if kind == "nor" else latches if kind == "latch" else [n for n in g if _kind(g, n) == kind]
        h.add_nodes_from((mapping.get(n, n), g.nodes[n]) for n in nodes)
    h.add_edges_from((mapping.get(u, u), mapping.get(v, v), d) for u, v, d in g.edges(data=True))
    return h
