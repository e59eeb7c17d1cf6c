"""What every engine shares: the interface, the idle-time watch and the progress bar (the result type
and the divergence check are in run_result.py, which spice/ reads too).

An engine integrates one mechanical model (physics.model.MechModel) under one stimulus for a number
of drive periods and returns a Run: the complex amplitude of each probe at the drive frequency for
every period.  Engines differ in fidelity (carrier-resolving RK4, envelope equations, circuit
simulators) and in what they support (`Capabilities`); the registry in `backends/__init__.py` maps
names to them.  Adding one: a module with an `Engine` subclass and one registry line
(docs/architecture.md).
"""
from __future__ import annotations

import math
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

import numpy as np

from ..errors import Mech2SpiceError
from ..inputs import MAX_PHYSICAL_CYCLES
from ..physics.model import MechModel
from ..physics.stimulus import Stimulus
from ..run_result import Run

@dataclass(frozen=True)
class Capabilities:
    """What an engine can do beyond integrating from rest."""
    physical: bool = True        # integrates the mechanical model (False: the logic-level oracle)
    batch: bool = True           # many stimuli side by side in one run
    state: bool = False          # continues from a returned state (chunked runs, settle loops)
    checkpoint: bool = False     # its state can be saved and restored exactly (processor runs)
    settle: bool = False         # skips idle time once every channel has settled
    averaged: bool = False       # integrates the envelope equations themselves: its states rest exactly on
                                 # their fixed points (physics/stability.py), not within the averaging error
    noise: bool = False          # takes thermal noise (a Langevin force on every dashpot, --noise)
    latency: bool = False        # freezes gates that have settled (--latency TOL)
    simulator: str | None = None  # the external circuit simulator it runs, one process per batch member


class FromFlags:
    """An engine's options read from the command line (the logic oracle has no model but takes the flags too)."""

    max_cycles: ClassVar[int] = MAX_PHYSICAL_CYCLES   # clock cycles one clocked run may ask for (memory grows
                                                      # with every cycle; inputs.check_cycles)

    @classmethod
    def options_from_flags(cls, flags):
        """This engine's options from the command line's parsed flags (an argparse namespace: a flag the
        command does not have is absent, one not given is None), validated; a flag it does not take is refused."""
        options = replace(cls.Options(), **cls.flag_changes(flags))
        options.validate()
        return options

    @classmethod
    def flag_changes(cls, flags) -> dict:
        """The Options fields the flags set; by default none (--steps ignored), the circuit simulators' and the
        envelope's speed flags refused."""
        refuse_circuit_flags(cls.name, flags)
        return speed_flags(cls.name, flags, ())


class Engine(FromFlags, ABC):
    """An integrator of the mechanical model, configured by its `Options` dataclass."""

    name: ClassVar[str]
    capabilities: ClassVar[Capabilities]
    Options: ClassVar[type]

    def __init__(self, options=None):
        self.options = options if options is not None else self.Options()
        self.options.validate()

    @abstractmethod
    def run(self, model: MechModel, periods: int, stimulus: Stimulus | None = None, *, state=None,
            start_period: int = 0, probes: list[str] | None = None, progress: bool = False) -> Run:
        """Integrate `periods` drive periods from `start_period` (from rest unless `state` is given)."""

    def describe(self) -> dict:
        """The options this engine runs with, for results and reports."""
        return dict(vars(self.options))

    def step(self, model: MechModel) -> float | None:
        """The step (drive periods) that stimulus changes must fall on, for engines with whole-period steps."""
        return None

    @classmethod
    def processor_latency(cls, threads: int = 1) -> float | None:
        """The per-gate latency threshold (u_R) a processor run on this engine uses unless told otherwise, with
        `threads` threads (docs/latency.md); None: every gate integrated at every step."""
        return None

    def longest_step(self, model: MechModel, cap: float) -> float:
        """The longest step (drive periods) up to `cap` this engine may take on `model` (its stability bound);
        `cap` itself for engines whose step is not in drive periods."""
        return cap

    def takes_etd(self, model: MechModel, step: float) -> bool:
        """Whether this engine steps each amplitude's own rate exactly (ETDRK4) on `model` at `step`: then its
        step error is that of ETDRK4, smaller than RK4's at the same step (the envelope; docs/latency.md)."""
        return False

    def reported_step(self, step: float) -> float:
        """The step (drive periods) a processor run records for this engine, given the whole-period step
        `step` it schedules with; by default that step itself."""
        return step

    def rests_on_fixed_point(self) -> bool:
        """Whether this engine, as configured, settles exactly onto the envelope equations' fixed points (so
        its distance from one is what is still to come); else the verdict trusts only its own trend."""
        return self.capabilities.averaged

    def dynamical_state(self, state):
        """A state this engine returned without its per-gate latency record, so that a run continuing it
        integrates every gate (the state alone where the engine keeps no record)."""
        return state

    def phasors(self, model: MechModel, state, t: float) -> tuple[np.ndarray, np.ndarray] | None:
        """A state this engine returned (Run.state, at time t) as envelope phasors: (A (n_fast, B) complex,
        s (n_slow, B)), what the stability verdict linearises at (physics/stability.py); None where the
        engine returns no state."""
        return None


