"""Slowly-varying amplitude (envelope) equations, generated from the mechanical model:

    (2 i omega M + C) A' = F^ - Z0 A - (G s) * A         Z0 = K - omega^2 M + i omega C  (fast block)
    M_s s'' = -K_s s - C_s s' - H |A|^2 / 2

Derivation, the meaning of F^, G, H and what the averaging drops: docs/physics.md, section
"The envelope equations".
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import Mech2SpiceError
from .model import MechModel


def _block_inverse(Bop, label: np.ndarray, sizes: np.ndarray):
    """The inverse of a block-diagonal sparse matrix (blocks: the connected components `label`), as sparse:
    the blocks of each size gathered into one dense stack and inverted together."""
    n = label.size
    order = np.argsort(label, kind="stable")                     # members of each block, ascending
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    pos = np.empty(n, np.int64)
    pos[order] = np.arange(n) - np.repeat(starts, sizes)         # a row's place inside its block
    coo = sp.coo_matrix(Bop)
    rows, cols, vals = [], [], []
    for k in np.unique(sizes):
        blocks = np.flatnonzero(sizes == k)
        slot = np.full(sizes.size, -1)
        slot[blocks] = np.arange(blocks.size)
        mine = slot[label[coo.row]] >= 0
        dense = np.zeros((blocks.size, k, k), coo.dtype)
        np.add.at(dense, (slot[label[coo.row[mine]]], pos[coo.row[mine]], pos[coo.col[mine]]), coo.data[mine])
        members = order[starts[blocks][:, None] + np.arange(k)]   # (blocks, k)
        rows.append(np.repeat(members, k, axis=1).ravel())
        cols.append(np.tile(members, (1, k)).ravel())
        vals.append(np.linalg.inv(dense).ravel())
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))


class Envelope:
    """The envelope equations' operators (Z0, Bop, G, H, slow block, drive map) for one model."""
    def __init__(self, model: MechModel):
        model.check()
        a = model.arrays
        self.model = model
        self.omega = w = model.omega
        self.fast = np.flatnonzero(~a["slow"])
        self.slow = np.flatnonzero(a["slow"])
        pos_f = -np.ones(model.n, int)
        pos_f[self.fast] = np.arange(self.fast.size)
        pos_s = -np.ones(model.n, int)
        pos_s[self.slow] = np.arange(self.slow.size)
        self._check_links(model, a["slow"])

        K, C = model.K.tocsr(), model.C.tocsr()
        Kff, Cff = K[self.fast][:, self.fast], C[self.fast][:, self.fast]
        Mf = sp.diags(a["mass"][self.fast])
        self.Z0 = (Kff - w * w * Mf + 1j * w * Cff).tocsc()
        self.Bop = (2j * w * Mf + Cff).tocsc()
        if not (np.isfinite(self.Z0.data).all() and np.isfinite(self.Bop.data).all()):
            raise Mech2SpiceError(f"the envelope equations are not finite at omega = {w:g} rad/s: a gate parameter "
                                  "is too large or too small for this model (omega^2 times a mass overflows)")
        self.solve_rate = spla.factorized(self.Bop)     # A' from a residual r: (2 i omega M + C) A' = r
        self.z0_diag = self.Z0.diagonal()
        self.diagonal = self.Z0.nnz == self.fast.size      # no fast-fast couplings

        qf, qs, g = pos_f[a["quad_fast"]], pos_s[a["quad_slow"]], a["quad_gamma"]
        nf, ns = self.fast.size, self.slow.size
        self.G = sp.csr_matrix((2 * g, (qf, qs)), shape=(nf, ns))
        self.H = sp.csr_matrix((g, (qs, qf)), shape=(ns, nf))
        self.ms = a["mass"][self.slow]
        # sparse: a dense slow block made every step O(n_slow^2) (reports/performance.md)
        self.Ks = K[self.slow][:, self.slow].tocsr()
        self.Cs = C[self.slow][:, self.slow].tocsr()

        dof = a["drive_dof"]
        if np.any(a["slow"][dof]):
            raise Mech2SpiceError("the envelope model cannot drive a slow DOF at omega")
        # settle detection watches the channels (the logic signals): gate oscillators ring in slow,
        # lightly damped gate-insulator modes that change no logic level (reports/envelope.md)
        gates = model.design.gates
        self.watch = pos_f[[g.channel for g in gates]] if gates else np.arange(nf)
        self.Dmap = sp.csr_matrix((-1j * np.exp(1j * a["drive_phase"]),
                                   (pos_f[dof], np.arange(dof.size))), shape=(nf, dof.size))

    @staticmethod
    def _check_links(model: MechModel, slow: np.ndarray) -> None:
        for i, j, _ in model.springs + model.dashpots:
            if slow[i] != slow[j]:
                raise Mech2SpiceError(
                    f"link between oscillating '{model.names[i]}' and slow '{model.names[j]}' "
                    "has no envelope form")

    @classmethod
    def of(cls, model: MechModel) -> "Envelope":
        """The model's envelope operator, built once (it factorises a sparse matrix); the model drops it
        when edited."""
        env = model.derived.get("envelope")
        if env is None:
            env = model.derived["envelope"] = cls(model)
        return env

    def block_inverse(self, max_block: int = 64):
        """Bop^-1 as a sparse matrix when Bop's connected blocks are small (a channel and the dashpot
        gates it drives), else None.  Cached."""
        if not hasattr(self, "_binv"):
            from scipy.sparse.csgraph import connected_components
            n, label = connected_components(abs(self.Bop), directed=False)
            sizes = np.bincount(label, minlength=n)
            self._binv = None
            if sizes.size == 0 or sizes.max() <= max_block:
                nf = self.fast.size
                self._binv = _block_inverse(self.Bop, label, sizes) if nf else None
        return self._binv

    # --- pieces --------------------------------------------------------------
    def forcing(self, amps: np.ndarray) -> np.ndarray:
        """Complex forcing F^ (n_fast, B) from drive amplitudes (n_drives, B)."""
        return self.Dmap @ np.asarray(amps, float).reshape(len(self.model.drives), -1)

    def residual_fast(self, A, s, F):
        """The fast equations' right-hand side F^ - Z0 A - (G s) * A."""
        return F - self.Z0 @ A - (self.G @ s) * A

    def slow_force(self, A):
        """The mean force -H |A|^2 / 2 the amplitudes exert on the slow DOFs."""
        return -(self.H @ (np.abs(A) ** 2)) / 2

    def rhs(self, A, s, sd, F):
        """Time derivatives (A', s', s'') for states of shape (n_fast, B), (n_slow, B)."""
        Ad = self.solve_rate(self.residual_fast(A, s, F))
        sdd = (self.slow_force(A) - self.Ks @ s - self.Cs @ sd) / self.ms[:, None]   # no negated matrix copies
        return Ad, sd, sdd

    def fast_response(self, s: np.ndarray, F: np.ndarray) -> np.ndarray:
        """A solving Z(s) A = F for one slow state s (n_slow,) and forcing F (n_fast,)."""
        if self.diagonal:
            return F / (self.z0_diag + self.G @ s)
        Z = (self.Z0 + sp.diags(self.G @ s)).tocsc()
        return spla.spsolve(Z, F)

    # --- real-vector form for Jacobians --------------------------------------
    def pack(self, A, s, sd) -> np.ndarray:
        """One real vector [Re A, Im A, s, s'] from a single state."""
        return np.concatenate([A.real, A.imag, s, sd])

    def unpack(self, y):
        """(A, s, s') from a real vector made by pack."""
        nf, ns = self.fast.size, self.slow.size
        return (y[:nf] + 1j * y[nf:2 * nf]), y[2 * nf:2 * nf + ns], y[2 * nf + ns:]

    def rhs_real(self, y: np.ndarray, F: np.ndarray) -> np.ndarray:
        """The time derivative of a packed real state y under forcing F (n_fast,)."""
        A, s, sd = self.unpack(y)
        Ad, sd_, sdd = self.rhs(A[:, None], s[:, None], sd[:, None], F[:, None])
        return self.pack(Ad[:, 0], sd_[:, 0], sdd[:, 0])

    def jacobian(self, y: np.ndarray, F: np.ndarray) -> np.ndarray:
        """Central finite-difference Jacobian of the real envelope equations."""
        J = np.empty((y.size, y.size))
        scale = np.maximum(np.abs(y), 1e-6 * max(np.abs(y).max(), 1e-12))
        for k in range(y.size):
            e = np.zeros_like(y)
            e[k] = 1e-6 * scale[k]
            J[:, k] = (self.rhs_real(y + e, F) - self.rhs_real(y - e, F)) / (2 * e[k])
        return J


