"""Races between clocked always blocks: a value passed from one block to another through a blocking `=` on
the same clock edge (docs/rtl.md, "Races between clocked blocks").

IEEE 1364 (section 11) lets a simulator run the always blocks woken by one edge in any order.  When block A
writes `x = ...` and block B, woken by the same edge, reads `x`, B sees the old value or the new one by that
order; synthesis (Yosys) reads every clocked block as flip-flops, so B always sees the old one.  The source
then has no single meaning: the network is proved equal to Yosys's reading, and Icarus may still differ.

Read from Yosys's own parse (`read_verilog -dump_ast1`, the ast.txt the flow writes), module by module:

* two edge-triggered blocks are woken by the same edge when their event lists share an edge of one signal
  (`posedge clk` in both; an added `or posedge rst` does not matter).  Different signals or edges are not
  paired: the source orders those events in time, and a race between two edges of one time step (clocks
  derived from each other) is not looked for;
* a read counts only where it is *exposed*: it may see a value from before the block ran (no whole-variable
  `=` to it earlier on every path through the block).  A blocking temporary, or a loop counter set by its
  own `for`, that each block writes before it reads, is no race;
* a write is a blocking `=` whose target is a variable of the module (not one declared in the block);
  non-blocking `<=` writes are what Verilog means for registers and never race here.

A variable written by two blocks on one edge is refused before this (refusals.check_drivers: two drivers).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from .refusals import _Ast, _nodes, read_ast, src_line

__all__ = ["Race", "find", "warning"]

_EDGES = ("AST_POSEDGE", "AST_NEGEDGE")


@dataclass(frozen=True)
class Race:
    """`variable` written with `=` at `write_line` and read at `read_line`, in two blocks of one edge."""

    module: str
    variable: str
    edge: str            # e.g. "posedge clock"
    write_line: int | None
    read_line: int | None

    def as_dict(self) -> dict:
        return {"module": self.module, "variable": self.variable, "edge": self.edge,
                "write_line": self.write_line, "read_line": self.read_line}


def warning(race: Race, path) -> str:
    """The one-line message (without the 'mech2spice: warning: ' prefix)."""
    where = f"{path}, line {race.write_line}" if race.write_line else str(path)
    read = f"line {race.read_line}" if race.read_line else "another block"
    return (f"{where}: '{race.variable}' is written with a blocking '=' in one clocked block and read at {read} "
            f"by another on the same edge ({race.edge}): Verilog leaves their order to the simulator (IEEE 1364 "
            "section 11), so the source's meaning depends on it; synthesis reads flip-flops (the old value); "
            "write '<=' to mean that")


@dataclass
class _Block:
    edges: set
    blocking: dict = field(default_factory=dict)   # variable -> src of its first blocking write
    exposed: dict = field(default_factory=dict)    # variable -> src of its first exposed read
    local: set = field(default_factory=set)        # declared inside the block


def find(ast_text: str, path: Path) -> list[Race]:
    """Every race in the modules of a `-dump_ast1` log (module docstring), in source order."""
    races = []
    for module in read_ast(ast_text):
        blocks = [_block(n) for n in _nodes(module, ("AST_FUNCTION", "AST_TASK")) if n.kind == "AST_ALWAYS"]
        blocks = [b for b in blocks if b is not None]
        for a in blocks:
            for b in blocks:
                if a is b or not (a.edges & b.edges):
                    continue
                edge = " or ".join(sorted(f"{k} {s}" for k, s in a.edges & b.edges))
                for var in sorted((set(a.blocking) & set(b.exposed)) - a.local - b.local):
                    races.append(Race(module.name, var, edge, src_line(a.blocking[var], path),
                                      src_line(b.exposed[var], path)))
    return sorted(races, key=lambda r: (r.write_line or 0, r.read_line or 0, r.variable))


def _block(always: _Ast) -> _Block | None:
    """An edge-triggered always block's edges, blocking writes and exposed reads; None for other blocks."""
    edges = {("posedge" if c.kind == "AST_POSEDGE" else "negedge", c.children[0].name)
             for c in always.children if c.kind in _EDGES and c.children and c.children[0].name}
    if not edges:
        return None
    block = _Block(edges)
    for child in always.children:
        if child.kind not in _EDGES + ("AST_EDGE", "ATTR"):
            _walk(child, frozenset(), block)
    return block


def _walk(node: _Ast, defined: frozenset, block: _Block) -> frozenset:
    """Record `node`'s reads not covered by `defined` (variables already written with `=` on every path) and
    its blocking writes; return what is defined after it."""
    kind = node.kind
    if kind in ("AST_ASSIGN_EQ", "AST_ASSIGN_LE"):
        for rhs in node.children[1:]:
            _walk(rhs, defined, block)
        whole = _lvalue(node.children[0], defined, block)
        if kind == "AST_ASSIGN_EQ":
            for name, is_whole in whole:
                block.blocking.setdefault(name, node.src)
            return defined | {name for name, is_whole in whole if is_whole}
        return defined
    if kind == "AST_IDENTIFIER":
        if node.name not in defined:
            block.exposed.setdefault(node.name, node.src)
        for child in node.children:          # indices
            _walk(child, defined, block)
        return defined
    if kind in ("AST_WIRE", "AST_MEMORY"):
        block.local.add(node.name)
        return defined
    if kind in ("AST_FUNCTION", "AST_TASK", "ATTR"):
        return defined
    if kind == "AST_CASE":
        return _case(node, defined, block)
    if kind == "AST_FOR":
        after_init = _walk(node.children[0], defined, block) if node.children else defined
        for child in node.children[1:]:
            _walk(child, after_init, block)
        return after_init                     # the body may run no time
    if kind in ("AST_WHILE", "AST_REPEAT"):
        for child in node.children:
            _walk(child, defined, block)
        return defined
    for child in node.children:               # a block in order; an expression's operands
        defined = _walk(child, defined, block)
    return defined


def _case(node: _Ast, defined: frozenset, block: _Block) -> frozenset:
    """`case` and `if` (Yosys parses `if` as a case): defined after it is what every branch defines, when a
    default branch exists."""
    outs, has_default = [], False
    for child in node.children:
        if child.kind not in ("AST_COND", "AST_CONDX", "AST_CONDZ"):
            _walk(child, defined, block)      # the selector
            continue
        body = child.children[-1] if child.children else None
        for label in child.children[:-1]:
            has_default |= label.kind == "AST_DEFAULT"
            _walk(label, defined, block)
        outs.append(_walk(body, defined, block) if body is not None else defined)
    if has_default and outs:
        return defined | frozenset.intersection(*outs)
    return defined


def _lvalue(node: _Ast, defined: frozenset, block: _Block) -> list[tuple[str, bool]]:
    """(variable, whether the whole of it is written) for each target; its indices are reads."""
    if node.kind == "AST_IDENTIFIER":
        for child in node.children:
            _walk(child, defined, block)
        return [(node.name, not node.children)]
    found = []
    for child in node.children:
        found += _lvalue(child, defined, block)
    return found
