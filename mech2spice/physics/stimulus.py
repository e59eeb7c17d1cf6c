"""Drive-amplitude schedules shared by every backend.

A stimulus is piecewise constant: from time ``times[k]`` on, drive d of batch
member b has amplitude ``amps[k, d, b]``.  A batch runs B independent copies of
the same network side by side (e.g. all 16 input pairs of an adder), which is
how the integrators amortise Python overhead.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import Mech2SpiceError
from .model import MechModel


@dataclass
class Stimulus:
    """Piecewise-constant drive amplitudes: segment start times and (segments, drives, batch) amps."""
    times: np.ndarray          # (K,) segment start times, times[0] == 0, increasing
    amps: np.ndarray           # (K, n_drives, B)

    def __post_init__(self):
        self.times = np.asarray(self.times, float)
        self.amps = np.asarray(self.amps, float)
        if self.amps.ndim != 3 or self.amps.shape[0] != self.times.size:
            raise Mech2SpiceError("stimulus: amps must have shape (segments, drives, batch)")
        if self.times[0] != 0 or np.any(np.diff(self.times) <= 0):
            raise Mech2SpiceError("stimulus: segment times must start at 0 and increase")

    @property
    def batch(self) -> int:
        """The number of batch members B."""
        return self.amps.shape[2]

    def segment(self, t: float) -> int:
        """The index of the segment in force at time t."""
        return int(np.searchsorted(self.times, t, side="right") - 1)

    def at(self, t: float) -> np.ndarray:
        """The (n_drives, B) amplitudes in force at time t."""
        return self.amps[self.segment(t)]

    def next_change(self, t: float) -> float:
        """The start time of the segment after the one at t (inf if none)."""
        k = self.segment(t) + 1
        return self.times[k] if k < self.times.size else np.inf

    @classmethod
    def constant(cls, model: MechModel, batch: int = 1) -> "Stimulus":
        """One segment: every drive at its model amplitude, repeated for `batch` members."""
        amp = model.arrays["drive_amp"][None, :, None]
        return cls([0.0], np.repeat(amp, batch, axis=2))

    @classmethod
    def input_levels(cls, model: MechModel, pairs, f_r: float) -> "Stimulus":
        """Constant levels on the model's external inputs from t = 0: one batch member per row of `pairs`
        (one level per input, as fractions of the reference force `f_r`; both drives of an input get it)."""
        lv = np.asarray(pairs, float) * f_r
        changes = {}
        for k, (ds, dd) in enumerate(model.design.input_drives):
            changes[ds] = changes[dd] = lv[:, k]
        return cls.from_levels(model, [(0.0, changes)], batch=len(lv))

    @classmethod
    def from_levels(cls, model: MechModel, segments: list[tuple[float, dict[int, np.ndarray | float]]],
                    batch: int = 1) -> "Stimulus":
        """Segments of (start time, {drive index: amplitude or (B,) amplitudes}); unnamed drives keep
        their model amplitude, named ones keep their last set value."""
        base = np.repeat(model.arrays["drive_amp"][:, None], batch, axis=1).astype(float)
        times, amps = [], []
        for t, changes in segments:
            base = base.copy()
            for d, a in changes.items():
                base[d, :] = a
            times.append(t)
            amps.append(base)
        return cls(times, np.stack(amps))
