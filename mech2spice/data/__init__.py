"""Data the package reads at run time: example Verilog designs, their stimuli and processor programs.

Shipped as package data, so a non-editable install finds them; the repository's top-level ``verilog/``
and ``programs/`` are links to these folders.
"""
from __future__ import annotations

from importlib.resources import files
from pathlib import Path


def path(*parts: str) -> Path:
    """The file ``data/<parts...>`` of the installed package, as a filesystem path."""
    return Path(str(files(__name__).joinpath(*parts)))


def verilog(name: str) -> Path:
    """A design shipped with the package, e.g. ``verilog("adder2.v")``."""
    return path("verilog", name)


def program(name: str) -> Path:
    """A processor program shipped with the package, e.g. ``program("sieve.asm")``."""
    return path("programs", name)
