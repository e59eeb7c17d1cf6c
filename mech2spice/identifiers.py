"""One writer of user names (ports, modules, registers, probes, titles) into the text mech2spice generates.

A design file names its modules and ports; those names end up in Verilog written back (verify's gate.v),
Icarus testbenches, Yosys scripts, ngspice and VACASK netlists and ngspice `.control` blocks.  Pasted
verbatim, a name can close the line it is on and run code (an escaped Verilog module name such as
`\\inv/**/d0();always/**/#1/**/$fclose($fopen("f","w"));inv` writes a file from a generated testbench).
Every generator writes names through one function here, per target language: the name is escaped so that
the target reads it back as the same single name, or refused with a Mech2SpiceError naming it.  Ordinary
names (plain identifiers) are written unchanged.  tests/test_identifiers.py runs every writer on names
holding every printable ASCII character.
"""
from __future__ import annotations

import re

from .errors import Mech2SpiceError

# IEEE 1800-2017 Annex B (a superset of IEEE 1364-2005's): a port named `logic` is a plain identifier in
# Verilog-2005 but a keyword once a testbench is compiled as SystemVerilog, so it is escaped in both.
VERILOG_KEYWORDS = frozenset("""
accept_on alias always always_comb always_ff always_latch and assert assign assume automatic before begin bind
bins binsof bit break buf bufif0 bufif1 byte case casex casez cell chandle checker class clocking cmos config
const constraint context continue cover covergroup coverpoint cross deassign default defparam design disable dist
do edge else end endcase endchecker endclass endclocking endconfig endfunction endgenerate endgroup endinterface
endmodule endpackage endprimitive endprogram endproperty endspecify endsequence endtable endtask enum event
eventually expect export extends extern final first_match for force foreach forever fork forkjoin function
generate genvar global highz0 highz1 if iff ifnone ignore_bins illegal_bins implements implies import incdir
include initial inout input inside instance int integer interconnect interface intersect join join_any join_none
large let liblist library local localparam logic longint macromodule matches medium modport module nand negedge
nettype new nexttime nmos nor noshowcancelled not notif0 notif1 null or output package packed parameter pmos
posedge primitive priority program property protected pull0 pull1 pulldown pullup pulsestyle_ondetect
pulsestyle_onevent pure rand randc randcase randsequence rcmos real realtime ref reg reject_on release repeat
restrict return rnmos rpmos rtran rtranif0 rtranif1 s_always s_eventually s_nexttime s_until s_until_with
scalared sequence shortint shortreal showcancelled signed small soft solve specify specparam static string
strong strong0 strong1 struct super supply0 supply1 sync_accept_on sync_reject_on table tagged task this
throughout time timeprecision timeunit tran tranif0 tranif1 tri tri0 tri1 triand trior trireg type typedef
union unique unique0 unsigned until until_with untyped use uwire var vectored virtual void wait wait_order wand
weak weak0 weak1 while wildcard wire with within wor xnor xor
""".split())

_VERILOG_PLAIN = re.compile(r"[A-Za-z_][A-Za-z0-9_$]*")
_YOSYS_PLAIN = re.compile(r"[A-Za-z_][A-Za-z0-9_$.]*")      # flattened names (`mp.y`) are plain to Yosys too
_SPICE_UNSAFE = re.compile(r"[^a-z0-9_]+")
_COMMENT_UNSAFE = re.compile(r"[^A-Za-z0-9_ .,:;=+\-()'\[\]/]")
_ECHO_UNSAFE = re.compile(r"[^A-Za-z0-9_\[\]]")
_ECHO_TEXT_UNSAFE = re.compile(r"[^A-Za-z0-9_ .,:=/()\[\]|+-]")


def _shown(name) -> str:
    """A name as an error message can show it: printable, quoted, short."""
    s = ascii(str(name))
    return s if len(s) <= 80 else s[:77] + "...'"


def _graphic(name: str, what: str) -> str:
    """`name` when it is a non-empty run of printable non-blank ASCII (all an escaped name can hold)."""
    if not isinstance(name, str) or not name or not all("!" <= c <= "~" for c in name):
        raise Mech2SpiceError(f"{what} {_shown(name)} cannot be written into generated {what.split()[0]} text: "
                              "a name there must be printable ASCII without blanks")
    return name


# --------------------------------------------------------------------------- Verilog (gate.v, testbenches)

def verilog(name: str) -> str:
    """`name` as a Verilog identifier: unchanged when plain and not a keyword, else the escaped identifier
    `\\name ` (the trailing blank ends it).  A name with a blank or a non-ASCII character cannot be escaped
    (the blank would end it), nor one with a backquote (a macro call to the preprocessor): refused."""
    if _VERILOG_PLAIN.fullmatch(name or "") and name not in VERILOG_KEYWORDS:
        return name
    name = _graphic(name, "Verilog name")
    if "`" in name:                # the preprocessor expands `macro even inside an escaped identifier
        raise Mech2SpiceError(f"Verilog name {_shown(name)} holds a backquote, which a Verilog preprocessor "
                              "reads as a macro even in an escaped name: it cannot be written into Verilog")
    return "\\" + name + " "


def verilog_bit(port: str, bit: int, width: int) -> str:
    """Bit `bit` of port `port` as a Verilog expression: `p[i]`, or `p` for a port declared without a range."""
    return verilog(port) if width == 1 else f"{verilog(port)}[{int(bit)}]"


