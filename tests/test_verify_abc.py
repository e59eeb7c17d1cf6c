"""`verify`'s ABC engine (docs/verify.md, "Engines"): the miter as AIGER, proved by ABC's pdr (sequential) or
iprove (combinational); a counterexample replayed on Icarus and the logic backend; x in the source; the
fallback to Yosys sat without berkeley-abc."""
from __future__ import annotations

import shutil

import pytest

from mech2spice import verify as V
from mech2spice.synthesis.synth import synthesize

from test_verify import VERILOG, _flip_gate_input, _stuck_at_one, _swap_outputs, recoded

pytestmark = pytest.mark.skipif(not (shutil.which("iverilog") and shutil.which("vvp")),
                                reason="Icarus Verilog (iverilog, vvp) not installed")
needs_abc = pytest.mark.skipif(V.abc_tool() is None, reason="Berkeley ABC (berkeley-abc) not installed")

# A binary-encoded FSM (5 states in 3 bits, written for these tests) that Yosys's fsm pass re-encodes one-hot
# (the attribute asks for it, as `synth`'s own choice did for the suite's traffic_light and b10): 5 latches
# against 3 source bits, so no register of the network is one of the source's.  Synthesis keeps the source's
# encoding (docs/rtl.md, "State machines"); the recoded network, correct too, is built for the proof engines.
FSM5 = """module fsm5(input clk, input rst, input go, input stop, output busy, output done);
  (* fsm_encoding = "one-hot" *) reg [2:0] state;
  always @(posedge clk)
    if (rst) state <= 3'd0;
    else case (state)
      3'd0: if (go) state <= 3'd1;
      3'd1: state <= stop ? 3'd0 : 3'd2;
      3'd2: state <= 3'd3;
      3'd3: state <= stop ? 3'd1 : 3'd4;
      3'd4: state <= 3'd0;
      default: state <= 3'd0;
    endcase
  assign busy = state != 3'd0 && state != 3'd4;
  assign done = state == 3'd4;
endmodule
"""
RST = [{"port": "rst", "level": 1}]


@needs_abc
def test_abc_proves_a_one_hot_recoded_fsm_that_short_induction_cannot(tmp_path, monkeypatch):
    src = tmp_path / "fsm5.v"
    src.write_text(FSM5)
    assert len(synthesize(src).latches()) == 3                      # as written: the attribute is not obeyed
    nl = recoded(src, monkeypatch)
    assert len(nl.latches()) == 5                                   # one-hot: a latch per state
    eq = V.equivalence(src, nl, 60, RST, engine="abc")
    assert eq["status"] == "proved" and eq["equivalence_engine"] == "abc" and eq["depth"] is None
    assert "pdr" in eq["method"] and "reset rst=1 in cycle 0" in eq["method"]
    monkeypatch.setattr(V, "INDUCTION_STEPS", 4)                   # sat's induction closes at length 8 here
    sat = V.equivalence(src, nl, 60, RST, engine="sat")
    assert sat["status"] == "unknown" and sat["equivalence_engine"] == "sat"


@needs_abc
def test_abc_counterexample_on_a_broken_counter_is_replayed():
    nl = _flip_gate_input(synthesize(VERILOG / "counter4.v"))
    eq = V.equivalence(VERILOG / "counter4.v", nl, 60, RST, engine="abc")
    assert eq["status"] == "counterexample" and eq["equivalence_engine"] == "abc"
    cex = eq["counterexample"]
    assert [s["cycle"] for s in cex] == list(range(len(cex))) and cex[0]["inputs"]["rst"] == 1
    rep = eq["replay"]                                  # Icarus and the logic backend differ in its last cycle
    assert rep["reproduced"] and rep["cycle"] == len(cex) - 1 and rep["bits"]
    assert cex[-1]["source"] != cex[-1]["network"]


