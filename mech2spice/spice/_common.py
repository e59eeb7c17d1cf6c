"""What the carrier-level and envelope netlists share: names, numbers, drive schedules, ngspice settings,
failure parsing and the batch of ngspice processes."""
from __future__ import annotations

import math
import os
import re
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from ..errors import DivergenceError, Mech2SpiceError
from ..identifiers import SpiceNamer, comment
from ..inputs import check_fields
from ..physics.model import MechModel
from ..run_result import blowup_bound

METHODS = ("trap", "gear")   # ngspice's integration methods


def is_netlist(path) -> bool:
    """Whether a file is a netlist or Verilog-A library mech2spice wrote: every one opens with a line naming
    it ("* mech2spice: ...", "mech2spice: ...", "// mech2spice ..."), so `emit -o` may replace it."""
    from ..inputs import head
    return head(path, 256).split(b"\n", 1)[0].lstrip(b"*/ \t").startswith(b"mech2spice")


NETLIST = ("a netlist mech2spice wrote", is_netlist)      # the kind of `emit -o` / `cpu emit -o` files


def drive_schedule(model: MechModel, stimulus, b: int, d: int, t_end: float) -> tuple[tuple[float, float], ...]:
    """(time, amplitude) points where drive d of batch member b changes before t_end."""
    if stimulus is None:
        return ((0.0, float(model.drives[d].amplitude)),)
    if not 0 <= b < stimulus.batch:
        raise Mech2SpiceError(f"batch index {b} out of range (stimulus has {stimulus.batch})")
    if stimulus.amps.shape[1] != len(model.drives):
        raise Mech2SpiceError(f"stimulus has {stimulus.amps.shape[1]} drives, model {len(model.drives)}")
    pts, last = [], None
    for t, a in zip(stimulus.times, stimulus.amps[:, d, b]):
        if t < t_end and a != last:
            pts.append((float(t), float(a)))
            last = a
    return tuple(pts)


# --- names: written by mech2spice/identifiers.py (one writer of names for every generated text) ----------
Namer = SpiceNamer
comment_text = comment


def num(x: float) -> str:
    """A number ngspice reads back exactly (repr; never a unit suffix)."""
    x = float(x)
    if not math.isfinite(x):
        raise Mech2SpiceError(f"cannot emit non-finite value {x} into a netlist")
    return repr(x)


# --- the subcircuit library ------------------------------------------------------


DEFAULT_TIMEOUT_S = 3600.0      # one simulator process; the adder takes seconds (`simulate --ngspice-timeout`)


def check_transient(o, simulator: str) -> None:
    """The checks every circuit simulator's transient settings share: method, max step, tolerances, time limit."""
    if o.method not in METHODS:
        raise Mech2SpiceError(f"{simulator} method '{o.method}' unknown (use {' or '.join(METHODS)})")
    if not (isinstance(o.max_step_periods, (int, float)) and 0 < o.max_step_periods <= o.MAX_STEP_LIMIT):
        raise Mech2SpiceError(f"max_step_periods must be in (0, {o.MAX_STEP_LIMIT:g}] drive periods")
    for name in ("reltol", "abstol", "chgtol", "vntol"):
        if not (math.isfinite(getattr(o, name)) and getattr(o, name) > 0):
            raise Mech2SpiceError(f"{type(o).__name__}.{name} must be positive")
    if o.timeout_s is not None and not (math.isfinite(o.timeout_s) and o.timeout_s > 0):
        raise Mech2SpiceError(f"the {simulator} timeout must be a positive number of seconds")


def prewarp_scale(o) -> float:
    """Capacitor scale making trapezoidal steps of max_step exact at the drive frequency (1 without prewarp)."""
    if not (o.prewarp and o.method == "trap"):
        return 1.0
    half = math.pi * o.max_step_periods      # omega * h / 2
    return half / math.tan(half)


