"""The operating domain: where a design works as its operating point moves away from nominal.

Three axes, each a relative change from the design's own nominal value (0 = nominal):

* `freq`: the drive frequency (every drive, the clock schedule counted in drive periods as before).  The
  structure stays as built: its springs, dashpots (the coupling dashpots k/omega of the nominal omega)
  and masses do not follow the drive.
* `amp`: the supply drive, the source force F_C of every gate block.  Inputs and clock drives keep their
  nominal logic levels (they come from other circuits).
* `drift`: every stiffness times (1 + drift), a common-mode temperature drift (physics/spread.drifted,
  the same as `--drift`).

A point works for the gate when the loaded gate's margin over the valid input region is positive
(experiments/tolerance.py: inputs anywhere in the bands give outputs in the band NOR asks for; the loaded
gate's upstream stand-ins are re-driven so that their amplitudes stay the input levels at the shifted
point), for a combinational design when every output of every input vector equals the logic oracle's
(experiments/montecarlo.DesignMC), and for the processor when every one of `cycles` cycles equals the
instruction-set simulator's (experiments/mc_clocked.CpuMC).  With a spread the same samples (seeds) are
drawn at every point, so the map's yield differences are the operating point's alone.
"""
from __future__ import annotations

import math
import re
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..errors import Mech2SpiceError
from ..physics import spread
from ..physics.model import Drive, MechModel
from ..physics.stimulus import Stimulus
from .mc_clocked import CpuMC, sampled
from .montecarlo import DesignMC, SpreadSpec, noise_seed, spec_of
from .tolerance import Sampler, wilson

AXES = {
    "freq": "drive frequency, relative change",
    "amp": "supply drive F_C, relative change",
    "drift": "common-mode stiffness drift (temperature), relative change",
}
MAX_POINTS = 400            # grid points of one map (a processor point is ~a minute)


@dataclass(frozen=True)
class Point:
    """An operating point: relative changes of the drive frequency, the supply drive and every stiffness."""
    freq: float = 0.0
    amp: float = 0.0
    drift: float = 0.0

    def validate(self) -> None:
        for name in AXES:
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and -1 < v < 1):
                raise Mech2SpiceError(f"operating point {name} = {v!r}: expected a relative change in (-1, 1)")


# --------------------------------------------------------------------------- parsing
def _finite(text: str, what: str) -> float:
    """A sweep bound as a finite number (inf and nan made numpy warn and the axis read nan)."""
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"{what} is {text.strip()!r}, not a number") from None
    if not math.isfinite(value):
        raise ValueError(f"{what} is {text.strip()!r}: a finite number is needed")
    return value


def parse_sweep(text: str) -> tuple[str, list[float]]:
    """`NAME=LO:HI:N` (N evenly spaced values from LO to HI) or `NAME=V` (one value): (name, values)."""
    name, eq, spec = str(text).partition("=")
    name = name.strip()
    if not eq or name not in AXES:
        raise Mech2SpiceError(f"--sweep {text!r}: expected NAME=LO:HI:N or NAME=VALUE with NAME one of "
                              f"{', '.join(AXES)}")
    parts = spec.split(":")
    try:
        if len(parts) == 1:
            values = [_finite(parts[0], "VALUE")]
        elif len(parts) == 3:
            lo, hi = _finite(parts[0], "LO"), _finite(parts[1], "HI")
            if not re.fullmatch(r"\s*\d{1,3}\s*", parts[2]) or not 1 <= int(parts[2]) <= 101:
                raise ValueError(f"N is {parts[2].strip()!r}: a whole number of points, 1 to 101")
            n = int(parts[2])
            values = [lo] if n == 1 else [float(v) for v in np.linspace(lo, hi, n)]
        else:
            raise ValueError("expected LO:HI:N or one value")
    except ValueError as err:
        raise Mech2SpiceError(f"--sweep {text!r}: {err}") from None
    for v in values:
        Point(**{name: v}).validate()
    return name, values


def grid_axes(sweeps: list[str]) -> tuple[tuple[str, list[float]], tuple[str, list[float]], dict]:
    """The map's two swept axes (x, y) and the fixed values of the others from the --sweep arguments:
    exactly two axes with several values; an axis given one value is fixed there, one not given is 0."""
    parsed = [parse_sweep(s) for s in sweeps]
    names = [n for n, _ in parsed]
    if len(set(names)) != len(names):
        raise Mech2SpiceError(f"--sweep: an axis is given twice ({', '.join(names)})")
    swept = [(n, v) for n, v in parsed if len(v) > 1]
    if len(swept) != 2:
        raise Mech2SpiceError(f"--sweep: give exactly two axes with several values (NAME=LO:HI:N), got "
                              f"{len(swept)}; an axis with one value (NAME=V) is held there")
    fixed = {n: 0.0 for n in AXES}
    fixed.update({n: v[0] for n, v in parsed if len(v) == 1})
    for n, _ in swept:
        del fixed[n]
    if len(swept[0][1]) * len(swept[1][1]) > MAX_POINTS:
        raise Mech2SpiceError(f"--sweep: at most {MAX_POINTS} grid points in one map")
    return swept[0], swept[1], fixed


