"""Issue #38: what the verdict costs at the least, against the quarter of the run it was asked to fit in.

The verdict is Newton's fixed point, then the sign and size of the rightmost eigenvalue there (docs/stability.md).
For each of the issue's three targets this measures, in one process and the same minutes, the run and the parts
no verdict of that method can do without:

- the adder, its 16 inputs in one batch (envelope): the run's share of one member, Newton's calls, and the
  whole spectrum of one member (`_dense_modes`; the eigenvalues of a 204 x 204 matrix alone timed apart), beside
  the sparse search on the same member;
- c880 and c6288 (ispras/hdl-benchmarks, the seeded random vector of verdict_scale.py; c880 for scale), and the
  processor's cycles (programs/sieve.asm on the envelope, the states after cycles FIRST..LAST): one operator
  product of the search (the solve by nets the verdict uses, median of 30), the checked search from a flat start
  with every product counted and its solves timed apart from ARPACK's own work, and (the processor) the same
  search from the previous cycle's vectors, as `--stability cycle` starts it.

From these: the quarter's budget in seconds, the products it would pay for if the search did nothing but solve
(`products_affordable`), and the products the search needed (`products_needed`).

Usage:  MECH2SPICE_BENCHMARKS=DIR OMP_NUM_THREADS=1 python scripts/verdict_floor.py [--first 21 --last 24]
                                                                  [--out reports/verdict_floor.json] [--render]
(the figure beside the JSON, reports/verdict_floor.png; `--render` redraws it from the JSON alone)
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
import scipy.linalg as sla
import scipy.sparse.linalg as spla

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from mech2spice.experiments.scenes import ADDER_INPUTS  # noqa: E402
from mech2spice.physics import insulators, stability  # noqa: E402
from mech2spice.synthesis.synth import synthesize  # noqa: E402

_spec = importlib.util.spec_from_file_location("verdict_scale", REPO / "scripts/verdict_scale.py")
scale = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(scale)


def _median_s(call, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        call()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def counted_search(E, J, T: float, nets, start=None) -> dict:
    """The verdict's checked search (_cayley_checked) with its products counted and their solves timed."""
    sigma = 2 * np.pi / (50 * T)
    solve = stability._shifted_solver(E, J, sigma, nets)
    count, spent = [0], [0.0]

    def timed_solve(b):
        t0 = time.perf_counter()
        out = solve(b)
        spent[0] += time.perf_counter() - t0
        count[0] += 1
        return out
    inner = stability._shifted_solver
    stability._shifted_solver = lambda *args, **kwargs: timed_solve
    try:
        t0 = time.perf_counter()
        lam, vec = stability._cayley_checked(E, J, sigma, stability.MODES, start, T, nets)
        total = time.perf_counter() - t0
    finally:
        stability._shifted_solver = inner
    K = (J + sigma * E).tocsr()
    b = np.random.default_rng(0).standard_normal(J.shape[0])
    return {"products": count[0], "seconds": total, "solve_s": spent[0], "arpack_own_s": total - spent[0],
            "product_s": _median_s(lambda: solve(K @ b), 30), "growth": float(lam.real.max() * T),
            "folded": np.real(vec).sum(axis=1) + np.imag(vec).sum(axis=1)}


def _without_folded(search: dict) -> dict:
    return {k: v for k, v in search.items() if k != "folded"}


def budget(run_s: float, product_s: float) -> dict:
    quarter = 0.25 * run_s
    return {"quarter_s": quarter, "products_affordable": int(quarter / product_s)}


def adder() -> dict:
    """The adder's batch: the run and Newton from the verdict's own parts; one member's spectrum timed alone."""
    nl = synthesize(str(REPO / "verilog/adder2.v"))
    vectors = list(ADDER_INPUTS)
    scale._run(nl, vectors, "envelope", 600)                # the kernels' first compilation is no run's cost
    run = scale._run(nl, vectors, "envelope", 600)
    fp = dict(scale._LAST_FIXED_POINT)
    E, J = stability.linearise(fp["env"], fp["A"], fp["s"])
    M = spla.splu(E.tocsc()).solve(J.toarray())
    T = fp["env"].model.period
    member = run["run_s"] / len(vectors)
    row = {"design": "adder x16", "batch": len(vectors), "unknowns": J.shape[0], "run_s": run["run_s"],
           "periods": run["periods"], "verdict_s": run["verdict_s"], "parts": run["parts"], "member_run_s": member,
           "dense_modes_s": _median_s(lambda: stability._dense_modes(fp["env"], E, J, stability.MODES), 7),
           "eigenvalues_alone_s": _median_s(lambda: sla.eigvals(M, check_finite=False), 7),
           "sparse_search": _without_folded(counted_search(E, J, T, insulators.fast_nets(fp["env"]))),
           "quarter_s": 0.25 * member}
    print(f"adder: {json.dumps(row)}", flush=True)
    return row


