"""Running emitted netlists under ngspice and reading the results back as a `run_result.Run`.

Default path: a subprocess `ngspice -b -n -r out.raw file.cir` in a temporary directory (binary raw file,
streamed to disk by ngspice, read here with a header parse + np.frombuffer).  ngspice's own time
points are used as they are (no `linearize`, no `interp`): with the step pinned at max_step (the
default, see spice.SpiceOptions.trtol_value) they form a uniform grid of T/N after start-up, and
`demodulate` is then exactly the N-point DFT of the integrator's samples, as in rk4.py; around
start-up and amplitude steps it falls back to the midpoint rule.

Second path, for interactive use: PySpice's shared-library mode (`run_pyspice`).
"""
from __future__ import annotations

import math
import os
import re
import shutil
import subprocess
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from ..errors import Mech2SpiceError, ToolMissingError
from ..physics.model import MechModel
from ..run_result import Run
from ._common import DEFAULT_TIMEOUT_S, check_samples, failure, map_batch, probe_dof_names
from .oscillator_netlist import SpiceOptions, emit_with_probes
from ..physics.stimulus import Stimulus

MISSING = "ngspice not found: apt-get install -y ngspice libngspice0"


def find_ngspice() -> str:
    """The path of the ngspice executable; ToolMissingError if it is not on PATH."""
    exe = shutil.which("ngspice")
    if exe is None:
        raise ToolMissingError(MISSING)
    return exe


# --- raw files ---------------------------------------------------------------------
def read_raw(path) -> tuple[list[str], np.ndarray]:
    """Vector names and data (points, vectors) of a binary real raw file; a run cut short keeps
    the whole rows it wrote."""
    data = Path(path).read_bytes()
    mark = data.find(b"Binary:\n")
    if mark < 0:
        raise Mech2SpiceError(f"{path}: not a binary ngspice raw file (no 'Binary:' section)")
    lines = data[:mark].decode("ascii", "replace").splitlines()
    head = dict(line.split(":", 1) for line in lines if ":" in line and not line.startswith("\t"))
    if "complex" in head.get("Flags", ""):
        raise Mech2SpiceError(f"{path}: complex raw data is not supported")
    nvar = int(head["No. Variables"])
    at = next(k for k, line in enumerate(lines) if line.startswith("Variables:"))
    names = [lines[at + 1 + j].split()[1].lower() for j in range(nvar)]
    rows = (len(data) - mark - 8) // (8 * nvar)          # whole rows only (a run cut short)
    values = np.frombuffer(data, dtype="<f8", offset=mark + 8, count=rows * nvar)
    return names, values.reshape(rows, nvar)


def demodulate(t: np.ndarray, x: np.ndarray, omega: float, periods: int):
    """Per-period phasor A (u = Re(A e^{i omega t})) and mean of samples x (S, n) at times t (S,).

    Each sample stands for its cell (half-way to its neighbours); a cell crossing a period edge
    kT is split between the two periods.  On a uniform grid of N = T/h points this is exactly the
    N-point DFT of the samples (the two halves of a split cell carry samples one period apart), the
    same demodulation as rk4.py; elsewhere (start-up, amplitude steps) it is the midpoint rule."""
    T = 2 * math.pi / omega
    mid = (t[1:] + t[:-1]) / 2
    lo, hi = np.concatenate([t[:1], mid]), np.concatenate([mid, t[-1:]])
    klo, khi = np.floor(lo / T).astype(int), np.floor(hi / T).astype(int)
    edge = khi * T
    w_lo = np.where(klo == khi, hi - lo, edge - lo)      # the part of each cell in period klo
    w_hi = np.where(klo == khi, 0.0, hi - edge)          # and in period khi
    rot = np.exp(-1j * omega * t)
    amp = np.zeros((periods, x.shape[1]), complex)
    mean = np.zeros((periods, x.shape[1]))
    for k, w in ((klo, w_lo), (khi, w_hi)):
        keep = (k >= 0) & (k < periods)
        k, w, z = k[keep], w[keep], x[keep] * (w[keep] * rot[keep])[:, None]
        for j in range(x.shape[1]):   # bincount takes real weights, one column at a time
            amp[:, j] += np.bincount(k, z[:, j].real, periods) + 1j * np.bincount(k, z[:, j].imag, periods)
            mean[:, j] += np.bincount(k, w * x[keep, j], periods)
    return amp * (2 / T), mean / T


