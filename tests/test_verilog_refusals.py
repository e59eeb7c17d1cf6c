"""Verilog the NOR mapping cannot represent faithfully is refused with the file and line, or handled and
checked against Icarus Verilog (issue #26, silent wrong answers): one test per class.

The command line runs in-process (mech2spice.cli.main).  The Icarus comparisons skip when `iverilog` is
absent (`make setup` installs it).
"""
import json
import shutil
import subprocess
from pathlib import Path

import pytest

from cli_helpers import run, refused, verilog

ROOT = Path(__file__).resolve().parents[1]
ICARUS = shutil.which("iverilog") and shutil.which("vvp")
needs_icarus = pytest.mark.skipif(not ICARUS, reason="Icarus Verilog (iverilog, vvp) is not installed")








# ------------------------------------------------------------------ a design path is only that path

def test_montecarlo_on_a_missing_path_never_runs_the_shipped_design(tmp_path, capsys, monkeypatch):
    """`montecarlo DIR/adder2.v` with no such file used to run verilog/adder2.v instead."""
    monkeypatch.chdir(tmp_path)
    for missing in (tmp_path / "nowhere" / "adder2.v", "adder2.v"):
        refused(capsys, "montecarlo", missing, "--samples", "1", "--spread", "0", "--scheduler", "inline",
                needle=f"no such file: {missing}")
    for command in (["synth"], ["simulate", "--backend", "logic"], ["emit", "-o", tmp_path / "x.cir"]):
        refused(capsys, command[0], "adder2.v", *command[1:], needle="adder2.v: No such file")


# ------------------------------------------------------------------ the assembler's .tape

def test_tape_over_the_programs_own_code_is_refused(tmp_path, capsys):
    """A tape mapped over code used to assemble; the processor then fetched tape symbols and never halted."""
    source = (ROOT / "programs/tm_increment.asm").read_text()
    assert "        .equ MMR 255\n" in source
    over = tmp_path / "over.asm"
    over.write_text(source.replace(".equ MMR 255", ".equ MMR 3"))      # address 3: the loop's code
    line = 1 + source.splitlines().index("        .tape MMR 0 21222")
    err = refused(capsys, "cpu", "run", over, "--backend", "logic", "--max-cycles", "2000",
                  needle=f"{over}: line {line}: .tape at address 3 lies over the program")
    assert "line 11 puts a byte there" in err                           # LDNX_AB MMR: bytes 3, 4
    twice = tmp_path / "twice.asm"
    twice.write_text(source + "        .tape 254 0 1\n")
    refused(capsys, "cpu", "run", twice, "--backend", "logic", needle="a second .tape")
    rc, out, _ = run(capsys, "cpu", "run", ROOT / "programs/tm_increment.asm", "--backend", "logic")
    assert rc == 0 and "tape at 255" in out


# ------------------------------------------------------------------ Icarus Verilog, the reference

def icarus(tmp_path, src: str, top: str, inputs: dict, outputs: dict, vectors: list[dict],
           signed=()) -> list[dict]:
    """Icarus's value of every output for each input vector: None where any bit is x or z.
    `inputs`/`outputs`: port -> width; ports in `signed` are declared and read as signed."""
    decl = lambda kind, p, w: f"  {kind} {'signed ' * (p in signed)}[{w - 1}:0] {p};"   # noqa: E731
    steps = [" ".join(f"{p} = {v};" for p, v in vec.items()) + f' #1 $display("{" ".join(["%b"] * len(outputs))}", '
             f"{', '.join(outputs)});" for vec in vectors]
    tb = "\n".join(["module tb;", *(decl("reg", p, w) for p, w in inputs.items()),
                    *(decl("wire", p, w) for p, w in outputs.items()),
                    f"  {top} dut({', '.join(f'.{p}({p})' for p in [*inputs, *outputs])});",
                    "  initial begin", *(f"    {s}" for s in steps), "  end", "endmodule", ""])
    (tmp_path / "tb.v").write_text(tb)
    sim = tmp_path / "tb.vvp"
    subprocess.run(["iverilog", "-o", sim, src, tmp_path / "tb.v"], check=True, capture_output=True)
    lines = subprocess.run(["vvp", "-n", sim], check=True, capture_output=True, text=True).stdout.split("\n")
    return [{p: _value(b, p in signed) for p, b in zip(outputs, line.split())} for line in lines[:len(vectors)]]


