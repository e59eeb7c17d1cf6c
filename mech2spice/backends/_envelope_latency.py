"""Per-gate latency for the compiled envelope loop: a gate block that has settled is frozen (its
amplitudes held, not integrated) until something it reads moves beyond a threshold.

A block is one GateBlock's DOFs (channel, insulator, gate oscillators).  Its rates read, through the
residual and the block-diagonal Bop^-1, amplitudes and insulator displacements of a few other blocks
(its drivers' channels, its loads' dashpot gates): its *inputs*.  A block freezes when, at two checks in
a row, its own DOFs moved less than `tol` over the last window and its rates predict less than `tol`
over HOLD periods; at the freeze it records its inputs (and the forcing on its residual rows).  After
every step each active block's frozen *dependents* compare their inputs with that record and wake up
beyond `tol`: wake-ups travel along the coupling graph.  When no block is active the state is constant
and the loop stops (status SETTLED): the caller holds it until the stimulus changes.

Insulator displacements count in amplitude-equivalent units: s x |G| u_R / |Z0_ff| (the relative
detuning they cause on the oscillators they couple to, times a logic-1 amplitude).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ._rk4_kernel import njit

FAST = {"contract", "reassoc", "nsz", "arcp"}
LAMBDA_TOL = 0.1     # |lambda h| a row's own rate may move (its insulator's detuning) before its ETDRK4 weights are
                     # recomputed: any lambda keeps the step 4th-order and exact at rest if N = f - lambda A uses the
                     # same one; the lag only leaves <= LAMBDA_TOL / h of the own rate to the RK4 part (beside the
                     # coupling's 0.026 x 20 at step 20).  0.1 instead of 0.01: 1.09x per block-step, reads within
                     # 0.0014 u_R (3 fcb samples x 80 sieve cycles; docs/latency.md)
SETTLED, DIVERGED, DONE = 1, 2, 0
CHANNELS_ONLY = True
QUIET_BASE = 1 << 20  # a block's quiet counts packed in one int64 (the state's format): checks in a row with its
                      # inputs calm + QUIET_BASE x checks in a row with its inputs and its own channel calm


def _csr_pattern(M) -> tuple[np.ndarray, np.ndarray]:
    M = sp.csr_matrix(M)
    M.sum_duplicates()
    M.sort_indices()
    return M.indptr.astype(np.int64), M.indices.astype(np.int64)


class Blocks:
    """The gate blocks of one Envelope in index arrays (CSR: ptr, idx) for the compiled loop."""

    def __init__(self, env, Binv):
        model = env.model
        nf, ns = env.fast.size, env.slow.size
        pos_f = -np.ones(model.n, np.int64)
        pos_f[env.fast] = np.arange(nf)
        pos_s = -np.ones(model.n, np.int64)
        pos_s[env.slow] = np.arange(ns)
        owner = -np.ones(model.n, np.int64)
        for k, g in enumerate(model.design.gates):
            owner[[g.channel, g.insulator, *[d for pair in g.inputs for d in pair]]] = k
        rest = owner < 0                                   # DOFs outside gates: one block, never frozen
        nblk = len(model.design.gates) + int(rest.any())
        owner[rest] = nblk - 1
        self.n = nblk
        self.always = nblk - 1 if rest.any() else -1
        of_f, of_s = owner[env.fast], owner[env.slow]
        Rf = sp.csr_matrix((np.ones(nf), (of_f, np.arange(nf))), shape=(nblk, nf))
        Rs = sp.csr_matrix((np.ones(ns), (of_s, np.arange(ns))), shape=(nblk, ns))
        pat = lambda M: (abs(sp.csr_matrix(M)) > 0).astype(float)
        Pb, Pz, Pg, Ph = pat(Binv), pat(env.Z0) + sp.identity(nf), pat(env.G), pat(env.H)
        res = pat(Rf @ Pb)                                 # residual rows each block's rates read
        ext_f = pat(res @ Pz + Rs @ Ph).tolil()
        ext_s = pat(res @ Pg).tolil()
        ext_f = self._drop_own(ext_f, of_f)      # the record: every other block's fast DOF its rates read (its
        ext_s = self._drop_own(ext_s, of_s)      # drivers' channels, its loads' gate oscillators; docs/latency.md)
        wake_f = ext_f
        if CHANNELS_ONLY:                        # the wake-ups' graph follows the channels a block reads
            ch = np.zeros(nf, bool)
            ch[env.watch] = True
            wake_f = sp.csr_matrix(ext_f.multiply(ch[None, :].astype(float)))
            wake_f.eliminate_zeros()
            ext_s = sp.csr_matrix(ext_s.shape)
            Rk = sp.csr_matrix((np.ones(ch.sum()), (of_f[ch], np.flatnonzero(ch))), shape=(nblk, nf))
            self.key = _csr_pattern(Rk)
            self.key_s = _csr_pattern(sp.csr_matrix((nblk, ns)))
        else:
            self.key, self.key_s = _csr_pattern(Rf), _csr_pattern(Rs)
        self.fast = _csr_pattern(Rf)
        self.slow = _csr_pattern(Rs)
        self.res = _csr_pattern(res)
        self.ext_f = _csr_pattern(ext_f)
        watched = np.zeros(nf, np.int8)
        watched[env.watch] = 1
        self.ext_channel = watched[self.ext_f[1]]       # which recorded inputs are channels (the calm test's)
        self.ext_s = _csr_pattern(ext_s)
        dep = pat(wake_f @ Rf.T + ext_s @ Rs.T).T         # (a, d): d reads a's channel (its DOFs)
        self.dep = _csr_pattern(dep)
        # amplitude-equivalent scale of an insulator displacement (module docstring)
        z = np.abs(env.Z0.diagonal())
        Gc = abs(env.G).tocsc()
        self.s_scale = np.zeros(ns)
        for j in range(ns):
            rows = Gc.indices[Gc.indptr[j]:Gc.indptr[j + 1]]
            if rows.size:
                self.s_scale[j] = np.max(Gc.data[Gc.indptr[j]:Gc.indptr[j + 1]] / z[rows]) * model.amplitude_unit

    @staticmethod
    def _drop_own(M, owner_of_col):
        M = M.tocoo()
        keep = owner_of_col[M.col] != M.row
        return sp.csr_matrix((M.data[keep], (M.row[keep], M.col[keep])), shape=M.shape)

    def arrays(self):
        """The tuple the compiled loop takes."""
        return (self.fast[0], self.fast[1], self.slow[0], self.slow[1], self.res[0], self.res[1],
                self.ext_f[0], self.ext_f[1], self.ext_s[0], self.ext_s[1], self.dep[0], self.dep[1],
                self.s_scale, self.key[0], self.key[1], self.key_s[0], self.key_s[1], self.ext_channel)

    def fresh_state(self, B: int):
        """Every block active, nothing recorded: (active, quiet, snap_f, snap_s, snap_F)."""
        return (np.ones(self.n, np.int8), np.zeros(self.n, np.int64),
                np.zeros((self.ext_f[1].size, B), complex), np.zeros((self.ext_s[1].size, B)),
                np.zeros((self.res[1].size, B), complex))


def propagators(env, h: float):
    """exp(M h/2) and exp(M h) of each insulator's [s, s']' = M [s, s'] (M = [[0, 1], [-k/m, -c/m]]) as
    (ns, 4) rows [e00, e01, e10, e11]; None when the insulators are coupled to each other."""
    from scipy.linalg import expm
    ns = env.slow.size
    if env.Ks.nnz > ns or env.Cs.nnz > ns:
        return None
    kinds, which = np.unique(np.stack([env.Ks.diagonal() / env.ms, env.Cs.diagonal() / env.ms], 1), axis=0,
                             return_inverse=True)
    out = []
    for tau in (h / 2, h):
        E = np.array([expm(np.array([[0.0, 1.0], [-k, -c]]) * tau).ravel() for k, c in kinds]).reshape(-1, 4)
        out.append(np.ascontiguousarray(E[np.asarray(which).ravel()]))
    return out


def own_rates(env, Binv) -> tuple[np.ndarray, np.ndarray]:
    """Each amplitude's own rate at rest, d(A_f')/dA_f = -(Bop^-1 Z0)_ff, and (Bop^-1)_ff, by which an
    insulator's detuning G s adds to it: the exponential step advances A_f by exp(lambda_f h), lambda_f =
    own0_f - binv_ff (G s)_f at the step's start, and leaves RK4 only the coupling between amplitudes.
    At rest the largest own rate (an input pair's oscillator, detuned from the drive: |lambda| T = 0.145 on
    the processor) is what bounded the step; the coupling's rate is 0.026 (docs/latency.md)."""
    Binv = sp.csr_matrix(Binv)
    own0 = -np.asarray((Binv @ sp.csc_matrix(env.Z0)).diagonal(), complex)
    return np.ascontiguousarray(own0), np.ascontiguousarray(np.asarray(Binv.diagonal(), complex))


