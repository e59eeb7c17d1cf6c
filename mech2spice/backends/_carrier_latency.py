"""Per-gate latency at oscillator level: the carrier's loop integrates only the gate blocks that are moving.

A settled gate's orbit is periodic with the drive, so one period of it, recorded, stands for every later
one: while a block is frozen its neighbours read its recorded values at each step's RK4 stages (the same
stage times every period), and it costs nothing else.  Decisions fall on period boundaries, from each
block's channel amplitude (the trapezoid Fourier coefficient the loop computes anyway):

- an active block freezes after two windows of WINDOW_PERIODS in which its channel amplitude stayed
  within `tol` of each window's first value, if the two windows' means also differ by less than
  tol / REACH (a slow drift, as at a band-edge input, keeps it integrated: frozen, it would stop short
  of its level); its state goes back to the recorded period's start and it records what its input
  blocks' channels were;
- a frozen block wakes when one of its input blocks' channel moved more than `tol` from that record,
  or when a drive on one of its DOFs changes (a new stimulus segment), and continues from its recorded
  period-start state.

Only channels are watched, as in the envelope's latency (_envelope_latency.py): a block reads the rest
of the network through couplings to its drivers' channels and its loads' gate oscillators, and a
block's channel responds to both.  When no block is active the state is periodic and, with a settle
tolerance, the pause ends as the whole-circuit rule would end it.

The loop runs each batch member to the end of the call before the next (activity is per member); the
DOFs of each kind group that are active form one index list, so the gather and combine loops run over
that list instead of the whole range (_carrier_kernel.py has the scheme and the full-range loops).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ._carrier_kernel import DIVERGED, DONE, SETTLED, _FLAGS, njit

WINDOW_PERIODS = 100      # a block's settle watch compares windows of this many periods (module doc)
REACH = 10                # windows: a drift between two windows' means, over this many, must stay below the threshold


class Blocks:
    """The gate blocks of one carrier Operator, in loop numbering, as the arrays the compiled loop reads."""

    def __init__(self, model, op):
        gates = model.design.gates
        owner = -np.ones(model.n, np.int64)
        for k, g in enumerate(gates):
            owner[list(g.dofs) or [g.channel, g.insulator, *[d for pair in g.inputs for d in pair]]] = k
        rest = owner < 0                                    # DOFs outside gates: one block, never frozen
        self.n = len(gates) + int(rest.any())
        self.always = self.n - 1 if rest.any() else -1
        owner[rest] = self.n - 1
        self.owner = np.ascontiguousarray(owner[op.order])  # loop index -> block
        chan = np.array([g.channel for g in gates] + ([int(np.flatnonzero(rest)[0])] if rest.any() else []))
        self.channel = np.ascontiguousarray(op.pos[chan])
        order = np.argsort(self.owner, kind="stable")
        self.dof_ptr = np.searchsorted(self.owner[order], np.arange(self.n + 1)).astype(np.int64)
        self.dofs = order.astype(np.int64)
        reads = _block_reads(model, op, self.owner, self.n)        # (d, a): block d reads block a's DOFs
        self.in_ptr, self.in_idx = reads.indptr.astype(np.int64), reads.indices.astype(np.int64)
        feeds = reads.T.tocsr()                                     # (a, d)
        feeds.sort_indices()
        self.out_ptr, self.out_idx = feeds.indptr.astype(np.int64), feeds.indices.astype(np.int64)
        # the entry of feeds that holds each entry of reads: a record per (reader, input) pair
        where = {(a, d): e for a in range(self.n) for e, d in
                 zip(range(self.out_ptr[a], self.out_ptr[a + 1]), self.out_idx[self.out_ptr[a]:self.out_ptr[a + 1]])}
        self.in_entry = np.array([where[(a, d)] for d in range(self.n)
                                  for a in self.in_idx[self.in_ptr[d]:self.in_ptr[d + 1]]], np.int64)
        self.input_dofs = _input_dofs(model, op, self.owner, self.n)

    def arrays(self):
        """The tuple the compiled loop takes."""
        return (self.owner, self.channel, self.dof_ptr, self.dofs, self.in_ptr, self.in_idx, self.in_entry,
                self.out_ptr, self.out_idx, self.input_dofs[0], self.input_dofs[1], self.always)

    def fresh_record(self, B: int, N: int, n: int):
        """Every block active, nothing recorded: (active, calm, ref, out, snap, stages, coef, drive)."""
        return (np.ones((B, self.n), np.int8), np.zeros((B, self.n, 2), np.int64), np.zeros((B, self.n, 6)),
                np.zeros((B, self.n, 2)), np.zeros((B, self.out_idx.size, 2)), np.zeros((B, N, 4, 2, n)),
                np.zeros((B, n, 3)), np.full((B, 2, n), np.nan))


def _block_reads(model, op, owner, nblk) -> sp.csr_matrix:
    """Pattern (d, a) of blocks d whose forces read a DOF of another block a (springs, dashpots, quadratic)."""
    rows, cols = _pairs(model, op)
    d, a = owner[rows], owner[cols]
    keep = d != a
    m = sp.csr_matrix((np.ones(int(keep.sum())), (d[keep], a[keep])), shape=(nblk, nblk))
    m.sum_duplicates()
    m.sort_indices()
    m.data[:] = 1.0
    return m


def _pairs(model, op) -> tuple[np.ndarray, np.ndarray]:
    """(i, j) in loop numbering for every force term on DOF i that reads DOF j."""
    C = (abs(model.K) + abs(model.C)).tocoo()
    a = model.arrays
    rows = np.r_[C.row, a["quad_fast"], a["quad_slow"]]
    cols = np.r_[C.col, a["quad_slow"], a["quad_fast"]]
    off = rows != cols
    return op.pos[rows[off]], op.pos[cols[off]]


def _input_dofs(model, op, owner, nblk) -> tuple[np.ndarray, np.ndarray]:
    """CSR (ptr, idx) of the DOFs of other blocks that each block's forces read (what it needs replayed)."""
    rows, cols = _pairs(model, op)
    keep = owner[rows] != owner[cols]
    m = sp.csr_matrix((np.ones(int(keep.sum())), (owner[rows[keep]], cols[keep])), shape=(nblk, op.n))
    m.sum_duplicates()
    m.sort_indices()
    return m.indptr.astype(np.int64), m.indices.astype(np.int64)