def _value(bits: str, signed: bool):
    if set(bits) - {"0", "1"}:
        return None
    v = int(bits, 2)
    return v - (1 << len(bits)) if signed and bits[0] == "1" else v


def logic(capsys, src: str, vector: dict) -> dict:
    """`simulate --backend logic --json` of one input vector: its output ports."""
    sets = [x for p, v in vector.items() for x in ("--set", f"{p}={v}")]
    rc, out, err = run(capsys, "simulate", src, "--backend", "logic", "--json", *sets)
    assert rc == 0, err
    return json.loads(out)["outputs"]


# ------------------------------------------------------------------ multiple drivers

TWO_ASSIGNS = "module two(input a, input b, output y);\n  assign y = a;\n  assign y = b;\nendmodule\n"


def test_two_continuous_assignments_are_refused_where_icarus_reads_x(tmp_path, capsys):
    """Accepted before (Yosys kept one assignment); Icarus resolves the two drivers to x where they differ."""
    src = verilog(tmp_path, TWO_ASSIGNS)
    refused(capsys, "simulate", src, "--backend", "logic", "--set", "a=0", "--set", "b=1",
            needle=f"{src}, line 3: 'y' has more than one driver (lines 2, 3)")
    if ICARUS:
        got = icarus(tmp_path, src, "two", {"a": 1, "b": 1}, {"y": 1},
                     [{"a": 0, "b": 1}, {"a": 1, "b": 0}, {"a": 1, "b": 1}, {"a": 0, "b": 0}])
        assert got == [{"y": None}, {"y": None}, {"y": 1}, {"y": 0}]


@pytest.mark.parametrize("body, needle", [
    ("  assign y = a;\n  assign y = b;\n", "line 3: 'y' has more than one driver (lines 2, 3)"),
    # proc's opt_expr used to fold the NOT away, leaving w = a
    ("  wire w;\n  assign w = a;\n  assign w = ~a;\n  assign y = w;\n",
     "line 4: 'w' has more than one driver (lines 3, 4)"),
    ("  assign y = 1'b0;\n  assign y = 1'b1;\n", "line 3: 'y' has more than one driver (lines 2, 3)"),
    ("  assign y = a;\n  assign y = 1'b0;\n", "line 3: 'y' has more than one driver (lines 2, 3)"),
])
def test_two_drivers_of_one_net_are_refused_with_their_lines(tmp_path, capsys, body, needle):
    src = verilog(tmp_path, f"module two(input a, input b, output y);\n{body}endmodule\n")
    refused(capsys, "synth", src, needle=f"{src}, {needle}")


GENERATE_AND_ESCAPED = """module coll(input clk, input a, input b, output y, output z);
  generate
    if (1) begin : x
      reg y;
      always @(posedge clk) y <= a;
    end
  endgenerate
  reg \\x.y ;
  always @(posedge clk) \\x.y <= b;
  assign y = x.y;
  assign z = \\x.y ;
endmodule
"""


def test_an_escaped_name_equal_to_a_generate_members_is_refused_as_that(tmp_path, capsys):
    """Public RTL pass 9: two registers to Icarus, one net with two drivers once Yosys names both `x.y`; the
    refusal used to say the source drove one net twice."""
    src = verilog(tmp_path, GENERATE_AND_ESCAPED)
    refused(capsys, "synth", src, needle=f"{src}, line 8: the escaped identifier '\\x.y ' has the name Yosys gives "
                                         "'y' of generate block 'x' (line 3)")
    apart = verilog(tmp_path, GENERATE_AND_ESCAPED.replace("\\x.y ", "\\x_y "), name="apart.v")
    assert run(capsys, "synth", apart, "--json")[0] == 0      # the generate member alone is an ordinary register


