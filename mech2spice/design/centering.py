"""Design centering of the NOR block by worst-case distance (issue #27; docs/design.md, "Design centering").

The loaded gate (physics/loaded.py) passes when, at every valid input point, its stable steady state stays
inside the band NOR asks for and does not vanish.  Both are linearised in the relative element changes t
(physics/spread.py's elements), t = spread * Sa xi + residual * Sb zeta with xi, zeta standard normal:

  * a *margin constraint* per stable steady state: its band margin m (band widths) and gradient g;
  * a *fold constraint* per local extremum of the insulator's balance r(s) (steady_batch: r(s) = k_s s +
    1/2 sum h |A(s)|^2, one equation in s per input point): where an extremum's value r_e crosses zero a
    pair of steady states is born or dies, so a state jumps or a new one appears.  r_e's first-order
    change is dr/dt at fixed s (dr/ds = 0 there), so its distance is linear in t, not a square root;
  * a *stability constraint* per stable steady state: minus its growth rate (the leading eigenvalue of the
    envelope Jacobian J there, steady_batch.jacobian), whose change is w^T (dJ/dt + dJ/dA dA/dt + dJ/ds ds/dt) v
    / (w^T v) with v, w the right and left eigenvectors and dA/dt, ds/dt the state's own first-order change
    (`Fast.growth`): under spread a state at another input point than the nominal block's slowest may lose
    stability first (measured on centered_fc as centred, docs/design.md).

Each constraint's worst-case distance is beta = m / ||S^T g|| (in standard deviations of the spread along
its most dangerous direction).  Both come from one adjoint solve per state: the steady state reduces to
r(s) = 0 with A = Z(s)^-1 F, so dA/dt = -Z^-1 (dZ/dt A - dF/dt) at fixed s and ds/dt = -dr/dt / r'(s);
tests/test_centering.py checks the margin gradients against sensitivity.margin_gradients (the
implicit-function theorem on the full residual) and every kind against finite differences.

Trimming (the sigma vector): after fabrication every oscillating DOF of the block has its total k/m (and
with 'fc' its total c/m) set back to nominal through its local spring (dashpot), with a relative residual:
linearised, the local k's change is (K_tot (t_m + residual) - sum of attached coupling springs' changes)
/ k_local; the insulator, couplings, gammas and drives keep the full spread.

The optimiser (`step`) maximises the smallest beta over all constraints of the coarse input grid by
sequential linear programming with a trust region over the block's parameters (`Design`), with forward
finite differences of the active constraints (their states tracked by input point and s).  Continuation in
sigma: each step works at the spread where the block's smallest beta is Z99 (the linear tolerance), capped
at the target spread.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import Mech2SpiceError
from ..inputs import head
from ..schema import ANY, BOOL, COUNT, NUMBER, Leaf, Map, Opt, SchemaError, check_finite
from ..physics import loaded, spread, steady_batch
from ..physics.params import GateParams, Levels

Z99 = 2.3263478740408408        # one-sided standard normal quantile of 99 %
TRIMS = spread.LINEAR_TRIMS


# --- the spread (one relative sigma, trimmed or not) and its noise matrices ---------------------------------------------------------
@dataclass(frozen=True)
class TrimmedSpread:
    """Relative Gaussian spread on every element; optionally trimmed ('f': k/m, 'fc': k/m and c/m of every
    oscillating DOF of the block) back to nominal with a relative residual."""
    spread: float
    trim: str = "none"
    residual: float = 0.0

    def validate(self) -> None:
        """Raise Mech2SpiceError on a spread or residual outside [0, 1] or an unknown trim."""
        for name, v in (("--spread", self.spread), ("--trim-residual", self.residual)):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and 0 <= v <= 1):
                raise Mech2SpiceError(f"{name} must be a relative sigma in [0, 1], got {v!r}")
        if self.trim not in TRIMS:
            raise Mech2SpiceError(f"--trim must be one of {', '.join(TRIMS)}, got {self.trim!r}")
        if self.spread <= 0:
            raise Mech2SpiceError("--spread must be > 0: centering needs a spread to center against")


def noise_matrices(model, elems: list[spread.Element], trim: str):
    """(Sa, Sb, residual names): t = spread Sa xi + residual Sb zeta for the elements `elems`, trimmed as
    `trim` says: physics/spread.py's linearised trim (trim_map), its coordinates split by what spreads them."""
    J = spread.trim_map(model, elems, trim)
    by_spread = spread.sigmas(elems, model, 1.0, trim, 0.0) == 1.0      # the rest: trim residuals
    names = [f"trim residual {e.name}" for e, s in zip(elems, by_spread) if not s]
    return J[:, by_spread], J[:, ~by_spread], names


