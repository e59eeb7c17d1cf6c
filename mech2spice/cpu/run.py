"""Run a program on any of the processor's machines (cpu/machines.py), with checkpoints.

``run_program`` returns ``{"cycles", "halted", "memory", "registers", "wall_s", "backend"}`` and,
when a checkpoint file is given, writes the whole machine state there every ``checkpoint_every``
cycles and at the end; ``resume=True`` continues from that file (cycle counts are totals).
"""

from __future__ import annotations

import copy
import dataclasses
import glob
import hashlib
import json
import re
import secrets
import sys
import time
from pathlib import Path

from ..errors import Mech2SpiceError
from ..inputs import (MAX_CYCLES, check_output_file, replace_file, first_json_line, head, is_int, read_input, read_json,
                      strict_json)
from ..waveform import Waveform, is_vcd, write_vcd
from .isa import MEM_SIZE, OPCODE_MASK, OPCODES
from .iss import FETCH, ISS, LDNX, LOAD, REGISTERS
from .asm import Program, assemble_program, check_not_empty
from .machines import CIRCUIT, PHYSICAL, make_cpu
from .memory import Memory
from .tm import Tape

CHECKPOINT_FORMAT = "mech2spice-cpu-checkpoint"


# --------------------------------------------------------------------------- programs

def load_program(source) -> Program:
    """A Program from an .asm path, a .bin path, or raw bytes."""
    if isinstance(source, (bytes, bytearray, list)):
        return Program(bytes(source), "", {})
    path = Path(source)
    data = read_input(path, "program", 16 << 20)
    if path.suffix.lower() == ".asm":
        try:
            return check_not_empty(assemble_program(data.decode("utf-8")))
        except Mech2SpiceError as err:
            raise Mech2SpiceError(f"{path}: {err}") from None
        except UnicodeDecodeError:
            raise Mech2SpiceError(f"{path}: not a text file") from None
    if not data:
        raise Mech2SpiceError(f"program {path} is empty: nothing to run")
    if len(data) > MEM_SIZE:
        raise Mech2SpiceError(f"program {path} holds {len(data)} bytes: a memory image has at most {MEM_SIZE}")
    if _is_text(data):     # every byte decodes as an instruction: a source run as code would run its letters
        raise Mech2SpiceError(f"program {path} is text, not a memory image (`cpu asm` writes one): an assembly "
                              "source needs the .asm suffix")
    return Program(data, "", {})


def _is_text(data: bytes) -> bool:
    """Printable characters and blanks only, at least one of them not blank (a memory image holds opcodes)."""
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        return False
    return bool(text.strip()) and all(c.isprintable() or c.isspace() for c in text)


def is_image(path) -> bool:
    """Whether a file may be a memory image `cpu asm` wrote: not an assembly source, at most MEM_SIZE bytes,
    not text."""
    data = head(path, MEM_SIZE + 1)
    return Path(path).suffix.lower() != ".asm" and len(data) <= MEM_SIZE and not _is_text(data)


def make_memory(program: Program) -> Memory:
    """The memory with the program image and, for a .tape program, the tape mapped in."""
    devices = {}
    if program.tape is not None:
        devices[program.tape.addr] = Tape.from_digits(program.tape.cells, program.tape.head)
    return Memory(program.image, devices)


class IssCheck:
    """The instruction-set simulator in lockstep with another machine, from that machine's state (at power-up
    or at a resumed checkpoint): every cycle's memory access and the registers after it must be the ISS's."""

    def __init__(self, cpu):
        self.iss = ISS(copy.deepcopy(cpu.mem))      # its own memory and devices: both commit their own writes
        self.iss.set_registers(cpu.registers())
        self.iss.cycle, self.iss.halted = cpu.cycle, cpu.halted
        self.start, self.checked, self.mismatches, self.first = cpu.cycle, 0, 0, None

    def compare(self, rec, cpu) -> None:
        want = None if self.iss.halted else self.iss.step()
        self.checked += 1
        got_regs, want_regs = cpu.registers(), self.iss.registers()
        if want == rec and got_regs == want_regs and cpu.halted == self.iss.halted:
            return
        self.mismatches += 1
        if self.first is None:
            self.first = {"cycle": rec.cycle, "machine": {**dataclasses.asdict(rec), "registers": got_regs},
                          "iss": {**(dataclasses.asdict(want) if want else {"halted": True}),
                                  "registers": want_regs}}

    def to_json(self) -> dict:
        return {"from_cycle": self.start, "cycles_checked": self.checked, "mismatches": self.mismatches,
                "first_mismatch": self.first}