# --- the compiled loop ------------------------------------------------------------------------------------

@njit(**_FLAGS)
def _lists(active, owner, groups, inp_ptr, inp_idx, act, gact, bnd, tact, track):
    """Rebuild the index lists from `active`: act (active DOFs, ascending, so each group's are contiguous;
    gact[r] their start for group r), bnd (frozen DOFs an active block reads) and tact (tracked active DOFs).
    Returns (len(act), len(bnd), len(tact))."""
    na = 0
    r = 0
    ng = groups.shape[0]
    n = owner.size
    for i in range(n):
        while r < ng and i >= groups[r, 1]:
            r += 1
            gact[r] = na
        if active[owner[i]]:
            act[na] = i
            na += 1
    while r < ng:
        r += 1
        gact[r] = na
    gact[0] = 0
    nb = 0
    seen = np.zeros(n, np.int8)
    for blk in range(active.size):
        if not active[blk]:
            continue
        for e in range(inp_ptr[blk], inp_ptr[blk + 1]):
            j = inp_idx[e]
            if not active[owner[j]] and not seen[j]:
                seen[j] = 1
                bnd[nb] = j
                nb += 1
    nt = 0
    for ii in range(na):
        i = act[ii]
        if track[i]:
            tact[nt] = i
            nt += 1
    return na, nb, nt


