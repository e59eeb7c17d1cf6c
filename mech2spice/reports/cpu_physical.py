"""The processor at oscillator level against the ISS, cycle by cycle: reports/cpu_physical.md, rendered from
cpu_physical.json (mech2spice/studies/cpu_physical.py measures it).

Run: mech2spice report cpu_physical [--cycles N] [--program programs/sieve.asm] [--backend envelope]
                                    [--step 4] [--settle TOL] [--checkpoint FILE [--resume]] [--name STEM]
                                    [--render]
--cycles 0 runs to the halt; --render measures nothing and rewrites NAME.md and the figures from NAME.json.
The figures come from the physical run's own trace.  The fidelity table comes from `mech2spice report fidelity`
(fidelity.json beside the report) when present.
"""
from __future__ import annotations

from pathlib import Path

from ..errors import Mech2SpiceError
from ._common import out_dir, pyplot, read_json, save_figure, stored, write_json
from .cpu import fig_sieve, plot_traffic

plt = pyplot()

PAPER_CYCLES, PAPER_WALL = 719, "50 h 22 min"


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
          step: float | None = None, settle: float | None = None, checkpoint=None, resume: bool = False,
          name: str = "cpu_physical", render: bool = False) -> Path:
    """Run `program` on the oscillators (`cycles` 0: to its halt) into NAME.json, comparing every cycle with the
    ISS (unless `render`), and write NAME.md and the figures from it (step and settle: the processor's
    defaults unless given)."""
    out = out_dir(directory)
    if not render:
        from ..studies import cpu_physical as study      # measuring loads the processor; rendering does not
        given = {k: v for k, v in (("step", step), ("settle", settle)) if v is not None}
        a = study.Options(cycles, program, backend, checkpoint=checkpoint, resume=resume, name=name, **given)
        write_json(out / f"{name}.json", study.measure(out, a), default=None)
    return render_json(out, name)


def render_json(out: Path, name: str) -> Path:
    """NAME.md and the figures from NAME.json (a JSON written before the study kept its rows: one error line)."""
    res = stored(out / f"{name}.json", "cpu_physical")
    if "rows" not in res:
        raise Mech2SpiceError(f"{out / (name + '.json')} has no per-cycle rows (written before the report kept "
                              f"them): measure it again with `{res.get('command', 'mech2spice report cpu_physical')}`")
    o = res["options"]
    if res["moments"]:
        fig_sieve(res["moments"], out / "cpu_sieve_physical.png",
                  f"the processor's oscillators at {o['backend']} fidelity "
                  f"({res.get('simulated_periods', 0):,} periods integrated)")
    fig_activity(res["rows"], out / f"{name}_trace.png", o["backend"])
    (out / f"{name}.md").write_text(_markdown(res, out, name))
    print(out / f"{name}.md", f"{res['wall_s']:.0f} s")
    return out / f"{name}.md"


def _speedups_txt(res: dict) -> str:
    """The processor's default envelope speed-ups (cpu/physical.py, docs/latency.md), as used by this run."""
    sp = res["speedups"]
    if not sp:
        return ""
    parts = ([f"per-gate latency {sp['latency']} u_R"] if sp["latency"] else []) + \
        (["the insulators stepped exactly (exponential step)"] if sp["exponential"] else [])
    return "; " + ", ".join(parts) + " (docs/latency.md)" if parts else ""


def _markdown(res: dict, out: Path, name: str) -> str:
    o, rows, sieve = res["options"], res["rows"], res["sieve"]
    wall, per_cycle, primes = res["wall_s"], res["s_per_cycle"], res["primes"]
    paper_wall = f" (the paper's sieve run: {PAPER_WALL})" if sieve else ""
    settle_txt = (f"each pause ends once every channel has stayed within {o['settle']} u_R for two 200-period "
                  "windows (`envelope.integrate(settle_tol=...)`; pulses always run in full)" if o["settle"] else
                  "fixed-length pauses")
    return f"""# The processor at oscillator level ({o['backend']})

Generated by `{res['command']}` on {res['host']}, 2 cores (shared with other jobs),
program `{o['program']}`{' (resumed from a checkpoint: wall time is this session only)' if o['resume'] else ''}.

`verilog/cpu.v` synthesised with the fan-out limit: 6486 oscillators. Simulated at {o['backend']} fidelity
(step {o['step']:g} periods, compiled envelope kernel, {settle_txt}{_speedups_txt(res)}). The behavioural memory decodes the read
address from the raddr channels' amplitudes each cycle, drives rdata with the stored byte as forces and
commits writes at the clock edge (`mech2spice/cpu/physical.py`). Every cycle is compared with the ISS
(port activity, all registers decoded from the latch amplitudes, and memory).

## Result

- **{'halted' if res['halted'] else 'did not halt'} after {res['cycles']} cycles**{f" (the paper's sieve: {PAPER_CYCLES} cycles)" if sieve else ""}; {'every cycle identical to the ISS' if res['agree_every_cycle'] else 'DISAGREED with the ISS'};
  final memory {'equal to' if res['final_memory_equals_iss'] else 'DIFFERENT from'} the golden (ISS) memory.
{f"- primes left unmarked in 128..159: {primes}" if sieve else ""}
- **wall time {wall:.0f} s ({wall / 60:.1f} min)**, {per_cycle:.2f} s per cycle on average{paper_wall}
  (CPU time of the process {res.get('cpu_s') or 0:.1f} s, ISS comparison included; {res.get('load', '')} at the end: the machine was shared);
  {res.get('periods', 0):,} drive periods of processor time, of which
  {res.get('simulated_periods', 0):,} were integrated.

{'![sieve memory, physical run](cpu_sieve_physical.png)' if res['moments'] else ''}
{devices_md(res)}
![memory traffic, physical run]({name}_trace.png)
{fidelity_section(out / 'fidelity.json')}
## Every cycle

<details><summary>{len(rows)} cycles (click)</summary>

| cycle | pc | instruction | raddr | rdata | we | waddr | wdata | = ISS | wall (s) |
|---|---|---|---|---|---|---|---|---|---|
""" + "\n".join(f"| {r['cycle']} | {r['pc']} | {r['instr']} | {r['raddr']} | {r['rdata']} | {r['we']} | "
                f"{r['waddr']} | {r['wdata']} | {'yes' if r['same'] else 'NO'} | {r['wall_s']:.1f} |"
                for r in rows) + "\n\n</details>\n"
