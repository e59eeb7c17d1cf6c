"""`mech2spice verify`: Yosys equivalence and Icarus co-simulation of the shipped designs, a broken
mapping caught, the JUnit/JSON output and the exit-code contract."""
from __future__ import annotations

import json
import re
import os
import shutil
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from mech2spice import cli, verify as V
from mech2spice.synthesis.synth import synthesize

ROOT = Path(__file__).resolve().parents[1]
VERILOG = ROOT / "verilog"
COMBINATIONAL = ["adder2", "comparator4", "mult2", "mux4", "parity8"]
CLOCKED = ["counter4", "dff", "fsm", "sqrt"]

pytestmark = pytest.mark.skipif(not (shutil.which("iverilog") and shutil.which("vvp")),
                                reason="Icarus Verilog (iverilog, vvp) not installed")


def _run(capsys, *argv) -> tuple[int, str, str]:
    code = cli.main(["verify", *map(str, argv)])
    out, err = capsys.readouterr()
    return code, out, err


def test_verify_proves_and_runs_the_buffered_network_simulate_runs(tmp_path, capsys):
    """verify built its network without `simulate`'s buffer trees: its proof and its physical sample were of a
    network no other command emits (a gate driving 17 loads; public RTL pass, session 26)."""
    src = tmp_path / "fan.v"
    src.write_text("module fan(input [15:0] d, input en, output [15:0] y);\n  assign y = d & {16{en}};\nendmodule\n")
    code, out, _ = _run(capsys, src, "--json", "--vectors", 200)
    res = json.loads(out)
    buffered = synthesize(src, max_fanout=12)
    assert code == 0 and res["equivalence"]["status"] == "proved"
    assert res["logic_gates"] == res["gates"] == len(buffered.gates()) > len(synthesize(src).gates())
    code, out, _ = _run(capsys, src, "--json", "--vectors", 200, "--max-fanout", 64)
    assert code == 0 and json.loads(out)["logic_gates"] == len(synthesize(src).gates())


@pytest.mark.parametrize("design", COMBINATIONAL + CLOCKED)
def test_shipped_design_proved_and_agrees_with_icarus(design, capsys):
    code, out, err = _run(capsys, VERILOG / f"{design}.v", "--json", "--cycles" if design in CLOCKED else
                          "--vectors", 300)
    res = json.loads(out)
    assert code == 0, out
    assert res["equivalence"]["status"] == "proved"
    assert res["cosim"]["agree"] and res["cosim"]["mismatches"] == []
    assert res["cosim"]["backend"] == "logic"
    if design in CLOCKED:
        assert res["cosim"]["cycles"] == 300
    assert res["verdict"] == "pass"


