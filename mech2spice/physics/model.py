"""The one mechanical model that every backend (RK4, envelope, ngspice) reads.

`MechModel` holds per-DOF masses, total stiffness and damping, coupling springs and dashpots, signed
quadratic couplings, drives and probes.  Its equations of motion and sign conventions (total vs local
values, the signed gamma): docs/physics.md, section "The mechanical model".
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from ..errors import Mech2SpiceError
from .params import GateParams


@dataclass
class Drive:
    """One sinusoidal drive a*sin(omega t + phase) on one DOF."""
    dof: int
    amplitude: float
    phase: float = 0.0
    name: str = ""


@dataclass
class Design:
    """What a builder knows beyond the equations: which DOFs form which gate, which drives carry which input."""
    gates: list = field(default_factory=list)              # every GateBlock (physics.nor), in build order
    blocks: dict = field(default_factory=dict)             # netlist gate name -> GateBlock
    input_drives: list = field(default_factory=list)       # small circuits: (spring, dashpot) drives per input
    load_drives: list = field(default_factory=list)        # fan-out circuits: the loads' second-input drives
    bit_drives: dict = field(default_factory=dict)         # input-port bit -> its drive indices
    clock_drives: list = field(default_factory=list)       # drive indices of every latch's clock pairs
    const_outputs: dict = field(default_factory=dict)      # output bit -> 0/1 when a constant drives it
    latch_blocks: list = field(default_factory=list)       # the GateBlocks that make up latches
    latch_outputs: dict = field(default_factory=dict)      # latch name -> GateBlock whose channel is Q
    netlist: object = None                                 # synthesis.Netlist the model was built from


@dataclass
class MechModel:
    """DOFs, coupling springs/dashpots, quadratic couplings, drives and probes at one drive frequency."""
    omega: float
    names: list[str] = field(default_factory=list)
    mass: list[float] = field(default_factory=list)
    k_total: list[float] = field(default_factory=list)
    c_total: list[float] = field(default_factory=list)
    slow: list[bool] = field(default_factory=list)      # True for insulators (not oscillating at omega)
    springs: list[tuple[int, int, float]] = field(default_factory=list)
    dashpots: list[tuple[int, int, float]] = field(default_factory=list)
    quads: list[tuple[int, int, float]] = field(default_factory=list)   # (fast, slow, signed gamma)
    drives: list[Drive] = field(default_factory=list)
    probes: dict[str, int] = field(default_factory=dict)
    params: GateParams | None = None                      # the nominal gate parameters the builder used
    design: Design = field(default_factory=Design)

    @property
    def period(self) -> float:
        """The drive period 2 pi / omega."""
        return 2 * np.pi / self.omega

    @property
    def levels(self):
        """The logic levels outputs are decoded with: the builder's block's (the default ones without gate
        parameters)."""
        from .params import DEFAULT_LEVELS
        return self.params.levels if self.params is not None else DEFAULT_LEVELS

    @property
    def amplitude_unit(self) -> float:
        """u_R, the unit output amplitudes are decoded in (1 for a model built without gate parameters)."""
        return self.params.u_r if self.params is not None else 1.0

    # --- building -----------------------------------------------------------
    def add_dof(self, name: str, m: float, k: float, c: float, slow: bool = False) -> int:
        """Add a DOF with mass, total stiffness and total damping; returns its index."""
        if name in self._index:
            raise Mech2SpiceError(f"duplicate degree of freedom '{name}'")
        if m <= 0 or k <= 0:
            raise Mech2SpiceError(
                f"DOF '{name}': mass {m:g} and total stiffness {k:g} must be positive "
                "(a negative total stiffness makes the oscillator unstable)")
        self.names.append(name)
        self.mass.append(m)
        self.k_total.append(k)
        self.c_total.append(c)
        self.slow.append(slow)
        self._index[name] = len(self.names) - 1
        self.invalidate()
        return len(self.names) - 1

    def add_spring(self, i: int, j: int, k: float) -> None:
        """Add a coupling spring k between DOFs i and j (their totals are not changed)."""
        self.springs.append((i, j, k))
        self.invalidate()

    def add_dashpot(self, i: int, j: int, c: float) -> None:
        """Add a coupling dashpot c between DOFs i and j (their totals are not changed)."""
        self.dashpots.append((i, j, c))
        self.invalidate()

    def add_quad(self, fast: int, slow: int, gamma: float) -> None:
        """Add a quadratic coupling V = gamma u_fast^2 u_slow (signed gamma) from an oscillating to a slow DOF."""
        if self.slow[fast] or not self.slow[slow]:
            raise Mech2SpiceError(
                f"quadratic coupling must join an oscillating DOF to a slow one, got "
                f"'{self.names[fast]}' -> '{self.names[slow]}'")
        self.quads.append((fast, slow, gamma))
        self.invalidate()

    def add_drive(self, dof: int, amplitude: float, phase: float = 0.0, name: str = "") -> int:
        """Add a drive amplitude*sin(omega t + phase) on `dof`; returns the drive's index."""
        self.drives.append(Drive(dof, amplitude, phase, name or self.names[dof]))
        self.invalidate()
        return len(self.drives) - 1

    def add_probe(self, name: str, dof: int) -> None:
        """Record DOF `dof` under `name` as an observed output."""
        self.probes[name] = dof

    def index(self, name: str) -> int:
        """The index of the DOF called `name`."""
        return self._index[name]

    @cached_property
    def _index(self) -> dict[str, int]:
        return {n: i for i, n in enumerate(self.names)}

    def invalidate(self) -> None:
        """Forget everything derived from the elements: call after editing them in place."""
        for key in ("K", "C", "k_local", "c_local", "arrays", "derived"):
            self.__dict__.pop(key, None)

    @cached_property
    def derived(self) -> dict:
        """A cache for what other modules derive from the model (an engine's operator, say); emptied on edit."""
        return {}

    # --- derived arrays -----------------------------------------------------
    @property
    def n(self) -> int:
        """The number of DOFs."""
        return len(self.names)

    @cached_property
    def arrays(self) -> dict[str, np.ndarray]:
        """The per-DOF, per-quad and per-drive lists as numpy arrays, keyed by name."""
        q = np.array(self.quads, dtype=float).reshape(-1, 3)
        return {
            "mass": np.array(self.mass), "k_total": np.array(self.k_total),
            "c_total": np.array(self.c_total), "slow": np.array(self.slow, bool),
            "quad_fast": q[:, 0].astype(int), "quad_slow": q[:, 1].astype(int), "quad_gamma": q[:, 2],
            "drive_dof": np.array([d.dof for d in self.drives], int),
            "drive_amp": np.array([d.amplitude for d in self.drives], float),
            "drive_phase": np.array([d.phase for d in self.drives], float),
        }

    def _coupling_matrix(self, total: list[float], links) -> sp.csr_matrix:
        """Symmetric matrix with totals on the diagonal and -k_ij off it."""
        rows, cols, vals = [np.arange(self.n)], [np.arange(self.n)], [np.array(total, float)]
        for i, j, k in links:
            rows += [[i], [j]]
            cols += [[j], [i]]
            vals += [[-k], [-k]]
        return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                             shape=(self.n, self.n))

    @cached_property
    def K(self) -> sp.csr_matrix:
        """The stiffness matrix: total stiffness on the diagonal, -k of each coupling spring off it."""
        return self._coupling_matrix(self.k_total, self.springs)

    @cached_property
    def C(self) -> sp.csr_matrix:
        """The damping matrix: total damping on the diagonal, -c of each coupling dashpot off it."""
        return self._coupling_matrix(self.c_total, self.dashpots)

    def _local(self, total: list[float], links) -> np.ndarray:
        local = np.array(total, float)
        for i, j, k in links:
            local[i] -= k
            local[j] -= k
        return local

    @cached_property
    def k_local(self) -> np.ndarray:
        """Each DOF's own spring to ground: total minus attached coupling springs (may be negative)."""
        return self._local(self.k_total, self.springs)

    @cached_property
    def c_local(self) -> np.ndarray:
        """Each DOF's own dashpot to ground: total minus attached coupling dashpots (may be negative)."""
        return self._local(self.c_total, self.dashpots)

    def counts(self) -> dict[str, int]:
        """Element counts in the paper's convention."""
        return {"oscillators": self.n, "linear_springs": len(self.springs),
                "nonlinear_springs": len(self.quads), "dashpots": len(self.dashpots)}

    def check(self) -> None:
        """Reject models no backend could run sensibly."""
        a = self.arrays
        for key in ("mass", "k_total", "c_total"):
            bad = np.flatnonzero(~np.isfinite(a[key]))
            if bad.size:
                raise Mech2SpiceError(f"DOF '{self.names[bad[0]]}': {key} is not finite")
        neg = np.flatnonzero(a["c_total"] < 0)
        if neg.size:
            raise Mech2SpiceError(
                f"DOF '{self.names[neg[0]]}': total damping {a['c_total'][neg[0]]:g} is negative "
                "(the oscillator would grow without bound)")
        self._check_time_scales()

    FREQUENCY_SPAN = 1e5     # an oscillator this many times faster or slower than the drive is no gate of this model

    def _check_time_scales(self) -> None:
        """Refuse a drive frequency no engine can step together with the oscillators' own frequencies: every
        engine steps a fixed fraction of the drive period, so an own frequency 1e5 times the drive's (or its
        1e-5) overflows the phasors or needs ~1e5 times the steps (omega = 1e-300 decoded NaN as 0.0)."""
        a = self.arrays
        with np.errstate(all="ignore"):
            ratio = np.sqrt(np.abs(a["k_total"]) / (a["mass"] * np.float64(self.omega) ** 2))
        span = self.FREQUENCY_SPAN
        bad = np.flatnonzero(~np.isfinite(ratio) | ((a["k_total"] != 0) & ((ratio > span) | (ratio < 1 / span))))
        if bad.size:
            raise Mech2SpiceError(
                f"DOF '{self.names[bad[0]]}': its own frequency sqrt(k/m) is {ratio[bad[0]]:.3g} times the drive's "
                f"(omega = {float(self.omega):.4g} rad/s); outside 1e-5..1e5 no engine can step both: is omega in "
                "rad/s, and the masses and stiffnesses in one unit system?")