# --- states and their first-order changes ------------------------------------------------------------
@dataclass
class Fast:
    """The loaded gate's envelope arrays at input level 1 (steady_batch's), plus what the derivatives need:
    `d`, per element the change of the envelope's coefficients per unit relative change (`derivatives`)."""
    lg: loaded.LoadedGate
    elems: list[spread.Element]
    st: steady_batch.Stack
    fast: np.ndarray          # model DOF index of each fast row
    slow: int
    d: dict

    @classmethod
    def of(cls, p: GateParams) -> "Fast":
        lg = loaded.build(p)
        m = lg.model
        st = steady_batch.stack([m], lg.input_groups(), lg.gate.channel)
        elems, fast, slow = spread.elements(m, lg.block_dofs), np.flatnonzero(~np.asarray(m.slow, bool)), \
            int(np.flatnonzero(m.slow)[0])
        return cls(lg, elems, st, fast, slow, derivatives(m, elems, fast, slow, lg.input_groups(), st.groups))

    def state(self, levels: np.ndarray, s: np.ndarray) -> dict:
        """At slow positions s (n,) and input levels (n, G): A, r, dr/ds, dA/ds, and at fixed s the
        derivatives dr/dt (n, E) and dA/dt (n, nf, E) for every element (A_out etc.: the output row)."""
        st, d = self.st, self.d
        nf = self.fast.size
        Z = st.Z0[0][None] + (st.g[0][None, :, None] * np.eye(nf)[None]) * s[:, None, None]
        F = np.einsum("fg,ng->nf", st.f[0], levels)
        A = np.linalg.solve(Z, F[..., None])[..., 0]
        dA_ds = -np.linalg.solve(Z, (st.g[0] * A)[..., None])[..., 0]
        h = st.h[0]
        r = st.ks[0] * s + 0.5 * (h * np.abs(A) ** 2).sum(axis=1)
        r_s = st.ks[0] + (h * (A.conj() * dA_ds).real).sum(axis=1)
        D = (np.einsum("eij,nj->nie", d["Z0"], A) + d["g"].T[None] * (s[:, None] * A)[..., None]
             - np.einsum("eig,ng->nie", d["F"], levels))                    # d(Z A - F)/dt at fixed s
        direct = d["ks"][None] * s[:, None] + 0.5 * np.abs(A) ** 2 @ d["h"].T
        X = np.linalg.solve(Z, D)                                   # dA/dt = -X at fixed s
        r_t = direct - np.einsum("f,nf,nfe->ne", h, A.conj(), X).real
        o = st.out
        return {"A": A, "r": r, "r_s": r_s, "A_out": A[:, o], "dAo_ds": dA_ds[:, o], "r_t": r_t,
                "dAo_dt": -X[:, o, :], "dA_ds": dA_ds, "dA_dt": -X}

    def growth(self, A: np.ndarray, s: np.ndarray, dA: np.ndarray, ds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Growth rate (n,) of steady states (A, s) and its total derivative (n, E) for the states' own
        first-order changes dA (n, nf, E), ds (n, E): d lambda = w^T dJ v / (w^T v) for the leading eigenvalue
        of the envelope Jacobian J (steady_batch.jacobian, variables Re A, Im A, s, s'), v and w its right and
        left eigenvectors, dJ = dJ/dt at fixed state + dJ/dA dA + dJ/ds ds (J is affine in A and s)."""
        st, d = self.st, self.d
        n, nf = A.shape
        lam, V = np.linalg.eig(steady_batch.jacobian(st, 0, A, s))
        k = np.argmax(lam.real, axis=1)
        i = np.arange(n)
        v, w = V[i, :, k], np.linalg.inv(V)[i, k, :]                # w V = 1: the left eigenvector, normalised
        Bi, g, h, ms = st.Binv[0], st.g[0], st.h[0], st.ms[0]
        eye = np.eye(nf)
        M1 = -Bi @ (st.Z0[0][None] + g[None, :, None] * eye * s[:, None, None])
        vA = -(Bi @ (g * A).T).T
        dM1 = -Bi @ (np.einsum("eij,njk->neik", d["B"], M1) + d["Z0"][None]
                     + d["g"][None, :, :, None] * eye * s[:, None, None, None] + g[:, None] * eye * ds[..., None, None])
        dv = -np.einsum("ij,nej->nei", Bi, np.einsum("eij,nj->nei", d["B"], vA) + d["g"][None] * A[:, None]
                        + g * dA.transpose(0, 2, 1))
        drow = -(d["h"][None] * A[:, None] + h * dA.transpose(0, 2, 1)) / ms + (h * A / ms)[:, None] * d["ms"][:, None] / ms
        dJ = np.zeros((n, len(self.elems), 2 * nf + 2, 2 * nf + 2))
        dJ[..., :nf, :nf], dJ[..., :nf, nf:2 * nf] = dM1.real, -dM1.imag
        dJ[..., nf:2 * nf, :nf], dJ[..., nf:2 * nf, nf:2 * nf] = dM1.imag, dM1.real
        dJ[..., :nf, 2 * nf], dJ[..., nf:2 * nf, 2 * nf] = dv.real, dv.imag
        dJ[..., 2 * nf + 1, :nf], dJ[..., 2 * nf + 1, nf:2 * nf] = drow.real, drow.imag
        dJ[..., 2 * nf + 1, 2 * nf] = (-d["ks"] + st.ks[0] * d["ms"] / ms)[None] / ms
        dJ[..., 2 * nf + 1, 2 * nf + 1] = (-d["cs"] + st.cs[0] * d["ms"] / ms)[None] / ms
        return lam.real[i, k], np.einsum("ni,nei->ne", w, (dJ @ v[:, None, :, None])[..., 0]).real


def derivatives(m, elems: list[spread.Element], fast: np.ndarray, slow: int, groups, n_groups: int) -> dict:
    """Per element e, the change per unit relative change t_e of the envelope's coefficients (steady_batch's
    arrays): Z0 and B = 2 i w M + C of the fast block (E, nf, nf), g = 2 gamma and h = gamma (E, nf), the
    insulator's ks, cs, ms (E,), and the forcing F at level 1 (E, nf, groups)."""
    nf, E, w = fast.size, len(elems), m.omega
    pos = -np.ones(m.n, int)
    pos[fast] = np.arange(nf)
    d = {"Z0": np.zeros((E, nf, nf), complex), "B": np.zeros((E, nf, nf), complex), "g": np.zeros((E, nf)),
         "h": np.zeros((E, nf)), "ks": np.zeros(E), "cs": np.zeros(E), "ms": np.zeros(E),
         "F": np.zeros((E, nf, n_groups), complex)}
    kl, cl = m.k_local, m.c_local
    for j, e in enumerate(elems):
        i = e.index
        if e.kind in ("k", "m", "c") and i == slow:
            d[e.kind + "s"][j] = {"k": kl, "m": m.mass, "c": cl}[e.kind][i]
        elif e.kind in ("k", "m", "c"):
            a = pos[i]
            d["Z0"][j, a, a] = {"k": kl[i], "m": -w * w * m.mass[i], "c": 1j * w * cl[i]}[e.kind]
            d["B"][j, a, a] = {"k": 0.0, "m": 2j * w * m.mass[i], "c": cl[i]}[e.kind]
        elif e.kind in ("spring", "dashpot"):
            a, b, v = (m.springs if e.kind == "spring" else m.dashpots)[i]
            u = np.zeros(nf)
            u[pos[a]], u[pos[b]] = 1.0, -1.0
            d["Z0"][j] = (v if e.kind == "spring" else 1j * w * v) * np.outer(u, u)
            d["B"][j] = (0.0 if e.kind == "spring" else v) * np.outer(u, u)
        elif e.kind == "gamma":
            f, _, gam = m.quads[i]
            d["g"][j, pos[f]], d["h"][j, pos[f]] = 2 * gam, gam
        else:                                                        # a drive: only the forcing moves
            dr = m.drives[i]
            d["F"][j, pos[dr.dof], groups[i]] = -1j * dr.amplitude * np.exp(1j * dr.phase)
    return d


@dataclass
class Constraints:
    """Every linearised pass condition of one block over an input grid."""
    kind: np.ndarray          # "margin", "stability" or "fold"
    point: np.ndarray         # input-point index
    s: np.ndarray             # the state's (or extremum's) insulator position
    value: np.ndarray         # margin (band widths), -growth rate (1/time) or |r_e|
    grad: np.ndarray          # (n, E) d value / dt
    nominal_margin: float     # the block's worst margin over the grid (point_margins)
    growth: float             # the largest growth rate (1/time) of any stable state over the grid
    growth_at: tuple[int, float]   # ... its input point and s

    def variances(self, Sa, Sb) -> tuple[np.ndarray, np.ndarray]:
        """Per constraint ||Sa^T g||^2 and ||Sb^T g||^2."""
        return (self.grad @ Sa) ** 2 @ np.ones(Sa.shape[1]), (self.grad @ Sb) ** 2 @ np.ones(Sb.shape[1])


def constraints(fx: Fast, levels: np.ndarray, expect: np.ndarray, p: GateParams, n_grid: int) -> Constraints:
    """The margin and stability constraints (every stable state) and fold constraints (every extremum of
    r(s)) of the loaded gate at the input points `levels` (P, G) with expected outputs `expect`."""
    st, u_r = fx.st, p.u_r
    r = steady_batch.roots(st, 0, levels, n_grid)
    nominal = float(loaded.point_margins(r, expect, u_r, p.levels).min())
    keep = r.stable
    pts, s_roots = r.point[keep], r.s[keep]
    sr = fx.state(levels[pts], s_roots)
    lo, hi = loaded.band_edges(expect[pts], p.levels)
    a = np.abs(sr["A_out"]) / u_r
    sign = np.where(a - lo < hi - a, 1.0, -1.0)
    ds_dt = -sr["r_t"] / sr["r_s"][:, None]
    dAo = sr["dAo_dt"] + sr["dAo_ds"][:, None] * ds_dt
    da = (sr["A_out"].conj()[:, None] * dAo).real / np.abs(sr["A_out"])[:, None] / u_r
    m_val = np.minimum(a - lo, hi - a) / (hi - lo)
    m_grad = da * (sign / (hi - lo))[:, None]
    g_val, g_grad = fx.growth(sr["A"], s_roots, sr["dA_dt"] + sr["dA_ds"][..., None] * ds_dt[:, None], ds_dt)
    ep, es = extrema(st, levels, n_grid)
    se = fx.state(levels[ep], es)
    f_val, f_grad = np.abs(se["r"]), np.sign(se["r"])[:, None] * se["r_t"]
    kind = np.array(["margin"] * pts.size + ["stability"] * pts.size + ["fold"] * ep.size)
    return Constraints(kind, np.concatenate([pts, pts, ep]), np.concatenate([s_roots, s_roots, es]),
                       np.concatenate([m_val, -g_val, f_val]), np.concatenate([m_grad, -g_grad, f_grad]), nominal,
                       *_slowest(r.growth[keep], pts, s_roots))


def _slowest(growth: np.ndarray, pts: np.ndarray, s: np.ndarray) -> tuple[float, tuple[int, float]]:
    """The largest growth rate among the stable states and where (point, s)."""
    if not growth.size:
        return -math.inf, (-1, math.nan)
    k = int(np.argmax(growth))
    return float(growth[k]), (int(pts[k]), float(s[k]))


def extrema(st: steady_batch.Stack, levels: np.ndarray, n_grid: int) -> tuple[np.ndarray, np.ndarray]:
    """(point, s) of every interior local extremum of r(s) over the roots' s range, refined by a parabola
    through the grid's three points around it."""
    lo, hi = steady_batch.root_range(st, 0, np.abs(levels).max(axis=0))
    s = np.linspace(lo, hi, n_grid)
    W = steady_batch.w_matrix(st, 0, steady_batch.responses(st, 0, s)).reshape(n_grid, -1)
    q = (levels[:, :, None] * levels[:, None, :]).reshape(levels.shape[0], -1)
    r = st.ks[0] * s[None, :] + 0.5 * q @ W.T                        # (P, S)
    d = np.diff(r, axis=1)
    p, j = np.nonzero(np.signbit(d[:, 1:]) != np.signbit(d[:, :-1]))
    j = j + 1                                                        # the grid point at the turn
    r0, r1, r2 = r[p, j - 1], r[p, j], r[p, j + 1]
    den = r0 - 2 * r1 + r2
    shift = np.where(den != 0, 0.5 * (r0 - r2) / np.where(den != 0, den, 1), 0.0)
    return p, s[j] + np.clip(shift, -1, 1) * (s[1] - s[0])


# --- worst-case distances ------------------------------------------------------------------------
@dataclass
class Analysis:
    """One block's constraints under one spread spec."""
    p: GateParams
    spec: TrimmedSpread
    cons: Constraints
    a: np.ndarray            # per constraint: variance per unit spread^2
    b: np.ndarray            # ... per unit residual^2
    levels: np.ndarray
    elements: list[str]      # names of the noise sources: every element, then the trim residuals
    sources: np.ndarray      # (n, sources) g^T Sa, g^T Sb
    n_elements: int          # how many of the sources are elements (the rest: trim residuals)
    fx: Fast
    noise: tuple             # (Sa, Sb)
    n_grid: int

    def beta(self, spread_: float | None = None) -> np.ndarray:
        """Per constraint worst-case distance at spread `spread_` (default the spec's) and the spec's residual."""
        s = self.spec.spread if spread_ is None else spread_
        var = s * s * self.a + self.spec.residual ** 2 * self.b
        return np.where(var > 0, self.cons.value / np.sqrt(np.maximum(var, 1e-300)), np.inf)

    def tolerance(self) -> float:
        """The linear tolerance: the largest spread at which every constraint keeps beta >= Z99 (0 where the
        residual alone brings one below it, or the nominal block fails)."""
        if not self.cons.nominal_margin > 0:
            return 0.0
        room = (self.cons.value / Z99) ** 2 - self.spec.residual ** 2 * self.b
        with np.errstate(divide="ignore"):
            s = np.where(room > 0, np.sqrt(np.maximum(room, 0) / self.a), 0.0)
        return float(s.min())

    def limiting(self, spread_: float | None = None) -> dict:
        """The smallest-beta constraint: its kind, input point, beta, and the element contributing most."""
        beta = self.beta(spread_)
        k = int(np.argmin(beta))
        s = self.spec.spread if spread_ is None else spread_
        n_res = self.sources.shape[1] - self.n_elements
        scale = np.concatenate([np.full(self.n_elements, s), np.full(n_res, self.spec.residual)])
        contrib = (self.sources[k] * scale) ** 2
        top, total = np.argsort(-contrib)[:3], float(contrib.sum())
        return {"kind": str(self.cons.kind[k]), "inputs": self.levels[self.cons.point[k], 1:].tolist(),
                "s": float(self.cons.s[k]), "value": float(self.cons.value[k]), "beta": float(beta[k]),
                "elements": [{"name": self.elements[i],      # no share where the spread underflows to nothing
                              "share": float(contrib[i]) / total if total > 0 else None} for i in top]}


def analyse(p: GateParams, spec: TrimmedSpread, per_band: int = 6, n_grid: int = 1000) -> Analysis:
    """Every constraint of block p over the input grid (per_band levels per band) and its variances."""
    fx = Fast.of(p)
    levels, expect = loaded.input_grid(per_band, p.levels)
    cons = constraints(fx, levels, expect, p, n_grid)
    Sa, Sb, res_names = noise_matrices(fx.lg.model, fx.elems, spec.trim)
    a, b = cons.variances(Sa, Sb)
    sources = np.concatenate([cons.grad @ Sa, cons.grad @ Sb], axis=1)
    return Analysis(p, spec, cons, a, b, levels, [e.name for e in fx.elems] + res_names, sources, len(fx.elems),
                    fx, (Sa, Sb), n_grid)


# --- the design variables ------------------------------------------------------------------------
W_SEED = GateParams().omega
# name -> (DOFs it sets, what): d* detuning k = m w^2 (1 + d); lq*, lm* log10 of Q and mass
# The four gate oscillators stay identical: a spring- and a dashpot-linked oscillator that differ break the
# cancellation of their back-action on the upstream output (physics/loaded.py), and a first version that let
# them differ found blocks that pass as the loaded gate (one load) and fail fan-out 2 and 3 (measured).
DOF_VARS = {"c": ("C",), "g": ("G1s", "G1d", "G2s", "G2d")}
LOG_VARS = ("lk_i", "lgam_g", "lgam_ic", "lf_c", "lq_i")
LEVEL_VARS = ("band0_lo", "band0_hi", "band1_lo", "band1_hi")
STEP0 = {"d": 2e-4, "l": 2e-3, "b": 2e-3}    # initial trust region per coordinate: detunings, log10 values, bands
FD_STEP = {"d": 1e-7, "l": 1e-6, "b": 1e-6}
WIDTH_FLOOR = 0.05        # the narrowest band (u_R, F_R) the optimiser may make
GAP_FLOOR = 0.02          # ... and the narrowest gap between band 0 and band 1
# Every stable state over the grid must decay at least this fast (1/time; the default block's slowest decays
# at 0.0064): without it the optimiser walks the robust block to a Hopf point of the insulator mode at the
# (1, 1) corner (growth -1e-5, measured), which no margin or fold constraint sees.
GROWTH_FLOOR = 0.005


@dataclass(frozen=True)
class Design:
    """The classic block's parameters as a vector x: for the channel c and the (identical) gate oscillators
    g their detuning, log10 Q and log10 mass; log10 of the insulator stiffness, of the gammas, of the
    source force and of the insulator's Q.  The insulator's mass, omega, F_R and u_R are the seed's.  With `levels`, the four band edges too (docs/design.md):
    a block's bands are its own data, and the window between them is what its threshold must fall in."""
    seed: GateParams
    levels: bool = True

    @property
    def names(self) -> list[str]:
        return ([f"{v}_{k}" for k in DOF_VARS for v in ("d", "lq", "lm")] + list(LOG_VARS)
                + list(LEVEL_VARS if self.levels else ()))

    def x0(self) -> np.ndarray:
        """The seed block as a vector (refuses a block that is not classic-shaped)."""
        b = self.seed.structure
        names = {d.name for d in b.dofs}
        gam = {f: g for f, _, g in b.quads}
        gates = DOF_VARS["g"]
        if names != {"C", "I", *gates} or b.springs or b.dashpots or b.output != "C":
            raise Mech2SpiceError(f"centering needs a classic-shaped block (C, I, G1s, G1d, G2s, G2d), "
                                  f"not '{self.seed.name}' ({b.name})")
        if len({(b.dof(n).m, b.dof(n).k, b.dof(n).q, gam[n]) for n in gates}) > 1:
            raise Mech2SpiceError(f"centering needs the block's four gate oscillators identical ('{self.seed.name}')")
        w2 = self.seed.omega ** 2
        x = []
        for dofs in DOF_VARS.values():
            d = b.dof(dofs[0])
            x += [d.k / (d.m * w2) - 1, math.log10(d.q), math.log10(d.m)]
        x += [math.log10(b.dof("I").k), math.log10(gam["G1s"]), math.log10(-gam["C"]),
              math.log10(b.source_force), math.log10(b.dof("I").q)]
        if self.levels:
            x += [*self.seed.levels.band0, *self.seed.levels.band1]
        return np.array(x)

    def params(self, x) -> GateParams:
        """The block at vector x."""
        from ..physics.blocks import BlockSpec, Dof
        from ..physics.params import block_params
        v = dict(zip(self.names, np.asarray(x, float)))
        b, w2 = self.seed.structure, self.seed.omega ** 2
        dofs = []
        for key, names in DOF_VARS.items():
            m = 10.0 ** v[f"lm_{key}"]
            dofs += [Dof(n, m, m * w2 * (1 + v[f"d_{key}"]), 10.0 ** v[f"lq_{key}"]) for n in names]
        ins = b.dof("I")
        dofs.insert(1, Dof("I", ins.m, 10.0 ** v["lk_i"], 10.0 ** v["lq_i"], slow=True))
        quads = [("C", "I", -10.0 ** v["lgam_ic"])] + [(n, "I", 10.0 ** v["lgam_g"]) for n in DOF_VARS["g"]]
        spec = BlockSpec(b.name, tuple(dofs), (), (), tuple(quads), "C", 10.0 ** v["lf_c"], "C", b.inputs)
        return block_params({"block": spec.to_dict(), "name": self.seed.name, "f_r": self.seed.f_r,
                             "u_r": self.seed.u_r, "omega": self.seed.omega,
                             "levels": self._levels(v).to_dict()}, "centering")

    def _levels(self, v: dict) -> Levels:
        """The seed's levels, or the bands of v with the seed's nominal levels where they stay inside
        (else the band's middle)."""
        old = self.seed.levels
        if not self.levels:
            return old
        bands = ((v["band0_lo"], v["band0_hi"]), (v["band1_lo"], v["band1_hi"]))
        nominal = [old.nominal(bit) if lo <= old.nominal(bit) <= hi else (lo + hi) / 2
                   for bit, (lo, hi) in enumerate(bands)]
        return Levels(*bands, *nominal)

    def scale(self, table: dict) -> np.ndarray:
        """Per coordinate: table['d'] for detunings, table['l'] for log10 values, table['b'] for band edges."""
        return np.array([table[n[0]] for n in self.names])

    def linear(self, x) -> tuple[np.ndarray, np.ndarray]:
        """(A, b): A dx <= b keeps the bands ordered, each at least WIDTH_FLOOR wide, GAP_FLOOR apart, >= 0."""
        if not self.levels:
            return np.zeros((0, x.size)), np.zeros(0)
        i = [self.names.index(n) for n in LEVEL_VARS]
        rows, b = [], []
        for lo, hi, floor in ((None, i[0], 0.0), (i[0], i[1], WIDTH_FLOOR), (i[1], i[2], GAP_FLOOR),
                              (i[2], i[3], WIDTH_FLOOR)):
            row = np.zeros(x.size)                       # x[hi] + dx[hi] - x[lo] - dx[lo] >= floor
            row[hi] = -1.0
            if lo is not None:
                row[lo] = 1.0
            rows.append(row)
            b.append(x[hi] - (x[lo] if lo is not None else 0.0) - floor)
        return np.array(rows), np.array(b)


# --- the optimiser ---------------------------------------------------------------------------------
ACTIVE_RATIO = 2.0        # constraints within this factor of the smallest beta enter the step's LP
ACTIVE_MAX = 300
TRUST_MAX = 64.0          # the trust region's growth cap, in multiples of STEP0
TRUST_MIN = 1e-3          # ... and where it stops shrinking: the run has converged


@dataclass
class Settings:
    """What a centering run is: the seed, the spread spec, the grid; a resumed run must match it."""
    seed_name: str
    spec: TrimmedSpread
    per_band: int = 6
    n_grid: int = 1000
    levels: bool = True          # the band edges are design variables
    growth_floor: float = GROWTH_FLOOR

    def to_dict(self) -> dict:
        return {"from": self.seed_name, "variables": Design(GateParams(), self.levels).names, "stability": "per state",
                "growth_floor": self.growth_floor, "spread": self.spec.spread, "trim": self.spec.trim,
                "trim_residual": self.spec.residual, "per_band": self.per_band, "n_grid": self.n_grid}


class Centering:
    """Maximise the smallest beta of the block `design` over its vector x (module docstring)."""

    def __init__(self, design: Design, settings: Settings):
        self.design, self.settings = design, settings
        self.trust0, self.fd = design.scale(STEP0), design.scale(FD_STEP)

    def analyse(self, x) -> Analysis:
        """The block at x under the run's spec; a block the model rejects is an Analysis-less None."""
        st = self.settings
        try:
            with np.errstate(over="raise", invalid="raise", divide="raise"):
                return analyse(self.design.params(x), st.spec, st.per_band, st.n_grid)
        except (Mech2SpiceError, np.linalg.LinAlgError, FloatingPointError, ValueError):
            return None

    @staticmethod
    def works_on_full_grid(p: GateParams) -> bool:
        """The nominal gate's margin > 0 on `gate --spread`'s grid (15 levels per band, 4000 s points): the
        coarse grid's points alone let a first version walk into multistable slivers between them."""
        lg = loaded.build(p)
        levels, expect = loaded.input_grid(loaded.PER_BAND, p.levels)
        st = steady_batch.stack([lg.model], lg.input_groups(), lg.gate.channel)
        r = steady_batch.roots(st, 0, levels, steady_batch.N_GRID)
        return bool(loaded.point_margins(r, expect, p.u_r, p.levels).min() > 0)

    def working_spread(self, an: Analysis) -> float:
        """Continuation: the spread at which the block's smallest beta is Z99, within [1e-7, target]."""
        return float(np.clip(an.tolerance(), 1e-7, self.settings.spec.spread))

    @staticmethod
    def score(an: Analysis | None, s_w: float) -> float:
        """The smallest beta at spread s_w; -inf for a block that fails nominally (or does not build)."""
        if an is None or not an.cons.nominal_margin > 0:
            return -math.inf
        return float(an.beta(s_w).min())

    def jacobian(self, x, an: Analysis, active: np.ndarray, s_w: float) -> tuple[np.ndarray, np.ndarray]:
        """Forward differences over x of the active constraints' betas (a constraint that cannot be tracked,
        its state vanished, gets a zero entry) and of the largest growth rate."""
        base = an.beta(s_w)[active]
        J, Jg = np.zeros((active.size, x.size)), np.zeros(x.size)
        for i in range(x.size):
            xi = x.copy()
            xi[i] += self.fd[i]
            other = self.analyse(xi)
            if other is None:
                continue
            J[:, i] = (_match(an, other, active, s_w) - base) / self.fd[i]
            Jg[i] = (other.cons.growth - an.cons.growth) / self.fd[i]
        return np.where(np.isfinite(J), J, 0.0), np.where(np.isfinite(Jg), Jg, 0.0)

    def growth_caps(self, an: Analysis) -> tuple[float, float]:
        """(what the step's LP aims at, what a trial may have) for the largest growth rate: -floor, or no
        worse than now for a block above it; a trial may overshoot the aim by 2 % of the floor (the LP is
        linear, the growth rate is not, and it sits on its bound once active)."""
        floor = self.settings.growth_floor
        aim = an.cons.growth if an.cons.growth > -0.9 * floor else -floor
        return aim, max(aim, -floor) + 0.02 * floor

    def lp(self, an: Analysis, beta, J, Jg, radius, x):
        """The step's LP; a block above the growth floor is first asked to come 10 % of the floor nearer it
        (then, where that is infeasible in the trust region, only not to get worse)."""
        A_lin, b_lin = self.design.linear(x)
        aim, _ = self.growth_caps(an)
        floor = self.settings.growth_floor
        for target in ((max(aim - 0.1 * floor, -floor), aim) if aim > -floor else (aim,)):
            dx, gain = _lp_step(beta, J, radius, np.vstack([A_lin, Jg]), np.r_[b_lin, target - an.cons.growth])
            if np.any(dx):
                break
        return dx, gain

    def step(self, x, trust: float, log=lambda msg: None) -> dict:
        """One trust-region SLP step from x; returns the step's record (x_new is x when rejected)."""
        an = self.analyse(x)
        s_w = self.working_spread(an)
        beta = an.beta(s_w)
        active = np.argsort(beta)[:ACTIVE_MAX]
        active = active[beta[active] <= ACTIVE_RATIO * beta[active[0]]]
        J, Jg = self.jacobian(x, an, active, s_w)
        _, cap = self.growth_caps(an)
        dx, predicted = self.lp(an, beta[active], J, Jg, trust * self.trust0, x)
        trial = self.analyse(x + dx)
        new = self.score(trial, s_w) if trial is not None and trial.cons.growth <= cap else -math.inf
        if an.cons.growth > -self.settings.growth_floor and trial is not None and new > -math.inf:
            new = new if trial.cons.growth < an.cons.growth else -math.inf    # above the floor: growth must fall
        old = float(beta.min())
        accepted = new > old and self.works_on_full_grid(trial.p)
        rho = (new - old) / predicted if predicted > 0 else 0.0
        trust_next = trust * (2.0 if accepted and rho > 0.5 else 0.5 if accepted and rho > 0.1 else 0.25)
        rec = {"working_spread": s_w, "beta_before": old, "beta_after": new, "predicted_gain": predicted,
               "accepted": bool(accepted), "trust": trust, "trust_next": float(min(trust_next, TRUST_MAX)),
               "active": int(active.size), "limiting": an.limiting(s_w)}
        done = trial if accepted else an
        rec.update(_figures(done))
        rec["x"] = [float(v) for v in (x + dx if accepted else x)]
        return rec


def _match(an: Analysis, other: Analysis, active: np.ndarray, s_w: float) -> np.ndarray:
    """The betas in `other` of an's constraints `active`: same kind and input point, nearest s."""
    ob = other.beta(s_w)
    out = np.full(active.size, np.nan)
    for n, k in enumerate(active):
        same = np.flatnonzero((other.cons.kind == an.cons.kind[k]) & (other.cons.point == an.cons.point[k]))
        if same.size:
            out[n] = ob[same[np.argmin(np.abs(other.cons.s[same] - an.cons.s[k]))]]
    return out


def _lp_step(beta: np.ndarray, J: np.ndarray, radius: np.ndarray, A_lin: np.ndarray,
             b_lin: np.ndarray) -> tuple[np.ndarray, float]:
    """max tau s.t. beta + J dx >= tau, A_lin dx <= b_lin, |dx| <= radius: the step and its predicted gain
    of min beta."""
    from scipy.optimize import linprog
    n = radius.size
    A = np.vstack([np.hstack([-J * radius[None, :], np.ones((beta.size, 1))]),     # in u = dx / radius
                   np.hstack([A_lin * radius[None, :], np.zeros((b_lin.size, 1))])])
    res = linprog(np.r_[np.zeros(n), -1.0], A_ub=A, b_ub=np.r_[beta, b_lin],
                  bounds=[(-1, 1)] * n + [(None, None)], method="highs")
    if not res.success:
        return np.zeros(n), 0.0
    return res.x[:n] * radius, float(res.x[n] - beta.min())


def _figures(an: Analysis | None) -> dict:
    """What the record keeps of a block's analysis: nominal margin, linear tolerance, beta at the target."""
    if an is None:
        return {"nominal_margin": None, "tolerance_linear": 0.0, "beta_target": None}
    beta = an.beta()
    stab = an.cons.kind == "stability"
    return {"nominal_margin": an.cons.nominal_margin, "growth": an.cons.growth, "tolerance_linear": an.tolerance(),
            "beta_target": float(beta.min()), "beta_stability_target": float(beta[stab].min()) if stab.any() else None,
            "limiting_target": an.limiting()}


# --- a resumable run ---------------------------------------------------------------------------------
FORMAT = "mech2spice-centering"
RECORD, BEST = "centering.json", "best.json"


def _is_best(path) -> bool:
    return b'"method": "design centering' in head(path, 1 << 20)


BEST_KIND = ("a block `center` wrote", _is_best)


# A record as run() reads it back (docs/architecture.md, "Files the tool reads back"), in mech2spice/schema.py's
# language; each step's x is also as long as the block's variables.  FIGURES are what the summary prints and
# best.json keeps.
POSITIVE = Leaf("a number > 0", lambda v: NUMBER.test(v) and v > 0)
STEP = {"step": COUNT, "x": [NUMBER], "trust_next": POSITIVE, "accepted": BOOL, "beta_target": Opt(NUMBER),
        "nominal_margin": Opt(NUMBER), "tolerance_linear": NUMBER, "growth?": Opt(NUMBER),
        "limiting_target?": Opt(Map(ANY)), "wall_s?": NUMBER}
FIGURES = ("nominal_margin", "tolerance_linear", "beta_target", "growth", "beta_stability_target")


def _steps_problem(steps: list, n_vars: int) -> SchemaError | None:
    """What is wrong with a record's steps, at its JSON path (None: nothing)."""
    try:
        check_finite(steps, [STEP], "$.steps")
    except SchemaError as err:
        return err
    for k, st in enumerate(steps):
        if len(st["x"]) != n_vars:
            return SchemaError(f"$.steps[{k}].x", f"{len(st['x'])} numbers, not the block's {n_vars} variables")
    return None


def read_record(path, settings: dict, n_vars: int) -> dict:
    """A run's record at `path`, checked field by field (it may come from someone else: docs/architecture.md),
    or None where it holds other settings."""
    import json
    try:
        rec = json.loads(open(path, "rb").read())
    except OSError as e:
        raise Mech2SpiceError(f"cannot read centering record {path}: {e.strerror or e}") from None
    except (ValueError, RecursionError) as e:
        raise Mech2SpiceError(f"centering record {path} is damaged (not JSON: {e})") from None
    if not (isinstance(rec, dict) and rec.get("format") == FORMAT and isinstance(rec.get("settings"), dict)
            and isinstance(rec.get("steps"), list)):
        raise Mech2SpiceError(f"{path} is not a centering record (format '{FORMAT}', settings, steps)")
    if rec["settings"] != settings:
        return None
    if not rec["steps"]:
        raise Mech2SpiceError(f"centering record {path} has no steps (not even the seed's): delete it to start again")
    problem = _steps_problem(rec["steps"], n_vars)
    if problem:
        raise Mech2SpiceError(f"centering record {path}: {problem.path}: {problem.message}: delete it to start again")
    if _best(rec["steps"]) is None:
        raise Mech2SpiceError(f"centering record {path} has no accepted step with a worst-case distance "
                              "(beta_target): delete it to start again")
    return rec


def _best(steps: list[dict]) -> dict | None:
    """The accepted step of the largest worst-case distance (None: none has one)."""
    return max((s for s in steps if s["accepted"] and s["beta_target"] is not None),
               key=lambda s: s["beta_target"], default=None)


def _check_finite(st: dict, k: int, settings: Settings) -> None:
    """A step's figures are finite or the run stops before writing them (JSON has no Infinity)."""
    for key in FIGURES:
        v = st.get(key)
        if isinstance(v, float) and not math.isfinite(v):
            why = (f" (--spread {settings.spec.spread:g} is too small: the margins' spread underflows)"
                   if key.startswith("beta") and v > 0 else "")
            raise Mech2SpiceError(f"centering step {k}: {key} is {v}{why}; nothing written")


def run(seed: GateParams, settings: Settings, out_dir, steps: int, log=lambda msg: None) -> dict:
    """Centre `seed` for up to `steps` steps in all (resuming out_dir/centering.json when its settings
    match), writing the record after every step and the best block to out_dir/best.json."""
    import time
    from pathlib import Path
    from .search import write_atomic
    settings.spec.validate()
    design = Design(seed, settings.levels)
    x0 = design.x0()
    opt = Centering(design, settings)
    out = Path(out_dir)
    path = out / RECORD
    rec = read_record(path, settings.to_dict(), x0.size) if path.is_file() else None
    if rec is None:
        first = {"step": 0, "x": x0.tolist(), "trust_next": 1.0, "accepted": True, **_figures(opt.analyse(x0))}
        _check_finite(first, 0, settings)
        if first["beta_target"] is None:
            raise Mech2SpiceError(f"the seed block {settings.seed_name} does not work on the centering grid (no "
                                  "worst-case distance): nothing to centre")
        rec = {"format": FORMAT, "version": 1, "settings": settings.to_dict(), "variables": design.names,
               "steps": [first]}
        write_atomic(path, rec)
    t0, start = time.time(), len(rec["steps"])
    for k in range(start, steps + 1):
        last = rec["steps"][-1]
        if last["trust_next"] < TRUST_MIN:
            log(f"trust region below {TRUST_MIN} x the initial step: converged")
            break
        ts = time.time()
        st = opt.step(np.array(last["x"]), last["trust_next"])
        _check_finite(st, k, settings)
        rec["steps"].append({"step": k, **st, "wall_s": time.time() - ts})
        write_atomic(path, rec)
        eta = (time.time() - t0) / (k - start + 1) * (steps - k)
        lim = st["limiting"]
        log(f"step {k}/{steps}: beta {st['beta_before']:.3f} -> {st['beta_after']:.3f} "
            f"({'accepted' if st['accepted'] else 'rejected'}), linear tolerance {st['tolerance_linear']:.3g}, "
            f"limiting {lim['kind']} at {lim['inputs']}: {lim['elements'][0]['name']}; ETA {eta:.0f} s")
    best = _best(rec["steps"])
    p, damping = _damped(design.params(best["x"]), log)
    block = {"name": p.name, "block": p.structure.to_dict(), "f_r": p.f_r, "u_r": p.u_r, "omega": p.omega,
             "levels": p.levels.to_dict(),
             "search": {"method": "design centering (design/centering.py)", **settings.to_dict(),
                        "step": best["step"], "steps": len(rec["steps"]) - 1, "held_damping": damping},
             "measured": {**{k: best.get(k) for k in ("nominal_margin", "tolerance_linear", "beta_target", "growth")},
                          "held_growth": damping["tried"][-1]["growth"]}}
    write_atomic(out / BEST, block)
    return {"record": str(path), "best_file": str(out / BEST), "best_step": best["step"],
            "steps": len(rec["steps"]) - 1, **block["measured"],
            "seed": {k: rec["steps"][0][k] for k in ("nominal_margin", "tolerance_linear", "beta_target")},
            "limiting": best.get("limiting_target"), "held_damping": damping}


def _damped(p: GateParams, log) -> tuple[GateParams, dict]:
    """The centred block with its insulator damped until its register loops settle while they hold
    (experiments/held.py): the grid's constraints see one loaded gate, not a latch's loop, which circled a
    Hopf point on both issue-#27 blocks as centred.  The insulator's Q moves no steady state, so every
    margin and fold constraint above stands; 'growth' in the record is the centring's, before it."""
    from ..experiments import held
    p, rec = held.damp_insulator(p, log=log)
    if not rec["reached"]:
        log(f"the held counter4 still grows at insulator Q {rec['q_insulator']:.3f}: not a block for latches")
    return p, rec