# --------------------------------------------------------------------------- checkpoints
# A checkpoint is one JSON file; a physical run's also names its oscillator-state file and that file's
# sha256.  Each save writes the state under a new unique name, then atomically replaces the JSON, then
# deletes the old state file: a kill at any instant leaves the old pair or the new one, both usable.

CHECKPOINT_VERSION = 2
_REG_MAX = {"pc": 255, "a": 255, "b": 255, "c": 255, "d": 255, "ov": 1}


def _state(cpu, program: Program, backend: str) -> dict:
    devices = {str(a): d.state() for a, d in cpu.mem.devices.items()}
    return {"format": CHECKPOINT_FORMAT, "version": CHECKPOINT_VERSION, "backend": backend,
            "program_sha256": hashlib.sha256(program.image).hexdigest(),
            "cycle": cpu.cycle, "halted": cpu.halted, "registers": cpu.registers(),
            "memory": cpu.mem.snapshot(), "devices": devices}


def physical_state_path(checkpoint) -> Path:
    """Where a version-1 checkpoint kept its oscillator state (read on resume only)."""
    return Path(str(checkpoint) + ".state.npz")


def _state_file_pattern(path: Path) -> re.Pattern:
    return re.compile(re.escape(path.name) + r"\.state-[0-9a-f]{16}\.npz")


def checkpoint_state_file(checkpoint) -> Path | None:
    """The oscillator-state file the checkpoint at `checkpoint` names (None: none, or unreadable)."""
    try:
        name = json.loads(Path(checkpoint).read_bytes()).get("state_file")
    except (OSError, ValueError, AttributeError):
        return None
    return Path(checkpoint).with_name(name) if isinstance(name, str) else None


class _Cost:
    """Wall and CPU seconds of a run summed over its resumed parts (each part up to its last checkpoint;
    unknown after a resume from a checkpoint that did not record them)."""

    def __init__(self, resumed_from: dict | None):
        self.wall0, self.cpu0 = time.perf_counter(), time.process_time()
        prior = resumed_from or {"wall_s_total": 0.0, "cpu_s_total": 0.0}
        ok = all(isinstance(prior.get(k), (int, float)) and prior[k] >= 0 for k in ("wall_s_total", "cpu_s_total"))
        self.prior = (prior["wall_s_total"], prior["cpu_s_total"]) if ok else None

    def totals(self) -> dict:
        """{wall_s_total, cpu_s_total} so far, or {} when an earlier part's cost is unknown."""
        if self.prior is None:
            return {}
        return {"wall_s_total": self.prior[0] + time.perf_counter() - self.wall0,
                "cpu_s_total": self.prior[1] + time.process_time() - self.cpu0}


def save_checkpoint(cpu, path, program: Program, backend: str, cost: dict | None = None) -> None:
    """Write the whole machine state (with a physical run's oscillator state) so that a kill at any
    instant leaves a checkpoint that resumes: the old one or the new one.  `cost`: the run's
    wall_s_total / cpu_s_total so far, carried into a resumed run."""
    path = Path(path)
    state = {**_state(cpu, program, backend), **(cost or {})}
    try:
        if hasattr(cpu, "save"):
            name = f"{path.name}.state-{secrets.token_hex(8)}.npz"
            state["state_file"], state["state_sha256"] = name, cpu.save(path.with_name(name))
        write_checkpoint(path, state)
    except OSError as err:
        raise Mech2SpiceError(f"cannot write checkpoint {path} at cycle {cpu.cycle}: {err.strerror or err} "
                              "(the previous checkpoint, if any, is intact)") from None
    if "state_file" in state:            # the old state file, and any a killed run left behind
        keep, pattern = state["state_file"], _state_file_pattern(path)
        for old in path.parent.glob(f"{glob.escape(path.name)}.state-*.npz"):
            if old.name != keep and pattern.fullmatch(old.name):
                old.unlink(missing_ok=True)