# --- time integration of the envelope equations ---------------------------------


def gershgorin_rate(env: Envelope, s_max: float = 0.5) -> float:
    """Upper bound (Gershgorin) on |eigenvalue| of the envelope equations' linear part, with the slow
    DOFs displaced by up to s_max.  Safe but ~3.5x above the true rate (reports/envelope.md)."""
    Bd = np.abs(env.Bop.diagonal())
    Zrow = np.asarray(abs(env.Z0).sum(axis=1)).ravel() + np.asarray(abs(env.G).sum(axis=1)).ravel() * s_max
    fast = float((Zrow / Bd).max()) if Bd.size else 0.0
    return max(fast, _slow_rate_bound(env))


def _slow_rate_bound(env: Envelope) -> float:
    if not env.slow.size:
        return 0.0
    return float(np.max(np.sqrt(np.abs(env.Ks.diagonal()) / env.ms) + np.abs(env.Cs.diagonal()) / env.ms))


DENSE_RATE_MAX = 300      # fast DOFs up to which spectral_rate takes the dense spectrum (~0.1 s at 300)


def spectral_rate(env: Envelope, slow_modes: bool = True, own_rates: bool = True) -> float | None:
    """The largest |eigenvalue| of the linear part at rest: ARPACK on A' = -Bop^-1 Z0 A for the amplitudes,
    exact roots for the insulators (each its own damped oscillator when Ks, Cs are diagonal; left out with
    slow_modes=False, for a step that treats them exactly).  own_rates=False: each amplitude's own rate (the
    diagonal of -Bop^-1 Z0) left out too, for a step that treats it exactly, so only the coupling between
    amplitudes is left.  None if ARPACK does not converge, the slow block is coupled, or (own_rates=False)
    Bop has no small blocks."""
    slow = 0.0
    if env.slow.size and slow_modes:
        if env.Ks.nnz > env.slow.size or env.Cs.nnz > env.slow.size:
            return None
        k, c, m = env.Ks.diagonal(), env.Cs.diagonal(), env.ms
        slow = float(np.max(np.abs(np.stack([(-c + s * np.sqrt(c * c - 4 * k * m + 0j)) / (2 * m)
                                              for s in (1, -1)]))))
    nf = env.fast.size
    if nf == 0:
        return slow
    own = np.zeros(nf, complex)
    if not own_rates:
        Binv = env.block_inverse()
        if Binv is None:
            return None
        own = -np.asarray((sp.csr_matrix(Binv) @ sp.csc_matrix(env.Z0)).diagonal(), complex)
    op = spla.LinearOperator((nf, nf), matvec=lambda x: -env.solve_rate(env.Z0 @ x) - own * x, dtype=complex)
    try:
        if nf <= DENSE_RATE_MAX:     # small networks: every eigenvalue (ARPACK can stall on them, error 3)
            lam = np.linalg.eigvals(np.column_stack([op.matvec(e) for e in np.eye(nf, dtype=complex)]))
        else:
            lam = spla.eigs(op, k=1, which="LM", v0=np.ones(nf, complex), tol=1e-4, maxiter=5000,
                            return_eigenvectors=False)
    except (spla.ArpackNoConvergence, spla.ArpackError):
        return None                  # the caller falls back to the Gershgorin bound
    return max(slow, float(np.abs(lam).max()))