# --------------------------------------------------------------------------- the shifted model
def supply_drives(model: MechModel) -> list[int]:
    """The drives of the gate blocks' sources (F_C): drives on a block's source DOF named '<gate>.src'."""
    sources = {g.source for g in model.design.gates}
    return [k for k, d in enumerate(model.drives) if d.dof in sources and d.name.endswith(".src")]


def shifted(model: MechModel, point: Point, supply: list[int]) -> MechModel:
    """`model` at operating point `point`: drifted stiffnesses, the drive frequency moved, the `supply`
    drives scaled; a copy, nothing shared with `model`."""
    point.validate()
    m = spread.drifted(model, point.drift)
    drives = list(m.drives)
    for k in supply:
        d = drives[k]
        drives[k] = Drive(d.dof, d.amplitude * (1 + point.amp), d.phase, d.name)
    return replace(m, omega=m.omega * (1 + point.freq), names=list(m.names), mass=list(m.mass),
                   k_total=list(m.k_total), c_total=list(m.c_total), slow=list(m.slow), springs=list(m.springs),
                   dashpots=list(m.dashpots), quads=list(m.quads), drives=drives, probes=dict(m.probes))


def _supply_factor(n_drives: int, supply: list[int], point: Point) -> np.ndarray:
    f = np.ones(n_drives)
    f[supply] = 1 + point.amp
    return f


# --------------------------------------------------------------------------- evaluators
def _spread_result(passes: list[bool]) -> dict:
    k, n = int(sum(passes)), len(passes)
    return {"passed": k, "samples": n, "yield": k / n if n else None, "yield_ci95": list(wilson(k, n))}


class GateDomain:
    """The loaded gate (experiments/tolerance.py's model and margin) at each operating point; with
    `sigma`, `samples` spread samples (trimmed as asked) at each point too."""

    design = "gate"

    def __init__(self, p, sigma: float = 0.0, samples: int = 0, seed: int = 0, trim: str = "none",
                 residual: float = 0.0):
        self.p, self.sigma = p, sigma
        self.sampler = Sampler(p, max(samples, 1), seed, trim=trim, residual=residual)
        self.samples = samples if sigma else 0
        lg = self.sampler.base
        self.supply = [k for k, d in enumerate(lg.model.drives)
                       if d.dof == lg.gate.source and d.name.endswith(".src")]

    def _at(self, model: MechModel, point: Point) -> MechModel:
        """The sample at `point`, its upstream stand-ins re-driven so their amplitudes stay the input levels."""
        out = shifted(model, point, self.supply)
        drives = list(out.drives)
        for up, k in zip(self.sampler.base.upstream, self.sampler.base.input_drives):
            ratio = _impedance(out, up) / _impedance(model, up)
            d = drives[k]
            drives[k] = Drive(d.dof, d.amplitude * ratio, d.phase, d.name)
        return replace(out, drives=drives)

    def evaluate(self, point: Point) -> dict:
        margin = float(self.sampler.margins(self._at(self.sampler.model(0.0, None), point)).min())
        out = {"pass": margin > 0, "margin": margin}
        if self.samples:
            margins = [float(self.sampler.margins(self._at(self.sampler.model(self.sigma, i), point)).min())
                       for i in range(self.samples)]
            out["spread"] = {**_spread_result([m > 0 for m in margins]),
                             "margin_median": float(np.median(margins))}
        return out

    def describe(self) -> dict:
        return {"model": "loaded gate (physics/loaded.py), margin over the valid input region (steady states)",
                "params": self.p.name}


def _impedance(model: MechModel, dof: int) -> float:
    """|k - m w^2 + i w c| of one DOF (a linear upstream stand-in: its amplitude is force / this)."""
    w = model.omega
    return abs(model.k_total[dof] - model.mass[dof] * w * w + 1j * w * model.c_total[dof])


