"""Issue #38: the stability verdict's time against the run's own, from the 2-bit adder to ISCAS-85 c6288.

For each design: synthesise it, pick one seeded random input vector (the adder: all 16 inputs in one batch), run
`simulation.run_physical` on the envelope at the defaults (the verdict's `fast` path), and record the wall time,
the verdicts' part of it (`verdict_s`), the periods, valid / stable / settled, the leading growth rate, and
whether the outputs equal the logic backend's.  The adder is also run with the verdict's `reference` path
(the dense generalised eigenproblem with every vector, no cache: the verdict before #38) and on RK4, in the same
process, so the ratios are measured under the same load.  ISCAS-85 netlists are not in the repository: put them
in $MECH2SPICE_BENCHMARKS/iscas85/ (c432_hansen.v: Mark C. Hansen's high-level model, from
github.com/msabrishami/DFT data/netlist_behavioral/c432.v at ed00832d; c880.v, c1355.v, c6288.v: ispras/
hdl-benchmarks iscas85/verilog/).  A design whose run exceeds --limit seconds is recorded as timed out.
Each run also records its verdicts' parts (`parts`: Newton's calls, seconds and fixed points not found; the
eigenvalue searches' calls and seconds), each design's `searches` (the sparse search alone at the run's final
fixed point, as before the second session of #38 and as now, timed in the same minute) and whether the logic
backend equals Icarus Verilog on the same vectors (`logic_equals_icarus`).

Usage:  OMP_NUM_THREADS=1 nice -n 5 python scripts/verdict_scale.py [--only adder,c432] [--limit 600] [--no-rk4]
                                                  [--processor CYCLES] [--out reports/verdict_scale]
Writes <out>.json and <out>.png (verdict and run seconds against the linearisation's unknowns) and prints the
table of docs/stability.md (--render: the table of an existing <out>.json, nothing measured).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import random
import signal
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from mech2spice import simulation  # noqa: E402
from mech2spice.experiments.scenes import ADDER_INPUTS  # noqa: E402
from mech2spice.physics import network, params, stability  # noqa: E402
from mech2spice.physics.envelope import Envelope  # noqa: E402
from mech2spice.synthesis.synth import synthesize  # noqa: E402

BENCH = Path(os.environ.get("MECH2SPICE_BENCHMARKS", REPO / "benchmarks")) / "iscas85"
DESIGNS = [("adder", REPO / "verilog/adder2.v", None), ("c432", BENCH / "c432_hansen.v", "Circuit432"),
           ("c880", BENCH / "c880.v", "c880"), ("c1355", BENCH / "c1355.v", "c1355"),
           ("c6288", BENCH / "c6288.v", "c6288")]


class TimedOut(Exception):
    pass


def _alarm(signum, frame):
    raise TimedOut


def _vectors(name: str, nl, seed: int) -> list[dict]:
    if name == "adder":
        return list(ADDER_INPUTS)
    rng = random.Random(seed)
    return [{p: rng.getrandbits(w) for p, w in nl.inputs.items()}]


def _unknowns(nl) -> tuple[int, int]:
    """(oscillators, real unknowns of the linearisation: 2 per oscillating DOF, 2 per insulator)."""
    env = Envelope.of(network.build(nl, params.DEFAULT))
    return env.model.n, 2 * env.fast.size + 2 * env.slow.size


def _run(nl, vectors, backend: str, limit: int) -> dict:
    """One run_physical call, summarised over its batch (None-valued fields when it timed out)."""
    signal.alarm(limit)
    _PARTS.clear()
    t0 = time.perf_counter()
    try:
        res = simulation.run_physical(nl, params.DEFAULT, vectors, backend)
    except TimedOut:
        return {"backend": backend, "timed_out": True, "wall_s": time.perf_counter() - t0}
    finally:
        signal.alarm(0)
    wall = time.perf_counter() - t0
    logic = [simulation.run_logic(nl, v)["outputs"] for v in vectors]
    growth = [r["stability"]["growth_rate"] for r in res if r.get("stability", {}).get("growth_rate") is not None]
    return {"backend": backend, "timed_out": False, "wall_s": wall, "verdict_s": res[0]["verdict_s"],
            "run_s": wall - res[0]["verdict_s"], "periods": res[0]["periods"], "batch": len(vectors),
            "valid": all(r["valid"] for r in res), "stable": all(r.get("stable", True) for r in res),
            "settled": all(r.get("settled", True) for r in res),
            "equal_to_logic": all(r["outputs"] == want for r, want in zip(res, logic)),
            "growth_rate_max": max(growth) if growth else None, "parts": dict(_PARTS)}


_LAST_FIXED_POINT = {}
_PARTS = {}


def _record_fixed_points() -> None:
    """Keep the last fixed point a verdict searched (for `searches`), and count the verdicts' parts for
    `_run`: Newton's calls (and how many found no fixed point) and seconds, the eigenvalue searches' calls and
    seconds (a cached spectrum is no search).  Wraps stability's functions."""
    inner_modes, inner_newton, inner_leading = stability._cached_modes, stability.operating_point, \
        stability.leading_modes

    def modes(env, A, s, converged, start, method):
        if converged:
            _LAST_FIXED_POINT.update(env=env, A=A, s=s)
        return inner_modes(env, A, s, converged, start, method)

    def timed(key, inner):
        def call(*args, **kwargs):
            t0 = time.perf_counter()
            out = inner(*args, **kwargs)
            _PARTS[key + "_s"] = _PARTS.get(key + "_s", 0.0) + time.perf_counter() - t0
            _PARTS[key + "_calls"] = _PARTS.get(key + "_calls", 0) + 1
            if key == "newton" and not out[2]:
                _PARTS["no_fixed_point"] = _PARTS.get("no_fixed_point", 0) + 1
            return out
        return call
    stability._cached_modes = modes
    stability.operating_point = timed("newton", inner_newton)
    stability.leading_modes = timed("search", inner_leading)


