"""Issue #38: why the sparse search is slow, and the structure a cheaper verdict can use.

At a run's final fixed point the linearisation E y' = J y splits into the oscillators' amplitudes (fast, f) and
the insulators (slow: position ds, velocity dv).  Eliminating the fast block exactly leaves, for every lambda
that is not an eigenvalue of the fast block alone, the insulators' own nonlinear eigenproblem

    S(lambda) ds = 0,   S(lambda) = lambda^2 M_s - lambda J_vv - J_vs - J_vf (lambda E_ff - J_ff)^-1 J_fs

(J_fs: an insulator moves its gate's oscillators' stiffness; J_vf: the oscillators' force on it).  Measured here,
per design (docs/stability.md, "The insulators' own problem"):

- `fast`: the fast block alone (every insulator held): its rightmost eigenvalue where it is small enough for the
  dense solver, and the smallest eigenvalue of the mass-scaled damping matrix.  Each DOF's total damping is
  omega m / Q, and a load's dashpot-coupled input oscillator (G1d, G2d: 0.048) carries its driver's 0.789
  dashpot, so its own dashpot to ground is negative and C is indefinite: no energy (passivity) argument bounds
  the fast block; it is measured.
- `nets`: the fast block's connected components (a channel and the oscillators it drives), so S is exact and
  sparse: one small dense inverse per net (physics/insulators.py).
- `own`: each insulator's own modes (that insulator free, every other held, its nets in between: a small dense
  problem each); the rightmost of them, against the leading eigenvalue.
- `slow`: along lambda = i w (and on the line halfway to the leading eigenvalue) the Perron root rho of
  |diag S|^-1 |S - diag S| (dense up to 1500 insulators, else physics/insulators.py's Collatz-Wielandt bound);
  rho < 1 makes S an H-matrix, so nonsingular there.  With rho < 1 on a closed contour (and no net's eigenvalue
  inside), S has as many eigenvalues inside as its diagonal entries have roots: the network's spectrum is its
  insulators' own modes, moved.  Beside rho the largest row sum of the same matrix (their ratio: how far from
  triangular, feed-forward, S is), and rho by loops (block_dominance: the insulators that drive each other
  grouped), where dense.
- `local` (where dense): each insulator's and each loop's root near the leading eigenvalue from S fitted by a
  quadratic in lambda on 5 points around it; a loop's root is what a collective mode is.
- `certificate`: physics/insulators.py's check that every eigenvalue lies left of half the rightmost own root
  (61 points on that line), and its seconds, beside the search's.
- `search`: the leading eigenvalue and the count of eigenvalues within 2x of its decay (from the dense spectrum,
  up to 7000 unknowns), or ARPACK's operator products for the fast path's search (_cayley_checked).

Usage:  OMP_NUM_THREADS=1 python scripts/verdict_structure.py [--only adder,c880] [--out reports/verdict_structure]
ISCAS-85 netlists from $MECH2SPICE_BENCHMARKS/iscas85/ (as scripts/verdict_scale.py); s344 from
../shared/reference/cases.  Writes <out>.json and <out>.png (rho along the imaginary axis per design).
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import io
import json
import os
import platform
import random
import sys
import time
from pathlib import Path

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from mech2spice import simulation  # noqa: E402
from mech2spice.physics import insulators, params, stability  # noqa: E402
from mech2spice.synthesis.synth import synthesize  # noqa: E402

BENCH = Path(os.environ.get("MECH2SPICE_BENCHMARKS", REPO / "benchmarks")) / "iscas85"
CASES = REPO.parent / "shared/reference/cases"
DESIGNS = ("adder", "adder Q_I=1.5", "adder Q_I=6", "c432", "c880", "c6288", "s344", "s344 Q_I=1.5", "processor")
GRID = np.linspace(0.0, 0.15, 31)      # Im(lambda) T on the contour (the spectrum is symmetric about the axis)


# --- fixed points -------------------------------------------------------------------------------

def recorded_fixed_points(run) -> list:
    """Call run() with every verdict's fixed point recorded: [(env, A, s)] for those Newton found."""
    seen, inner = [], stability._cached_modes

    def modes(env, A, s, converged, start, method):
        if converged:
            seen.append((env, A.copy(), s.copy()))
        return inner(env, A, s, converged, start, method)
    stability._cached_modes = modes
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            run()
    finally:
        stability._cached_modes = inner
    return seen


def combinational(path: Path, top: str | None, block, seed: int = 1):
    nl = synthesize(str(path), top=top)
    rng = random.Random(seed)
    vector = {p: rng.getrandbits(w) for p, w in nl.inputs.items()}
    return lambda: simulation.run_physical(nl, block, [vector], "envelope"), vector