class DesignDomain:
    """A combinational design on every input vector (experiments/montecarlo.DesignMC) at each point."""

    def __init__(self, netlist, p, vectors, backend: str = "envelope", sigma: float = 0.0, samples: int = 0,
                 seed: int = 0, trim: str = "none", residual: float = 0.0):
        self.design, self.p, self.backend, self.sigma = netlist.top, p, backend, sigma
        self.nominal = ShiftedDesignMC(netlist, p, vectors, backend, SpreadSpec(), seed, union=1)
        self.samples = samples if sigma else 0
        if self.samples:
            spec = replace(spec_of(sigma), trim=trim, trim_residual=residual)
            self.spread = ShiftedDesignMC(netlist, p, vectors, backend, spec, seed, union=min(self.samples, 8))

    def evaluate(self, point: Point) -> dict:
        self.nominal.point = point
        rec = self.nominal.evaluate([0])[0]
        out = {"pass": rec["pass"], "margin": rec.get("margin")}
        if self.samples:
            self.spread.point = point
            out["spread"] = _spread_result([r["pass"] for r in self.spread.evaluate(list(range(self.samples)))])
        return out

    def describe(self) -> dict:
        return {"model": f"{self.design}: every input vector against the logic oracle ({self.backend})",
                "vectors": len(self.nominal.vectors), "params": self.p.name}


class ShiftedDesignMC(DesignMC):
    """DesignMC whose samples are moved to `point` (the nominal design's when its spec spreads nothing)."""
    point = Point()

    def sample(self, i: int):
        model, stim = super().sample(i)
        supply = supply_drives(self.model)
        factor = _supply_factor(len(model.drives), supply, self.point)
        return shifted(model, self.point, supply), Stimulus(stim.times, stim.amps * factor[None, :, None])


class CpuDomain:
    """The processor running `program` for `cycles` cycles against the ISS (experiments/mc_clocked.CpuMC)."""

    design = "processor"

    def __init__(self, program: str, cycles: int, p, backend: str = "envelope", sigma: float = 0.0,
                 samples: int = 0, seed: int = 0, trim: str = "none", residual: float = 0.0):
        self.program, self.cycles, self.p, self.backend, self.sigma = program, cycles, p, backend, sigma
        self.nominal = ShiftedCpuMC(program, cycles, p, backend, SpreadSpec(), seed)
        self.samples = samples if sigma else 0
        if self.samples:
            spec = replace(spec_of(sigma), trim=trim, trim_residual=residual)
            self.spread = ShiftedCpuMC(program, cycles, p, backend, spec, seed)

    def evaluate(self, point: Point) -> dict:
        self.nominal.point = point
        rec = self.nominal.evaluate([0])[0]
        out = {"pass": rec["pass"], "first_bad_cycle": rec.get("first_bad_cycle"), "reason": rec.get("reason")}
        if self.samples:
            self.spread.point = point
            out["spread"] = _spread_result([r["pass"] for r in self.spread.evaluate(list(range(self.samples)))])
        return out

    def describe(self) -> dict:
        return {"model": f"the processor running {Path(self.program).name} for {self.cycles} cycles against the ISS "
                         f"({self.backend})", "params": self.p.name}


class ShiftedCpuMC(CpuMC):
    """CpuMC whose machines run at `point`."""
    point = Point()

    def _machine(self, i: int):
        """CpuMC's machine (sample i, powered up from rest) with its model moved to `point`."""
        from ..cpu.physical import PhysicalCPU
        from ..cpu.run import load_program, make_memory
        cpu = PhysicalCPU(make_memory(load_program(self.program)), self.backend, self.p, power_up=False,
                          noise=(self.noise, noise_seed(self.seed, i)))
        model, _ = sampled(cpu.model, spread.elements(cpu.model), self.spec, self.seed, i)
        cpu.model = shifted(model, self.point, supply_drives(cpu.model))
        cpu.amps = cpu._reset()
        return cpu


# --------------------------------------------------------------------------- the map
def domain_map(evaluator, x: tuple[str, list[float]], y: tuple[str, list[float]], fixed: dict,
               progress=False) -> dict:
    """Evaluate every point of the x-by-y grid (the other axes at `fixed`): cells[iy][ix]."""
    from ..backends import progress_bar
    t0 = time.time()
    bar = progress_bar(len(x[1]) * len(y[1]), progress, "point")
    cells = []
    for vy in y[1]:
        row = []
        for vx in x[1]:
            point = Point(**{**fixed, x[0]: vx, y[0]: vy})
            row.append(evaluator.evaluate(point))
            bar.update(1)
        cells.append(row)
    bar.close()
    nominal = next((c for vy, r in zip(y[1], cells) for vx, c in zip(x[1], r) if vx == 0 and vy == 0), None)
    return {"design": evaluator.design, "x": {"name": x[0], "values": list(x[1]), "label": AXES[x[0]]},
            "y": {"name": y[0], "values": list(y[1]), "label": AXES[y[0]]}, "fixed": fixed,
            "samples": evaluator.samples, "sigma": getattr(evaluator, "sigma", None), "method": evaluator.describe(),
            "cells": cells, "works": sum(c["pass"] for r in cells for c in r), "points": len(x[1]) * len(y[1]),
            "nominal_works": None if nominal is None else nominal["pass"], "wall_s": time.time() - t0}