def test_two_registers_and_an_instance_beside_an_assign_are_refused(tmp_path, capsys):
    src = verilog(tmp_path, "module t(input clk, input a, input b, output reg [1:0] y);\n"
                            "  always @(posedge clk) y[0] <= a;\n  always @(posedge clk) y[0] <= b;\n"
                            "  always @(posedge clk) y[1] <= a;\nendmodule\n")
    refused(capsys, "synth", src, needle=f"{src}, line 3: 'y[0]' has more than one driver (lines 2, 3)")
    src = verilog(tmp_path, "module inv(input a, output y);\n  assign y = ~a;\nendmodule\n"
                            "module t(input a, input b, output y);\n  inv u(.a(a), .y(y));\n"
                            "  assign y = b;\nendmodule\n")
    refused(capsys, "synth", src, needle=f"{src}, line 6: 'y' has more than one driver (lines 5, 6)")


def test_disjoint_bits_and_the_same_driver_twice_are_one_driver(tmp_path, capsys):
    """Two assignments to different bits, or of one input to one net twice, are accepted (Icarus agrees)."""
    src = verilog(tmp_path, "module t(input a, input b, input [0:3] c, output [1:0] y, output z, output [0:3] w);\n"
                            "  assign y[0] = a;\n  assign y[1] = b;\n  assign z = a;\n  assign z = a;\n"
                            "  assign w[0:1] = c[2:3];\n  assign w[2:3] = c[0:1];\nendmodule\n")
    assert logic(capsys, src, {"a": 1, "b": 0, "c": 0b0110}) == {"y": 1, "z": 1, "w": 0b1001}


# ------------------------------------------------------------------ which module is the top

TWO_MODULES = ("module foo(input a, output y);\n  assign y = ~a;\nendmodule\n"
               "module bar(input a, input b, output y);\n  assign y = a & b;\nendmodule\n")


def test_two_unrelated_modules_without_top_are_refused(tmp_path, capsys):
    src = verilog(tmp_path, TWO_MODULES)
    refused(capsys, "synth", src, needle=f"{src}: several top-level modules: foo (line 1), bar (line 4); "
                                         "choose one with --top")
    for top, inputs in (("foo", {"a": 1}), ("bar", {"a": 1, "b": 1})):
        rc, out, _ = run(capsys, "synth", src, "--top", top, "--json")
        assert rc == 0 and json.loads(out)["top"] == top and json.loads(out)["inputs"] == inputs
    marked = verilog(tmp_path, TWO_MODULES.replace("module bar", "(* top *) module bar"), "marked.v")
    rc, out, _ = run(capsys, "synth", marked, "--json")
    assert rc == 0 and json.loads(out)["top"] == "bar"          # chosen in the source
    # both marked: Yosys took the first without a word (public RTL pass 9)
    both = verilog(tmp_path, TWO_MODULES.replace("module foo", "(* top *) module foo")
                   .replace("module bar", "(* top *) module bar"), "both.v")
    refused(capsys, "synth", both, needle=f"{both}: several modules are marked (* top *): foo (line 1), bar "
                                          "(line 4); choose one with --top")
    rc, out, _ = run(capsys, "synth", both, "--top", "foo", "--json")
    assert rc == 0 and json.loads(out)["top"] == "foo"


def test_one_top_with_submodules_needs_no_top(tmp_path, capsys):
    src = verilog(tmp_path, "module inv(input a, output y);\n  assign y = ~a;\nendmodule\n"
                            "module pair(input [1:0] a, output [1:0] y);\n"
                            "  inv u0(.a(a[0]), .y(y[0]));\n  inv u1(.a(a[1]), .y(y[1]));\nendmodule\n")
    assert logic(capsys, src, {"a": 2}) == {"y": 1}


def test_an_interface_beside_the_module_is_no_top_candidate(tmp_path, capsys):
    """Public RTL pass 10: a SystemVerilog `interface` in the file was listed as a second top-level module."""
    src = verilog(tmp_path, "module m(input logic clk, input logic d, output logic q);\n"
                            "  always_ff @(posedge clk) q <= d;\nendmodule\n\n"
                            "interface bus_if(input logic clk);\n  logic valid;\nendinterface\n", "m.sv")
    rc, out, err = run(capsys, "synth", src, "--json")
    assert rc == 0 and json.loads(out)["top"] == "m", err