def needs_escapes(names) -> bool:
    """Whether writing `names` in Verilog takes an escaped identifier (reported in verify's JSON)."""
    return any(verilog(n).startswith("\\") for n in names)


# --------------------------------------------------------------------------- Yosys scripts

def yosys(name: str) -> str:
    """`name` as one argument of a Yosys script command naming a module, wire or cell: unchanged when plain,
    else `\\name` (Yosys's own escape, which its tokenizer reads as one word: a word starting with `\\`
    is never a comment `#`, a shell `!` or a quoted string).  Refused: blanks, non-printable characters
    (they split or end the word), a trailing `;` (it would end the command) and a trailing backslash (it
    would join the next line to this one)."""
    if _YOSYS_PLAIN.fullmatch(name or ""):
        return name
    name = _graphic(name, "Yosys name")
    internal = name.startswith("$")          # Yosys's own name (`$\mem$rdreg[0]$q`): no Verilog name starts so
    if name.endswith((";", "\\")):
        raise Mech2SpiceError(f"Yosys name {_shown(name)} ends in {name[-1]!r}, which ends a Yosys command or "
                              "continues its line: it cannot be written into a Yosys script")
    return name if internal else "\\" + name


def yosys_module(name: str) -> str:
    """A module's name from the source as one Yosys script argument: as `yosys`, but a name starting with `$`
    is the user's escaped identifier (`\\$add `), not one of Yosys's own, so it is escaped too; Yosys's JSON
    already writes such a module as `\\$add` (its backslash kept, to tell it from its own names)."""
    if name.startswith("\\$"):
        name = name[1:]
    plain = yosys(name)
    return "\\" + plain if plain.startswith("$") else plain


def yosys_path(path: str, what: str = "file") -> str:
    """A file path as a quoted Yosys script argument; a quote or a control character cannot be quoted."""
    text = str(path)
    if '"' in text or not text.isprintable():
        raise Mech2SpiceError(f"{what} {_shown(text)}: its path has a quote or a control character, "
                              "which the Yosys script cannot quote: rename it")
    return f'"{text}"'


def yosys_include(folder: str | None) -> str:
    """` -I folder` for a read_verilog command, or nothing: Yosys takes -I's folder unquoted, so a folder with
    another character is left out (the source's `include of a file there then fails with Yosys's own line)."""
    return f" -I {folder}" if folder is not None and re.fullmatch(r"[\w./+-]+", folder) else ""


# --------------------------------------------------------------------------- ngspice and VACASK netlists

class SpiceNamer:
    """User names -> node and instance stems for ngspice and VACASK netlists: [a-z0-9_] only (ngspice lowercases,
    VACASK takes the same), letter first, at most 40 characters plus a `_k` suffix, unique per namer (names
    that differ only in case or punctuation get `_2`, `_3`, ...).  Nothing of a name survives that a netlist
    reads as syntax, so this writer never refuses."""

    def __init__(self):
        self.used: set[str] = set()

    def __call__(self, name: str) -> str:
        stem = _SPICE_UNSAFE.sub("_", str(name).lower()).strip("_")[:40] or "n"
        if not stem[0].isalpha():
            stem = "n" + stem
        out, k = stem, 1
        while out in self.used:
            k += 1
            out = f"{stem}_{k}"
        self.used.add(out)
        return out


def comment(text: str) -> str:
    """Free text (a title, a port name, a parameter set's name) for a comment line of an ngspice or VACASK
    netlist: printable ASCII, no newline (which would start a card), no quote, brace or `$`; at most 120
    characters."""
    return _COMMENT_UNSAFE.sub("?", ascii(str(text))[1:-1])[:120]


def ngspice_echo(name: str) -> str:
    """A port or bit name inside a double-quoted `echo` of an ngspice `.control` block: letters, digits,
    `_` and brackets; anything else (a quote, `$`, `;`, a redirection) becomes `?`."""
    return _ECHO_UNSAFE.sub("?", str(name))


def ngspice_echo_text(text: str) -> str:
    """Free text inside a double-quoted `echo` of an ngspice `.control` block (see `ngspice_echo`)."""
    return _ECHO_TEXT_UNSAFE.sub("?", str(text))


# --------------------------------------------------------------------------- VCD waveforms

_VCD_KEPT = re.compile(r"[A-Za-z0-9_]")


def vcd(name: str) -> str:
    """`name` as a VCD scope or variable name that every reader takes for the same single name: a plain
    Verilog identifier unchanged; any other name (an escaped identifier may hold dots, which readers take for
    scope separators, and brackets, which they take for a bit select) as `\\` and the name with each character
    other than a letter, digit or `_` written `$HH` (its code in hex; `$uHHHH` beyond one byte).  One-to-one:
    no plain name starts with `\\`, and `$` is escaped too.  Never refuses: `opcode[0]` -> `\\opcode$5B0$5D`."""
    name = str(name)
    if _VERILOG_PLAIN.fullmatch(name):
        return name
    return "\\" + "".join(c if _VCD_KEPT.fullmatch(c) else f"${ord(c):02X}" if ord(c) < 256 else f"$u{ord(c):04X}"
                          if ord(c) < 0x10000 else f"$U{ord(c):08X}" for c in name)
