"""Logic evaluator: hand-built netlists (no Yosys) plus agreement checks on synthesized designs."""

import functools
import itertools
from pathlib import Path

import networkx as nx
import numpy as np
import pytest

from mech2spice.errors import Mech2SpiceError
from mech2spice.backends.logic import evaluate, evaluate_batch, evaluate_bits
from mech2spice.synthesis.ports import input_bits, output_bits, pack_inputs
from mech2spice.synthesis.synth import Netlist, synthesize

VERILOG = Path(__file__).resolve().parent.parent / "verilog"


def xor_netlist() -> Netlist:
    """x = a XOR b from 5 NORs and a constant output c = 1, built by hand."""
    g = nx.DiGraph()
    for port, i in (("a", 0), ("b", 0)):
        g.add_node(f"{port}[{i}]", kind="input", port=port, bit=i)
    g.add_node("const0", kind="const")
    g.add_node("const1", kind="const")
    g.add_nodes_from(["g0", "g1", "g2", "g3"], kind="nor")
    for node, port in (("x[0]", "x"), ("c[0]", "c")):
        g.add_node(node, kind="output", port=port, bit=0)
    # g0 = NOR(a,b); g1 = NOR(a,g0); g2 = NOR(b,g0); g3 = NOR(g1,g2) = XNOR; x = NOT g3
    g.add_node("g4", kind="nor")
    edges = [("a[0]", "g0", 0), ("b[0]", "g0", 1), ("a[0]", "g1", 0), ("g0", "g1", 1),
             ("b[0]", "g2", 0), ("g0", "g2", 1), ("g1", "g3", 0), ("g2", "g3", 1),
             ("g3", "g4", 0), ("const0", "g4", 1)]
    g.add_edges_from((u, v, {"pin": p}) for u, v, p in edges)
    g.add_edge("g4", "x[0]")
    g.add_edge("const1", "c[0]")
    return Netlist("xor", g, {"a": 1, "b": 1}, {"x": 1, "c": 1})


@functools.lru_cache(maxsize=None)
def net(name):
    return synthesize(VERILOG / f"{name}.v")


# ------------------------------------------------------------------ hand-built netlist

def test_evaluate_hand_built_xor():
    n = xor_netlist()
    for a, b in itertools.product((0, 1), repeat=2):
        assert evaluate(n, {"a": a, "b": b}) == {"x": a ^ b, "c": 1}


def test_evaluate_bits_covers_every_node_and_obeys_nor():
    n = xor_netlist()
    bits = evaluate_bits(n, {"a": 1})
    assert set(bits) == set(n.graph)                    # inputs, consts, gates, outputs
    assert bits["const0"] == 0 and bits["const1"] == 1 and bits["b[0]"] == 0
    for gate in n.gates():
        assert bits[gate] == int(not any(bits[p] for p in n.graph.predecessors(gate)))
    assert bits["g0"] == 0 and bits["x[0]"] == 1


def test_evaluate_bits_accepts_single_input_bits():
    n = xor_netlist()
    assert evaluate_bits(n, {"a[0]": 1, "b": 1})["x[0]"] == 0
    with pytest.raises(Mech2SpiceError, match="'a\\[0\\]' must be 0 or 1"):
        evaluate_bits(n, {"a[0]": 2})


def test_unset_inputs_are_zero():
    n = xor_netlist()
    assert evaluate(n, {}) == {"x": 0, "c": 1}
    assert evaluate(n, {"b": 1}) == {"x": 1, "c": 1}


def test_batch_matches_scalar_on_hand_built_xor():
    n = xor_netlist()
    vectors = np.array(list(itertools.product((False, True), repeat=2)))
    out = evaluate_batch(n, vectors)
    assert out.dtype == bool and out.shape == (4, 2)
    assert out[:, 0].tolist() == [a ^ b for a, b in vectors.tolist()]
    assert out[:, 1].all()


def test_batch_rejects_wrong_shape():
    n = xor_netlist()
    with pytest.raises(Mech2SpiceError, match=r"shape \(B, 2\)"):
        evaluate_batch(n, np.zeros((4, 3), dtype=bool))
    with pytest.raises(Mech2SpiceError, match=r"shape \(B, 2\)"):
        evaluate_batch(n, np.zeros(2, dtype=bool))