def _flip_gate_input(nl):
    """Rewire pin 0 of the middle gate to const1: a wrong mapping (the gate now always outputs 0)."""
    g = nl.graph
    gate = nl.gates()[len(nl.gates()) // 2]
    (src,) = [u for u, _, pin in g.in_edges(gate, data="pin") if pin == 0]
    g.remove_edge(src, gate)
    g.add_node("const1", kind="const")
    g.add_edge("const1", gate, pin=0)
    nl.__dict__.pop("_order_cache", None)
    return nl


def _swap_outputs(nl, a: str, b: str):
    g = nl.graph
    (sa,), (sb,) = g.predecessors(a), g.predecessors(b)
    g.remove_edges_from([(sa, a), (sb, b)])
    g.add_edges_from([(sb, a), (sa, b)])
    return nl


def test_broken_combinational_mapping_gives_the_counterexample():
    nl = _swap_outputs(synthesize(VERILOG / "mult2.v"), "p[0]", "p[1]")
    res = V.verify(VERILOG / "mult2.v", netlist=nl)
    eq = res["equivalence"]
    assert eq["status"] == "counterexample"
    (step,) = eq["counterexample"]
    a, b = step["inputs"]["a"], step["inputs"]["b"]
    product = format(a * b, "04b")
    assert step["source"]["p"] == product and step["network"]["p"] != product
    assert product[2] != product[3]            # the swapped bits differ on the counterexample
    assert res["cosim"]["mismatches"] and V.exit_code(res) == 1
    assert {m["bit"] for m in res["cosim"]["mismatches"]} == {"p[0]", "p[1]"}


def test_broken_clocked_mapping_gives_a_counterexample_sequence():
    nl = _flip_gate_input(synthesize(VERILOG / "counter4.v"))
    res = V.verify(VERILOG / "counter4.v", netlist=nl, vectors=200)
    eq = res["equivalence"]
    assert eq["status"] == "counterexample"
    assert [s["cycle"] for s in eq["counterexample"]] == list(range(len(eq["counterexample"])))
    assert not res["cosim"]["agree"] and res["verdict"] == "fail"
    rep = eq["replay"]                       # replayed before it is reported: the last cycle differs there
    assert rep["reproduced"] and rep["cycle"] == len(eq["counterexample"]) - 1 and rep["bits"]
    assert eq["counterexample"][-1]["source"] != eq["counterexample"][-1]["network"]


def _stuck_at_one(nl, out: str):
    """Drive output bit `out` from const1: a network that is right only where the source outputs 1."""
    g = nl.graph
    (src,) = g.predecessors(out)
    g.remove_edge(src, out)
    g.add_node("const1", kind="const")
    g.add_edge("const1", out)
    nl.__dict__.pop("_order_cache", None)
    return nl


def test_output_stuck_at_one_is_a_counterexample():
    """-ignore_gold_x in 2-valued SAT compared only "source 1 => network 1": this network passed as proved."""
    nl = _stuck_at_one(synthesize(VERILOG / "mult2.v"), "p[0]")
    eq = V.equivalence(VERILOG / "mult2.v", nl)
    assert eq["status"] == "counterexample"
    (step,) = eq["counterexample"]
    assert step["source"]["p"][-1] == "0" and step["network"]["p"][-1] == "1"


def test_clocked_output_stuck_at_one_is_a_counterexample():
    nl = _stuck_at_one(synthesize(VERILOG / "counter4.v"), "q[3]")
    assert V.equivalence(VERILOG / "counter4.v", nl)["status"] == "counterexample"


@pytest.mark.parametrize("body", [
    "output y); assign y = a ? b : 1'bx;",                                        # a don't-care output
    "output reg y); always @(posedge clk) y <= a ? b : 1'bx;",                   # a register assigned x
])
def test_source_x_matches_either_value_but_not_a_wrong_one(tmp_path, body):
    """`x` in the source is a don't-care (synthesis picks a value); where it is not x, a wrong bit still fails."""
    src = tmp_path / "dc.v"
    src.write_text(f"module dc(input clk, input a, input b, {body}\nendmodule\n")
    nl = synthesize(src)
    assert V.equivalence(src, nl)["status"] == "proved"
    assert V.equivalence(src, _stuck_at_one(nl, "y[0]"))["status"] == "counterexample"   # a=1, b=0


def _replay_after_reset(path, nl, cex) -> list[str]:
    """The output bits where Icarus (source) and the logic backend (network) differ on a counterexample
    from the zero state, run after one reset cycle (Icarus starts registers at x; the network's reset
    cycle keeps it at zero): read after the last cycle's predecessors' edges, its inputs on."""
    order = V.input_bits(nl)
    steps = [{"rst": 1, "rdata": 0}] + [s["inputs"] for s in cex]
    x = np.array([[bool(ins[b[:b.index("[")]] >> int(b[b.index("[") + 1:-1]) & 1) for b in order]
                  for ins in steps])
    ref = V.icarus(path, nl, x, clocked=True)[len(cex) - 1]
    got = V.run_backend(nl, x, True, "logic", None, False)[len(cex) - 1]["bits"]
    return [b for b, want in ref.items() if want in "01" and int(want) != got[b]]


def test_processor_proved_with_its_registers_matched():
    """cpu.v (43 latches): induction closes once every register is matched and compared (~3 s here)."""
    nl = synthesize(VERILOG / "cpu.v")
    regs = V.register_names(nl)
    assert len(regs) == len(nl.latches()) == 43
    eq = V.equivalence(VERILOG / "cpu.v", nl, engine="sat")
    assert eq["status"] == "proved" and "43 matched registers" in eq["method"]


def test_broken_processor_mapping_gives_a_counterexample_icarus_confirms():
    """Two write-address bits swapped: the sequence found (load B, read it) makes the outputs differ on
    Icarus against the network too."""
    path = VERILOG / "cpu.v"
    nl = _swap_outputs(synthesize(path), "waddr[0]", "waddr[1]")
    eq = V.equivalence(path, nl, budget_s=600)     # a budget a loaded machine cannot exhaust (took ~20 s)
    assert eq["status"] == "counterexample" and len(eq["counterexample"]) >= 2
    assert set(_replay_after_reset(path, nl, eq["counterexample"])) == {"waddr[0]", "waddr[1]"}


def test_broken_mapping_through_the_cli_exit_1_and_junit_failure(tmp_path, monkeypatch, capsys):
    import mech2spice.synthesis.synth as synth
    real = synth.synthesize
    monkeypatch.setattr(synth, "synthesize", lambda *a, **k: _swap_outputs(real(*a, **k), "s[0]", "s[2]"))
    junit = tmp_path / "verify.xml"
    code, out, err = _run(capsys, VERILOG / "adder2.v", "--junit", junit)
    assert code == 1, err
    assert "counterexample" in out and "mismatches" in out
    suite = ET.parse(junit).getroot()
    assert suite.tag == "testsuite" and suite.get("failures") == "2"
    cases = {c.get("name"): c for c in suite.iter("testcase")}
    assert set(cases) == {"equivalence", "cosim:logic"}
    assert "counterexample" in cases["equivalence"].find("failure").text
    assert "s[0]" in cases["cosim:logic"].find("failure").text


def test_junit_of_a_passing_design_has_no_failure(tmp_path, capsys):
    junit = tmp_path / "ok.xml"
    code, _, _ = _run(capsys, VERILOG / "fsm.v", "--cycles", 50, "--junit", junit)
    suite = ET.parse(junit).getroot()
    assert code == 0 and suite.get("failures") == "0" and suite.find("testcase/failure") is None


def test_icarus_x_agrees_with_either_value_and_is_counted(tmp_path):
    """A register Icarus never defines (no reset) reads x there: the source allows either value, as the
    proof's -ignore_gold_x does, so a valid bit agrees; the undefined bits are counted, not hidden."""
    src = tmp_path / "toggle.v"
    src.write_text("module toggle(input clk, input d, output reg q);\n"
                   "  always @(posedge clk) q <= q ^ d;\nendmodule\n")
    res = V.verify(src, vectors=5)
    assert res["equivalence"]["status"] == "proved"          # equal from the zero state
    assert res["cosim"]["mismatches"] == [] and res["cosim"]["undefined_bits"] == 5
    assert res["verdict"] == "pass" and "5 bits the source leaves undefined" in V.text(res)


def test_an_invalid_bit_against_icarus_x_is_still_a_mismatch():
    """Either value agrees with x; no value (an invalid amplitude) does not."""
    nl = synthesize(VERILOG / "dff.v")
    bit = V.output_bits(nl)[0]
    x = np.zeros((1, len(V.input_bits(nl))), int)
    got = [{"bits": {bit: None}, "amplitudes": {bit: 0.6}}]
    m = V.compare(nl, x, [{bit: "x"}], got, clocked=True)
    assert len(m) == 1 and m[0]["icarus"] == "x" and m[0]["backend"] is None


def test_source_register_folded_away_by_synthesis(tmp_path):
    """`q <= q` synthesises to a constant 0 and no flip-flop: the proof still models the source's register."""
    src = tmp_path / "hold.v"
    src.write_text("module hold(input clk, input d, output reg q);\n  always @(posedge clk) q <= q;\nendmodule\n")
    nl = synthesize(src)
    assert not nl.latches()
    assert V.equivalence(src, nl)["status"] == "proved"


def test_hidden_state_proved_with_register_correspondence():
    """sqrt's step counter is not an output: induction closes once the registers are matched by name."""
    nl = synthesize(VERILOG / "sqrt.v")
    assert {w for _, w, _ in V.register_names(nl)} == {"step", "root"}
    assert V.equivalence(VERILOG / "sqrt.v", nl)["status"] == "proved"


def test_envelope_sample_agrees_with_icarus(capsys):
    code, out, err = _run(capsys, VERILOG / "adder2.v", "--backend", "envelope", "--vectors", 3, "--json")
    co = json.loads(out)["cosim"]
    assert code == 0, out + err
    assert co["vectors"] == 3 and co["agree"] and co["valid"] and co["min_margin"] > 0


@pytest.mark.parametrize("argv, words", [
    (["/nonexistent/x.v"], "cannot read"),
    ([VERILOG / "adder2.v", "--vectors", "0"], "--vectors"),
    ([VERILOG / "adder2.v", "--backend", "nonsense"], "--backend"),
    ([VERILOG / "adder2.v", "--cycles", "5"], "no flip-flops"),
    ([VERILOG / "counter4.v", "--exhaustive"], "--cycles N"),
    ([VERILOG / "counter4.v", "--reset", "zz"], "--reset zz"),
    ([VERILOG / "bad_syntax.v"], "line 5"),
])
def test_bad_input_exit_2_one_line(argv, words, capsys):
    code, out, err = _run(capsys, *argv)
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and words in err and "Traceback" not in err


BENCH = os.environ.get("MECH2SPICE_BENCHMARKS")


@pytest.mark.skipif(not BENCH, reason="set MECH2SPICE_BENCHMARKS to a folder with ISCAS-85 c17.v / c880.v "
                                      "(docs/verify.md says where they come from)")
@pytest.mark.parametrize("name", ["c17", "c880"])
def test_public_benchmark_agrees_with_icarus(name, capsys):
    path = Path(BENCH) / f"{name}.v"
    if not path.exists():
        pytest.skip(f"{path} not there")
    code, out, _ = _run(capsys, path, "--vectors", 2000, "--json")
    res = json.loads(out)
    assert code == 0 and res["equivalence"]["status"] == "proved" and res["cosim"]["agree"]


S344 = Path(__file__).resolve().parents[1].parent / "shared" / "reference" / "cases" / "s344_reset.v"


@pytest.mark.skipif(not S344.exists(), reason="../shared/reference/cases/s344_reset.v not beside the clone")
@pytest.mark.parametrize("backend, cycles", [("logic", 200), ("envelope", 3)])
def test_public_sequential_benchmark_s344(backend, cycles, capsys):
    """ISCAS-89 s344 (public; its flip-flops given a synchronous reset: the file's header names the source),
    not written here: proved equal to its source, and equal to Icarus cycle by cycle on the logic backend and,
    for a sample, on the envelope with every bit valid and the network stable."""
    code, out, err = _run(capsys, S344, "--top", "s344", "--backend", backend, "--cycles", cycles, "--json")
    res = json.loads(out)
    assert code == 0, out + err
    assert res["equivalence"]["status"] == "proved" and res["latches"] == 15
    co = res["cosim"]
    assert co["agree"] and co["mismatches"] == [] and co["cycles"] == cycles
    if backend == "envelope":
        assert co["valid"] and co["stable"] and co["min_margin"] > 0


BACKWARDS = """module inv (input a, output y);
  assign y = ~a;
endmodule

module top (input a, output q);
  wire w;
  inv u (.a(a), .y(w));
  assign w = q;   // written backwards: q is never driven
endmodule
"""


def test_an_output_the_source_never_drives_is_named(tmp_path, capsys):
    """An output joined to its logic only by a backwards `assign` (as in a public behavioural c432): Yosys joins
    the nets, so the proof holds for its reading, but Icarus leaves the port undriven (z).  verify fails and
    says why: the port iverilog coerced to inout, and every z bit counted as undriven."""
    src = tmp_path / "backwards.v"
    src.write_text(BACKWARDS)
    code, out, err = _run(capsys, src, "--json")
    res = json.loads(out)
    assert code == 1 and res["verdict"] == "fail" and res["equivalence"]["status"] == "proved"
    co = res["cosim"]
    assert co["undriven_bits"] == len(co["mismatches"]) == 2 and co["undefined_bits"] == 0
    assert co["source_warnings"] == ["output port q is coerced to inout (iverilog): the source never drives it"]
    code, out, err = _run(capsys, src)
    assert code == 1 and "source: output port q is coerced to inout" in out and "2 bits the source does not drive" in out


ESCAPED = r"""module \top.level$1 (input \clk , input \opcode[0] , input \opcode[1] , input [1:0] \logic ,
                      output \y[0] , output reg [2:0] \q.r );
  wire \n,1 = \opcode[0] & ~\opcode[1] ;
  assign \y[0] = \n,1 ^ \logic [1];
  always @(posedge \clk ) \q.r <= {\q.r [1:0], \n,1 | \logic [0]};
endmodule
"""


def test_escaped_identifiers_proved_and_agree(tmp_path, capsys):
    """Escaped module, port, wire and register names as EPFL netlists write them (`\\opcode[0]`), a keyword
    (`\\logic`) and a comma: the network written back as Verilog, the testbench and the proof all read them."""
    src = tmp_path / "escaped.v"
    src.write_text(ESCAPED)
    code, out, err = _run(capsys, src, "--cycles", 200, "--json")
    res = json.loads(out)
    assert code == 0, out + err
    assert res["top"] == "top.level$1" and res["latches"] == 3
    assert res["equivalence"]["status"] == "proved" and res["cosim"]["agree"] and res["cosim"]["cycles"] == 200


EPFL = ["ctrl", "router", "int2float", "cavlc"]


@pytest.mark.skipif(not BENCH, reason="set MECH2SPICE_BENCHMARKS to a folder with epfl/ctrl.v ... "
                                      "(docs/verify.md says where they come from)")
@pytest.mark.parametrize("name", EPFL)
def test_epfl_benchmark_with_escaped_names_proved_and_agrees(name, capsys):
    """EPFL random-control benchmarks (lsils/benchmarks, random_control/NAME.v): every port an escaped name."""
    path = Path(BENCH) / "epfl" / f"{name}.v"
    if not path.exists():
        pytest.skip(f"{path} not there")
    code, out, err = _run(capsys, path, "--vectors", 500, "--json")
    res = json.loads(out)
    assert code == 0, out + err
    assert res["equivalence"]["status"] == "proved" and res["cosim"]["agree"] and res["cosim"]["mismatches"] == []


FIFO = """// A synchronous FIFO, 8 entries of 8 bits (written for these tests).
module fifo8(input clk, input rst, input push, input pop, input [7:0] din,
             output [7:0] dout, output empty, output full);
  reg [7:0] mem [0:7];
  reg [2:0] wp, rp;
  reg [3:0] count;
  assign empty = count == 0;
  assign full = count == 8;
  assign dout = mem[rp];
  wire do_push = push && !full;
  wire do_pop = pop && !empty;
  always @(posedge clk) begin
    if (rst) begin
      wp <= 0; rp <= 0; count <= 0;
    end else begin
      if (do_push) begin mem[wp] <= din; wp <= wp + 1; end
      if (do_pop) rp <= rp + 1;
      count <= count + do_push - do_pop;
    end
  end
endmodule
"""


def test_a_fifo_with_a_memory_is_proved(tmp_path, capsys):
    """The proof maps the source's memory to flip-flops as synthesis does (sat has no model of $mem cells):
    the 64 memory bits are matched registers and the induction closes."""
    src = tmp_path / "fifo8.v"
    src.write_text(FIFO)
    code, out, err = _run(capsys, src, "--cycles", 300, "--json", "--proof-engine", "sat")
    res = json.loads(out)
    assert code == 0, out + err
    eq = res["equivalence"]
    assert eq["status"] == "proved" and "77 matched registers" in eq["method"] and eq["equivalence_engine"] == "sat"
    assert res["cosim"]["agree"] and res["cosim"]["undefined_bits"] > 0     # dout reads unwritten words: x


GCD = """// GCD by subtraction; its reset port is named rst_n but is active high (written for these tests).
module gcd(input clk, input rst_n, input start, input [3:0] a, input [3:0] b,
           output reg [3:0] y, output reg done);
  reg [3:0] x, z;
  reg busy;
  always @(posedge clk) begin
    if (rst_n) begin
      x <= 0; z <= 0; y <= 0; busy <= 0; done <= 0;
    end else if (!busy) begin
      done <= 0;
      if (start) begin x <= a; z <= b; busy <= 1; end
    end else if (x == z || x == 0 || z == 0) begin
      y <= x == 0 ? z : x; done <= 1; busy <= 0;
    end else if (x > z) x <= x - z;
    else z <= z - x;
  end
endmodule
"""


def test_the_reset_level_is_read_from_the_design_not_the_name(tmp_path, capsys):
    """`rst_n` active high: its polarity comes from Yosys's $sdff cell (rule "design"), so the reset is applied
    and no output is x; stating it the other way (--reset rst_n=0) leaves the registers undefined."""
    src = tmp_path / "gcd.v"
    src.write_text(GCD)
    code, out, err = _run(capsys, src, "--cycles", 300, "--json")
    res = json.loads(out)
    assert code == 0, out + err
    (rst,) = res["cosim"]["resets"]
    assert rst["port"] == "rst_n" and rst["level"] == 1 and rst["rule"].startswith("design")
    assert res["cosim"]["undefined_bits"] == 0 and res["equivalence"]["status"] == "proved"
    code, out, err = _run(capsys, src, "--cycles", 300, "--json", "--reset", "rst_n=0", "--no-equivalence")
    res = json.loads(out)
    assert res["cosim"]["resets"] == [{"port": "rst_n", "level": 0, "rule": "given"}]
    assert res["cosim"]["undefined_bits"] > 0                      # the reset was never really applied


def test_several_resets_one_asynchronous(tmp_path):
    """Two resets, a synchronous active-low one and an asynchronous active-high one: both read from the design."""
    src = tmp_path / "two.v"
    src.write_text("module two(input clk, input clr_n, input arst, input d, output reg p, output reg q);\n"
                   "  always @(posedge clk) if (!clr_n) p <= 0; else p <= d;\n"
                   "  always @(posedge clk or posedge arst) if (arst) q <= 0; else q <= p;\nendmodule\n")
    nl = synthesize(VERILOG / "counter4.v")      # any netlist with the same ports will do for the port list
    nl.top, nl.inputs = "two", {"clr_n": 1, "arst": 1, "d": 1}
    found = V.reset_ports(nl, None, src)
    assert found[0]["port"] == "clr_n" and found[0]["level"] == 0 and "synchronous" in found[0]["rule"]
    assert found[1]["port"] == "arst" and found[1]["level"] == 1 and "asynchronous" in found[1]["rule"]
    assert V.reset_ports(nl, ["clr_n=0", "arst"]) == [
        {"port": "clr_n", "level": 0, "rule": "given"}, {"port": "arst", "level": 1, "rule": "given (level from the name)"}]
    with pytest.raises(V.Mech2SpiceError, match="level is 0 or 1"):
        V.reset_ports(nl, ["arst=2"])


def test_a_proof_out_of_time_is_unknown_and_says_so():
    """The budget bounds the proof: cut short, the status is `unknown`, never a hang or a pass."""
    nl = _swap_outputs(synthesize(VERILOG / "cpu.v"), "waddr[0]", "waddr[1]")
    t0 = time.time()
    eq = V.equivalence(VERILOG / "cpu.v", nl, budget_s=2, engine="sat")
    assert eq["status"] == "unknown" and "time budget (2 s) ran out" in eq["detail"]
    assert eq["budget_s"] == 2 and time.time() - t0 < 30


def test_a_counterexample_the_replay_does_not_confirm_is_unknown():
    """Inputs on which source and network agree, offered as a counterexample: the replay (Icarus and the logic
    backend) finds no differing bit, so the status is `unknown` and the text says why."""
    nl = synthesize(VERILOG / "counter4.v")
    cex = [{"cycle": k, "inputs": {"rst": int(k == 0), "en": 1}} for k in range(4)]
    res = V._replayed(VERILOG / "counter4.v", nl, {"status": "counterexample", "cex": cex, "depth": 4, "detail": ""})
    assert res["status"] == "unknown" and not res["replay"]["reproduced"]
    assert res["replay"]["source"] == res["replay"]["network"] == {"q": "0010"}   # reset at edge 0, counted at edges 1 and 2
    assert "do not differ" in res["detail"] and "give the reset with --reset" in res["detail"]
    given = V._replayed(VERILOG / "counter4.v", nl, {"status": "counterexample", "cex": cex, "depth": 4, "detail": ""},
                        [{"port": "rst", "level": 1}])
    # the reset was given: not sent after it again (OpenCores' sasc, public RTL pass 8)
    assert "--reset" not in given["detail"] and "the reset (rst=1) was applied in cycle 0" in given["detail"]


def test_agreement_on_mostly_undefined_outputs_says_so(tmp_path, capsys, monkeypatch):
    """A register nothing defines (rotated, never reset, never loaded): every q bit is x on Icarus as written,
    so any network agrees there.  The JSON counts the x bits per port; the co-simulation is then run again
    from where the network powers up, and that run is the one compared: a network rotating the other way
    fails it.  Where no register can be started, the verdict line says that most bits were undefined."""
    src = tmp_path / "rot.v"
    rot = "module rot(input clk, input d, output reg [3:0] q, output e);\n  assign e = d;\n" \
          "  always @(posedge clk) q <= {q[2:0], q[3]};\nendmodule\n"
    src.write_text(rot)
    code, out, err = _run(capsys, src, "--cycles", 50, "--json", "--no-equivalence")
    co = json.loads(out)["cosim"]
    assert co["undefined_by_port"] == {"q": {"x": 200, "z": 0, "compared": 200}, "e": {"x": 0, "z": 0, "compared": 50}}
    assert co["agree"] and co["compared_run"] == "power_up_start" and not co["mostly_undefined"]
    other = tmp_path / "other.v"                 # its network powers up at 0 too, then rotates 1s in
    other.write_text(rot.replace("{q[2:0], q[3]}", "{q[2:0], ~q[3]}"))
    wrong = V.verify(src, netlist=synthesize(other), vectors=50, equivalence_check=False)["cosim"]
    assert not wrong["agree"] and wrong["compared_run"] == "power_up_start"
    monkeypatch.setattr(V, "power_up_start", lambda netlist: [])
    code, out, err = _run(capsys, src, "--cycles", 50, "--json", "--no-equivalence")
    co = json.loads(out)["cosim"]
    assert co["mostly_undefined"] and co["agree"] and co["compared_run"] == "as_written"
    code, out, err = _run(capsys, src, "--cycles", 50, "--no-equivalence")
    verdict = out.strip().splitlines()[-1]
    assert "q 200/200" in verdict and "MOST compared bits were undefined" in verdict


def test_a_source_that_includes_a_file_and_holds_a_memory_is_proved(tmp_path, capsys):
    """A memory makes verify hand the proof a rewritten copy in a scratch folder (memory_guard), where the
    source's `include was not found: "Can't open include file" (jamesbowman/j1, ultraembedded spi_lite; public
    RTL pass 9).  The proof reads it with -I the original's folder, as synthesis does."""
    (tmp_path / "defs.vh").write_text("`define W 4\n")
    src = tmp_path / "inc_mem.v"
    src.write_text('`include "defs.vh"\nmodule inc_mem(input clk, input we, input [1:0] wa, input [1:0] ra, '
                   'input [`W-1:0] wd, output [`W-1:0] rd);\n  reg [`W-1:0] store [0:3];\n'
                   '  always @(posedge clk) if (we) store[wa] <= wd;\n  assign rd = store[ra];\nendmodule\n')
    code, out, err = _run(capsys, src, "--cycles", 200, "--json")
    res = json.loads(out)
    assert code == 0 and res["equivalence"]["status"] == "proved" and res["cosim"]["agree"], err


COUNT_BESIDE_REGISTER = """\
module pnc(input clk, input rst, input en, input [15:0] d, output reg [15:0] q, output reg [3:0] cnt);
  always @(posedge clk) q <= rst ? 16'd0 : d;
  always @(posedge clk) if (en) cnt <= cnt + 4'd1;
endmodule
"""


def test_a_port_undefined_in_every_cycle_is_compared_from_the_power_up(tmp_path, capsys, monkeypatch):
    """One port x in every cycle beside a defined 16-bit one (the run is not mostly undefined, so it was never
    run again from the power-up): Icarus never checked the port, and a network counting by 3 passed the
    co-simulation (oc_usb_phy's DataIn_o and oc_sasc's dout_o, public RTL pass 8).  Now a port mostly
    undefined starts the power-up run, and a port still undefined there is named in the verdict."""
    src = tmp_path / "pnc.v"
    src.write_text(COUNT_BESIDE_REGISTER)
    bad = tmp_path / "bad.v"
    bad.write_text(COUNT_BESIDE_REGISTER.replace("cnt + 4'd1", "cnt + 4'd3"))
    wrong = V.verify(src, netlist=synthesize(bad), vectors=40, equivalence_check=False)["cosim"]
    assert not wrong["agree"] and wrong["compared_run"] == "power_up_start"
    assert {m["bit"].split("[")[0] for m in wrong["mismatches"]} == {"cnt"}
    code, out, err = _run(capsys, src, "--cycles", 40, "--json", "--no-equivalence")
    co = json.loads(out)["cosim"]
    assert code == 0 and co["agree"] and co["compared_run"] == "power_up_start"
    assert co["undefined_by_port"]["cnt"] == {"x": 160, "z": 0, "compared": 160}     # as written
    assert co["ports_mostly_undefined"] == co["ports_never_compared"] == []            # in the run compared
    mostly_x = tmp_path / "mx.v"                 # x whatever the start: division by zero (rst is mostly 0)
    mostly_x.write_text(COUNT_BESIDE_REGISTER.replace("if (en) cnt <= cnt + 4'd1", "cnt <= d[3:0] / {3'd0, rst}"))
    code, out, err = _run(capsys, mostly_x, "--cycles", 40, "--json", "--no-equivalence")
    co = json.loads(out)["cosim"]
    assert co["ports_mostly_undefined"] == ["cnt"] and co["ports_never_compared"] == [] and co["agree"]
    monkeypatch.setattr(V, "power_up_start", lambda netlist: [])      # where no register can be started
    code, out, err = _run(capsys, src, "--cycles", 40, "--json", "--no-equivalence")
    co = json.loads(out)["cosim"]
    assert co["ports_never_compared"] == ["cnt"] and co["compared_run"] == "as_written" and not co["mostly_undefined"]
    code, out, err = _run(capsys, src, "--cycles", 40, "--no-equivalence")
    assert "cnt: undefined in every compared bit, so never checked against Icarus" in out.strip().splitlines()[-1]


@pytest.mark.parametrize("body", ["module noin(output y);\n  assign y = 1;\nendmodule\n",
                                  "module onlyclk(input clk, output reg [1:0] q);\n"
                                  "  always @(posedge clk) q <= q + 1;\nendmodule\n"])
def test_a_design_without_data_inputs_is_verified(tmp_path, capsys, body):
    """No data input, or only the clock: the testbench has nothing to apply (it raised a TypeError)."""
    src = tmp_path / "d.v"
    src.write_text(body)
    code, out, err = _run(capsys, src, "--json", *(["--cycles", 20] if "clk" in body else []))
    res = json.loads(out)
    assert code == 0, out + err
    assert res["equivalence"]["status"] == "proved" and res["cosim"]["agree"]


def recoded(src, monkeypatch):
    """The network Yosys's FSM pass makes of `src` (one-hot state registers; synthesis keeps the source's
    encoding, docs/rtl.md): a correct network whose latches are none of the source's registers, which is
    what makes a proof's induction long."""
    from mech2spice.synthesis import synth
    flow = synth._flow
    with monkeypatch.context() as m:
        m.setattr(synth, "_flow", lambda *a, **k: flow(*a, **k).replace("synth -flatten -nofsm", "synth -flatten"))
        return synthesize(src)


def test_an_induction_that_does_not_close_states_its_depth_and_budget(tmp_path, monkeypatch):
    """A recoded FSM whose induction closes only at length 4, given 3 steps: `unknown`, and the detail says
    how deep the bounded check went and how much of which budget the proof used (the suite's rows)."""
    src = tmp_path / "fsm3.v"
    src.write_text("module fsm3(input clk, input rst, input go, output y);\n  reg [1:0] state;\n"
                   "  always @(posedge clk)\n    if (rst) state <= 2'd0;\n    else case (state)\n"
                   "      2'd0: if (go) state <= 2'd1;\n      2'd1: state <= 2'd2;\n      2'd2: state <= 2'd0;\n"
                   "      default: state <= 2'd0;\n    endcase\n  assign y = state == 2'd2;\nendmodule\n")
    nl = recoded(src, monkeypatch)
    monkeypatch.setattr(V, "INDUCTION_STEPS", 3)
    res = V.equivalence(src, nl, budget_s=100, resets=[{"port": "rst", "level": 1}], engine="sat")
    assert res["status"] == "unknown" and res["depth"] == 3
    assert re.search(r"no counterexample within 3 cycles of the start, but the induction did not close within "
                     r"3 steps \(\d+ s of the proof's \d+ s budget used\)", res["detail"])


@pytest.mark.parametrize("engine", ["sat", "auto"])
def test_a_register_synthesis_fixed_from_an_undefined_start_is_proved(tmp_path, engine):
    """A ROM read into registers never initialised, `done` only ever loaded with 1 (as the public rom_dds):
    synthesis makes `done` the constant 1.  The bounded check starts the source's registers at x (any
    power-up refines it, as on Icarus) and the network's at their power-up, so this is proved; an all-zero
    source start made it `unknown` (0 against 1 in cycle 0, a difference no replay from power-up showed)."""
    src = tmp_path / "rom.v"
    src.write_text("module rom(input clk, input [1:0] a, output reg [1:0] d, output reg done);\n"
                   "  reg [1:0] m [0:3];\n  initial begin m[0] = 1; m[1] = 2; m[2] = 3; m[3] = 0; end\n"
                   "  always @(posedge clk) begin d <= m[a]; done <= 1; end\nendmodule\n")
    res = V.equivalence(src, synthesize(src), budget_s=100, engine=engine)
    assert res["status"] == "proved", res


def test_icarus_refusing_the_source_is_quoted_at_its_error_not_its_first_notice(tmp_path, capsys):
    """Public RTL pass 10 (pConst/basic_verilog leave_one_hot.sv): Icarus writes a `sorry:` notice before the
    error that stops it, and verify quoted the notice."""
    src = tmp_path / "t.sv"
    src.write_text("module t (input [3:0] in, output logic [3:0] out);\n  genvar i;\n"
                   "  for (i = 1; i < 4; i++) begin : g\n    always_comb out[i] = in[i] & ~in[i-1];\n  end\n"
                   "  assign out[0] = in[0];\nendmodule\n")
    code = cli.main(["verify", str(src)])
    last = capsys.readouterr().err.splitlines()[-1]          # after the progress lines
    assert code == 2 and last.startswith("mech2spice: error: iverilog -g2012 failed on the source design: ")
    assert last.endswith(f"{src}:6: error: reg out; cannot be driven by primitives or continuous assignment.")
    assert V._first_error("\n a: warning: w\nb: sorry: s\n") == "a: warning: w"      # no error line: the first


def test_a_cosimulation_past_its_budget_compares_the_cycles_icarus_read(tmp_path, monkeypatch, capsys):
    """Public RTL pass 10: pConst's 512-bit scrambler takes Icarus ~3.5 s a cycle, so verify's default 1000 cycles
    ran about an hour with nothing said (and an error at 600 s).  Here vvp stops after five rows: the budget
    (--cosim-time) ends the run, the five cycles read are compared, and the report says so."""
    iverilog, vvp = V._icarus_tools()
    stalled = tmp_path / "stalled_vvp"
    stalled.write_text(f"#!{sys.executable}\nimport subprocess, sys, time\n"
                       f"run = subprocess.Popen([{vvp!r}, *sys.argv[1:]], stdout=subprocess.PIPE, text=True)\n"
                       "for k, line in enumerate(run.stdout):\n"
                       "    sys.stdout.write(line)\n    sys.stdout.flush()\n"
                       "    if k == 4:\n        run.kill()\n        time.sleep(120)\n")
    stalled.chmod(0o755)
    monkeypatch.setattr(V, "_icarus_tools", lambda: (iverilog, str(stalled)))
    src = tmp_path / "t.v"             # y: a path from the input, read with the next cycle's input on
    src.write_text("module t(input clk, input [2:0] a, output [2:0] y, output reg [2:0] q);\n"
                   "  assign y = a;\n  always @(posedge clk) q <= a;\nendmodule\n")
    code = cli.main(["verify", str(src), "--cycles", "40", "--cosim-time", "4", "--no-equivalence", "--json",
                     "--seed", "1"])          # seed 1: cycles 4 and 5 differ in a
    res = json.loads(capsys.readouterr().out)
    co = res["cosim"]
    assert code == 0 and res["verdict"] == "pass", co["mismatches"]
    assert co["cut"] == {"read": 5, "of": 40, "budget_s": 4.0} and co["cycles"] == 5 and co["agree"]
    assert co["compared_run"] == "as_written"       # no mismatch to rerun for: cycle 4 read with cycle 5's a on
    assert "Icarus's budget (4 s, --cosim-time) ran out: 5 of 40 cycles read, and compared" in V.text(res)


def test_an_internal_assertion_of_icarus_is_named_as_icarus_s_defect(tmp_path, monkeypatch, capsys):
    """Public RTL pass 10: Icarus 11 aborts on pConst's fifo_single_clock_reg_v1.sv (`assert: elab_lval.cc:689:
    failed assertion`), which synthesises; the message read as if the source were refused."""
    iverilog, vvp = V._icarus_tools()
    aborts = tmp_path / "aborting_iverilog"
    aborts.write_text(f"#!{sys.executable}\nimport sys\n"
                      "sys.stderr.write('./x_init.svh:19: assert: elab_lval.cc:689: failed assertion rcl\\n')\n"
                      "sys.exit(134)\n")
    aborts.chmod(0o755)
    monkeypatch.setattr(V, "_icarus_tools", lambda: (str(aborts), vvp))
    code = cli.main(["verify", str(ROOT / "verilog" / "adder2.v"), "--no-equivalence"])
    last = capsys.readouterr().err.splitlines()[-1]
    assert code == 2 and "elab_lval.cc:689: failed assertion rcl (an internal check of Icarus failing: a " \
                          "defect of Icarus, not a refusal of the source" in last, last