def cases(only: set[str] | None):
    """(name, run, what) for each design: the last recorded fixed point of each run is analysed."""
    q = lambda qi: dataclasses.replace(params.DEFAULT, q_i=qi, name=f"q_i={qi}")
    from mech2spice import cli
    out = []
    want = lambda name: only is None or name in only
    for name, qi in (("adder", 1.0), ("adder Q_I=1.5", 1.5), ("adder Q_I=6", 6.0)):
        if not want(name):
            continue
        run, vec = combinational(REPO / "verilog/adder2.v", None, q(qi))
        out.append((name, run, {"vector": vec, "block": f"q_i={qi}"}))
    for name, top in (("c432", "Circuit432"), ("c880", "c880"), ("c6288", "c6288")):
        path = BENCH / ("c432_hansen.v" if name == "c432" else f"{name}.v")
        if want(name) and path.is_file():
            run, vec = combinational(path, top, params.DEFAULT)
            out.append((name, run, {"vector": vec, "source": path.name}))
    if (CASES / "s344_reset.v").is_file():
        import tempfile
        q15 = Path(tempfile.mkdtemp()) / "q_i_1.5.json"
        q15.write_text(json.dumps({"q_i": 1.5, "name": "q_i=1.5"}))
        for name, extra in (("s344", []), ("s344 Q_I=1.5", ["--params", str(q15)])):
            args = ["simulate", str(CASES / "s344_reset.v"), "--top", "s344", "--stimulus",
                    str(CASES / "s344_two_cycles.json"), "--backend", "envelope", "--json", *extra]
            shown = " ".join(a.replace(str(CASES), "../shared/reference/cases").replace(str(q15), "q_i_1.5.json")
                             for a in args)
            out.append((name, lambda a=args: cli.main(a), {"command": shown}))
    from mech2spice.cpu.run import run_program
    out.append(("processor", lambda: run_program(REPO / "programs/sieve.asm", "envelope", max_cycles=21,
                                                 stability="end"), {"program": "sieve.asm", "cycles": 21}))
    return [c for c in out if want(c[0])]


# --- the fast block alone ----------------------------------------------------------------------

def fast_alone(env, s: np.ndarray) -> dict:
    """The fast block alone (every insulator held at s): its rightmost eigenvalue per drive period (up to 6000
    unknowns), each DOF's own damping rate c_ii / m_i and the smallest eigenvalue of M^-1/2 C M^-1/2 (negative:
    the damping matrix is indefinite, so no energy argument bounds the fast block)."""
    m = env.model
    f = env.fast
    M = m.arrays["mass"][f]
    C = sp.csr_matrix(m.C.tocsr()[f][:, f])
    scale = sp.diags(1 / np.sqrt(M))
    out = {"own_damping_rate": [float((C.diagonal() / M).min()), float((C.diagonal() / M).max())],
           "damping_matrix_min": float(spla.eigsh(sp.csc_matrix(scale @ C @ scale), k=1, which="SA",
                                                  return_eigenvectors=False)[0])}
    if 2 * f.size <= 6000:
        Z = env.Z0 + sp.diags(env.G @ s)
        lam = sla.eigvals(spla.splu(env.Bop.tocsc()).solve(-Z.toarray()))
        out["rightmost"] = float(lam.real.max() * m.period)
        out["leftmost"] = float(lam.real.min() * m.period)
    return out


# --- the insulators' problem ------------------------------------------------------------------

def dominance(Sm: np.ndarray) -> tuple[float, float]:
    """(Perron root, largest row sum) of |diag S|^-1 |S - diag S|."""
    d = np.abs(np.diag(Sm))
    R = np.abs(Sm - np.diag(np.diag(Sm))) / d[:, None]
    return float(np.abs(np.linalg.eigvals(R)).max()), float(R.sum(axis=1).max())