@dataclass(frozen=True)
class NgspiceSettings:
    """The transient-analysis settings both netlist forms pass to ngspice (each form sets its own defaults)."""
    method: str = "trap"              # trap | gear (gear = BDF, numerically damped)
    max_step_periods: float = 1.0     # ngspice's max step, in drive periods
    reltol: float = 1e-4
    abstol: float = 1e-12
    chgtol: float = 1e-14
    vntol: float = 1e-9
    maxord: int = 2                   # gear order
    timeout_s: float | None = None    # one ngspice process's time limit; None: DEFAULT_TIMEOUT_S
    MAX_STEP_LIMIT = 1000.0           # longest max step a form accepts, in drive periods

    def __post_init__(self):
        self.validate()              # a bad value fails where it is set, not later inside a run

    def validate(self) -> None:
        """Refuse settings ngspice would reject or misread."""
        check_fields(self)
        check_transient(self, "ngspice")
        if not 1 <= self.maxord <= 6:
            raise Mech2SpiceError("maxord must be 1..6")

    @property
    def time_limit(self) -> float:
        """Seconds one ngspice process may run."""
        return self.timeout_s or DEFAULT_TIMEOUT_S


# --- failures -----------------------------------------------------------------------------------------
_TOO_SMALL = re.compile(r"timestep too small;\s*time\s*=\s*([0-9.eE+-]+)", re.I)
_NODE = re.compile(r'trouble with node\s+"?([\w.]+)', re.I)


def dof_of_node(model: MechModel, node: str, prefixes: tuple[str, ...]) -> str | None:
    """DOF name of a top-level node `<prefix>_<stem>` (the emitters' stems are a pure function of the names)."""
    namer = Namer()
    stems = {namer(n): n for n in model.names}
    kind, _, stem = node.lower().partition("_")
    return stems.get(stem) if kind in prefixes else None


def probe_dof_names(model: MechModel) -> list[str]:
    """The DOF each probe reads, by name (what a divergence message names)."""
    return [model.names[d] for d in model.probes.values()]


def check_samples(model: MechModel, t: np.ndarray, values: np.ndarray, names: list[str]) -> None:
    """DivergenceError at the first sample (row) where a probe (column; `names` its DOF) is non-finite or past
    the bound."""
    mag = np.abs(values)
    bad = ~np.isfinite(mag) | (mag > blowup_bound(model))
    if bad.any():
        row = int(np.flatnonzero(bad.any(axis=1))[0])
        col = int(np.flatnonzero(bad[row])[0])
        raise DivergenceError(names[col], float(t[row]), model.period, float(mag[row, col]))


def combinational_only(nl) -> None:
    """Refuse a clocked design for a one-shot netlist: it holds one input vector and no clock edges, so its
    flip-flops would only read their power-up values."""
    if nl.clocked:
        raise Mech2SpiceError(f"{nl.top} is clocked by {nl.clock_text()}: a netlist of one input vector has no clock "
                              "edges; run it cycle by cycle with `simulate --backend ngspice --cycles N` "
                              "(or --stimulus FILE.json)")


def failure(model: MechModel, err: Mech2SpiceError, probe_values, prefixes: tuple[str, ...]) -> Mech2SpiceError:
    """The error for a failed ngspice run: DivergenceError if the probes blew up (`probe_values(names, data)`
    gives their samples, or None) or ngspice's step collapsed (naming the node's DOF), else `err` itself."""
    names, data = getattr(err, "names", []), getattr(err, "data", np.zeros((0, 0)))
    values = probe_values(names, data) if data.ndim == 2 and data.shape[0] else None
    if values is not None:
        check_samples(model, data[:, 0], values, probe_dof_names(model))
    m = _TOO_SMALL.search(str(err))
    if not m:
        return err
    node = _NODE.search(str(err))
    dof = (dof_of_node(model, node.group(1), prefixes) if node else None) or (probe_dof_names(model) or model.names)[0]
    last = float(np.abs(data[-1, 1:]).max()) if data.ndim == 2 and data.size else math.nan
    return DivergenceError(dof, float(m.group(1)), model.period, last)


def map_batch(run_member, batch: int, workers: int | None = None) -> list:
    """run_member(b) for every batch member, one ngspice process each, up to `workers` (default: the CPU
    count; ngspice itself is single-threaded) at a time."""
    workers = max(1, min(batch, workers or os.cpu_count() or 1))
    with ThreadPoolExecutor(workers) as pool:
        return list(pool.map(run_member, range(batch)))
