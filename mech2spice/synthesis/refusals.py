"""Verilog that the NOR mapping cannot represent faithfully, refused with the file and line.

Yosys accepts each of these and synthesises *something*, while a simulator (Icarus) or the hardware
would do something else; every check reads a file the Yosys flow (synth._flow) writes beside its netlist:

* ``read.il`` (RTLIL as read): several top-level modules and no --top (Yosys would pick one by itself).
* ``drivers.il`` (after ``proc -noopt``, before anything merges or folds nets): a net with two drivers,
  e.g. two continuous assignments (a simulator reads x where they disagree; Yosys keeps one, and proc's
  own opt_expr can even delete one of them).  Not a tri-state bus: when every driver of a net can
  release it (``en ? d : 'bz``), the flow resolves it to a multiplexer (``tribuf -merge -logic``).
* ``ast.txt`` (``read_verilog -dump_ast1``): a non-edge ``always`` whose sensitivity list leaves out a
  signal it reads (Yosys builds it as ``@*``; a simulator runs it only when a listed signal changes, e.g.
  ``always @(clk) q <= d``), or an ``always`` with no event control at all (a simulator loops forever).
"""
from __future__ import annotations

import re
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import Mech2SpiceError
from .verilog_text import line_of

#: Part of the synthesis cache key: bump it when a check changes, so cached designs are checked again.
VERSION = 10


def check(tmp: Path, path: Path, source: str, top: str | None) -> tuple[dict[str, list[str]], list[AliasRead]]:
    """Run every check on the files the flow wrote in `tmp` (`source`: the file's text); return each module's
    output ports that a tri-state driver may release (`check_drivers`) and the always blocks accepted with an
    alias left out of their sensitivity lists (`check_sensitivity`)."""
    if top is None:
        single_top(tmp, path)
    aliased = check_sensitivity((tmp / "ast.txt").read_text(), path, source)
    modules = read_rtlil((tmp / "drivers.il").read_text())      # the nets as written, read once for both
    check_case_equality(modules, path)
    return check_drivers(modules, path, source), aliased


def src_line(src: str | None, path: Path) -> int | None:
    """The first line of a Yosys src attribute ('FILE:L.C-L.C') when FILE is the design file."""
    m = re.match(r"(.*?):(\d+)[.:]", src or "")
    return int(m[2]) if m and Path(m[1]).name == path.name else None


_DEFERRED = "$abstract\\"       # `read_verilog -defer` keeps each module under this name until `hierarchy`


def _name(rtlil_id: str) -> str:
    """RTLIL '\\foo' (or a deferred module's '$abstract\\foo') -> 'foo' (generated '$...' names stay)."""
    if rtlil_id.startswith(_DEFERRED):
        rtlil_id = rtlil_id[len(_DEFERRED) - 1:]
    return rtlil_id[1:] if rtlil_id.startswith("\\") else rtlil_id


# --------------------------------------------------------------------------- several top modules

def single_top(tmp: Path, path: Path) -> str | None:
    """The top module of a source read without --top (read.il and ast.txt in `tmp`): the one marked (* top *),
    else the one module (not an interface or a blackbox) no other instantiates; several such are refused (Yosys would pick one by itself).
    None where there is no candidate (every module instantiated: Yosys's -auto-top decides)."""
    used = instantiated((tmp / "ast.txt").read_text())
    modules, marked, attrs = {}, [], {}
    for line in (tmp / "read.il").read_text().splitlines():
        if m := re.match(r"attribute \\(\w+) (.*)$", line):
            attrs[m[1]] = m[2]
        elif m := re.match(r"module (\S+)$", line):
            name = _name(m[1])
            if attrs.get("blackbox", "0") == "0" and attrs.get("is_interface", "0") == "0":    # an interface: no design
                modules[name] = src_line(attrs.get("src", "").strip('"'), path)
            if attrs.get("top", "0") != "0":
                marked.append(name)
            attrs = {}
    roots = [name for name in modules if name not in used]
    listed = lambda names: ", ".join(f"{r} (line {modules[r]})" if modules.get(r) else r for r in names)  # noqa: E731
    if len(marked) > 1:                 # Yosys took the first: which one is the design is the user's to say
        raise Mech2SpiceError(f"{path}: several modules are marked (* top *): {listed(marked)}; choose one with "
                              "--top (synthesize(top=...) in the API)")
    if marked:
        return marked[0]
    if len(roots) > 1:
        raise Mech2SpiceError(f"{path}: several top-level modules: {listed(roots)}; choose one with --top "
                              "(synthesize(top=...) in the API)")
    return roots[0] if roots else None


