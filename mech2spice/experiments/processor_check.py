"""The carrier engine against textbook RK4 on the processor: whole clock cycles from one saved state.

RK4 at 160 steps per period costs ~40x the carrier on the 6486-oscillator processor, so it cannot run the
sieve; instead both engines continue the same `cpu run --backend carrier` checkpoint (the oscillator state
after cycle k) for a few whole cycles under the same rules (pulses in full, pauses ending once the channels
settle), and every probed amplitude (output ports and the 43 latch outputs) is compared at the end of each
cycle: magnitude in u_R and phase in degrees.

    python -m mech2spice.experiments.processor_check CHECKPOINT.json [--cycles 3] [--steps 160] [--out F.json]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from ..compare import agreement
from ..cpu import run as cpu_run
from ..inputs import strict_json, write_text
from ..cpu.machines import make_cpu


def _recording(engine, log: list):
    """The engine with each run's last-period complex amplitudes appended to `log`."""
    original = engine.run

    def run(*args, **kwargs):
        result = original(*args, **kwargs)
        log.append(result.amp[-1, :, 0].copy())
        return result
    engine.run = run
    return engine


def continue_cycles(checkpoint: str, program: str, backend: str, cycles: int, steps: int | None,
                    full_pauses: bool = False, rows_file: str | None = None, latency: float | None = None) -> dict:
    """Load the carrier checkpoint's oscillator state into a `backend` processor and run `cycles` cycles
    (`steps`: steps per period where the engine takes them, None for its default; `full_pauses`: every pause
    integrated to its end, no idle skipping; `latency`: the engine's per-gate latency threshold in u_R, None
    for every gate integrated).  With `rows_file`, each finished
    cycle is appended to it as a JSON line and the machine's state after it is kept beside it (an RK4 run
    takes hours): a run whose every cycle is there is read back, an unfinished one continues from its last
    finished cycle."""
    label = backend + ("-full" if full_pauses else "") + (f"-latency{latency:g}" if latency else "")
    done = _read_rows(rows_file, label, checkpoint, steps)
    if len(done) >= cycles:
        return {"probes": done[0]["probes"], "rows": done[:cycles], "unit": done[0]["unit"]}
    prog = cpu_run.load_program(program)
    options = {"steps_per_period": steps} if steps else {}
    options.update({"settle": None} if full_pauses else {})
    options["latency"] = latency                 # None: every gate integrated (not the engine's own default)
    cpu, wall0 = _resumed(rows_file, label, checkpoint, steps, done, backend, prog, options)
    if cpu is None:
        done, wall0 = [], 0.0
        cpu = _from_checkpoint(checkpoint, prog, backend, options, full_pauses)
    log: list = []
    _recording(cpu.pulse_engine, log)
    if cpu.pause_engine is not cpu.pulse_engine:
        _recording(cpu.pause_engine, log)
    rows, t0 = list(done), time.perf_counter() - wall0
    while len(rows) < cycles:
        rec = cpu.step()
        rows.append({"cycle": rec.cycle, "instr": rec.instr, "registers": cpu.registers(),
                     "amp": log[-1], "simulated": cpu.simulated, "wall_s": time.perf_counter() - t0})
        _append_row(rows_file, label, checkpoint, steps, rows[-1], cpu.probes, 1.0 / cpu.p.u_r)
        _keep_state(rows_file, label, checkpoint, steps, cpu, prog, rows[-1]["wall_s"])
        print(f"{label}: cycle {rec.cycle} done, {cpu.simulated} periods, {rows[-1]['wall_s']:.0f} s",
              file=sys.stderr, flush=True)
    return {"probes": cpu.probes, "rows": rows, "unit": 1.0 / cpu.p.u_r}


def _from_checkpoint(checkpoint, prog, backend, options, full_pauses):
    """A `backend` processor holding the carrier checkpoint's state (x, v: the same for every engine)."""
    state = cpu_run.read_checkpoint(checkpoint, prog, "carrier")
    cpu = make_cpu("carrier", cpu_run.make_memory(prog), power_up=False, latency=options.get("latency"),
                   **({"settle": None} if full_pauses else {}))
    cpu_run._restore(cpu, state, checkpoint)
    if backend != cpu.backend:
        other = make_cpu(backend, cpu_run.make_memory(prog), power_up=False, **options)
        other.mem = cpu.mem
        other.state, other.period, other.rdata, other.cycle, other.amps = \
            cpu.state, cpu.period, cpu.rdata, cpu.cycle, cpu.amps
        cpu = other
    cpu.simulated = 0                                        # periods integrated from here on
    return cpu


def _kept_checkpoint(rows_file, label, steps) -> Path:
    return Path(f"{rows_file}.{label}-{steps}.ckpt.json")


