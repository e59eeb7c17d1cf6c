"""The electrical analogy: netlists of the mechanical model for circuit simulators, and running them.

`carrier` writes the oscillator-level netlist (and the .subckt library), `envelope` the envelope equations
as a circuit, `runner` runs ngspice and reads its raw files; `_common` holds what they share.
"""
from ._common import METHODS, Namer, NgspiceSettings, comment_text, drive_schedule, failure, num

__all__ = ["METHODS", "Namer", "NgspiceSettings", "comment_text", "drive_schedule", "failure", "num"]