class CircuitSimulator(Engine):
    """An engine that runs an external circuit simulator: its settings are --method, --max-step and
    --ngspice-timeout; its step is --max-step, not --steps."""

    @classmethod
    def flag_changes(cls, flags) -> dict:
        """--method, --max-step, --ngspice-timeout as option fields; --steps and the speed flags refused."""
        if _flag(flags, "steps"):
            raise Mech2SpiceError(f"--steps applies to rk4, carrier and envelope; {cls.name}'s step is --max-step")
        changes = {name: _flag(flags, f) for f, name in CIRCUIT_FLAGS.items() if _flag(flags, f) is not None}
        return {**changes, **speed_flags(cls.name, flags, ())}


CIRCUIT_FLAGS = {"method": "method", "max_step": "max_step_periods", "ngspice_timeout": "timeout_s"}
SPEED_FLAGS = ("latency", "exponential", "parallel")


def _flag(flags, name: str):
    return getattr(flags, name, None)


def refuse_circuit_flags(engine: str, flags) -> None:
    """Refuse the circuit simulators' settings for an engine that integrates the model itself."""
    if any(_flag(flags, f) for f in CIRCUIT_FLAGS):
        raise Mech2SpiceError(f"--method, --max-step and --ngspice-timeout apply to the circuit simulators "
                              f"(ngspice, vacask), not {engine}")


def speed_flags(engine: str, flags, takes: tuple[str, ...]) -> dict:
    """--latency TOL|off, --exponential on|off, --parallel on|off as option fields, for the ones in `takes`;
    any other given is refused (they are the envelope's speed-ups; the carrier takes --latency)."""
    given = {f: _flag(flags, f) for f in SPEED_FLAGS if _flag(flags, f) is not None}
    if set(given) - set(takes):
        named = ("--exponential and --parallel" if "latency" in given and "latency" in takes
                 else ", ".join("--" + f for f in given))
        raise Mech2SpiceError(f"{named}: envelope backend options, not {engine}'s")
    return {f: (v or None) if f == "latency" else v == "on" for f, v in given.items()}


@dataclass(frozen=True)
class NoOptions:
    """For engines without settings."""

    def validate(self) -> None:
        """Nothing to check."""


def require_rest(engine: str, state, start_period: int) -> None:
    """Refuse a continuation for an engine that always starts from rest (the circuit simulators)."""
    if state is not None or start_period:
        raise Mech2SpiceError(f"the {engine} engine starts from rest: it cannot continue from a state")


class _NoBar:
    def update(self, n):
        """Do nothing (the progress bar is off)."""

    def close(self):
        """Do nothing (the progress bar is off)."""


PROGRESS_EVERY_S = 15.0     # a progress line this often when stderr is not a terminal


