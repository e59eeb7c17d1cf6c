"""The electrical analogy checked: ngspice (default SpiceOptions) against RK4 (80 steps/period) on four scenes,
measured into spice.json (mech2spice/reports/spice.py renders reports/spice.md from it).  One section, `all`
(~4 min).
"""
from __future__ import annotations

import time

from .. import data
from ..backends import rk4
from ..compare import agreement
from ..experiments import characterise
from ..experiments.scenes import ADDER_INPUTS
from ..physics import network, nor
from ..physics.params import DEFAULT
from ..physics.stimulus import Stimulus
from ..spice import oscillator_netlist as spice, runner as ngspice
from ..synthesis import synth
from ._common import conditions

SECTIONS = ("all",)


def compare(model, periods: int, stim: Stimulus) -> dict:
    """Settled amplitude and phase of every probe, ngspice (defaults) vs RK4 (80 steps/period)."""
    u_r = DEFAULT.u_r
    t0 = time.time()
    ref = rk4.integrate(model, periods, stimulus=stim)
    t_rk4 = time.time() - t0
    t0 = time.time()
    ng = ngspice.run_batch(model, periods, stimulus=stim)
    t_ng = time.time() - t0
    rows = [ng.probe_names.index(n) for n in ref.probe_names]
    a, b = ref.amp[-1], ng.amp[-1, rows]
    last = agreement(a, b, u_r)                    # the last period, as the checked-in report measured
    return {"probes": len(ref.probe_names), "cases": stim.batch, "periods": periods,
            "max_amp_err": last.amp, "max_phase_err": last.phase_deg,
            "rk4_s": t_rk4, "ngspice_s": t_ng}


def scenes() -> dict:
    """The suite's scenes by name, each (model, periods, stimulus): gate, 3-gate chain, fan-out 2, adder."""
    p = DEFAULT
    out = {}
    out["NOR gate, 4 input pairs"] = (nor.single_gate(p), 2500, characterise.truth_table_stimulus(p))
    ch = nor.chain(p, 3)
    out["3-gate chain, inputs 00"] = (ch, 1500, Stimulus.constant(ch))
    fo = nor.fanout(p, 2)
    out["fan-out 2, driver inputs 00"] = (fo, 2000, Stimulus.constant(fo))
    nl = synth.synthesize(data.verilog("adder2.v"))
    m = network.build(nl, p)
    vals = list(ADDER_INPUTS)
    out["2-bit adder, all 16 inputs"] = (m, 2900, network.stimulus(m, nl, p, [(0, vals)]))
    return out


def measure(section: str = "all", quick: bool = False) -> dict:
    """Every scene compared, with the ngspice options used and where it ran."""
    return {"scenes": {name: compare(*args) for name, args in scenes().items()},
            "options": repr(spice.SpiceOptions()), "conditions": conditions()}
