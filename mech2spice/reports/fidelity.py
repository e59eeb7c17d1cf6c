"""What each envelope speed-up (a longer step, settle detection) costs in accuracy (issue 6, multi-fidelity).

Section cpu: runs the first N sieve cycles of `verilog/cpu.v` at envelope fidelity under several settings, side by
side in one process, and compares every cycle with the ISS (decoded port activity and registers) and
with the reference setting (the full fixed-length pauses, step 2 periods): the largest difference of
any probed amplitude (output bits and latch outputs) at the end of each cycle, the smallest band
margin of any decoded bit, the drive periods actually integrated and the wall time.

Section clocked: the counter, the FSM and the square root of 2809 (`simulation.run_clocked_physical`)
under the same settings against the envelope at step 1 with full pauses (the setting validated against
RK4 in reports/envelope.md and reports/sequential.md): the decoded trace against the logic backend, the
largest amplitude difference at the read points, the smallest margin, integrated periods and wall time.

Section cone: cone pruning (`--observe`) on comparator4, all 256 inputs.

usage: mech2spice report fidelity [--only cpu|clocked|cone ...] [--cycles 30] [--render]
Writes reports/fidelity.json and reports/fidelity.md (~20 min on the 2-core machine).
"""
from __future__ import annotations

import time
from contextlib import contextmanager
from pathlib import Path

from .. import data, simulation
from ..backends.envelope import EnvelopeEngine, EnvelopeOptions
from ..cpu import run as R
from ..cpu.iss import ISS
from ..cpu.physical import PhysicalCPU
from ..physics.params import DEFAULT, margin
from ..synthesis.synth import synthesize
from ..studies._common import load_average, sections
from ._common import SANDBOX, out_dir, read_json, write_json
from ..experiments.scenes import COUNTER_STEPS, FSM_STEPS, sqrt_steps

SECTIONS = ("cpu", "clocked", "cone")

# (label, envelope step in periods, settle tolerance in u_R or None, latency threshold in u_R or None,
#  exponential step, rates on both cores).  "Alone" means on top of step 8, settle 0.1 (the default before
#  issue 18); the last rows combine them.
SETTINGS = [("reference: step 2, full pauses", 2.0, None, None, False, False),
            ("step 8, settle 0.1", 8.0, 0.1, None, False, False),
            ("step 8, settle 0.1, latency 0.05", 8.0, 0.1, 0.05, False, False),
            ("step 8, settle 0.1, latency 0.1", 8.0, 0.1, 0.1, False, False),
            ("step 8, settle 0.1, latency 0.2", 8.0, 0.1, 0.2, False, False),
            ("step 12, settle 0.1", 12.0, 0.1, None, False, False),
            ("step 16, settle 0.1, exponential", 16.0, 0.1, None, True, False),
            ("step 16, settle 0.1, exponential, latency 0.1", 16.0, 0.1, 0.1, True, False),
            ("step 16, settle 0.1, exponential, latency 0.2", 16.0, 0.1, 0.2, True, False),
            ("step 20, settle 0.1, exponential, latency 0.1", 20.0, 0.1, 0.1, True, False)]


def run_setting(prog, cycles: int, step: float, settle, latency=None, exponential=False, parallel=False) -> dict:
    """`cycles` cycles of `prog` on the envelope processor beside the ISS; stops at the first disagreement."""
    iss = ISS(R.make_memory(prog))
    t0, c0 = time.perf_counter(), time.process_time()
    cpu = PhysicalCPU(R.make_memory(prog), "envelope", step=step, settle=settle, latency=latency,
                      exponential=exponential, parallel=parallel)
    reset_s, reset_cpu_s = time.perf_counter() - t0, time.process_time() - c0
    rows = []
    for _ in range(cycles):
        t = time.perf_counter()
        sim0 = cpu.simulated
        want, got = iss.step(), cpu.step()
        try:
            same = want == got and iss.registers() == cpu.registers()
        except Exception as err:          # an invalid bit: report it as a disagreement
            same, got = False, str(err)
        amps = dict(cpu.amps)
        rows.append({"cycle": len(rows), "same": bool(same), "wall_s": time.perf_counter() - t,
                     "simulated": cpu.simulated - sim0, "amps": amps,
                     "min_margin": float(min(margin(v) for v in amps.values()))})
        if not same:
            break
    return {"reset_s": reset_s, "rows": rows, "periods": cpu.period, "simulated": cpu.simulated,
            "block_steps": cpu.block_steps, "wall_s": time.perf_counter() - t0,
            "cpu_s": time.process_time() - c0, "reset_cpu_s": reset_cpu_s}


