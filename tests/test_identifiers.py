"""One writer of names into generated text (mech2spice/identifiers.py): every generator, run on names holding
every printable ASCII character, writes text its target reads back as the same names or refuses the name in
one Mech2SpiceError; a design whose module name is a testbench statement creates no file (issues #35, #37)."""
from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import networkx as nx
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from mech2spice import api, cli, identifiers as ids, verify as V
from mech2spice.errors import Mech2SpiceError
from mech2spice.physics import network
from mech2spice.physics.params import load_params
from mech2spice.spice import vacask
from mech2spice.synthesis.synth import Netlist, synthesize

ROOT = Path(__file__).resolve().parents[1]
VERILOG = ROOT / "verilog"
PRINTABLE = "".join(chr(c) for c in range(32, 127))          # every printable ASCII character, blank included
GRAPHIC = PRINTABLE[1:]
ICARUS = shutil.which("iverilog") and shutil.which("vvp")
needs_icarus = pytest.mark.skipif(not ICARUS, reason="Icarus Verilog (iverilog, vvp) not installed")

names = st.text(alphabet=PRINTABLE, min_size=1, max_size=24)
VERILOG_GRAPHIC = GRAPHIC.replace("`", "")                  # a backquote is refused (a macro call), tested above
graphic_names = st.text(alphabet=VERILOG_GRAPHIC, min_size=1, max_size=24).filter(lambda s: not s.startswith(V.PREFIX))


def renamed(nl: Netlist, top: str, new: dict[str, str]) -> Netlist:
    """`nl` with its top module and ports renamed (`new`: old port -> new port); port bit nodes follow."""
    g = nl.graph.copy()
    relabel = {}
    for node, attrs in g.nodes(data=True):
        if attrs["kind"] in ("input", "output"):
            attrs["port"] = new[attrs["port"]]
            relabel[node] = f"{attrs['port']}[{attrs['bit']}]"
    g = nx.relabel_nodes(g, relabel)
    return Netlist(top, g, {new[p]: w for p, w in nl.inputs.items()}, {new[p]: w for p, w in nl.outputs.items()},
                   new.get(nl.clock, nl.clock), frozenset(new[p] for p in nl.signed))


ADDER = synthesize(VERILOG / "adder2.v")          # a[2], b[2] -> s[3]
COUNTER = synthesize(VERILOG / "counter4.v")      # clocked


def _hostile(nl: Netlist, words: list[str]) -> Netlist:
    ports = [*([nl.clock] if nl.clock else []), *nl.inputs, *nl.outputs]
    return renamed(nl, words[0], dict(zip(ports, words[1:])))


# --------------------------------------------------------------------------- the writers alone

def test_plain_names_are_written_unchanged_and_keywords_escaped():
    assert ids.verilog("a_1$") == "a_1$" and ids.yosys("mp.y") == "mp.y"
    assert ids.verilog("logic") == "\\logic " and ids.verilog("module") == "\\module "
    assert ids.verilog("opcode[0]") == "\\opcode[0] " and ids.verilog_bit("opcode[0]", 0, 1) == "\\opcode[0] "
    assert ids.verilog_bit("q", 3, 4) == "q[3]"
    assert ids.yosys("opcode[0]") == "\\opcode[0]"


@given(names)
def test_every_printable_name_is_escaped_or_refused_by_name(name):
    for writer in (ids.verilog, ids.yosys):
        try:
            text = writer(name)
        except Mech2SpiceError as err:
            assert " " in name or (writer is ids.yosys and name.endswith((";", "\\"))) or \
                (writer is ids.verilog and "`" in name), name
            assert ascii(name)[1:-1][:20] in str(err)
            continue
        if text.startswith("\\"):             # one word to the target: no blank inside, nothing after it
            assert text.rstrip(" ")[1:] == name and not re.search(r"\s", text.rstrip(" "))
        else:                                  # plain, or Yosys's own `$` name (no Verilog name starts so)
            assert text == name and (re.fullmatch(r"[A-Za-z_][A-Za-z0-9_$.]*", name) or
                                     writer is ids.yosys and name.startswith("$") and not re.search(r"\s", name))
    for text in (ids.comment(name), ids.ngspice_echo(name), ids.ngspice_echo_text(name)):
        assert text.isprintable() and not set(text) & set("\"'{}$;*\\`") - set("';")
    assert re.fullmatch(r"[a-z][a-z0-9_]*", ids.SpiceNamer()(name))