def local_roots(S, lead: complex, T: float, names: list[str], tau: float = 0.05) -> dict:
    """Each insulator's root of S_ii near `lead`, and each loop's (the blocks of block_dominance at `lead`):
    every entry of S fitted by a quadratic in lambda on 5 points 0.002/T around `lead`, each block's quadratic
    eigenproblem solved, the roots within 0.004/T of `lead` kept; the rightmost of each kind and whose it is."""
    from scipy.sparse.csgraph import connected_components
    pts = lead + 0.002 / T * np.array([0, 1, -1, 1j, -1j])
    mats = np.array([S(p) for p in pts])                           # (5, ns, ns)
    coef = np.linalg.lstsq(np.vander(pts, 3), mats.reshape(5, -1), rcond=None)[0].reshape(3, *mats.shape[1:])
    d = np.abs(np.diag(mats[0]))
    R = np.abs(mats[0] - np.diag(np.diag(mats[0]))) / d[:, None]
    nb, label = connected_components(sp.csr_matrix(R >= tau), directed=True, connection="strong")
    out = {"leading_growth": float(lead.real * T)}
    for kind, groups in (("insulator", [np.array([i]) for i in range(d.size)]),
                         ("loop", [np.flatnonzero(label == b) for b in range(nb)])):
        best = None
        for rows in groups:
            c2, c1, c0 = (c[np.ix_(rows, rows)] for c in coef)
            k = rows.size                                          # (c2 l^2 + c1 l + c0) x = 0, linearised
            Z, I = np.zeros((k, k)), np.eye(k)
            roots = sla.eigvals(np.block([[Z, I], [-c0, -c1]]), np.block([[I, Z], [Z, c2]]))
            roots = roots[np.isfinite(roots) & (np.abs(roots - lead) < 0.004 / T)]
            if roots.size and (best is None or roots.real.max() > best[0].real):
                best = (roots[np.argmax(roots.real)], rows)
        if best is not None:
            out[kind] = {"growth": float(best[0].real * T), "im_t": float(abs(best[0].imag) * T),
                         "insulators": [names[i] for i in best[1][:6]], "size": int(best[1].size)}
    out["loops"] = {"blocks": int(nb), "largest": int(np.bincount(label).max())}
    return out


def block_dominance(Sm: np.ndarray, tau: float = 0.05) -> dict:
    """The same test by blocks: the insulators joined where |S_ij / S_ii| >= tau both ways round a loop (the
    strongly connected components of that graph), and rho of B_bc = ||S_bb^-1 S_bc||_inf (< 1: S nonsingular,
    Feingold-Varga).  A latch's two insulators drive each other; a feed-forward network has only single ones."""
    from scipy.sparse.csgraph import connected_components
    d = np.abs(np.diag(Sm))
    R = np.abs(Sm - np.diag(np.diag(Sm))) / d[:, None]
    nb, label = connected_components(sp.csr_matrix(R >= tau), directed=True, connection="strong")
    members = [np.flatnonzero(label == b) for b in range(nb)]
    B = np.zeros((nb, nb))
    for b, rows in enumerate(members):
        X = np.abs(np.linalg.solve(Sm[np.ix_(rows, rows)], Sm[rows, :]))
        X[:, rows] = 0.0
        sums = np.zeros((rows.size, nb))
        np.add.at(sums.T, label, X.T)                     # row sums of X over each block's columns
        B[b] = sums.max(axis=0)
    sizes = np.bincount(label)
    return {"rho": float(np.abs(np.linalg.eigvals(B)).max()), "blocks": int(nb), "largest": int(sizes.max()),
            "in_loops": int(sizes[sizes > 1].sum())}


# --- one design ---------------------------------------------------------------------------------

