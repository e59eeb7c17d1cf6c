"""Sensitivity of steady states to every element, like SPICE's .sens: the implicit-function theorem.

A steady state solves R(y; t) = 0 with y = (Re A, Im A, s) (envelope.py's equations with A' = 0,
s' = 0) and t the relative changes of the elements (spread.py) and of the drive frequency omega:

    Z(s) A = F,   Z = K - w^2 M + i w C + diag(G s);     K_s s + H |A|^2 / 2 = 0.

Then dy/dt = -(dR/dy)^-1 dR/dt.  R is written in real arithmetic and is a polynomial in y and t, so
both Jacobians come from complex-step differentiation, exact to rounding.  The derivative of an
amplitude |A_o| is (Re A_o dRe A_o + Im A_o dIm A_o) / |A_o|.  tests/test_robustness.py checks it
against central finite differences of the all-roots steady-state scan.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .model import MechModel
from .spread import Element

CS_STEP = 1e-30          # complex step: no subtraction, so any tiny step is exact
NEWTON_STEPS = 2         # the scan's roots are already accurate to ~1e-15


@dataclass
class Operator:
    """The steady-state residual of one model, parametrised by relative element changes."""
    model: MechModel
    elems: list[Element]

    def __post_init__(self):
        m = self.model
        self.fast = np.flatnonzero(~np.asarray(m.slow, bool))
        self.slow = np.flatnonzero(m.slow)
        self.nf, self.ns = self.fast.size, self.slow.size

    @property
    def n_params(self) -> int:
        """How many parameters t holds: every element, then omega."""
        return len(self.elems) + 1                   # the elements, then omega

    def residual(self, y: np.ndarray, t: np.ndarray) -> np.ndarray:
        """R(y; t) in real arithmetic (complex dtypes pass through, for complex steps)."""
        m, nf = self.model, self.nf
        K, C, M, gam, amp, w = self._values(t)
        f, s_ = self.fast, self.slow
        Ar, Ai, s = y[:nf], y[nf:2 * nf], y[2 * nf:]
        shift = np.zeros(m.n, np.result_type(y, gam))
        for (qf, qs, _), g in zip(m.quads, gam):
            shift[qf] = shift[qf] + 2 * g * s[np.searchsorted(s_, qs)]
        Zr = K[np.ix_(f, f)] - w * w * np.diag(M[f]) + np.diag(shift[f])
        Zi = w * C[np.ix_(f, f)]
        Fr, Fi = self._forcing(amp)
        slow_force = np.zeros(self.ns, dtype=Zr.dtype)
        pos = {d: k for k, d in enumerate(f)}
        for (qf, qs, _), g in zip(m.quads, gam):
            k = pos[qf]
            slow_force[np.searchsorted(s_, qs)] += 0.5 * g * (Ar[k] ** 2 + Ai[k] ** 2)
        Ks = K[np.ix_(s_, s_)]
        return np.concatenate([Zr @ Ar - Zi @ Ai - Fr, Zr @ Ai + Zi @ Ar - Fi, Ks @ s + slow_force])

    def _values(self, t: np.ndarray):
        """Dense K, C, masses, gammas, drive amplitudes and omega at relative changes t."""
        m = self.model
        dt = np.result_type(t, float)
        fac = {kind: np.ones(n, dt) for kind, n in (("k", m.n), ("m", m.n), ("c", m.n),
                                                   ("spring", len(m.springs)), ("dashpot", len(m.dashpots)),
                                                   ("gamma", len(m.quads)), ("drive", len(m.drives)))}
        for el, x in zip(self.elems, t[:-1]):
            fac[el.kind][el.index] = fac[el.kind][el.index] * (1 + x)
        K = _matrix(m.k_local * fac["k"], m.springs, fac["spring"])
        C = _matrix(m.c_local * fac["c"], m.dashpots, fac["dashpot"])
        gam = np.array([g for *_, g in m.quads]) * fac["gamma"]
        amp = np.array([d.amplitude for d in m.drives]) * fac["drive"]
        return K, C, np.asarray(m.mass) * fac["m"], gam, amp, m.omega * (1 + t[-1])

    def _forcing(self, amp):
        """Real and imaginary parts of F^ = -i a e^{i phase} on the fast DOFs."""
        pos = {d: k for k, d in enumerate(self.fast)}
        Fr = np.zeros(self.nf, amp.dtype)
        Fi = np.zeros(self.nf, amp.dtype)
        for d, a in zip(self.model.drives, amp):
            Fr[pos[d.dof]] += a * np.sin(d.phase)
            Fi[pos[d.dof]] += -a * np.cos(d.phase)
        return Fr, Fi

    # --- derivatives -----------------------------------------------------------------
    def jac_y(self, y: np.ndarray) -> np.ndarray:
        """dR/dy at the nominal parameters, by complex step (exact to rounding)."""
        t0 = np.zeros(self.n_params)
        return np.column_stack([self.residual(y + 1j * CS_STEP * e, t0).imag / CS_STEP
                                for e in np.eye(y.size)])

    def jac_t(self, y: np.ndarray) -> np.ndarray:
        """dR/dt (every element and omega) at y, by complex step."""
        return np.column_stack([self.residual(y.astype(complex), 1j * CS_STEP * e).imag / CS_STEP
                                for e in np.eye(self.n_params)])

    def pack(self, A: np.ndarray, s: np.ndarray) -> np.ndarray:
        """The real unknowns y = (Re A, Im A, s)."""
        return np.concatenate([A.real, A.imag, np.atleast_1d(s)])

    def polish(self, y: np.ndarray) -> np.ndarray:
        """Newton-polish a steady state (from the scan) to rounding."""
        t0 = np.zeros(self.n_params)
        for _ in range(NEWTON_STEPS):
            y = y - np.linalg.solve(self.jac_y(y), self.residual(y, t0))
        return y

    def out_row(self, dof: int) -> int:
        """The fast-block row of an oscillating DOF."""
        return int(np.flatnonzero(self.fast == dof)[0])

    def amplitude_sensitivity(self, y: np.ndarray, out_dof: int) -> np.ndarray:
        """d|A_out| / dt for every element and omega (last), at steady state y."""
        dy = -np.linalg.solve(self.jac_y(y), self.jac_t(y))
        k = self.out_row(out_dof)
        ar, ai = y[k], y[self.nf + k]
        return (ar * dy[k] + ai * dy[self.nf + k]) / np.hypot(ar, ai)


def _matrix(local, links, factors) -> np.ndarray:
    """Symmetric matrix: local + attached links on the diagonal, -link off it."""
    M = np.diag(np.asarray(local))
    M = M.astype(np.result_type(M, factors))
    for (i, j, k), x in zip(links, factors):
        v = k * x
        M[i, i] += v
        M[j, j] += v
        M[i, j] -= v
        M[j, i] -= v
    return M


# --- the NOR gate, loaded as in a network ------------------------------------------------------
CASES = ((0, 0), (1, 0), (0, 1), (1, 1))


def element_names(elems: list[Element]) -> list[str]:
    """The names of the sensitivity table's columns: the elements, then omega."""
    return [e.name for e in elems] + ["omega"]


