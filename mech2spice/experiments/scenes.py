"""Every experiment defined once: a model, its stimulus, a duration and what to read, used by the gate's
characterisation, the tests, the envelope validation and the reports.

A *scene* runs from rest on any engine; its batch members are the cases (input pairs, band-edge
levels, adder inputs).  `events` are the periods at which inputs change and `windows` the periods just
before which settled amplitudes are read.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .. import data
from ..inputs import read_json
from ..physics import network, nor
from ..physics.model import MechModel
from ..physics.params import DEFAULT, GateParams, Levels
from ..physics.stimulus import Stimulus
from ..synthesis import synth
from ..synthesis.ports import output_bits

PAIRS = [(0, 0), (1, 0), (0, 1), (1, 1)]                  # the truth table's input pairs, in this order


def mid(levels: Levels) -> float:
    """The threshold between the bands (u_R), for delays."""
    return (levels.band0[1] + levels.band1[0]) / 2


def edges(levels: Levels) -> tuple[float, ...]:
    """The band edges, as input levels."""
    return (*levels.band0, *levels.band1)


def cascade_edges(levels: Levels) -> list[tuple[float, float]]:
    """Constant input pairs at band edges, for level restoration: both low edges, high/low of '0', ..."""
    (lo0, hi0), (lo1, hi1) = levels.band0, levels.band1
    return [(lo0, lo0), (hi0, lo0), (hi0, hi0), (lo1, lo0), (hi1, hi0), (hi1, hi1), (lo1, lo1)]


# the default block's, for code that has no block at hand (a block's own: the functions above on p.levels)
LEVEL = {0: DEFAULT.levels.nominal0, 1: DEFAULT.levels.nominal1}   # a logic level as a drive force (F_R)
MID = mid(DEFAULT.levels)
EDGES = edges(DEFAULT.levels)
CASCADE_EDGES = cascade_edges(DEFAULT.levels)
FANOUT_CASES = [(0, 0, 0), (0, 0, 1), (1, 0, 0), (1, 0, 1)]   # (driver x1, driver x2, every load's x2)
ADDER_INPUTS = [{"a": a, "b": b} for a in range(4) for b in range(4)]   # all 16 sums of the 2-bit adder
ADDER_HOLD = 2900   # adder2.v's clocking.period_budget (logic depth 7), a constant so scenes need not import it
COUNTER_STEPS = [{"set": {"rst": 1}, "cycles": 1}, {"set": {"rst": 0, "en": 1}, "cycles": 3},
                 {"set": {"en": 0}, "cycles": 2}, {"set": {"en": 1}, "cycles": 2}, {"set": {"rst": 1}, "cycles": 1}]
FSM_X = [1, 1, 0, 1, 1, 0, 1, 0]                           # verilog/fsm.v's input sequence, one bit per cycle
FSM_STEPS = [{"set": {"rst": 1}, "cycles": 1}] + [{"set": {"rst": 0, "x": x}, "cycles": 1} for x in FSM_X]


def sqrt_steps() -> list[dict]:
    """The clocked stimulus of sqrt(2809), as shipped in verilog/sqrt_2809.json."""
    return read_json(data.verilog("sqrt_2809.json"), "stimulus file")


def latch_phases(pulse: int = 800, hold: int = 2500) -> list[tuple[str, int, int, int]]:
    """verilog/dff.v's pulse sequence (name, d, clock, periods): store 1, hold while d toggles, store 0, hold."""
    return [("power-up d=0", 0, 0, hold), ("store 1", 1, 1, pulse), ("settle", 1, 0, hold),
            ("hold, d=0", 0, 0, hold), ("hold, d=1", 1, 0, hold), ("hold, d=0", 0, 0, hold),
            ("store 0", 0, 1, pulse), ("settle", 0, 0, hold), ("hold, d=1", 1, 0, hold),
            ("hold, d=0", 0, 0, hold)]


@dataclass
class Scene:
    """One model, one stimulus from rest, a period count, the probes to read and what each batch member is."""
    name: str
    model: MechModel
    stimulus: Stimulus
    periods: int
    probes: list[str]
    members: list[str]                 # a label per batch member
    events: list[int]                  # periods at which inputs change (0: start from rest)
    windows: list[int]                 # settled amplitudes are read just before these periods
    description: str = ""
    extra: dict = field(default_factory=dict)


def input_amps(drives_of_inputs, levels: np.ndarray, p: GateParams) -> dict[int, np.ndarray]:
    """{drive index: (B,) amplitudes} for input pairs given levels (B, n_inputs) in units of F_R."""
    out = {}
    for k, drives in enumerate(drives_of_inputs):        # (spring, dashpot), or one per link of a block
        for d in drives:
            out[d] = levels[:, k] * p.f_r
    return out


def levels_stimulus(model: MechModel, p: GateParams, segments: list[tuple[int, np.ndarray]], extra=None) -> Stimulus:
    """Input-pair levels (B, 2) from each segment's start period on -> a stimulus on the model's input drives."""
    segs = []
    for t, lv in segments:
        amps = input_amps(model.design.input_drives, lv, p)
        amps.update(extra or {})
        segs.append((t * p.period, amps))
    return Stimulus.from_levels(model, segs, batch=segments[0][1].shape[0])