def analyse(name: str, run, what: dict) -> dict:
    t0 = time.perf_counter()
    fps = recorded_fixed_points(run)
    run_s = time.perf_counter() - t0
    env, A, s = fps[-1]                     # the run's last verdict (s344 at Q_I 1.5: the unstable read it stops at)
    E, J = stability.linearise(env, A, s)
    T = env.model.period
    nf, ns, n = env.fast.size, env.slow.size, J.shape[0]
    row = {"design": name, **{k: v for k, v in what.items() if k != "vector"}, "unknowns": n, "fast_dofs": nf,
           "insulators": ns, "verdicts": len(fps), "run_with_verdicts_s": run_s}
    if "vector" in what:
        row["vector"] = what["vector"]
    t = time.perf_counter()
    row["fast"] = fast_alone(env, s)
    row["fast"]["seconds"] = time.perf_counter() - t
    # the leading eigenvalue: the whole spectrum where small, else the fast path's checked search (its products)
    products = [0]
    t = time.perf_counter()
    if n <= 7000:
        lam = sla.eigvals(spla.splu(E.tocsc()).solve(J.toarray()))
        lam = lam[np.isfinite(lam)]
        lead = lam[np.argmax(lam.real)]
        g = lam.real * T
        top = np.argsort(-g)[:12]
        row["search"] = {"method": "dense", "within_2x_of_leading_decay": int(np.sum(g > 2 * lead.real * T))
                         if lead.real < 0 else None, "leading_growths": g[top].tolist(),
                         "leading_im_t": np.abs(lam[top].imag * T).tolist()}
    else:
        inner = spla.LinearOperator.matvec

        def counted(self, x):
            products[0] += 1
            return inner(self, x)
        spla.LinearOperator.matvec = counted
        try:
            lam, _ = stability._cayley_checked(E, J, 2 * np.pi / (50 * T), stability.MODES, None, T)
        finally:
            spla.LinearOperator.matvec = inner
        lead = lam[np.argmax(lam.real)]
        row["search"] = {"method": "cayley (fast path)", "operator_products": products[0]}
    row["search"].update(seconds=time.perf_counter() - t, growth=float(lead.real * T), im_t=float(abs(lead.imag) * T))
    # the insulators' problem along the contour (S exact, net by net: physics/insulators.py)
    P = insulators.InsulatorProblem(env, E, J)
    dense = ns <= 1500
    S = lambda lam: P.S(lam).toarray()
    label, sizes = insulators.fast_nets(env)
    row["nets"] = {"count": int(sizes.size), "largest": int(sizes.max())}
    t = time.perf_counter()
    own, nets = P.own_modes()
    i = int(np.argmax(own.real))
    row["own"] = {"growth": float(own.real[i] * T), "im_t": float(abs(own.imag[i]) * T),
                  "insulator": env.model.names[env.slow[i]], "nets_rightmost": float(nets.real.max() * T),
                  "seconds": time.perf_counter() - t}
    if dense:
        row["local"] = local_roots(S, lead, T, [env.model.names[i] for i in env.slow])
    t = time.perf_counter()
    lines = {"axis": 0.0}
    if lead.real < 0:
        lines["half_margin"] = float(lead.real * T / 2)
    row["slow"] = {"rho_method": "dense Perron root" if dense else "Collatz-Wielandt bound (radius_bound)"}
    for label, re in lines.items():
        pts = [(re + 1j * w) / T for w in GRID]
        vals = [dominance(S(p)) for p in pts] if dense else [(P.radius_bound(p), None) for p in pts]
        row["slow"][label] = {"re_t": re, "im_t": GRID.tolist(), "rho": [v[0] for v in vals],
                              "row_sum": [v[1] for v in vals], "rho_max": max(v[0] for v in vals)}
    if dense:
        blocks = [block_dominance(S(1j * w / T)) for w in GRID]
        row["slow"]["axis"]["blocks"] = blocks
        row["slow"]["axis"]["rho_block_max"] = max(b["rho"] for b in blocks)
        sv = np.linalg.svd(S(lead), compute_uv=False)
        row["slow"]["sigma_min_at_leading"] = float(sv[-1] / sv[0])
    row["slow"]["seconds"] = time.perf_counter() - t
    # the certificate as physics/insulators.py runs it: every eigenvalue left of half the leading insulator root
    t = time.perf_counter()
    line = min(row["own"]["growth"] / 2, 0.0)
    cert = P.certify(line)
    row["certificate"] = {**cert.to_json(), "seconds": time.perf_counter() - t}
    print(f"{name}: {n} unknowns ({ns} insulators), leading {row['search']['growth']:+.4e}/period; fast block "
          f"rightmost {row['fast'].get('rightmost', float('nan')):+.4e}; "
          f"rho on the axis <= {row['slow']['axis']['rho_max']:.3f}, "
          f"half-way {row['slow'].get('half_margin', {}).get('rho_max', float('nan')):.3f}; by loops "
          f"{row['slow']['axis'].get('rho_block_max', float('nan')):.3f}; own root {row['own']['growth']:+.4e} "
          f"({row['own']['insulator']}); loop root "
          f"{row.get('local', {}).get('loop', {}).get('growth', float('nan')):+.4e}; "
          f"certificate {row['certificate']['certified']} at {line:+.2e} in {row['certificate']['seconds']:.2f} s "
          f"(search {row['search']['seconds']:.2f} s)", flush=True)
    return row


