"""Port values <-> the netlist's bit nodes: bit i of port p is node ``p[i]``, LSB = bit 0.

A port declared ``signed`` holds a two's complement value, as Verilog reads it: a 4-bit signed port
takes and gives -8..7, an unsigned one 0..15.
"""
from __future__ import annotations

import numpy as np

from ..errors import Mech2SpiceError


def input_bits(netlist) -> list[str]:
    """Input node names in batch-column order (ports in declaration order, LSB first)."""
    return [f"{p}[{i}]" for p, w in netlist.inputs.items() for i in range(w)]


def output_bits(netlist) -> list[str]:
    """Output node names in batch-column order (ports in declaration order, LSB first)."""
    return [f"{p}[{i}]" for p, w in netlist.outputs.items() for i in range(w)]


def pack_inputs(netlist, values: dict[str, int]) -> dict[str, int]:
    """Port integers -> {"a[0]": bit, ...} for every input bit (unset ports are 0)."""
    bits = dict.fromkeys(input_bits(netlist), 0)
    for port, value in values.items():
        if port not in netlist.inputs:
            if port == netlist.clock:
                raise Mech2SpiceError(f"'{port}' is the clock: every cycle pulses it; leave it out of the inputs "
                                      "given")
            known = ", ".join(netlist.inputs) or "none"
            raise Mech2SpiceError(f"unknown input port '{port}' (inputs: {known})")
        width, span = netlist.inputs[port], port_range(netlist, port)
        if not isinstance(value, (int, np.integer)) or isinstance(value, bool):
            raise Mech2SpiceError(f"input '{port}' needs an integer, got {value!r}")
        if value not in span:
            raise Mech2SpiceError(f"value {value} does not fit input '{port}' ({width} bit{'s' * (width != 1)}"
                                  f"{', signed' * (port in netlist.signed)}, {span[0]}..{span[-1]})")
        for i in range(width):
            bits[f"{port}[{i}]"] = (int(value) >> i) & 1
    return bits


def port_range(netlist, port: str) -> range:
    """The values an input port takes: 0..2^w-1, or -2^(w-1)..2^(w-1)-1 when it is signed."""
    width = netlist.inputs[port]
    return range(-(1 << width - 1), 1 << width - 1) if port in netlist.signed else range(1 << width)


def port_values(netlist, bits: dict[str, int | None]) -> dict[str, int | None]:
    """Output port -> integer from its bits (None when any bit is None: undecodable; signed ports
    read as two's complement)."""
    out = {}
    for port, width in netlist.outputs.items():
        vals = [bits[f"{port}[{i}]"] for i in range(width)]
        value = None if None in vals else sum(v << i for i, v in enumerate(vals))
        if value is not None and port in netlist.signed and vals[-1]:
            value -= 1 << width
        out[port] = value
    return out