# --------------------------------------------------------------------------- sensitivity lists

@dataclass
class _Ast:
    kind: str
    src: str
    name: str | None
    children: list = field(default_factory=list)


_AST_LINE = re.compile(r"^( *)(AST_\w+|ATTR)\b(?: <([^>]*)>)?")
_AST_STR = re.compile(r" str='(.*?)'")


def read_ast(text: str) -> list[_Ast]:
    """The AST_MODULE trees of a `read_verilog -dump_ast1` log (nesting by indentation)."""
    roots, stack = [], []
    for line in text.splitlines():
        m = _AST_LINE.match(line)
        if not m:
            continue
        name = _AST_STR.search(line)
        node = _Ast(m[2], m[3] or "", _name(name[1]) if name else None)
        depth = len(m[1])
        while stack and stack[-1][0] >= depth:
            stack.pop()
        (stack[-1][1].children if stack else roots).append(node)
        stack.append((depth, node))
    return [n for n in roots if n.kind == "AST_MODULE"]


def instantiated(ast_text: str) -> set[str]:
    """The module names the source instantiates anywhere (its AST_CELLTYPE nodes)."""
    return {n.name for module in read_ast(ast_text) for n in _nodes(module) if n.kind == "AST_CELLTYPE"}


def _nodes(node: _Ast, skip=()):
    """Every node under `node` (itself included), not entering subtrees whose kind is in `skip`."""
    stack = [node]
    while stack:
        node = stack.pop()
        yield node
        stack.extend(c for c in reversed(node.children) if c.kind not in skip)


_EVENTS = ("AST_EDGE", "AST_POSEDGE", "AST_NEGEDGE")
_ASSIGN = ("AST_ASSIGN_EQ", "AST_ASSIGN_LE")


def _reads(node: _Ast, reads: set, written: set) -> None:
    """Names `node` reads and names it assigns or declares (an lvalue's indices are reads)."""
    if node.kind in _ASSIGN:
        _lvalue(node.children[0], reads, written)
        for child in node.children[1:]:
            _reads(child, reads, written)
        return
    if node.kind in ("AST_WIRE", "AST_MEMORY"):        # a local declaration in a named block
        written.add(node.name)
        return
    if node.kind == "AST_IDENTIFIER":
        reads.add(node.name)
    for child in node.children:
        _reads(child, reads, written)


def _lvalue(node: _Ast, reads: set, written: set) -> None:
    if node.kind == "AST_IDENTIFIER":
        written.add(node.name)
        for child in node.children:
            _reads(child, reads, written)
    else:
        for child in node.children:
            _lvalue(child, reads, written)


@dataclass(frozen=True)
class AliasRead:
    """A non-edge always block (at `line`) that reads `names`, each only another name of a listed signal
    (`assign name = listed;`, whole to whole): accepted, and warned (`alias_warning`)."""
    line: int | None
    names: tuple
    listed: tuple


def _aliases(module: _Ast) -> dict[str, str]:
    """name -> the signal a module-level `assign name = other;` makes it another name of (whole identifiers:
    no select, no operator; Icarus then updates the name before any process reads it)."""
    out = {}
    for node in module.children:
        if node.kind == "AST_ASSIGN" and len(node.children) == 2 and all(
                c.kind == "AST_IDENTIFIER" and not c.children for c in node.children):
            out[node.children[0].name] = node.children[1].name
    return out


def _listed_by_alias(name: str, aliases: dict, listed: set) -> str | None:
    """The listed signal `name` is another name of, through a chain of aliases (None: not one)."""
    seen = set()
    while name in aliases and name not in seen:
        seen.add(name)
        name = aliases[name]
        if name in listed:
            return name
    return None


