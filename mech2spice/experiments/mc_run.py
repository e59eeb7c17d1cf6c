"""Monte-Carlo sweeps on Dask, streamed to an append-only JSON-lines file that a later run resumes.

The file's first line is a header naming the job (design, parameters, vectors, spread spec, seed,
backend, periods); every other line is one sample's record.  A run reads what is there, skips the
sample indices already recorded (a torn last line from a killed run is cut off), and appends the rest,
one task's records per write.  Sample i's draws depend only on (seed, i), so a resumed sweep gives the
records an uninterrupted one would.

Tasks hold `DesignMC.union` samples (the engine's batch: one union model); the driver keeps at most
IN_FLIGHT tasks per worker submitted, so its memory and the workers' stay bounded whatever the count.
"""
from __future__ import annotations

import json
import os
import re
import resource
import time
from pathlib import Path

from ..backends import progress_bar
from ..errors import Mech2SpiceError
from ..inputs import first_json_line, strict_json
from ..schema import BOOL, COUNT, NUMBER, STR, Map, Opt, SchemaError, check_finite
from . import montecarlo as mc

IN_FLIGHT = 2                  # tasks submitted per worker at a time
_DESIGNS: dict = {}            # per process: job key -> DesignMC (synthesis and model built once)


class Interrupted(Exception):
    """Raised by the `stop_after` hook (tests): the run stops as a Ctrl-C would."""


def design_for(job: dict) -> mc.DesignMC:
    """The job's DesignMC, built once per process."""
    key = mc.job_key(job)
    if key not in _DESIGNS:
        from ..physics import network
        from ..physics.params import load_params
        from ..synthesis.synth import synthesize
        _DESIGNS.clear()                 # one design per worker at a time bounds its memory
        spec, p, noise = mc.spec_of(job["spread"]), load_params(job["params"]), job.get("noise", 0.0)
        if "program" in job:             # the processor (cpu montecarlo)
            from ..cpu.physical import PROCESSOR_STEP     # files before ETD_PROCESSOR_STEP: the cap was 16
            from .mc_clocked import CpuMC
            _DESIGNS[key] = CpuMC(job["program"], job["cycles"], p, job["backend"], spec, job["seed"], noise,
                                  batch=job.get("union", 1), max_fanout=job.get("max_fanout"),
                                  step=job.get("step"), etd=job.get("integrator") == "etd",
                                  etd_step=job.get("etd_step", PROCESSOR_STEP),
                                  latency_calm=job.get("latency_calm"),      # None: files before it
                                  latency_wake=job.get("latency_wake"))
            return _DESIGNS[key]
        nl = synthesize(job["design"], max_fanout=network.MAX_FANOUT)
        if "steps" in job:               # a clocked design under a stimulus of cycles
            from .mc_clocked import ClockedMC
            _DESIGNS[key] = ClockedMC(nl, p, job["steps"], job["backend"], spec, job["seed"], noise=noise)
        else:
            _DESIGNS[key] = mc.DesignMC(nl, p, job["vectors"], job["backend"], spec, job["seed"],
                                        job.get("periods"), union=job.get("union"), noise=noise)
    return _DESIGNS[key]


def task(job: dict, indices: list[int]) -> list[dict]:
    """Evaluate samples `indices` of `job` (runs on a worker)."""
    return design_for(job).evaluate(indices)


def is_results(path) -> bool:
    """Whether `path` holds montecarlo results (its first line a results header)."""
    first = first_json_line(path)
    return isinstance(first, dict) and first.get("type") == "header" and isinstance(first.get("key"), str)


RESULTS_KIND = ("a montecarlo results file", is_results)


def read_results(path: Path, job: dict, design_of=None) -> dict[int, dict]:
    """Records already in `path` by sample index.  The whole file is checked first (a header of this job,
    then whole records, each consistent in itself and, given `design_of` (called at the first record: the
    header is checked before any design is built), with the design's bits, gates and vectors; a sample given
    twice only with the same values); only then is a torn last line (a killed run) cut off."""
    if not path.exists() or path.stat().st_size == 0:
        return {}
    if not is_results(path):
        raise Mech2SpiceError(f"{path} is not a montecarlo results file (its first line is no results header): "
                              "give another --out")
    if first_json_line(path)["key"] != mc.job_key(job):
        raise Mech2SpiceError(f"{path} holds results of another job (design or its source, spread, seed, backend or "
                              "inputs differ): give another --out")
    done, torn, design = {}, False, None
    with open(path, "rb") as fh:
        for n, raw in enumerate(fh, 1):
            if not raw.endswith(b"\n"):
                torn = True                 # the last line, cut off below
            elif n > 1:
                rec = _record(raw, n, path)
                if rec.get("type") != "sample":
                    continue
                design = design or (design_of() if design_of else None)
                problem = _inconsistent(rec, design) or (
                    "sample {i} is given again with other values".format(**rec)
                    if done.get(rec["i"], rec) != rec else None)
                if problem:
                    raise Mech2SpiceError(f"{path}, line {n}: {problem}; the tool writes no such record: give "
                                          "another --out")
                done.setdefault(rec["i"], rec)
    if torn:
        _cut_torn_line(path)
    return done