@pytest.mark.parametrize("design", sorted(p.name for p in (ROOT / "verilog").glob("*.v")))
def test_every_shipped_design_synthesises_as_before(capsys, design):
    """The new checks refuse none of verilog/ (the three refused here were refused before, for their own reason;
    async_reset.v synthesises since issue 34)."""
    rc, out, err = run(capsys, "synth", ROOT / "verilog" / design, "--json")
    expected = {"bad_syntax.v": "syntax error",
                "inferred_latch.v": "level-sensitive latch", "loop.v": "combinational loop"}
    if design in expected:
        assert rc == 2 and expected[design] in err, err
    else:
        assert rc == 0, err


# ------------------------------------------------------------------ non-edge always blocks

def test_an_always_block_on_a_clock_without_an_edge_is_refused(tmp_path, capsys):
    """`always @(clk) q <= d` is a register to a simulator (q changes only when clk does) and a wire to Yosys."""
    src = verilog(tmp_path, "module t(input clk, input d, output reg q);\n  always @(clk)\n    q <= d;\nendmodule\n")
    refused(capsys, "synth", src, needle=f"{src}, line 2: this always block reads 'd' but its sensitivity list "
                                         "leaves it out")
    if ICARUS:     # d rises while clk holds still: Icarus keeps q at 0, the wire Yosys builds would follow d
        got = icarus(tmp_path, src, "t", {"clk": 1, "d": 1}, {"q": 1},
                     [{"clk": 0, "d": 0}, {"clk": 1, "d": 0}, {"d": 1}, {"clk": 0}])
        assert got == [{"q": 0}, {"q": 0}, {"q": 0}, {"q": 1}]


def test_a_level_sensitive_latch_and_a_bare_always_are_refused_with_their_lines(tmp_path, capsys):
    src = verilog(tmp_path, "module t(input clk, input d, output reg q);\n"
                            "  always @(clk or d)\n    if (clk) q <= d;\nendmodule\n")
    refused(capsys, "synth", src, needle=f"{src}, line 2: module t: Yosys inferred a level-sensitive latch")
    src = verilog(tmp_path, "module t(input a, output reg q);\n  always q = a;\nendmodule\n")
    refused(capsys, "synth", src, needle=f"{src}, line 2: an always block without an event control")
    src = verilog(tmp_path, "module t(input a, output reg q);\n  always @* q = a;\nendmodule\n", "star.sv")
    assert logic(capsys, src, {"a": 1}) == {"q": 1}


COMPLETE_LIST = """module t(input clk, input [3:0] a, input [3:0] b, input [1:0] s, output reg [4:0] y, output reg g);
  always @(a or b or s)
    case (s)
      2'd0: y = a & b;
      2'd1: y = a | b;
      2'd2: y = a ^ b;
      default: y = a + b;
    endcase
  always @(clk or a) g = clk & a[0];   // a level-sensitive read of clk: combinational, both agree
endmodule
"""


@needs_icarus
def test_a_complete_sensitivity_list_is_combinational_and_matches_icarus(tmp_path, capsys):
    import random
    rng = random.Random(26)
    src = verilog(tmp_path, COMPLETE_LIST)
    widths = {"clk": 1, "a": 4, "b": 4, "s": 2}
    vectors = [{p: rng.randrange(1 << w) for p, w in widths.items()} for _ in range(200)]
    expected = icarus(tmp_path, src, "t", widths, {"y": 5, "g": 1}, vectors)
    assert [logic(capsys, src, v) for v in vectors] == expected


# `assign as = a;` names a listed signal again: Icarus updates it before the block reads it (the first block
# below); through any operator (`b ^ 1`, a concatenation of slices) it is a process of its own, and Icarus
# runs the block first and reads the old value (the second).
ALIASED_LIST = """module al(input [3:0] a, input [3:0] b, input [1:0] op, output reg [4:0] r);
  always @(a or b or op)
    case (op)
      2'd0: r <= as + bs;
      2'd1: r <= as2 - bs;
      2'd2: r <= {4'b0, as < bs};
      default: r <= bs >>> a[1:0];
    endcase
  wire signed [3:0] as, bs, as2;
  assign as = a;
  assign bs = b;
  assign as2 = as;
endmodule
"""


