"""reports/domain.md: the operating domain of the gate, the adder and the processor (drive frequency, supply
drive, stiffness drift; without and with spread), rendered from domain.json (mech2spice/studies/domain.py
measures it); `plot_map` also draws `mech2spice domain`'s figure.

Run: mech2spice report domain [--only gate|adder|cpu] [--quick] [--render]
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ._common import md_table, measured_on, out_dir, pyplot, save_figure, stored

TITLES = {"gate": "the loaded NOR gate", "adder": "the 2-bit adder (16 input vectors)",
          "cpu": "the processor (sieve, first cycles)"}
FIGURES = {s: f"domain_{s}.png" for s in TITLES}


def _fmt(v: float) -> str:
    return "0" if v == 0 else f"{v:+.3g}"


def _grid(m: dict, value) -> np.ndarray:
    return np.array([[value(c) for c in row] for row in m["cells"]], float)


def _yield(c: dict) -> float:
    return c["spread"]["yield"] if c.get("spread") else np.nan


def measured_what(m: dict) -> str:
    """One line: what the map was measured on (design model, parameters, grid, spread samples)."""
    sp = m.get("spread") or {}
    spread = (f"{m['samples']} spread samples per point (sigma {sp.get('sigma', m.get('sigma'))}, trim "
              f"{sp.get('trim', 'none')}, residual {sp.get('residual', 0)}, seed {sp.get('seed', 0)})"
              if m.get("samples") else "no spread samples")
    held = ", ".join(f"{k} {_fmt(v)}" for k, v in m["fixed"].items())
    return (f"{m['method']['model']}; params {m['method']['params']}; {len(m['x']['values'])}x{len(m['y']['values'])} "
            f"grid; {held} held; {spread}")


def plot_map(m: dict, path: Path, title: str | None = None) -> None:
    """One map as two panels: the nominal design (works / fails, margin where there is one) and, with
    samples, the spread samples' yield at each point."""
    plt = pyplot()
    panels = 2 if m.get("samples") else 1
    fig, axs = plt.subplots(1, panels, figsize=(5.2 * panels + 0.6, 4.6), squeeze=False)
    _panel(axs[0, 0], m, _grid(m, lambda c: float(c["pass"])), "nominal: works (blue) / fails (red)",
           [[("ok" if c["pass"] else "x") + (f"\n{c['margin']:+.2f}" if c.get("margin") is not None else "")
             for c in row] for row in m["cells"]])
    if panels == 2:
        _panel(axs[0, 1], m, _grid(m, _yield), f"yield of {m['samples']} spread samples",
               [[f"{c['spread']['passed']}/{c['spread']['samples']}" for c in row] for row in m["cells"]])
    fig.suptitle((title or f"operating domain: {m['design']}") + "\n" + _wrap(measured_what(m), 110), fontsize=8.5)
    save_figure(fig, path, dpi=100)


def _wrap(text: str, width: int) -> str:
    import textwrap
    return "\n".join(textwrap.wrap(text, width))


def _panel(ax, m: dict, z: np.ndarray, title: str, labels) -> None:
    xs, ys = m["x"]["values"], m["y"]["values"]
    ax.imshow(z, origin="lower", cmap="RdYlBu", vmin=0, vmax=1, aspect="auto")
    for iy, row in enumerate(labels):
        for ix, text in enumerate(row):
            ax.text(ix, iy, text, ha="center", va="center", fontsize=7)
    ax.set_xticks(range(len(xs)), [_fmt(v) for v in xs], fontsize=7)
    ax.set_yticks(range(len(ys)), [_fmt(v) for v in ys], fontsize=7)
    ax.set_xlabel(m["x"]["label"], fontsize=8)
    ax.set_ylabel(m["y"]["label"], fontsize=8)
    ax.set_title(title, fontsize=9)


def figure(section: str, maps: dict, path: Path) -> None:
    """A section's maps stacked, one row each (both panels)."""
    plt = pyplot()
    names = list(maps)
    spread = any(m.get("samples") for m in maps.values())
    fig, axs = plt.subplots(len(names), 2 if spread else 1, figsize=(11.5 if spread else 6, 4.4 * len(names)),
                            squeeze=False)
    for r, name in enumerate(names):
        m = maps[name]
        _panel(axs[r, 0], m, _grid(m, lambda c: float(c["pass"])), f"{name}: nominal works (blue) / fails (red)",
               [[("ok" if c["pass"] else "x") + (f"\n{c['margin']:+.2f}" if c.get("margin") is not None else "")
                 for c in row] for row in m["cells"]])
        if spread:
            _panel(axs[r, 1], m, _grid(m, _yield), f"{name}: yield of {m['samples']} spread samples",
                   [[f"{c['spread']['passed']}/{c['spread']['samples']}" if c.get("spread") else "" for c in row]
                    for row in m["cells"]])
    first = maps[names[0]]
    fig.suptitle(f"operating domain of {TITLES.get(section, section)}\n" + _wrap(measured_what(first), 130),
                 fontsize=9)
    save_figure(fig, path, dpi=100)


