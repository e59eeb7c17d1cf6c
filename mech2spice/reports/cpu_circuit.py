"""The whole processor in a circuit simulator (VACASK, envelope level, memory inside): reports/cpu_circuit.md.

Run: mech2spice report cpu_circuit [--cycles N] [--max_step P] [--reltol TOL] [--only circuit,envelope]
     [--render]
Measures, in this order (each part cached in cpu_circuit.json, `--only` re-measures some, `--render` none):
* circuit: the sieve's first N cycles (`cycles` 0: to the ISS's halt + 1) as one VACASK netlist
  (cpu/circuit.py); every cycle against the ISS (port activity, registers, memory), the circuit's final
  memory, VACASK's cost counters (time points, Newton iterations, where the time went);
* envelope: the same cycles on the envelope engine (PhysicalCPU, step 2, full pauses: the fidelity reference),
  the probes (output bits, 43 latch outputs) sampled before each clock pulse as in the circuit; the per-cycle
  worst amplitude difference between the two;
* setting: another VACASK setting (--max_step, --reltol) on --cycles cycles, kept beside the others (a row of
  the settings table; the main run is one too);
* profile: the reset and one cycle with and without the memory devices (rdata held at 0): the memory's
  share of VACASK's cost.
"""
from __future__ import annotations

import platform
import time
from pathlib import Path

import numpy as np

from ..cpu import run as R
from ..cpu.iss import ISS
from ..errors import Mech2SpiceError
from ._common import HOST, out_dir, pyplot, read_json, save_figure, write_json

PROGRAM = "programs/sieve.asm"
TARGET = 0.02            # u_R: the per-cycle bound against the envelope model
ENVELOPE_STEP = 2.0      # the fidelity report's reference setting (full pauses)
SIEVE_CYCLES = 458       # the sieve halts after 457 cycles; the halt is seen one cycle later


def _machine() -> str:
    import os
    return f"{HOST}, {os.cpu_count()} cores (shared with other jobs), {platform.node() or 'sandbox'}"


# --- the circuit -----------------------------------------------------------------------------------------
def measure_circuit(cycles: int, max_step: float, reltol: float, settle: int | None = None) -> dict:
    """The circuit run and its cycle-by-cycle comparison with the ISS."""
    from ..cpu.circuit import CircuitCPU
    prog = R.load_program(PROGRAM)
    if cycles == 0:
        cycles = R.run_program(PROGRAM, "iss")["cycles"] + 1
    t0 = time.perf_counter()
    cpu = CircuitCPU(R.make_memory(prog), cycles=cycles, max_step=max_step, reltol=reltol, settle=settle)
    wall = time.perf_counter() - t0
    iss, rows, stopped = ISS(R.make_memory(prog)), [], None
    try:
        while cpu.cycle < cycles and not cpu.halted:
            got, want = cpu.step(), iss.step()
            same = got == want and cpu.registers() == iss.registers() and cpu.mem.snapshot() == iss.mem.snapshot()
            rows.append({"cycle": got.cycle, "pc": got.pc, "instr": got.instr or got.phase, "raddr": got.raddr,
                         "rdata": got.rdata, "we": got.we, "waddr": got.waddr, "wdata": got.wdata, "same": same})
    except Mech2SpiceError as err:
        stopped = str(err)
    t = cpu.result["t_periods"]
    sched = cpu.net.schedule
    edges = [0, sched.start(0)] + [sched.start(k) for k in range(1, cycles + 1)]
    points = np.histogram(t, bins=edges)[0].tolist()
    return {"cycles": cycles, "max_step": max_step, "reltol": reltol, "schedule": vars(sched),
            "wall_s": wall, "simulator_wall_s": cpu.result["wall_s"], "stats": cpu.result["stats"],
            "time_points": cpu.result["points"], "points_reset": points[0], "points_per_cycle": points[1:],
            "rows": rows, "stopped": stopped, "halted": cpu.halted,
            "circuit_memory": cpu.result["memory"], "iss_memory": R.run_program(PROGRAM, "iss")["memory"],
            "probes": cpu.net.probes, "amps": cpu.result["amps"].tolist(), "machine": _machine()}