def nominal_levels(p: GateParams = DEFAULT) -> np.ndarray:
    """The four nominal input pairs of PAIRS as force levels (4, 2), in p's levels."""
    return np.array([[p.levels.nominal(a), p.levels.nominal(b)] for a, b in PAIRS], float)


def gate_scene(p: GateParams = DEFAULT, which: str = "nominal", periods: int = 2500) -> Scene:
    """Single gate from rest: the 4 nominal input pairs, or all 16 pairs of band-edge levels."""
    e = edges(p.levels)
    pairs = [tuple(x) for x in nominal_levels(p)] if which == "nominal" else [(a, b) for a in e for b in e]
    m = nor.single_gate(p)
    return Scene(f"gate_{which}", m, levels_stimulus(m, p, [(0, np.array(pairs, float))]), periods, ["g0"],
                 [f"{a:g},{b:g}" for a, b in pairs], [0], [periods],
                 f"single NOR gate, {'nominal' if which == 'nominal' else 'band-edge'} inputs, {periods} periods from rest")


def chain_scene(p: GateParams = DEFAULT, hold: int = 1500, edges: bool = True) -> Scene:
    """3-gate chain ((x1 NOR x2) NOR 0) NOR 0: member 0 inputs 00 -> 10 -> 00 (delays both ways), the others
    constant band-edge inputs (level restoration)."""
    m = nor.chain(p, 3)
    n0, n1 = p.levels.nominal0, p.levels.nominal1
    lv0 = np.array([[n0, n0]] + ([list(e) for e in cascade_edges(p.levels)] if edges else []))
    lv1 = lv0.copy()
    lv1[0] = [n1, n0]
    st = levels_stimulus(m, p, [(0, lv0), (hold, lv1), (2 * hold, lv0)])
    return Scene("chain3", m, st, 3 * hold, ["g0", "g1", "g2"],
                 ["00->10->00"] + [f"{a:g},{b:g}" for a, b in lv0[1:]], [0, hold, 2 * hold],
                 [hold, 2 * hold, 3 * hold],
                 f"3-gate chain ((x1 NOR x2) NOR 0) NOR 0, hold {hold} periods per input setting")


def fanout_scene(p: GateParams = DEFAULT, n_loads: int = 2, periods: int = 2500) -> Scene:
    """One driver feeding n_loads gates: driver 00 / 10, every load's second input 0 / 1 (FANOUT_CASES)."""
    m = nor.fanout(p, n_loads)
    level = p.levels.nominal
    lv = np.array([[level(a), level(b)] for a, b, _ in FANOUT_CASES])
    amps = input_amps(m.design.input_drives, lv, p)
    for pair in m.design.load_drives:
        amps.update(input_amps([pair], np.array([[level(c)] for *_, c in FANOUT_CASES]), p))
    st = Stimulus.from_levels(m, [(0.0, amps)], batch=len(FANOUT_CASES))
    return Scene(f"fanout{n_loads}", m, st, periods, list(m.probes),
                 [f"drv {a}{b}, loads x2={c}" for a, b, c in FANOUT_CASES], [0], [periods],
                 f"one driver feeding {n_loads} loads, {periods} periods from rest")


def adder_scene(p: GateParams = DEFAULT, hold: int = ADDER_HOLD) -> Scene:
    """verilog/adder2.v: inputs 0 for `hold` periods (default: its period budget), then each of the 16 (a, b)."""
    nl = synth.synthesize(data.verilog("adder2.v"))
    m = network.build(nl, p)
    st = network.stimulus(m, nl, p, [(0, [{}] * len(ADDER_INPUTS)), (hold, ADDER_INPUTS)])
    probes = [b for b in output_bits(nl) if b in m.probes]
    return Scene("adder2", m, st, 2 * hold, probes, [f"a={v['a']} b={v['b']}" for v in ADDER_INPUTS], [0, hold],
                 [hold, 2 * hold], f"2-bit adder (17 gates), inputs 0 for {hold} periods then (a, b)",
                 {"netlist": nl, "values": ADDER_INPUTS})


def latch_scene(p: GateParams = DEFAULT, pulse: int = 800, hold: int = 2500) -> Scene:
    """verilog/dff.v (the paper's NOR latch + 3 delay pairs) through latch_phases, probing Q and the loop node."""
    nl = synth.synthesize(data.verilog("dff.v"))
    m = network.build(nl, p)
    phases = latch_phases(pulse, hold)
    starts = [int(x) for x in np.cumsum([0] + [ph[3] for ph in phases])]
    st = network.stimulus(m, nl, p, [(t, [{"d": d}]) for t, (_, d, _, _) in zip(starts, phases)],
                          clock=[[c] for _, _, c, _ in phases])
    m.add_probe("q0.m.C", m.index("q0.m.C"))          # the loop node's channel
    return Scene("latch", m, st, starts[-1], ["q[0]", "q0.m.C"], ["dff"], starts[:-1], starts[1:],
                 "verilog/dff.v latch (+3 delay pairs) through its store/hold pulse sequence", {"phases": phases})