# --------------------------------------------------------------------------- Verilog and Yosys, end to end

def _icarus_equals_logic(nl: Netlist, tmp: Path) -> None:
    """gate.v written with these names, run under the generated testbench on Icarus, equals the network on
    the logic backend; Yosys reads the same gate.v through the generated script and proves it equal to the
    network (the script names the top module).  Names are checked first, as `verify` checks them."""
    V.check_names(nl)
    src = tmp / "gate.v"
    src.write_text(V.write_verilog(nl, nl.top))
    clocked = nl.clock is not None
    x = V.make_cycles(nl, 12, 1, None) if clocked else V.make_vectors(nl, 16, True, 0)[0]
    ref = V.icarus(src, nl, x, clocked)
    got = V.run_backend(nl, x, clocked, "logic", None, False)
    assert V.compare(nl, x, ref, got, clocked) == []
    assert V.equivalence(src, nl)["status"] == "proved"


@needs_icarus
@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(graphic_names, min_size=4, max_size=4, unique=True))
def test_hostile_names_in_gate_v_testbench_and_yosys_script(tmp_path, words):
    if "#" in words:                    # Icarus 11 cannot bind `\\# ` itself: verify refuses it (next test)
        with pytest.raises(Mech2SpiceError, match="only '#'"):
            _icarus_equals_logic(_hostile(ADDER, words), tmp_path)
        return
    _icarus_equals_logic(_hostile(ADDER, words), tmp_path)


@needs_icarus
@pytest.mark.parametrize("at", [0, 1, 3])
def test_a_name_that_is_only_a_hash_is_refused_in_one_line(tmp_path, at):
    """Icarus 11 answers `\\# [0]` with "sorry: Implicit class handle super" and no binding (measured), so
    a module or port named '#' is refused by name before any file is written; '#a' and '##' are bound."""
    words = ["m", "a", "b", "s"]
    words[at] = "#"
    with pytest.raises(Mech2SpiceError, match="only '#'"):
        _icarus_equals_logic(_hostile(ADDER, words), tmp_path)
    _icarus_equals_logic(_hostile(ADDER, ["#m", "##", "b#", "s"]), tmp_path)


@needs_icarus
def test_every_printable_character_at_once(tmp_path):
    """One name of every graphic character for each port of a combinational and a clocked design."""
    words = [f"{VERILOG_GRAPHIC}{k}" for k in range(5)]
    _icarus_equals_logic(_hostile(ADDER, words), tmp_path)
    words = [w + VERILOG_GRAPHIC for w in ("top", "clk", "rst", "en", "q")]
    nl = COUNTER
    assert [nl.clock, *nl.inputs, *nl.outputs] == ["clk", "rst", "en", "q"], "counter4's ports changed"
    _icarus_equals_logic(_hostile(nl, words), tmp_path)


def test_a_name_with_a_blank_or_a_backquote_is_refused_naming_it():
    with pytest.raises(Mech2SpiceError, match="'a b'"):
        V.check_names(_hostile(ADDER, ["top", "a b", "b", "s"]))
    with pytest.raises(Mech2SpiceError, match="'a`define'.*backquote"):
        V.check_names(_hostile(ADDER, ["top", "a`define", "b", "s"]))
    with pytest.raises(Mech2SpiceError, match="m2s__mem"):
        V.check_names(_hostile(ADDER, ["top", "m2s__mem", "b", "s"]))


# --------------------------------------------------------------------------- ngspice and VACASK: inert

