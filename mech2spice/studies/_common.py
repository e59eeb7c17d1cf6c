"""What every study shares: the conditions of a measurement (machine, load, versions), section selection and
saving.  One place, so every JSON says the same things about where its numbers come from."""
from __future__ import annotations

import json
import os
import platform
import time
from importlib import metadata
from pathlib import Path

import numpy as np

from ..errors import Mech2SpiceError
from ..inputs import strict_json
SANDBOX = "2-core Debian 12 sandbox"               # where the long reports' checked-in numbers were measured


def load_average() -> list[float]:
    """The 1-, 5- and 15-minute load averages, rounded (other jobs share the machine)."""
    return [round(x, 2) for x in os.getloadavg()]


def _version(package: str) -> str | None:
    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return None


def conditions() -> dict:
    """The machine, its load now and the versions that shape the numbers."""
    return {"machine": f"{platform.machine()} {platform.system()}, {os.cpu_count()} cores",
            "load_avg": load_average(), "python": platform.python_version(),
            "versions": {p: _version(p) for p in ("numpy", "scipy", "numba", "mech2spice")},
            "date": time.strftime("%Y-%m-%d")}


def sections(study: str, only, known, default=None) -> list[str]:
    """The sections to measure, in the order given (`only` empty or None: `default`, or every known one);
    an unknown name is one Mech2SpiceError line naming the choices."""
    wanted = list(only or (known if default is None else default))
    bad = [s for s in wanted if s not in known]
    if bad:
        raise Mech2SpiceError(f"{study}: unknown section {', '.join(bad)} (choose from {', '.join(known)})")
    return wanted


def timed_section(res: dict, name: str, fn) -> None:
    """res[name] = fn(), with its wall time and the load averages around it under res['sections'][name]."""
    t0, before = time.perf_counter(), load_average()
    res[name] = fn()
    res.setdefault("sections", {})[name] = {"wall_s": round(time.perf_counter() - t0, 1), "load_before": before,
                                            "load_after": load_average()}


def json_default(o):
    """json.dumps fallback for numpy values (complex arrays as magnitudes)."""
    if isinstance(o, np.ndarray):
        return np.abs(o).tolist() if np.iscomplexobj(o) else o.tolist()
    if isinstance(o, (np.floating, np.integer, np.bool_)):
        return o.item()
    raise TypeError(type(o))


def write_json(path: Path, data, default=json_default) -> None:
    """Write `data` as indented strict JSON (the reports' data files all use indent 1): a non-finite figure is
    null, read back by its renderer as what it stood for (`reports/_common.non_finite`, the meaning of each
    such null in docs/architecture.md)."""
    Path(path).write_text(strict_json(data, default, indent=1))


def read_json(path: Path, missing=None):
    """The JSON in `path`, or `missing` where there is no such file; a file that is not JSON is one
    Mech2SpiceError line (JSON is data: reading it runs nothing)."""
    path = Path(path)
    if not path.exists():
        return missing
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as err:
        raise Mech2SpiceError(f"{path} is not the JSON a report wrote ({str(err)[:120]}): delete it to measure "
                              "again") from None


def timed(fn):
    """fn() and its wall time in seconds."""
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def log(msg: str) -> None:
    """A timestamped progress line."""
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", flush=True)
