"""`verify --vcd FILE`: the co-simulation and the proof's counterexample as one VCD waveform.

One file, two time ranges (docs/waveforms.md): the co-simulation at times 0 .. n-1 (one per vector or
cycle), then, when the proof reported a counterexample, one empty time and the counterexample's replay,
one time per cycle.  Under the top module's scope, per output port, the source (Icarus) and the network
(the backend) side by side in scopes `source` and `network`, and a `mismatch` vector marking the bits that
differ; the inputs; amplitudes in u_R as reals on a physical backend.  Every name goes through ids.vcd.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from . import identifiers as ids
from .waveform import Waveform

if TYPE_CHECKING:
    from .synthesis.synth import Netlist


def verify_waveform(netlist: Netlist, result: dict) -> tuple[Waveform, dict]:
    """verify's result (computed with keep_trace=True) as a Waveform, and the time range of each section:
    {"cosim": [first, last], "counterexample": [first, last] or None}."""
    trace = result["cosim"]["trace"]
    n = len(trace)
    eq = result.get("equivalence") or {}
    cex = eq.get("counterexample") or []
    start = n + 1                                   # one empty (all x) time between the two sections
    times = list(range(n)) + ([n, *range(start, start + len(cex))] if cex else [])
    sections = {"cosim": [0, n - 1], "counterexample": [start, start + len(cex) - 1] if cex else None}
    wave = Waveform(times, comment=_comment(result, sections))
    top = ids.vcd(netlist.top)
    pad = len(times) - n
    key = "cycle" if "cycle" in (trace[0] if trace else {}) else "vector"
    wrong = {(m[key], m["bit"]) for m in result["cosim"]["mismatches"]}
    _ports(wave, [top], netlist, [s["inputs"] for s in trace] + [None] * pad,
           [s["source"] for s in trace] + [None] * pad, [s["network"] for s in trace] + [None] * pad,
           [{b for (k, b) in wrong if k == i} for i in range(n)] + [None] * pad)
    if trace and "inputs_at_read" in trace[0]:          # clocked: what a path from an input saw at the read
        for port, width in netlist.inputs.items():
            wave.add_wire([top, "inputs_at_read"], ids.vcd(port), width,
                          [s["inputs_at_read"][port] for s in trace] + [None] * pad)
    for bit in trace[0].get("amplitudes") or {} if trace else {}:
        port, _, index = bit.rpartition("[")
        values = [s["amplitudes"][bit] for s in trace]
        wave.add_real([top, "amplitudes"], f"{ids.vcd(port)}[{index}", values + values[-1:] * pad)
    if cex:
        _counterexample(wave, top, netlist, cex, eq.get("replay") or {}, n + 1)
    return wave, sections


def _ports(wave: Waveform, scope: list[str], netlist: Netlist, inputs: list, source: list, network: list,
           differ: list) -> None:
    """Scopes inputs, source, network and mismatch under `scope`: per time an entry of each list (None: x)."""
    for port, width in netlist.inputs.items():
        wave.add_wire([*scope, "inputs"], ids.vcd(port), width, [None if i is None else i[port] for i in inputs])
    for port, width in netlist.outputs.items():
        name = ids.vcd(port)
        wave.add_wire([*scope, "source"], name, width, [None if s is None else s[port] for s in source])
        wave.add_wire([*scope, "network"], name, width, [None if s is None else s[port] for s in network])
        wave.add_bits([*scope, "mismatch"], name, [[None] * width if d is None else
                                                   [int(f"{port}[{i}]" in d) for i in range(width)] for d in differ])


def _counterexample(wave: Waveform, top: str, netlist: Netlist, cex: list[dict], replay: dict, first: int) -> None:
    """The counterexample's inputs and its replay (Icarus vs the logic backend) per cycle, from time `first`;
    `mismatch` marks the bits the source defines (0/1) and the network has otherwise, as the replay judges."""
    steps = replay.get("trace") or [{}] * len(cex)
    before = [None] * first
    source = [s.get("source") for s in steps]
    network = [s.get("network") for s in steps]
    differ = [None if s is None or g is None else
              {f"{p}[{w - 1 - j}]" for p, w in netlist.outputs.items() for j in range(w)
               if s[p][j] in "01" and g[p][j] != s[p][j]} for s, g in zip(source, network)]
    _ports(wave, [top, "counterexample"], netlist, before + [c["inputs"] for c in cex], before + source,
           before + network, before + differ)


def _comment(result: dict, sections: dict) -> str:
    co, eq = result["cosim"], result.get("equivalence") or {}
    a, b = sections["cosim"]
    unit = "cycle (inputs of cycle k, outputs read after edge k)" if "cycles" in co else "input vector"
    text = (f"mech2spice verify {ids.vcd(result['top'])}: times {a}-{b} the co-simulation, one per {unit}: inputs, "
            f"source (Icarus: 0 1 x z), network ({co['backend']}; x: an invalid bit), mismatch (1: a compared "
            "bit that differs)" + (", amplitudes in u_R" if co["trace"] and "amplitudes" in co["trace"][0] else ""))
    if sections["counterexample"]:
        a, b = sections["counterexample"]
        text += (f"; times {a}-{b} scope counterexample: the proof's counterexample ({eq['status']}) replayed, "
                 "source Icarus from power-up, network on the logic backend from all-zero latches")
    return text