# A sample line as the summary reads it back (mech2spice/schema.py's language; a failed sample's margin is
# null, its reason beside it).
SAMPLE = {"i": COUNT, "pass": BOOL, "stable?": BOOL, "margin?": Opt(NUMBER), "gate_margin?": Opt(NUMBER),
          "failing_bits?": Map(COUNT), "failing_gates?": [STR], "worst_gate?": Opt(STR), "periods?": COUNT,
          "reason?": STR}


def _inconsistent(rec: dict, design) -> str | None:
    """Why a sample record cannot be one this design's run wrote (None: it can): given the `design`, its bits
    and gates are the design's and no bit fails more often than there are input vectors; and `pass` agrees
    with the rest (a pass has every bit right, a stable network and no negative margin; a failure has a
    wrong bit, a growing mode or a reason)."""
    bits, gates = rec.get("failing_bits") or {}, rec.get("failing_gates") or []
    if design is not None:
        unknown = sorted(set(bits) - set(design.outs)) + sorted(set(gates) - set(design.gates)) + (
            [rec["worst_gate"]] if rec.get("worst_gate") not in (None, *design.gates) else [])
        if unknown:
            return f"sample {rec['i']} names {unknown[0]!r}, which is no output bit or gate of this design"
        if any(c > len(design.vectors) for c in bits.values()):
            return (f"sample {rec['i']} has a bit failing more often than the {len(design.vectors)} input "
                    "vectors run")
    failed = bool(bits) or rec.get("stable") is False or "reason" in rec
    if rec["pass"] and (failed or (rec.get("margin") or 0) < 0):
        return f"sample {rec['i']} passes with a wrong bit, a growing mode, a reason or a negative margin"
    if not rec["pass"] and not failed:
        return f"sample {rec['i']} fails with every bit right, the network stable and no reason"
    return None


def _cut_torn_line(path: Path) -> None:
    """Drop a last line without its newline (the run was killed while writing it)."""
    data = path.read_bytes()
    if data and not data.endswith(b"\n"):
        with open(path, "r+b") as fh:
            fh.truncate(data.rfind(b"\n") + 1)


def _record(raw: bytes, n: int, path: Path) -> dict:
    """Line n of a results file, checked for what the summary reads."""
    try:
        rec = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError):
        rec = None
    if not isinstance(rec, dict):
        raise Mech2SpiceError(f"{path}, line {n}: damaged (not a JSON record): give another --out")
    if rec.get("type") == "sample":
        try:
            check_finite(rec, SAMPLE, why="not a finite number (the tool writes null and a reason)")
        except SchemaError as err:
            raise Mech2SpiceError(f"{path}, line {n}: not a Monte-Carlo results record ({err.path}: {err.message}): "
                                  "give another --out") from None
    return rec


def _append(fh, records: list[dict]) -> None:
    fh.write("".join(strict_json({"type": "sample", **r}, default=_num) + "\n" for r in records))
    fh.flush()
    os.fsync(fh.fileno())


def _num(x):
    return float(x) if hasattr(x, "__float__") else str(x)


def tasks_of(todo: list[int], size: int) -> list[list[int]]:
    """Consecutive groups of `size` sample indices."""
    return [todo[k:k + size] for k in range(0, len(todo), size)]


_ADDRESS = re.compile(r"(?:(?:tcp|tls)://)?(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9._-]+):([0-9]{1,5})")
SCHEDULERS = "local, inline, or a Dask scheduler address HOST:PORT or tcp://HOST:PORT (e.g. tcp://10.0.0.5:8786)"


def check_scheduler(text) -> str:
    """local, inline or a scheduler address: checked before any work (Dask itself fails late, with a traceback)."""
    if text in ("local", "inline"):
        return text
    m = _ADDRESS.fullmatch(text) if isinstance(text, str) else None
    if m is None or not 1 <= int(m.group(2)) <= 65535:
        raise Mech2SpiceError(f"scheduler {text!r}: expected {SCHEDULERS}")
    return text