def extent(m: dict) -> str:
    """Along each axis through nominal: the range of grid values where the nominal design works."""
    xs, ys = m["x"]["values"], m["y"]["values"]
    out = []
    if 0.0 in ys:
        row = m["cells"][ys.index(0.0)]
        ok = [v for v, c in zip(xs, row) if c["pass"]]
        out.append(f"{m['x']['name']} {_span(ok)}")
    if 0.0 in xs:
        col = [r[xs.index(0.0)] for r in m["cells"]]
        ok = [v for v, c in zip(ys, col) if c["pass"]]
        out.append(f"{m['y']['name']} {_span(ok)}")
    return "; ".join(out)


def _span(ok: list[float]) -> str:
    return "nowhere on the grid" if not ok else f"{_fmt(min(ok))} to {_fmt(max(ok))}"


def table(m: dict) -> list[str]:
    """The map as a markdown table: y down, x across; 'ok'/'x' for the nominal design, k/n of the samples."""
    xs = m["x"]["values"]
    rows = []
    for vy, row in reversed(list(zip(m["y"]["values"], m["cells"]))):
        rows.append([_fmt(vy)] + [("ok" if c["pass"] else "x") + (
            f" {c['spread']['passed']}/{c['spread']['samples']}" if c.get("spread") else "") for c in row])
    return md_table([f"{m['y']['name']} \\ {m['x']['name']}"] + [_fmt(v) for v in xs], rows)


def markdown(d: dict) -> str:
    lines = ["# Operating domain", "",
             "Generated by `mech2spice report domain` (measured by `mech2spice/studies/domain.py`, rendered by "
             f"`mech2spice/reports/domain.py`){' with --quick' if d.get('quick') else ''}; measured on "
             f"{measured_on(d['conditions'])}.", "", DOC, ""]
    for section in TITLES:
        if section not in d:
            continue
        wall = d.get("sections", {}).get(section, {}).get("wall_s")
        lines += [f"## {TITLES[section][0].upper()}{TITLES[section][1:]}", "",
                  f"![{section}]({FIGURES[section]})", ""]
        for name, m in d[section].items():
            lines += [f"**{name}** ({m['works']} of {m['points']} points work nominally; {extent(m)}): "
                      f"{measured_what(m)}.", "", *table(m), ""]
        if wall is not None:
            lines += [f"Measured in {wall:.0f} s.", ""]
    return "\n".join(lines).rstrip("\n") + "\n"


DOC = """Where each design works as its operating point moves from nominal (0): `freq`, the drive frequency;
`amp`, the supply drive F_C of every gate (inputs and clock at their logic levels); `drift`, every
stiffness times (1 + drift), a common-mode temperature drift (the same as `--drift`).  All three are
relative changes (`mech2spice/experiments/domain.py`).  A cell reads `ok` or `x` for the nominal design
and `k/n` for the spread samples that work there (the same samples at every point).  The gate works
when inputs anywhere in the bands give outputs in the band NOR asks for (the loaded gate's margin, as
`gate --spread` judges it); the adder when all 16 sums decode right on the envelope engine; the
processor when every cycle equals the instruction-set simulator's.  A single map of any design:
`mech2spice domain DESIGN --sweep freq=LO:HI:N --sweep amp=LO:HI:N [--spread S --samples N] -o MAP.png`."""


def write(directory="reports", only=None, quick: bool = False, render: bool = False) -> Path:
    """Measure the sections in `only` (default all; `render`: none) into domain.json and rewrite domain.md and
    its figures from the whole JSON."""
    out = out_dir(directory)
    path = out / "domain.json"
    if not render:
        import sys
        from ..studies import domain as study          # measuring loads the engines; rendering does not
        study.measure_into(path, only, quick, progress=sys.stderr.isatty())
    d = stored(path, "domain")
    for section in TITLES:
        if section in d:
            figure(section, d[section], out / FIGURES[section])
    (out / "domain.md").write_text(markdown(d))
    return out / "domain.md"