def measure_profile(max_step: float, reltol: float) -> dict:
    """VACASK's counters for the reset and one cycle, with and without the memory devices."""
    from ..cpu.circuit import emit_cpu, run_cpu_netlist
    image = R.load_program(PROGRAM).image
    out = {"max_step": max_step, "reltol": reltol, "machine": _machine()}
    for key, mem in (("without_memory", False), ("with_memory", True)):
        r = run_cpu_netlist(emit_cpu(image, 1, max_step=max_step, reltol=reltol, memory=mem))
        out[key] = {"points": r["points"], "wall_s": r["wall_s"], **r["stats"]}
    return out


# --- the envelope reference --------------------------------------------------------------------------------
def measure_envelope(cycles: int, step: float = ENVELOPE_STEP) -> dict:
    """The envelope engine's probes just before each clock pulse (PhysicalCPU, full pauses)."""
    return measure_physical("envelope", cycles, step=step)


def measure_physical(backend: str, cycles: int, **options) -> dict:
    """An oscillator-level processor's probes just before each clock pulse (PhysicalCPU, full pauses), where
    the circuit is sampled."""
    from ..cpu.physical import PhysicalCPU
    prog = R.load_program(PROGRAM)
    t0 = time.perf_counter()
    cpu = PhysicalCPU(R.make_memory(prog), backend, settle=None, **options)
    samples, last = [], {"amps": cpu.amps}
    run = cpu._run

    def recording(periods, values, clock):            # keep the last settled amplitudes before each pulse
        if clock:
            samples.append([last["amps"][p] for p in cpu.probes])
        last["amps"] = run(periods, values, clock)
        return last["amps"]
    cpu._run = recording
    for _ in range(cycles):
        cpu.step()
    samples.append([cpu.amps[p] for p in cpu.probes])   # the state after the last edge
    return {"cycles": cycles, "backend": backend, **options, "probes": cpu.probes, "amps": samples,
            "wall_s": time.perf_counter() - t0, "machine": _machine()}


def amplitude_differences(circ: dict, env: dict) -> list[float]:
    """Per sample before a clock pulse, the largest |amplitude difference| (u_R) over the probes both runs
    have.  An oscillator-level run's last sample (the state after its last edge, before the next cycle's
    rdata) is not one: the circuit samples after that rdata has settled."""
    ce, ee = dict(zip(circ["probes"], range(len(circ["probes"])))), env["probes"]
    common = [p for p in ee if p in ce]
    a = np.array(circ["amps"])[:, [ce[p] for p in common]]
    b = np.array(env["amps"])[:, [ee.index(p) for p in common]]
    n = min(len(a), len(b), env.get("cycles", len(b)))
    return np.abs(a[:n] - b[:n]).max(axis=1).tolist()


# --- the report ------------------------------------------------------------------------------------------------
def write(directory="reports", cycles: int = 30, max_step: float = 32.0, reltol: float = 1e-2,
          only="", render: bool = False) -> Path:
    """Measure (or re-render) and write cpu_circuit.md, cpu_circuit.json and cpu_circuit.png."""
    out = out_dir(directory)
    path = out / "cpu_circuit.json"
    data = read_json(path, {}) or {}
    only = ",".join(only) if isinstance(only, (list, tuple)) else (only or "")
    parts = set(filter(None, only.split(","))) or {"circuit", "envelope", "profile"}
    if not render:
        if "circuit" in parts:
            data["circuit"] = measure_circuit(cycles, max_step, reltol)
            write_json(path, data)
        if "setting" in parts:
            data.setdefault("settings", {})[f"{max_step:g}/{reltol:g}"] = measure_circuit(cycles, max_step, reltol)
            write_json(path, data)
        if "profile" in parts:
            data["profile"] = measure_profile(max_step, reltol)
            write_json(path, data)
        if "envelope" in parts:
            n = min(data.get("circuit", {}).get("cycles", cycles), max(cycles, 1))
            data["envelope"] = measure_envelope(n)
            write_json(path, data)
        if "carrier" in parts:         # oscillator level (not in the default parts: ~1 min per cycle here)
            n = min(data.get("circuit", {}).get("cycles", cycles), max(cycles, 1))
            data["carrier"] = measure_physical("carrier", n)
            write_json(path, data)
    if "circuit" not in data:
        raise Mech2SpiceError(f"{path} has no circuit run: run without --render first")
    diffs = amplitude_differences(data["circuit"], data["envelope"]) if "envelope" in data else []
    _figure(data, diffs, out / "cpu_circuit.png")
    md = out / "cpu_circuit.md"
    md.write_text(_markdown(data, diffs))
    print(md)
    return md