def parallel_ratio(periods: int = 2000, repeats: int = 2) -> dict:
    """Both cores alone: the processor's rates on one thread and on all (EnvelopeOptions.parallel), from
    its power-up state, `periods` periods at step 8, alternated `repeats` times in one process."""
    from ..backends.envelope import integrate
    from ..physics import network
    cpu = PhysicalCPU(R.make_memory(R.load_program(data.program("sieve.asm"))), "envelope", step=8.0,
                      latency=None, exponential=False)
    stim = network.stimulus(cpu.model, cpu.netlist, cpu.p, [(0, [{"rdata": 0}])], clock=[[0]])
    times = {False: [], True: []}
    for _ in range(repeats):
        for parallel in (False, True):
            t = time.perf_counter()
            integrate(cpu.model, periods, step_periods=8.0, stimulus=stim, state=cpu.state[:3],
                      start_period=cpu.period, parallel=parallel)
            times[parallel].append(time.perf_counter() - t)
    one, two = min(times[False]), min(times[True])
    import numba
    return {"periods": periods, "one_thread_s": one, "all_threads_s": two, "threads": numba.get_num_threads(),
            "speed_up": one / two}


def compare(res: dict) -> list[dict]:
    """Per setting: agreement with the ISS, max amplitude difference to the reference, margin, cost."""
    ref = res[SETTINGS[0][0]]["rows"]
    out = []
    for label, step, settle, latency, exponential, parallel in SETTINGS:
        r = res[label]
        rows = r["rows"]
        diffs = [max(abs(row["amps"][k] - rr["amps"][k]) for k in rr["amps"]) for row, rr in zip(rows, ref)]
        out.append({"setting": label, "step": step, "settle": settle, "latency": latency, "parallel": parallel,
                    "exponential": exponential,
                    "block_steps": r.get("block_steps", 0), "cycles": len(rows),
                    "all_same_as_iss": all(row["same"] for row in rows),
                    "max_amp_diff": float(max(diffs)), "min_margin": min(row["min_margin"] for row in rows),
                    "periods": r["periods"], "simulated": r["simulated"],
                    "wall_s": r["wall_s"], "reset_s": r["reset_s"],
                    "s_per_cycle": (r["wall_s"] - r["reset_s"]) / max(len(rows), 1),
                    "cpu_s_per_cycle": (r["cpu_s"] - r["reset_cpu_s"]) / max(len(rows), 1)})
    return out


# --- clocked designs through simulation.run_clocked_physical -------------------------------------------
# (label, step (None: the engine's default), settle, latency, exponential)
CLOCKED_SETTINGS = [("reference: step 1, full pauses", 1, None, None, False),
                    ("step 2, full pauses", 2, None, None, False),
                    ("step 4, settle 0.1", None, 0.1, None, False),
                    ("step 4, settle 0.1, latency 0.1", None, 0.1, 0.1, False),
                    ("step 8, settle 0.1", 8, 0.1, None, False),
                    ("step 16, settle 0.1, exponential", 16, 0.1, None, True),
                    ("step 16, settle 0.1, exponential, latency 0.1", 16, 0.1, 0.1, True)]


@contextmanager
def _timed_engine(record: list):
    """Time each EnvelopeEngine.run: the integration alone, after the model and its cached operators
    (EnvelopeEngine.prepare: envelope operator, compiled arrays, stability bound) are built."""
    original = EnvelopeEngine.run

    def run(self, model, *args, **kwargs):
        self.prepare(model)                    # the model's cached operators: part of building it
        t, c = time.perf_counter(), time.process_time()
        out = original(self, model, *args, **kwargs)
        record.append((time.perf_counter() - t, time.process_time() - c))
        return out
    EnvelopeEngine.run = run
    try:
        yield
    finally:
        EnvelopeEngine.run = original