@njit(cache=True, fastmath=FAST)
def _append(b, blk, mark, frows, srows, rrows, ablk, nf, ns, nr, na):
    """Block b's rows appended to the lists (residual rows only if not yet listed); the new counts."""
    fp, fi, sp_, si, rp, ri = blk[0], blk[1], blk[2], blk[3], blk[4], blk[5]
    ablk[na] = b
    na += 1
    for k in range(fp[b], fp[b + 1]):
        frows[nf] = fi[k]
        nf += 1
    for k in range(sp_[b], sp_[b + 1]):
        srows[ns] = si[k]
        ns += 1
    for k in range(rp[b], rp[b + 1]):
        r = ri[k]
        if mark[r] == 0:
            mark[r] = 1
            rrows[nr] = r
            nr += 1
    return nf, ns, nr, na


@njit(cache=True, fastmath=FAST)
def _lists(active, blk, mark, frows, srows, rrows, ablk):
    """Rows of the active blocks: (n fast, n slow, n residual, n active blocks); residual rows deduplicated."""
    nf = ns = nr = na = 0
    mark[:] = 0
    for b in range(active.size):
        if active[b] != 0:
            nf, ns, nr, na = _append(b, blk, mark, frows, srows, rrows, ablk, nf, ns, nr, na)
    return nf, ns, nr, na


