"""The VIS Verilog dialect, read as standard SystemVerilog (docs/rtl.md, "The VIS dialect").

VIS (the Verification Interacting with Synthesis system, whose `vl2mv` front end reads its own Verilog) lets an
enumerated type declare a register: ``typedef enum {A, B, C} State;`` then ``State reg stato;``.  Neither
IEEE 1364 nor IEEE 1800 has that form (a SystemVerilog variable of an enum type is ``State stato;``), so Yosys
and Icarus stop at it with a syntax error.  F. Somenzi's translations of the ITC'99 benchmarks use it.

The rule (no option to give): a file is read in the VIS dialect when a declaration names one of its own
``typedef enum`` types followed by ``reg``.  That form is a syntax error in standard Verilog, so no standard
file is ever rewritten.  In such a file, and only there:

* ``State reg stato;`` becomes ``State     stato;`` (``reg`` blanked, columns kept);
* an enum so used that has no base type, ``typedef enum {A, B, C}``, gets ``logic [W-1:0]`` with W the bits
  for its values: VIS encodes an enumerated variable in that many bits, and it is x until given a value.
  SystemVerilog's own default, ``int``, is 2-state and starts at 0, which would hide an uninitialised state
  register from the co-simulation.

Every line keeps its number, so Yosys's and Icarus's messages point into the file as written.  Synthesis,
the proof and Icarus all read the text `standard_text` returns (`standard_source` gives it a path), which
also guards memory writes by their address range in every file (memory_guard.py).

``$ND(a, b, ...)``, VIS's nondeterministic choice (each evaluation may yield any of the listed values), is
refused in any file: a NOR network computes one function of its inputs and has no source of choice; the
environment's choice is an input port.
"""

from __future__ import annotations

import contextlib
import re
import tempfile
from pathlib import Path
from typing import Iterator

from ..errors import Mech2SpiceError
from ..inputs import read_input
from . import memory_guard
from .verilog_text import (blanked as blank, closing_paren, comments_blanked, link_readmem_files, processes,
                           statement_or_block_end)

__all__ = ["standard_text", "standard_source", "is_vis", "mirror_siblings"]

_ENUM = re.compile(r"\btypedef\s+enum\s*(?P<base>[^{;]*?)\s*\{(?P<values>[^{}]*)\}\s*(?P<name>[A-Za-z_]\w*)\s*;")
_ND = re.compile(r"\$ND\s*\(")


def _line(text: str, at: int) -> int:
    return text.count("\n", 0, at) + 1


def _enum_register(names) -> re.Pattern:
    """`<enum type> reg`: the VIS declaration (the type at a statement's start: after `;`, a block or BOL)."""
    alts = "|".join(re.escape(n) for n in sorted(names, key=len, reverse=True))
    return re.compile(rf"(?:(?<=[;\n])|^)(?P<lead>\s*)(?P<type>{alts})(?P<gap>\s+)(?P<reg>reg)\b", re.M)


def _enums(blanked: str) -> dict[str, re.Match]:
    return {m["name"]: m for m in _ENUM.finditer(blanked)}


def is_vis(text: str) -> bool:
    """Whether the text uses the VIS enum-register declaration (the dialect's detection rule)."""
    blanked = blank(text)
    enums = _enums(blanked)
    return bool(enums) and _enum_register(enums).search(blanked) is not None


def _width(values: str) -> int | None:
    """Bits for an enum's plain value list (None when it gives values or ranges: left as written)."""
    items = [v.strip() for v in values.split(",") if v.strip()]
    if not items or not all(re.fullmatch(r"[A-Za-z_]\w*", v) for v in items):
        return None
    return max(1, (len(items) - 1).bit_length())


def standard_text(path, text: str) -> str:
    """The text every tool reads (synthesis, the proof, Icarus), line numbers kept: the VIS dialect as
    SystemVerilog (module docstring), then memory writes guarded by their address range
    (memory_guard.py: a no-op under Verilog's rules that Yosys needs); refuses `$ND` naming the file and line."""
    return memory_guard.guarded(_split_reset_ors(_prints_emptied(_severity_as_print(_vis_as_standard(path, text)))))


_PRINT = re.compile(r"\$(?:display|write)\s*\(")


