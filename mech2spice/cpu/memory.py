"""The 256-byte memory outside the processor, with optional memory-mapped devices.

Reads are combinational (``read(addr)`` is what the processor sees within the cycle); a write is
committed at the clock edge (``commit``).  A device mapped at an address (e.g. the Turing-machine
tape at 255) answers reads and takes writes there instead of the array.
"""

from __future__ import annotations

from typing import Protocol

from ..errors import Mech2SpiceError
from .isa import MEM_SIZE


class Device(Protocol):
    """A memory-mapped device: answers reads and takes writes at the address it is mapped to."""
    def read(self) -> int:
        """The byte the processor reads at the device's address."""

    def write(self, value: int) -> None:
        """Take a byte written to the device's address."""


class Memory:
    """The 256-byte memory array plus devices mapped at single addresses."""
    def __init__(self, data=b"", devices: dict[int, Device] | None = None):
        data = list(data)
        if len(data) > MEM_SIZE:
            raise Mech2SpiceError(f"memory image has {len(data)} bytes; the processor addresses {MEM_SIZE}")
        if any(not 0 <= int(v) <= 255 for v in data):
            raise Mech2SpiceError("memory image values must be bytes (0..255)")
        self.cells = [int(v) for v in data] + [0] * (MEM_SIZE - len(data))
        self.devices = dict(devices or {})

    def read(self, addr: int) -> int:
        """The byte at addr as the processor sees it within the cycle (a device's, if one is mapped there)."""
        dev = self.devices.get(addr)
        return dev.read() if dev is not None else self.cells[addr]

    def commit(self, waddr: int, wdata: int, we: int) -> None:
        """The clock edge: store wdata at waddr if we = 1."""
        if not we:
            return
        dev = self.devices.get(waddr)
        if dev is not None:
            dev.write(wdata)
        else:
            self.cells[waddr] = wdata

    def snapshot(self) -> list[int]:
        """The array's 256 bytes (device addresses show the array cell, which devices never touch)."""
        return list(self.cells)

    @staticmethod
    def decode_address(bits: list[int | None], cycle: int, what: str) -> int:
        """An address (or data byte) from decoded bits, LSB first; an invalid (None) bit is an error.

        The physical backends decode each output bit from its amplitude; a bit outside both logic
        bands must stop the run rather than be rounded into a wrong address.
        """
        for i, bit in enumerate(bits):
            if bit is None:
                raise Mech2SpiceError(f"cycle {cycle}: {what} bit {i} is invalid (its amplitude is "
                                      "outside both logic bands)")
            if bit not in (0, 1):
                raise Mech2SpiceError(f"cycle {cycle}: {what} bit {i} is {bit!r}, not 0/1")
        return sum(bit << i for i, bit in enumerate(bits))
