"""What the front end reads (docs/rtl.md): the VIS dialect rewritten into SystemVerilog with its lines kept,
VIS's `$ND` refused, and $display/$write in always blocks left out with a warning.  Each accepted design is
co-simulated against Icarus Verilog reading the same rewritten text, with random stimulus; the VIS
translations of ITC'99 in the public RTL suite are used when MECH2SPICE_BENCHMARKS holds rtl/."""
import os
import shutil
from pathlib import Path

import pytest

from mech2spice import verify
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
        assert f"{path}, line {line}: $display/$write left out" in err
    assert err.count("\n") == 3
    res = verify.verify(path, equivalence_check=False, vectors=300)
    assert res["cosim"]["agree"] and nl.outputs == {"q": 1, "y": 1}


@pytest.mark.parametrize("body, match", [
    ("  always @(posedge clk) begin q <= a; $finish; end", r"line 2: .*\$finish"),
    ("  initial begin q = 0; $display(\"x\"); end\n  always @(posedge clk) q <= a;", r"line 2: a system task"),
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