def _keep_state(rows_file, label, checkpoint, steps, cpu, prog, wall_s) -> None:
    """The machine after its last finished cycle, as a `cpu run` checkpoint beside the rows (atomic)."""
    if rows_file is None:
        return
    cpu_run.save_checkpoint(cpu, _kept_checkpoint(rows_file, label, steps), prog, cpu.backend,
                            {"wall_s_total": wall_s, "cpu_s_total": 0.0, "origin": checkpoint})


def _resumed(rows_file, label, checkpoint, steps, done, backend, prog, options):
    """(the machine after the last finished cycle, wall seconds so far), or (None, 0) to start over."""
    path = _kept_checkpoint(rows_file, label, steps)
    if rows_file is None or not done or not path.exists():
        return None, 0.0
    state = cpu_run.read_checkpoint(path, prog, backend)
    if state.get("origin") != checkpoint or state["cycle"] != done[-1]["cycle"] + 1:
        return None, 0.0
    cpu = make_cpu(backend, cpu_run.make_memory(prog), power_up=False, **options)
    cpu_run._restore(cpu, state, path)
    print(f"{label}: continuing after cycle {cpu.cycle - 1} ({len(done)} cycles kept)", file=sys.stderr, flush=True)
    return cpu, float(state["wall_s_total"])


def _append_row(path, label, checkpoint, steps, row, probes, unit) -> None:
    if path is None:
        return
    line = {**row, "amp": [row["amp"].real.tolist(), row["amp"].imag.tolist()], "backend": label,
            "checkpoint": checkpoint, "steps": steps, "probes": probes, "unit": unit}
    with open(path, "a") as f:
        f.write(strict_json(line) + "\n")
        f.flush()


def _read_rows(path, label, checkpoint, steps) -> list[dict]:
    """The consecutive cycles of one run (backend, checkpoint, steps) that `path` holds (a cycle written
    twice, by a run started over, once: the runs are deterministic)."""
    rows = {}
    try:
        lines = open(path).read().splitlines() if path else []
    except FileNotFoundError:
        return []
    for text in lines:
        try:
            r = json.loads(text)
        except json.JSONDecodeError:                     # a line cut by an interrupted write
            continue
        if (r["backend"], r["checkpoint"], r["steps"]) == (label, checkpoint, steps):
            r["amp"] = np.array(r["amp"][0]) + 1j * np.array(r["amp"][1])
            rows[r["cycle"]] = r
    out = []
    for k in sorted(rows):
        if out and k != out[-1]["cycle"] + 1:
            break
        out.append(rows[k])
    return out


def compare(a: dict, b: dict) -> list[dict]:
    """Per cycle: the largest |A| difference (u_R) and phase difference (deg, where |A| > 0.1 u_R)."""
    out = []
    for x, y in zip(a["rows"], b["rows"]):
        ax, ay = x["amp"] * a["unit"], y["amp"] * b["unit"]
        d = agreement(ay, ax, 1.0, floor=0.1)
        out.append({"cycle": x["cycle"], "instr": x["instr"], "registers_equal": x["registers"] == y["registers"],
                    "amp_diff": d.amp, "phase_diff_deg": d.phase_deg})
    return out