def alias_warning(read: AliasRead, path: Path) -> str:
    where = f"{path}, line {read.line}" if read.line else str(path)
    pairs = ", ".join(f"'{n}' (another name of '{s}')" for n, s in zip(read.names, read.listed))
    it = "it" if len(read.names) == 1 else "them"
    return (f"{where}: this always block reads {pairs} without listing {it}: each changes with its listed "
            f"signal and Icarus updates it first, but the standard leaves that order open; list {it} or write @*")


def check_sensitivity(ast_text: str, path: Path, source: str) -> list[AliasRead]:
    """Refuse non-edge always blocks that a simulator runs differently from the gates Yosys builds; return
    the blocks accepted because what they leave out is only another name of a listed signal."""
    accepted = []
    for module in read_ast(ast_text):
        signals = {n.name for n in _nodes(module, ("AST_FUNCTION", "AST_TASK"))
                   if n.kind in ("AST_WIRE", "AST_MEMORY")}
        aliases = _aliases(module)
        for block in (n for n in _nodes(module) if n.kind == "AST_ALWAYS"):
            events = [c for c in block.children if c.kind in _EVENTS]
            if any(c.kind != "AST_EDGE" for c in events):
                continue                                 # posedge/negedge: a register, mapped as one
            where = f"{path}, line {src_line(block.src, path)}" if src_line(block.src, path) else str(path)
            if not events:
                _check_event_control(block, where, path, source)
                continue
            listed = {n.name for c in events for n in _nodes(c) if n.kind == "AST_IDENTIFIER"}
            reads, written = set(), set()
            for child in block.children:
                if child.kind not in _EVENTS:
                    _reads(child, reads, written)
            missing = sorted((reads & signals) - written - listed)
            named = {m: _listed_by_alias(m, aliases, listed) for m in missing}
            if missing and all(named.values()):
                accepted.append(AliasRead(src_line(block.src, path), tuple(missing), tuple(named[m] for m in missing)))
                continue
            missing = [m for m in missing if not named[m]]
            if missing:
                names = ", ".join(f"'{m}'" for m in missing)
                raise Mech2SpiceError(
                    f"{where}: this always block reads {names} but its sensitivity list leaves "
                    f"{'it' if len(missing) == 1 else 'them'} out: a simulator runs the block only when a listed "
                    "signal changes, the gates compute it all the time; list every signal it reads (or write "
                    "@*), or write posedge for a register")
    return accepted


def _check_event_control(block: _Ast, where: str, path: Path, source: str) -> None:
    """`always @*` and `always_comb` are combinational; a bare `always` (or `always #d`) is not."""
    start = _offset(source, block.src, path)
    body = [c for c in block.children if c.kind != "ATTR"]
    end = _offset(source, body[0].src, path) if body else None
    if start is None or end is None:
        return
    head = source[start:end]
    if re.match(r"always\b", head) and "@" not in head:
        raise Mech2SpiceError(f"{where}: an always block without an event control (@(...) or @*): a simulator "
                              "runs it in an endless loop, synthesis would make it combinational; write "
                              "always @* or always @(posedge clk)")


def _offset(source: str, src: str, path: Path) -> int | None:
    """The character offset of a src attribute's start in `source` (the design file only)."""
    m = re.match(r"(.*?):(\d+)\.(\d+)", src or "")
    if not m or Path(m[1]).name != path.name:
        return None
    lines = source.split("\n")
    line, col = int(m[2]), int(m[3])
    return sum(len(x) + 1 for x in lines[:line - 1]) + col - 1 if line <= len(lines) else None


# --------------------------------------------------------------------------- multiple drivers

@dataclass
class _Module:
    wires: dict = field(default_factory=dict)      # name -> (width, offset, upto, direction, src)
    cells: list = field(default_factory=list)      # (type, name, {port: bits}, src)
    connects: list = field(default_factory=list)   # (lhs bits, rhs bits)