def clocked_designs() -> dict:
    """The clocked designs with their stimuli: counter4, the FSM, the square root of 2809."""
    fsm = FSM_STEPS
    sqrt = sqrt_steps()
    return {"counter4": (data.verilog("counter4.v"), COUNTER_STEPS), "fsm": (data.verilog("fsm.v"), fsm),
            "sqrt(2809)": (data.verilog("sqrt.v"), sqrt)}


def clocked() -> list[dict]:
    """The clocked section: each design under each setting against the logic trace and the reference."""
    rows = []
    for name, (path, steps) in clocked_designs().items():
        nl = synthesize(path)
        cycles = simulation.expand_steps(steps)
        timing = simulation.clock_timing(nl)
        want = [e["outputs"] for e in simulation.run_clocked_logic(nl, cycles)["trace"]]
        ref = None
        for label, step, settle, latency, exponential in CLOCKED_SETTINGS:
            t, runs = time.perf_counter(), []
            # step None: envelope.default_step(model), 4 periods where the stability bound allows
            with _timed_engine(runs):
                r = simulation.run_clocked_physical(nl, DEFAULT, cycles, "envelope", timing,
                                                    options=EnvelopeOptions(step_periods=step, latency=latency,
                                                                            exponential=exponential),
                                                    settle_tol=settle)
            wall = time.perf_counter() - t
            ref = ref or r
            got = [e["outputs"] for e in r["trace"]]
            diff = max(abs(e["amplitudes"][k] - f["amplitudes"][k]) for e, f in zip(r["trace"], ref["trace"])
                       for k in e["amplitudes"])
            rows.append({"design": name, "setting": label, "step": r["envelope_step"], "settle": settle,
                         "latency": latency, "exponential": exponential, "engine_s": sum(w for w, _ in runs),
                         "engine_cpu_s": sum(c for _, c in runs),
                         "cycles": len(cycles), "trace_equals_logic": got == want, "max_amp_diff": diff,
                         "min_margin": r["min_margin"], "periods": r["periods"],
                         "simulated": r["simulated_periods"], "wall_s": wall, "valid": r["valid"],
                         "stable": r.get("stable"), "settled": r.get("settled"),
                         "reintegrated": r.get("cycles_reintegrated", 0),
                         "worst_growth": max(e["stability"]["growth_rate"] for e in r["trace"]
                                             if e.get("stability", {}).get("growth_rate") is not None)})
            print(rows[-1], flush=True)
    return rows


# --- cone pruning (synth.observe, `--observe PORT`) ----------------------------------------------------
def cone() -> list[dict]:
    """comparator4 on all 256 input pairs (envelope, one batch): the full netlist against the netlist
    pruned to the cone of one output port."""
    from ..synthesis.synth import observe
    full_nl = synthesize(data.verilog("comparator4.v"))
    values = [{"a": a, "b": b} for a in range(16) for b in range(16)]
    t = time.perf_counter()
    full = simulation.run_physical(full_nl, DEFAULT, values, "envelope")
    full_s = time.perf_counter() - t
    rows = []
    for port in full_nl.outputs:
        nl = observe(full_nl, [port])
        t = time.perf_counter()
        got = simulation.run_physical(nl, DEFAULT, values, "envelope")
        wall = time.perf_counter() - t
        same = all(g["outputs"][port] == f["outputs"][port] for g, f in zip(got, full))
        diff = max(abs(g["amplitudes"][b] - f["amplitudes"][b]) for g, f in zip(got, full) for b in g["amplitudes"])
        rows.append({"design": "comparator4", "observe": port, "gates": len(nl.gates()),
                     "gates_full": len(full_nl.gates()), "outputs_identical": same, "max_amp_diff": diff,
                     "wall_s": wall, "wall_full_s": full_s, "cases": len(values)})
        print(rows[-1], flush=True)
    return rows


TOL = 0.02     # u_R: issue 6's agreement tolerance for reduced models
BASE = "step 8, settle 0.1"     # the processor's setting before issue 18: what "alone" adds to