def write_checkpoint(path, state: dict) -> None:
    """Replace the JSON checkpoint atomically (a crash mid-write leaves the previous one intact)."""
    replace_file(path, strict_json(state).encode("utf-8"), durable=True)


def is_checkpoint(path) -> bool:
    """Whether `path` holds a processor checkpoint (so a new run may replace it)."""
    try:
        state = json.loads(Path(path).read_bytes())
    except (OSError, ValueError, RecursionError):
        return False
    return isinstance(state, dict) and state.get("format") == CHECKPOINT_FORMAT


def read_checkpoint(path, program: Program, backend: str) -> dict:
    """The checkpoint at `path`, checked field by field against the program and backend."""
    if not Path(path).exists():
        raise Mech2SpiceError(f"no checkpoint at {path}: the run stopped before writing one (or the path is "
                              "wrong); start it again without --resume")
    state = read_json(path, "checkpoint")
    if not isinstance(state, dict) or state.get("format") != CHECKPOINT_FORMAT:
        raise Mech2SpiceError(f"{path} is not a processor checkpoint")
    _check_fields(state, path)
    if state["program_sha256"] != hashlib.sha256(program.image).hexdigest():
        raise Mech2SpiceError(f"checkpoint {path} belongs to a different program")
    if state["backend"] != backend:
        raise Mech2SpiceError(f"checkpoint {path} was written by the {state['backend']} backend, "
                              f"not {backend}")
    if backend in PHYSICAL + CIRCUIT and state["version"] >= 2:
        _check_state_file(state, Path(path))
    return state


def _check_state_file(state: dict, path: Path) -> None:
    """The oscillator-state file a checkpoint names exists beside it and is the one it wrote (checked
    before the model is built, which takes seconds)."""
    name, digest = state.get("state_file"), state.get("state_sha256")
    if not (isinstance(name, str) and _state_file_pattern(path).fullmatch(name) and isinstance(digest, str)):
        raise Mech2SpiceError(f"checkpoint {path} does not name a valid oscillator-state file")
    try:
        data = path.with_name(name).read_bytes()
    except OSError as err:
        raise Mech2SpiceError(f"cannot read the oscillator state {path.with_name(name)}: "
                              f"{err.strerror or err}") from None
    if hashlib.sha256(data).hexdigest() != digest:
        raise Mech2SpiceError(f"the oscillator state {path.with_name(name)} does not match its checkpoint "
                              "(changed or damaged since it was written)")


def _check_fields(state: dict, path) -> None:
    """Types and ranges of every field a resume uses (a hand-edited file must not run on wrong state)."""
    def bad(what: str):
        raise Mech2SpiceError(f"checkpoint {path}: {what}")
    if state.get("version") not in (1, CHECKPOINT_VERSION):
        bad(f"unknown version {state.get('version')!r} (this mech2spice reads 1 and {CHECKPOINT_VERSION})")
    for key, ok in (("backend", isinstance(state.get("backend"), str)),
                    ("program_sha256", isinstance(state.get("program_sha256"), str)),
                    ("cycle", is_int(state.get("cycle")) and 0 <= state["cycle"] <= MAX_CYCLES),
                    ("halted", isinstance(state.get("halted"), bool))):
        if not ok:
            bad(f"field '{key}' is missing or has the wrong type")
    regs = state.get("registers")
    if not isinstance(regs, dict) or set(regs) != set(REGISTERS):
        bad(f"'registers' must hold exactly {', '.join(REGISTERS)}")
    if regs["phase"] not in (FETCH, LOAD, LDNX) or not all(
            is_int(regs[r]) and 0 <= regs[r] <= hi for r, hi in _REG_MAX.items()):
        bad(f"register values out of range: {regs}")
    mem = state.get("memory")
    if not isinstance(mem, list) or len(mem) != MEM_SIZE or not all(is_int(v) and 0 <= v <= 255 for v in mem):
        bad(f"'memory' must be a list of {MEM_SIZE} bytes")
    devices = state.get("devices", {})
    if not isinstance(devices, dict):
        bad("'devices' must map addresses to tape states")
    for addr, dev in devices.items():
        problem = _device_problem(dev)
        if problem:
            bad(f"'devices': the tape at {addr!r}: {problem}")
    if state["halted"] and not _halts(regs, mem):
        bad(f"'halted' is true but the machine is not at a halt (a JMP_C to itself, fetched with C = pc = "
            f"{regs['pc']}): C = {regs['c']}, memory[pc] = {mem[regs['pc']]:#04x}, phase {regs['phase']}")


