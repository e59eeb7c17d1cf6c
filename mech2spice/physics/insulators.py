"""The insulators' own eigenproblem: the network's linearisation with its oscillators eliminated exactly.

The linearisation (physics/stability.py) splits into the oscillators' amplitudes (fast, f) and the insulators
(position ds, velocity dv).  An oscillator couples to other oscillators only through springs and dashpots to
its own channel, so the fast block falls apart into small nets (a channel and the input oscillators it
drives: at most 38-66 real unknowns on c880, the processor and c6288).  For every lambda that is not an
eigenvalue of a net,

    S(lambda) ds = 0,   S(lambda) = lambda^2 M_s - lambda J_vv - J_vs - J_vf (lambda E_ff - J_ff)^-1 J_fs

has the network's remaining eigenvalues as its roots, and S is exact and sparse: one small dense inverse per net.
Where |diag S|^-1 |S - diag S| has spectral radius below 1 on a closed contour, S is nonsingular there and
(homotopy from diag S) has inside exactly as many eigenvalues as the insulators' own problems S_ii (each insulator
free, every other held).  So "no eigenvalue right of Re lambda = c" is certified by: no net's eigenvalue and no
insulator's own root right of c, and the radius below 1 along the line (the arc at large |lambda|, where
lambda^2 M_s dominates, is not checked).  docs/stability.md, "The insulators' own problem".
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .envelope import Envelope, _block_inverse

THETAS = (0.3, 0.5, 0.7, 0.8, 0.9, 0.95, 0.99)   # trial radii of radius_bound's positive vector
SERIES_TERMS = 200


def fast_nets(env: Envelope) -> tuple[np.ndarray, np.ndarray]:
    """(label, sizes) of the fast block's 2 n_fast real unknowns (a, b): its connected components, built once per
    model.  An oscillator's a and b are one net's (its damping joins them)."""
    nets = env.model.derived.get("insulator_nets")
    if nets is None:
        _, label = connected_components(abs(env.Z0) + abs(env.Bop), directed=False)
        label = np.concatenate([label, label])
        nets = env.model.derived["insulator_nets"] = (label, np.bincount(label))
    return nets


@dataclass
class Certificate:
    """Whether every eigenvalue of the linearisation lies left of Re lambda = line (per drive period)."""
    certified: bool
    line: float                  # c x T
    rho_max: float               # the largest Collatz-Wielandt bound of the radius along the line
    own_rightmost: float         # the rightmost insulator's own root, growth per period
    own_insulator: str           # whose
    nets_rightmost: float        # the rightmost eigenvalue of the fast nets, growth per period
    points: int                  # lambdas checked on the line

    def to_json(self) -> dict:
        return dict(self.__dict__)


class InsulatorProblem:
    """S(lambda) at one linearisation (E, J) of `env`; see the module's docstring."""

    def __init__(self, env: Envelope, E: sp.spmatrix, J: sp.spmatrix):
        self.env = env
        nf, ns = env.fast.size, env.slow.size
        n = J.shape[0]
        F, D, V = slice(0, 2 * nf), slice(2 * nf, 2 * nf + ns), slice(2 * nf + ns, n)
        E, J = sp.csr_matrix(E), sp.csr_matrix(J)
        self.E, self.J = E, J
        self.Jff, self.Eff = J[F][:, F], E[F][:, F]
        self.Jfs, self.Jvf = J[F][:, D].tocsc(), J[V][:, F].tocsr()
        self.Jvs, self.Jvv, self.Ms = J[V][:, D], J[V][:, V], E[V][:, V]
        self.label, self.sizes = fast_nets(env)
        self.T = env.model.period

    def resolvent(self, lam: complex) -> sp.csr_matrix:
        """(lambda E_ff - J_ff)^-1, net by net."""
        return _block_inverse((lam * self.Eff - self.Jff).astype(complex), self.label, self.sizes)

    def S(self, lam: complex) -> sp.csr_matrix:
        R = self.resolvent(lam)
        return sp.csr_matrix(lam * lam * self.Ms - lam * self.Jvv - self.Jvs - self.Jvf @ (R @ self.Jfs))

    def radius_bound(self, lam: complex) -> float:
        """An upper bound of the spectral radius of B = |diag S|^-1 |S - diag S| at lam; below 1 makes S
        nonsingular.  Collatz-Wielandt: rho(B) <= max_i (B w)_i / w_i for any positive w; w = sum_k (B / theta)^k 1
        (positive, and the bound is below theta once the series has converged) for theta from 0.3 to 0.99, the
        smallest bound kept.  (Power iteration's w has near-zero entries where B is near-triangular.)"""
        Sm = self.S(lam)
        d = np.abs(Sm.diagonal())
        B = (sp.diags(1 / d) @ abs(Sm - sp.diags(Sm.diagonal()))).tocsr()
        best = np.inf
        for theta in THETAS:
            w, term = np.ones(B.shape[0]), np.ones(B.shape[0])
            for _ in range(SERIES_TERMS):
                term = B @ term / theta
                w += term
                if term.max() < 1e-3:
                    break
            best = min(best, float(np.max((B @ w) / w)))
            if best < theta:                      # a larger theta cannot do better than a converged series
                break
        return best

    def own_modes(self) -> tuple[np.ndarray, np.ndarray]:
        """Each insulator's own modes: the rightmost eigenvalue of the network with that insulator free and every
        other held (its ds, dv and the nets its gate's oscillators belong to), and the rightmost eigenvalue of
        each net alone, both as rates (not per period).  Dense eigenvalue problems batched by size."""
        nf2, ns = self.Eff.shape[0], self.Ms.shape[0]
        touched = (abs(self.Jfs).T + abs(self.Jvf)).tocsr()            # insulator -> fast unknowns it meets
        members = [np.flatnonzero(self.label == b) for b in range(self.sizes.size)]
        problems = []
        for i in range(ns):
            nets = np.unique(self.label[touched.indices[touched.indptr[i]:touched.indptr[i + 1]]])
            idx = np.concatenate([members[b] for b in nets] + [[nf2 + i, nf2 + ns + i]]).astype(int)
            problems.append(idx)
        own = _rightmost(self.E, self.J, problems)
        nets = _rightmost(self.E, self.J, members)
        return own, nets

    def certify(self, line: float, points: int = 61, im_max: float = 0.15) -> Certificate:
        """No eigenvalue right of Re lambda = line / T?  The radius bound at `points` lambdas on the line,
        Im lambda T in [0, im_max] (the spectrum is symmetric), and the insulators' and nets' own modes."""
        own, nets = self.own_modes()
        i = int(np.argmax(own.real))
        names = self.env.model.names
        rho = max(self.radius_bound((line + 1j * w) / self.T) for w in np.linspace(0.0, im_max, points))
        ok = rho < 1 and own.real.max() * self.T < line and nets.real.max() * self.T < line
        return Certificate(bool(ok), line, rho, float(own.real[i] * self.T), names[self.env.slow[i]],
                           float(nets.real.max() * self.T), points)


def _rightmost(E: sp.csr_matrix, J: sp.csr_matrix, problems: list[np.ndarray]) -> np.ndarray:
    """The rightmost finite eigenvalue of each sub-pencil (J, E)[idx, idx], problems of one size stacked."""
    out = np.full(len(problems), -np.inf + 0j)
    sizes = np.array([p.size for p in problems])
    for k in np.unique(sizes):
        which = np.flatnonzero(sizes == k)
        idx = np.array([problems[j] for j in which])                       # (m, k)
        Es = np.array([E[p][:, p].toarray() for p in idx])
        Js = np.array([J[p][:, p].toarray() for p in idx])
        lam = np.linalg.eigvals(np.linalg.solve(Es, Js))                   # E is nonsingular on every sub-block
        out[which] = lam[np.arange(lam.shape[0]), np.argmax(lam.real, axis=1)]
    return out