@needs_icarus
def test_a_block_reading_another_name_of_a_listed_signal_is_accepted_and_matches_icarus(tmp_path, capsys):
    import random
    rng = random.Random(38)
    src = verilog(tmp_path, ALIASED_LIST)
    widths = {"a": 4, "b": 4, "op": 2}
    vectors = [{p: rng.randrange(1 << w) for p, w in widths.items()} for _ in range(200)]
    expected = icarus(tmp_path, src, "al", widths, {"r": 5}, vectors)
    assert [logic(capsys, src, v) for v in vectors] == expected
    rc, _, err = run(capsys, "synth", src)
    assert rc == 0 and f"{src}, line 2: this always block reads 'as' (another name of 'a'), 'as2' (another " \
        "name of 'a'), 'bs' (another name of 'b') without listing them" in err, err
    computed = verilog(tmp_path, ALIASED_LIST.replace("assign bs = b;", "assign bs = b ^ 4'd1;"), "computed.v")
    refused(capsys, "synth", computed, needle=f"{computed}, line 2: this always block reads 'bs' but its "
                                              "sensitivity list leaves it out")
    by_icarus = icarus(tmp_path, computed, "al", widths, {"r": 5}, vectors)
    at_once = [{"r": (((a if a < 8 else a - 16) + ((b ^ 1) if b ^ 1 < 8 else (b ^ 1) - 16)) & 31)}
               for a, b in ((v["a"], v["b"]) for v in vectors if v["op"] == 0)]
    assert [e for e, v in zip(by_icarus, vectors) if v["op"] == 0] != at_once     # Icarus read the old bs



# ------------------------------------------------------------------ signed ports

SIGNED = """module sg(input signed [3:0] a, input signed [3:0] b, input [3:0] u,
          output signed [4:0] sum, output signed [7:0] prod, output lt, output signed [3:0] sra,
          output signed [4:0] mixed, output [3:0] raw);
  assign sum = a + b;
  assign prod = a * b;
  assign lt = a < b;                  // a signed comparison
  assign sra = a >>> 1;
  assign mixed = $signed(u) - b;      // an unsigned port read as signed inside
  assign raw = a;                     // a signed value on an unsigned port: its bit pattern
endmodule
"""
SIGNED_IN, SIGNED_OUT = {"a": 4, "b": 4, "u": 4}, {"sum": 5, "prod": 8, "lt": 1, "sra": 4, "mixed": 5, "raw": 4}


@needs_icarus
def test_signed_ports_are_read_and_printed_as_icarus_does(tmp_path, capsys):
    import random
    rng = random.Random(2026)
    src = verilog(tmp_path, SIGNED)
    vectors = [{"a": rng.randrange(-8, 8), "b": rng.randrange(-8, 8), "u": rng.randrange(16)} for _ in range(200)]
    expected = icarus(tmp_path, src, "sg", SIGNED_IN, SIGNED_OUT, vectors, signed={"a", "b", "sum", "prod", "sra",
                                                                                     "mixed"})
    assert any(e["sum"] < 0 for e in expected) and any(e["raw"] > 7 for e in expected)
    assert [logic(capsys, src, v) for v in vectors] == expected


def test_signed_ports_take_the_twos_complement_range(tmp_path, capsys):
    from mech2spice.experiments import montecarlo as mc
    from mech2spice.synthesis.synth import synthesize
    src = verilog(tmp_path, SIGNED)
    rc, out, _ = run(capsys, "synth", src, "--json")
    assert rc == 0 and json.loads(out)["signed"] == ["a", "b", "sum", "prod", "sra", "mixed"]
    assert logic(capsys, src, {"a": -8, "b": -1, "u": 15}) == {"sum": -9, "prod": 8, "lt": 1, "sra": -4,
                                                               "mixed": 0, "raw": 8}
    refused(capsys, "simulate", src, "--backend", "logic", "--set", "a=8",
            needle="value 8 does not fit input 'a' (4 bits, signed, -8..7)")
    refused(capsys, "simulate", src, "--backend", "logic", "--set", "u=-1",
            needle="value -1 does not fit input 'u' (4 bits, 0..15)")
    vectors = mc.all_vectors(synthesize(verilog(tmp_path, "module t(input signed [1:0] a, input b, output y);\n"
                                                          "  assign y = a[0] ^ b;\nendmodule\n", "t.v")))
    assert sorted({v["a"] for v in vectors}) == [-2, -1, 0, 1] and len(vectors) == 8