_CELL = re.compile(r"-?[0-9]+")      # ASCII digits only: str.isdigit() takes '٣' and int() makes it 3


def _device_problem(dev) -> str | None:
    """Why a tape state cannot be restored (None: it can): cells keyed by whole numbers, holding symbols 0..7
    (what a tape command writes), the head a whole number, the step and idle counts whole and >= 0."""
    if not isinstance(dev, dict) or not isinstance(dev.get("cells"), dict):
        return "not a tape state ({'cells': {...}, 'head': N, 'steps': N, 'idle': N})"
    for k, v in dev["cells"].items():
        if not _CELL.fullmatch(k):
            return f"cell key {k!r} is not a whole number in ASCII digits"
        if not (is_int(v) and 0 <= v <= 7):
            return f"cell {k} holds {v!r}; a tape symbol is 0..7"
    if not is_int(dev.get("head")):
        return "'head' must be a whole number"
    for key in ("steps", "idle"):
        if not (is_int(dev.get(key)) and dev[key] >= 0):
            return f"'{key}' must be a whole number >= 0"
    return None


def _halts(regs: dict, mem: list) -> bool:
    """Whether these registers and memory are the ISS's halt: a JMP_C fetched at pc with C = pc."""
    return regs["phase"] == FETCH and regs["c"] == regs["pc"] and mem[regs["pc"]] & OPCODE_MASK == OPCODES["JMP_C"]


def _restore(cpu, state: dict, path) -> None:
    if hasattr(cpu, "load"):
        if "state_file" in state:
            cpu.load(Path(path).with_name(state["state_file"]), sha256=state["state_sha256"])
        else:
            cpu.load(physical_state_path(path))
    cpu.mem.cells = [int(v) for v in state["memory"]]
    devices = state.get("devices", {})
    for addr, dev_state in devices.items():
        if not addr.isdigit() or int(addr) not in cpu.mem.devices:
            raise Mech2SpiceError(f"checkpoint has a device at {addr} that the program does not map")
        cpu.mem.devices[int(addr)].restore(dev_state)
    missing = sorted(set(cpu.mem.devices) - {int(a) for a in devices})     # its tape would restart blank
    if missing:
        raise Mech2SpiceError(f"checkpoint {path} holds no state for the device at {missing[0]} that the program "
                              "maps: it cannot resume (run again without --resume)")
    cpu.set_registers(state["registers"])
    cpu.cycle, cpu.halted = int(state["cycle"]), bool(state["halted"])


def is_trace(path) -> bool:
    """Whether `path` holds a `cpu run --trace` (its first line a cycle's record)."""
    first = first_json_line(path)
    return isinstance(first, dict) and {"cycle", "registers"} <= set(first)


CHECKPOINT_KIND, TRACE_KIND = ("a processor checkpoint", is_checkpoint), ("a cpu run trace", is_trace)
VCD_KIND = ("a VCD file", is_vcd)


def check_run_outputs(checkpoint, trace, program_source, resume: bool = False, force: bool = False,
                      params=None, vcd=None, remedy: str = "give --force to replace it") -> None:
    """--checkpoint, --trace and --vcd, before any work: neither the program, the --params file nor each
    other; a file of another kind only with `force` (`remedy` says how to give it); a resumed trace must be
    one, whole."""
    read = {"the program": program_source, "the --params file": params}
    if vcd is not None:
        check_output_file(vcd, {**read, "the --checkpoint file": checkpoint, "the --trace file": trace}, "VCD file",
                          kind=VCD_KIND, force=force)
    if checkpoint is not None:            # resuming, read_checkpoint says what else the file is
        check_output_file(checkpoint, {**read, "the --trace file": trace}, "checkpoint",
                          kind=None if resume else CHECKPOINT_KIND, force=force, regular=True, remedy=remedy)
    if trace is not None:
        check_output_file(trace, {**read, "the --checkpoint file": checkpoint}, "trace",
                          kind=None if resume else TRACE_KIND, force=force, regular=resume)
        if resume:
            trace_lines(trace)


