"""What the front end reads (docs/rtl.md): the VIS dialect rewritten into SystemVerilog with its lines kept,
VIS's `$ND` refused, and $display/$write in always blocks left out with a warning.  Each accepted design is
co-simulated against Icarus Verilog reading the same rewritten text, with random stimulus; the VIS
translations of ITC'99 in the public RTL suite are used when MECH2SPICE_BENCHMARKS holds rtl/."""
import json
import os
import shutil
from pathlib import Path

import pytest

from mech2spice import cli, verify
from mech2spice.errors import Mech2SpiceError
from mech2spice.synthesis import dialect
from mech2spice.synthesis.synth import synthesize

ICARUS = shutil.which("iverilog") and shutil.which("vvp")
needs_icarus = pytest.mark.skipif(not ICARUS, reason="Icarus Verilog (iverilog, vvp) is not installed")
SUITE = Path(os.environ.get("MECH2SPICE_BENCHMARKS", "/nonexistent")) / "rtl"
needs_suite = pytest.mark.skipif(not (SUITE / "manifest.json").is_file(),
                                 reason="MECH2SPICE_BENCHMARKS/rtl (the public RTL suite) not present")

# The VIS constructs in one file: a file-level enum, an enum register, enum labels in a case, an `initial`
# power-up value, blocking assignments in a clocked block, and a block label followed by a stray `;`.
VIS = """// a VIS-style machine
typedef enum {IDLE, RUN, DONE} State;

module vis(clock, go, d, q, busy);
    input clock, go;
    input [1:0] d;
    output [2:0] q;
    output busy;
    reg [2:0] q;
    State reg st;
    initial begin
        st = IDLE;
        q = 0;
    end
    assign busy = (st == RUN);
    always @ (posedge clock) begin: step;
        case (st)
          IDLE: if (go) st = RUN;
          RUN: begin q = q + d; if (q > 5) st = DONE; end
          DONE: begin q = 0; st = IDLE; end
        endcase
    end
endmodule
"""


def _file(tmp_path, text: str, name: str = "vis.sv") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_the_vis_declaration_is_rewritten_in_place_and_lines_are_kept():
    out = dialect.standard_text("vis.sv", VIS)
    assert out.count("\n") == VIS.count("\n")
    assert "typedef enum logic [1:0] {IDLE, RUN, DONE} State;" in out        # 3 values: 2 bits, 4-state
    assert "    State     st;\n" in out                                       # `reg` blanked, columns kept
    assert [a for a, b in zip(VIS.splitlines(), out.splitlines()) if a != b] == \
        ["typedef enum {IDLE, RUN, DONE} State;", "    State reg st;"]
    assert dialect.is_vis(VIS)


@pytest.mark.parametrize("text", [
    "typedef enum {A, B} S;\nmodule m(input a, output y); S s; assign y = a; endmodule\n",   # standard SV
    "module m(input a, output y); reg r; assign y = a; endmodule\n",
    "// State reg st;\ntypedef enum {A, B} State;\nmodule m(input a, output y); assign y = a; endmodule\n",
])
def test_standard_files_are_never_rewritten(text):
    assert dialect.standard_text("m.sv", text) == text
    assert not dialect.is_vis(text)


@needs_icarus
def test_a_vis_file_synthesises_and_agrees_with_icarus_reading_the_same_text(tmp_path):
    path = _file(tmp_path, VIS)
    nl = synthesize(path)
    assert nl.clock == "clock" and len(nl.latches()) >= 5
    with dialect.standard_source(path) as src:
        assert src != path and src.name == path.name
        co = verify.cosim(src, nl, "logic", 400, False, seed=3, resets=[])
    assert co["agree"], co["mismatches"][:3]
    assert co["undefined_bits"] == 0                  # every register has a power-up value


@needs_icarus
def test_an_uninitialised_enum_register_reads_x_on_icarus_not_int_zero(tmp_path):
    text = VIS.replace("        st = IDLE;\n", "\n")
    path = _file(tmp_path, text)
    nl = synthesize(path)
    with dialect.standard_source(path) as src:
        co = verify.cosim(src, nl, "logic", 20, False, seed=1, resets=[])
    assert co["undefined_by_port"]["busy"]["x"] > 0   # logic [1:0] is 4-state: x until assigned


def test_a_syntax_error_in_a_vis_file_names_the_line_of_the_file_as_written(tmp_path):
    lines = VIS.splitlines()
    lines[16] = "        case (st"                          # line 17: a missing parenthesis
    path = _file(tmp_path, "\n".join(lines) + "\n")
    with pytest.raises(Mech2SpiceError, match=rf"{path}, line 1[78]: "):
        synthesize(path)