def read_rtlil(text: str) -> dict[str, _Module]:
    """The wires, cells and module-level connections of each module in a `write_rtlil` dump.
    A bit is (wire, position) with position 0 the LSB, or ('', '0'|'1'|'x'|'z') for a constant."""
    modules, mod, cell, src = {}, None, None, None
    for line in text.splitlines():
        words = line.split()
        if not words:
            continue
        if words[0] == "attribute" and words[1] == "\\src":
            src = line.split('"')[1] if '"' in line else None
        elif words[0] == "module":
            mod = modules[_name(words[1])] = _Module()
        elif words[0] == "wire":
            mod.wires[words[-1]] = _wire(words[1:-1], src)
        elif words[0] == "cell":
            cell = (words[1], words[2], {}, src)
            mod.cells.append(cell)
        elif words[0] == "connect" and cell is not None:
            cell[2][words[1]] = _sig(words[2:], mod.wires)
        elif words[0] == "connect":
            lhs, rest = _sig_prefix(words[1:], mod.wires)
            mod.connects.append((lhs, _sig(rest, mod.wires)))
        elif words[0] == "end":
            cell = None
        if words[0] != "attribute":
            src = None
    return modules


def _wire(words: list[str], src: str | None) -> tuple:
    opts = dict(zip(words, words[1:]))
    direction = next((d for d in ("input", "output", "inout") if d in words), None)
    return int(opts.get("width", 1)), int(opts.get("offset", 0)), "upto" in words, direction, src


def _sig(words: list[str], wires: dict) -> list:
    bits, rest = _sig_prefix(words, wires)
    if rest:
        raise ValueError(f"unexpected RTLIL after a signal: {' '.join(rest)}")
    return bits


def _sig_prefix(words: list[str], wires: dict) -> tuple[list, list[str]]:
    """One RTLIL signal from the front of `words` as bits LSB first; the words after it."""
    word = words[0]
    if word == "{":
        parts, rest = [], words[1:]
        while rest[0] != "}":
            part, rest = _sig_prefix(rest, wires)
            parts.append(part)
        return [b for part in reversed(parts) for b in part], rest[1:]      # written MSB part first
    if m := re.fullmatch(r"(\d+)'([01xzm-]*)", word):
        return [("", c) for c in reversed(m[2])], words[1:]
    if re.fullmatch(r"-?\d+", word):
        return [("", c) for c in reversed(format(int(word) & 0xFFFFFFFF, "032b"))], words[1:]
    if len(words) > 1 and (m := re.fullmatch(r"\[(\d+)(?::(\d+))?\]", words[1])):
        hi, lo = int(m[1]), int(m[2] if m[2] is not None else m[1])
        step = 1 if hi >= lo else -1
        return [(word, i) for i in range(lo, hi + step, step)], words[2:]
    return [(word, i) for i in range(wires[word][0])], words[1:]


class _Nets:
    """Union-find over wire bits: the bits `connect` joins are one net."""

    def __init__(self):
        self.parent = {}

    def find(self, bit):
        self.parent.setdefault(bit, bit)
        while self.parent[bit] != bit:
            self.parent[bit] = self.parent[self.parent[bit]]
            bit = self.parent[bit]
        return bit

    def union(self, a, b) -> None:
        self.parent[self.find(a)] = self.find(b)


def _outputs(ctype: str, modules: dict) -> set[str]:
    """The output ports of a cell.  Of Yosys's own cells, those the Verilog front end and `proc` create:
    Y (logic), Q (flip-flops, latches), RD_DATA ($mem) and DATA of a memory read (a write's is an input);
    a user module's from its port declarations."""
    if ctype.startswith("$") and _name(ctype) not in modules:
        return {"\\DATA"} if ctype.startswith("$memrd") else {"\\Y", "\\Q", "\\RD_DATA"}
    wires = modules[_name(ctype)].wires if _name(ctype) in modules else {}
    return {w for w, info in wires.items() if info[3] == "output"}