# --------------------------------------------------------------------------- the runner

class _NoBar:
    def update(self, n: int) -> None:
        """Do nothing (the progress bar is off)."""

    def close(self) -> None:
        """Do nothing (the progress bar is off)."""


def _cycle_bar(enabled: bool, done: int, total: int | None, backend: str):
    """A progress bar over cycles: to the program's own end when `total` is known (program_length), else the
    cycles and the time so far (the --max-cycles cap is no end: a percentage of it said nothing)."""
    if callable(enabled):                      # a redirected stderr: a line now and then (backends._base)
        from ..backends import progress_bar
        return progress_bar(total, enabled, "cycle", initial=done)
    if not enabled:
        return _NoBar()
    from tqdm import tqdm
    return tqdm(total=total, initial=done, unit="cycle", desc=backend + ("" if total is None else " (to the halt)"),
                leave=False, file=sys.stderr, dynamic_ncols=True)


ISS_LOOKAHEAD_S = 2.0      # what the ISS may spend finding a program's length before a long run


def program_length(cpu, max_cycles: int) -> int | None:
    """The cycle the run will stop at, from the ISS run ahead from `cpu`'s state: its halt, or max_cycles if it
    runs that far; None when the ISS has not found either within ISS_LOOKAHEAD_S (the bar then shows no end)."""
    iss = ISS(copy.deepcopy(cpu.mem))
    iss.set_registers(cpu.registers())
    iss.cycle, iss.halted = cpu.cycle, cpu.halted
    start, deadline = iss.cycle, time.perf_counter() + ISS_LOOKAHEAD_S
    while not iss.halted and iss.cycle < max_cycles:
        if (iss.cycle - start) % 4096 == 0 and time.perf_counter() > deadline:
            return None
        iss.step()
    return iss.cycle


def trace_lines(path) -> list[str]:
    """The lines of a `cpu run --trace` file (none if there is none), each checked to be a cycle's record."""
    try:
        lines = Path(path).read_text(encoding="utf-8").splitlines(keepends=True)
        for line in lines:
            if not is_int(json.loads(line)["cycle"]):
                raise TypeError("a cycle that is not a whole number")
    except FileNotFoundError:
        return []
    except (OSError, ValueError, KeyError, TypeError, RecursionError) as err:
        raise Mech2SpiceError(f"trace {path} is not a cpu run trace (one JSON object per line): {err}") from None
    return [line if line.endswith("\n") else line + "\n" for line in lines]


class TraceFile:
    """`cpu run --trace FILE`: one JSON line per cycle (what the ISS records, the registers after it, the time
    it ended and, on the oscillator-level backends, every probed amplitude in u_R), flushed as it goes.  A resumed run first
    drops the lines past its checkpoint's cycle (rewritten atomically), so the file always continues it."""

    def __init__(self, path, resume_cycle: int | None):
        self.path = Path(path)
        if resume_cycle is None:
            self.file = open(self.path, "w", encoding="utf-8")
            return
        kept = [line for line in trace_lines(self.path) if json.loads(line)["cycle"] < resume_cycle]
        replace_file(self.path, "".join(kept).encode("utf-8"))
        self.file = open(self.path, "a", encoding="utf-8")

    def __call__(self, rec, cpu) -> None:
        row = {**dataclasses.asdict(rec), "registers": cpu.registers(), "unix_time": round(time.time(), 3)}
        amps = getattr(cpu, "amps", None)
        if isinstance(amps, dict):
            row.update(period=cpu.period, simulated_periods=cpu.simulated,
                       amps={k: round(float(v), 6) for k, v in amps.items()})
            if hasattr(cpu, "block_steps"):        # the oscillator-level engines (not the circuit)
                row["block_steps"] = cpu.block_steps
        self.file.write(strict_json(row) + "\n")
        self.file.flush()

    def close(self) -> None:
        self.file.close()