def combinational(name: str) -> dict:
    """An ISCAS-85 circuit on verdict_scale.py's seeded vector: the run, then the search at its final fixed point."""
    nl = synthesize(str(scale.BENCH / f"{name}.v"), top=name)
    run = scale._run(nl, scale._vectors(name, nl, 1), "envelope", 900)
    fp = dict(scale._LAST_FIXED_POINT)
    E, J = stability.linearise(fp["env"], fp["A"], fp["s"])
    search = counted_search(E, J, fp["env"].model.period, insulators.fast_nets(fp["env"]))
    row = {"design": name, "unknowns": J.shape[0], "run_s": run["run_s"], "periods": run["periods"],
           "verdict_s": run["verdict_s"], "parts": run["parts"], "valid": run["valid"],
           "search": _without_folded(search), **budget(run["run_s"], search["product_s"]),
           "products_needed": search["products"]}
    print(f"{name}: {json.dumps(row)}", flush=True)
    return row


def processor(first: int, last: int) -> dict:
    """The sieve's cycles: the plain run's CPU-s a cycle (the whole sieve's mean); Newton's CPU-s a verdict (the
    searches stubbed while the judged run records its fixed points); then each recorded state searched cold and warm."""
    from mech2spice.cpu.run import run_program
    sieve = REPO / "programs/sieve.asm"
    run_program(sieve, "envelope", max_cycles=2)            # the clocked kernels' first compilation
    plain = run_program(sieve, "envelope")                   # to the halt: a cycle's mean share of the sieve
    states, parts = [], {}

    def recorded(env, A, s, k=stability.MODES, start=None, method="fast"):
        states.append((env, A.copy(), s.copy()))
        return [stability.Mode(-1e-3, None)], None
    inner_modes, inner_newton = stability.leading_modes, stability.operating_point

    def newton(*args, **kwargs):              # CPU seconds, as the run's
        t0 = time.process_time()
        out = inner_newton(*args, **kwargs)
        parts["newton_s"] = parts.get("newton_s", 0.0) + time.process_time() - t0
        parts["newton_calls"] = parts.get("newton_calls", 0) + 1
        return out
    stability.leading_modes, stability.operating_point = recorded, newton
    try:
        run_program(sieve, "envelope", max_cycles=last, stability="cycle")
    finally:
        stability.leading_modes, stability.operating_point = inner_modes, inner_newton
    cycle_s = plain["cpu_s_total"] / plain["cycles"]
    rows, previous = [], None
    for cycle in range(first, last + 1):
        env, A, s = states[cycle - 1]
        E, J = stability.linearise(env, A, s)
        nets, T = insulators.fast_nets(env), env.model.period
        cold = counted_search(E, J, T, nets)
        warm = counted_search(E, J, T, nets, start=previous) if previous is not None else None
        previous = cold["folded"]
        rows.append({"cycle": cycle, "cold": _without_folded(cold), "warm": warm and _without_folded(warm)})
        print(f"processor cycle {cycle}: {json.dumps(rows[-1])}", flush=True)
    product_s = float(np.median([r["cold"]["product_s"] for r in rows]))
    needed = [r["warm"]["products"] for r in rows if r["warm"]] or [r["cold"]["products"] for r in rows]
    return {"design": "processor cycle (CPU-s)", "unknowns": J.shape[0], "cycles": plain["cycles"],
            "cycle_run_cpu_s": cycle_s, "newton_s_per_verdict": parts["newton_s"] / parts["newton_calls"],
            "newton_calls": parts["newton_calls"], "rows": rows, **budget(cycle_s, product_s),
            "product_s": product_s, "products_needed": int(min(needed)),
            "products_needed_median": float(np.median(needed))}


