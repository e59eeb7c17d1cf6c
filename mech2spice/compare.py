"""How far one run is from a reference run: the one definition studies, experiments and tests share.

Amplitudes are complex per-period arrays (periods, probes, batch) as engines return them in `Run.amp`;
differences are in amplitude units (`unit`, usually u_R) and degrees.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

AVG = 20                # periods averaged for a settled amplitude


def settled(amp: np.ndarray, avg: int = AVG) -> np.ndarray:
    """The settled complex amplitudes: the mean over the last `avg` periods."""
    return np.asarray(amp)[-avg:].mean(axis=0)


@dataclass(frozen=True)
class Agreement:
    """The worst amplitude difference and the worst phase difference of two sets of amplitudes."""
    amp: float          # max | |got| - |ref| | / unit
    phase_deg: float    # max |angle(got / ref)| where |ref| > floor * unit (0 where nowhere)

    def as_dict(self) -> dict:
        return asdict(self)


def agreement(ref: np.ndarray, got: np.ndarray, unit: float, floor: float = 0.0) -> Agreement:
    """Elementwise agreement of `got` with `ref` (same shape); phases only where |ref| exceeds `floor`
    units (a phase of an amplitude near zero means nothing)."""
    ref, got = np.asarray(ref), np.asarray(got)
    big = np.abs(ref) > floor * unit
    phase = np.degrees(np.abs(np.angle(got[big] / ref[big]))).max() if big.any() else 0.0
    return Agreement(float(np.abs(np.abs(got) - np.abs(ref)).max() / unit), float(phase))


def settled_agreement(ref: np.ndarray, got: np.ndarray, unit: float, avg: int = AVG) -> Agreement:
    """agreement() of the settled amplitudes (the mean of the last `avg` periods of each run)."""
    return agreement(settled(ref, avg), settled(got, avg), unit)


def trajectory(ref: np.ndarray, got: np.ndarray, unit: float, skip: int = 0) -> float:
    """The worst per-period |A| difference over the runs after their first `skip` periods (delays,
    overshoots the settled values do not show)."""
    return agreement(np.asarray(ref)[skip:], np.asarray(got)[skip:], unit).amp