PHASES = {FETCH: 0, LOAD: 1, LDNX: 2}      # the phase as a 2-bit wire in a VCD
REGISTER_WIDTHS = {"pc": 8, "a": 8, "b": 8, "c": 8, "d": 8, "ov": 1}
BUS_WIDTHS = {"pc": 8, "raddr": 8, "rdata": 8, "we": 1, "waddr": 8, "wdata": 8}


class VcdTrace:
    """`cpu run --vcd FILE`: the trace as a waveform, one timestep per clock cycle (time = the cycle's number):
    scope `cycle` what the cycle did (its pc and phase at the start, the memory read and write, the opcode of a
    fetch), scope `registers` the registers after it, scope `amplitudes` (envelope, carrier, rk4,
    vacask-envelope) every probed amplitude in u_R after it, as reals named as in --trace's `amps`.  Kept
    in memory and written at the end (a resumed run writes the cycles of this process)."""

    COMMENT = ("mech2spice cpu run: one time unit per clock cycle; cycle.* is what cycle t did, registers.* and "
               "amplitudes.* (u_R) are read after it; phase 0 fetch, 1 load, 2 ldnx")

    def __init__(self, path):
        self.path = path
        self.rows: list[tuple] = []

    def __call__(self, rec, cpu) -> None:
        amps = getattr(cpu, "amps", None)
        self.rows.append((rec, cpu.registers(), dict(amps) if isinstance(amps, dict) else {}))

    def waveform(self) -> Waveform:
        wave = Waveform([rec.cycle for rec, _, _ in self.rows], comment=self.COMMENT)
        for name, width in BUS_WIDTHS.items():
            wave.add_wire(["cpu", "cycle"], name, width, [getattr(rec, name) for rec, _, _ in self.rows])
        wave.add_wire(["cpu", "cycle"], "phase", 2, [PHASES[rec.phase] for rec, _, _ in self.rows])
        wave.add_wire(["cpu", "cycle"], "opcode", 4, [OPCODES.get(rec.instr) for rec, _, _ in self.rows])
        for name, width in REGISTER_WIDTHS.items():
            wave.add_wire(["cpu", "registers"], name, width, [regs[name] for _, regs, _ in self.rows])
        wave.add_wire(["cpu", "registers"], "phase", 2, [PHASES[regs["phase"]] for _, regs, _ in self.rows])
        probes = list(self.rows[0][2]) if self.rows else []
        for probe in probes:                    # "latch.Q3" -> scope amplitudes.latch, real Q3
            *scope, name = probe.split(".")
            wave.add_real(["cpu", "amplitudes", *scope], name, [amps[probe] for _, _, amps in self.rows])
        return wave

    def close(self) -> None:
        write_vcd(self.path, self.waveform())


def _both(first, second):
    """One per-cycle callback calling two (either may be None)."""
    if first is None or second is None:
        return first or second
    return lambda rec, cpu: (first(rec, cpu), second(rec, cpu))


def _judge_cycle(cpu) -> dict:
    """The stability verdict of the machine as it stands after a cycle, with its cost."""
    t = time.perf_counter()
    v = cpu.stability()
    return {"cycle": cpu.cycle, **v.to_json(), "wall_s": time.perf_counter() - t}


