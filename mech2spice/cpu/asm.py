"""Assembler for the 8-bit processor.

Syntax, one statement per line (``;`` starts a comment, mnemonics are case-insensitive):

    loop:   LDNX_AB 130      ; an instruction; LDNX_AB may carry its data byte as an operand
            JMP_C
    count:  .byte 0, loop+1  ; bytes: numbers, labels, .equ names, sums/differences of them
            .equ MMR 255     ; a named constant (no byte emitted)
            .org 128         ; continue at an address (forward only; the gap is zeros)
            .tape 255 21 110102  ; a Turing-machine tape at address 255: head cell, cell digits
            .result primes zeros 130 30 2  ; what the program computes, printed by `cpu run`: the numbers
                                           ; 2 + i (i < 30) whose cell 130 + i is 0 (or `bytes ADDR N`)

Numbers: decimal, 0x.. hex, 0b.. binary.  Every value must fit a byte (0..255).  Errors are one
line naming the source line.  ``assemble`` returns (image, listing, symbols); the image runs from
address 0 to the last byte emitted.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from ..errors import Mech2SpiceError
from .isa import MEM_SIZE, OPCODES, opcode

_LABEL = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*)\s*:\s*(.*)$")
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_TERM = re.compile(r"\s*([+-]?)\s*([^+\-\s]+)\s*")


@dataclass
class TapeSpec:
    """An external tape mapped at ``addr`` (see tm.Tape): cell i holds digit i; the head at ``head``."""
    addr: int
    head: int
    cells: str


@dataclass
class Program:
    """An assembled program: memory image, listing, symbols, optional tape, and per-statement rows."""
    image: bytes
    listing: str
    symbols: dict[str, int]
    tape: TapeSpec | None = None
    lines: list = field(default_factory=list)   # (address, bytes, source) per statement
    results: list = field(default_factory=list)  # ResultSpec per .result: what the program computes, where

    def read_results(self, memory: list[int]) -> dict[str, list[int]]:
        """{label: values} of every .result, read from a final memory image."""
        return {r.label: r.read(memory) for r in self.results}


@dataclass(frozen=True)
class ResultSpec:
    """`.result LABEL zeros ADDR COUNT [BASE]`: the numbers BASE + i (i < COUNT) whose cell ADDR + i holds 0
    (a sieve's unmarked numbers); `.result LABEL bytes ADDR COUNT`: the COUNT bytes from ADDR."""
    label: str
    kind: str          # "zeros" or "bytes"
    addr: int
    count: int
    base: int = 0

    def read(self, memory: list[int]) -> list[int]:
        cells = [memory[(self.addr + i) % MEM_SIZE] for i in range(self.count)]
        if self.kind == "bytes":
            return cells
        return [self.base + i for i, v in enumerate(cells) if v == 0]


def assemble(text: str) -> tuple[bytes, str, dict[str, int]]:
    """Assemble source text into (memory image, listing, symbols)."""
    p = assemble_program(text)
    return p.image, p.listing, p.symbols


def check_not_empty(program: Program) -> Program:
    """A program file that assembles to no bytes (empty, or only comments) ran an all-zero memory and was
    reported "did not halt"; `cpu asm` wrote a 0-byte image: refused instead."""
    if not program.image:
        raise Mech2SpiceError("no instruction and no data: the program assembles to no bytes, nothing to run")
    return program


def assemble_program(text: str) -> Program:
    """Assemble source text into a Program (image, listing, symbols, tape, rows)."""
    statements = _parse(text)
    symbols = _layout(statements)
    image = [0] * MEM_SIZE
    rows, end = [], 0
    for st in statements:
        data = [_value(v, symbols, st.lineno) for v in st.values]
        if st.op is not None:
            data = [OPCODES[st.op]] + data
        image[st.addr:st.addr + len(data)] = data
        end = max(end, st.addr + len(data))
        rows.append((st.addr, data, st.source))
    tape = _tape(statements, symbols, rows)
    results = [_result(st, symbols) for st in statements if st.result is not None]
    listing = "\n".join(f"{addr:3d}  {' '.join(f'{b:02X}' for b in data):<6} {src}" if data
                         else f"{'':11}{src}" for addr, data, src in rows)
    return Program(bytes(image[:end]), listing, symbols, tape, rows, results)


def _result(st, symbols: dict[str, int]) -> ResultSpec:
    label, kind, *nums = st.result
    values = [_value(v, symbols, st.lineno) for v in nums]
    if kind == "bytes" and len(values) == 3:
        raise _err(st.lineno, ".result LABEL bytes ADDR COUNT takes no BASE")
    return ResultSpec(label, kind, *values)


def _tape(statements: list, symbols: dict[str, int], rows: list) -> TapeSpec | None:
    """The one .tape, at an address no statement emits a byte to: the device answers every read there,
    so code or data under it would be replaced by tape symbols (a program that then never halts)."""
    tapes = [st for st in statements if st.tape is not None]
    if len(tapes) > 1:
        raise _err(tapes[1].lineno, f"a second .tape (the first is on line {tapes[0].lineno}): "
                                    "the processor has one tape")
    if not tapes:
        return None
    st = tapes[0]
    addr, head, cells = st.tape
    spec = TapeSpec(_value(addr, symbols, st.lineno), _value(head, symbols, st.lineno), cells)
    for (start, data, _), other in zip(rows, statements):
        if start <= spec.addr < start + len(data):
            raise _err(st.lineno, f".tape at address {spec.addr} lies over the program (line {other.lineno} "
                                  f"puts a byte there), which would read tape symbols instead: map the tape "
                                  f"at an address the program does not use")
    return spec


@dataclass
class _Statement:
    lineno: int
    source: str
    label: str | None = None
    op: str | None = None            # mnemonic, or None for data/directives
    values: list = field(default_factory=list)   # operand expressions (bytes emitted)
    equ: tuple | None = None
    result: tuple | None = None      # .result LABEL KIND ADDR COUNT [BASE], unevaluated
    org: str | None = None
    tape: tuple | None = None
    addr: int = 0


def _err(lineno: int, msg: str) -> Mech2SpiceError:
    return Mech2SpiceError(f"line {lineno}: {msg}")


def _shown(text: str) -> str:
    """A piece of the user's source in a message: at most 40 characters (a 5000-digit number made a 5 KB line)."""
    return text if len(text) <= 40 else text[:40] + "…"


def _parse(text: str) -> list[_Statement]:
    text = text.removeprefix("\ufeff")      # an editor's byte-order mark: invisible, it read as part of a mnemonic
    out = []
    for lineno, raw in enumerate(text.splitlines(), 1):
        code = raw.split(";", 1)[0].strip()
        st = _Statement(lineno, raw.rstrip())
        m = _LABEL.match(code)
        if m:
            st.label, code = m.group(1), m.group(2).strip()
        if code:
            _parse_body(st, code)
        out.append(st)
    return out


def _parse_body(st: _Statement, code: str) -> None:
    word, rest = (code.split(None, 1) + [""])[:2]
    rest = rest.strip()
    if word.startswith("."):
        _parse_directive(st, word.lower(), rest)
        return
    if word.upper() not in OPCODES:
        raise _err(st.lineno, f"unknown mnemonic '{word}'")
    st.op = word.upper()
    if rest:
        if st.op != "LDNX_AB":
            raise _err(st.lineno, f"{st.op} takes no operand (only LDNX_AB carries a data byte)")
        st.values = [rest]


def _parse_directive(st: _Statement, word: str, rest: str) -> None:
    if word == ".byte":
        st.values = [v.strip() for v in rest.split(",")]
        if not rest or any(not v for v in st.values):
            raise _err(st.lineno, ".byte needs one or more comma-separated values")
    elif word == ".equ":
        parts = rest.split(None, 1)
        if len(parts) != 2 or not _NAME.match(parts[0]):
            raise _err(st.lineno, ".equ needs a name and a value")
        st.equ = (parts[0], parts[1])
    elif word == ".org":
        if not rest:
            raise _err(st.lineno, ".org needs an address")
        st.org = rest
    elif word == ".result":
        parts = rest.split()
        if not (4 <= len(parts) <= 5 and _NAME.match(parts[0]) and parts[1] in ("zeros", "bytes")):
            raise _err(st.lineno, ".result needs LABEL zeros|bytes ADDR COUNT [BASE]")
        st.result = tuple(parts)
    elif word == ".tape":
        parts = rest.split()
        if len(parts) != 3 or not re.fullmatch(r"[0-7]+", parts[2]):
            raise _err(st.lineno, ".tape needs an address, a head cell and the cells as digits 0-7")
        st.tape = tuple(parts)
    else:
        raise _err(st.lineno, f"unknown directive '{word}'")


def _layout(statements: list[_Statement]) -> dict[str, int]:
    """Assign addresses; return labels and .equ names (equ values may use earlier names only)."""
    symbols: dict[str, int] = {}
    addr = 0
    for st in statements:
        if st.org is not None:
            new = _value(st.org, symbols, st.lineno, limit=MEM_SIZE)
            if new < addr:
                raise _err(st.lineno, f".org {new} would move backwards (already at {addr})")
            addr = new
        for name in (st.label, st.equ[0] if st.equ else None):
            if name and name in symbols:
                raise _err(st.lineno, f"'{name}' is defined twice")
        if st.label:
            symbols[st.label] = addr
        if st.equ:
            symbols[st.equ[0]] = _value(st.equ[1], symbols, st.lineno)
        st.addr = addr
        addr += (st.op is not None) + len(st.values)
        if addr > MEM_SIZE:
            raise _err(st.lineno, f"program too long: it needs {addr} bytes, memory has {MEM_SIZE}")
    # Labels may be used before they are defined: check every operand now that all are known.
    for st in statements:
        for v in st.values:
            _value(v, symbols, st.lineno)
    return symbols


def _value(expr: str, symbols: dict[str, int], lineno: int, limit: int = 256) -> int:
    """Evaluate NUMBER | NAME, joined by + and -; the result must be in 0..limit-1."""
    total, pos = 0, 0
    expr = expr.strip()
    while pos < len(expr):
        m = _TERM.match(expr, pos)
        if not m or (pos > 0 and not m.group(1)):
            raise _err(lineno, f"cannot read the value '{_shown(expr)}'")
        sign = -1 if m.group(1) == "-" else 1
        total += sign * _term(m.group(2), symbols, lineno)
        pos = m.end()
    if not expr:
        raise _err(lineno, "missing value")
    if not 0 <= total < limit:
        raise _err(lineno, f"value {_shown(expr)} = {_shown(str(total))} is out of range (0..{limit - 1})")
    return total


def _term(tok: str, symbols: dict[str, int], lineno: int) -> int:
    try:
        if re.fullmatch(r"0[xX][0-9a-fA-F]+", tok):
            return int(tok, 16)
        if re.fullmatch(r"0[bB][01]+", tok):
            return int(tok, 2)
        if re.fullmatch(r"[0-9]+", tok):
            return int(tok, 10)
    except ValueError:                  # beyond Python's 4300 digits: a number, far out of range
        raise _err(lineno, f"the number '{_shown(tok)}' ({len(tok):,} digits) is out of range") from None
    if _NAME.match(tok):
        if tok in symbols:
            return symbols[tok]
        if tok.upper() in OPCODES:      # an opcode's value, e.g. to build code as data
            return opcode(tok)
        raise _err(lineno, f"undefined label '{tok}'")
    raise _err(lineno, f"cannot read the number '{_shown(tok)}'")