def check_case_equality(modules: dict, path: Path) -> None:
    """Refuse `===` / `!==` against a value with x or z bits: it asks whether a net holds x or z, which a
    mechanical net never does (it always carries a 0 or a 1), and Yosys reads the x bits as don't-cares, so
    the network answered differently from Icarus with exit 0."""
    for name, mod in modules.items():
        for ctype, _, conns, src in mod.cells:
            if ctype not in ("$eqx", "$nex"):
                continue
            if any(not wire and value in "xz" for port in ("\\A", "\\B") for wire, value in conns.get(port, [])):
                line = src_line(src, path)
                op = "===" if ctype == "$eqx" else "!=="
                raise Mech2SpiceError(f"{path}{f', line {line}' if line else f' (module {name})'}: `{op}` against a "
                                      "value with x or z bits asks whether a net holds x or z; a mechanical net "
                                      "always carries a 0 or a 1, so the answer is a constant: write the "
                                      "constant, or compare the defined bits with `==`")


def check_drivers(modules: dict, path: Path, source: str) -> dict[str, list[str]]:
    """Refuse a net driven from two places: ports, cell outputs and constants each count as a driver.
    A net whose every driver can release it (a tri-state driver: `en ? d : 'bz`, or a submodule's output
    that is one) is a tri-state bus, not a conflict: the flow resolves it to a multiplexer (`tribuf`).
    `modules`: `read_rtlil` of the design after `proc -noopt`.  Returns each module's output ports with such
    a bit (module name -> port names, sorted)."""
    released: dict[str, set] = {}
    for name in _bottom_up(modules):
        released[name] = _check_module_drivers(name, modules, released, path, source)
    return {name: sorted({_name(wire) for wire, _ in bits}) for name, bits in released.items()}


def _bottom_up(modules: dict) -> list[str]:
    """Module names, each after the modules it instantiates (what its tri-state outputs depend on)."""
    order, seen = [], set()

    def visit(name):
        if name in seen:
            return
        seen.add(name)
        for ctype, *_ in modules[name].cells:
            if _name(ctype) in modules:
                visit(_name(ctype))
        order.append(name)
    for name in modules:
        visit(name)
    return order


def _check_module_drivers(name: str, modules: dict, released: dict, path: Path, source: str) -> set:
    """Refuse a net of module `name` with two drivers unless all of them can release it; return the
    module's port bits that a tri-state driver drives (what its instances' outputs may release)."""
    mod = modules[name]
    nets, drivers, written = _Nets(), [], defaultdict(int)
    for wire, (width, _, _, direction, src) in mod.wires.items():
        if direction == "input":
            drivers += [((wire, i), ("input", wire, i), None, False) for i in range(width)]
    for ctype, cname, conns, src in mod.cells:
        outputs = _outputs(ctype, modules)
        for port, bits in conns.items():
            if port in outputs:
                drivers += [(b, (cname, port, k), src, _releases(ctype, conns, port, k, released))
                            for k, b in enumerate(bits) if b[0]]
    for lhs, rhs in mod.connects:
        for a, b in zip(lhs, rhs):
            if a[0] and b[0]:
                nets.union(a, b)
                written[a] += 1
            elif a[0] or b[0]:                      # a wire tied to a constant
                value = (b if a[0] else a)[1]
                drivers.append((a if a[0] else b, ("const", value), None, value == "z"))
    by_net, tristate = defaultdict(dict), defaultdict(lambda: True)
    for bit, who, src, releases in drivers:
        written[bit] += 1
        by_net[nets.find(bit)].setdefault(who, src)
        tristate[nets.find(bit)] &= releases
    for net, who in by_net.items():
        if len(who) > 1 and not tristate[net]:
            _refuse_drivers(name, mod, nets, net, who, written, path, source)
    return {b for b in (*nets.parent, *(d[0] for d in drivers))
            if mod.wires.get(b[0], (0, 0, 0, None))[3] == "output" and nets.find(b) in by_net
            and tristate[nets.find(b)]}


_TRISTATE_CELLS = {"$mux": ("\\A", "\\B"), "$pmux": ("\\A", "\\B"), "$_MUX_": ("\\A", "\\B")}