def searches(tight: bool) -> dict | None:
    """The sparse search alone at the last run's final fixed point, timed in the same minute: as it was before
    this session (ARPACK tolerance 1e-6, subspace 120) and now (_cayley_checked), each leading growth's error
    against a search converged to 1e-10 (`tight`; skipped on c6288, where it alone takes minutes)."""
    fp = _LAST_FIXED_POINT
    if not fp or 2 * fp["env"].fast.size + 2 * fp["env"].slow.size <= stability.DENSE_LIMIT:
        return None
    E, J = stability.linearise(fp["env"], fp["A"], fp["s"])
    T = fp["env"].model.period
    sigma = 2 * np.pi / (50 * T)
    out = {}
    for label, search in (("before", lambda: stability._cayley(E, J, sigma, stability.MODES,
                                                                ncv=stability.CAYLEY_NCV, tol=1e-6)),
                          ("checked", lambda: stability._cayley_checked(E, J, sigma, stability.MODES, None, T))):
        t0 = time.perf_counter()
        lam, _ = search()
        out[label] = {"seconds": time.perf_counter() - t0, "growth": float(lam.real.max() * T)}
    if tight:
        lam, _ = stability._cayley(E, J, sigma, stability.MODES, ncv=stability.CAYLEY_NCV, tol=1e-10)
        for label in ("before", "checked"):
            out[label]["error"] = out[label]["growth"] - float(lam.real.max() * T)
    return out


def logic_equals_icarus(path: Path, nl, vectors: list[dict]) -> dict | None:
    """Whether the logic backend's output bits equal Icarus Verilog's on the source for each vector (None: no
    Icarus), so a run equal to the logic backend is equal to Icarus; bits Icarus leaves x or z (a port the
    source never drives: verify.icarus) are counted, not compared."""
    import shutil
    from mech2spice import verify
    if not shutil.which("iverilog"):
        return None
    order = verify.input_bits(nl)
    bit = lambda v, b: (v[b.split("[")[0]] >> int(b.split("[")[1][:-1])) & 1
    rows = verify.icarus(path, nl, np.array([[bit(v, b) for b in order] for v in vectors]), False)
    equal, undefined = True, 0
    for row, v in zip(rows, vectors):
        logic = simulation.run_logic(nl, v)["outputs"]
        for name, value in row.items():
            if value not in "01":
                undefined += 1
                continue
            port, i = name.split("[")[0], int(name.split("[")[1][:-1])
            equal &= (logic[port] >> i) & 1 == int(value)
    return {"equal": bool(equal), "undefined_bits": undefined}


