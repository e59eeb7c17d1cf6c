#!/usr/bin/env python3
"""Regenerate the checked-in ngspice subcircuit library in subckts/ (same as `mech2spice subckts`).

usage: python scripts/gen_subckts.py [DIRECTORY] [--params default|printed|FILE.json]
"""
from __future__ import annotations

import argparse
from pathlib import Path

from mech2spice.physics.params import load_params
from mech2spice.spice.carrier import write_subckt_library

ROOT = Path(__file__).resolve().parent.parent


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("directory", nargs="?", default=str(ROOT / "subckts"))
    ap.add_argument("--params", default=None, help="gate parameter set (default: 'default')")
    args = ap.parse_args(argv)
    for path in write_subckt_library(args.directory, load_params(args.params)):
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