@njit(**_FLAGS)
def _forces(act, gact, x, v, s, c, P, Q, groups, Ci, Ck, Cd, Qi, Qg, f, rx, rv):
    """The carrier kernel's gather loop over the active DOFs only; records each one's stage state (rx, rv)."""
    for r in range(groups.shape[0]):
        a0, a1 = gact[r], gact[r + 1]
        if a0 >= a1:
            continue
        g0, m, slow = groups[r, 0], groups[r, 1] - groups[r, 0], groups[r, 6]
        if groups[r, 7]:
            for ii in range(a0, a1):
                i = act[ii]
                f[i] = P[i] * s + Q[i] * c
        else:
            for ii in range(a0, a1):
                f[act[ii]] = 0.0
        for k in range(groups[r, 2]):
            o = groups[r, 4] - g0 + k * m
            for ii in range(a0, a1):
                i = act[ii]
                j = Ci[o + i]
                f[i] += Ck[o + i] * x[j] + Cd[o + i] * v[j]
        for k in range(groups[r, 3]):
            o = groups[r, 5] - g0 + k * m
            if slow:
                for ii in range(a0, a1):
                    i = act[ii]
                    u = x[Qi[o + i]]
                    f[i] -= Qg[o + i] * u * u
            else:
                for ii in range(a0, a1):
                    i = act[ii]
                    f[i] -= Qg[o + i] * x[i] * x[Qi[o + i]]
        for ii in range(a0, a1):
            i = act[ii]
            rx[i] = x[i]
            rv[i] = v[i]


@njit(**_FLAGS)
def _step(h, x, v, w, sc, P, Q, gkind, inv_m, E, H, groups, Ci, Ck, Cd, Qi, Qg, act, gact, bnd, nb, R):
    """One Lawson RK4 step over the active DOFs (the carrier kernel's passes), frozen neighbours replayed
    from R (4, 2, n): this step's recorded stage states."""
    xa, va, vb, xe, ve, xn, vn, f = w[0], w[1], w[2], w[3], w[4], w[5], w[6], w[7]
    for k in range(4):
        if k == 0:
            xin, vin, ti = x, v, 0
        elif k == 1:
            xin, vin, ti = xa, va, 2
        elif k == 2:
            xin, vin, ti = xe, vb, 2
        else:
            xin, vin, ti = xa, va, 4
        for q in range(nb):
            j = bnd[q]
            xin[j] = R[k, 0, j]
            vin[j] = R[k, 1, j]
        _forces(act, gact, xin, vin, sc[ti], sc[ti + 1], P, Q, groups, Ci, Ck, Cd, Qi, Qg, f, R[k, 0], R[k, 1])
        # _carrier_kernel._combine1..4 over the index list.  Sharing the updates through inline helpers was
        # tried: the compiler contracted differently (results moved in the last bits) and both loops ran
        # 5-11 % slower, so the few lines of the scheme are written out here as there.
        for r in range(groups.shape[0]):
            a0, a1 = gact[r], gact[r + 1]
            if a0 >= a1:
                continue
            t = gkind[r]
            im = inv_m[t]
            h0, h1, h2, h3 = H[t, 0], H[t, 1], H[t, 2], H[t, 3]
            if k == 0:
                e0, e1, e2, e3 = E[t, 0], E[t, 1], E[t, 2], E[t, 3]
                for ii in range(a0, a1):
                    i = act[ii]
                    a = f[i] * im
                    xi, vi = x[i], v[i]
                    u = vi + 0.5 * h * a
                    xa[i] = h0 * xi + h1 * u
                    va[i] = h2 * xi + h3 * u
                    xe[i] = h0 * xi + h1 * vi
                    ve[i] = h2 * xi + h3 * vi
                    u = vi + h / 6.0 * a
                    xn[i] = e0 * xi + e1 * u
                    vn[i] = e2 * xi + e3 * u
            elif k == 1:
                g1, g3 = h1 * h / 3.0, h3 * h / 3.0
                for ii in range(a0, a1):
                    i = act[ii]
                    a = f[i] * im
                    vb[i] = ve[i] + 0.5 * h * a
                    xn[i] += g1 * a
                    vn[i] += g3 * a
            elif k == 2:
                for ii in range(a0, a1):
                    i = act[ii]
                    a = f[i] * im
                    u = ve[i] + h * a
                    xa[i] = h0 * xe[i] + h1 * u
                    va[i] = h2 * xe[i] + h3 * u
                    xn[i] += h1 * (h / 3.0) * a
                    vn[i] += h3 * (h / 3.0) * a
            else:
                g = im * h / 6.0
                for ii in range(a0, a1):
                    i = act[ii]
                    x[i] = xn[i]
                    v[i] = vn[i] + g * f[i]