def merge(rows_files: list[str], steps: int = 160, base: dict | None = None) -> dict:
    """One comparison over every cycle that both engines finished in `rows_files` (each run's rows, any
    checkpoint), in the JSON layout of a single run; `base`'s settle-vs-full fields are kept."""
    out = {"checkpoint": [], "steps": steps, "cycles": [], "carrier_wall_s": 0.0, "rk4_wall_s": 0.0,
           "carrier_periods": 0, "rk4_periods": 0}
    for path in rows_files:
        starts = {json.loads(line)["checkpoint"] for line in open(path) if line.startswith("{")
                  and line.rstrip().endswith("}")}
        for ck in sorted(starts):
            car, rk = _read_rows(path, "carrier", ck, None), _read_rows(path, "rk4", ck, steps)
            n = min(len(car), len(rk))
            if not n:
                continue
            out["checkpoint"].append(f"{Path(ck).name} ({n} cycles)")
            out["cycles"] += compare({"rows": car[:n], "unit": car[0]["unit"]}, {"rows": rk[:n], "unit": rk[0]["unit"]})
            out["carrier_wall_s"] += car[n - 1]["wall_s"]
            out["rk4_wall_s"] += rk[n - 1]["wall_s"]
            out["carrier_periods"] += car[n - 1]["simulated"]
            out["rk4_periods"] += rk[n - 1]["simulated"]
    out["checkpoint"] = " and ".join(out["checkpoint"])
    kept = ("settle_vs_full", "full_wall_s", "full_periods", "settle_periods")
    return {**out, **{k: base[k] for k in kept if base and k in base}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("checkpoint", nargs="?", help="a `cpu run --backend carrier --checkpoint` file")
    ap.add_argument("--merge", action="append", metavar="ROWS", help="no run: one comparison over every cycle "
                    "both engines finished in these --rows files (repeatable), written to --out")
    ap.add_argument("--base", default=None, help="with --merge: an earlier comparison whose settle-vs-full "
                    "fields are kept")
    ap.add_argument("--program", default=None, help="the program (default: the shipped sieve)")
    ap.add_argument("--cycles", type=int, default=3)
    ap.add_argument("--steps", type=int, default=160, help="RK4 steps per period (default 160; 0: no RK4 run)")
    ap.add_argument("--out", default=None, help="write the comparison as JSON")
    ap.add_argument("--rows", default=None, help="append each finished cycle to this JSON-lines file; "
                    "a run already complete there is read back, not run again")
    ap.add_argument("--full-pauses", action="store_true", help="also the carrier without idle skipping: what "
                    "ending pauses early costs")
    ap.add_argument("--latency", type=float, action="append", metavar="TOL", help="no RK4 run: the carrier with "
                    "per-gate latency at TOL u_R (repeatable) against the carrier with full pauses and with idle "
                    "skipping alone")
    args = ap.parse_args(argv)
    if args.out:                                   # refused before hours of integration, not after
        from ..inputs import check_output_file
        read = [("the checkpoint", args.checkpoint), ("the program", args.program), ("the --rows file", args.rows),
                ("the --base file", args.base), *(("a --merge file", m) for m in args.merge or ())]
        check_output_file(args.out, read, "comparison")
    if args.merge:
        base = json.loads(Path(args.base).read_text()) if args.base else None
        return _write(merge(args.merge, args.steps, base), args.out)
    if not args.checkpoint:
        ap.error("give a checkpoint, or --merge ROWS")
    from ..backends.carrier import CarrierOptions
    for tol in args.latency or ():                 # refused before hours of integration, not after
        CarrierOptions(latency=tol).validate()
    from .. import data
    program = args.program or str(data.program("sieve.asm"))
    carrier = continue_cycles(args.checkpoint, program, "carrier", args.cycles, None, rows_file=args.rows)
    if args.latency:
        return _write(_latency_check(args, program, carrier), args.out)
    res = {"checkpoint": args.checkpoint, "steps": args.steps,
           "carrier_wall_s": carrier["rows"][-1]["wall_s"], "carrier_periods": carrier["rows"][-1]["simulated"]}
    if args.steps:
        rk4 = continue_cycles(args.checkpoint, program, "rk4", args.cycles, args.steps, rows_file=args.rows)
        res.update(cycles=compare(carrier, rk4), rk4_wall_s=rk4["rows"][-1]["wall_s"],
                   rk4_periods=rk4["rows"][-1]["simulated"])
    if args.full_pauses:
        full = continue_cycles(args.checkpoint, program, "carrier", args.cycles, None, full_pauses=True,
                               rows_file=args.rows)
        res["settle_vs_full"] = compare(carrier, full)
        res["full_wall_s"], res["full_periods"] = full["rows"][-1]["wall_s"], full["rows"][-1]["simulated"]
    return _write(res, args.out)


def _latency_check(args, program: str, carrier: dict) -> dict:
    """The carrier with per-gate latency at each --latency threshold, cycle by cycle against the carrier
    with full pauses (the reference) and with idle skipping alone (what latency adds to it)."""
    full = continue_cycles(args.checkpoint, program, "carrier", args.cycles, None, full_pauses=True,
                           rows_file=args.rows)
    res = {"checkpoint": args.checkpoint, "full_wall_s": full["rows"][-1]["wall_s"],
           "full_periods": full["rows"][-1]["simulated"], "settle_wall_s": carrier["rows"][-1]["wall_s"],
           "settle_periods": carrier["rows"][-1]["simulated"], "settle_vs_full": compare(carrier, full),
           "latency": []}
    for tol in args.latency:
        lat = continue_cycles(args.checkpoint, program, "carrier", args.cycles, None, rows_file=args.rows,
                              latency=tol)
        res["latency"].append({"tol": tol, "wall_s": lat["rows"][-1]["wall_s"],
                               "periods": lat["rows"][-1]["simulated"], "vs_full": compare(lat, full),
                               "vs_settle": compare(lat, carrier)})
    return res


def _write(res: dict, out: str | None) -> int:
    text = strict_json(res, indent=2)
    if out:
        write_text(out, text)
    print(text)
    return 0


if __name__ == "__main__":
    from ..errors import Mech2SpiceError
    try:
        sys.exit(main())
    except Mech2SpiceError as err:                # bad input: one line, exit 2
        print(f"processor_check: error: {err}", file=sys.stderr)
        sys.exit(2)
