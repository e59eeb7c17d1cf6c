"""The processor at oscillator level against the ISS, cycle by cycle: reports/cpu_physical.md.

Run: mech2spice report cpu_physical [--cycles N] [--program programs/sieve.asm] [--backend envelope]
                                    [--step 4] [--settle TOL] [--checkpoint FILE [--resume]] [--name STEM]
--cycles 0 runs to the halt.  Each cycle's port activity (read address, data, write port) and the
registers decoded from the latch amplitudes are compared with the ISS; the run stops at the first
disagreement.  The run goes through `run_program` (checkpoints every 10 cycles with --checkpoint, so an
interrupted run continues with --resume); the figures come from the physical run's own trace.
The fidelity table comes from `mech2spice report fidelity` (fidelity.json beside the report) when present.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

from .. import data
from ..cpu import run as R
from ..cpu.iss import ISS
from ..cpu import physical as P
from ..cpu.physical import PROCESSOR_STEP as ENVELOPE_STEP, SETTLE_TOL as SETTLE
from ..errors import Mech2SpiceError
from ..studies._common import load_average
from ._common import HOST, out_dir, pyplot, read_json, save_figure, write_json
from .cpu import fig_sieve, plot_traffic, sieve_moments

plt = pyplot()

PAPER_CYCLES, PAPER_WALL = 719, "50 h 22 min"


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


def fig_activity(rows, path: Path, backend: str) -> None:
    """The physical run's memory traffic per cycle, with the wall time per cycle."""
    fig, ax = plt.subplots(figsize=(10, 3.4))
    plot_traffic(ax, ((r["cycle"], r["raddr"], r["we"], r["waddr"]) for r in rows),
                 "read address (decoded from amplitudes)")
    ax2 = ax.twinx()
    ax2.plot([r["cycle"] for r in rows], [r["wall_s"] for r in rows], lw=0.6, color="0.4")
    ax2.set_ylabel("wall time per cycle (s)", color="0.4")
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title(f"{backend} fidelity: memory traffic per cycle (grey: the sieve's primality array)", fontsize=10)
    save_figure(fig, path, dpi=130)


def devices_md(res: dict) -> str:
    """The memory-mapped tape of a Turing-machine program, as the physical run left it."""
    lines = []
    for addr, d in res.get("devices", {}).items():
        cells = "".join(str(d["cells"][k]) for k in sorted(d["cells"], key=int))
        lines.append(f"- tape at address {addr} after the run: cells {cells} (from the leftmost written), head "
                     f"{d['head']}, {d['steps']} head moves, identical to the ISS's tape after every cycle.")
    return "\n".join(lines) + ("\n" if lines else "")


def fidelity_section(path: Path) -> str:
    """The processor table of `mech2spice report fidelity` (fidelity.json), when it has been run."""
    d = read_json(path, {})
    if "cpu" not in d:
        return ""
    lines = ["\n## What each speed-up costs (`mech2spice report fidelity`, [fidelity.md](fidelity.md))\n",
             f"The first {d['cycles']} sieve cycles under each setting, side by side in one run on the "
             f"{d['machine']}. *Amplitude difference*: the largest difference of any probed amplitude (the "
             "output bits and all 43 latch outputs) at the end of each cycle against the reference setting; "
             "*margin*: the smallest distance of any of them to its band edge, in band widths; "
             "*integrated*: the drive periods actually integrated (a settled pause skips the rest).\n",
             "| setting | cycles = ISS | max amplitude difference (u_R) | min margin | integrated / "
             "simulated periods | s per cycle |", "|---|---|---|---|---|---|"]
    for r in d["cpu"]:
        lines.append(f"| {r['setting']} | {r['cycles'] if r['all_same_as_iss'] else 'NO'} | "
                     f"{r['max_amp_diff']:.4f} | {r['min_margin']:+.3f} | {r['simulated']:,} / {r['periods']:,} "
                     f"| {r['s_per_cycle']:.2f} |")
    return "\n".join(lines) + "\n"


def write(directory="reports", cycles: int = 0, program: str = "programs/sieve.asm", backend: str = "envelope",
          step: float = ENVELOPE_STEP, settle: float = SETTLE, checkpoint=None, resume: bool = False,
          name: str = "cpu_physical") -> Path:
    """Run `program` on the oscillators (`cycles` 0: to its halt), compare every cycle with the ISS and write
    NAME.md, NAME.json and the figures."""
    a = Options(cycles, program, backend, step, settle, checkpoint, resume, name)
    out = out_dir(directory)
    tracker = Tracker(R.load_program(a.path))
    if a.resume:
        tracker.fast_forward(read_json(a.checkpoint)["cycle"])
    t0, c0 = time.perf_counter(), time.process_time()
    res = _run(a, tracker, out)
    wall, cpu_s = time.perf_counter() - t0, time.process_time() - c0
    load = "load average %.2f, %.2f, %.2f" % tuple(load_average())
    golden = R.run_program(a.path, "iss")
    final_same = res["memory"] == golden["memory"] and res["cycles"] == golden["cycles"]
    moments = sieve_moments(tracker.frames) if res["halted"] and a.sieve else []
    if moments:
        fig_sieve(tracker.frames, moments, out / "cpu_sieve_physical.png",
                  f"the processor's oscillators at {a.backend} fidelity ({res.get('simulated_periods', 0):,} periods integrated)")
    fig_activity(tracker.rows, out / f"{a.name}_trace.png", a.backend)
    rows = tracker.rows
    per_cycle = sum(r["wall_s"] for r in rows) / max(len(rows), 1)
    primes = [n for n in range(2, 32) if res["memory"][128 + n] == 0] if a.sieve else None
    cmd = _command(a)
    (out / f"{a.name}.md").write_text(_markdown(a, res, tracker, cmd, wall, per_cycle, primes, final_same,
                                                moments, out, cpu_s, load))
    summary = {**res, "agree_every_cycle": tracker.agree, "final_memory_equals_iss": final_same,
               "wall_s": wall, "cpu_s": cpu_s, "load": load, "s_per_cycle": per_cycle, "primes": primes, "command": cmd,
               "resumed": a.resume, "machine": f"{HOST}, 2 cores (shared)"}
    write_json(out / f"{a.name}.json", summary, default=None)
    print(out / f"{a.name}.md", f"{wall:.0f} s")
    return out / f"{a.name}.md"


