"""The result of an integration (`Run`) and the divergence check, shared by the engines (backends/) and
the circuit simulators' readers (spice/), so that neither imports the other's internals."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .errors import DivergenceError
from .physics.model import MechModel

BLOWUP = 1e3     # u_R: an amplitude this large means the integration diverged (logic levels are ~1 u_R)


@dataclass
class Run:
    """Result of an integration; amplitudes are complex phasors A with u = Re(A e^{i omega t})."""
    probe_names: list[str]
    period: float
    t_end: np.ndarray                 # (P,) time at the end of each recorded period
    amp: np.ndarray                   # (P, n_probes, B) complex
    mean: np.ndarray                  # (P, n_probes, B)
    x: np.ndarray | None              # final displacements (n, B), carrier-level engines
    v: np.ndarray | None              # final velocities (n, B)
    t: float                          # final time
    traces: np.ndarray | None = None  # (S, n_probes, B) raw samples if asked for
    trace_t: np.ndarray | None = None
    extra: dict = field(default_factory=dict)
    state: Any = None                 # the engine's state at the end, to continue from (Engine.run(state=...))
    settled_periods: int = 0          # periods held at a settled state instead of integrated (idle skipping)

    def probe(self, name: str) -> int:
        """Row of a probe in `amp`."""
        return self.probe_names.index(name)

    def amplitude(self, name: str) -> np.ndarray:
        """|A| per period, (P, B)."""
        return np.abs(self.amp[:, self.probe(name), :])

    def final_amplitudes(self, names: list[str], unit: float, average: int = 1) -> np.ndarray:
        """|A| / unit over the last `average` periods, (len(names), B)."""
        rows = [self.probe(n) for n in names]
        return np.abs(self.amp[-average:, rows, :]).mean(axis=0) / unit


def blowup_bound(model: MechModel) -> float:
    """The displacement or amplitude beyond which a run counts as diverged."""
    return BLOWUP * model.amplitude_unit


def check_divergence(model: MechModel, values: np.ndarray, t: float, dofs=None, bound: float | None = None) -> None:
    """Raise DivergenceError naming the first DOF whose |value| (rows of `values`) is non-finite or past the bound.

    `dofs` maps rows to DOF indices (default: row k is DOF k)."""
    bound = bound or blowup_bound(model)
    mag = np.abs(values).max(axis=1) if values.ndim > 1 else np.abs(values)
    bad = ~np.isfinite(mag) | (mag > bound)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        dof = i if dofs is None else int(dofs[i])
        raise DivergenceError(model.names[dof], t, model.period, float(mag[i]))
