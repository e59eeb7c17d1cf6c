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
from ..errors import Mech2SpiceError
from ..synthesis.ports import input_bits, output_bits, pack_inputs
from .model import MechModel
from .params import GateParams
from .stimulus import Stimulus
from ..synthesis.synth import Netlist, latch_inputs


# Largest fan-out measured to work (characterise.fanout_test, RK4 80 steps/period, 2000 periods): 12 loads all
# decode correctly with margin >= 0.09 and the driver's amplitude moves by <= 1.1e-3 u_R. Beyond it synthesis
# inserts NOR-pair buffers.
MAX_FANOUT = 12


LATCH_DELAY_PAIRS = 3      # identity pairs (x NOR 0) NOR 0 after each latch: output waits out the pulse


def build(netlist: Netlist, p: GateParams, delay_pairs: int = LATCH_DELAY_PAIRS) -> MechModel:
    """Build the mechanical model of a NOR netlist (gates, latches, input/clock drives, output probes)."""
    g = netlist.graph
    m = nor.new_model(p)
    blocks = {name: nor.add_nor(m, p, name) for name in netlist.gates()}
    wiring: list[tuple[str, str, int]] = [(src, name, d["pin"]) for name in blocks
                                          for src, _, d in g.in_edges(name, data=True)]
    outs: dict[str, nor.GateBlock] = dict(blocks)        # node -> block whose channel is its output
    clock_pairs = []
    for q in netlist.latches():
        d_src, f_src = latch_inputs(g, q)
        first, last, clocked, force = _add_latch(m, p, q, delay_pairs, g.nodes[q].get("inverted", 0),
                                                 forced=f_src is not None)
        outs[q] = last
        wiring.append((d_src, first.name, 0))
        if f_src is not None:
            wiring.append((f_src, force.name, 1))
        clock_pairs += clocked
    bit_drives: dict[str, list[int]] = {b: [] for b in input_bits(netlist)}
    every = {**blocks, **{b.name: b for b in m.design.latch_blocks}}
    for src, sink, pin in wiring:
        pair = every[sink].inputs[pin]
        kind = g.nodes[src]["kind"]
        if kind in ("nor", "latch"):
            nor.connect(m, p, outs[src].channel, pair)
        elif kind == "input":
            bit_drives[src] += nor.drive_pair(m, p, pair, p.levels.nominal0, f"in.{src}.{sink}")
        elif src == "const0":
            nor.drive_pair(m, p, pair, p.levels.nominal0, f"zero.{sink}")
        elif src == "const1":       # a latch taking a constant 1 (every NOR gate's 1 input is folded away)
            nor.drive_pair(m, p, pair, p.levels.nominal1, f"one.{sink}")
        else:
            raise Mech2SpiceError(f"gate {sink} is fed by {src} ({kind}); only gates, latches, inputs "
                                  "and constants can drive a gate")
    clock_drives = [d for pair in clock_pairs for d in nor.drive_pair(m, p, pair, p.levels.nominal0, "clk")]
    const_out = {}
    m.probes.clear()              # a design is observed at its outputs (internal DOFs by name if wanted)
    for bit in output_bits(netlist):
        (src,) = list(g.predecessors(bit))
        if g.nodes[src]["kind"] in ("nor", "latch"):
            m.add_probe(bit, outs[src].channel)
        else:
            const_out[bit] = 1 if src == "const1" else 0
    m.design.gates = list(every.values())
    m.design.blocks, m.design.bit_drives, m.design.const_outputs = blocks, bit_drives, const_out
    m.design.netlist, m.design.clock_drives = netlist, clock_drives
    m.design.latch_outputs = {q: outs[q] for q in netlist.latches()}
    return m