CARD = re.compile(r"^(\*.*|\.\w+.*|\+ .*|[A-Za-z]\w*( [\w.()={}*+/\-]+| I = .*)*)$")


def _ngspice_lines_inert(text: str) -> None:
    """Every card of the netlist is a comment, a dot card, a continuation or an element of plain words;
    inside .control, every echo is one double-quoted string holding no quote, `$` or `;`."""
    body, control = text.split(".control", 1)
    bad = [ln for ln in body.splitlines() if ln and not CARD.match(ln)]
    assert not bad, bad[:3]
    for ln in control.splitlines():
        if ln.startswith("echo "):
            assert re.fullmatch(r'echo( "[^"$;`\\]*")?', ln), ln
        assert not ln.lower().startswith(("shell", "write", "wrdata", "source", "load", "cd ")), ln
    assert text.count(".control") == 1 and text.count(".endc") == 1 and text.rstrip().endswith(".end")


def _netlists(words: list[str]) -> tuple[str, str]:
    """The ngspice and VACASK netlists of adder2 with its module and ports named `words`, a + b = 1 + 1."""
    nl = _hostile(ADDER, words)
    values = {q: 1 for q in nl.inputs}
    p = load_params("default")
    model = network.build(nl, p)
    stim = network.stimulus(model, nl, p, [(0, [values])])
    title = "mech2spice: " + " ".join(words)
    return (api.emit(nl, values, periods=20),
            vacask.emit(model, 20, stim, title=title, standalone=True, about=title).text)


PLAIN = _netlists(["top", "a", "b", "s"])
QUOTED = re.compile(r'"[^"\n]*"')


@settings(max_examples=10, deadline=None)
@given(st.lists(names, min_size=4, max_size=4, unique=True))
def test_hostile_names_leave_spice_netlists_inert(words):
    """Names only rename nodes and fill comments: the same cards, the same quoted strings, one line each."""
    for text, plain in zip(_netlists(words), PLAIN):
        assert text.isascii() and len(text.splitlines()) == len(plain.splitlines())
        assert sorted(QUOTED.findall(text.split(".control")[0])) == sorted(QUOTED.findall(plain.split(".control")[0]))
    ngspice_text, vacask_text = _netlists(words)
    _ngspice_lines_inert(ngspice_text)
    body = [ln for ln in vacask_text.split("\nembed ")[0].splitlines()[1:] if not ln.lstrip().startswith("//")]
    plain_body = [ln for ln in PLAIN[1].split("\nembed ")[0].splitlines()[1:] if not ln.lstrip().startswith("//")]
    shape = re.compile(r"[a-z0-9_]+")          # instance and node names are the namer's stems
    assert [shape.sub("N", ln) for ln in body] == [shape.sub("N", ln) for ln in plain_body]


@pytest.mark.skipif(not shutil.which("ngspice"), reason="ngspice not installed")
def test_an_all_printable_netlist_runs_and_writes_nothing_else(tmp_path):
    words = [PRINTABLE + str(k) for k in range(4)]
    nl = _hostile(ADDER, words)
    (tmp_path / "a.cir").write_text(api.emit(nl, {words[1]: 1, words[2]: 2}, periods=40))
    proc = subprocess.run(["ngspice", "-b", "a.cir"], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-500:]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.cir"]
    assert re.search(r"= \d+ \((in)?valid\)", proc.stdout)    # the .control block's reading of the port ran


# --------------------------------------------------------------------------- the injection (issue #37)

EVIL_MODULE = '\\inv/**/d0();always/**/#1/**/$fclose($fopen("{0}","w"));inv '
EVIL_PORT = '\\a);always/**/#1/**/$fclose($fopen("{0}","w"));//'