def test_nd_is_refused_with_its_line_and_reason(tmp_path):
    path = _file(tmp_path, VIS.replace("if (go) st = RUN;", "st = $ND(IDLE, RUN);"))
    with pytest.raises(Mech2SpiceError, match=r"line 18: \$ND \(VIS's nondeterministic choice\).*input port"):
        synthesize(path)


DISPLAY = """module t(input clk, input a, input b, output reg q, output y);
  assign y = a ^ b;
  always @(posedge clk) begin
    q <= a & ~q;
    if (a) $display("a at %t", $time);
    $write("%b", b);
  end
  always @* if (b) $display("b");
endmodule
"""


@needs_icarus
def test_display_in_always_blocks_is_left_out_with_a_warning_per_line(tmp_path, capsys):
    path = _file(tmp_path, DISPLAY, "t.v")
    nl = synthesize(path)
    err = capsys.readouterr().err
    for line in (5, 6, 8):
        assert f"{path}, line {line}: a print ($display, $write" in err
    assert err.count("\n") == 3
    res = verify.verify(path, equivalence_check=False, vectors=300)
    assert res["cosim"]["agree"] and nl.outputs == {"q": 1, "y": 1}


SEVERITY = """module t(input clk, input rst, input rd, output reg [1:0] cnt);
  always @(posedge clk) begin
    if (rst) cnt <= 0; else if (rd) cnt <= cnt - 1;
    if (rd && cnt == 0) $error("Reading an empty FIFO");   // nandland's FIFO check
    if (cnt == 2'd3) $warning;
  end
  always @* if (cnt == 2'd2) $info("two");
  initial begin : never_built
    if (0) $error("elaboration check, left to Yosys");
  end
endmodule
"""


@needs_icarus
def test_severity_tasks_in_always_blocks_only_print_and_are_left_out(tmp_path, capsys):
    """`$error`/`$warning`/`$info` in an always block print and carry on (IEEE 1800 20.10, Icarus): they were
    refused as being "in an `initial` block", which the file did not have."""
    path = _file(tmp_path, SEVERITY, "t.sv")
    nl = synthesize(path)
    err = capsys.readouterr().err
    assert [f"line {n}: a print" in err for n in (4, 5, 7)] == [True] * 3 and err.count("\n") == 3
    res = verify.verify(path, vectors=300)
    assert res["verdict"] == "pass" and nl.latches()


# Public RTL pass 10: formats Yosys does not read, and a real argument it rounds (refused as a real in logic)
PRINTS = """module p #(parameter CLK_FREQ = 50000000) (input clk, input a, output reg q);
  initial $display("clock period = %.0f ns",
                   1000000000.0 / CLK_FREQ);
  always @(posedge clk) begin
    q <= a;
    $display("t=%0t a=%b x=%f (%s)", $time, a, 1.5, "a ) in a string");
    $write("%e %g %v\\n", 2.5, 0.25, a);
  end
endmodule
"""


@needs_icarus
def test_prints_with_formats_yosys_cannot_read_are_left_out(tmp_path, capsys):
    path = _file(tmp_path, PRINTS, "p.v")
    text = dialect.standard_text(Path(path), PRINTS)
    assert text.count("\n") == PRINTS.count("\n") and "%" not in text and "$display;" in text and "$write;" in text
    nl = synthesize(path)
    err = capsys.readouterr().err
    assert [f"line {n}: a print" in err for n in (2, 6, 7)] == [True] * 3, err
    res = verify.verify(path, vectors=200)
    assert res["verdict"] == "pass" and nl.outputs == {"q": 1}


@pytest.mark.parametrize("body, match", [
    ("  always @(posedge clk) begin q <= a; $finish; end", r"line 2: a system task \(`\$finish`\) in an `always` "
                                                           r"block: it stops the simulation"),
    ("  always @(posedge clk) begin q <= a;\n if (a) $fatal(1, \"bad\"); end", r"line 3: .*`\$fatal`\) in an `always`"),
    ("  initial begin q = 0; $monitor(\"x\"); end\n  always @(posedge clk) q <= a;", r"line 2: a system task"),
])
def test_finish_and_initial_block_tasks_are_still_refused(tmp_path, body, match):
    path = _file(tmp_path, f"module t(input clk, input a, output reg q);\n{body}\nendmodule\n", "t.v")
    with pytest.raises(Mech2SpiceError, match=match):
        synthesize(path)


VIS_DESIGNS = ["b02", "b03", "b04", "b05", "b07", "b08", "b09", "b12", "b13"]


