"""Why a block's latched networks do not settle (issue #27, docs/design.md "In networks"): the measurements.

    python scripts/held_diagnosis.py PARAMS [--periods N]

On the envelope, for block PARAMS (a preset or a block file), prints as JSON:
  * held: counter4 at reset, sqrt(2809) at reset and a toggle flip-flop (q <= ~q), each held with the clock low
    for N periods: the largest swing of any gate's output over the last 4000 periods and its period, and the
    fixed point Newton finds from the states of the next 120 periods (the first that converges) with its
    leading mode (growth per drive period > 0: the loop circles a Hopf point);
  * open: chains of 1-3 gates whose later gates have '0' or '1' on their other input, and counter4's
    next-state logic with its q driven from outside: the leading growth rate of each (no loop).
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

from mech2spice.backends import make_engine
from mech2spice.data import verilog
from mech2spice.physics import network, nor, stability
from mech2spice.physics.envelope import Envelope
from mech2spice.physics.params import load_params
from mech2spice.synthesis import synth

TOGGLE = "module toggle(input clk, output reg q);\n  always @(posedge clk) q <= ~q;\nendmodule\n"
NEXT_STATE = ("module next_state(input rst, input en, input [3:0] q, output [3:0] d);\n"
              "  assign d = rst ? 4'd0 : (en ? q + 4'd1 : q);\nendmodule\n")
TAIL = 4000
ENGINE = make_engine("envelope")


def _mode(v: stability.Verdict) -> dict:
    return {"fixed_point_found": v.converged, "growth_per_period": v.growth_rate, "mode_period": v.mode.period,
            "mode_dofs": v.mode.dofs[:6]}


def held(p, design: str, values: dict, periods: int) -> dict:
    """The design held at `values` with the clock low: swing and period of its gates, the fixed point's mode."""
    nl = synth.synthesize(design)
    m = network.build(nl, p)
    stim = network.stimulus(m, nl, p, [(0, [values])], clock=[[0]])
    probes = []
    for g in m.design.gates:
        probes.append(f"ch:{g.name}")
        m.add_probe(probes[-1], g.channel)
    run = ENGINE.run(m, periods, stim, probes=probes)
    tail = np.abs(run.amp[-TAIL:, :, 0]) / p.u_r
    k = int(np.ptp(tail, axis=0).argmax())
    x = tail[:, k] - tail[:, k].mean()
    peak = int(np.abs(np.fft.rfft(x))[1:].argmax()) + 1
    F = Envelope.of(m).forcing(stim.at((periods - 1e-6) * m.period))[:, 0]
    state, t = run.state, periods
    for _ in range(12):                  # Newton from a few points of the orbit: one of them reaches it
        part = ENGINE.run(m, 10, stim, state=state, start_period=t, probes=probes[:1])
        state, t = part.state, t + 10
        A, s = ENGINE.phasors(m, state, t)
        v = stability.verdict(m, A[:, 0], s[:, 0], F, {})
        if v.converged:
            break
    return {"gates": len(probes), "largest_swing_u_r": float(np.ptp(tail[:, k])), "at": probes[k][3:],
            "swing_period": TAIL / peak, **_mode(v)}


def _settled_mode(m, stim=None, periods: int = 8000) -> dict:
    run = ENGINE.run(m, periods, stim, probes=[next(iter(m.probes))])
    A, s = ENGINE.phasors(m, run.state, periods)
    amps = stim.at(0.0) if stim is not None else np.array([d.amplitude for d in m.drives])
    return _mode(stability.verdict(m, A[:, 0], s[:, 0], Envelope.of(m).forcing(amps)[:, 0], {}))


def chain(p, x: tuple[int, int], others: tuple[int, ...]):
    """x1 NOR x2, then one gate per entry of `others`, each fed by the last and with that bit on its other pin."""
    lv = p.levels
    m = nor.new_model(p)
    gates = [nor.add_nor(m, p, f"g{k}") for k in range(len(others) + 1)]
    nor.drive_pair(m, p, gates[0].inputs[0], lv.nominal(x[0]), "x1")
    nor.drive_pair(m, p, gates[0].inputs[1], lv.nominal(x[1]), "x2")
    for k, bit in enumerate(others, 1):
        nor.connect(m, p, gates[k - 1].channel, gates[k].inputs[0])
        nor.drive_pair(m, p, gates[k].inputs[1], lv.nominal(bit), f"z{k}")
    return m


def open_paths(p, tmp: Path) -> dict:
    out = {}
    for x in ((0, 0), (1, 0)):
        for others in ((), (0,), (1,), (0, 0), (0, 1), (1, 1)):
            out[f"chain {x} then {others}"] = _settled_mode(chain(p, x, others))["growth_per_period"]
    nl = synth.synthesize(str(tmp / "next_state.v"))
    m = network.build(nl, p)
    for vals in ({"rst": 1}, {"en": 1}, {"en": 1, "q": 5}):
        stim = network.stimulus(m, nl, p, [(0, [vals])])
        out[f"next_state {vals}"] = _settled_mode(m, stim)["growth_per_period"]
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("params")
    ap.add_argument("--periods", type=int, default=20000)
    args = ap.parse_args()
    p = load_params(args.params)
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        (tmp / "toggle.v").write_text(TOGGLE)
        (tmp / "next_state.v").write_text(NEXT_STATE)
        res = {"params": args.params, "periods": args.periods,
               "held": {"toggle": held(p, str(tmp / "toggle.v"), {}, args.periods),
                        "counter4 at reset": held(p, str(verilog("counter4.v")), {"rst": 1}, args.periods),
                        "sqrt(2809) at reset": held(p, str(verilog("sqrt.v")), {"rst": 1, "n": 2809}, args.periods)},
               "open": open_paths(p, tmp)}
    print(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