def gate_sensitivity(p, per_band: int | None = None, n_grid: int | None = None) -> dict:
    """Sensitivities of the loaded gate (physics/loaded.py) to every element of its block and omega, as
    d(quantity)/d(relative change): the output amplitude (u_R) for the four nominal input pairs, and the
    margin (band widths) at the worst input point and at the limiting point (smallest margin / |gradient|)."""
    from . import loaded, steady_batch
    per_band, n_grid = per_band or loaded.PER_BAND, n_grid or steady_batch.N_GRID
    lg = loaded.build(p)
    elems = spread_elements(lg)
    level = {0: p.levels.nominal0, 1: p.levels.nominal1}
    outputs, amps = {}, {}
    for a, b in CASES:
        g = margin_gradients(p, lg, elems, np.array([[1.0, level[a], level[b]]]), np.array([int(not (a or b))]),
                             n_grid)
        outputs[f"{a}{b}"], amps[f"{a}{b}"] = g["amp_grad"][0], g["amp"][0]
    levels, expect = loaded.input_grid(per_band, p.levels)
    g = margin_gradients(p, lg, elems, levels, expect, n_grid)
    k = int(np.argmin(g["margin"]))
    ratio = np.where(g["margin"] > 0, g["margin"] / np.linalg.norm(g["margin_grad"], axis=1), np.inf)
    j = int(np.argmin(ratio))
    return {"elements": element_names(elems), "outputs": outputs, "amplitudes": amps,
            "worst": {"margin": float(g["margin"][k]), "inputs": levels[k, 1:].tolist(), "output": g["amp"][k],
                      "gradient": g["margin_grad"][k]},
            "limiting": {"margin": float(g["margin"][j]), "inputs": levels[j, 1:].tolist(), "output": g["amp"][j],
                         "gradient": g["margin_grad"][j], "sigma_1": float(ratio[j]),
                         "gradient_norm": float(np.linalg.norm(g["margin_grad"][j]))},
            "grid_points": int(levels.shape[0])}


def spread_elements(lg) -> list[Element]:
    """The elements the loaded gate's spread covers (its block and its load pair)."""
    from .spread import elements
    return elements(lg.model, lg.block_dofs)


def margin_gradients(p, lg, elems, levels: np.ndarray, expect: np.ndarray, n_grid: int) -> dict:
    """Per input point: the margin of its worst stable state, that state's output (u_R), and the gradients
    of both (NaN where no state is stable)."""
    from . import loaded, steady_batch
    st = steady_batch.stack([lg.model], lg.input_groups(), lg.gate.channel)
    r = steady_batch.roots(st, 0, levels, n_grid)
    margin = loaded.point_margins(r, expect, p.u_r, p.levels)
    n = levels.shape[0]
    amp, amp_grad = np.full(n, np.nan), np.full((n, len(elems) + 1), np.nan)
    for k in range(n):
        idx = np.flatnonzero((r.point == k) & r.stable)
        if not idx.size:
            continue
        i = idx[np.argmin(loaded.band_margin(r.amp[idx] / p.u_r, np.full(idx.size, expect[k]), p.levels))]
        op = Operator(loaded.at_inputs(lg, *levels[k, 1:]), elems)
        A = steady_batch.responses(st, 0, r.s[i:i + 1])[0] @ levels[k]
        y = op.polish(op.pack(A, r.s[i:i + 1]))
        amp[k] = np.hypot(y[op.out_row(lg.gate.channel)], y[op.nf + op.out_row(lg.gate.channel)]) / p.u_r
        amp_grad[k] = op.amplitude_sensitivity(y, lg.gate.channel) / p.u_r
    lo, hi = loaded.band_edges(expect, p.levels)
    sign = np.where(amp - lo < hi - amp, 1.0, -1.0)
    return {"margin": margin, "amp": amp, "amp_grad": amp_grad,
            "margin_grad": amp_grad * (sign / (hi - lo))[:, None]}