def _releases(ctype: str, conns: dict, port: str, k: int, released: dict) -> bool:
    """Whether output bit k of a cell can leave its net undriven ('z'): a $tribuf, a multiplexer with a 'z'
    among the values it selects for that bit, or a submodule whose output bit is such a driver."""
    if ctype in ("$tribuf", "$_TBUF_"):
        return True
    if ctype in _TRISTATE_CELLS:
        width = len(conns.get("\\Y", [])) or 1
        data = [b for p in _TRISTATE_CELLS[ctype] for i, b in enumerate(conns.get(p, [])) if i % width == k]
        return ("", "z") in data
    return (port, k) in released.get(_name(ctype), ())


def _refuse_name_collision(wire: str, path: Path, source: str) -> None:
    """Refuse a net that is two of the source's names: an escaped identifier `\\x.y ` and the member y of generate
    block x, both `x.y` to Yosys (public RTL pass 9).  They are two registers to a simulator, one net with two
    drivers once read."""
    scope, dot, member = wire.rpartition(".")
    if not dot:
        return
    escaped = re.search(r"\\" + re.escape(wire) + r"\s", source)
    label = re.search(r"\bbegin\s*:\s*" + re.escape(scope.rpartition(".")[2]) + r"(?![\w$])", source)
    if escaped and label:
        at, block_at = (line_of(source, m.start()) for m in (escaped, label))
        raise Mech2SpiceError(
            f"{path}, line {at}: the escaped identifier '\\{wire} ' has the name Yosys gives '{member}' "
            f"of generate block '{scope}' (line {block_at}): read, the two are one net with two drivers; "
            "rename the escaped identifier")


def _refuse_drivers(module: str, mod: _Module, nets: _Nets, net, who: dict, written: dict, path: Path,
                    source: str) -> None:
    """Name the bit where two drivers meet (the most writes: own drivers plus `assign`s into it) and the
    lines that drive it."""
    bits = [b for b in nets.parent if nets.find(b) == net] or [net]
    bit = max(bits, key=lambda b: (written[b], b[0].startswith("\\"), mod.wires[b[0]][3] != "input"))
    _refuse_name_collision(_name(bit[0]), path, source)
    lines = {src_line(src, path) for src in who.values()} | set(_assign_lines(source, module, _name(bit[0])))
    lines = sorted(x for x in lines if x)
    where = f"{path}, line {lines[-1]}" if lines else f"{path}, module {module}"
    also = f" (lines {', '.join(map(str, lines))})" if len(lines) > 1 else ""
    raise Mech2SpiceError(f"{where}: '{_bit_label(mod, bit)}' has more than one driver{also}: a simulator reads "
                          "x where they disagree, synthesis would keep one of them; drive each net from one "
                          "place (combine the values with logic or a multiplexer)")


def _bit_label(mod: _Module, bit) -> str:
    """'y' for a 1-bit wire, else 'y[HDL index]'."""
    wire, pos = bit
    width, offset, upto = mod.wires[wire][:3]
    return _name(wire) if width == 1 else f"{_name(wire)}[{offset + (width - 1 - pos if upto else pos)}]"


_BLANK = re.compile(r'//[^\n]*|/\*.*?\*/|"(?:\\.|[^"\\\n])*"', re.S)


def _assign_lines(source: str, module: str, name: str) -> list[int]:
    """Lines of `assign` statements (and `wire w = ...` declarations) in `module` that write `name`."""
    text = _BLANK.sub(lambda m: re.sub(r"[^\n]", " ", m.group()), source)
    base = module.split("\\")[1] if module.startswith("$paramod") else module
    m = re.search(rf"\bmodule\s+{re.escape(base)}\b(.*?)\bendmodule\b", text, re.S)
    start, end = (m.start(1), m.end(1)) if m else (0, len(text))
    found = []
    for st in re.finditer(r"\b(assign|wire)\b([^;]*?)(?<![=!<>])=(?!=)", text[start:end]):
        written = set(re.findall(r"[A-Za-z_][\w$]*", re.sub(r"\[[^\]]*\]", "", st[2])))
        if name in written:
            found.append(text.count("\n", 0, start + st.start()) + 1)
    return found