class _LineBar:
    """Progress as a line through `log` every PROGRESS_EVERY_S seconds: a redirected stderr (a log file, a
    pipe) has no bar to redraw, but a long run still shows that it moves and when it should end."""

    def __init__(self, total: int, unit: str, log, initial: int = 0):
        self.total, self.unit, self.log, self.n, self.n0 = total, unit, log, initial, initial
        self.t0 = self.last = time.monotonic()

    def update(self, n):
        """Count n more; a line once PROGRESS_EVERY_S has passed since the last one."""
        self.n += n
        now = time.monotonic()
        if now - self.last >= PROGRESS_EVERY_S:
            self.last = now
            if self.total is None:               # an end nobody knows: what was done, and for how long
                self.log(f"{self.n:,} {self.unit}s, {now - self.t0:.0f} s elapsed")
                return
            rate = (self.n - self.n0) / max(now - self.t0, 1e-9)
            eta = f", at most {(self.total - self.n) / rate:.0f} s to go" if rate > 0 else ""
            self.log(f"{self.n:,}/{self.total:,} {self.unit}s ({self.n / max(self.total, 1):.0%}){eta}")

    def close(self):
        """Nothing to clear (lines stay)."""


def progress_bar(total: int | None, enabled, unit: str = "period", initial: int = 0):
    """A tqdm bar with an ETA when `enabled` is True (callers enable it on a terminal only); a line every
    PROGRESS_EVERY_S through `enabled` when it is a callable (the CLI's log, on a redirected stderr); else a
    no-op.  `total` None: the end is not known, so no percentage and no ETA, only the count and the time."""
    if callable(enabled):
        return _LineBar(total, unit, enabled, initial)
    if not enabled:
        return _NoBar()
    from tqdm import tqdm
    return tqdm(total=total, initial=initial, unit=unit, leave=False)


def probe_dofs(model: MechModel, names: list[str]) -> np.ndarray:
    """DOF index of each probe name or DOF name."""
    return np.array([model.probes[n] if n in model.probes else model.index(n) for n in names], int)


def watched_dofs(model: MechModel) -> np.ndarray:
    """The DOFs idle-time detection watches: the gates' channels (the logic signals), else every oscillating DOF.
    Gate oscillators ring in slow gate-insulator modes that change no logic level (reports/fidelity.md)."""
    gates = model.design.gates
    dofs = [g.channel for g in gates] if gates else np.flatnonzero(~model.arrays["slow"])
    return np.asarray(dofs, np.int64)


class SettleWatch:
    """Idle-time detection for engines that see per-period amplitudes: a stretch of constant stimulus has
    settled once every watched amplitude stayed within a range of `tol` for two windows of `window` periods
    in a row, the windows starting `first` periods after the stimulus changed (the envelope's rule,
    envelope.integrate; the carrier's kernel applies it inside its compiled loop)."""

    def __init__(self, tol: float, first: int, window: int):
        self.tol, self.first, self.window = tol, first, window
        self.restart()

    def restart(self) -> None:
        """A new stretch of constant stimulus: no window seen yet."""
        self.lo, self.hi, self.quiet = np.inf, -np.inf, 0

    def periods_to_check(self, age: int) -> int:
        """Periods from `age` (periods since the change) to the end of the next window."""
        if age < self.first:
            return self.first + self.window - age
        return self.window - (age - self.first) % self.window

    def update(self, amps: np.ndarray, age: int) -> bool:
        """Watched |A| (periods, ...) of the periods ending at ages age+1 ... : True once settled (at the last one)."""
        for k, a in enumerate(amps):
            now = age + k + 1
            if now <= self.first:
                continue
            self.lo, self.hi = np.minimum(self.lo, a), np.maximum(self.hi, a)
            if (now - self.first) % self.window == 0:
                self.quiet = self.quiet + 1 if np.max(self.hi - self.lo, initial=0.0) < self.tol else 0
                self.lo, self.hi = np.inf, -np.inf
                if self.quiet >= 2:
                    return True
        return False


def oscillator_phasors(model: MechModel, x: np.ndarray, v: np.ndarray, t: float):
    """(A, s) from displacements and velocities (n, B) at time t: u = Re(A e^{i omega t}) and u' = Re(i omega A
    e^{i omega t}) give A = (u - i u' / omega) e^{-i omega t}; the slow DOFs at their instantaneous position
    (their 2-omega ripple is small, and the verdict refines (A, s) to the fixed point anyway)."""
    slow = np.asarray(model.arrays["slow"], bool)
    w = model.omega
    A = (x[~slow] - 1j * v[~slow] / w) * np.exp(-1j * w * t)
    return A, np.array(x[slow], float)


def whole_periods(x: float) -> bool:
    """True for a whole number of periods."""
    return abs(x - round(x)) < 1e-9 and math.isfinite(x)