def _prints_emptied(text: str) -> str:
    """Every `$display(...)`/`$write(...)` as `$display`/`$write` without arguments, lines kept.  A print
    computes nothing the design's outputs read, and synthesis leaves it out with a warning (its line kept by
    the call); but Yosys reads its arguments first, refusing most formats (`%f`, `%e`, `%g`, `%t` of a
    non-time, a precision `%.0f`) and rounding a real argument, which was refused as a real in logic
    (public RTL pass 10: `initial $display("period = %.0f ns", 1e9 / CLK_FREQ)`)."""
    blanked = blank(text)
    for m in reversed(list(_PRINT.finditer(blanked))):
        close = closing_paren(blanked, m.end() - 1)
        if close < len(text):
            text = text[:m.end() - 1] + "\n" * blanked.count("\n", m.end() - 1, close) + text[close + 1:]
    return text


_SEVERITY = re.compile(r"\$(?:error|warning|info)\b")


def _severity_as_print(text: str) -> str:
    """`$error`, `$warning` and `$info` inside an `always` block as `$display`, lines kept: in a running
    simulation each only prints (IEEE 1800 20.10; Icarus prints and carries on), which Yosys cannot read
    there ("Can't resolve task name") and reads as a print, which synthesis leaves out with a warning.  In an
    `initial` block they stay elaboration checks, for Yosys to decide (synth._ELABORATION_TASKS)."""
    blanked = blank(text)
    spans = [(a, b) for kind, a, b in processes(blanked) if kind.startswith("always")]
    hits = [m for m in _SEVERITY.finditer(blanked) if any(a <= m.start() < b for a, b in spans)]
    for m in reversed(hits):
        text = text[:m.start()] + "$display" + text[m.end():]
    return text


def _vis_as_standard(path, text: str) -> str:
    """`text` unchanged unless it is in the VIS dialect; `$ND` refused."""
    blanked = blank(text)
    nd = _ND.search(blanked)
    if nd:
        raise Mech2SpiceError(
            f"{path}, line {_line(blanked, nd.start())}: $ND (VIS's nondeterministic choice): each evaluation may "
            "take any of the listed values, and a NOR network computes one function of its inputs, with no "
            "source of choice; make the choice an input port of the design (the environment then picks it)")
    enums = _enums(blanked)
    if not enums:
        return text
    declared = list(_enum_register(enums).finditer(blanked))
    if not declared:
        return text
    edits = [(m.start("reg"), m.end("reg"), "   ") for m in declared]
    for name in {m["type"] for m in declared}:
        e = enums[name]
        width = _width(e["values"])
        if not e["base"] and width is not None:
            brace = blanked.index("{", e.start())
            edits.append((brace, brace, f"logic [{width - 1}:0] "))
    for start, end, new in sorted(edits, reverse=True):
        text = text[:start] + new + text[end:]
    return text


def mirror_siblings(path: Path, folder: Path, text: str) -> None:
    """Links in `folder` to the other files beside `path`, when `text` includes files: an `include resolves
    beside the rewritten copy as it did beside the original (Yosys and Icarus look in the file's folder)."""
    link_readmem_files(text, Path(path).resolve().parent, folder)
    if "`include" not in text:
        return
    for entry in Path(path).resolve().parent.iterdir():
        if entry.name != Path(path).name and not (folder / entry.name).exists():   # a $readmem file: copied
            (folder / entry.name).symlink_to(entry)


@contextlib.contextmanager
def standard_source(path) -> Iterator[Path]:
    """A path holding the source as the tools must read it: `path` itself for standard Verilog; for the VIS
    dialect, the rewritten text in a scratch folder under the same file name (removed afterwards).  Messages
    from a tool that read it name the scratch path: replace ``str(that path)`` with ``str(path)``."""
    path = Path(path)
    text = read_input(path, "Verilog file").decode("utf-8", errors="replace")
    standard = standard_text(path, text)
    if standard == text:
        yield path
        return
    with tempfile.TemporaryDirectory(prefix="mech2spice_dialect_") as tmp:
        mirror_siblings(path, Path(tmp), standard)
        out = Path(tmp) / path.name
        out.write_text(standard, encoding="utf-8")
        yield out


_EDGE_BLOCK = re.compile(r"\balways(?:_ff)?\s*@\s*\(")
_EDGE = re.compile(r"\b(posedge|negedge)\s+([A-Za-z_][\w$]*)")
_FIRST_IF = re.compile(r"\s*(?:begin\b(?:\s*:\s*[A-Za-z_][\w$]*)?\s*)?if\s*\(")