def measure(name: str, path: Path, top: str | None, seed: int, limit: int, rk4: bool) -> dict:
    nl = synthesize(str(path), top=top)
    oscillators, unknowns = _unknowns(nl)
    vectors = _vectors(name, nl, seed)
    row = {"design": name, "source": str(path.relative_to(REPO) if path.is_relative_to(REPO) else path.name),
           "top": top, "oscillators": oscillators, "unknowns": unknowns, "vector": vectors if len(vectors) == 1 else
           "all 16 (a, b)", "logic_equals_icarus": logic_equals_icarus(path, nl, vectors),
           "fast": _run(nl, vectors, "envelope", limit)}
    print(f"{name}: {unknowns} unknowns, fast: {json.dumps(row['fast'])}", flush=True)
    if not row["fast"]["timed_out"]:
        row["searches"] = searches(tight=unknowns < 20000)
        _LAST_FIXED_POINT.clear()
        print(f"{name}: searches at the final fixed point: {json.dumps(row['searches'])}", flush=True)
    if name == "adder":                 # fast and reference alternated, twice each; the faster of each kept
        runs = {"fast": [row["fast"]], "reference": []}
        for method in ("reference", "fast", "reference"):
            stability.METHOD = method
            try:
                runs[method].append(_run(nl, vectors, "envelope", limit))
            finally:
                stability.METHOD = "fast"
        row.update({m: min(rs, key=lambda r: r["wall_s"]) for m, rs in runs.items()})
        row["walls_s"] = {m: [r["wall_s"] for r in rs] for m, rs in runs.items()}
        print(f"{name}: reference: {json.dumps(row['reference'])}; walls {row['walls_s']}", flush=True)
        if rk4:
            row["rk4"] = _run(nl, vectors, "rk4", limit)
            print(f"{name}: rk4: {json.dumps(row['rk4'])}", flush=True)
    return row


def measure_processor(cycles: int) -> dict:
    """The processor (programs/sieve.asm on the envelope): `cycles` cycles without and with a verdict after
    every cycle (`--stability cycle`), one after the other; CPU seconds are the comparable numbers on a shared
    machine.  run_s: the plain run's CPU-s; verdict_s: the judged run's CPU-s less the plain run's."""
    from mech2spice.cpu.run import run_program
    sieve = REPO / "programs/sieve.asm"
    plain = run_program(sieve, "envelope", max_cycles=cycles)
    judged = run_program(sieve, "envelope", max_cycles=cycles, stability="cycle")
    verdicts = judged.get("stability_cycles", [])
    run_s, with_s = plain["cpu_s_total"], judged["cpu_s_total"]
    fast = {"backend": "envelope", "timed_out": False, "wall_s": judged["wall_s_total"], "run_s": run_s,
            "verdict_s": with_s - run_s, "periods": judged["periods"], "batch": 1, "valid": True,
            "stable": bool(judged.get("stable")), "settled": True,
            "equal_to_logic": plain["iss_check"]["mismatches"] == 0 and judged["iss_check"]["mismatches"] == 0,
            "growth_rate_max": max(v["growth_rate"] for v in verdicts) if verdicts else None,
            "cpu_seconds": True, "cycles": cycles, "verdict_wall_s": [v["wall_s"] for v in verdicts]}
    oscillators = judged["model"]["oscillators"]
    row = {"design": f"processor ({cycles} cycles, CPU-s)", "source": "programs/sieve.asm", "top": None,
           "oscillators": oscillators, "unknowns": 2 * oscillators, "vector": "the sieve",
           "logic_equals_icarus": None, "fast": fast}
    print(f"processor: {json.dumps(fast)}", flush=True)
    return row