@needs_suite
@pytest.mark.parametrize("name", VIS_DESIGNS)
def test_the_itc99_vis_translations_synthesise(name):
    nl = synthesize(SUITE / f"itc99_{name}_vis" / f"itc99_{name}_vis.sv")
    assert nl.clock.lower() == "clock" and nl.latches()


@needs_suite
@needs_icarus
@pytest.mark.parametrize("name", ["b02", "b08"])
def test_small_vis_translations_agree_with_icarus(name):
    path = SUITE / f"itc99_{name}_vis" / f"itc99_{name}_vis.sv"
    nl = synthesize(path)
    with dialect.standard_source(path) as src:
        co = verify.cosim(src, nl, "logic", 500, False, seed=0, resets=[])
    assert co["agree"], co["mismatches"][:3]


# ------------------------------------------------------------------ memories: out-of-range writes

# 12 words at a 5-bit address: 20 of 32 addresses are out of range, and Yosys's decoding of the low 4 bits
# would send e.g. a write to 17 into word 1.  MEM2REG: the asynchronous reset makes Yosys's front end turn the
# words into registers (mem2reg); PLAIN keeps a `$mem` cell.  Reads in range only, so every bit is defined.
PLAIN = """module mem(input clk, input we, input [4:0] wa, input [3:0] d, input [3:0] ra, output [3:0] q);
  reg [3:0] m [0:11];
  integer i;
  initial for (i = 0; i < 12; i = i + 1) m[i] = i;
  always @(posedge clk) if (we) m[wa] <= d;
  assign q = m[ra < 12 ? ra : 4'd0];
endmodule
"""
MEM2REG = """module mem(input clk, input rst_n, input we, input [4:0] wa, input [3:0] d, input [3:0] ra,
           output reg [3:0] q);
  reg [3:0] m [11:0];
  integer i;
  always @(posedge clk or negedge rst_n)
    if (!rst_n) begin
      for (i = 0; i < 12; i = i + 1) m[i] <= 0;
    end else if (we)
      m[wa] <= d;
  always @(posedge clk) q <= m[ra < 12 ? ra : 4'd0];
endmodule
"""


def test_memory_writes_are_guarded_on_their_own_line_and_initial_writes_are_not():
    from mech2spice.synthesis.memory_guard import guarded
    out = guarded(PLAIN)
    assert out.count("\n") == PLAIN.count("\n")
    assert "if (we) begin if ((wa) >= 0 && (wa) <= 11) m[wa] <= d; end" in out
    assert "m[i] = i;" in out and "if ((i)" not in out                    # `initial`: power-up values
    assert guarded(MEM2REG).count("begin if (") == 2                     # the reset loop and the write
    assert "begin if ((i) >= 0 && (i) <= 11) m[i] <= 0; end" in guarded(MEM2REG)
    no_memory = "module t(input a, output y); reg [3:0] r; assign y = a; endmodule\n"
    assert guarded(no_memory) == no_memory
    vector = ("module t(input clk, input [1:0] i, input b, output reg [7:0] v);\n  reg [3:0] x = v[3:0], m [0:1];\n"
              "  always @(posedge clk) begin v[i] <= b; m[i] <= v[3:0]; end\nendmodule\n")
    assert guarded(vector).count("begin if (") == 1 and "if ((i) >= 0 && (i) <= 1) m[i]" in guarded(vector)


# Public RTL pass 10: two modules, each with its own memory `mem` (16 and 4 words), and a module whose vector
# `v` shares its name with another module's memory.  The guard took every memory's bounds file-wide: the top's
# writes above word 3 were dropped (the 4-word memory's bounds), in the text Icarus read too (a false pass), and
# `v[3:0] = a` became a guard around a range (a syntax error).
TWO_MEMORIES = """module top(input clk, input we, input [3:0] wa, input [3:0] ra, input [7:0] d, output [7:0] q,
           output [7:0] q2);
  reg [7:0] mem [0:15];
  always @(posedge clk) if (we) mem[wa] <= d;
  assign q = mem[ra];
  little s(.clk(clk), .we(we), .wa(wa[1:0]), .ra(ra[1:0]), .d(d), .q(q2));
endmodule

module little(input clk, input we, input [1:0] wa, input [1:0] ra, input [7:0] d, output [7:0] q);
  reg [7:0] mem [0:3];
  reg [7:0] v;
  always @(posedge clk) if (we) mem[wa] <= d;
  always @(*) begin v = 8'h00; v[3:0] = ra; end
  assign q = mem[ra] ^ v;
endmodule
"""


