"""Run a program on the processor: the ISS, or the synthesized NOR netlist at logic level.

``run_program`` returns ``{"cycles", "halted", "memory", "registers", "wall_s", "backend"}`` and,
when a checkpoint file is given, writes the whole machine state there every ``checkpoint_every``
cycles and at the end; ``resume=True`` continues from that file (cycle counts are totals).
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import sys
import time
from pathlib import Path

from ..errors import Mech2SpiceError
from .. import data
from .asm import Program, assemble_program
from .iss import FETCH, ISS, LDNX, LOAD, REGISTERS, Cycle
from .isa import mnemonic
from .memory import Memory
from .tm import Tape

CPU_VERILOG = data.verilog("cpu.v")
BACKENDS = ("iss", "logic", "envelope", "rk4")
CHECKPOINT_FORMAT = "mech2spice-cpu-checkpoint"


# --------------------------------------------------------------------------- programs

def load_program(source) -> Program:
    """A Program from an .asm path, a .bin path, or raw bytes."""
    if isinstance(source, (bytes, bytearray, list)):
        return Program(bytes(source), "", {})
    path = Path(source)
    try:
        data = path.read_bytes()
    except OSError as err:
        raise Mech2SpiceError(f"cannot read program {path}: {err.strerror or err}") from None
    if path.suffix.lower() == ".asm":
        try:
            return assemble_program(data.decode("utf-8"))
        except Mech2SpiceError as err:
            raise Mech2SpiceError(f"{path}: {err}") from None
        except UnicodeDecodeError:
            raise Mech2SpiceError(f"{path}: not a text file") from None
    return Program(data, "", {})


def make_memory(program: Program) -> Memory:
    """The memory with the program image and, for a .tape program, the tape mapped in."""
    devices = {}
    if program.tape is not None:
        devices[program.tape.addr] = Tape.from_digits(program.tape.cells, program.tape.head)
    return Memory(program.image, devices)


# --------------------------------------------------------------------------- logic backend

@functools.lru_cache(maxsize=2)
def cpu_netlist(path: str = str(CPU_VERILOG)):
    """The synthesized processor (cached: Yosys takes a few seconds)."""
    from ..synthesis.synth import synthesize
    return synthesize(path)


def register_map(netlist) -> dict[str, tuple[str, int]]:
    """latch -> (register, bit), read from the net each latch's D input carries (next_<reg>[i])."""
    g = netlist.graph
    out = {}
    for q in netlist.latches():
        (src,) = g.predecessors(q)
        net = str(g.nodes[src].get("net", ""))
        name, _, idx = net.partition("[")
        if not name.startswith("next_"):
            raise Mech2SpiceError(f"latch {q} is fed by net '{net}', not a next_<register> net; "
                                  "cannot read the processor state")
        out[q] = (name[5:], int(idx.rstrip("]") or 0))
    return out


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
        vals = dict.fromkeys(("pc", "a", "b", "c", "d", "ov", "ld", "nx"), 0)
        for q, (reg, bit) in self.regmap.items():
            vals[reg] |= self.logic.state[q] << bit
        ld, nx = vals.pop("ld"), vals.pop("nx")
        phase = LOAD if ld else LDNX if nx else FETCH
        return {**{r: vals[r] for r in REGISTERS if r != "phase"}, "phase": phase}

    def set_registers(self, regs: dict) -> None:
        vals = {r: regs[r] for r in REGISTERS if r != "phase"}
        vals.update(ld=int(regs["phase"] == LOAD), nx=int(regs["phase"] == LDNX))
        self.logic.state = {q: (vals[reg] >> bit) & 1 for q, (reg, bit) in self.regmap.items()}

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
        while not self.halted and self.cycle < max_cycles:
            self.step()
        return self.cycle, self.halted


PHYSICAL = ("envelope", "rk4")


def make_cpu(backend: str, memory: Memory, power_up: bool = True, **physical):
    """physical: step / settle for the oscillator-level backends (physical.PhysicalCPU)."""
    if backend == "iss":
        return ISS(memory)
    if backend == "logic":
        return LogicCPU(memory)
    if backend in PHYSICAL:
        from .physical import PhysicalCPU
        return PhysicalCPU(memory, backend, power_up=power_up, **physical)
    raise Mech2SpiceError(f"unknown backend '{backend}' (choose from {', '.join(BACKENDS)})")


# --------------------------------------------------------------------------- checkpoints