@needs_icarus
@pytest.mark.parametrize("where", ["module", "port"])
def test_a_name_that_is_a_testbench_statement_creates_no_file(tmp_path, capsys, where):
    target = tmp_path / "PWNED"
    inner = "module inv(input a, output y); assign y = ~a; endmodule\n"
    if where == "module":
        src = inner + f"module {EVIL_MODULE.format(target)}(input a, output y);\n  inv u(.a(a), .y(y));\nendmodule\n"
    else:
        port = EVIL_PORT.format(target)
        src = f"module top(input {port} , output y);\n  assign y = ~{port} ;\nendmodule\n"
    (tmp_path / "evil.v").write_text(src)
    code = cli.main(["verify", str(tmp_path / "evil.v"), "--json"])
    out, err = capsys.readouterr()
    assert not target.exists()
    assert code == 0 and '"verdict": "pass"' in out, err   # written safely: proved and agreeing


# --------------------------------------------------------------------------- VCD names

def _vcd_unescaped(text: str) -> str:
    """The inverse of ids.vcd, written here from its rule, to show that the map is one-to-one."""
    if not text.startswith("\\"):
        return text
    return re.sub(r"\$(?:u([0-9A-F]{4})|U([0-9A-F]{8})|([0-9A-F]{2}))",
                  lambda m: chr(int(next(g for g in m.groups() if g), 16)), text[1:])


def test_vcd_names_plain_unchanged_others_escaped():
    assert ids.vcd("q") == "q" and ids.vcd("a_1$") == "a_1$" and ids.vcd("logic") == "logic"
    assert ids.vcd("opcode[0]") == "\\opcode$5B0$5D" and ids.vcd("top.level$1") == "\\top$2Elevel$241"
    assert ids.vcd("é") == "\\$E9" and ids.vcd("\u2192") == "\\$u2192"


@given(st.text(min_size=1, max_size=24))
def test_every_name_has_one_writable_vcd_name(name):
    """Any string (control characters and non-ASCII too) maps to a name the VCD writer takes (printable, no
    blank, no dot, no bracket), and back to itself: two names never share one."""
    from mech2spice.waveform import Waveform, vcd_text
    text = ids.vcd(name)
    assert text.isprintable() and not any(c.isspace() or c in ".[]" for c in text) and text.isascii()
    assert _vcd_unescaped(text) == name
    wave = Waveform([0])
    wave.add_wire([ids.vcd(name)], text, 1, [1])
    assert f" {text} $end" in vcd_text(wave)


COLLIDING = "module top(input [1:0] a, input \\a[0] , output [1:0] y, output z);\n  assign y = a;\n  assign z = \\a[0] ;\nendmodule\n"


@needs_icarus
def test_a_port_named_like_another_ports_bit_is_that_port(tmp_path, capsys):
    """`input \\a[0]` beside `input [1:0] a`: `--set a[0]=B` sets the port, as Verilog reads the name. The logic
    backend took it for bit 0 of `a` and printed wrong outputs with exit 0 (the physical engines did not)."""
    src = tmp_path / "collide.v"
    src.write_text(COLLIDING)
    vectors = [(a, b) for a in range(4) for b in (0, 1)]
    tb = ["module tb;", "  reg [1:0] a; reg a0; wire [1:0] y; wire z;", "  top dut(.a(a), .\\a[0] (a0), .y(y), .z(z));",
          "  initial begin", *(f'    a = {a}; a0 = {b}; #1 $display("%0d %0d", y, z);' for a, b in vectors),
          "  end", "endmodule", ""]
    (tmp_path / "tb.v").write_text("\n".join(tb))
    subprocess.run(["iverilog", "-o", tmp_path / "tb.vvp", src, tmp_path / "tb.v"], check=True, capture_output=True)
    lines = subprocess.run(["vvp", "-n", tmp_path / "tb.vvp"], check=True, capture_output=True, text=True).stdout.split("\n")
    want = [dict(zip("yz", map(int, line.split()))) for line in lines[:len(vectors)]]
    for backend, cases in (("logic", range(len(vectors))), ("envelope", [2])):
        for k in cases:
            a, b = vectors[k]
            assert cli.main(["simulate", str(src), "--backend", backend, "--json", "--set", f"a={a}", "--set", f"a[0]={b}"]) == 0
            assert json.loads(capsys.readouterr().out)["outputs"] == want[k], (backend, a, b)


