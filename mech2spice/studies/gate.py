"""The NOR gate against the paper's six requirements, and why the printed parameters fail: everything
reports/gate.md shows, measured into gate.json (mech2spice/reports/gate.py renders it).

One section, `all` (~1 min; `quick`: the characterisation's shorter runs).
"""
from __future__ import annotations

import numpy as np

from ..experiments import characterise
from ..physics.params import DEFAULT, PRINTED, GateParams
from ._common import conditions

SECTIONS = ("all",)
MAP_GRID = 71
WIDE_FANOUT = (6, 12)
CURVE_POINTS = 4000


def _figures(out: dict) -> dict:
    """The transient and cascade arrays the figures draw (characterise keeps whole runs beside them)."""
    figs = out.pop("_figures", {})
    tr, cas = figs.get("transient", {}), figs.get("cascade", {})
    def curves(d: dict) -> dict:          # <= CURVE_POINTS points, 1e-4 u_R: below a pixel of the 10-inch figures
        every = max(1, -(-len(d.get("t_periods", ())) // CURVE_POINTS))
        return {k: np.round(np.asarray(d[k])[every - 1::every], 4) for k in ("t_periods", "amplitude") if k in d}
    return {"transient": {**{k: tr[k] for k in ("sequence", "hold") if k in tr}, **curves(tr)},
            "cascade": {**{k: cas[k] for k in ("hold", "delay_periods", "restoration") if k in cas}, **curves(cas)}}


def complete(out: dict, log=lambda m: None) -> dict:
    """What the report shows beyond `characterise`'s result `out` for one parameter set: its steady-state map,
    the step study at 40 steps, the wide fan-out, and the printed set for comparison."""
    p = GateParams(**out["params"])
    log("report: steady-state map")
    xs, amp, nstable = characterise.steady_map(p, n=MAP_GRID)
    log("report: step study and wide fan-out")
    conv40 = characterise.convergence(p, 1500, 40)
    wide = [characterise.fanout_test(p, n, periods=2000) for n in WIDE_FANOUT]
    log("report: printed parameter set")
    printed = characterise.characterise(PRINTED, quick=True)
    printed.pop("_figures", None)
    scan = characterise.omega_scan(PRINTED, np.linspace(0.3, 60, 1200))
    return {"characterise": out, "figures": _figures(out),
            "map": {"grid": MAP_GRID, "xs": xs, "out": np.round(amp, 6), "nstable": nstable},
            "conv40": conv40, "wide_fanout": wide, "printed": printed, "printed_scan": scan,
            "conditions": conditions()}


def measure(section: str = "all", quick: bool = False, log=lambda m: None) -> dict:
    """The default gate characterised (`quick`: shorter runs) and completed for the report."""
    return complete(characterise.characterise(DEFAULT, quick=quick, log=log), log)