def run(job: dict, samples: int, out: Path, scheduler: str = "local", workers: int | None = None,
        progress: bool = False, stop_after: int | None = None, log=lambda msg: None) -> dict:
    """Evaluate samples 0..samples-1 of `job` (those not yet in `out`), appending to `out`; the summary."""
    check_scheduler(scheduler)
    t0 = time.time()
    out = Path(out)
    done = read_results(out, job, lambda: design_for(job))
    if not out.exists() or out.stat().st_size == 0:
        out.write_text(strict_json({"type": "header", "key": mc.job_key(job), "job": job}) + "\n", encoding="utf-8")
    todo = [i for i in range(samples) if i not in done]
    size = job.get("union") or design_for(job).union
    groups = tasks_of(todo, size)
    log(f"{samples} samples: {len(done)} already in {out}, {len(todo)} to run in {len(groups)} tasks")
    bar = _bar(samples, len(done), progress)
    t_run = time.time()
    stats = {"workers": 0, "worker_peak_rss_mb": None}
    _ARRIVALS.clear()
    try:
        with open(out, "a", encoding="utf-8") as fh:
            if scheduler == "inline":
                from .blas import set_blas_threads
                set_blas_threads(1)          # as Dask's workers have it: no spinning BLAS threads (blas.py)
                stats["workers"] = 1
                for n, g in enumerate(groups):
                    _stream(fh, task(job, g), done, bar, n, stop_after)
            else:
                stats.update(_run_dask(job, groups, fh, done, bar, scheduler, workers, stop_after))
    finally:
        bar.close()
    ran = len(todo)
    wall = time.time() - t0
    recs = [done[i] for i in range(samples) if i in done]
    res = mc.summary(recs, len(design_for(job).gates))
    return {**res, "ran": ran, "resumed": samples - ran, "samples_per_s": ran / max(time.time() - t_run, 1e-9),
            "steady_samples_per_s": steady_rate(_ARRIVALS, stats["workers"]),
            "wall_s": wall, "driver_peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
            **stats, "out": str(out)}


_ARRIVALS: list = []           # (time, records) per task streamed in this run: the steady throughput


def steady_rate(arrivals: list, workers: int = 1) -> float | None:
    """Samples per second after every worker's first task (from the workers-th arrival to the last): the
    throughput without the cluster's start (worker processes, synthesis, compiled-kernel loading); None
    with too few tasks."""
    w = max(int(workers), 1)
    if len(arrivals) <= w:
        return None
    return sum(n for _, n in arrivals[w:]) / max(arrivals[-1][0] - arrivals[w - 1][0], 1e-9)


def _stream(fh, records, done, bar, n, stop_after) -> None:
    _ARRIVALS.append((time.time(), len(records)))
    _append(fh, records)
    for r in records:
        done.setdefault(r["i"], r)
    bar.update(len(records))
    if stop_after is not None and n + 1 >= stop_after:
        raise Interrupted(f"stopped after {stop_after} tasks")


def _worker_config() -> dict:
    """A LocalCluster's workers without two of Dask's defaults that cost a compute-bound worker its core: the
    Nanny's MALLOC_TRIM_THRESHOLD_ (it turns off glibc's dynamic thresholds, so every compiled call's scratch
    arrays come back as fresh pages: two 80-cycle processor samples took 1.67 s of system time with it, 0.25 s
    without, docs/design.md section 7), and the statistical profiler, which samples each thread every 10 ms."""
    import dask
    import distributed  # noqa: F401  (its defaults into dask.config)
    environ = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}))
    environ.pop("MALLOC_TRIM_THRESHOLD_", None)
    return {"distributed.nanny.pre-spawn-environ": environ, "distributed.worker.profile.enabled": False}


def _run_dask(job, groups, fh, done, bar, scheduler, workers, stop_after) -> dict:
    """Tasks on a LocalCluster (one single-threaded worker per core) or the scheduler at an address."""
    try:
        import dask
        from dask.distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise Mech2SpiceError("montecarlo needs Dask: pip install 'mech2spice[mc]' (or --scheduler inline)") from None
    cluster = None
    if scheduler == "local":
        with dask.config.set(_worker_config()):
            cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1, processes=True,
                                   dashboard_address=":0", memory_limit="4GiB")
        client = Client(cluster)
    else:
        client = Client(scheduler)
    try:
        n_workers = len(client.scheduler_info()["workers"])
        pending, queue = as_completed(), list(groups)
        for _ in range(min(len(queue), IN_FLIGHT * n_workers)):
            pending.add(client.submit(task, job, queue.pop(0), pure=False))
        n = 0
        for fut in pending:
            records = fut.result()
            fut.release()
            if queue:
                pending.add(client.submit(task, job, queue.pop(0), pure=False))
            _stream(fh, records, done, bar, n, stop_after)
            n += 1
        peaks = client.run(_peak_rss_mb)
        return {"workers": n_workers, "worker_peak_rss_mb": max(peaks.values()) if peaks else None}
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _bar(total: int, initial: int, enabled):
    return progress_bar(total, enabled, unit="sample", initial=initial)