def plot(rows: list[dict], path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    colour = {name: plt.cm.tab10(i) for i, name in enumerate(DESIGNS)}
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.4), sharey=True)
    for ax, line in zip(axes, ("axis", "half_margin")):
        for r in rows:
            if line in r["slow"]:
                bound = r["slow"]["rho_method"].startswith("Collatz")
                ax.semilogy(r["slow"][line]["im_t"], r["slow"][line]["rho"], color=colour[r["design"]],
                            ls="--" if bound else "-", label=r["design"] + (" (upper bound)" if bound else ""))
        ax.axhline(1.0, color="k", lw=0.8, ls=":")
        ax.set_xlabel("Im(lambda) x drive period")
        ax.set_title("on Re lambda = 0" if line == "axis" else "on Re lambda = half the leading growth rate",
                     fontsize=10)
    axes[0].set_ylabel("rho(|diag S|^-1 |S - diag S|)\n(< 1: S nonsingular there)")
    axes[0].legend(fontsize=7, loc="lower center")
    fig.suptitle("The insulators' own problem S(lambda): dominant on feed-forward circuits, not on c6288 or with "
                 "latches (issue #38)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def table(rows: list[dict]) -> str:
    """The table of docs/stability.md, "The insulators' own problem"."""
    out = ["| design | unknowns | insulators (nets, largest) | leading growth / period | oscillators alone: "
           "rightmost | rho on Re = 0 | rho half-way | rho by loops | rightmost own root (whose) | loop root (size) "
           "| certificate (line, s) | search s (how) | run s |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    f = lambda x, fmt: fmt % x if x is not None else "-"
    for r in rows:
        search, cert, loop = r["search"], r["certificate"], r.get("local", {}).get("loop")
        how = (f"dense, {search['within_2x_of_leading_decay']} within 2x" if search["method"] == "dense" and
               search["within_2x_of_leading_decay"] is not None else "dense" if search["method"] == "dense"
               else f"{search['operator_products']} products")
        nets = r["nets"]
        out.append(f"| {r['design']} | {r['unknowns']} | {r['insulators']} ({nets['count']}, {nets['largest']}) | "
                   f"{search['growth']:+.3e} | {f(r['fast'].get('rightmost'), '%+.3e')} | "
                   f"{r['slow']['axis']['rho_max']:.3f} | "
                   f"{f(r['slow'].get('half_margin', {}).get('rho_max'), '%.3f')} | "
                   f"{f(r['slow']['axis'].get('rho_block_max'), '%.3f')} | {r['own']['growth']:+.3e} "
                   f"({r['own']['insulator']}) | {f(loop and loop['growth'], '%+.3e')}"
                   f"{' (%d)' % loop['size'] if loop else ''} | {'yes' if cert['certified'] else 'no'} "
                   f"({cert['line']:+.2e}, {cert['seconds']:.2f}) | {search['seconds']:.2f} ({how}) | "
                   f"{r['run_with_verdicts_s']:.2f} |")
    return "\n".join(out)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", help="comma-separated design names")
    ap.add_argument("--out", default=str(REPO / "reports/verdict_structure"))
    ap.add_argument("--append", action="store_true", help="keep <out>.json's other designs, replace these")
    ap.add_argument("--render", action="store_true", help="print the table of an existing <out>.json, nothing measured")
    ap.add_argument("--merge", nargs="+", metavar="JSON", help="combine earlier outputs of this script into <out> "
                    "(a later file's design replaces an earlier one's), nothing measured")
    args = ap.parse_args()
    out = Path(args.out)
    if args.merge:
        docs = [json.loads(Path(f).read_text()) for f in args.merge]
        rows = {r["design"]: dict(r, measured=r.get("measured", d["conditions"]["date"]))
                for d in docs for r in d["designs"]}
        rows = sorted(rows.values(), key=lambda r: DESIGNS.index(r["design"]))
        out.with_suffix(".json").write_text(json.dumps({"conditions": docs[-1]["conditions"], "designs": rows},
                                                       indent=1) + "\n")
        plot(rows, out.with_suffix(".png"))
        print(table(rows))
        return 0
    if args.render:
        print(table(json.loads(out.with_suffix(".json").read_text())["designs"]))
        return 0
    only = set(args.only.split(",")) if args.only else None
    rows = [analyse(*c) for c in cases(only)]
    conditions = {"machine": platform.processor() or platform.machine(), "cpus": os.cpu_count(),
                  "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
                  "omp_threads": os.environ.get("OMP_NUM_THREADS")}
    for r in rows:
        r["measured"] = conditions["date"]
    if args.append and out.with_suffix(".json").is_file():
        old = json.loads(out.with_suffix(".json").read_text())["designs"]
        names = {r["design"] for r in rows}
        order = list(DESIGNS)
        rows = sorted([r for r in old if r["design"] not in names] + rows,
                      key=lambda r: order.index(r["design"]) if r["design"] in order else len(order))
    out.with_suffix(".json").write_text(json.dumps({"conditions": conditions, "designs": rows}, indent=1) + "\n")
    plot(rows, out.with_suffix(".png"))
    print(table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