def floors(row: dict) -> dict:
    """Seconds of one target's run, its quarter, Newton, the search's products alone and the whole search (the
    adder: one member's share of the batch, with the dense spectrum as its search)."""
    if row["design"].startswith("adder"):
        parts = row["parts"]
        return {"run": row["member_run_s"], "quarter": row["quarter_s"],
                "Newton": parts["newton_s"] / row["batch"],
                "products alone": row["sparse_search"]["solve_s"], "search": row["dense_modes_s"]}
    if "rows" in row:
        warm = [r["warm"] for r in row["rows"] if r["warm"]]
        return {"run": row["cycle_run_cpu_s"], "quarter": row["quarter_s"], "Newton": row["newton_s_per_verdict"],
                "products alone": float(np.median([w["solve_s"] for w in warm])),
                "search": float(np.median([w["seconds"] for w in warm]))}
    return {"run": row["run_s"], "quarter": row["quarter_s"], "Newton": row["parts"]["newton_s"],
            "products alone": row["search"]["solve_s"], "search": row["search"]["seconds"]}


LABELS = {"run": "the run (a member's, a cycle's share)", "quarter": "a quarter of it (the issue's budget)",
          "Newton": "Newton's fixed point", "products alone": "the search's solves alone (no ARPACK work)",
          "search": "the whole search (the adder: its dense spectrum)"}


def render(doc: dict, path: Path) -> None:
    """One row of bars per target, log seconds: what the quarter allows against what the verdict's parts cost."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    rows = doc["designs"]
    keys = ["run", "quarter", "Newton", "products alone", "search"]
    colours = ["tab:blue", "tab:green", "tab:orange", "tab:red", "tab:purple"]
    fig, ax = plt.subplots(figsize=(7.6, 1.8 + 1.1 * len(rows)))
    height = 0.8 / len(keys)
    for i, row in enumerate(rows):
        f = floors(row)
        for j, (key, colour) in enumerate(zip(keys, colours)):
            ax.barh(i + (j - 2) * height, f[key], height, color=colour, label=LABELS[key] if i == 0 else None)
    names = {"adder x16": "adder, one member\n(of a 16-input batch)", "processor cycle (CPU-s)":
             "processor, one cycle\n(warm search, CPU-s)"}
    ax.set_yticks(range(len(rows)), [names.get(r["design"], r["design"]) for r in rows])
    ax.invert_yaxis()
    ax.set_xscale("log")
    ax.set_xlabel("seconds (one process, envelope, OMP_NUM_THREADS=1)")
    ax.set_title(f"The verdict's parts against a quarter of the run ({doc['conditions']['date']})", fontsize=9)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.4, -0.14), ncol=2)
    ax.grid(True, axis="x", which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--first", type=int, default=21)
    ap.add_argument("--last", type=int, default=24)
    ap.add_argument("--only", default="adder,c880,c6288,processor")
    ap.add_argument("--out", default=str(REPO / "reports/verdict_floor.json"))
    ap.add_argument("--render", action="store_true", help="only the figure (reports/verdict_floor.png) from --out")
    args = ap.parse_args()
    figure = Path(args.out).with_suffix(".png")
    if args.render:
        render(json.loads(Path(args.out).read_text()), figure)
        return 0
    conditions = {"machine": platform.processor() or platform.machine(), "cpus": os.cpu_count(),
                  "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
                  "omp_threads": os.environ.get("OMP_NUM_THREADS"), "load_before": os.getloadavg()[0]}
    scale._record_fixed_points()
    only = set(args.only.split(","))
    rows = []
    if "adder" in only:
        rows.append(adder())
    for name in ("c880", "c6288"):
        if name in only and (scale.BENCH / f"{name}.v").is_file():
            rows.append(combinational(name))
    if "processor" in only:
        rows.append(processor(args.first, args.last))
    conditions["load_after"] = os.getloadavg()[0]
    doc = {"conditions": conditions, "designs": rows}
    Path(args.out).write_text(json.dumps(doc, indent=1) + "\n")
    render(doc, figure)
    print(f"wrote {args.out} and {figure}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