@njit(cache=True, fastmath=FAST)
def _relist(active, blk, mark, frows, srows, rrows, ablk, nr_old, na_old):
    """_lists after some blocks froze, from the previous lists only (O(active), not O(network))."""
    for q in range(nr_old):
        mark[rrows[q]] = 0
    nf = ns = nr = na = 0
    for q in range(na_old):
        b = ablk[q]
        if active[b] != 0:            # _append writes ablk[na], na <= q: compacts in place
            nf, ns, nr, na = _append(b, blk, mark, frows, srows, rrows, ablk, nf, ns, nr, na)
    return nf, ns, nr, na


@njit(cache=True, fastmath=FAST)
def _rhs(A, s, sd, F, Z, G, H, Ks, Cs, inv_ms, Binv, rrows, nr, frows, nf, srows, ns, Ad, sdd, work, linear):
    """The envelope rates on the listed rows only (residuals on rrows, which Bop^-1 of frows reads);
    linear=False: the insulators' acceleration without their own spring and damper (exponential step)."""
    Zp, Zi, Zd = Z
    Gp, Gi, Gd = G
    Hp, Hi, Hd = H
    Kp, Ki, Kd = Ks
    Cp, Ci, Cd = Cs
    Bp, Bi, Bd = Binv
    for b in range(A.shape[1]):
        for q in range(nr):
            f = rrows[q]
            r = F[f, b]
            for k in range(Zp[f], Zp[f + 1]):
                r -= Zd[k] * A[Zi[k], b]
            gs = 0.0
            for k in range(Gp[f], Gp[f + 1]):
                gs += Gd[k] * s[Gi[k], b]
            work[f] = r - gs * A[f, b]
        for q in range(nf):
            f = frows[q]
            acc = 0j
            for k in range(Bp[f], Bp[f + 1]):
                acc += Bd[k] * work[Bi[k]]
            Ad[f, b] = acc
        for q in range(ns):
            j = srows[q]
            acc = 0.0
            for k in range(Hp[j], Hp[j + 1]):
                a = A[Hi[k], b]
                acc -= 0.5 * Hd[k] * (a.real * a.real + a.imag * a.imag)
            if linear:
                for k in range(Kp[j], Kp[j + 1]):
                    acc -= Kd[k] * s[Ki[k], b]
                for k in range(Cp[j], Cp[j + 1]):
                    acc -= Cd[k] * sd[Ci[k], b]
            sdd[j, b] = acc * inv_ms[j]