# ------------------------------------------------------------------ pack_inputs

def test_pack_inputs_bit_order():
    n = net("comparator4")
    bits = pack_inputs(n, {"a": 0b1010, "b": 1})
    assert list(bits) == input_bits(n) == [f"a[{i}]" for i in range(4)] + [f"b[{i}]" for i in range(4)]
    assert [bits[f"a[{i}]"] for i in range(4)] == [0, 1, 0, 1]     # LSB first
    assert [bits[f"b[{i}]"] for i in range(4)] == [1, 0, 0, 0]
    assert pack_inputs(n, {"a": np.int64(15)})["a[3]"] == 1


def test_pack_inputs_errors():
    n = net("adder2")
    with pytest.raises(Mech2SpiceError, match="unknown input port 'c'.*inputs: a, b"):
        pack_inputs(n, {"c": 1})
    with pytest.raises(Mech2SpiceError, match=r"value 4 does not fit input 'a' \(2 bits, 0..3\)"):
        pack_inputs(n, {"a": 4})
    with pytest.raises(Mech2SpiceError, match=r"value -1 does not fit input 'b'"):
        pack_inputs(n, {"b": -1})
    with pytest.raises(Mech2SpiceError, match="needs an integer"):
        pack_inputs(n, {"a": 1.5})
    with pytest.raises(Mech2SpiceError, match="unknown input port 's'"):   # an output is no input
        evaluate(n, {"s": 1})


# ------------------------------------------------------------------ synthesized designs

@pytest.mark.parametrize("name", ["adder2", "comparator4", "mux4", "mult2", "parity8"])
def test_batch_agrees_with_evaluate(name):
    n = net(name)
    ins, outs = input_bits(n), output_bits(n)
    rng = np.random.default_rng(0)
    vectors = rng.integers(0, 2, size=(256, len(ins))).astype(bool)
    got = evaluate_batch(n, vectors)
    assert got.shape == (256, len(outs))
    for row, out in zip(vectors, got):
        bits = evaluate_bits(n, {bit: int(v) for bit, v in zip(ins, row)})
        assert [bool(bits[o]) for o in outs] == out.tolist()


def test_parity8_random_vectors():
    n = net("parity8")
    rng = np.random.default_rng(1)
    data = rng.integers(0, 256, size=256)
    for d in data:
        assert evaluate(n, {"d": int(d)}) == {"p": bin(int(d)).count("1") % 2}
    vectors = (data[:, None] >> np.arange(8)) & 1
    assert evaluate_batch(n, vectors.astype(bool))[:, 0].tolist() == \
        [bool(bin(int(d)).count("1") % 2) for d in data]


@pytest.mark.parametrize("design", ["adder2.v", "counter4.v", "cpu.v", "fsm.v", "sqrt.v", "parity8.v", "dff.v"])
def test_the_level_by_level_evaluation_equals_the_gate_by_gate_one(design):
    """ClockedLogic evaluates a netlist without forced latches one logic level at a time (numpy): every node
    equal to evaluate_bits's, gate by gate, on random inputs and register states; and a whole clocked run
    equal too."""
    from mech2spice.backends.logic import ClockedLogic, _Levels
    from mech2spice.simulation import run_clocked_logic
    nl = synthesize(Path(__file__).resolve().parents[1] / "verilog" / design)
    levels, rng = _Levels(nl), np.random.default_rng(7)
    for _ in range(40):
        values = {b: int(rng.integers(2)) for b in input_bits(nl)}
        state = {q: int(rng.integers(2)) for q in nl.latches()}
        assert levels.evaluate(values, state) == evaluate_bits(nl, values, state)
    cycles = [{b: int(rng.integers(2)) for b in input_bits(nl)} for _ in range(30)]
    fast = run_clocked_logic(nl, cycles)["trace"]
    plain = ClockedLogic.__init__

    def gate_by_gate(self, netlist):
        plain(self, netlist)
        self._levels = None
    try:
        ClockedLogic.__init__ = gate_by_gate
        slow = run_clocked_logic(nl, cycles)["trace"]
    finally:
        ClockedLogic.__init__ = plain
    assert [t["bits"] for t in fast] == [t["bits"] for t in slow]