@njit(**_FLAGS)
def run_periods(X, V, nper, N, h, P, Q, gkind, inv_m, E, H, groups, Ci, Ck, Cd, Qi, Qg, trig, demod, pidx, widx,
                bound, tol, check, settle_min, since, watch, amp, mean,
                owner, channel, dof_ptr, dofs, in_ptr, in_idx, in_entry, out_ptr, out_idx, inp_ptr, inp_idx, always,
                lat_tol, window, track, active, calm, ref, out, snap, R, coef, drive, work):
    """_carrier_kernel.run_periods with per-gate latency (module doc): the same arguments, the blocks'
    arrays (Blocks.arrays), the threshold lat_tol, the watch's `window` in periods, the tracked-DOF mask,
    the latency record (Blocks.fresh_record), updated in place; work[0] counts the active blocks x steps
    integrated.  Returns (periods done, status) of the
    call: each member runs to its own settling (its amplitudes held from there to the call's end), and
    the call is SETTLED, after the most periods any member integrated, once every member settled.
    watch's quiet count is per member here, (B,)."""
    B, n = X.shape
    nblk = active.shape[1]
    w = np.empty((8, n))
    act, gact = np.empty(n, np.int64), np.empty(groups.shape[0] + 1, np.int64)
    bnd, tact = np.empty(n, np.int64), np.empty(n, np.int64)
    acc = np.empty((3, n))
    tol2 = lat_tol * lat_tol
    lo, hi, quiet = watch[0], watch[1], watch[2]
    most, settled = 0, 0
    for b in range(B):
        x, v, Rb, cb, act_b = X[b], V[b], R[b], coef[b], active[b]
        for i in range(n):                                  # a new drive wakes the block it acts on
            if not (P[b, i] == drive[b, 0, i] and Q[b, i] == drive[b, 1, i]):
                blk = owner[i]
                if not act_b[blk]:
                    act_b[blk], calm[b, blk, 0], calm[b, blk, 1] = 1, 0, 0
                drive[b, 0, i], drive[b, 1, i] = P[b, i], Q[b, i]
        na, nb, nt = _lists(act_b, owner, groups, inp_ptr, inp_idx, act, gact, bnd, tact, track)
        done = nper
        for p in range(nper):
            if na > 0:
                work[0] += N * _count_active(act_b)
                c0 = demod[N - 1]
                for q in range(nt):
                    i = tact[q]
                    acc[0, i], acc[1, i], acc[2, i] = 0.5 * x[i] * c0.real, 0.5 * x[i] * c0.imag, 0.5 * x[i]
                for s in range(N):
                    _step(h, x, v, w, trig[s], P[b], Q[b], gkind, inv_m, E, H, groups, Ci, Ck, Cd, Qi, Qg, act,
                          gact, bnd, nb, Rb[s])
                    f = 0.5 if s == N - 1 else 1.0
                    cs = demod[s]
                    for q in range(nt):
                        i = tact[q]
                        u = f * x[i]
                        acc[0, i] += u * cs.real
                        acc[1, i] += u * cs.imag
                        acc[2, i] += u
                for q in range(nb):                          # frozen neighbours back to their period start
                    j = bnd[q]
                    x[j], v[j] = Rb[0, 0, 0, j], Rb[0, 0, 1, j]
                for ii in range(na):
                    i = act[ii]
                    if not (abs(x[i]) < bound):              # catches NaN too
                        return p, DIVERGED
                for q in range(nt):
                    i = tact[q]
                    cb[i, 0], cb[i, 1], cb[i, 2] = 2.0 / N * acc[0, i], 2.0 / N * acc[1, i], acc[2, i] / N
            for j in range(pidx.size):
                i = pidx[j]
                amp[p, j, b] = cb[i, 0] + 1j * cb[i, 1]
                mean[p, j, b] = cb[i, 2]
            if lat_tol > 0.0 and na > 0 and _decide(b, active, calm, ref, out, snap, cb, channel, in_ptr, in_idx,
                                                     in_entry, out_ptr, out_idx, dof_ptr, dofs, always, tol2, window,
                                                     x, v, Rb):
                na, nb, nt = _lists(act_b, owner, groups, inp_ptr, inp_idx, act, gact, bnd, tact, track)
            age = since + p + 1
            if tol > 0.0 and age > settle_min:
                if na == 0:
                    done = p + 1
                    break
                for j in range(widx.size):
                    i = widx[j]
                    a = np.sqrt(cb[i, 0] ** 2 + cb[i, 1] ** 2)
                    lo[j, b] = min(lo[j, b], a)
                    hi[j, b] = max(hi[j, b], a)
                if (age - settle_min) % check == 0:
                    spread = 0.0
                    for j in range(widx.size):
                        spread = max(spread, hi[j, b] - lo[j, b])
                    quiet[b] = quiet[b] + 1 if spread < tol else 0
                    lo[:, b] = np.inf
                    hi[:, b] = 0.0
                    if quiet[b] >= 2:
                        done = p + 1
                        break
        if done < nper:                                      # settled: its orbit holds to the call's end
            settled += 1
            for p in range(done, nper):
                amp[p, :, b] = amp[done - 1, :, b]
                mean[p, :, b] = mean[done - 1, :, b]
        most = max(most, done)
    if settled == B:
        return most, SETTLED
    return nper, DONE


