"""The processor's machines behind one interface: the ISS, the NOR netlist at logic level, the oscillators.

Every machine has `mem`, `cycle`, `halted`, `step() -> Cycle` (one clock cycle), `registers()` and
`set_registers(regs)`; the oscillator-level one also `save(path)` / `load(path)` its dynamical state.
"""
from __future__ import annotations

from typing import Protocol

from ..errors import Mech2SpiceError
from .isa import mnemonic
from .iss import FETCH, ISS, Cycle
from .memory import Memory
from .netlist import cpu_netlist, latches_from_registers, register_map, registers_from_latches
from ..backends import names
from .physical import PHYSICAL, PhysicalCPU

CIRCUIT = ("vacask-envelope",)   # the whole processor, memory included, in a circuit simulator (cpu/circuit.py)
LOGIC = names(lambda caps: not caps.physical)   # the NOR netlist as Boolean logic (the registry's oracle)
BACKENDS = ("iss", *LOGIC, *PHYSICAL, *CIRCUIT)


class Machine(Protocol):
    """What the runner needs of a processor model."""

    mem: Memory
    cycle: int
    halted: bool

    def step(self) -> Cycle:
        """One clock cycle."""

    def registers(self) -> dict:
        """The architectural registers now."""

    def set_registers(self, regs: dict) -> None:
        """Restore the architectural registers (a checkpoint)."""


class LogicCPU:
    """The synthesized NOR netlist of verilog/cpu.v clocked cycle by cycle against a Memory."""

    def __init__(self, memory: Memory, netlist=None):
        from ..backends.logic import ClockedLogic
        self.netlist = netlist if netlist is not None else cpu_netlist()
        self.logic = ClockedLogic(self.netlist)
        self.regmap = register_map(self.netlist)
        self.mem = memory
        self.cycle = 0
        self.halted = False

    def registers(self) -> dict:
        """The architectural registers held by the latches."""
        return registers_from_latches(self.regmap, self.logic.state.__getitem__)

    def set_registers(self, regs: dict) -> None:
        """Load the latches with these registers (a restored checkpoint)."""
        self.logic.state = latches_from_registers(self.regmap, regs)

    def step(self) -> Cycle:
        """One clock cycle: read at raddr, present rdata, commit the write, clock the latches."""
        regs = self.registers()
        raddr = self.logic.evaluate({"rdata": 0})["raddr"]   # raddr depends on the state only
        rdata = self.mem.read(raddr)
        outs = self.logic.evaluate({"rdata": rdata})
        before = self.logic.state
        self.logic.tick({"rdata": rdata})
        self.mem.commit(outs["waddr"], outs["wdata"], outs["we"])
        # Only JMP_C to itself leaves every latch unchanged: that is the halt.
        self.halted = self.logic.state == before
        rec = Cycle(self.cycle, regs["pc"], regs["phase"],
                    mnemonic(rdata) if regs["phase"] == FETCH else None,
                    raddr, rdata, outs["we"], outs["waddr"], outs["wdata"])
        self.cycle += 1
        return rec

    def run(self, max_cycles: int) -> tuple[int, bool]:
        """Step until halted or `max_cycles` in total."""
        while not self.halted and self.cycle < max_cycles:
            self.step()
        return self.cycle, self.halted


def make_cpu(backend: str, memory: Memory, power_up: bool = True, **physical) -> Machine:
    """The machine for a backend; `physical`: step / settle for the oscillator-level ones (PhysicalCPU),
    cycles / max_step / settle for the circuit (CircuitCPU)."""
    if backend == "iss":
        return ISS(memory)
    if backend in LOGIC:
        return LogicCPU(memory)
    if backend in PHYSICAL:
        return PhysicalCPU(memory, backend, power_up=power_up, **physical)
    if backend in CIRCUIT:
        from .circuit import CircuitCPU
        return CircuitCPU(memory, power_up=power_up, **physical)
    raise Mech2SpiceError(f"unknown backend '{backend}' (choose from {', '.join(BACKENDS)})")