def _figure(data: dict, diffs: list[float], path: Path) -> None:
    plt = pyplot()
    c = data["circuit"]
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 3.4))
    per = np.array(c["points_per_cycle"])
    length = c["schedule"]["settle"] + c["schedule"]["pulse"]
    a1.bar(range(len(per)), length / np.maximum(per, 1), color="tab:blue")
    a1.set_xlabel("cycle")
    a1.set_ylabel("mean VACASK step (drive periods)")
    a1.set_title(f"time step per cycle (max {c['max_step']:g} T, reltol {c['reltol']:g})", fontsize=9)
    if diffs:
        a2.semilogy(range(len(diffs)), np.maximum(diffs, 1e-6), "o-", ms=3)
        a2.axhline(TARGET, color="tab:red", lw=0.8, ls="--", label=f"target {TARGET} u_R")
        a2.legend(fontsize=8)
    a2.set_xlabel("cycle (sampled before its clock pulse)")
    a2.set_ylabel("max |amplitude difference| (u_R)")
    a2.set_title("VACASK circuit vs envelope engine (step 2, full pauses)", fontsize=9)
    fig.suptitle(f"sieve on the processor in VACASK (envelope level, memory in Verilog-A); {c['machine']}",
                 fontsize=9)
    save_figure(fig, path, dpi=120)


