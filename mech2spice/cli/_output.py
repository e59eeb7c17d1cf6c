"""What every command prints through: JSON of numpy values, a timestamped log and the progress setting."""
from __future__ import annotations

import json
import sys
import time

import numpy as np


def jsonable(o):
    """numpy values and tuples as JSON; every key is kept (user port names may be anything)."""
    if isinstance(o, dict):
        return {str(k): jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [jsonable(v) for v in o]
    if isinstance(o, np.ndarray):
        return jsonable(o.tolist())
    if isinstance(o, (np.floating, float)):
        return None if not np.isfinite(o) else float(o)
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.bool_,)):
        return bool(o)
    return o


def print_json(data) -> None:
    print(json.dumps(jsonable(data), indent=2, allow_nan=False))


def progress(args):
    """Progress of long steps on stderr: a bar on a terminal; redirected, a timestamped line every
    backends._base.PROGRESS_EVERY_S (a log file still shows the run moving); nothing with --json."""
    if getattr(args, "json", False):
        return False
    return True if sys.stderr.isatty() else log(args)


def log(args):
    quiet = getattr(args, "json", False)
    t0 = time.time()
    return (lambda msg: None) if quiet else (lambda msg: print(f"[{time.time() - t0:6.1f}s] {msg}",
                                                               file=sys.stderr, flush=True))