def figure(d: dict, path: Path) -> None:
    """Cost (s per cycle / engine s) against the worst amplitude difference, one marker per setting."""
    from ._common import pyplot, save_figure
    plt = pyplot()
    panels = [("processor, first %d sieve cycles" % d.get("cycles", 0), d.get("cpu", []), "s_per_cycle",
               "s per cycle")]
    for design in dict.fromkeys(r["design"] for r in d.get("clocked", [])):
        panels.append((design, [r for r in d["clocked"] if r["design"] == design], "engine_s", "engine run (s)"))
    panels = [p for p in panels if p[1] and all(p[2] in r for r in p[1])]
    if not panels:
        return
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 5.6), squeeze=False)
    for ax, (title, rows, key, unit) in zip(axes[0], panels):
        for k, r in enumerate(rows):
            ax.scatter(r[key], max(r["max_amp_diff"], 1e-5), s=30, color=f"C{k % 10}", label=r["setting"],
                       marker="o" if r.get("all_same_as_iss", r.get("trace_equals_logic")) else "x")
        ax.axhline(TOL, color="0.5", ls="--", lw=0.8)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.xaxis.set_minor_formatter(plt.NullFormatter())
        ax.xaxis.set_major_formatter(plt.FormatStrFormatter("%g"))
        ax.set_xlabel(unit)
        ax.set_ylabel("worst amplitude difference (u_R; 0 drawn at 1e-5)")
        ax.set_title(title, fontsize=9)
        ax.legend(fontsize=6, loc="upper center", bbox_to_anchor=(0.5, -0.2))
    fig.suptitle(f"envelope options: cost against fidelity (envelope backend, {d['machine']}, {d.get('load', '')})\n"
                 "reference: step 2 full pauses (processor), step 1 full pauses (clocked); dashed: 0.02 u_R; "
                 "x: a decoded value differed", fontsize=8)
    save_figure(fig, path, dpi=120)


def defaults_md(d: dict) -> list[str]:
    """Which settings are on by default, checked against the measured rows."""
    from ..cpu import physical
    rows = [(r.get("design", "processor"), r) for r in d.get("cpu", []) + d.get("clocked", [])]
    L = ["## Defaults", ""]
    from ..backends.envelope import DEFAULT_STEP
    for what, cpu, step, settle, latency, expo in (
            ("`cpu run --backend envelope`", True, physical.PROCESSOR_STEP, physical.SETTLE_TOL, physical.LATENCY,
             physical.EXPONENTIAL),
            ("clocked `simulate --backend envelope`", False, DEFAULT_STEP, simulation.CLOCKED_SETTLE_TOL, None,
             False)):
        hit = [(n, r) for n, r in rows if r["settle"] == settle and r["step"] == step
               and (n == "processor") == cpu and r.get("latency") == latency
               and bool(r.get("exponential")) == expo and not r.get("parallel")]
        if not hit:
            continue
        worst = max(r["max_amp_diff"] for _, r in hit)
        ok = worst <= TOL and all(r.get("all_same_as_iss", r.get("trace_equals_logic")) for _, r in hit)
        L.append(f"- {what}: settle {settle}" + (f", step {step:g}" if step else "") +
                 (f", latency {latency}" if latency else "") + (", exponential" if expo else "") +
                 f": worst amplitude difference {worst:.4f} u_R over {', '.join(sorted({n for n, _ in hit}))}, "
                 f"{'within' if ok else 'NOT within'} the {TOL} u_R tolerance, every decoded value identical.")
    over = [r for _, r in rows if r["max_amp_diff"] > TOL]
    if over:
        L.append("- Not used: " + "; ".join(f"{r['setting']} ({r['max_amp_diff']:.4f} u_R)" for r in over) +
                 f" exceeds {TOL} u_R.")
    L += ["- Cone pruning is opt-in (`--observe`): it changes what the scene contains.", ""]
    return L