def plot(rows: list[dict], path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    done = [r for r in rows if not r["fast"]["timed_out"]]
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    x = [r["unknowns"] for r in done]
    ax.loglog(x, [r["fast"]["run_s"] for r in done], "o-", label="run (integration, settle loop)")
    ax.loglog(x, [r["fast"]["verdict_s"] for r in done], "s-", label="verdicts (fast path)")
    for r in done:
        ax.annotate(r["design"], (r["unknowns"], r["fast"]["verdict_s"]), textcoords="offset points", xytext=(4, 4))
    ref = [r for r in done if "reference" in r and not r["reference"]["timed_out"]]
    if ref:
        ax.loglog([r["unknowns"] for r in ref], [r["reference"]["verdict_s"] for r in ref], "x", ms=9,
                  label="verdicts (reference path)")
    for r in rows:
        if r["fast"]["timed_out"]:
            ax.axvline(r["unknowns"], ls=":", c="grey")
            ax.annotate(f"{r['design']}: > {r['fast']['wall_s']:.0f} s", (r["unknowns"], 1), rotation=90, fontsize=8)
    ax.set_xlabel("real unknowns of the linearised envelope equations")
    ax.set_ylabel("wall seconds (one process, envelope)")
    ax.legend(fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def table(rows: list[dict]) -> str:
    """The markdown table of docs/stability.md."""
    lines = ["| design | oscillators | unknowns | periods | run s | verdict s | verdict / run | "
             "valid, stable, = logic, logic = Icarus |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        for path in ("fast", "reference", "rk4"):
            m = r.get(path)
            if m is None:
                continue
            name = r["design"] + ("" if path == "fast" else f" ({path})") + (" x16" if m.get("batch", 1) > 1 else "")
            if m["timed_out"]:
                lines.append(f"| {name} | {r['oscillators']} | {r['unknowns']} | | | | timed out after "
                             f"{m['wall_s']:.0f} s | |")
                continue
            ic = r.get("logic_equals_icarus")
            icarus = "-" if ic is None else ("yes" if ic["equal"] else "no") + \
                (f" ({ic['undefined_bits']} bits z)" if ic["undefined_bits"] else "")
            ok = ", ".join(["yes" if m[k] else "no" for k in ("valid", "stable", "equal_to_logic")] + [icarus])
            lines.append(f"| {name} | {r['oscillators']} | {r['unknowns']} | {m['periods']} | {m['run_s']:.2f} | "
                         f"{m['verdict_s']:.2f} | {m['verdict_s'] / m['run_s']:.2f} | {ok} |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="", help="comma-separated design names (default: every one present)")
    ap.add_argument("--limit", type=int, default=600, help="seconds per run before it is recorded as timed out")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--no-rk4", action="store_true", help="skip the adder's RK4 run")
    ap.add_argument("--out", default=str(REPO / "reports/verdict_scale"))
    ap.add_argument("--render", action="store_true", help="print the table of <out>.json, measure nothing")
    ap.add_argument("--keep", action="store_true",
                    help="keep the rows of <out>.json this run does not measure (each row says when it was measured)")
    ap.add_argument("--processor", type=int, default=0, metavar="CYCLES",
                    help="also the sieve on the processor for CYCLES cycles, with and without a verdict per cycle")
    args = ap.parse_args()
    if args.render:
        print(table(json.loads(Path(args.out + ".json").read_text())["designs"]))
        return
    signal.signal(signal.SIGALRM, _alarm)
    _record_fixed_points()
    only = set(filter(None, args.only.split(",")))
    warm = synthesize(str(REPO / "verilog/adder2.v"))      # compile the engines' kernels before any timing
    simulation.run_physical(warm, params.DEFAULT, list(ADDER_INPUTS), "envelope", periods=200)
    if not args.no_rk4:
        simulation.run_physical(warm, params.DEFAULT, list(ADDER_INPUTS), "rk4", periods=10)
    rows = []
    for name, path, top in DESIGNS:
        if (only and name not in only) or not path.is_file():
            continue
        rows.append(measure(name, path, top, args.seed, args.limit, not args.no_rk4))
    if args.processor:
        rows.append(measure_processor(args.processor))
    conditions = {"machine": platform.node(), "python": platform.python_version(),
                  "load_before": os.getloadavg(), "omp_num_threads": os.environ.get("OMP_NUM_THREADS"),
                  "cayley_ncv": stability.CAYLEY_NCV, "dense_limit": stability.DENSE_LIMIT,
                  "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
    for r in rows:
        r["measured"] = {"date": conditions["date"], "load_before": conditions["load_before"]}
    if args.keep and Path(args.out + ".json").is_file():
        old = json.loads(Path(args.out + ".json").read_text())
        done = {r["design"] for r in rows}
        kept = [{"measured": {k: old["conditions"][k] for k in ("date", "load_before")}, **r}
                for r in old["designs"] if r["design"] not in done]
        rows = sorted(kept + rows, key=lambda r: r["unknowns"])
    out = {"conditions": conditions, "designs": rows}
    Path(args.out + ".json").write_text(json.dumps(out, indent=1) + "\n")
    plot(rows, Path(args.out + ".png"))
    print(table(rows))
    print(f"wrote {args.out}.json and {args.out}.png")


if __name__ == "__main__":
    main()
