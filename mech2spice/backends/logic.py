"""Logic-level evaluation of a NOR Netlist: the reference the mechanical simulations must match.

Bit order: bit i of port p is node ``p[i]``, LSB = bit 0.  Batch vectors put input bits in
port declaration order, LSB first within a port (see ``input_bits`` / ``output_bits``).
"""

from __future__ import annotations

import numpy as np

from ..errors import Mech2SpiceError
from ..inputs import MAX_CYCLES
from ..synthesis.ports import input_bits, output_bits, pack_inputs, port_values
from ..synthesis.synth import Netlist, latch_inputs
from ._base import Capabilities, FromFlags, NoOptions, _flag

TIME_FLAGS = ("periods", "steps", "pulse", "pause")     # a physical run's time, in the command line's names

__all__ = ["evaluate", "evaluate_bits", "evaluate_batch", "power_up", "ClockedLogic", "LogicEngine"]


def _input_bit_values(netlist: Netlist, values: dict) -> dict[str, int]:
    """Accept port integers ({"a": 3}) and/or single input bits ({"a[0]": 1}). A name that is a port is the
    port, even where it also names another port's bit (`input [1:0] a, input \\a[0] `): Verilog's meaning."""
    g = netlist.graph
    single = {k: v for k, v in values.items()
              if k not in netlist.inputs and k in g and g.nodes[k]["kind"] == "input"}
    bits = pack_inputs(netlist, {k: v for k, v in values.items() if k not in single})
    for name, v in single.items():
        if v not in (0, 1):
            raise Mech2SpiceError(f"input bit '{name}' must be 0 or 1, got {v!r}")
        bits[name] = int(v)
    return bits


def power_up(netlist: Netlist) -> dict[str, int]:
    """Each register's value at power-up: the latch loop starts storing 0, so a register whose latch stores
    its complement (`inverted`: an initial value of 1, or an asynchronous set) starts at 1."""
    g = netlist.graph
    return {q: int(g.nodes[q].get("inverted", 0)) for q in netlist.latches()}


def evaluate_bits(netlist: Netlist, values: dict, state: dict[str, int] | None = None) -> dict[str, int]:
    """0/1 for every node (inputs, consts, latches, gates, outputs) given port ints or input bits;
    latches hold `state` (their power-up value where not given), a forced latch (F high) its forced value."""
    g = netlist.graph
    val = _input_bit_values(netlist, values)
    val.update({n: int(n == "const1") for n in g if g.nodes[n]["kind"] == "const"})
    latches = netlist.latches()
    held = state if state is not None and len(state) == len(latches) else {**power_up(netlist), **(state or {})}
    val.update({q: int(held[q]) for q in latches})
    if netlist.forced():
        _evaluate_forced(netlist, val)
    else:
        for gate in netlist.gates():
            val[gate] = int(not any(val[src] for src in g.predecessors(gate)))
    for out in output_bits(netlist):
        (src,) = g.predecessors(out)
        val[out] = val[src]
    return val


def _evaluate_forced(netlist: Netlist, val: dict) -> None:
    """Gates and latches in schedule order: a latch whose F is high reads its forced value at once (an
    asynchronous reset or set acts without the clock)."""
    g = netlist.graph
    for node in netlist.schedule():
        if g.nodes[node]["kind"] == "latch":
            f = latch_inputs(g, node)[1]
            if f is not None and val[f]:
                val[node] = int(g.nodes[node].get("inverted", 0))
        else:
            val[node] = int(not any(val[src] for src in g.predecessors(node)))


def evaluate(netlist: Netlist, values: dict[str, int], state: dict[str, int] | None = None) -> dict[str, int]:
    """Output port -> integer for input port integers (unset inputs are 0)."""
    bits = evaluate_bits(netlist, values, state)
    return port_values(netlist, bits)