@njit(cache=True, fastmath=FAST)
def _moved(A, s, F, blk, b, snap_f, snap_s, snap_F, tol, forcing=True, channels=False, tol_channels=-1.0):
    """Whether frozen block b's inputs (or, with `forcing`, the forcing on its residual rows) left their
    record by > tol (its input channels by > tol_channels where that is >= 0); with `channels`, of its inputs
    only the channels (its drivers' news, not its loads' ringing back-action).  Within one compiled call the
    forcing is constant: the wake-ups after each step skip it."""
    xp, xi, yp, yi, rp, ri, scale, is_channel = blk[6], blk[7], blk[8], blk[9], blk[4], blk[5], blk[12], blk[17]
    for bb in range(A.shape[1]):
        for k in range(xp[b], xp[b + 1]):
            if channels and is_channel[k] == 0:
                continue
            d = A[xi[k], bb] - snap_f[k, bb]
            t = tol_channels if tol_channels >= 0.0 and is_channel[k] != 0 else tol
            if d.real * d.real + d.imag * d.imag > t * t:
                return True
        for k in range(yp[b], yp[b + 1]):
            if abs(s[yi[k], bb] - snap_s[k, bb]) * scale[yi[k]] > tol:
                return True
        if forcing:
            for k in range(rp[b], rp[b + 1]):
                if F[ri[k], bb] != snap_F[k, bb]:
                    return True
    return False


@njit(cache=True, fastmath=FAST)
def _record(A, s, F, blk, b, snap_f, snap_s, snap_F):
    """Record block b's inputs (and the forcing on its residual rows)."""
    xp, xi, yp, yi, rp, ri = blk[6], blk[7], blk[8], blk[9], blk[4], blk[5]
    for bb in range(A.shape[1]):
        for k in range(xp[b], xp[b + 1]):
            snap_f[k, bb] = A[xi[k], bb]
        for k in range(yp[b], yp[b + 1]):
            snap_s[k, bb] = s[yi[k], bb]
        for k in range(rp[b], rp[b + 1]):
            snap_F[k, bb] = F[ri[k], bb]


@njit(cache=True, fastmath=FAST)
def _freeze(A, s, blk, b, At, st, sd, v2, v3, v4):
    """Park block b's stage values on its state (frozen rows read as held)."""
    fp, fi, sp_, si = blk[0], blk[1], blk[2], blk[3]
    for bb in range(A.shape[1]):
        for k in range(fp[b], fp[b + 1]):
            At[fi[k], bb] = A[fi[k], bb]
        for k in range(sp_[b], sp_[b + 1]):
            j = si[k]
            st[j, bb] = s[j, bb]
            v2[j, bb] = v3[j, bb] = v4[j, bb] = sd[j, bb]


@njit(cache=True, fastmath=FAST)
def _quiet(A, s, sd, a1, Aref, sref, blk, b, tol, hold):
    """Block b moved < tol since the last check and its rates predict < tol over `hold` seconds."""
    fp, fi, sp_, si, scale = blk[13], blk[14], blk[15], blk[16], blk[12]
    for bb in range(A.shape[1]):
        for k in range(fp[b], fp[b + 1]):
            f = fi[k]
            if abs(A[f, bb] - Aref[f, bb]) > tol or abs(a1[f, bb]) * hold > tol:
                return False
        for k in range(sp_[b], sp_[b + 1]):
            j = si[k]
            if (abs(s[j, bb] - sref[j, bb]) * scale[j] > tol or abs(sd[j, bb]) * hold * scale[j] > tol):
                return False
    return True


