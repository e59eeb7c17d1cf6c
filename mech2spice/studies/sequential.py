"""The mechanical latch, a counter, the FSM and sqrt(2809) (paper Figs. 5, 6), measured into sequential.json
(mech2spice/reports/sequential.py renders sequential.md, sqrt.md and their figures from it).  One section,
`all` (~4 min; `sqrt_rk4`: also the ~20-min RK4 square root).
"""
from __future__ import annotations

import sys

import numpy as np

from .. import data, simulation
from ..backends import engine_class, envelope
from ..experiments import characterise
from ..experiments.scenes import COUNTER_STEPS, FSM_STEPS, FSM_X, sqrt_steps
from ..physics import network
from ..physics.params import DEFAULT
from ..synthesis import synth
from ._common import conditions

SECTIONS = ("all",)
CURVE_POINTS = 2000       # at most this many stored points per curve: ~2 per pixel of the 11-inch figures


def curve(amp) -> dict:
    """Per-period amplitudes (periods, ...) thinned to at most CURVE_POINTS rows, 4 decimals (u_R)."""
    amp = np.asarray(amp, float)
    every = max(1, -(-amp.shape[0] // CURVE_POINTS))
    return {"every": every, "amplitude": np.round(amp[every - 1::every], 4)}


def _run(r: dict, drawn: bool) -> dict:
    """A clocked run as JSON: its trace, wall time, periods and, where the report draws it, its thinned waveform."""
    out = {k: r[k] for k in ("trace", "wall_s", "periods") if k in r}
    if drawn and "waveform" in r:
        w = r["waveform"]
        out["waveform"] = {**curve(w.amplitude), "reads": list(w.reads), "probes": list(w.probes)}
    return out


def _clocked(design: str, steps: list[dict], backends=("logic", "envelope"), drawn: str = "") -> tuple:
    nl = synth.synthesize(data.verilog(design))
    cycles = simulation.expand_steps(steps)
    timing = simulation.clock_timing(nl)
    runs = {}
    for b in backends:
        runs[b] = simulation.run_clocked_logic(nl, cycles) if not engine_class(b).capabilities.physical else \
            simulation.run_clocked_physical(nl, DEFAULT, cycles, b, timing, progress=sys.stderr.isatty(),
                                          waveform=True)
    return nl, {b: _run(r, b == drawn) for b, r in runs.items()}, timing


def _latch(backend: str, drawn: bool = False, **kw) -> dict:
    r = characterise.latch_sequence(DEFAULT, backend, **kw)
    keep = {k: r[k] for k in ("phases", "starts", "pulse", "backend", "decoded", "output_delays")}
    return {**keep, **(curve(r["amplitude"]) if drawn else {})}


def measure(section: str = "all", quick: bool = False, sqrt_rk4: bool = False) -> dict:
    """The latch on RK4 and the envelope, a short enable pulse, the counter, the FSM and the square root."""
    p = DEFAULT
    res = {"latch": _latch("rk4", drawn=True), "latch_envelope": _latch("envelope"), "short_pulse": _latch("envelope", pulse=300)}
    _, res["counter"], res["counter_timing"] = _clocked("counter4.v", COUNTER_STEPS, ("logic", "rk4", "envelope"))
    _, res["fsm"], res["fsm_timing"] = _clocked("fsm.v", FSM_STEPS, ("logic", "rk4"), drawn="rk4")
    sq_nl, res["sqrt"], res["sqrt_timing"] = _clocked("sqrt.v", sqrt_steps(),
                                                      ("logic", "envelope") + (("rk4",) if sqrt_rk4 else ()),
                                                      drawn="envelope")
    model = network.build(sq_nl, p)
    res["sqrt_counts"] = {"gates": len(model.design.gates), **model.counts()}
    res.update(sqrt_latches=len(sq_nl.latches()), sqrt_logic=len(sq_nl.gates()), sqrt_rk4=sqrt_rk4, fsm_x=FSM_X,
               envelope_step=envelope.DEFAULT_STEP, clocked_settle_tol=simulation.CLOCKED_SETTLE_TOL,
               conditions=conditions())
    return res