# --- errors --------------------------------------------------------------------------
_ERR = re.compile(r"^\s*(error|fatal)\b|\berror:|timestep too small", re.I)
_MORE = re.compile(r"trouble|aborted|interrupted|line\s*\d", re.I)


def _ngspice_message(log: str) -> str | None:
    """The first error line ngspice printed (with its 'trouble with node'/'aborted' follow-ups) as one line."""
    lines = [s.strip() for s in log.splitlines()]
    for n, line in enumerate(lines):
        if _ERR.search(line):
            more = [s for s in lines[n + 1:n + 3] if _MORE.search(s) and not _ERR.search(s)]
            return " ".join([line, *more])[:400]
    return None


NODE_PREFIXES = ("x", "v")            # the carrier netlist's top-level node kinds (displacement, velocity)


def _failure(model: MechModel, err: Mech2SpiceError, vecs: list[str]) -> Mech2SpiceError:
    """A failed run's error, naming the DOF where the probes blew up or ngspice's step collapsed."""
    return failure(model, err, lambda names, data: data[:, [names.index(v) for v in vecs]]
                   if set(vecs) <= set(names) else None, NODE_PREFIXES)


# --- running ---------------------------------------------------------------------------
_LIVE: set[subprocess.Popen] = set()     # running ngspice processes (runs may be in worker threads)
_LOCK = threading.Lock()
_STOPPED = threading.Event()


def stop_all() -> None:
    """Kill every running ngspice and refuse new ones (called from a signal handler; allow_runs undoes)."""
    _STOPPED.set()
    with _LOCK:
        for proc in _LIVE:
            proc.kill()


def allow_runs() -> None:
    """Let ngspice runs start again after stop_all."""
    _STOPPED.clear()


def run_guarded(argv: list[str], cwd: Path, timeout: float) -> subprocess.CompletedProcess:
    """Run ngspice; on a timeout or any exception (an interrupt included) the process is killed first."""
    if _STOPPED.is_set():
        raise Mech2SpiceError("ngspice run cancelled: interrupted")
    # -n: no user .spiceinit (one asking for ASCII raw files, or anything else, must not change runs)
    proc = subprocess.Popen(argv, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            stdin=subprocess.DEVNULL, env={**os.environ, "SPICE_ASCIIRAWFILE": "0"})
    with _LOCK:
        _LIVE.add(proc)
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        raise Mech2SpiceError(f"ngspice did not finish within {timeout:g} s (simulate --ngspice-timeout "
                              "sets the limit)") from None
    except BaseException:
        proc.kill()
        proc.wait()
        raise
    finally:
        with _LOCK:
            _LIVE.discard(proc)
    return subprocess.CompletedProcess(argv, proc.returncode, out, err)


def run_netlist(text: str, workdir=None, timeout: float | None = None) -> tuple[list[str], np.ndarray, str]:
    """Run a netlist under `ngspice -b -r` (timeout default: DEFAULT_TIMEOUT_S); returns (vector names,
    data, log).  Raises Mech2SpiceError with ngspice's message on an error (the data of a run cut short is
    in .data).  The temporary directory goes on any exit, an interrupt included."""
    exe = find_ngspice()
    timeout = timeout or DEFAULT_TIMEOUT_S
    with tempfile.TemporaryDirectory(prefix="m2s_ng_") as tmp:
        d = Path(workdir or tmp)
        cir, raw = d / "circuit.cir", d / "out.raw"
        cir.write_text(text, encoding="ascii")
        proc = run_guarded([exe, "-b", "-n", "-r", str(raw), str(cir)], d, timeout)
        if _STOPPED.is_set():
            raise Mech2SpiceError("ngspice run cancelled: interrupted")
        log = proc.stdout + "\n" + proc.stderr
        msg = _ngspice_message(proc.stderr) or _ngspice_message(proc.stdout)
        names, data = read_raw(raw) if raw.exists() and raw.stat().st_size else ([], np.zeros((0, 0)))
    if proc.returncode != 0 or msg:
        err = Mech2SpiceError(f"ngspice failed (exit {proc.returncode}): {msg or 'no message'}")
        err.names, err.data, err.log = names, data, log
        raise err
    if data.shape[0] < 2:
        raise Mech2SpiceError("ngspice wrote no data (raw file empty)")
    return names, data, log