def _markdown(data: dict, diffs: list[float]) -> str:
    c = data["circuit"]
    rows, st, s = c["rows"], c["stats"], c["schedule"]
    same = sum(r["same"] for r in rows)
    first_bad = next((r["cycle"] for r in rows if not r["same"]), None)
    per_cycle = c["simulator_wall_s"] / max(c["cycles"], 1)
    points = np.array(c["points_per_cycle"])
    newton = st.get("newton_iterations", 0) / max(st.get("accepted", 1), 1)
    step_ms = 1e3 * st.get("newton_s", 0) / max(st.get("accepted", 1), 1)
    mem_ok = c["circuit_memory"] == c["iss_memory"] if c["halted"] else None
    lines = [
        "# The whole processor in a circuit simulator (VACASK)\n",
        f"Generated by `python -m mech2spice.reports.cpu_circuit --only circuit --cycles {c['cycles']} --max_step "
        f"{c['max_step']:g} --reltol {c['reltol']:g}` (the envelope reference: `--only envelope --cycles "
        f"{data.get('envelope', {}).get('cycles', c['cycles'])}`) on {c['machine']}. Design: verilog/cpu.v synthesised with the fan-out "
        "limit (6486 oscillators), program `programs/sieve.asm`; backend `vacask-envelope` "
        "(`mech2spice/cpu/circuit.py`, the memory in `mech2spice/spice/memory.py`; docs/cpu_circuit.md).\n",
        "## Result\n",
        f"- **{same} of {len(rows)} cycles equal to the ISS** (port activity, every register decoded from the "
        f"latch amplitudes, memory after the cycle){'' if first_bad is None else f'; first difference at cycle {first_bad}'}"
        f"{'; stopped: ' + c['stopped'] if c['stopped'] else ''}.",
        f"- halted: {c['halted']}" + (f"; the circuit's final memory (printed by the byte cells at the last time "
                                        f"step) {'equals' if mem_ok else 'DIFFERS from'} the ISS's golden memory."
                                        if mem_ok is not None else
                                        f" (ran {c['cycles']} cycles); the circuit's memory after them "
                                        f"{'equals' if c['circuit_memory'] == _iss_memory_after(len(rows)) else 'differs from'} "
                                        "the ISS's after as many cycles."),
        f"- one VACASK process: {c['simulator_wall_s']:.0f} s wall for the reset and {c['cycles']} cycles "
        f"({s['settle'] + s['pulse']:,} drive periods each), **{per_cycle:.1f} s per cycle**; "
        f"{c['time_points']:,} time points ({points.mean():.0f} per cycle, mean step "
        f"{(s['settle'] + s['pulse']) / max(points.mean(), 1):.2f} periods).",
        f"- profile (VACASK `print stats`): {st.get('unknowns', 0):.0f} unknowns, {st.get('nonzeros', 0):.0f} "
        f"nonzeros; {st.get('accepted', 0):.0f} accepted / {st.get('rejected', 0):.0f} rejected time points, "
        f"{newton:.2f} Newton iterations per time point, {step_ms:.1f} ms of Newton time per time point "
        f"(device evaluation {st.get('eval_s', 0):.0f} s, refactorisation {st.get('refactor_s', 0):.0f} s, "
        f"solves {st.get('solve_s', 0):.0f} s of {st.get('newton_s', 0):.0f} s).",
    ]
    if c.get("note"):
        lines.append(f"- note: {c['note']}.")
    if diffs:
        worst = max(diffs)
        lines.append(f"- against the envelope engine (step 2, full pauses, {data['envelope']['wall_s']:.0f} s): "
                     f"worst amplitude difference per cycle {min(diffs):.4f}..{worst:.4f} u_R over "
                     f"{len(diffs)} samples ({'within' if worst <= TARGET else 'ABOVE'} the {TARGET} u_R target).")
    osc = amplitude_differences(c, data["carrier"]) if "carrier" in data else []
    if osc:
        ref = amplitude_differences(data["envelope"], data["carrier"]) if "envelope" in data else []
        lines.append(f"- against the oscillator level (`carrier`, 12 steps per period, full pauses, "
                     f"{data['carrier']['wall_s']:.0f} s; `--only carrier`): worst amplitude difference per cycle "
                     f"{min(osc):.4f}..{max(osc):.4f} u_R over {len(osc)} samples"
                     + (f"; the envelope engine against it: {min(ref):.4f}..{max(ref):.4f} u_R" if ref else "") + ".")
    lines += _settings_md(data) + _profile_md(data) + _gap_md(data)
    lines += ["\n![time step and amplitude difference per cycle](cpu_circuit.png)\n", "## Every cycle\n",
              "| cycle | pc | instruction | raddr | rdata | we | waddr | wdata | = ISS | time points | "
              "max amp diff to the envelope (u_R) | to the oscillator level (u_R) |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for k, r in enumerate(rows):
        d = f"{diffs[k]:.4f}" if k < len(diffs) else ""
        o = f"{osc[k]:.4f}" if k < len(osc) else ""
        p = points[k] if k < len(points) else ""
        lines.append(f"| {r['cycle']} | {r['pc']} | {r['instr']} | {r['raddr']} | {r['rdata']} | {r['we']} | "
                     f"{r['waddr']} | {r['wdata']} | {'yes' if r['same'] else 'NO'} | {p} | {d} | {o} |")
    return "\n".join(lines) + "\n"


def summary(c: dict, env: dict | None) -> dict:
    """One settings-table row: agreement, step, cost per cycle and the sieve extrapolated."""
    st, s = c["stats"], c["schedule"]
    points = np.array(c["points_per_cycle"], float)
    diffs = amplitude_differences(c, env) if env else []
    per_cycle = c["simulator_wall_s"] / c["cycles"]        # the reset is charged to the cycles (conservative)
    flag = " (print overhead: see the note)" if c.get("note") else ""
    return {"setting": f"max step {c['max_step']:g} T, reltol {c['reltol']:g}, settle {s['settle']}{flag}",
            "cycles": c["cycles"], "same": sum(r["same"] for r in c["rows"]), "rows": len(c["rows"]),
            "max_diff": max(diffs) if diffs else None, "mean_step": (s["settle"] + s["pulse"]) / points.mean(),
            "points_per_cycle": points.mean(), "newton_per_point": st["newton_iterations"] / st["accepted"],
            "ms_per_point": 1e3 * c["simulator_wall_s"] / c["time_points"],
            "eval_share": st["eval_s"] / st["newton_s"], "s_per_cycle": per_cycle,
            "sieve_h": per_cycle * SIEVE_CYCLES / 3600}


def _settings_md(data: dict) -> list[str]:
    runs = [data["circuit"], *data.get("settings", {}).values()]
    env = data.get("envelope")
    lines = ["\n## Settings: accuracy against cost\n",
             f"Each row one VACASK run of the sieve's first cycles ({runs[0]['machine']}; wall times are of a "
             "machine shared with other jobs: time points and Newton iterations per cycle do not depend on the load, "
             "ms per point and s per cycle do, and the load changed between the runs). *max amp diff*: the "
             "worst amplitude difference of any probe at any sample against the envelope engine; *sieve*: the "
             f"wall time per cycle (reset included) times the sieve's {SIEVE_CYCLES} cycles. The first row is the "
             "main run; the others: `python -m mech2spice.reports.cpu_circuit --only setting --cycles N "
             "--max_step P --reltol TOL`.\n",
             "| setting | cycles = ISS | max amp diff (u_R) | mean step (T) | points / cycle | Newton it. / point "
             "| ms / point | device eval share | s / cycle | sieve (h) |", "|---|---|---|---|---|---|---|---|---|---|"]
    for c in runs:
        r = summary(c, env)
        diff = f"{r['max_diff']:.4f}" if r["max_diff"] is not None else "-"
        lines.append(f"| {r['setting']} | {r['same']} / {r['rows']} | {diff} | {r['mean_step']:.2f} | "
                     f"{r['points_per_cycle']:.0f} | {r['newton_per_point']:.2f} | {r['ms_per_point']:.1f} | "
                     f"{r['eval_share']:.0%} | {r['s_per_cycle']:.1f} | {r['sieve_h']:.1f} |")
    return lines


def _profile_md(data: dict) -> list[str]:
    pr = data.get("profile")
    if not pr:
        return []
    lines = ["\n## Profile: the memory's share\n",
             f"The reset and one cycle (max step {pr['max_step']:g} T, reltol {pr['reltol']:g}; `--only profile`), "
             "one run each "
             f"({pr['machine']}):\n", "| netlist | unknowns | nonzeros | time points | Newton iterations | "
             "Newton time (s) | device eval (s) | refactorisation (s) | solves (s) | wall (s) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for key in ("without_memory", "with_memory"):
        r = pr[key]
        lines.append(f"| {key.replace('_', ' ')} | {r['unknowns']:.0f} | {r['nonzeros']:.0f} | {r['accepted']:.0f} | "
                     f"{r['newton_iterations']:.0f} | {r['newton_s']:.1f} | {r['eval_s']:.1f} | "
                     f"{r['refactor_s']:.1f} | {r['solve_s']:.1f} | {r['wall_s']:.1f} |")
    return lines


def _gap_md(data: dict) -> list[str]:
    """The sieve in an hour: what the fastest measured setting that kept every cycle lacks."""
    runs = [summary(c, data.get("envelope")) for c in [data["circuit"], *data.get("settings", {}).values()]
            if not c.get("note")]
    good = [r for r in runs if r["same"] == r["rows"] == r["cycles"]]
    if not good:
        return []
    best = min(good, key=lambda r: r["s_per_cycle"])
    need = 3600 / SIEVE_CYCLES
    return ["\n## The sieve to its halt\n",
            f"Not run: the fastest setting that kept every cycle equal to the ISS ({best['setting']}) costs "
            f"{best['s_per_cycle']:.1f} s per cycle here, {best['sieve_h']:.1f} h for the sieve's {SIEVE_CYCLES} "
            f"cycles; an hour allows {need:.1f} s per cycle, {best['s_per_cycle'] / need:.1f}x less. What would "
            "close the gap: docs/cpu_circuit.md."]


def _iss_memory_after(cycles: int) -> list[int]:
    iss = ISS(R.make_memory(R.load_program(PROGRAM)))
    for _ in range(cycles):
        iss.step()
    return iss.mem.snapshot()


def main(argv=None) -> int:
    """`python -m mech2spice.reports.cpu_circuit [--cycles N] [--max_step P] [--reltol TOL] [--only ...]`."""
    import argparse
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--directory", default="reports")
    ap.add_argument("--cycles", type=int, default=30)
    ap.add_argument("--max_step", type=float, default=32.0)
    ap.add_argument("--reltol", type=float, default=1e-2)
    ap.add_argument("--only", default="")
    ap.add_argument("--render", action="store_true")
    a = ap.parse_args(argv)
    write(a.directory, a.cycles, a.max_step, a.reltol, a.only, a.render)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
