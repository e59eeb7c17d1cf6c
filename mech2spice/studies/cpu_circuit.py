"""The whole processor in a circuit simulator (VACASK, envelope level, memory inside), measured into
cpu_circuit.json (mech2spice/reports/cpu_circuit.py renders reports/cpu_circuit.md and .png from it).

Sections, in this order (each merged into the JSON as it finishes; default circuit, envelope, profile):
* circuit: the sieve's first N cycles (`cycles` 0: to the ISS's halt + 1) as one VACASK netlist
  (cpu/circuit.py); every cycle against the ISS (port activity, registers, memory), the circuit's final
  memory, VACASK's cost counters (time points, Newton iterations, where the time went);
* setting: another VACASK setting (max_step, reltol) on N cycles, kept beside the others (a row of the
  settings table; the main run is one too);
* profile: the reset and one cycle with and without the memory devices (rdata held at 0): the memory's
  share of VACASK's cost;
* envelope: the same cycles on the envelope engine (PhysicalCPU, step 2, full pauses: the fidelity reference),
  the probes (output bits, 43 latch outputs) sampled before each clock pulse as in the circuit;
* carrier: the same at oscillator level (~1 min per cycle here).
"""
from __future__ import annotations

import os
import platform
import time
from pathlib import Path

import numpy as np

from ..cpu import run as R
from ..cpu.iss import ISS
from ..errors import Mech2SpiceError
from ._common import read_json, sections, write_json

SECTIONS = ("circuit", "setting", "profile", "envelope", "carrier")
DEFAULT = ("circuit", "profile", "envelope")
PROGRAM = "programs/sieve.asm"
ENVELOPE_STEP = 2.0      # the fidelity report's reference setting (full pauses)


def _machine() -> str:
    return (f"{platform.machine()} {platform.system()}, {os.cpu_count()} cores (shared with other jobs), "
            f"{platform.node() or 'sandbox'}")


def iss_memory_after(cycles: int) -> list[int]:
    """The ISS's memory after `cycles` cycles of the sieve (what a circuit run that did not halt is held to)."""
    iss = ISS(R.make_memory(R.load_program(PROGRAM)))
    for _ in range(cycles):
        iss.step()
    return iss.mem.snapshot()


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
            "iss_memory_after": iss_memory_after(len(rows)),
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


# --- the oscillator-level references ---------------------------------------------------------------------------
def measure_envelope(cycles: int, step: float = ENVELOPE_STEP) -> dict:
    """The envelope engine's probes just before each clock pulse (PhysicalCPU, full pauses), at the fidelity
    report's reference: no per-gate latency, no exponential step (the processor's defaults since)."""
    return measure_physical("envelope", cycles, step=step, latency=None, exponential=False)


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


# --- entry point -------------------------------------------------------------------------------------------
def measure(out: Path, only=None, cycles: int = 30, max_step: float = 32.0, reltol: float = 1e-2) -> dict:
    """Measure the sections in `only` (names, or one comma-separated string; default DEFAULT) in SECTIONS order,
    merging each into OUT/cpu_circuit.json as it finishes; the references run the circuit's cycle count."""
    path = Path(out) / "cpu_circuit.json"
    data = read_json(path, {}) or {}
    names = [n for item in ([only] if isinstance(only, str) else only or []) for n in item.split(",") if n]
    wanted = set(sections("cpu_circuit", names, SECTIONS, default=DEFAULT))
    for name in (s for s in SECTIONS if s in wanted):
        if name == "circuit":
            data["circuit"] = measure_circuit(cycles, max_step, reltol)
        elif name == "setting":
            data.setdefault("settings", {})[f"{max_step:g}/{reltol:g}"] = measure_circuit(cycles, max_step, reltol)
        elif name == "profile":
            data["profile"] = measure_profile(max_step, reltol)
        else:                      # envelope, carrier: as many cycles as the circuit ran (at least one)
            n = min(data.get("circuit", {}).get("cycles", cycles), max(cycles, 1))
            data[name] = measure_envelope(n) if name == "envelope" else measure_physical("carrier", n, latency=None)
        write_json(path, data)
    return data