def markdown(d: dict) -> str:
    """The text of fidelity.md from the measured results `d`."""
    L = ["# What each envelope speed-up costs", "",
         f"Generated by `mech2spice report fidelity` on the {d['machine']}; every setting of a table ran in "
         "the same process, one after another (wall times compare within a table; the machine was shared).",
         "", "These options trade accuracy for speed at envelope fidelity (docs/latency.md):", "",
         "- **step**: RK4 on the envelope equations with steps of whole drive periods (refused above the "
         "stability bound, reports/envelope.md);",
         "- **exponential**: the insulators' linear oscillators stepped exactly (Lawson RK4): their mode is "
         "the stiffest at rest, so the bound rises (15.1 -> 27.5 periods on the processor) and steps of 16 "
         "periods become possible;",
         "- **latency** TOL: a gate block (channel, insulator, gate oscillators) whose channel, inputs and "
         "rates stayed within TOL u_R for ~200 periods is frozen (held, not integrated) until an input "
         "channel or its forcing moves by more than TOL; *gate-block steps* counts the blocks integrated "
         "per step, summed;",
         "- **both cores**: the rates of every step on two threads (numba prange; without latency), measured "
         "alone below the processor table;",
         "- **settle** (idle-time skipping): a stretch of constant inputs ends once every channel's amplitude "
         "has stayed within `settle` u_R for two 200-period windows (at least 400 periods after the change); "
         "the rest of the stretch is the settled state, held. It watches channels only: gate oscillators "
         "ring in slow, lightly damped gate-insulator modes that change no logic level, and on the "
         "processor a few logic-0 channels keep an 83-period, ~0.05 u_R peak-to-peak oscillation for "
         "thousands of periods (measured while building this), which a derivative test would wait out.", ""]
    if "cpu" in d:
        L += [f"## The processor (`verilog/cpu.v`, 6486 oscillators): first {d['cycles']} sieve cycles", "",
              "*Amplitude difference*: the largest difference of any probed amplitude (output bits and the "
              "43 latch outputs) at the end of each cycle against the reference setting; *margin*: the "
              "smallest distance of any of them to its band edge, in band widths.", "",
              "| setting | cycles = ISS | max amplitude difference (u_R) | min margin | integrated / simulated "
              "periods | gate-block steps | s per cycle | speed-up |", "|---|---|---|---|---|---|---|---|"]
        base = next((r for r in d["cpu"] if r["setting"] == BASE), d["cpu"][0])
        for r in d["cpu"]:
            blocks = f"{r['block_steps']:,}" if r.get("block_steps") else "all"
            L.append(f"| {r['setting']} | {r['cycles'] if r['all_same_as_iss'] else 'NO'} | {r['max_amp_diff']:.4f} "
                     f"| {r['min_margin']:+.3f} | {r['simulated']:,} / {r['periods']:,} | {blocks} | "
                     f"{r['s_per_cycle']:.3f}" + (f" ({r['cpu_s_per_cycle']:.3f})" if "cpu_s_per_cycle" in r else "") +
                     f" | {base['s_per_cycle'] / r['s_per_cycle']:.1f}x |")
        L += ["", "*s per cycle*: wall seconds (in brackets, where recorded: CPU seconds of the process). "
              f"*speed-up*: wall s per cycle of `{BASE}` over this row's, in the same run. "
              f"Machine load while it ran (`uptime`): {d.get('load', 'not recorded')}.", "",
              "![cost against fidelity per option](fidelity_options.png)", ""]
        if "parallel" in d:
            q = d["parallel"]
            L += [f"**Both cores** (`EnvelopeOptions.parallel`, measured alone: {q['periods']:,} processor periods "
                  f"at step 8 from its power-up state, one thread against {q['threads']}, alternated in one run): "
                  f"{q['one_thread_s']:.2f} s against {q['all_threads_s']:.2f} s, a speed-up of "
                  f"{q['speed_up']:.2f}x. Each RK4 stage is three parallel passes, each waiting for the slower "
                  "thread; on this shared machine the other engineers' jobs hold the second core. It is off by "
                  "default and not combined with latency (too few active rows to share out).", ""]
    if "clocked" in d:
        L += ["## Clocked designs (`simulation.run_clocked_physical`)", "",
              "Against the envelope at step 1 with full pauses, which reports/sequential.md and "
              "reports/envelope.md validate against RK4. *trace = logic*: every cycle's decoded outputs equal "
              "the logic backend's. *stable / settled*: every read's stability verdict (docs/stability.md: a "
              "stable fixed point; within 0.005 band widths of it), with the number of cycles whose held state "
              "had not settled and were integrated again, and the least stable mode's growth per drive "
              "period over all reads.", "",
              "| design | setting | trace = logic | max amplitude difference at reads (u_R) | min margin | "
              "stable / settled (cycles again) | worst growth | integrated / simulated periods | engine run (s) | "
              "wall (s) |", "|---|---|---|---|---|---|---|---|---|---|"]
        for r in d["clocked"]:
            eng = f"{r['engine_s']:.2f}" if "engine_s" in r else "-"
            eng += f" ({r['engine_cpu_s']:.2f})" if "engine_cpu_s" in r else ""
            verdict = (f"{r['stable']} / {r['settled']} ({r['reintegrated']})" if r.get("stable") is not None
                       else "-")
            growth = f"{r['worst_growth']:.1e}" if r.get("worst_growth") is not None else "-"
            L.append(f"| {r['design']} | {r['setting']} (step {r['step']:g}) | {r['trace_equals_logic']} | {r['max_amp_diff']:.4f} | "
                     f"{r['min_margin']:+.3f} | {verdict} | {growth} | {r['simulated']:,} / {r['periods']:,} | {eng} | "
                     f"{r['wall_s']:.1f} |")
        L += ["", "*engine run*: the integration alone (`EnvelopeEngine.run` after `EnvelopeEngine.prepare`: the "
              "model and its cached operators -- envelope operator, compiled arrays, stability bound -- are built "
              "before it), "
              "wall seconds (in brackets: CPU seconds of this process, which the other jobs on the machine do "
              "not inflate); "
              "*wall*: synthesis-free `run_clocked_physical`, model build included.", ""]
        L.append("")
    L += defaults_md(d)
    if "cone" in d:
        L += ["## Cone pruning (`--observe PORT`, `synth.observe`)", "",
              "comparator4, all 256 input pairs in one envelope batch: the full netlist against the netlist "
              "pruned to one output's fan-in cone. The kept gates lose the loads of the pruned ones, which "
              "moves their amplitudes slightly.", "",
              "| observed | gates (full) | outputs identical | max amplitude difference (u_R) | wall (s), "
              "pruned / full |", "|---|---|---|---|---|"]
        for r in d["cone"]:
            L.append(f"| {r['observe']} | {r['gates']} ({r['gates_full']}) | {r['outputs_identical']} | "
                     f"{r['max_amp_diff']:.4f} | {r['wall_s']:.1f} / {r['wall_full_s']:.1f} |")
        L.append("")
    return "\n".join(L) + "\n"