def test_a_name_outside_ascii_is_refused_and_a_comment_outside_ascii_is_read(tmp_path, capsys):
    """`input \\café` came out of Yosys as "caf\\uffffFFC3\\uffffFFA9", accepted with exit 0 and then unknown to
    `--set café=1` (hostile-input pass, session 21). Verilog names are ASCII; comments may be anything."""
    bad, good = tmp_path / "bad.v", tmp_path / "good.v"
    bad.write_text("module t(input \\café , output y);\n  assign y = \\café ;\nendmodule\n", encoding="utf-8")
    good.write_bytes("module t(input a, output y);  // café\n  assign y = ~a;  /* \xe9 */\nendmodule\n".encode("utf-8")
                     .replace(b"\xc3\xa9 */", b"\xe9 */"))       # a Latin-1 byte in a comment, too
    assert cli.main(["synth", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "line 1: the character 'é'" in err and "ASCII" in err
    assert cli.main(["simulate", str(good), "--set", "a=0", "--backend", "logic", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["outputs"] == {"y": 1}


def test_top_names_a_module_whose_name_is_escaped(tmp_path, capsys):
    """`--top` took only plain names, so a module named `\\my-top` could not be chosen (hostile-input pass,
    session 21); a name the Yosys script cannot hold is still refused, one that is no module is not found."""
    src = tmp_path / "two.v"
    src.write_text("module \\my-top (input a, output y);\n  assign y = ~a;\nendmodule\n"
                   "module other(input a, output y);\n  assign y = a;\nendmodule\n")
    for top, y in (("my-top", 1), ("other", 0)):
        assert cli.main(["simulate", str(src), "--top", top, "--set", "a=0", "--backend", "logic", "--json"]) == 0
        assert json.loads(capsys.readouterr().out)["outputs"] == {"y": y}
    for top, needle in (("a;b", "not found"), ("x y", "without blanks"), ("", "invalid top module name")):
        assert cli.main(["synth", str(src), "--top", top]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and needle in err, (top, err)


def test_a_module_named_with_a_dollar_is_a_users_name(tmp_path, capsys):
    """`module \\$add (...)`: Yosys's JSON writes it `\\$add` (to tell it from its own `$add` cells), verify's
    proof named it `\\\\$add` and did not find it, and `--top '$add'` was refused as "invalid" without a reason
    (public RTL pass 9).  Its name is `$add` everywhere now, escaped for Yosys and for Icarus."""
    src = tmp_path / "d.v"
    src.write_text("module \\$add (input [3:0] a, input [3:0] b, output [3:0] y);\n  assign y = a ^ b;\nendmodule\n")
    for argv in ([], ["--top", "$add"]):
        assert cli.main(["verify", str(src), "--json", *argv]) == 0
        res = json.loads(capsys.readouterr().out)
        assert res["top"] == "$add" and res["equivalence"]["status"] == "proved" and res["cosim"]["agree"]


def test_an_include_folder_is_given_to_yosys_only_where_it_can_be_read(tmp_path):
    """-I takes its folder unquoted (Yosys keeps quotes as part of the name): one helper decides for synthesis
    and verify's proof alike; a folder it can hold is searched by Yosys."""
    assert ids.yosys_include(None) == "" and ids.yosys_include("a b") == "" and ids.yosys_include('a"b') == ""
    headers = tmp_path / "v1.0+hdr"
    headers.mkdir()
    (headers / "w.vh").write_text("localparam W = 3;\n")
    (tmp_path / "t.v").write_text('`include "w.vh"\nmodule t(input [W-1:0] a, output [W-1:0] y);\n'
                                  "assign y = ~a;\nendmodule\n")
    option = ids.yosys_include("v1.0+hdr")
    assert option == " -I v1.0+hdr"
    from mech2spice.synthesis import yosys
    done = yosys.run_script(f"read_verilog{option} t.v\nhierarchy -top t\n", str(tmp_path))
    assert done.returncode == 0, yosys.error_line(done)
