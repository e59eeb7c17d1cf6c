"""The paper's 8-bit processor: ISA, assembler, instruction-set simulator, memory, Turing machines,
and a runner for the ISS and the synthesized netlist (``verilog/cpu.v``)."""

from .asm import assemble, assemble_program
from .iss import ISS
from .memory import Memory
from .run import run_program

__all__ = ["assemble", "assemble_program", "ISS", "Memory", "run_program"]
