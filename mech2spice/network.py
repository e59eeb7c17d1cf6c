"""From a NOR netlist (networkx graph) to the mechanical model every backend reads.

One NOR node -> one gate block; each gate-to-gate edge -> spring + dashpot from
the driver's channel to the sink's input pair; an input-port bit -> an external
drive of the pair it feeds (amplitude set by the stimulus); const0 -> a
constant-level drive at 0.5 F_R; each output bit -> a probe on its driving
channel.
"""
from __future__ import annotations

import numpy as np

from . import nor
from .errors import Mech2SpiceError
from .logic import input_bits, output_bits, pack_inputs
from .model import MechModel
from .params import NOMINAL0, NOMINAL1, GateParams
from .stimulus import Stimulus
from .synth import Netlist


# Largest fan-out measured to work (characterise.fanout_test, RK4 80 steps/period, 2000 periods): 12 loads all
# decode correctly with margin >= 0.09 and the driver's amplitude moves by <= 1.1e-3 u_R. Beyond it synthesis
# inserts NOR-pair buffers.
MAX_FANOUT = 12


def build(netlist: Netlist, p: GateParams) -> MechModel:
    g = netlist.graph
    m = nor.new_model(p)
    blocks = {name: nor.add_nor(m, p, name) for name in netlist.gates()}
    bit_drives: dict[str, list[int]] = {b: [] for b in input_bits(netlist)}
    for name, block in blocks.items():
        for src, _, data in g.in_edges(name, data=True):
            pair = block.inputs[data["pin"]]
            kind = g.nodes[src]["kind"]
            if kind == "nor":
                nor.connect(m, p, blocks[src].channel, pair)
            elif kind == "input":
                bit_drives[src] += nor.drive_pair(m, p, pair, NOMINAL0, f"in.{src}.{name}")
            elif src == "const0":
                nor.drive_pair(m, p, pair, NOMINAL0, f"zero.{name}")
            else:
                raise Mech2SpiceError(f"gate {name} is fed by {src} ({kind}); only NOR gates, inputs and "
                                      "const0 can drive a gate")
    const_out = {}
    for bit in output_bits(netlist):
        (src,) = list(g.predecessors(bit))
        if g.nodes[src]["kind"] == "nor":
            m.add_probe(bit, blocks[src].channel)
        else:
            const_out[bit] = 1 if src == "const1" else 0
    m.meta.update(gates=list(blocks.values()), blocks=blocks, bit_drives=bit_drives, const_outputs=const_out,
                  netlist=netlist)
    return m


def drive_levels(model: MechModel, netlist: Netlist, p: GateParams, values: list[dict[str, int]]) \
        -> dict[int, np.ndarray]:
    """{drive index: (B,) amplitude} for input-port values, one dict per batch member."""
    out: dict[int, np.ndarray] = {}
    bits = [pack_inputs(netlist, v) for v in values]
    for bit, drives in model.meta["bit_drives"].items():
        amp = np.array([p.force(NOMINAL1 if b.get(bit, 0) else NOMINAL0) for b in bits])
        for d in drives:
            out[d] = amp
    return out


def stimulus(model: MechModel, netlist: Netlist, p: GateParams,
             segments: list[tuple[float, list[dict[str, int]]]]) -> Stimulus:
    """Piecewise-constant input values: [(start period, [values per batch member])]."""
    batch = len(segments[0][1])
    return Stimulus.from_levels(
        model, [(t * p.period, drive_levels(model, netlist, p, vals)) for t, vals in segments], batch=batch)


def logic_depth(netlist: Netlist) -> int:
    """Longest chain of NOR gates from any input to any output."""
    g = netlist.graph
    depth = {}
    for node in netlist.gates():
        depth[node] = 1 + max((depth.get(s, 0) for s in g.predecessors(node)), default=0)
    return max(depth.values(), default=0)
