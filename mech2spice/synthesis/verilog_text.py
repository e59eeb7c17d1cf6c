"""Small readers of Verilog source text shared by the front end's passes (synth's checks, the memory guard),
kept apart so those passes do not import each other."""
from __future__ import annotations

import re

_COMMENT_OR_STRING = re.compile(r'//[^\n]*|/\*.*?\*/|"(?:\\.|[^"\\\n])*"', re.S)


def blanked(text: str) -> str:
    """The text with comments and strings blanked (every character but newlines), so keywords in them do
    not count; offsets and lines kept."""
    return _COMMENT_OR_STRING.sub(lambda m: re.sub(r"[^\n]", " ", m.group()), text)


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