@needs_abc
def test_abc_proves_a_combinational_design_and_catches_swapped_outputs():
    eq = V.equivalence(VERILOG / "mult2.v", synthesize(VERILOG / "mult2.v"), 60, engine="abc")
    assert eq["status"] == "proved" and "iprove" in eq["method"] and eq["equivalence_engine"] == "abc"
    nl = _swap_outputs(synthesize(VERILOG / "mult2.v"), "p[0]", "p[1]")
    eq = V.equivalence(VERILOG / "mult2.v", nl, 60, engine="abc")
    assert eq["status"] == "counterexample"
    (step,) = eq["counterexample"]
    product = format(step["inputs"]["a"] * step["inputs"]["b"], "04b")
    assert step["source"]["p"] == product and step["network"]["p"] != product


@needs_abc
def test_an_abc_counterexample_the_replay_cannot_confirm_leaves_it_to_sat():
    """q[3] stuck at 1: ABC's shortest difference is in cycle 0, before the reset's clock edge, where Icarus
    reads x (the source's registers start x in a simulator): unconfirmed, so sat decides, and its sequence
    (after the reset's edge) is confirmed."""
    nl = _stuck_at_one(synthesize(VERILOG / "counter4.v"), "q[3]")
    eq = V.equivalence(VERILOG / "counter4.v", nl, 60, RST)
    assert eq["status"] == "counterexample" and eq["equivalence_engine"] == "sat"
    assert "replay did not confirm" in eq["engine_note"] and eq["replay"]["reproduced"]


@needs_abc
def test_source_x_abc_claims_every_choice_and_sat_decides_the_rest(tmp_path):
    """`x` is a free value for ABC (a stronger claim); where the network picked one value, ABC's counterexample
    reads x on Icarus, the replay does not confirm it and sat (x: either value agrees) proves the design.  A
    bit that is wrong where the source is defined is still ABC's counterexample."""
    src = tmp_path / "dc.v"
    src.write_text("module dc(input a, input b, output y, output z);\n"
                   "  assign y = a ? b : 1'bx;\n  assign z = a & b;\nendmodule\n")
    nl = synthesize(src)
    eq = V.equivalence(src, nl, 60)
    assert eq["status"] == "proved" and eq["equivalence_engine"] == "sat"
    assert "replay did not confirm" in eq["engine_note"]
    eq = V.equivalence(src, _stuck_at_one(synthesize(src), "z[0]"), 60)
    assert eq["status"] == "counterexample" and eq["equivalence_engine"] == "abc"


def test_without_abc_sat_decides_and_says_so(monkeypatch):
    monkeypatch.setattr(V, "abc_tool", lambda: None)
    eq = V.equivalence(VERILOG / "counter4.v", synthesize(VERILOG / "counter4.v"), 60, RST)
    assert eq["status"] == "proved" and eq["equivalence_engine"] == "sat"
    assert eq["engine_note"] == "berkeley-abc not found: proved with Yosys sat alone"


@needs_abc
def test_abc_reads_an_internal_tri_state_bus_as_synthesis_does(tmp_path):
    """Two drivers on one bus: an AIGER wire has one driver, so without `tribuf -formal` on the source the
    miter kept one of them and ABC's counterexample was not confirmed (measured: status unknown)."""
    src = tmp_path / "tri2.v"
    src.write_text("module tri2(input clk, input a, input b, input s, output reg y);\n  wire bus;\n"
                   "  assign bus = s ? a : 1'bz;\n  assign bus = s ? 1'bz : b;\n"
                   "  always @(posedge clk) y <= bus;\nendmodule\n")
    eq = V.equivalence(src, synthesize(src), 60, engine="abc")
    assert eq["status"] == "proved" and eq["equivalence_engine"] == "abc"


@needs_abc
def test_proof_engine_flag_and_json_fields(capsys):
    from mech2spice import cli
    import json
    for engine in ("abc", "sat"):
        code = cli.main(["verify", str(VERILOG / "counter4.v"), "--json", "--cycles", "50", "--proof-engine", engine])
        eq = json.loads(capsys.readouterr().out)["equivalence"]
        assert code == 0 and eq["status"] == "proved" and eq["equivalence_engine"] == engine
        assert eq["engine_note"] is None and ("pdr" in eq["method"]) == (engine == "abc")
