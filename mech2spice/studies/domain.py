"""The operating domain of the gate, the 2-bit adder and the processor (30 sieve cycles): where each works as
the drive frequency, the supply drive and a common-mode stiffness drift move away from nominal, without and
with element spread (experiments/domain.py), measured into domain.json (reports/domain.py renders it).

Sections: `gate` (two 7x7 maps: frequency x supply, frequency x drift; ~10 min), `adder` (frequency x supply,
5x5, ~15 min), `cpu` (frequency x supply, 3x3, ~15 min).  `quick`: 3x3 grids, fewer samples, 5 cycles.
"""
from __future__ import annotations

from pathlib import Path

from ._common import conditions, read_json, sections, timed_section, write_json

SECTIONS = ("gate", "adder", "cpu")
PARAMS = "centered_fc2"           # the processor's block (docs/design.md)
SPREAD = {"sigma": 0.01, "trim": "fcb", "residual": 1e-4, "seed": 7}   # issue 36: the balance trim
CYCLES = 30

# (map name, x axis, y axis, held) per section; axes (name, lo, hi, n) at full size
PLANS = {
    "gate": [("freq_amp", ("freq", -1e-3, 1e-3, 7), ("amp", -0.1, 0.1, 7), {"drift": 0.0}),
             ("freq_drift", ("freq", -1e-3, 1e-3, 7), ("drift", -2e-3, 2e-3, 7), {"amp": 0.0})],
    "adder": [("freq_amp", ("freq", -2e-3, 2e-3, 5), ("amp", -0.2, 0.2, 5), {"drift": 0.0})],
    "cpu": [("freq_amp", ("freq", -5e-4, 5e-4, 3), ("amp", -0.05, 0.05, 3), {"drift": 0.0})],
}
SAMPLES = {"gate": 8, "adder": 4, "cpu": 2}


def _axis(spec, quick: bool) -> tuple[str, list[float]]:
    import numpy as np
    name, lo, hi, n = spec
    n = 3 if quick else n
    return name, [float(v) for v in np.linspace(lo, hi, n)]


def evaluator(section: str, quick: bool):
    """The section's evaluator, with its spread samples."""
    from ..experiments import domain
    from ..physics.params import load_params
    p = load_params(PARAMS)
    s = dict(sigma=SPREAD["sigma"], samples=1 if quick else SAMPLES[section], seed=SPREAD["seed"],
             trim=SPREAD["trim"], residual=SPREAD["residual"])
    if section == "gate":
        return domain.GateDomain(p, **s)
    if section == "adder":
        from .. import data
        from ..experiments.montecarlo import all_vectors
        from ..synthesis import synth
        nl = synth.synthesize(data.verilog("adder2.v"))
        return domain.DesignDomain(nl, p, all_vectors(nl), "envelope", **s)
    from .. import data
    return domain.CpuDomain(str(data.program("sieve.asm")), 5 if quick else CYCLES, p, "envelope", **s)


def measure(section: str, quick: bool = False, progress=False) -> dict:
    """One section's maps: {map name: experiments.domain.domain_map's dict}."""
    from ..experiments import domain
    ev = evaluator(section, quick)
    return {name: {**domain.domain_map(ev, _axis(x, quick), _axis(y, quick), held, progress),
                   "params": PARAMS, "spread": SPREAD}
            for name, x, y, held in PLANS[section]}


def measure_into(path: Path, only=None, quick: bool = False, progress=False) -> dict:
    """Measure the sections in `only` (default all), merge them into the JSON at `path` and save it."""
    d = read_json(path, {})
    for name in sections("domain", only, SECTIONS):
        timed_section(d, name, lambda: measure(name, quick, progress))
        d["conditions"] = conditions()
        d["quick"] = quick
        write_json(path, d)
    return d