def run_program(source, backend: str = "iss", max_cycles: int = 100_000, checkpoint=None,
                resume: bool = False, progress: bool = False, checkpoint_every: int | None = None,
                trace=None, force: bool = False, stability: bool | str = False, vcd=None, **physical) -> dict:
    """Run until halted or ``max_cycles`` (total) and return the result dict.  Checkpoints are written
    every ``checkpoint_every`` cycles (default 1000, or 10 for the oscillator-level and circuit backends).  ``trace``:
    a callable(record, cpu) called after each cycle, or a path for a TraceFile.  Neither file may be the
    program; one of another kind is replaced only with ``force``.  ``stability``: "end" (or True) judges the
    oscillator-level machine at its halt, "cycle" after every cycle as well, stopping at the first unstable
    one (docs/stability.md; ~4 s a cycle on the processor, the sieve ~85x its run).  ``vcd``: a path for the
    run's waveform (VcdTrace), written when the run ends."""
    stability = {True: "end", False: "off", None: "off"}.get(stability, stability)
    if stability not in ("off", "end", "cycle"):
        raise Mech2SpiceError(f"stability {stability!r}: choose off, end or cycle")
    checkpoint_every = checkpoint_every or (10 if backend in PHYSICAL + CIRCUIT else 1000)
    if max_cycles < 0 or checkpoint_every < 1:
        raise Mech2SpiceError("max_cycles must be >= 0 and checkpoint_every >= 1")
    if resume and checkpoint is None:
        raise Mech2SpiceError("resume needs a checkpoint file")
    check_run_outputs(checkpoint, None if callable(trace) else trace, source, resume, force, vcd=vcd)
    program = load_program(source)
    state = read_checkpoint(checkpoint, program, backend) if resume else None
    t0 = time.perf_counter()                       # wall_s includes building the model and power-up
    cost = _Cost(state)
    if progress is True and backend in PHYSICAL:           # a terminal (a log gets the cycle lines only)
        print(f"[{backend}] building the processor's oscillator model ...", file=sys.stderr, flush=True)
    if backend in CIRCUIT and checkpoint is not None:    # one simulator process per checkpoint interval
        physical.setdefault("segment", checkpoint_every)
    cpu = make_cpu(backend, make_memory(program), power_up=not resume, **physical)
    if resume:
        _restore(cpu, state, checkpoint)
    if trace is not None and not callable(trace):
        trace = TraceFile(trace, cpu.cycle if resume else None)
    waves = VcdTrace(vcd) if vcd is not None else None
    record = _both(trace, waves)
    shown = progress if backend != "iss" else False
    bar = _cycle_bar(shown, cpu.cycle, program_length(cpu, max_cycles) if shown else None, backend)
    shadow = IssCheck(cpu) if backend != "iss" else None
    judged = [] if stability == "cycle" and backend in PHYSICAL else None
    while not cpu.halted and cpu.cycle < max_cycles:
        rec = cpu.step()
        if shadow is not None:
            shadow.compare(rec, cpu)
        if judged is not None:
            judged.append(_judge_cycle(cpu))
        bar.update(1)
        if record is not None:
            record(rec, cpu)
        if checkpoint is not None and cpu.cycle % checkpoint_every == 0:
            save_checkpoint(cpu, checkpoint, program, backend, cost.totals())
        if judged and not judged[-1]["stable"]:       # the machine is not at a stable state: stop here
            break
    bar.close()
    if isinstance(trace, TraceFile):
        trace.close()
    if waves is not None:
        waves.close()
    if checkpoint is not None:
        save_checkpoint(cpu, checkpoint, program, backend, cost.totals())
    result = {"backend": backend, "cycles": cpu.cycle, "halted": cpu.halted,
              "memory": cpu.mem.snapshot(), "registers": cpu.registers(),
              "wall_s": time.perf_counter() - t0, **cost.totals()}
    if program.results:
        result["results"] = program.read_results(result["memory"])
    if shadow is not None:
        result["iss_check"] = shadow.to_json()
    if hasattr(cpu, "model"):
        result["model"] = cpu.model.counts()
    if backend in PHYSICAL:
        result.update(periods=cpu.period, simulated_periods=cpu.simulated, step=cpu.step_periods,
                      settle=cpu.settle, latency=cpu.latency, latency_calm=cpu.latency_calm,
                      latency_wake=cpu.latency_wake, block_steps=cpu.block_steps)
        if cpu.settle_check is not None:      # the reads of this process (a resumed run: since the resume)
            result["settle_check"] = cpu.settle_check.to_json()
            result["settled"] = result["settle_check"]["settled"]
        if judged is not None:
            result["stability_cycles"] = judged
        if stability != "off":         # the verdict where the run ended (per cycle: the last one judged)
            last = judged[-1] if judged else _judge_cycle(cpu)
            result.update(stable=last["stable"], stability=last)
    if hasattr(cpu, "extra"):                      # the circuit backend: simulator cost, the circuit's memory
        result.update(cpu.extra())
    for addr, dev in cpu.mem.devices.items():
        result.setdefault("devices", {})[str(addr)] = dev.state()
    return result