def _state(cpu, program: Program, backend: str) -> dict:
    devices = {str(a): d.state() for a, d in cpu.mem.devices.items()}
    return {"format": CHECKPOINT_FORMAT, "version": 1, "backend": backend,
            "program_sha256": hashlib.sha256(program.image).hexdigest(),
            "cycle": cpu.cycle, "halted": cpu.halted, "registers": cpu.registers(),
            "memory": cpu.mem.snapshot(), "devices": devices}


def physical_state_path(checkpoint) -> Path:
    """Where a physical run keeps its oscillator state beside the JSON checkpoint."""
    return Path(str(checkpoint) + ".state.npz")


def save_checkpoint(cpu, path, program: Program, backend: str) -> None:
    if hasattr(cpu, "save"):             # the oscillator state first: the JSON names a complete pair
        cpu.save(physical_state_path(path))
    write_checkpoint(path, _state(cpu, program, backend))


def write_checkpoint(path, state: dict) -> None:
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(state))
    os.replace(tmp, path)            # a crash mid-write leaves the previous checkpoint intact


def read_checkpoint(path, program: Program, backend: str) -> dict:
    try:
        state = json.loads(Path(path).read_text())
    except OSError as err:
        raise Mech2SpiceError(f"cannot read checkpoint {path}: {err.strerror or err}") from None
    except json.JSONDecodeError as err:
        raise Mech2SpiceError(f"checkpoint {path} is not valid JSON ({err.msg})") from None
    if not isinstance(state, dict) or state.get("format") != CHECKPOINT_FORMAT:
        raise Mech2SpiceError(f"{path} is not a processor checkpoint")
    if state["program_sha256"] != hashlib.sha256(program.image).hexdigest():
        raise Mech2SpiceError(f"checkpoint {path} belongs to a different program")
    if state["backend"] != backend:
        raise Mech2SpiceError(f"checkpoint {path} was written by the {state['backend']} backend, "
                              f"not {backend}")
    return state


def _restore(cpu, state: dict, path) -> None:
    if hasattr(cpu, "load"):
        cpu.load(physical_state_path(path))
    cpu.mem.cells = [int(v) for v in state["memory"]]
    for addr, dev_state in state.get("devices", {}).items():
        if int(addr) not in cpu.mem.devices:
            raise Mech2SpiceError(f"checkpoint has a device at {addr} that the program does not map")
        cpu.mem.devices[int(addr)].restore(dev_state)
    cpu.set_registers(state["registers"])
    cpu.cycle, cpu.halted = int(state["cycle"]), bool(state["halted"])


# --------------------------------------------------------------------------- the runner

def run_program(source, backend: str = "iss", max_cycles: int = 100_000, checkpoint=None,
                resume: bool = False, progress: bool = False, checkpoint_every: int | None = None,
                trace=None, **physical) -> dict:
    """Run until halted or ``max_cycles`` (total) and return the result dict.  Checkpoints are written
    every ``checkpoint_every`` cycles (default 1000, or 10 for the oscillator-level backends)."""
    checkpoint_every = checkpoint_every or (10 if backend in PHYSICAL else 1000)
    if max_cycles < 0 or checkpoint_every < 1:
        raise Mech2SpiceError("max_cycles must be >= 0 and checkpoint_every >= 1")
    if resume and checkpoint is None:
        raise Mech2SpiceError("resume needs a checkpoint file")
    program = load_program(source)
    state = read_checkpoint(checkpoint, program, backend) if resume else None
    t0 = time.perf_counter()                       # wall_s includes building the model and power-up
    cpu = make_cpu(backend, make_memory(program), power_up=not resume, **physical)
    if resume:
        _restore(cpu, state, checkpoint)
    last_report = t0
    while not cpu.halted and cpu.cycle < max_cycles:
        rec = cpu.step()
        if trace is not None:
            trace(rec, cpu)
        if checkpoint is not None and cpu.cycle % checkpoint_every == 0:
            save_checkpoint(cpu, checkpoint, program, backend)
        if progress and time.perf_counter() - last_report > 1.0:
            last_report = time.perf_counter()
            print(f"[{backend}] cycle {cpu.cycle}", file=sys.stderr, flush=True)
    if checkpoint is not None:
        save_checkpoint(cpu, checkpoint, program, backend)
    result = {"backend": backend, "cycles": cpu.cycle, "halted": cpu.halted,
              "memory": cpu.mem.snapshot(), "registers": cpu.registers(),
              "wall_s": time.perf_counter() - t0}
    if backend in PHYSICAL:
        result.update(periods=cpu.period, simulated_periods=cpu.simulated, step=cpu.step_periods,
                      settle=cpu.settle)
    for addr, dev in cpu.mem.devices.items():
        result.setdefault("devices", {})[str(addr)] = dev.state()
    return result