def run(model: MechModel, periods: int, stimulus: Stimulus | None = None,
        options: SpiceOptions = SpiceOptions(), batch_index: int = 0, timeout: float | None = None,
        keep_netlist: str | Path | None = None) -> Run:
    """Simulate `periods` drive periods of one batch member under ngspice (subprocess)."""
    text, vecs = emit_with_probes(model, periods, stimulus, batch_index, options)
    if keep_netlist:
        Path(keep_netlist).write_text(text, encoding="ascii")
    t0 = time.perf_counter()
    try:
        names, data, log = run_netlist(text, timeout=timeout or options.time_limit)
    except ToolMissingError:
        raise
    except Mech2SpiceError as e:
        raise _failure(model, e, vecs) from None
    wall = time.perf_counter() - t0
    return to_run(model, periods, names, data, vecs, options, {"wall_s": wall, "backend": "ngspice"})


def to_run(model: MechModel, periods: int, names: list[str], data: np.ndarray, vecs: list[str],
           options: SpiceOptions, extra: dict) -> Run:
    """A carrier-level run's raw data as a Run: per-period probe phasors, step statistics in extra."""
    missing = [v for v in vecs if v not in names]
    if missing or names[:1] != ["time"]:
        raise Mech2SpiceError(f"ngspice raw file lacks {missing or ['time']}")
    T = model.period
    t, x = data[:, 0], data[:, [names.index(v) for v in vecs]]
    dofs = list(model.probes.values())
    check_samples(model, t, x, probe_dof_names(model))
    h = options.max_step_periods * T
    amp, mean = demodulate(t, x, model.omega, periods)
    dt = np.diff(t)
    uniform = float(np.mean(np.abs(dt - h) < 1e-6 * h)) if dt.size else 0.0
    extra = {**extra, "points": int(t.size), "uniform_fraction": uniform}
    if options.fixed_step and uniform < 0.9:
        # the prewarp is exact for steps of max_step only; say so rather than return quietly wrong data
        extra["warning"] = (f"only {uniform:.0%} of ngspice's steps were at max_step: the prewarp is "
                            "inexact (raise trtol or lower max_step_periods)")
    xf = np.zeros((model.n, 1))
    end = np.searchsorted(t, periods * T * (1 + 1e-12))      # last sample at or before the end
    xf[dofs, 0] = x[max(end - 1, 0)]
    return Run(list(model.probes), T, (1 + np.arange(periods)) * T, amp[:, :, None], mean[:, :, None],
               xf, np.zeros((model.n, 1)), periods * T, extra=extra)


def run_batch(model: MechModel, periods: int, stimulus: Stimulus | None = None,
              options: SpiceOptions = SpiceOptions(), workers: int | None = None,
              timeout: float | None = None) -> Run:
    """Every batch member of `stimulus` as its own ngspice process (up to `workers` at a time, default
    the CPU count: ngspice itself is single-threaded); results stacked along the batch axis."""
    B = stimulus.batch if stimulus is not None else 1
    runs = map_batch(lambda b: run(model, periods, stimulus, options, b, timeout), B, workers)
    first = runs[0]
    return Run(first.probe_names, first.period, first.t_end,
               np.concatenate([r.amp for r in runs], axis=2), np.concatenate([r.mean for r in runs], axis=2),
               np.concatenate([r.x for r in runs], axis=1), np.concatenate([r.v for r in runs], axis=1),
               first.t, extra={"backend": "ngspice",
                               **{k: [r.extra[k] for r in runs] for k in ("wall_s", "points", "uniform_fraction")}})


