"""Issue #38: can a bound certify "every eigenvalue left of -r" without computing them?  Measured on the adder.

The verdict's eigenvalue search costs more than the run (docs/stability.md, "The verdict's cost").  Two
certificates that would need no search, tested at the 2-bit adder's fixed point (a = 3, b = 2, settled by a
1500-period envelope run; 102 oscillators, 204 real unknowns, small enough for the dense spectrum):

1. Block Gershgorin (Feingold-Varga) with a diagonal scaling: with blocks i (one per gate: its oscillators and
   its insulator), beta_i = min over Re s >= -r of sigma_min(Jh_ii - s I) and R_ij = ||Jh_ij|| (Jh = the pencil
   premultiplied by the inverse of E's diagonal blocks; E's off-diagonal blocks only add |s| ||N_ij||), every
   eigenvalue lies left of -r if the comparison matrix diag(beta) - R is a nonsingular M-matrix, i.e.
   rho(diag(beta)^-1 R) < 1 (the best diagonal scaling reaches exactly this).  beta_i is taken on a frequency
   grid at r = 0, which overestimates it (a grid minimum is >= the true minimum), so the rho printed is a lower
   bound of the true one: rho > 1 means the certificate fails.
2. A block-diagonal Lyapunov function V = y^T W y: every eigenvalue has Re lambda <= the largest eigenvalue of
   (M^T W + W M, 2 W) (the numerical abscissa in W's norm, M = E^-1 J); < 0 certifies.  W from each gate's own
   Lyapunov equation (M_ii^T W_i + W_i M_ii = -Q_i), and the oscillators' energy metric (m on each oscillator's
   (a, b), k_s and m_s on the insulators), the latter also for the oscillators alone (insulators frozen).

Usage:  python scripts/verdict_bounds.py [--q-i 1.0]      (a few seconds; prints the numbers docs/stability.md
                                                          quotes, and each coupling's rate by the DOF kinds it joins)
"""
from __future__ import annotations

import argparse
import re
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import scipy.linalg as sla

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from mech2spice.backends import make_engine  # noqa: E402
from mech2spice.physics import network, params, stability  # noqa: E402
from mech2spice.physics.envelope import Envelope  # noqa: E402
from mech2spice.synthesis.synth import synthesize  # noqa: E402


def settled_adder(p):
    """(envelope, A, s) at the adder's fixed point for a = 3, b = 2."""
    nl = synthesize(str(REPO / "verilog/adder2.v"))
    m = network.build(nl, params.DEFAULT)
    stim = network.stimulus(m, nl, params.DEFAULT, [(0, [{"a": 3, "b": 2}])])
    run = make_engine("envelope").run(m, 1500, stim)
    env = Envelope.of(m)
    A, s, ok = stability.operating_point(env, run.state[0][:, 0], run.state[1][:, 0], env.forcing(stim.at(0))[:, 0])
    assert ok, "no fixed point"
    return Envelope.of(network.build(nl, p)), A, s


def unknown_names(env) -> list[str]:
    """The DOF name of each real unknown: (a, b) per oscillating DOF, (ds, ds') per insulator."""
    m = env.model
    fast, slow = [m.names[i] for i in env.fast], [m.names[i] for i in env.slow]
    return fast + fast + slow + slow


def gershgorin(Jh: np.ndarray, blocks: dict, T: float) -> dict:
    """beta_i (grid), the row sums, and rho(diag(beta)^-1 R), all rates x T."""
    names = sorted(blocks)
    k = len(names)
    R = np.zeros((k, k))
    beta = np.zeros(k)
    grid = np.linspace(-0.5, 0.5, 2001) / T
    for a, g in enumerate(names):
        ii = blocks[g]
        Aii = Jh[np.ix_(ii, ii)]
        beta[a] = min(np.linalg.svd(Aii - 1j * w * np.eye(len(ii)), compute_uv=False)[-1] for w in grid)
        for b, h in enumerate(names):
            if a != b:
                R[a, b] = np.linalg.norm(Jh[np.ix_(ii, blocks[h])], 2)
    rho = max(abs(np.linalg.eigvals(R / beta[:, None])))
    return {"beta_T": (beta.min() * T, beta.max() * T), "row_sum_T": (R.sum(1).min() * T, R.sum(1).max() * T),
            "rho": rho}


