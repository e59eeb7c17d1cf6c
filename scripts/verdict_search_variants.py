"""Issue #38: variants of the sparse eigenvalue search, measured in operator products (sparse solves) and seconds.

The verdict's sparse path (physics/stability.py, `_cayley_checked`) runs ARPACK on the Cayley transform with a
subspace of 120 vectors, k = 6 modes, tolerance 1e-4 then checked.  Here, at fixed points the runs reach:

- c880 (ispras/hdl-benchmarks, seeded random vector as scripts/verdict_scale.py): the subspace (60, 120), k (2, 6),
  the tolerance (1e-4, 1e-3, 1e-2: the error of the leading growth rate against a 1e-10 search), a start vector
  built from each gate's own rightmost mode (the 20 or 100 least damped gates, from 12 x 12 dense problems), and
  complex shift-and-invert at the least damped gate's own eigenvalue moved right by 0.5e-3 to 2e-3 per period;
- the processor (the sieve on the envelope, states after cycles 30-36, the searches stubbed while the run
  records them): each state cold (a flat start) and warm (from the previous state's six eigenvectors folded
  into one vector, as `cpu run --stability cycle` does), and cold with a 60-vector subspace.

- the search's solve (J - sigma E) x = b as the verdict now does it, the oscillators eliminated net by net and
  only the insulators' Schur complement factorised (stability._shifted_solver), against one sparse LU of the
  whole: the time of one product and of the whole checked search, alternated twice, on c880, the processor after
  cycle 21 and c6288 (`--solves`: this part alone, into "solves").

Usage:  OMP_NUM_THREADS=1 python scripts/verdict_search_variants.py [--solves]
                                                           [--out reports/verdict_search_variants.json]
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

from mech2spice.physics import insulators, params, stability  # noqa: E402

_spec = importlib.util.spec_from_file_location("verdict_structure", REPO / "scripts/verdict_structure.py")
vs = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(vs)


class Search:
    """ARPACK on the Cayley transform at one linearisation, counting operator products."""

    def __init__(self, E, J, T: float):
        self.E, self.J, self.T = E.tocsr(), J.tocsr(), T
        self.sigma = 2 * np.pi / (50 * T)
        self.lu = spla.splu((J - self.sigma * E).tocsc())
        self.K = (J + self.sigma * E).tocsr()

    def cayley(self, start=None, k=6, ncv=120, tol=1e-4) -> dict:
        n = self.J.shape[0]
        count = [0]

        def product(x):
            count[0] += 1
            return self.lu.solve(self.K @ x)
        t = time.perf_counter()
        mu, vec = spla.eigs(spla.LinearOperator(self.J.shape, matvec=product, dtype=float), k=k, which="LM",
                            tol=tol, ncv=min(ncv, n - 1), v0=np.ones(n) if start is None else start, maxiter=20 * n)
        lam = self.sigma * (mu + 1) / (mu - 1)
        return {"products": count[0], "seconds": time.perf_counter() - t, "growth": float(lam.real.max() * self.T),
                "folded": np.real(vec).sum(axis=1) + np.imag(vec).sum(axis=1)}

    def shift_invert(self, shift: complex, k=6, ncv=30) -> dict:
        n = self.J.shape[0]
        t = time.perf_counter()
        lu = spla.splu((self.J - shift * self.E).tocsc().astype(complex))
        count = [0]

        def product(x):
            count[0] += 1
            return lu.solve(self.E @ x)
        nu, _ = spla.eigs(spla.LinearOperator(self.J.shape, matvec=product, dtype=complex), k=k, which="LM",
                          tol=1e-8, ncv=ncv, v0=np.ones(n, complex), maxiter=20 * n)
        lam = shift + 1 / nu
        return {"products": count[0], "seconds": time.perf_counter() - t, "growth": float(lam.real.max() * self.T)}


def gate_modes(env, E, J):
    """Each gate's own rightmost eigenvalue and vector (its 12 unknowns, the rest held), least damped first."""
    nf, ns = env.fast.size, env.slow.size
    E, J = E.tocsr(), J.tocsr()
    idx = {}
    for k, d in enumerate(env.fast):
        idx.setdefault(env.model.names[d].split(".")[0], []).extend([k, nf + k])
    for k, d in enumerate(env.slow):
        idx.setdefault(env.model.names[d].split(".")[0], []).extend([2 * nf + k, 2 * nf + ns + k])
    out = []
    for gate, rows in idx.items():
        rows = np.array(rows)
        lam, vec = sla.eig(J[rows][:, rows].toarray(), E[rows][:, rows].toarray())
        ok = np.isfinite(lam)
        if ok.any():
            i = np.flatnonzero(ok)[np.argmax(lam[ok].real)]
            out.append((lam[i], rows, vec[:, i], gate))
    return sorted(out, key=lambda m: -m[0].real)


def start_from(modes, n: int, top: int) -> np.ndarray:
    v = np.zeros(n)
    for _, rows, vec, _ in modes[:top]:
        v[rows] += np.real(vec) + np.imag(vec)
    return v


