"""What the report modules share: machine strings, plotting set-up, band shading, markdown tables, JSON.

matplotlib is imported only through `pyplot()`: the performance workers import this module and must not
pay for (or count in their memory baseline) a plotting library they never use.
"""
from __future__ import annotations

import json
import os
import platform
import time
from pathlib import Path

import numpy as np

from ..physics.params import BAND0, BAND1

HOST = f"{platform.machine()} {platform.system()}"
MACHINE = f"{HOST}, {os.cpu_count()} cores"       # the machine running this report
SANDBOX = "2-core Debian 12 sandbox"               # where the long reports' checked-in numbers were measured


def pyplot():
    """matplotlib.pyplot on the non-interactive Agg backend (reports only write files)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def shade_bands(ax, offset: float = 0.0, alpha: float = 0.1) -> None:
    """Shade the logic '0' (red) and '1' (blue) amplitude bands, shifted up by `offset`."""
    ax.axhspan(offset + BAND0[0], offset + BAND0[1], color="tab:red", alpha=alpha, lw=0)
    ax.axhspan(offset + BAND1[0], offset + BAND1[1], color="tab:blue", alpha=alpha, lw=0)


def save_figure(fig, path: Path, dpi: int = 110, tight: bool = True) -> None:
    """Lay out, write and close a figure."""
    if tight:
        fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    pyplot().close(fig)


def md_table(header: list[str], rows) -> list[str]:
    """A markdown table as lines: the header, the separator, one line per row of cells."""
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return out + ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]


def json_default(o):
    """json.dumps fallback for numpy values (complex arrays as magnitudes)."""
    if isinstance(o, np.ndarray):
        return np.abs(o).tolist() if np.iscomplexobj(o) else o.tolist()
    if isinstance(o, (np.floating, np.integer, np.bool_)):
        return o.item()
    raise TypeError(type(o))


def write_json(path: Path, data, default=json_default) -> None:
    """Write `data` as indented JSON (the reports' data files all use indent 1)."""
    Path(path).write_text(json.dumps(data, indent=1, default=default))


def read_json(path: Path, missing=None):
    """The JSON in `path`, or `missing` where there is no such file; a file that is not JSON is one
    Mech2SpiceError line (JSON is data: reading it runs nothing)."""
    from ..errors import Mech2SpiceError
    path = Path(path)
    if not path.exists():
        return missing
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as err:
        raise Mech2SpiceError(f"{path} is not the JSON a report wrote ({str(err)[:120]}): delete it to measure "
                              "again") from None


def log(msg: str) -> None:
    """A timestamped progress line."""
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", flush=True)


def timed(fn):
    """fn() and its wall time in seconds."""
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def out_dir(directory) -> Path:
    """The report directory, created if needed."""
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    return d
