"""Figures of processor runs shared by the report scripts (scripts/cpu_report.py, scripts/cpu_physical.py)."""
from __future__ import annotations

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402


def sieve_moments(frames) -> list[int]:
    """Four moments of the sieve like the paper's Fig. 8: the last mark of 2's multiples, of 3's, the
    first mark of 5's, and the end."""
    writes = [k for k, (rec, _, _) in enumerate(frames) if rec.we]
    last = {frames[k][0].wdata: k for k in writes}       # last write of each step p (the value written)
    first5 = next(k for k in writes if frames[k][0].wdata == 5)
    return [last[2], last[3], first5, len(frames) - 1]


def _grid_xy(addr: int) -> tuple[int, int]:
    return addr % 16, addr // 16               # address 0 bottom-left, along rows, then up


def fig_sieve(frames, moments, path, source: str) -> None:
    """The paper's Fig. 8: memory at four moments (frames: (Cycle, memory before, memory after))."""
    fig, axes = plt.subplots(1, 4, figsize=(14, 5.6))
    norm = matplotlib.colors.PowerNorm(0.3, vmin=0, vmax=255)     # marks are small values (2..5)
    for ax, k in zip(axes, moments):
        rec, _, mem = frames[k]
        img = [[mem[16 * r + c] for c in range(16)] for r in range(16)]
        ax.imshow(img, origin="lower", cmap="viridis", norm=norm, extent=(0, 16, 0, 16))
        # magnified primality region (addresses 128..159 = n 0..31) above the grid
        for n in range(32):
            x, y = (n % 16), 17.2 + 2 * (n // 16)
            val = mem[128 + n]
            ax.add_patch(Rectangle((x, y), 1, 2, facecolor=plt.cm.viridis(norm(val)), edgecolor="w", lw=0.5))
            ax.text(x + 0.5, y + 1, str(n), ha="center", va="center", fontsize=5.5,
                    color="w" if norm(val) < 0.5 else "k")
        ax.add_patch(Rectangle((0, 8), 16, 2, fill=False, ls=":", ec="w", lw=1.2))
        for addr, color in ((rec.raddr, "lime"), (rec.waddr if rec.we else None, "red")):
            if addr is not None:
                x, y = _grid_xy(addr)
                ax.add_patch(Rectangle((x, y), 1, 1, fill=False, ec=color, lw=2))
        ax.set_xlim(0, 16)
        ax.set_ylim(0, 21.4)
        ax.set_xticks([])
        ax.set_yticks([])
        what = f"{rec.instr}" if rec.instr else f"{rec.phase} data"
        ax.set_title(f"cycle {rec.cycle} ({what})\nread {rec.raddr}" + (f", write {rec.waddr}" if rec.we else ""),
                     fontsize=9)
    fig.suptitle(f"Sieve of Eratosthenes on {source}: memory (address 0 bottom left, 16 per row); green: read, "
                 "red: write;\ndotted: primality array 128..159, magnified above (label n, non-zero = composite)",
                 fontsize=10)
    fig.tight_layout(rect=(0, 0, 1, 0.9))
    fig.savefig(path, dpi=130)
    plt.close(fig)