def c880() -> dict:
    path = vs.BENCH / "c880.v"
    run, _ = vs.combinational(path, "c880", params.DEFAULT)
    env, A, s = vs.recorded_fixed_points(run)[-1]
    E, J = stability.linearise(env, A, s)
    T = env.model.period
    search = Search(E, J, T)
    exact = search.cayley(tol=1e-10)["growth"]
    rows = []

    def add(label, r):
        r.pop("folded", None)
        rows.append({"variant": label, **r, "error": r["growth"] - exact})
        print(f"c880 {label}: {json.dumps(rows[-1])}", flush=True)
    for k, ncv, tol in ((6, 120, 1e-4), (6, 60, 1e-4), (2, 20, 1e-4), (6, 120, 1e-3), (2, 40, 1e-2)):
        add(f"flat start, k={k}, subspace {ncv}, tol {tol:g}", search.cayley(k=k, ncv=ncv, tol=tol))
    modes = gate_modes(env, E, J)
    for top in (20, 100):
        for ncv in (120, 60):
            add(f"start from the {top} least damped gates' modes, subspace {ncv}",
                search.cayley(start_from(modes, J.shape[0], top), ncv=ncv))
    own = modes[0][0]
    for offset in (0.5e-3, 1e-3, 2e-3):
        add(f"shift-invert at the least damped gate's mode + {offset:g}/period",
            search.shift_invert(complex(own.real + offset / T, abs(own.imag))))
    return {"design": "c880", "unknowns": J.shape[0], "growth_1e-10": exact,
            "least_damped_gate": {"gate": modes[0][3], "growth": float(own.real * T)}, "rows": rows}


def recorded_states(run) -> list:
    """run() with each verdict's fixed point recorded and its search stubbed out: [(env, A, s)]."""
    states = []
    inner = stability.leading_modes

    def recorded(env, A, s, k=stability.MODES, start=None, method="fast"):
        states.append((env, A.copy(), s.copy()))
        return [stability.Mode(-1e-3, None)], None
    stability.leading_modes = recorded
    try:
        run()
    finally:
        stability.leading_modes = inner
    return states


def sieve_states(last: int) -> list:
    from mech2spice.cpu.run import run_program
    return recorded_states(lambda: run_program(REPO / "programs/sieve.asm", "envelope", max_cycles=last,
                                               stability="cycle"))


def processor(first: int = 30, last: int = 36) -> dict:
    states = sieve_states(last)
    rows, previous = [], None
    for cycle in range(first, last + 1):
        env, A, s = states[cycle - 1]
        E, J = stability.linearise(env, A, s)
        search = Search(E, J, env.model.period)
        cold = search.cayley()
        row = {"cycle": cycle, "cold": {k: v for k, v in cold.items() if k != "folded"},
               "cold_subspace_60": {k: v for k, v in search.cayley(ncv=60).items() if k != "folded"}}
        if previous is not None:
            row["warm"] = {k: v for k, v in search.cayley(start=previous).items() if k != "folded"}
        previous = cold["folded"]
        rows.append(row)
        print(f"processor cycle {cycle}: {json.dumps(row)}", flush=True)
    total = lambda key: sum(r[key]["products"] for r in rows if "warm" in r)
    return {"design": "processor", "unknowns": rows and J.shape[0], "rows": rows,
            "products_cycles_after_the_first": {"cold": total("cold"), "warm": total("warm"),
                                                "cold_subspace_60": total("cold_subspace_60")}}


def solve_by_nets(name: str, env, A, s) -> dict:
    """One LU of the whole against the nets eliminated first: one product (50 timed) and the whole checked search,
    alternated twice; the leading growth of each search."""
    E, J = stability.linearise(env, A, s)
    T = env.model.period
    sigma = 2 * np.pi / (50 * T)
    nets = insulators.fast_nets(env)
    K = (J + sigma * E).tocsr()
    b = np.random.default_rng(0).standard_normal(J.shape[0])
    row = {"design": name, "unknowns": J.shape[0], "product_ms": {}, "search_s": {"one LU": [], "by nets": []},
           "growth": {}}
    for label, how in (("one LU", None), ("by nets", nets)):
        solve = stability._shifted_solver(E, J, sigma, how)
        t = time.perf_counter()
        for _ in range(50):
            solve(K @ b)
        row["product_ms"][label] = (time.perf_counter() - t) / 50 * 1e3
    for label, how in (("one LU", None), ("by nets", nets)) * 2:
        t = time.perf_counter()
        lam, _ = stability._cayley_checked(E, J, sigma, stability.MODES, None, T, how)
        row["search_s"][label].append(time.perf_counter() - t)
        row["growth"][label] = float(lam.real.max() * T)
    print(f"solves {json.dumps(row)}", flush=True)
    return row


def solves() -> list[dict]:
    out = []
    for name in ("c880", "c6288"):
        run, _ = vs.combinational(vs.BENCH / f"{name}.v", name, params.DEFAULT)
        out.append(solve_by_nets(name, *recorded_states(run)[-1]))
    out.append(solve_by_nets("processor, cycle 21", *sieve_states(21)[20]))
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(REPO / "reports/verdict_search_variants.json"))
    ap.add_argument("--solves", action="store_true",
                    help="only the solve by nets against one LU (kept beside the rest)")
    args = ap.parse_args()
    out = Path(args.out)
    conditions = {"machine": platform.processor() or platform.machine(), "cpus": os.cpu_count(),
                  "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
                  "omp_threads": os.environ.get("OMP_NUM_THREADS"), "load": os.getloadavg()[0]}
    if args.solves:
        doc = json.loads(out.read_text()) if out.is_file() else {"conditions": conditions, "designs": []}
        doc["solves"] = {"conditions": conditions, "rows": solves()}
    else:
        doc = {"conditions": conditions, "designs": [c880(), processor()]}
    out.write_text(json.dumps(doc, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