class ClockedLogic:
    """Cycle-level model of a clocked netlist: latches are registers that start at their power-up value and
    take their D value at each clock edge (`tick`), unless their forcing input holds them."""

    def __init__(self, netlist: Netlist):
        self.netlist = netlist
        self.state = power_up(netlist)
        self._plain = not netlist.forced() and not any(self.state.values())   # D is the next state
        # a forced latch acts inside the evaluation (schedule order): evaluate_bits keeps that one
        self._levels = None if netlist.forced() else _Levels(netlist)

    def evaluate_bits(self, values: dict) -> dict[str, int]:
        """Every node's value for these inputs and the current register state."""
        if self._levels is None:
            return evaluate_bits(self.netlist, values, self.state)
        return self._levels.evaluate(values, self.state)

    def evaluate(self, values: dict) -> dict[str, int]:
        """Output ports for these inputs and the current register state."""
        return port_values(self.netlist, self.evaluate_bits(values))

    def tick(self, values: dict) -> None:
        """One rising clock edge with inputs `values`."""
        bits = self.evaluate_bits(values)
        g = self.netlist.graph
        if self._plain:
            self.state = {q: bits[next(iter(g.predecessors(q)))] for q in self.state}
            return
        self.state = {q: _captured(g, q, bits) for q in self.state}


class _Levels:
    """evaluate_bits for a netlist without forced latches, one numpy operation per logic level: the gates of a
    level read only earlier levels, so each level is computed at once.  A clocked run evaluates the network
    twice a cycle, gate by gate in Python about a second a cycle at 187,363 gates (WangXuan95's uart2axi4,
    public RTL pass 10; that one has asynchronous resets, whose forced latches keep the gate-by-gate schedule).
    Built once per ClockedLogic, so a graph changed before it is read as it is."""

    def __init__(self, netlist: Netlist):
        g = netlist.graph
        self.netlist, self.nodes = netlist, list(g.nodes)
        self.at = {n: i for i, n in enumerate(self.nodes)}
        low = len(self.nodes)                            # one slot more, always 0: a gate's missing input
        level, rows = {}, {}
        for gate in netlist.gates():                     # topological order (evaluate_bits relies on it too)
            preds = [self.at[p] for p in g.predecessors(gate)]
            level[gate] = 1 + max((level.get(self.nodes[p], 0) for p in preds), default=0)
            a, b = (preds * 2)[:2] if preds else (low, low)
            rows.setdefault(level[gate], []).append((self.at[gate], a, b))
        self.levels = [np.array(rows[k]).T for k in sorted(rows)]
        self.outputs = [(self.at[o], self.at[next(iter(g.predecessors(o)))]) for o in output_bits(netlist)]
        self.latches = netlist.latches()

    def evaluate(self, values: dict, state: dict | None) -> dict[str, int]:
        """What evaluate_bits(netlist, values, state) gives."""
        netlist, at = self.netlist, self.at
        val = np.zeros(len(self.nodes) + 1, dtype=bool)
        held = state if state is not None and len(state) == len(self.latches) else \
            {**power_up(netlist), **(state or {})}
        for name, v in _input_bit_values(netlist, values).items():
            val[at[name]] = bool(v)
        for q in self.latches:
            val[at[q]] = bool(held[q])
        if "const1" in at:
            val[at["const1"]] = True
        for gate, a, b in self.levels:
            val[gate] = ~(val[a] | val[b])
        for out, src in self.outputs:
            val[out] = val[src]
        return dict(zip(self.nodes, val[:-1].view(np.uint8).tolist()))


def _captured(g, q: str, bits: dict) -> int:
    """The register value a latch holds after a clock edge: forced while F is high, else its D pin (which
    carries the complement for an inverted latch)."""
    d, f = latch_inputs(g, q)
    inverted = int(g.nodes[q].get("inverted", 0))
    return inverted if f is not None and bits[f] else bits[d] ^ inverted


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


class LogicEngine(FromFlags):
    """The NOR graph evaluated as Boolean logic: the oracle the physical engines must match."""

    name = "logic"
    capabilities = Capabilities(physical=False, batch=True)
    Options = NoOptions
    max_cycles = MAX_CYCLES              # a trace entry per cycle, no oscillators: far more cycles than the others

    def __init__(self, options=None):
        self.options = options if options is not None else NoOptions()

    @classmethod
    def flag_changes(cls, flags) -> dict:
        """No settings: the flags that set a physical run's time are refused, not ignored (it has no time)."""
        given = [f"--{name}" for name in TIME_FLAGS if _flag(flags, name) is not None]
        if given:
            raise Mech2SpiceError(f"{', '.join(given)}: the logic backend evaluates the NOR graph and has no drive "
                                  "periods, steps or pulses (the physical backends do)")
        return super().flag_changes(flags)

    def describe(self) -> dict:
        """No settings."""
        return {}