@dataclass
class Options:
    """One physical run's settings, as given (the program as named, for the report's text)."""
    cycles: int
    program: str
    backend: str
    step: float
    settle: float
    checkpoint: str | None
    resume: bool
    name: str

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


def _run(a: Options, tracker: Tracker, out: Path) -> dict:
    """The physical run; on a failure the rows measured up to it go to NAME_failed.md."""
    physical = {"step": a.step, "settle": a.settle or None} if a.backend == "envelope" else {}
    try:
        return R.run_program(a.path, a.backend, a.cycles or 100_000, checkpoint=a.checkpoint,
                             resume=a.resume, trace=tracker, **physical)
    except Mech2SpiceError as err:       # keep what was measured: the rows up to the failure
        (out / f"{a.name}_failed.md").write_text(f"# Physical run stopped\n\n{err}\n\n" + "\n".join(
            json.dumps(r) for r in tracker.rows) + "\n")
        raise Mech2SpiceError(f"{err} (rows in {out / (a.name + '_failed.md')})") from None


def _command(a: Options) -> str:
    """The command that reproduces this run."""
    return (f"mech2spice report cpu_physical --cycles {a.cycles} --backend {a.backend}"
            + ("" if a.sieve else f" --program {a.program} --name {a.name}")
            + (f" --step {a.step:g} --settle {a.settle}" if a.backend == "envelope" else ""))


def _speedups_txt(a: Options) -> str:
    """The processor's default envelope speed-ups (cpu/physical.py, docs/latency.md), as used by this run."""
    if a.backend != "envelope":
        return ""
    parts = ([f"per-gate latency {P.LATENCY} u_R"] if P.LATENCY else []) + \
        (["the insulators stepped exactly (exponential step)"] if P.EXPONENTIAL else [])
    return "; " + ", ".join(parts) + " (docs/latency.md)" if parts else ""


def _markdown(a: Options, res, tracker, cmd, wall, per_cycle, primes, final_same, moments, out, cpu_s=None,
              load="") -> str:
    sieve, rows = a.sieve, tracker.rows
    paper_wall = f" (the paper's sieve run: {PAPER_WALL})" if sieve else ""
    settle_txt = (f"each pause ends once every channel has stayed within {a.settle} u_R for two 200-period "
                  "windows (`envelope.integrate(settle_tol=...)`; pulses always run in full)" if a.settle else
                  "fixed-length pauses")
    return f"""# The processor at oscillator level ({a.backend})

Generated by `{cmd}` on {HOST}, 2 cores (shared with other jobs),
program `{a.program}`{' (resumed from a checkpoint: wall time is this session only)' if a.resume else ''}.

`verilog/cpu.v` synthesised with the fan-out limit: 6486 oscillators. Simulated at {a.backend} fidelity
(step {a.step:g} periods, compiled envelope kernel, {settle_txt}{_speedups_txt(a)}). The behavioural memory decodes the read
address from the raddr channels' amplitudes each cycle, drives rdata with the stored byte as forces and
commits writes at the clock edge (`mech2spice/cpu/physical.py`). Every cycle is compared with the ISS
(port activity, all registers decoded from the latch amplitudes, and memory).

## Result

- **{'halted' if res['halted'] else 'did not halt'} after {res['cycles']} cycles**{f" (the paper's sieve: {PAPER_CYCLES} cycles)" if sieve else ""}; {'every cycle identical to the ISS' if tracker.agree else 'DISAGREED with the ISS'};
  final memory {'equal to' if final_same else 'DIFFERENT from'} the golden (ISS) memory.
{f"- primes left unmarked in 128..159: {primes}" if sieve else ""}
- **wall time {wall:.0f} s ({wall / 60:.1f} min)**, {per_cycle:.2f} s per cycle on average{paper_wall}
  (CPU time of the process {cpu_s or 0:.1f} s, ISS comparison included; {load} at the end: the machine was shared);
  {res.get('periods', 0):,} drive periods of processor time, of which
  {res.get('simulated_periods', 0):,} were integrated.

{'![sieve memory, physical run](cpu_sieve_physical.png)' if moments else ''}
{devices_md(res)}
![memory traffic, physical run]({a.name}_trace.png)
{fidelity_section(out / 'fidelity.json')}
## Every cycle

<details><summary>{len(rows)} cycles (click)</summary>

| cycle | pc | instruction | raddr | rdata | we | waddr | wdata | = ISS | wall (s) |
|---|---|---|---|---|---|---|---|---|---|
""" + "\n".join(f"| {r['cycle']} | {r['pc']} | {r['instr']} | {r['raddr']} | {r['rdata']} | {r['we']} | "
                f"{r['waddr']} | {r['wdata']} | {'yes' if r['same'] else 'NO'} | {r['wall_s']:.1f} |"
                for r in rows) + "\n\n</details>\n"
