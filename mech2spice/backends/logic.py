"""Logic-level evaluation of a NOR Netlist: the reference the mechanical simulations must match.

Bit order: bit i of port p is node ``p[i]``, LSB = bit 0.  Batch vectors put input bits in
port declaration order, LSB first within a port (see ``input_bits`` / ``output_bits``).
"""

from __future__ import annotations

import numpy as np

from ..errors import Mech2SpiceError
from ..synthesis.synth import Netlist

__all__ = ["evaluate", "evaluate_bits", "evaluate_batch", "pack_inputs",
           "input_bits", "output_bits", "ClockedLogic"]


def input_bits(netlist: Netlist) -> list[str]:
    """Input node names in batch-column order."""
    return [f"{p}[{i}]" for p, w in netlist.inputs.items() for i in range(w)]


def output_bits(netlist: Netlist) -> list[str]:
    """Output node names in batch-column order."""
    return [f"{p}[{i}]" for p, w in netlist.outputs.items() for i in range(w)]


def pack_inputs(netlist: Netlist, values: dict[str, int]) -> dict[str, int]:
    """Port integers -> {"a[0]": bit, ...} for every input bit (unset ports are 0)."""
    bits = dict.fromkeys(input_bits(netlist), 0)
    for port, value in values.items():
        if port not in netlist.inputs:
            known = ", ".join(netlist.inputs) or "none"
            raise Mech2SpiceError(f"unknown input port '{port}' (inputs: {known})")
        width = netlist.inputs[port]
        if not isinstance(value, (int, np.integer)):
            raise Mech2SpiceError(f"input '{port}' needs an integer, got {value!r}")
        if value < 0 or value >> width:
            raise Mech2SpiceError(f"value {value} does not fit input '{port}' "
                                  f"({width} bit{'s' * (width != 1)}, 0..{2 ** width - 1})")
        for i in range(width):
            bits[f"{port}[{i}]"] = (int(value) >> i) & 1
    return bits


def _input_bit_values(netlist: Netlist, values: dict) -> dict[str, int]:
    """Accept port integers ({"a": 3}) and/or single input bits ({"a[0]": 1})."""
    g = netlist.graph
    single = {k: v for k, v in values.items() if k in g and g.nodes[k]["kind"] == "input"}
    bits = pack_inputs(netlist, {k: v for k, v in values.items() if k not in single})
    for name, v in single.items():
        if v not in (0, 1):
            raise Mech2SpiceError(f"input bit '{name}' must be 0 or 1, got {v!r}")
        bits[name] = int(v)
    return bits


def evaluate_bits(netlist: Netlist, values: dict, state: dict[str, int] | None = None) -> dict[str, int]:
    """0/1 for every node (inputs, consts, latches, gates, outputs) given port ints or input bits;
    latches hold `state` (0 where not given)."""
    g = netlist.graph
    val = _input_bit_values(netlist, values)
    val.update({n: int(n == "const1") for n in g if g.nodes[n]["kind"] == "const"})
    val.update({q: int((state or {}).get(q, 0)) for q in netlist.latches()})
    for gate in netlist.gates():
        val[gate] = int(not any(val[src] for src in g.predecessors(gate)))
    for out in output_bits(netlist):
        (src,) = g.predecessors(out)
        val[out] = val[src]
    return val


def evaluate(netlist: Netlist, values: dict[str, int], state: dict[str, int] | None = None) -> dict[str, int]:
    """Output port -> integer for input port integers (unset inputs are 0)."""
    bits = evaluate_bits(netlist, values, state)
    return _ports(netlist, bits)


def _ports(netlist: Netlist, bits: dict[str, int]) -> dict[str, int]:
    return {p: sum(bits[f"{p}[{i}]"] << i for i in range(w)) for p, w in netlist.outputs.items()}


class ClockedLogic:
    """Cycle-level model of a clocked netlist: latches are registers that start at 0 and take their
    D value at each clock edge (`tick`)."""

    def __init__(self, netlist: Netlist):
        self.netlist = netlist
        self.state = dict.fromkeys(netlist.latches(), 0)

    def evaluate_bits(self, values: dict) -> dict[str, int]:
        return evaluate_bits(self.netlist, values, self.state)

    def evaluate(self, values: dict) -> dict[str, int]:
        return _ports(self.netlist, self.evaluate_bits(values))

    def tick(self, values: dict) -> None:
        """One rising clock edge with inputs `values`."""
        bits = self.evaluate_bits(values)
        g = self.netlist.graph
        self.state = {q: bits[next(iter(g.predecessors(q)))] for q in self.state}


def evaluate_batch(netlist: Netlist, vectors) -> np.ndarray:
    """(B, n_input_bits) bool -> (B, n_output_bits) bool, one numpy op per gate."""
    ins, outs = input_bits(netlist), output_bits(netlist)
    x = np.asarray(vectors, dtype=bool)
    if x.ndim != 2 or x.shape[1] != len(ins):
        raise Mech2SpiceError(f"evaluate_batch needs an array of shape (B, {len(ins)}), "
                              f"got {np.shape(vectors)}")
    g = netlist.graph
    val = {name: x[:, j] for j, name in enumerate(ins)}
    val["const0"] = np.zeros(len(x), dtype=bool)
    val["const1"] = np.ones(len(x), dtype=bool)
    for gate in netlist.gates():
        a, b = g.predecessors(gate)
        val[gate] = ~(val[a] | val[b])
    result = np.empty((len(x), len(outs)), dtype=bool)
    for j, out in enumerate(outs):
        (src,) = g.predecessors(out)
        result[:, j] = val[src]
    return result