def _add_latch(m: MechModel, p: GateParams, q: str, delay_pairs: int, inverted: int = 0, forced: bool = False):
    """The paper's symmetric NOR latch (Fig. 5a) plus a delay line:
        ne = NOR(EN, F), a = NOR(D, ne) = !D.EN, b = NOR(m, EN) = !Q.!EN, m = NOR(a, b) = Q_next,
    so the loop m -> b -> m holds the bit, and D and Q each reach m through one gate.  The output is m
    after 2 * delay_pairs inverters (one more for an `inverted` latch, which stores the register's
    complement), so it changes only after the enable pulse is over.  From rest the loop settles with m at
    '0': a register powers up at `inverted`.  F (pin 1 of ne, the constant '0' unless `forced`) is the
    asynchronous reset: with F high ne is 0 whatever the clock, and the netlist keeps D low while F is high
    (synth._connect_latch), so a = 1 forces m to 0 through one gate, and the b side is left as it is.
    Returns (gate taking D on pin 0, gate whose channel is the output, the two clock pairs, the gate taking
    F on pin 1)."""
    mk = {k: nor.add_nor(m, p, f"{q}.{k}") for k in ("ne", "a", "b", "m")}
    for src, sink, pin in (("ne", "a", 1), ("m", "b", 0), ("a", "m", 0), ("b", "m", 1)):
        nor.connect(m, p, mk[src].channel, mk[sink].inputs[pin])
    last = mk["m"]
    for k in range(2 * delay_pairs + inverted):
        nxt = nor.add_nor(m, p, f"{q}.d{k}")
        nor.connect(m, p, last.channel, nxt.inputs[0])
        mk[f"d{k}"] = last = nxt
    for name, block in mk.items():                 # every free pin 1 is a constant '0'
        if (name == "ne" and not forced) or name.startswith("d"):
            nor.drive_pair(m, p, block.inputs[1], p.levels.nominal0, f"zero.{block.name}")
    m.design.latch_blocks.extend(mk.values())
    return mk["a"], last, [mk["ne"].inputs[0], mk["b"].inputs[1]], mk["ne"]


def drive_levels(model: MechModel, netlist: Netlist, p: GateParams, values: list[dict[str, int]]) \
        -> dict[int, np.ndarray]:
    """{drive index: (B,) amplitude} for input-port values, one dict per batch member."""
    out: dict[int, np.ndarray] = {}
    bits = [pack_inputs(netlist, v) for v in values]
    for bit, drives in model.design.bit_drives.items():
        amp = np.array([p.force(p.levels.nominal(b.get(bit, 0))) for b in bits])
        for d in drives:
            out[d] = amp
    return out


def stimulus(model: MechModel, netlist: Netlist, p: GateParams,
             segments: list[tuple[float, list[dict[str, int]]]], clock: list[list[int]] | None = None) -> Stimulus:
    """Piecewise-constant input values: [(start period, [values per batch member])]; `clock` gives the
    clock level (0/1) per segment and member, for clocked designs."""
    batch = len(segments[0][1])
    levels = []
    for k, (t, vals) in enumerate(segments):
        lv = drive_levels(model, netlist, p, vals)
        if model.design.clock_drives:
            ck = np.array([p.force(p.levels.nominal(c)) for c in (clock[k] if clock else [0] * batch)])
            lv.update({d: ck for d in model.design.clock_drives})
        levels.append((t * p.period, lv))
    return Stimulus.from_levels(model, levels, batch=batch)


def logic_depth(netlist: Netlist, delay_pairs: int = LATCH_DELAY_PAIRS) -> int:
    """Longest chain of NOR gates from any input or latch to any output or latch.  A forced latch's output
    follows its forcing input F without the clock, through ne, a, m and the delay line: a path through it
    counts those gates too."""
    from ..synthesis.synth import combinational_view
    g = combinational_view(netlist.graph)
    depth = {}
    for node in (netlist.schedule() if netlist.forced() else netlist.gates()):
        if g.nodes[node]["kind"] == "latch":
            f = latch_inputs(netlist.graph, node)[1]
            if f is not None:
                depth[node] = depth.get(f, 0) + 3 + 2 * delay_pairs + g.nodes[node].get("inverted", 0)
            continue
        depth[node] = 1 + max((depth.get(s, 0) for s in g.predecessors(node)), default=0)
    return max(depth.values(), default=0)
