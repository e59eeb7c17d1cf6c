"""The 8-bit processor's instruction set: one source for the assembler, the ISS and the Verilog check.

An instruction is one byte; its low nibble is the opcode and the high nibble is ignored (the
assembler writes 0).  The grouping (bits 3..2) lets the NOR decoder in ``verilog/cpu.v`` share
terms: 00xx register moves, 01xx D/C arithmetic, 10xx C/jump/memory, 11xx skips and LDNX.

Timing: one clock cycle = one memory read.  Every instruction takes one cycle, except LOAD_AB and
LDNX_AB, which need a second read and take two (the second cycle is a *data* cycle: the byte read
is data, not an opcode).  A write (SAVE_AB) is committed at the clock edge ending its cycle.
"""

from __future__ import annotations

from ..errors import Mech2SpiceError

MEM_SIZE = 256
OPCODE_MASK = 0x0F

#: mnemonic -> opcode (low nibble)
OPCODES: dict[str, int] = {
    "SWAP_AC": 0x0, "COPY_AC": 0x1, "SWAP_AB": 0x2, "SWAP_BD": 0x3,
    "RSL_D": 0x4, "RSA_D": 0x5, "APLUSB_TO_D": 0x6, "ANORB_TO_C": 0x7,
    "NOT_C": 0x8, "JMP_C": 0x9, "SAVE_AB": 0xA, "LOAD_AB": 0xB,
    "SKPNX_A_GRT_B": 0xC, "SKPNX_A_DIF_B": 0xD, "SKPNX_OVER": 0xE, "LDNX_AB": 0xF,
}
MNEMONICS: dict[int, str] = {v: k for k, v in OPCODES.items()}

#: what each instruction does, for listings and the report
SEMANTICS: dict[str, str] = {
    "SWAP_AC": "A <-> C",
    "COPY_AC": "C <- A",
    "SWAP_AB": "A <-> B",
    "SWAP_BD": "B <-> D",
    "RSL_D": "D <- D >> 1 (logical: bit 7 <- 0)",
    "RSA_D": "D <- D >> 1 (arithmetic: bit 7 kept)",
    "APLUSB_TO_D": "D <- (A + B) mod 256; overflow <- (A + B > 255)",
    "ANORB_TO_C": "C <- ~(A | B)",
    "NOT_C": "C <- ~C",
    "JMP_C": "pc <- C (a jump to itself halts)",
    "SAVE_AB": "mem[B] <- A",
    "LOAD_AB": "B <- mem[A]",
    "SKPNX_A_GRT_B": "skip the next byte if A > B (unsigned)",
    "SKPNX_A_DIF_B": "skip the next byte if A != B",
    "SKPNX_OVER": "skip the next byte if the last APLUSB_TO_D overflowed",
    "LDNX_AB": "A <- mem[pc + 1]; continue at pc + 2",
}

#: clock cycles per instruction
CYCLES: dict[str, int] = {name: 2 if name in ("LOAD_AB", "LDNX_AB") else 1 for name in OPCODES}


def opcode(name: str) -> int:
    """The opcode of a mnemonic (case-insensitive); Mech2SpiceError if unknown."""
    try:
        return OPCODES[name.upper()]
    except KeyError:
        raise Mech2SpiceError(f"unknown mnemonic '{name}'") from None


def mnemonic(byte: int) -> str:
    """The instruction a memory byte decodes to (only the low nibble counts)."""
    return MNEMONICS[byte & OPCODE_MASK]