@njit(**_FLAGS)
def _count_active(act_b):
    c = 0
    for blk in range(act_b.size):
        c += act_b[blk] != 0
    return c


@njit(**_FLAGS)
def _decide(b, active, calm, ref, out, snap, cb, channel, in_ptr, in_idx, in_entry, out_ptr, out_idx, dof_ptr,
            dofs, always, tol2, window, x, v, Rb):
    """The period's freeze and wake decisions of member b (module doc); True when any block changed.

    Per active block, calm = (periods into the window, flags: 1 moved beyond the threshold in this window,
    2 the previous window's mean is in ref[4:6]) and ref = (the window's first value, its running sum,
    the previous window's mean), complex numbers as (re, im) pairs."""
    act_b = active[b]
    nblk = act_b.size
    for blk in range(nblk):                                # each active block's channel this period
        if act_b[blk]:
            i = channel[blk]
            cr, ci = cb[i, 0], cb[i, 1]
            out[b, blk, 0], out[b, blk, 1] = cr, ci
            if _watch(calm[b, blk], ref[b, blk], cr, ci, tol2, window) and blk != always:
                act_b[blk] = 3
    changed = False
    for a in range(nblk):                                  # frozen readers of a moving channel wake up
        if not act_b[a]:
            continue
        for e in range(out_ptr[a], out_ptr[a + 1]):
            d = out_idx[e]
            if act_b[d] == 0 and (out[b, a, 0] - snap[b, e, 0]) ** 2 + (out[b, a, 1] - snap[b, e, 1]) ** 2 > tol2:
                act_b[d] = 2
    for blk in range(nblk):
        if act_b[blk] == 2:
            act_b[blk], changed = 1, True
            calm[b, blk, 0], calm[b, blk, 1] = 0, 0
        elif act_b[blk] == 3:
            act_b[blk], changed = 0, True
            for q in range(dof_ptr[blk], dof_ptr[blk + 1]):   # the recorded period's start
                i = dofs[q]
                x[i], v[i] = Rb[0, 0, 0, i], Rb[0, 0, 1, i]
            for e in range(in_ptr[blk], in_ptr[blk + 1]):     # what its inputs' channels were
                a = in_idx[e]
                k = in_entry[e]
                snap[b, k, 0], snap[b, k, 1] = out[b, a, 0], out[b, a, 1]
    return changed


@njit(**_FLAGS)
def _watch(calm, ref, cr, ci, tol2, window):
    """One period of an active block's settle watch; True when it may freeze: in this window and the last
    its channel stayed within the threshold of the window's first value, and the two windows' means differ
    by less than the threshold over REACH windows (a slow drift keeps it integrated)."""
    if calm[0] == 0:
        ref[0], ref[1], ref[2], ref[3] = cr, ci, 0.0, 0.0
    elif (cr - ref[0]) ** 2 + (ci - ref[1]) ** 2 >= tol2:
        calm[1] |= 1
    ref[2] += cr
    ref[3] += ci
    calm[0] += 1
    if calm[0] < window:
        return False
    mr, mi = ref[2] / window, ref[3] / window
    ok = calm[1] == 2 and ((mr - ref[4]) ** 2 + (mi - ref[5]) ** 2) * REACH * REACH < tol2
    ref[4], ref[5] = mr, mi
    calm[0], calm[1] = 0, 2
    return ok
