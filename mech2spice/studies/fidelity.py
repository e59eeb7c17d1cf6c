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

Each section is merged into reports/fidelity.json with the defaults it checks (`defaults()`);
mech2spice/reports/fidelity.py renders fidelity.md from it.
Section settled: the processor's reads judged against their own future (`cpu run --settle-check`): the whole
sieve at the defaults, and its first cycles with lower latency thresholds.

usage: mech2spice report fidelity [--only cpu|clocked|cone|settled ...] [--cycles 30] [--render]  (~30 min, 2 cores)
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
from ._common import SANDBOX, load_average, read_json, sections, write_json
from ..experiments.scenes import COUNTER_STEPS, FSM_STEPS, sqrt_steps

SECTIONS = ("cpu", "clocked", "cone", "settled")

# The processor's reads against their own future (cpu/settle_check.py): the whole sieve at the defaults, then
# its first cycles at the defaults and with the latency threshold lowered (what a tighter rule costs).
SETTLED_LATENCIES = (0.05, 0.02)
SETTLED_CYCLES = 60

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


def settled() -> dict:
    """The sieve's reads judged against their own future (settle_check.PERIODS more, nothing skipped): at the
    processor's defaults to its halt, then SETTLED_CYCLES cycles at each lower latency; with the cost of each
    setting without the check (gate-block steps, CPU seconds)."""
    from ..cpu.settle_check import PERIODS
    prog = data.program("sieve.asm")
    runs = []
    load = "load average %.2f, %.2f, %.2f" % tuple(load_average())
    for latency, cycles in ((None, 100_000), (None, SETTLED_CYCLES), *((lat, SETTLED_CYCLES) for lat in SETTLED_LATENCIES)):
        own = {} if latency is None else {"latency": latency}
        c0 = time.process_time()
        plain = R.run_program(prog, "envelope", cycles, **own)
        cpu_s = time.process_time() - c0
        checked = R.run_program(prog, "envelope", cycles, settle_check=PERIODS, **own)
        runs.append({"latency": plain["latency"], "cycles": plain["cycles"], "halted": plain["halted"],
                     "iss_mismatches": checked["iss_check"]["mismatches"], "block_steps": plain["block_steps"],
                     "cpu_s": cpu_s, "wall_s": plain["wall_s"], "checked_wall_s": checked["wall_s"],
                     "settle_check": checked["settle_check"]})
        print(runs[-1]["latency"], runs[-1]["settle_check"]["worst_still_to_come_bw"], flush=True)
    return {"settled": runs, "settled_load": load}


def defaults() -> dict:
    """The envelope settings each command uses by default: the report checks them against the measured rows."""
    from ..backends.envelope import DEFAULT_STEP
    from ..cpu import physical
    return {"processor": {"step": physical.PROCESSOR_STEP, "settle": physical.SETTLE_TOL, "latency": physical.LATENCY,
                          "exponential": physical.EXPONENTIAL},
            "clocked": {"step": DEFAULT_STEP, "settle": simulation.CLOCKED_SETTLE_TOL, "latency": None,
                        "exponential": False}}


def measure(section: str, quick: bool = False, cycles: int = 30) -> dict:
    """One section's results, as the keys it adds to fidelity.json (`quick` is not used: the settings are the
    study)."""
    if section == "cpu":
        prog = R.load_program(data.program("sieve.asm"))
        res = {}
        for label, step, settle, latency, exponential, parallel in SETTINGS:
            res[label] = run_setting(prog, cycles, step, settle, latency, exponential, parallel)
            print(label, f"{res[label]['wall_s']:.0f} s", flush=True)
        return {"cpu": compare(res), "cycles": cycles, "parallel": parallel_ratio()}
    if section == "settled":
        return settled()
    return {section: {"clocked": clocked, "cone": cone}[section]()}


def measure_into(path: Path, only=None, cycles: int = 30) -> dict:
    """Measure the sections in `only` (default all), merge them into the JSON at `path` and save it."""
    d = read_json(path, {})
    d["machine"] = f"{SANDBOX} (shared)"
    d["defaults"] = defaults()
    for name in sections("fidelity", only, SECTIONS):
        if name == "cpu":          # the processor table's load (2 cores, shared); settled records its own
            d["load"] = "load average %.2f, %.2f, %.2f" % tuple(load_average())
        d.update(measure(name, cycles=cycles))
        write_json(path, d, default=None)
    return d
