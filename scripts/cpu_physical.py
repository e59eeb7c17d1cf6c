"""The processor at oscillator level against the ISS, cycle by cycle: reports/cpu_physical.md.

Usage: python scripts/cpu_physical.py [--cycles N] [--program programs/sieve.asm] [--backend envelope]
                                      [--step 4] [--settle TOL] [--checkpoint FILE [--resume]]
--cycles 0 runs to the halt.  Each cycle's port activity (read address, data, write port) and the
registers decoded from the latch amplitudes are compared with the ISS; the run stops at the first
disagreement.  The run goes through `run_program` (checkpoints every 10 cycles with --checkpoint, so an
interrupted run continues with --resume); the figures come from the physical run's own trace.
The fidelity table comes from benchmarks/fidelity.py (reports/fidelity.json) when present.
"""
import argparse
import json
import platform
import time
from pathlib import Path

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from mech2spice.cpu import figures  # noqa: E402
from mech2spice.cpu import run as R  # noqa: E402
from mech2spice.cpu.iss import ISS  # noqa: E402
from mech2spice.cpu.physical import ENVELOPE_STEP, SETTLE  # noqa: E402
from mech2spice.errors import Mech2SpiceError  # noqa: E402

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
    fig, ax = plt.subplots(figsize=(10, 3.4))
    ax.plot([r["cycle"] for r in rows], [r["raddr"] for r in rows], ".", ms=2.5, color="tab:green",
            label="read address (decoded from amplitudes)")
    w = [r for r in rows if r["we"]]
    ax.plot([r["cycle"] for r in w], [r["waddr"] for r in w], "s", ms=3.5, color="tab:red", label="write address")
    ax2 = ax.twinx()
    ax2.plot([r["cycle"] for r in rows], [r["wall_s"] for r in rows], lw=0.6, color="0.4")
    ax2.set_ylabel("wall time per cycle (s)", color="0.4")
    ax.axhspan(128, 159, color="0.9", zorder=0)
    ax.set_xlabel("clock cycle")
    ax.set_ylabel("address")
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title(f"{backend} fidelity: memory traffic per cycle (grey: the sieve's primality array)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def devices_md(res: dict) -> str:
    """The memory-mapped tape of a Turing-machine program, as the physical run left it."""
    lines = []
    for addr, d in res.get("devices", {}).items():
        cells = "".join(str(d["cells"][k]) for k in sorted(d["cells"], key=int))
        lines.append(f"- tape at address {addr} after the run: cells {cells} (from the leftmost written), head "
                     f"{d['head']}, {d['steps']} head moves, identical to the ISS's tape after every cycle.")
    return "\n".join(lines) + ("\n" if lines else "")


def fidelity_section(path: Path) -> str:
    """The processor table of benchmarks/fidelity.py (reports/fidelity.json), when it has been run."""
    if not path.exists() or "cpu" not in json.loads(path.read_text()):
        return ""
    d = json.loads(path.read_text())
    lines = [f"\n## What each speed-up costs (`python benchmarks/fidelity.py`, [fidelity.md](fidelity.md))\n",
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cycles", type=int, default=0, help="cycles to run (0: to the halt)")
    ap.add_argument("--program", default="programs/sieve.asm")
    ap.add_argument("--backend", default="envelope", choices=["envelope", "rk4"])
    ap.add_argument("--step", type=float, default=ENVELOPE_STEP)
    ap.add_argument("--settle", type=float, default=SETTLE)
    ap.add_argument("--checkpoint", default=None)
    ap.add_argument("--resume", action="store_true")
    ap.add_argument("--out", default="reports")
    ap.add_argument("--name", default="cpu_physical", help="report file stem (default cpu_physical)")
    a = ap.parse_args()
    out = Path(a.out)
    sieve = Path(a.program).name == "sieve.asm"
    prog = R.load_program(a.program)
    tracker = Tracker(prog)
    if a.resume:
        tracker.fast_forward(json.loads(Path(a.checkpoint).read_text())["cycle"])
    physical = {"step": a.step, "settle": a.settle or None} if a.backend == "envelope" else {}
    t0 = time.perf_counter()
    try:
        res = R.run_program(a.program, a.backend, a.cycles or 100_000, checkpoint=a.checkpoint,
                            resume=a.resume, trace=tracker, **physical)
    except Mech2SpiceError as err:       # keep what was measured: the rows up to the failure
        (out / f"{a.name}_failed.md").write_text(f"# Physical run stopped\n\n{err}\n\n" + "\n".join(
            json.dumps(r) for r in tracker.rows) + "\n")
        raise SystemExit(f"{err} (rows in {out / (a.name + '_failed.md')})")
    wall = time.perf_counter() - t0
    golden = R.run_program(a.program, "iss")
    final_same = res["memory"] == golden["memory"] and res["cycles"] == golden["cycles"]
    moments = figures.sieve_moments(tracker.frames) if res["halted"] and sieve else []
    if moments:
        figures.fig_sieve(tracker.frames, moments, out / "cpu_sieve_physical.png",
                          f"the processor's oscillators at {a.backend} fidelity ({res.get('simulated_periods', 0):,} periods integrated)")
    fig_activity(tracker.rows, out / f"{a.name}_trace.png", a.backend)
    rows = tracker.rows
    per_cycle = sum(r["wall_s"] for r in rows) / max(len(rows), 1)
    primes = [n for n in range(2, 32) if res["memory"][128 + n] == 0] if sieve else None
    cmd = (f"python scripts/cpu_physical.py --cycles {a.cycles} --backend {a.backend}"
           + ("" if sieve else f" --program {a.program} --name {a.name}")
           + (f" --step {a.step:g} --settle {a.settle}" if a.backend == "envelope" else ""))
    paper_wall = f" (the paper's sieve run: {PAPER_WALL})" if sieve else ""
    settle_txt = (f"each pause ends once every channel has stayed within {a.settle} u_R for two 200-period "
                  "windows (`envelope.integrate(settle=...)`; pulses always run in full)" if a.settle else
                  "fixed-length pauses")
    text = f"""# The processor at oscillator level ({a.backend})

Generated by `{cmd}` on {platform.machine()} {platform.system()}, 2 cores (shared with other jobs),
program `{a.program}`{' (resumed from a checkpoint: wall time is this session only)' if a.resume else ''}.

`verilog/cpu.v` synthesised with the fan-out limit: 6486 oscillators. Simulated at {a.backend} fidelity
(step {a.step:g} periods, compiled envelope kernel, {settle_txt}). The behavioural memory decodes the read
address from the raddr channels' amplitudes each cycle, drives rdata with the stored byte as forces and
commits writes at the clock edge (`mech2spice/cpu/physical.py`). Every cycle is compared with the ISS
(port activity, all registers decoded from the latch amplitudes, and memory).

## Result

- **{'halted' if res['halted'] else 'did not halt'} after {res['cycles']} cycles**{f" (the paper's sieve: {PAPER_CYCLES} cycles)" if sieve else ""}; {'every cycle identical to the ISS' if tracker.agree else 'DISAGREED with the ISS'};
  final memory {'equal to' if final_same else 'DIFFERENT from'} the golden (ISS) memory.
{f"- primes left unmarked in 128..159: {primes}" if sieve else ""}
- **wall time {wall:.0f} s ({wall / 60:.1f} min)**, {per_cycle:.2f} s per cycle on average{paper_wall};
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
    (out / f"{a.name}.md").write_text(text)
    summary = {**res, "agree_every_cycle": tracker.agree, "final_memory_equals_iss": final_same,
               "wall_s": wall, "s_per_cycle": per_cycle, "primes": primes, "command": cmd,
               "resumed": a.resume, "machine": f"{platform.machine()} {platform.system()}, 2 cores (shared)"}
    (out / f"{a.name}.json").write_text(json.dumps(summary, indent=1))
    print(out / f"{a.name}.md", f"{wall:.0f} s")


if __name__ == "__main__":
    main()
