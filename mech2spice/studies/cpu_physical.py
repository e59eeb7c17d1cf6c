"""The processor at oscillator level against the ISS, cycle by cycle, measured into NAME.json (default
cpu_physical.json; mech2spice/reports/cpu_physical.py renders NAME.md and the figures from it).

One run per call: `program` on the oscillators (`cycles` 0: to its halt) through `run_program` (checkpoints
every 10 cycles with `checkpoint`, so an interrupted run continues with `resume`).  Each cycle's port activity
(read address, data, write port) and the registers decoded from the latch amplitudes are compared with the
ISS; the run stops at the first disagreement, and the rows measured up to it go to NAME_failed.md.
"""
from __future__ import annotations

import platform
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from .. import data
from ..cpu import physical as P
from ..cpu import run as R
from ..cpu.iss import ISS
from ..cpu.physical import PROCESSOR_STEP as ENVELOPE_STEP, SETTLE_TOL as SETTLE
from ..errors import Mech2SpiceError
from ..inputs import strict_json
from ._common import conditions, load_average, read_json
from .cpu import moment_frames

SECTIONS = ("all",)
HOST = f"{platform.machine()} {platform.system()}"


class Tracker:
    """Steps the ISS beside the physical run (trace callback) and keeps Fig. 8's frames."""

    def __init__(self, prog):
        self.iss = ISS(R.make_memory(prog))
        self.frames, self.rows, self.agree = [], [], True
        self.t = time.perf_counter()

    def fast_forward(self, cycles: int) -> None:
        """A resumed run: replay the ISS to the checkpoint (frames before it are ISS frames)."""
        while self.iss.cycle < cycles:
            before = self.iss.mem.snapshot()
            rec = self.iss.step()
            self.frames.append((rec, before, self.iss.mem.snapshot()))

    def __call__(self, got, cpu) -> None:
        before = self.iss.mem.snapshot()
        want = self.iss.step()
        same = want == got and self.iss.registers() == cpu.registers() and \
            cpu.mem.snapshot() == self.iss.mem.snapshot() and \
            {a: d.state() for a, d in cpu.mem.devices.items()} == {a: d.state() for a, d in self.iss.mem.devices.items()}
        self.frames.append((got, before, cpu.mem.snapshot()))
        now = time.perf_counter()
        self.rows.append({"cycle": got.cycle, "pc": got.pc, "instr": got.instr or got.phase, "raddr": got.raddr,
                          "rdata": got.rdata, "we": got.we, "waddr": got.waddr, "wdata": got.wdata,
                          "same": same, "wall_s": now - self.t})
        self.t = now
        if not same:
            self.agree = False
            raise Mech2SpiceError(f"cycle {got.cycle}: the physical run differs from the ISS "
                                  f"({got} vs {want})")
        if got.cycle % 25 == 0:
            print(f"cycle {got.cycle}: pc {got.pc} {got.instr or got.phase}", flush=True)


@dataclass
class Options:
    """One physical run's settings, as given (the program as named, for the report's text)."""
    cycles: int = 0
    program: str = "programs/sieve.asm"
    backend: str = "envelope"
    step: float = ENVELOPE_STEP
    settle: float = SETTLE
    checkpoint: str | None = None
    resume: bool = False
    name: str = "cpu_physical"

    def __post_init__(self):
        if self.backend not in ("envelope", "rk4"):
            raise Mech2SpiceError(f"cpu_physical: backend must be envelope or rk4, not {self.backend!r}")

    @property
    def path(self) -> Path:
        """The program file: as given, else the package's copy of a program of that name."""
        p = Path(self.program)
        return p if p.exists() else data.program(p.name)

    @property
    def sieve(self) -> bool:
        """Whether the program is the sieve (sieve.asm): the report then adds Fig. 8 and the primes."""
        return Path(self.program).name == "sieve.asm"


def measure(out: Path, a: Options) -> dict:
    """Run `a.program` on the oscillators, compare every cycle with the ISS; the JSON the report renders."""
    R.check_run_outputs(a.checkpoint, None, a.path, resume=a.resume,      # before any row is measured or written
                        remedy="give another --checkpoint")
    tracker = Tracker(R.load_program(a.path))
    if a.resume:
        tracker.fast_forward(read_json(a.checkpoint)["cycle"])
    t0, c0 = time.perf_counter(), time.process_time()
    res = _run(a, tracker, out)
    wall, cpu_s = time.perf_counter() - t0, time.process_time() - c0
    load = "load average %.2f, %.2f, %.2f" % tuple(load_average())
    golden = R.run_program(a.path, "iss")
    final_same = res["memory"] == golden["memory"] and res["cycles"] == golden["cycles"]
    rows = tracker.rows
    per_cycle = sum(r["wall_s"] for r in rows) / max(len(rows), 1)
    return {**res, "agree_every_cycle": tracker.agree, "final_memory_equals_iss": final_same,
            "wall_s": wall, "cpu_s": cpu_s, "load": load, "s_per_cycle": per_cycle,
            "primes": [n for n in range(2, 32) if res["memory"][128 + n] == 0] if a.sieve else None,
            "command": command(a), "resumed": a.resume, "machine": f"{HOST}, 2 cores (shared)",
            "host": HOST, "options": asdict(a), "sieve": a.sieve, "speedups": speedups(a), "rows": rows,
            "moments": moment_frames(tracker.frames) if res["halted"] and a.sieve else [],
            "conditions": conditions()}


def _run(a: Options, tracker: Tracker, out: Path) -> dict:
    """The physical run; on a failure the rows measured up to it go to NAME_failed.md."""
    physical = {"step": a.step, "settle": a.settle or None} if a.backend == "envelope" else {}
    try:
        return R.run_program(a.path, a.backend, a.cycles or 100_000, checkpoint=a.checkpoint,
                             resume=a.resume, trace=tracker, **physical)
    except Mech2SpiceError as err:       # keep what was measured: the rows up to the failure
        (out / f"{a.name}_failed.md").write_text(f"# Physical run stopped\n\n{err}\n\n" + "\n".join(
            strict_json(r) for r in tracker.rows) + "\n")
        raise Mech2SpiceError(f"{err} (rows in {out / (a.name + '_failed.md')})") from None


def command(a: Options) -> str:
    """The command that reproduces this run."""
    return (f"mech2spice report cpu_physical --cycles {a.cycles} --backend {a.backend}"
            + ("" if a.sieve else f" --program {a.program} --name {a.name}")
            + (f" --step {a.step:g} --settle {a.settle}" if a.backend == "envelope" else ""))


def speedups(a: Options) -> dict:
    """The processor's default envelope speed-ups this run used (cpu/physical.py, docs/latency.md)."""
    return {"latency": P.LATENCY, "exponential": P.EXPONENTIAL} if a.backend == "envelope" else {}