# --- PySpice shared mode (interactive use) ------------------------------------------------
def find_libngspice() -> str:
    """Path of libngspice.so.0 from the loader cache (Debian ships no unversioned libngspice.so,
    which is the name PySpice 1.5 asks for)."""
    try:
        out = subprocess.run(["ldconfig", "-p"], capture_output=True, text=True, timeout=30).stdout
    except (OSError, subprocess.SubprocessError):
        out = ""
    m = re.search(r"libngspice\.so(?:\.\d+)*\s.*=>\s*(\S+)", out)
    if m is None:
        raise ToolMissingError("libngspice not found: apt-get install -y ngspice libngspice0")
    return m.group(1)


_SHARED = None


def _shared():
    """One NgSpiceShared instance per process (the library keeps global state)."""
    global _SHARED
    if _SHARED is None:
        import logging
        lib = find_libngspice()
        os.environ["NGSPICE_LIBRARY_PATH"] = lib         # read by PySpice at import
        logging.getLogger("PySpice").setLevel(logging.ERROR)  # "Unsupported Ngspice version 39"
        try:
            from PySpice.Spice.NgSpice.Shared import NgSpiceShared
        except ImportError as e:
            raise ToolMissingError(f"PySpice not importable: {e}; pip install PySpice") from None
        NgSpiceShared.LIBRARY_PATH = lib                  # in case PySpice was imported earlier
        _SHARED = NgSpiceShared.new_instance()
    return _SHARED


def _vector(ng, plot: str, name: str) -> np.ndarray:
    """A real vector straight from ngGet_Vec_Info (PySpice's Plot needs a Simulation object)."""
    from PySpice.Spice.NgSpice.Shared import ffi
    info = ng._ngspice_shared.ngGet_Vec_Info(f"{plot}.{name}".encode())
    if info == ffi.NULL or info.v_realdata == ffi.NULL:
        raise Mech2SpiceError(f"ngspice (shared) has no real vector {name}")
    return np.frombuffer(ffi.buffer(info.v_realdata, info.v_length * 8), dtype=np.float64).copy()


def run_pyspice(model: MechModel, periods: int, stimulus: Stimulus | None = None,
                options: SpiceOptions = SpiceOptions(), batch_index: int = 0) -> Run:
    """As `run`, through libngspice in this process (PySpice 1.5 shared mode): no files, no
    subprocess.  Not thread-safe (one library instance per process)."""
    text, vecs = emit_with_probes(model, periods, stimulus, batch_index, options)
    t0 = time.perf_counter()
    try:
        names, data = run_netlist_shared(text, vecs)
    except Mech2SpiceError as e:
        raise _failure(model, e, vecs) from None
    return to_run(model, periods, names, data, vecs, options,
                  {"wall_s": time.perf_counter() - t0, "backend": "ngspice-shared"})


def run_netlist_shared(text: str, vecs: list[str]) -> tuple[list[str], np.ndarray]:
    """Load and run a netlist in the shared library; returns (["time", *vecs], data).  Errors are
    read from ngspice's own output (PySpice 1.5 raises bare NameError/NgSpiceCommandError)."""
    ng = _shared()
    ng.clear_output()
    msg = None
    try:                       # each PySpice call clears the captured output: read it after each
        ng.load_circuit(text)
    except Exception:
        pass
    msg = _ngspice_message("\n".join([ng.stderr, ng.stdout]))
    if msg is None:
        try:
            ng.run()
        except Exception:
            pass
        msg = _ngspice_message("\n".join([ng.stderr, ng.stdout]))
    plot = ng.last_plot
    names, data = ["time", *vecs], np.zeros((0, 0))
    try:
        if plot.startswith("tran"):
            data = np.stack([_vector(ng, plot, n) for n in ["time", *[v[2:-1] for v in vecs]]], axis=1)
    finally:
        _release(ng, plot)
    if msg or not data.size:
        err = Mech2SpiceError(f"ngspice (shared) failed: {msg or 'no transient results'}")
        err.names, err.data = names, data
        raise err
    return names, data


def _release(ng, plot: str) -> None:
    """Free the plot and the circuit so repeated runs do not accumulate."""
    for cmd in ([f"destroy {plot}"] if plot.startswith("tran") else []) + ["remcirc"]:
        try:
            ng.exec_command(cmd)
        except Exception:
            pass