# ------------------------------------------------------------------ case equality against x or z

@needs_icarus
def test_case_equality_against_x_or_z_is_refused_and_against_a_defined_value_agrees(tmp_path, capsys):
    """`a === 2'bx1` gave e = 1 for a = 1 with exit 0 (Icarus: 0): Yosys reads the x bits as don't-cares
    (second hostile-input pass, session 21). A net never holds x or z, so the question has no mechanical
    meaning; `===` against a defined value is `==` and stays."""
    for op, const in (("===", "2'bx1"), ("!==", "2'b1z")):
        src = verilog(tmp_path, f"module q(input [1:0] a, output e);\n  assign e = (a {op} {const});\nendmodule\n")
        refused(capsys, "synth", src, needle=f"{src}, line 2: `{op}` against a value with x or z bits")
    src = verilog(tmp_path, "module q(input [1:0] a, output e, output n);\n  assign e = (a === 2'b01);\n"
                            "  assign n = (a !== 2'b10);\nendmodule\n")
    vectors = [{"a": a} for a in range(4)]
    want = icarus(tmp_path, src, "q", {"a": 2}, {"e": 1, "n": 1}, vectors)
    assert [logic(capsys, src, v) for v in vectors] == want


# ------------------------------------------------------------------ real numbers in logic

@needs_icarus
def test_a_real_number_in_logic_is_refused_and_an_integral_one_agrees(tmp_path, capsys):
    """`a * 1.5` was refused with a Yosys internal error, and Yosys reads 1.5 as 2 where it builds the cell
    (second hostile-input pass, session 21); 4.0 is 4 to both readers."""
    src = verilog(tmp_path, "module r(input [3:0] a, output [5:0] y);\n  assign y = a * 1.5;\nendmodule\n")
    refused(capsys, "synth", src, needle=f"{src}, line 2: the real number 1.5 in logic: Yosys rounds it to 2")
    src = verilog(tmp_path, "module r(input [3:0] a, output [7:0] y);\n  localparam integer W = 4.0;\n"
                            "  assign y = a << W;\nendmodule\n")
    vectors = [{"a": a} for a in (0, 3, 15)]
    assert [logic(capsys, src, v) for v in vectors] == icarus(tmp_path, src, "r", {"a": 4}, {"y": 8}, vectors)


@needs_icarus
@pytest.mark.parametrize("real", ["2.0", "2.5", "-2.5", "2.5 * 3"])
def test_a_real_given_to_a_sized_parameter_is_the_languages_conversion(tmp_path, capsys, real):
    """`localparam [7:0] P = 2.0` was refused as "Yosys rounds it to 8" (the warning's width, `8'00000010`,
    read as the value; a public-RTL pass): a sized parameter converts the real itself, rounding, on every
    reader.  The network equals Icarus."""
    src = verilog(tmp_path, f"module r(input [3:0] a, output [7:0] y);\n  localparam [7:0] P = {real};\n"
                            "  assign y = a + P;\nendmodule\n")
    vectors = [{"a": a} for a in (0, 3, 15)]
    assert [logic(capsys, src, v) for v in vectors] == icarus(tmp_path, src, "r", {"a": 4}, {"y": 8}, vectors)


def test_an_escaped_top_given_with_its_backslash_is_told_how_to_give_it(tmp_path, capsys):
    """`--top '\\my.top'` as the source writes it was "not found" and nothing more (public RTL pass 9)."""
    src = verilog(tmp_path, "module \\my.top (input a, input b, output y);\n  assign y = a & ~b;\nendmodule\n")
    refused(capsys, "synth", src, "--top", "\\my.top",
            needle="an escaped name is given without its backslash and trailing space (--top my.top)")
    rc, out, _ = run(capsys, "synth", src, "--top", "my.top", "--json")
    assert rc == 0 and json.loads(out)["top"] == "my.top"