def write(directory="reports", only=None, cycles: int = 30, render: bool = False) -> Path:
    """Measure the sections in `only` (default all; `render`: none), merge them into fidelity.json and
    rewrite fidelity.md from the whole JSON."""
    sections = [] if render else _sections(only)
    out = out_dir(directory)
    path = out / "fidelity.json"
    d = read_json(path, {})
    d["machine"] = f"{SANDBOX} (shared)"
    if sections:
        d["load"] = _uptime_load()
    if "cpu" in sections:
        prog = R.load_program(data.program("sieve.asm"))
        res = {}
        for label, step, settle, latency, exponential, parallel in SETTINGS:
            res[label] = run_setting(prog, cycles, step, settle, latency, exponential, parallel)
            print(label, f"{res[label]['wall_s']:.0f} s", flush=True)
        d["cpu"], d["cycles"] = compare(res), cycles
        d["parallel"] = parallel_ratio()
    if "clocked" in sections:
        d["clocked"] = clocked()
    if "cone" in sections:
        d["cone"] = cone()
    write_json(path, d, default=None)
    figure(d, out / "fidelity_options.png")
    from . import carrier                   # the whole sieve, envelope against oscillator level (carrier.json)
    sieve = carrier.sieve_block(out)
    (out / "fidelity.md").write_text(markdown(d).rstrip("\n") + ("\n\n" + sieve if sieve else "\n"))
    return out / "fidelity.md"


def _uptime_load() -> str:
    """The 1/5/15-minute load averages at the start of the measurement (2 cores, shared)."""
    return "load average %.2f, %.2f, %.2f" % tuple(load_average())


def _sections(only) -> list[str]:
    """The sections to measure: all by default; unknown names are an error."""
    return sections("fidelity", only, SECTIONS)