def abscissa(M: np.ndarray, W: np.ndarray, T: float) -> float:
    """The largest eigenvalue of (M^T W + W M, 2 W) x T: a bound on every eigenvalue's real part."""
    WM = W @ M
    return float(sla.eigh(WM + WM.T, 2 * W, eigvals_only=True).max() * T)


def couplings(Jh: np.ndarray, env, T: float) -> list[tuple]:
    """The largest rate (x T) of Jh's 2x2 DOF blocks, by (row kind, column kind, same gate or not)."""
    nf, ns = env.fast.size, env.slow.size
    m = env.model
    dofs = [m.names[i] for i in env.fast] + [m.names[i] for i in env.slow]
    rows = [[i, i + nf] if i < nf else [2 * nf + i - nf, 2 * nf + ns + i - nf] for i in range(nf + ns)]
    out = {}
    for a, da in enumerate(dofs):
        for b, db in enumerate(dofs):
            v = np.linalg.norm(Jh[np.ix_(rows[a], rows[b])], 2) * T if a != b else 0.0
            if v > 0:
                key = (da.split(".")[1][:2], db.split(".")[1][:2], da.split(".")[0] == db.split(".")[0])
                out[key] = max(out.get(key, 0.0), v)
    return sorted(((*k, v) for k, v in out.items()), key=lambda x: -x[3])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--q-i", type=float, default=params.DEFAULT.q_i, help="the insulator's Q (1.5: the old one)")
    args = ap.parse_args()
    env, A, s = settled_adder(replace(params.DEFAULT, q_i=args.q_i))
    E, J = (x.toarray() for x in stability.linearise(env, A, s))
    T = env.model.period
    group = np.array([re.match(r"[^.]+", x).group(0) for x in unknown_names(env)])
    blocks = {g: np.where(group == g)[0] for g in set(group)}
    P = np.zeros_like(E)
    for ii in blocks.values():
        P[np.ix_(ii, ii)] = np.linalg.inv(E[np.ix_(ii, ii)])
    Jh, M = P @ J, np.linalg.solve(E, J)
    lead = sla.eigvals(J, E)
    print(f"adder a=3 b=2, Q_I {args.q_i}: {J.shape[0]} unknowns, {len(blocks)} gate blocks; "
          f"rightmost eigenvalue x T {lead[np.isfinite(lead)].real.max() * T:.4e}")
    g = gershgorin(Jh, blocks, T)
    print(f"block Gershgorin: beta_i x T in [{g['beta_T'][0]:.2e}, {g['beta_T'][1]:.2e}], off-diagonal row sums "
          f"x T in [{g['row_sum_T'][0]:.2e}, {g['row_sum_T'][1]:.2e}]; rho(diag(beta)^-1 R) >= {g['rho']:.1f} "
          f"(certifies only below 1)")
    W = np.zeros_like(E)
    for ii in blocks.values():
        Mi = np.linalg.solve(E[np.ix_(ii, ii)], J[np.ix_(ii, ii)])
        W[np.ix_(ii, ii)] = sla.solve_continuous_lyapunov(Mi.T, -np.eye(len(ii)))
    print(f"block-diagonal Lyapunov (each gate's own, Q = I): abscissa bound x T {abscissa(M, W, T):+.3e}")
    nf = env.fast.size
    mass = np.asarray(env.Bop.diagonal()).imag / (2 * 2 * np.pi / T)
    energy = np.concatenate([mass, mass, np.asarray(env.Ks.diagonal()).ravel(), np.asarray(env.ms).ravel()])
    print(f"energy metric: abscissa bound x T {abscissa(M, np.diag(energy), T):+.3e}; the oscillators alone "
          f"(insulators frozen) {abscissa(M[:2 * nf, :2 * nf], np.diag(energy[:2 * nf]), T):+.3e}")
    print("largest coupling rate x T by DOF kinds (row <- column, same gate):")
    for row, col, same, v in couplings(Jh, env, T):
        print(f"  {row:>3} <- {col:<3} {'same' if same else 'cross'}  {v:.3e}")


if __name__ == "__main__":
    main()
