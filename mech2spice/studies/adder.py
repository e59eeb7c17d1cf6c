"""The 2-bit adder from Verilog, all 16 sums on RK4 (paper Fig. 4), measured into adder.json
(mech2spice/reports/adder.py renders reports/adder.md from it).  One section, `all` (~1 min).
"""
from __future__ import annotations

import sys
import time

import numpy as np

from .. import data, simulation
from ..backends import logic, make_engine
from ..synthesis import ports
from ..physics import network
from ..physics.params import DEFAULT
from ..synthesis import synth
from ._common import conditions
from ..experiments.scenes import ADDER_INPUTS

SECTIONS = ("all",)
AMPS_EVERY = 10         # periods between the stored amplitudes: the figure draws ~25 periods per pixel


def run(design=data.verilog("adder2.v"), hold: int | None = None) -> dict:
    """Inputs 0 for the first half, then each of the 16 pairs (one RK4 batch)."""
    p = DEFAULT
    nl = synth.synthesize(design)
    model = network.build(nl, p)
    hold = hold or simulation.period_budget(nl)
    vals = list(ADDER_INPUTS)
    stim = network.stimulus(model, nl, p, [(0, [{}] * 16), (hold, vals)])
    t0 = time.time()
    probes = [b for b in ports.output_bits(nl) if b in model.probes]
    r = make_engine("rk4").run(model, 2 * hold, stim, probes=probes, progress=sys.stderr.isatty())
    wall = time.time() - t0
    amps = np.abs(r.amp) / p.u_r                              # (P, 3, 16)
    names = probes
    rows = []
    for b, v in enumerate(vals):
        d = simulation.decode(nl, {n: float(amps[-20:, k, b].mean()) for k, n in enumerate(names)}, {})
        rows.append({"inputs": v, **d, "expected": logic.evaluate(nl, v)["s"],
                     "amplitudes": {n: float(amps[-1, k, b]) for k, n in enumerate(names)}})
    return {"netlist": nl, "counts": {"gates": len(nl.gates()), **model.counts()}, "hold": hold,
            "amps": amps, "names": names, "rows": rows, "wall_s": wall, "depth": network.logic_depth(nl)}


def measure(section: str = "all", quick: bool = False) -> dict:
    """run() as JSON: the amplitudes every AMPS_EVERY periods (u_R, 3 decimals: 1/50 of a pixel), without the
    netlist."""
    res = run()
    del res["netlist"]
    res["amps_every"] = AMPS_EVERY
    res["amps"] = np.round(res["amps"][AMPS_EVERY - 1::AMPS_EVERY], 3)
    res["conditions"] = conditions()
    return res