def _or_terms(cond: str) -> list[tuple[int, int]]:
    """(start, end) of each top-level `||` operand of `cond`."""
    terms, depth, start, k = [], 0, 0, 0
    while k < len(cond):
        c = cond[k]
        depth += {"(": 1, ")": -1, "[": 1, "]": -1, "{": 1, "}": -1}.get(c, 0)
        if depth == 0 and cond.startswith("||", k):
            terms.append((start, k))
            start, k = k + 2, k + 2
            continue
        k += 1
    return terms + [(start, len(cond))]


def _edge_test(term: str, edges: dict[str, str]) -> str | None:
    """The listed signal `term` tests as an asynchronous reset (`x` for posedge x, `!x`/`~x` for negedge)."""
    t = term.strip()
    while t.startswith("(") and closing_paren(t, 0) == len(t) - 1:
        t = t[1:-1].strip()
    m = re.fullmatch(r"([!~]?)\s*([A-Za-z_][\w$]*)", t)
    if m and edges.get(m[2]) == ("negedge" if m[1] else "posedge"):
        return m[2]
    return None


_BLOCK_LABEL = re.compile(r"\b(begin|end)(\s*:\s*)([A-Za-z_][\w$]*)")


def _relabelled(branch: str, k: int, text: str) -> str:
    """The k-th copy of a branch with its named blocks renamed (`begin : rb` -> `begin : rb__copy2`): two blocks
    of one name in one scope are an error (Icarus: "'rb' has already been declared")."""
    def rename(m):
        name = f"{m[3]}__copy{k}"
        while re.search(rf"(?<![\w$]){re.escape(name)}(?![\w$])", text):
            name += "_"
        return f"{m[1]}{m[2]}{name}"
    return _BLOCK_LABEL.sub(rename, branch)


def _split_reset_ors(text: str) -> str:
    """An edge block whose first `if` ORs its asynchronous resets (`if (reset || clear)` under `posedge reset
    or posedge clear`, or `if (sync_clear || reset)`) as one `if` per reset, then the rest, each taking the
    same branch: the same logic (an OR without side effects), in the form Yosys reads (it stops at the OR:
    "Multiple edge sensitive events found for this signal").  Lines kept: the copies of the branch go on its
    last line, their comments blanked and newlines joined."""
    blanked = blank(text)
    bare = comments_blanked(text)              # a comment joined onto one line would end it there
    edits = []
    for m in _EDGE_BLOCK.finditer(blanked):
        close = closing_paren(blanked, m.end() - 1)
        edges = {name: kind for kind, name in _EDGE.findall(blanked[m.end():close])}
        first = _FIRST_IF.match(blanked, close + 1)
        if len(edges) < 2 or not first:
            continue
        c0 = first.end()
        c1 = closing_paren(blanked, c0 - 1)
        spans = _or_terms(blanked[c0:c1])
        resets = [k for k, (a, b) in enumerate(spans) if _edge_test(blanked[c0 + a:c0 + b], edges)]
        if len(spans) < 2 or not resets:
            continue
        order = resets + [k for k in range(len(spans)) if k not in resets]
        conds = [bare[c0 + spans[k][0]:c0 + spans[k][1]].strip() for k in order]
        rest = [c for k, c in zip(order, conds) if k not in resets]
        conds = conds[:len(resets)] + ([" || ".join(rest)] if rest else [])
        b0, b1 = c1 + 1, statement_or_block_end(blanked, c1 + 1)
        label = re.match(r"\s*:\s*[A-Za-z_][\w$]*", blanked[b1:]) if blanked[:b1].endswith("end") else None
        b1 += label.end() if label else 0          # SystemVerilog's `end : rb` belongs to the branch
        branch = bare[b0:b1].replace("\n", " ").strip()
        flat = [" ".join(c.split()) for c in conds]
        edits.append((c0, c1, flat[0] + "\n" * blanked[c0:c1].count("\n")))
        edits.append((b1, b1, "".join(f" else if ({c}) {_relabelled(branch, k, text)}"
                                      for k, c in enumerate(flat[1:], 2))))
    for a, b, new in sorted(edits, reverse=True):
        text = text[:a] + new + text[b:]
    return text
