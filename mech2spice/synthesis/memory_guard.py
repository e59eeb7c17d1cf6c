"""Memory writes guarded by their address range, so Yosys reads them as Verilog means them (docs/rtl.md,
"Memories: out-of-range addresses").

IEEE 1364 drops a write to a memory word that does not exist (an address outside the declared range, or one
with x or z bits) and reads x there.  Yosys decodes only the low address bits: a memory its front end turns
into registers (`mem2reg`, forced e.g. by an asynchronous reset of the words) truncates the address to the
bits the word count needs, so `RAM[49] <= d` on a 12-word RAM writes word 1; a memory kept as a `$mem` cell
is mapped (`memory_map`) the same way.  The network then changes a word the source leaves alone.

The fix is in the text every tool reads: each procedural write `M[a] <= d;` (or `=`) to a declared memory
becomes `begin if ((a) >= LO && (a) <= HI) M[a] <= d; end`, on the same line.  Under Verilog's own rules the
guard changes nothing (a write it blocks is one the simulator drops anyway, and an x address makes the `if`
false, which drops it too), so Icarus reads the same meaning; Yosys now builds the range check.  Writes in
`initial` blocks (power-up values, ROM contents) and writes at a literal index are left as written.  Reads
out of range stay x in the source: the network returns some word there, which the proof (`-ignore_gold_x`)
and the co-simulation (an x bit agrees with either value) accept as a refinement.
"""

from __future__ import annotations

import re

from .verilog_text import blanked as blank, statement_or_block_end

__all__ = ["guarded"]

# `reg [7:0] RAM [11:0], other [0:3];`: memories are names followed by one unpacked range.
_DECL = re.compile(r"\b(?:reg|logic)\b(?:\s+(?:signed|unsigned))?\s*(?:\[[^\]]*\]\s*)*(?P<names>[^;]*);")
_MEMORY = re.compile(r"(?P<name>[A-Za-z_]\w*)\s*\[(?P<a>[^\]:]+):(?P<b>[^\]]+)\]\s*(?=[,;=]|$)")
# What may stand just before a procedural statement.
_STATEMENT_START = re.compile(r"(?:[;:)]|\bbegin|\belse|\bend)\s*$")


def _memories(blanked: str) -> dict[str, tuple[str, str]]:
    """Memory name -> (first bound, second bound), as written, for one-dimensional memories."""
    found = {}
    for decl in _DECL.finditer(blanked):
        names = re.sub(r"=[^,]*", "", decl["names"])      # `reg [7:0] a = b[3:0], m [0:3];`: b is no memory
        for m in _MEMORY.finditer(names):
            found[m["name"]] = (m["a"].strip(), m["b"].strip())
    return found


def _matching(text: str, at: int, open_: str = "[", close: str = "]") -> int:
    """The index just past the bracket closing the one at `at`."""
    depth = 0
    for k in range(at, len(text)):
        if text[k] == open_:
            depth += 1
        elif text[k] == close:
            depth -= 1
            if depth == 0:
                return k + 1
    return -1


def _statement_end(text: str, at: int) -> int:
    """Just past the `;` ending the statement at `at` (outside brackets); -1 when none."""
    depth = 0
    for k in range(at, len(text)):
        c = text[k]
        if c in "([{":
            depth += 1
        elif c in ")]}":
            depth -= 1
        elif c == ";" and depth == 0:
            return k + 1
    return -1


def _initial_spans(blanked: str) -> list[tuple[int, int]]:
    """Where the `initial` blocks are (their writes are power-up values, not guarded)."""
    return [(m.start(), statement_or_block_end(blanked, m.end())) for m in re.finditer(r"\binitial\b", blanked)]


def _bounds(a: str, b: str) -> tuple[str, str]:
    """(lowest, highest) word index as Verilog expressions."""
    if re.fullmatch(r"\d+", a) and re.fullmatch(r"\d+", b):
        lo, hi = sorted((int(a), int(b)))
        return str(lo), str(hi)
    return f"(({a}) < ({b}) ? ({a}) : ({b}))", f"(({a}) < ({b}) ? ({b}) : ({a}))"


def _modules(blanked: str) -> list[tuple[int, int]]:
    """(start, end) of each module: a memory is a name in the module that declares it (another module's
    vector of the same name is no memory, public RTL pass 10)."""
    ends = [m.end() for m in re.finditer(r"\bendmodule\b", blanked)]
    spans = []
    for m in re.finditer(r"(?<![\w$`])(?:macro)?module\b", blanked):
        end = next((e for e in ends if e > m.start()), len(blanked))
        spans.append((m.start(), end))
    return spans or [(0, len(blanked))]


def guarded(text: str) -> str:
    """`text` with every procedural memory write guarded by its address range (module docstring); the
    text itself when it writes no memory at a non-literal index.  Lines are kept."""
    blanked = blank(text)
    edits, initial = [], _initial_spans(blanked)
    for start, end in _modules(blanked):
        edits += _guards(blanked, start, end, initial)
    for at, new in sorted(edits, reverse=True):
        text = text[:at] + new + text[at:]
    return text


def _guards(blanked: str, start: int, end: int, initial: list[tuple[int, int]]) -> list[tuple[int, str]]:
    """The insertions that guard the memory writes of the module at blanked[start:end] (`initial`: the
    file's `initial` blocks, whose writes stay as written)."""
    memories = _memories(blanked[start:end])
    if not memories:
        return []
    names = "|".join(re.escape(n) for n in sorted(memories, key=len, reverse=True))
    edits = []
    for m in re.compile(rf"(?<![\w$.])(?P<name>{names})\s*\[").finditer(blanked, start, end):
        if any(s <= m.start() < e for s, e in initial) or not _STATEMENT_START.search(blanked[max(0, m.start() - 80):m.start()]):
            continue
        close = _matching(blanked, m.end() - 1)
        if close < 0:
            continue
        index = blanked[m.end():close - 1].strip()
        rest = re.match(r"(?:\s*\[[^\]]*\])*\s*(<=|=)(?!=)", blanked[close:])
        if rest is None or re.fullmatch(r"\d+", index) or (":" in index and "?" not in index):
            continue                                   # a literal word, or a range: a vector's, not a word's
        stop = _statement_end(blanked, close + rest.end())
        if stop < 0:
            continue
        lo, hi = _bounds(*memories[m["name"]])
        guard = f"({index}) >= {lo} && ({index}) <= {hi}"
        edits += [(m.start(), f"begin if ({guard}) "), (stop, " end")]
    return edits
