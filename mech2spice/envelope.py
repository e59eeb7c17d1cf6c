"""Slowly-varying amplitude (envelope) equations, generated from the mechanical model.

Each oscillating DOF is written u = Re(A e^{i omega t}) with A slowly varying;
slow DOFs (insulators) keep their own real coordinate s.  Averaging over one
drive period (dropping the 2*omega part of u^2 and terms of order A'') gives

    (2 i omega M + C) A' = F^ - Z0 A - (G s) * A         Z0 = K - omega^2 M + i omega C  (fast block)
    M_s s'' = -K_s s - C_s s' - H |A|^2 / 2

with F^ = -i a e^{i phase} for a drive a sin(omega t + phase), G[f, s] = 2 gamma
and H[s, f] = gamma for every quadratic coupling.  The same equations give the
paper's semi-analytic steady state (A' = 0, s' = 0) and its linear stability.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .errors import Mech2SpiceError
from .model import MechModel


class Envelope:
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
        self._Bsolve = spla.factorized(self.Bop)
        self.z0_diag = self.Z0.diagonal()
        self.diagonal = self.Z0.nnz == self.fast.size      # no fast-fast couplings

        qf, qs, g = pos_f[a["quad_fast"]], pos_s[a["quad_slow"]], a["quad_gamma"]
        nf, ns = self.fast.size, self.slow.size
        self.G = sp.csr_matrix((2 * g, (qf, qs)), shape=(nf, ns))
        self.H = sp.csr_matrix((g, (qs, qf)), shape=(ns, nf))
        self.ms = a["mass"][self.slow]
        self.Ks = K[self.slow][:, self.slow].toarray()
        self.Cs = C[self.slow][:, self.slow].toarray()

        dof = a["drive_dof"]
        if np.any(a["slow"][dof]):
            raise Mech2SpiceError("the envelope model cannot drive a slow DOF at omega")
        self.Dmap = sp.csr_matrix((-1j * np.exp(1j * a["drive_phase"]),
                                   (pos_f[dof], np.arange(dof.size))), shape=(nf, dof.size))

    @staticmethod
    def _check_links(model: MechModel, slow: np.ndarray) -> None:
        for i, j, _ in model.springs + model.dashpots:
            if slow[i] != slow[j]:
                raise Mech2SpiceError(
                    f"link between oscillating '{model.names[i]}' and slow '{model.names[j]}' "
                    "has no envelope form")

    # --- pieces --------------------------------------------------------------
    def forcing(self, amps: np.ndarray) -> np.ndarray:
        """Complex forcing F^ (n_fast, B) from drive amplitudes (n_drives, B)."""
        return self.Dmap @ np.asarray(amps, float).reshape(len(self.model.drives), -1)

    def residual_fast(self, A, s, F):
        return F - self.Z0 @ A - (self.G @ s) * A

    def slow_force(self, A):
        return -(self.H @ (np.abs(A) ** 2)) / 2

    def rhs(self, A, s, sd, F):
        """Time derivatives (A', s', s'') for states of shape (n_fast, B), (n_slow, B)."""
        Ad = self._Bsolve(self.residual_fast(A, s, F))
        sdd = (-self.Ks @ s - self.Cs @ sd + self.slow_force(A)) / self.ms[:, None]
        return Ad, sd, sdd

    def fast_response(self, s: np.ndarray, F: np.ndarray) -> np.ndarray:
        """A solving Z(s) A = F for one slow state s (n_slow,) and forcing F (n_fast,)."""
        if self.diagonal:
            return F / (self.z0_diag + self.G @ s)
        Z = (self.Z0 + sp.diags(self.G @ s)).tocsc()
        return spla.spsolve(Z, F)

    # --- real-vector form for Jacobians --------------------------------------
    def pack(self, A, s, sd) -> np.ndarray:
        return np.concatenate([A.real, A.imag, s, sd])

    def unpack(self, y):
        nf, ns = self.fast.size, self.slow.size
        return (y[:nf] + 1j * y[nf:2 * nf]), y[2 * nf:2 * nf + ns], y[2 * nf + ns:]

    def rhs_real(self, y: np.ndarray, F: np.ndarray) -> np.ndarray:
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
