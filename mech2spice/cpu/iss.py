"""Instruction-set simulator: the golden, cycle-exact model of ``verilog/cpu.v``.

One ``step()`` is one clock cycle: one memory read (at pc, or at A in a LOAD_AB data cycle), the
register updates of that cycle, and the write committed at its closing edge.  The processor halts
when it executes JMP_C with C == pc (a jump to itself); that cycle is counted.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from ..errors import Mech2SpiceError
from .isa import mnemonic
from .memory import Memory

FETCH, LOAD, LDNX = "fetch", "load", "ldnx"   # what the byte read this cycle is
REGISTERS = ("pc", "a", "b", "c", "d", "ov", "phase")


@dataclass(frozen=True)
class Cycle:
    """What the processor did in one clock cycle (registers as they were at its start)."""
    cycle: int            # 0-based index of this cycle
    pc: int
    phase: str            # FETCH, or LOAD / LDNX for the data cycle of those instructions
    instr: str | None     # the mnemonic executed (None in a data cycle)
    raddr: int
    rdata: int
    we: int
    waddr: int
    wdata: int


class ISS:
    """The cycle-exact instruction-set simulator: registers, memory, one clock cycle per step()."""
    def __init__(self, memory: Memory | bytes | list, trace: Callable[[Cycle], None] | None = None):
        self.mem = memory if isinstance(memory, Memory) else Memory(memory)
        self.trace = trace
        self.pc = self.a = self.b = self.c = self.d = self.ov = 0
        self.phase = FETCH
        self.cycle = 0
        self.halted = False

    # ------------------------------------------------------------------ state
    def registers(self) -> dict:
        """The register state (pc, a, b, c, d, ov, phase) as a dict."""
        return {r: getattr(self, r) for r in REGISTERS}

    def set_registers(self, regs: dict) -> None:
        """Restore a register state made by registers(); checks every register and the phase."""
        for r in REGISTERS:
            if r not in regs:
                raise Mech2SpiceError(f"register state lacks '{r}'")
        if regs["phase"] not in (FETCH, LOAD, LDNX):
            raise Mech2SpiceError(f"unknown phase {regs['phase']!r}")
        for r in REGISTERS:
            setattr(self, r, regs[r])

    # ------------------------------------------------------------------ execution
    def step(self) -> Cycle:
        """One clock cycle."""
        raddr = self.a if self.phase == LOAD else self.pc
        rdata = self.mem.read(raddr)
        instr = mnemonic(rdata) if self.phase == FETCH else None
        # The write port shows B / A every cycle; only SAVE_AB raises we.
        rec = Cycle(self.cycle, self.pc, self.phase, instr, raddr, rdata,
                    int(instr == "SAVE_AB"), self.b, self.a)
        if self.phase == LOAD:
            self.b, self.phase = rdata, FETCH      # pc already points past LOAD_AB
        elif self.phase == LDNX:
            self.a, self.phase = rdata, FETCH
            self.pc = (self.pc + 1) & 0xFF
        else:
            self._execute(instr)
        self.mem.commit(rec.waddr, rec.wdata, rec.we)
        self.cycle += 1
        if self.trace is not None:
            self.trace(rec)
        return rec

    def _execute(self, op: str) -> None:
        nxt = (self.pc + 1) & 0xFF
        a, b, c, d = self.a, self.b, self.c, self.d
        if op == "SWAP_AC":
            self.a, self.c = c, a
        elif op == "COPY_AC":
            self.c = a
        elif op == "SWAP_AB":
            self.a, self.b = b, a
        elif op == "SWAP_BD":
            self.b, self.d = d, b
        elif op == "RSL_D":
            self.d = d >> 1
        elif op == "RSA_D":
            self.d = (d >> 1) | (d & 0x80)
        elif op == "APLUSB_TO_D":
            self.d, self.ov = (a + b) & 0xFF, int(a + b > 0xFF)
        elif op == "ANORB_TO_C":
            self.c = ~(a | b) & 0xFF
        elif op == "NOT_C":
            self.c = ~c & 0xFF
        elif op == "JMP_C":
            self.halted = c == self.pc
            nxt = c
        elif op == "LOAD_AB":
            self.phase = LOAD
        elif op == "LDNX_AB":
            self.phase = LDNX
        elif op in ("SKPNX_A_GRT_B", "SKPNX_A_DIF_B", "SKPNX_OVER"):
            skip = {"SKPNX_A_GRT_B": a > b, "SKPNX_A_DIF_B": a != b, "SKPNX_OVER": bool(self.ov)}[op]
            nxt = (nxt + skip) & 0xFF
        # SAVE_AB changes no register: its write is committed by step()
        self.pc = nxt

    def run(self, max_cycles: int) -> tuple[int, bool]:
        """Step until halted or until ``max_cycles`` cycles have run in total; (cycles, halted)."""
        while not self.halted and self.cycle < max_cycles:
            self.step()
        return self.cycle, self.halted