@njit(cache=True, fastmath=FAST)
def _mark_ref(A, s, Aref, sref, blk, b):
    fp, fi, sp_, si = blk[0], blk[1], blk[2], blk[3]
    for bb in range(A.shape[1]):
        for k in range(fp[b], fp[b + 1]):
            Aref[fi[k], bb] = A[fi[k], bb]
        for k in range(sp_[b], sp_[b + 1]):
            sref[si[k], bb] = s[si[k], bb]


@njit(cache=True, fastmath=FAST)
def _phi1(w, e):
    """phi_1(w) = (e^w - 1) / w given e = e^w; a series where |w| < 1/2 (the closed form cancels there)."""
    if abs(w) >= 0.5:
        return (e - 1.0) / w
    p = 0j
    fact = 14.0 * 13.0 * 12.0 * 11.0 * 10.0 * 9.0 * 8.0 * 7.0 * 6.0 * 5.0 * 4.0 * 3.0 * 2.0    # 14!
    for j in range(13, -1, -1):           # Horner on sum_j w^j / (j + 1)!, j <= 13
        p = p * w + 1.0 / fact
        fact /= j + 1
    return p


@njit(cache=True, fastmath=FAST)
def _etd_weights(z):
    """ETDRK4's weights for one row, z = lambda h: exp(z/2), phi_1(z/2) and, from phi_k(z) = sum_j z^j / (j + k)!,
    phi_1 - 3 phi_2 + 4 phi_3, phi_2 - 2 phi_3, 4 phi_3 - phi_2 (Cox & Matthews 2002); one exp."""
    e2 = np.exp(0.5 * z)
    e = e2 * e2
    p1h = _phi1(0.5 * z, e2)
    if abs(z) >= 0.5:
        iz = 1.0 / z
        p1 = (e - 1.0) * iz
        p2 = (p1 - 1.0) * iz
        p3 = (p2 - 0.5) * iz
    else:                                 # phi_3's series, then phi_2 = 1/2 + z phi_3
        p3 = 0j
        fact = 15.0 * 14.0 * 13.0 * 12.0 * 11.0 * 10.0 * 9.0 * 8.0 * 7.0 * 6.0 * 5.0 * 4.0 * 3.0 * 2.0   # 15!
        for j in range(12, -1, -1):
            p3 = p3 * z + 1.0 / fact
            fact /= j + 3
        p2 = 0.5 + z * p3
        p1 = 1.0 + z * p2
    return e2, p1h, p1 - 3.0 * p2 + 4.0 * p3, p2 - 2.0 * p3, 4.0 * p3 - p2