def test_each_module_guards_its_own_memories(tmp_path):
    from mech2spice.backends.logic import ClockedLogic
    from mech2spice.synthesis.memory_guard import guarded
    out = guarded(TWO_MEMORIES)
    assert "begin if ((wa) >= 0 && (wa) <= 15) mem[wa] <= d; end" in out.split("module little")[0]
    assert "begin if ((wa) >= 0 && (wa) <= 3) mem[wa] <= d; end" in out.split("module little")[1]
    assert "v[3:0] = ra;" in out and out.count("begin if (") == 2
    sel = "module t(input clk, input s, input [1:0] a, input [1:0] b, input d);\n  reg m [0:3];\n" \
          "  always @(posedge clk) m[s ? a : b] <= d;\nendmodule\n"
    assert "begin if ((s ? a : b) >= 0 && (s ? a : b) <= 3)" in guarded(sel)        # a ternary is an index
    nl = synthesize(_file(tmp_path, TWO_MEMORIES, "two.v"))
    logic = ClockedLogic(nl)
    logic.tick({"we": 1, "wa": 9, "ra": 0, "d": 0xAB})                 # word 9 of the 16-word memory
    assert logic.evaluate({"we": 0, "wa": 0, "ra": 9, "d": 0})["q"] == 0xAB


@needs_icarus
@pytest.mark.parametrize("text", [PLAIN, MEM2REG], ids=["mem", "mem2reg"])
def test_an_out_of_range_write_changes_no_word_as_on_icarus(tmp_path, text, monkeypatch):
    path = _file(tmp_path, text, "mem.v")
    nl = synthesize(path)
    reset = [{"port": "rst_n", "level": 0}] if "rst_n" in nl.inputs else []
    co = verify.cosim(path, nl, "logic", 600, False, seed=5, resets=reset)
    assert co["agree"] and co["undefined_bits"] == 0, co["mismatches"][:3]
    # The guard is what makes it agree: Yosys's own reading writes word (address mod 16).
    from mech2spice.synthesis import memory_guard
    monkeypatch.setattr(memory_guard, "guarded", lambda t: t)
    bare = synthesize(path)                   # the cache key is the text read: this one runs Yosys again
    assert not verify.cosim(path, bare, "logic", 600, False, seed=5, resets=reset)["agree"]


@needs_suite
@needs_icarus
def test_rtllm_ram_agrees_with_icarus(tmp_path):
    path = SUITE / "rtllm_ram" / "rtllm_ram.v"
    nl = synthesize(path)
    co = verify.cosim(path, nl, "logic", 1000, False, seed=0, resets=[{"port": "rst_n", "level": 0}])
    assert co["agree"], co["mismatches"][:3]


@needs_icarus
def test_a_rewritten_file_still_finds_its_includes(tmp_path):
    (tmp_path / "width.vh").write_text("`define W 4\n")
    text = PLAIN.replace("module mem(", "`include \"width.vh\"\nmodule mem(").replace("[3:0] d", "[`W-1:0] d")
    path = _file(tmp_path, text, "mem.v")
    nl = synthesize(path)
    assert nl.inputs["d"] == 4
    with dialect.standard_source(path) as src:
        assert src != path
        co = verify.cosim(src, nl, "logic", 200, False, seed=2, resets=[])
    assert co["agree"], co["mismatches"][:3]


@needs_icarus
def test_a_design_that_prints_rows_of_bits_is_co_simulated_on_its_results_only(tmp_path, capsys):
    """The source's own `$display` (left out of the network, kept on Icarus) prints lines that look like the
    testbench's result rows; only the testbench's tagged lines are read, so verify passes and agrees."""
    src = tmp_path / "chatty.v"
    src.write_text("module chatty(input clk, input d, output reg q);\n"
                   "  always @(posedge clk) begin q <= d; $display(\"%b\", ~q); $display(\"1\"); end\n"
                   "endmodule\n")
    code = cli.main(["verify", str(src), "--cycles", "40", "--json"])
    res = json.loads(capsys.readouterr().out)
    assert code == 0 and res["cosim"]["agree"] and res["equivalence"]["status"] == "proved", res


def test_a_v_file_with_a_keywordless_parameter_list_is_read_as_systemverilog(tmp_path):
    """nandland's `module Count_And_Toggle #(COUNT_LIMIT = 10)`: Yosys refuses it in Verilog mode with its own
    message ("In pure Verilog (not SystemVerilog) ..."), not a syntax error, so the SystemVerilog retry never ran."""
    path = _file(tmp_path, "module m #(W = 3) (input [W-1:0] a, output y);\n  assign y = &a;\nendmodule\n", "m.v")
    nl = synthesize(path)
    assert nl.inputs == {"a": 3} and nl.systemverilog
