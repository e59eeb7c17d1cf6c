"""Where mech2spice keeps what it can rebuild: compiled Verilog-A models, Yosys netlists."""
from __future__ import annotations

import os
from pathlib import Path


def cache_dir() -> Path:
    """$MECH2SPICE_CACHE, else $XDG_CACHE_HOME/mech2spice, else ~/.cache/mech2spice."""
    env = os.environ.get("MECH2SPICE_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "mech2spice"