@njit(cache=True, fastmath=FAST, nogil=True)     # nogil: a Dask worker's own threads run beside it (mc_run)
def run_latent(A, s, sd, nsteps, sub, per, h, F, Z, G, H, Ks, Cs, inv_ms, Binv, prow, amp, bound,
               settle_tol, watch, check_every, settle_from, blk, active, quiet, snap_f, snap_s, snap_F,
               tol, hold, lat_check, need, always, expo, Eh, Ef, etd, own0, binv, lambda_tol, amp_from, need_calm,
               channels_calm, wake_tol):
    """run_steps (_envelope_kernel) with per-block latency: only active blocks' rows are integrated.
    A block freezes once its inputs moved < tol since the last check at `need` checks in a row (lat_check
    steps apart) and, at the last `need_calm` (<= need) of them, its channel moved < tol too and its rates
    predicted < tol over `hold` (quiet: the two counts, QUIET_BASE); channels_calm: the inputs' calm test
    reads the input channels only (the wake-ups read every recorded input); wake_tol >= 0: a frozen block wakes
    once an input channel left its record by that much (its other inputs: tol).  tol = 0: only blocks
    standing exactly still freeze.  expo: the insulators' linear oscillator (s, s') is stepped exactly (Lawson RK4 with its
    propagators over h/2 and h, Eh and Ef as (ns, 4) rows [e00, e01, e10, e11]); RK4 then no longer
    resolves their ringing, the stiffest mode at rest.  With etd too, each amplitude's own rate lambda_f
    (own_rates: at rest own0, plus its insulators' detuning through binv, at the step's start) is stepped
    exactly too, by ETDRK4 (Cox & Matthews 2002: the stages carry N = f - lambda A, weighted by phi functions
    of lambda h): exact for a constant N, so a settled state is a fixed point of the step at any h, which
    Lawson's RK4 is not (its settled amplitudes were off by 0.011 u_R at 8 periods on the chain).
    lambda_tol: LAMBDA_TOL, an argument so that a comparison can set it at run time.  amp: the probes' amplitude
    at each period from amp_from on (the periods before are left unwritten: the caller keeps the last ones).
    Returns (steps done, DONE | SETTLED | DIVERGED, block-steps integrated)."""
    nf, B = A.shape
    ns = s.shape[0]
    nblk = active.size
    bound2 = bound * bound
    a1 = np.zeros_like(A)
    a2 = np.zeros_like(A)
    a3 = np.zeros_like(A)
    a4 = np.zeros_like(A)
    At = A.copy()
    st = s.copy()
    c1 = np.zeros_like(s)
    c2 = np.zeros_like(s)
    c3 = np.zeros_like(s)
    c4 = np.zeros_like(s)
    v2 = sd.copy()
    v3 = sd.copy()
    v4 = sd.copy()
    lam = np.full_like(A, 1e300)                  # etd: each row's lambda and its ETDRK4 weights (none yet)
    eh = np.ones_like(A)
    qh = np.zeros_like(A)
    w1 = np.zeros_like(A)
    w2 = np.zeros_like(A)
    w3 = np.zeros_like(A)
    Gp, Gi, Gd = G
    Aref = A.copy()
    sref = s.copy()
    work = np.zeros(nf, A.dtype)
    mark = np.zeros(nf, np.int8)
    frows = np.empty(nf, np.int64)
    srows = np.empty(ns, np.int64)
    rrows = np.empty(nf, np.int64)
    ablk = np.empty(nblk, np.int64)
    lo = np.zeros((watch.size, B))
    hi = np.zeros((watch.size, B))
    settle_quiet = 0
    work_done = 0
    wpos = -np.ones(nf, np.int64)                 # fast row -> its index in watch (-1: not watched)
    for q in range(watch.size):
        wpos[watch[q]] = q
    if always >= 0:
        active[always] = 1
    for b in range(nblk):                          # a changed forcing wakes the blocks it reaches
        if active[b] == 0 and _moved(A, s, F, blk, b, snap_f, snap_s, snap_F, tol):
            active[b] = 1
            quiet[b] = 0
    nfr, nsr, nr, na = _lists(active, blk, mark, frows, srows, rrows, ablk)
    for n in range(nsteps):
        if na == 0:
            return n, SETTLED, work_done
        work_done += na
        _rhs(A, s, sd, F, Z, G, H, Ks, Cs, inv_ms, Binv, rrows, nr, frows, nfr, srows, nsr, a1, c1, work, not expo)
        if settle_tol > 0.0 and n % check_every == 0:
            if n >= settle_from + check_every:
                worst = 0.0
                for q in range(watch.size):
                    for b in range(B):
                        worst = max(worst, hi[q, b] - lo[q, b])
                settle_quiet = settle_quiet + 1 if worst < settle_tol else 0
                if settle_quiet >= 2:
                    return n, SETTLED, work_done
            for q in range(watch.size):
                for b in range(B):
                    lo[q, b] = hi[q, b] = abs(A[watch[q], b])
        if n % lat_check == 0:                     # freeze the blocks quiet at two checks in a row
            froze = False
            for q in range(na):
                b = ablk[q]
                if b == always:
                    continue
                calm_own = _quiet(A, s, sd, a1, Aref, sref, blk, b, tol, hold)
                calm_in = not _moved(A, s, F, blk, b, snap_f, snap_s, snap_F, tol, True, channels_calm)
                _record(A, s, F, blk, b, snap_f, snap_s, snap_F)
                q_in = quiet[b] % QUIET_BASE + 1 if calm_in else 0
                q_all = quiet[b] // QUIET_BASE + 1 if calm_own and calm_in else 0
                quiet[b] = q_in + QUIET_BASE * q_all
                if q_in >= need and q_all >= need_calm:
                    active[b] = 0
                    froze = True
                    _freeze(A, s, blk, b, At, st, sd, v2, v3, v4)
                _mark_ref(A, s, Aref, sref, blk, b)
            if froze:
                nfr, nsr, nr, na = _relist(active, blk, mark, frows, srows, rrows, ablk, nr, na)
                if na == 0:
                    return n, SETTLED, work_done
        if etd:                       # ETDRK4: a = E(h/2) u + Q N(u), N(u) = f(u) - lambda u
            for b in range(B):
                for q in range(nfr):
                    f = frows[q]
                    gs = 0.0
                    for k in range(Gp[f], Gp[f + 1]):
                        gs += Gd[k] * s[Gi[k], b]
                    la = own0[f] - binv[f] * gs
                    d = la - lam[f, b]
                    if (d.real * d.real + d.imag * d.imag) * h * h > lambda_tol * lambda_tol:
                        lam[f, b] = la                # weights kept while lambda h moves less
                        e2, p1h, x1, x2, x3 = _etd_weights(h * la)
                        eh[f, b] = e2
                        qh[f, b] = 0.5 * h * p1h
                        w1[f, b] = h * x1
                        w2[f, b] = h * x2
                        w3[f, b] = h * x3
                    At[f, b] = A[f, b] + qh[f, b] * a1[f, b]      # = E(h/2) u + Q N(u): lambda Q = E(h/2) - 1
                    a1[f, b] -= lam[f, b] * A[f, b]                # N(u) from here on (a1 is read again next step)
        else:
            for b in range(B):        # members outside: the row loops run with a fixed b
                for q in range(nfr):
                    f = frows[q]
                    At[f, b] = A[f, b] + 0.5 * h * a1[f, b]
        for b in range(B):
            for q in range(nsr):
                j = srows[q]
                if expo:                           # E(h/2) (y + h/2 k1)
                    w = sd[j, b] + 0.5 * h * c1[j, b]
                    st[j, b] = Eh[j, 0] * s[j, b] + Eh[j, 1] * w
                    v2[j, b] = Eh[j, 2] * s[j, b] + Eh[j, 3] * w
                else:
                    st[j, b] = s[j, b] + 0.5 * h * sd[j, b]
                    v2[j, b] = sd[j, b] + 0.5 * h * c1[j, b]
        _rhs(At, st, v2, F, Z, G, H, Ks, Cs, inv_ms, Binv, rrows, nr, frows, nfr, srows, nsr, a2, c2, work, not expo)
        for b in range(B):
            for q in range(nfr):
                f = frows[q]
                if etd:                   # b = E(h/2) u + Q N(a)
                    a2[f, b] -= lam[f, b] * At[f, b]
                    At[f, b] = eh[f, b] * A[f, b] + qh[f, b] * a2[f, b]
                else:
                    At[f, b] = A[f, b] + 0.5 * h * a2[f, b]
        for b in range(B):
            for q in range(nsr):
                j = srows[q]
                if expo:                           # E(h/2) y + h/2 k2
                    st[j, b] = Eh[j, 0] * s[j, b] + Eh[j, 1] * sd[j, b]
                    v3[j, b] = Eh[j, 2] * s[j, b] + Eh[j, 3] * sd[j, b] + 0.5 * h * c2[j, b]
                else:
                    st[j, b] = s[j, b] + 0.5 * h * v2[j, b]
                    v3[j, b] = sd[j, b] + 0.5 * h * c2[j, b]
        _rhs(At, st, v3, F, Z, G, H, Ks, Cs, inv_ms, Binv, rrows, nr, frows, nfr, srows, nsr, a3, c3, work, not expo)
        for b in range(B):
            for q in range(nfr):
                f = frows[q]
                if etd:                   # c = E(h/2) a + Q (2 N(b) - N(u)), a = E(h/2) u + Q N(u)
                    a3[f, b] -= lam[f, b] * At[f, b]
                    e2 = eh[f, b]
                    At[f, b] = e2 * e2 * A[f, b] + qh[f, b] * ((e2 - 1.0) * a1[f, b] + 2.0 * a3[f, b])
                else:
                    At[f, b] = A[f, b] + h * a3[f, b]
        for b in range(B):
            for q in range(nsr):
                j = srows[q]
                if expo:                           # E(h) y + h E(h/2) k3
                    st[j, b] = Ef[j, 0] * s[j, b] + Ef[j, 1] * sd[j, b] + h * Eh[j, 1] * c3[j, b]
                    v4[j, b] = Ef[j, 2] * s[j, b] + Ef[j, 3] * sd[j, b] + h * Eh[j, 3] * c3[j, b]
                else:
                    st[j, b] = s[j, b] + h * v3[j, b]
                    v4[j, b] = sd[j, b] + h * c3[j, b]
        _rhs(At, st, v4, F, Z, G, H, Ks, Cs, inv_ms, Binv, rrows, nr, frows, nfr, srows, nsr, a4, c4, work, not expo)
        for b in range(B):
            for q in range(nfr):
                f = frows[q]
                if etd:                   # u+ = E(h) u + w1 N(u) + 2 w2 (N(a) + N(b)) + w3 N(c)
                    e2 = eh[f, b]
                    A[f, b] = (e2 * e2 * A[f, b] + w1[f, b] * a1[f, b] + 2.0 * w2[f, b] * (a2[f, b] + a3[f, b])
                               + w3[f, b] * (a4[f, b] - lam[f, b] * At[f, b]))
                else:
                    A[f, b] += (h / 6.0) * (a1[f, b] + 2.0 * a2[f, b] + 2.0 * a3[f, b] + a4[f, b])
                z = A[f, b]
                if not z.real * z.real + z.imag * z.imag < bound2:     # |A| < bound without a hypot; NaN too
                    return n, DIVERGED, work_done
        for b in range(B):
            for q in range(nsr):
                j = srows[q]
                if expo:                           # E(h) (y + h/6 k1) + h/3 E(h/2) (k2 + k3) + h/6 k4
                    w = sd[j, b] + (h / 6.0) * c1[j, b]
                    k23 = (h / 3.0) * (c2[j, b] + c3[j, b])
                    s_new = Ef[j, 0] * s[j, b] + Ef[j, 1] * w + Eh[j, 1] * k23
                    sd[j, b] = Ef[j, 2] * s[j, b] + Ef[j, 3] * w + Eh[j, 3] * k23 + (h / 6.0) * c4[j, b]
                    s[j, b] = s_new
                else:
                    s[j, b] += (h / 6.0) * (sd[j, b] + 2.0 * v2[j, b] + 2.0 * v3[j, b] + v4[j, b])
                    sd[j, b] += (h / 6.0) * (c1[j, b] + 2.0 * c2[j, b] + 2.0 * c3[j, b] + c4[j, b])
        if settle_tol > 0.0:                      # frozen channels hold: only active rows can widen a range
            for r in range(nfr):
                q = wpos[frows[r]]
                if q >= 0:
                    for b in range(B):
                        m = abs(A[frows[r], b])
                        lo[q, b] = min(lo[q, b], m)
                        hi[q, b] = max(hi[q, b], m)
        dp, di = blk[10], blk[11]                  # wake-ups travel to the frozen dependents of active blocks
        n_active = na
        for q in range(n_active):
            for k in range(dp[ablk[q]], dp[ablk[q] + 1]):
                d = di[k]
                if active[d] == 0 and _moved(A, s, F, blk, d, snap_f, snap_s, snap_F, tol, False, False, wake_tol):
                    active[d] = 1
                    quiet[d] = 0
                    _mark_ref(A, s, Aref, sref, blk, d)
                    _record(A, s, F, blk, d, snap_f, snap_s, snap_F)
                    nfr, nsr, nr, na = _append(d, blk, mark, frows, srows, rrows, ablk, nfr, nsr, nr, na)
        if (n + 1) % sub == 0:
            c = (n + 1) // sub - 1
            for p in range(max(0, amp_from - c * per), per):
                for q in range(prow.size):
                    for b in range(B):
                        amp[c * per + p, q, b] = A[prow[q], b]
    return nsteps, DONE, work_done
