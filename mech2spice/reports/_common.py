"""What the report modules share: machine strings, plotting set-up, band shading, markdown tables; the JSON
helpers are the studies' (mech2spice/studies/_common.py).

matplotlib is imported only through `pyplot()`: the performance workers import this module and must not
pay for (or count in their memory baseline) a plotting library they never use.
"""
from __future__ import annotations

import os
import platform
import time
from pathlib import Path


from ..physics.params import BAND0, BAND1
from ..studies import SANDBOX, json_default, log, read_json, timed, write_json  # noqa: F401 (the studies')

HOST = f"{platform.machine()} {platform.system()}"
MACHINE = f"{HOST}, {os.cpu_count()} cores"       # the machine running this report


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


def measured_on(conditions: dict) -> str:
    """A study's recorded conditions (studies/_common.conditions) as one phrase for a report: the machine, its
    load averages when the measurement ended, the date and the versions that shape the numbers."""
    load = " / ".join(f"{x:.2f}" for x in conditions["load_avg"])
    versions = ", ".join(f"{k} {v}" for k, v in conditions["versions"].items() if v)
    return (f"{conditions['machine']} (load averages {load} over 1, 5, 15 min when it ended; "
            f"{conditions['date']}; Python {conditions['python']}, {versions})")


def md_table(header: list[str], rows) -> list[str]:
    """A markdown table as lines: the header, the separator, one line per row of cells."""
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return out + ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]


def out_dir(directory) -> Path:
    """The report directory, created if needed."""
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    return d


def stored(path: Path, report: str) -> dict:
    """The JSON a study wrote at `path`; without it one Mech2SpiceError line says how to measure it.  Its
    fields are mech2spice/reports/schemas.py's to check (`--render` checks them before any report is drawn)."""
    from ..errors import Mech2SpiceError
    data = read_json(path)
    if data is None:
        raise Mech2SpiceError(f"{path} does not exist: measure it with `mech2spice report {report}` (without --render)")
    if not isinstance(data, dict) or not data:
        from ..inputs import type_name
        raise Mech2SpiceError(f"{path} is not the JSON `mech2spice report {report}` writes (an object of its results, "
                              f"not {'an empty object' if data == {} else type_name(data)}): measure it again")
    return data


def non_finite(data, fields: tuple[str, ...], value: float):
    """`data` with each null in a figure named in `fields` (the field itself, or an entry of its list or
    object) read as `value` (math.inf or math.nan): the study's strict JSON writes a non-finite figure as null
    (studies/_common.write_json), and the renderer reads it as the number it stood for.  Other nulls (a field
    that was never measured) are left alone."""
    if isinstance(data, dict):
        for key, item in data.items():
            data[key] = _as_value(item, value) if key in fields else non_finite(item, fields, value)
    elif isinstance(data, list):
        data[:] = [non_finite(item, fields, value) for item in data]
    return data


def _as_value(figure, value: float):
    if isinstance(figure, list):
        return [value if x is None else x for x in figure]
    if isinstance(figure, dict):
        return {k: value if x is None else x for k, x in figure.items()}
    return value if figure is None else figure
