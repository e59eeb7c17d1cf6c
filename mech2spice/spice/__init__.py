"""The electrical analogy: netlists of the mechanical model for circuit simulators, and running them.

`oscillator_netlist` writes the oscillator-level netlist (and the .subckt library), `envelope_netlist` the
envelope equations as a circuit, `runner` runs ngspice and reads its raw files; `_common` holds what they
share.  `vacask` and `veriloga` are the VACASK forms, `openvaf` compiles their Verilog-A.
"""
from ._common import (DEFAULT_TIMEOUT_S, METHODS, NETLIST, Namer, NgspiceSettings, combinational_only, comment_text,
                      drive_schedule, failure, num)

__all__ = ["DEFAULT_TIMEOUT_S", "METHODS", "NETLIST", "Namer", "NgspiceSettings", "combinational_only", "comment_text",
           "drive_schedule", "failure", "num"]
