"""One NOR gate in the context a network gives it: N load pairs on its output, other loads on its drivers.

    in1.C --+-- gate input 1 pair                       +-- load 1 input pair (insulator held at s_1)
            +-- (u1 other load pairs, held at s)         |   ...
    in2.C --+-- gate input 2 pair        gate.C --------+-- load N input pair (insulator held at s_N)
            +-- (u2 other load pairs)

physics/loaded.py's gate has one load pair whose insulator is at rest and upstream stand-ins that drive
nothing else.  In a network a gate drives up to network.MAX_FANOUT loads and each load's insulator sits
where that load's logic state puts it (its displacement s detunes the pair's two oscillators by 2 gamma s:
the pair's spring- and dashpot-linked back-actions then no longer cancel once their elements are spread).
Here every load pair carries that detuning, from `insulator_positions` (the nominal loaded gate's steady
insulator position at the load's two input levels), added after the spread and trim: a trim sets the
oscillators at rest.  The loads' insulators are held (the batched steady-state scan keeps the gate's own
insulator as its one slow DOF), which is what the processor cut-outs of scripts/cpu_mc_diagnosis.py
showed reproduces the network's amplitude (docs/design.md).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import loaded, nor, steady_batch
from .model import MechModel
from .params import GateParams

GATE = loaded.GATE


@dataclass
class ContextGate:
    """The gate with its N output loads and its drivers' other loads (DOF indices into model)."""
    model: MechModel
    gate: nor.GateBlock
    upstream: tuple[int, int]
    input_drives: tuple[int, int]
    loads: list[tuple[int, ...]]           # output load pairs
    up_loads: list[tuple[int, ...]]        # the drivers' other load pairs
    load_insulators: list[int] = ()        # each load pair's own insulator (loads, then up_loads): held, see `held`

    @property
    def block_dofs(self) -> list[int]:
        """DOFs the spread covers: the gate's, every load pair's (output and upstream) with its links and its
        coupling to its own insulator."""
        return [*self.gate.dofs, *[d for pair in self.loads + self.up_loads for d in pair], *self.load_insulators]

    def input_groups(self) -> np.ndarray:
        """Per drive: 0 for constant drives, k for drives scaled by input level k (1, 2)."""
        groups = np.zeros(len(self.model.drives), int)
        groups[list(self.input_drives)] = [1, 2]
        return groups


def build(p: GateParams, n_loads: int, up_loads: tuple[int, int] = (0, 0)) -> ContextGate:
    """The gate with n_loads output load pairs and up_loads[k] other load pairs on driver k (insulators at
    rest: `held` puts them where their logic states hold them)."""
    p.validate()
    m = MechModel(omega=p.omega, params=p)
    b = p.structure
    out = b.dof(b.output)               # the stand-in has the impedance of the block's output DOF
    z_c = abs(out.k - out.m * p.omega ** 2 + 1j * p.omega * out.c)
    ups, drives = [], []
    for name in loaded.INPUTS:
        ups.append(m.add_dof(f"{name}.C", out.m, out.k, out.c))
        drives.append(m.add_drive(ups[-1], z_c * p.u_r, 0.0, f"{name}.src"))
    gate = nor.add_nor(m, p, GATE)
    for u, pair in zip(ups, gate.inputs):
        nor.connect(m, p, u, pair)
    names = [f"load{j}" for j in range(n_loads)]
    loads = [_pair(m, p, gate.channel, name) for name in names]
    up = [(k, f"{loaded.INPUTS[k]}.load{j}") for k in (0, 1) for j in range(up_loads[k])]
    up_names = [name for _, name in up]
    extra = [_pair(m, p, ups[k], name) for k, name in up]
    # the loads' own insulators last, so that `held` drops them by truncation (the pairs keep their indices)
    ins = b.dof(b.slow_dofs[0])
    gam = pair_gammas(p)
    insulators = []
    for name, pair in zip(names + up_names, loads + extra):
        insulators.append(m.add_dof(f"{name}.{ins.name}", ins.m, ins.k, ins.c, slow=True))
        for dof, g in zip(pair, gam):
            m.add_quad(dof, insulators[-1], g)
    return ContextGate(m, gate, tuple(ups), tuple(drives), loads, extra, insulators)


def _pair(m: MechModel, p: GateParams, channel: int, name: str) -> tuple[int, ...]:
    """A downstream gate's input oscillators (its first input's), wired to `channel`."""
    b = p.structure
    pair = tuple(m.add_dof(f"{name}.{a.dof}", b.dof(a.dof).m, b.dof(a.dof).k, b.dof(a.dof).c) for a in b.inputs[0])
    nor.connect(m, p, channel, pair)
    return pair


def pair_gammas(p: GateParams) -> np.ndarray:
    """gamma of each input oscillator (pin 0's, in GateBlock.inputs order) to its gate's insulator."""
    b = p.structure
    g = {f: v for f, s, v in b.quads}
    return np.array([g.get(a.dof, 0.0) for a in b.inputs[0]])


def held(cg: ContextGate, model: MechModel, s_loads, s_up=0.0) -> MechModel:
    """A copy of `model` (cg.model or a spread copy) with each output load's insulator held at s_j (s_loads: one
    position per load, or one for all) and the drivers' other loads' at s_up: each pair oscillator detuned by
    2 gamma s_j with its own (spread) gamma, the held insulators then dropped from the model."""
    from .spread import _copy
    gamma = {f: g for f, _, g in model.quads}
    k = np.array(model.k_total, float)
    for pairs, s in ((cg.loads, s_loads), (cg.up_loads, s_up)):
        s = np.broadcast_to(np.asarray(s, float), (len(pairs),))
        for pair, sj in zip(pairs, s):
            for d in pair:
                k[d] += 2 * gamma[d] * sj
    n = model.n - len(cg.load_insulators)
    return _copy(model, names=model.names[:n], slow=model.slow[:n], mass=model.mass[:n], k_total=list(k[:n]),
                 c_total=list(model.c_total[:n]), quads=[q for q in model.quads if q[1] < n])


def insulator_positions(p: GateParams) -> dict[tuple[int, int], float]:
    """The nominal loaded gate's insulator position for each pair of logic inputs (x own, x other) at the
    nominal levels: where a load's insulator sits when its input from us is x_own and its other input x_other
    (the lowest-s stable state where there are several)."""
    lg = loaded.build(p)
    st = steady_batch.stack([lg.model], lg.input_groups(), lg.gate.channel)
    lv = p.levels
    pts = [(a, b) for a in (0, 1) for b in (0, 1)]
    levels = np.array([[1.0, lv.nominal(a), lv.nominal(b)] for a, b in pts])
    r = steady_batch.roots(st, 0, levels)
    out = {}
    for k, key in enumerate(pts):
        ok = (r.point == k) & r.stable
        out[key] = float(np.min(r.s[ok])) if ok.any() else 0.0
    return out


_BALANCE_POINT: dict[str, float] = {}


def balance_point(p: GateParams) -> float:
    """The block's insulator position with both inputs at nominal '0' (insulator_positions[(0, 0)]): where
    trim fcb balances each input pair (physics/spread.balanced; cached per block)."""
    key = loaded.digest(p)
    if key not in _BALANCE_POINT:
        _BALANCE_POINT[key] = insulator_positions(p)[(0, 0)]
    return _BALANCE_POINT[key]


def reduced(cg: ContextGate, model: MechModel) -> MechModel:
    """`model` (cg.model or a spread, held copy) with every load pair eliminated: held, a pair is linear, so
    at the drive frequency it adds -Z_cp Z_pp^-1 Z_pc to the impedance of the channel it hangs on (a stiffness
    and a damping there); the steady states are the full model's exactly, and the scan stays at the gate's
    own size whatever the fan-out.  (Its stability verdicts see the loads as static.)"""
    w = model.omega
    n0 = max(cg.gate.dofs) + 1               # loads are built after the stand-ins and the gate
    Z = model.K.toarray() - w * w * np.diag(model.mass) + 1j * w * model.C.toarray()
    core, rest = np.arange(n0), np.arange(n0, model.n)
    dZ = -Z[np.ix_(core, rest)] @ np.linalg.solve(Z[np.ix_(rest, rest)], Z[np.ix_(rest, core)])
    if np.abs(dZ - np.diag(np.diag(dZ))).max(initial=0) > 1e-9 * np.abs(Z).max():
        raise ValueError("a load pair couples two core DOFs: not a channel's own impedance")
    m = MechModel(omega=w, params=model.params)
    for i in core:
        m.add_dof(model.names[i], model.mass[i], model.k_total[i] + dZ[i, i].real, model.c_total[i] + dZ[i, i].imag / w,
                  slow=model.slow[i])
    for links, add in ((model.springs, m.add_spring), (model.dashpots, m.add_dashpot), (model.quads, m.add_quad)):
        for i, j, v in links:
            if i < n0 and j < n0:
                add(i, j, v)
    for d in model.drives:
        m.add_drive(d.dof, d.amplitude, d.phase, d.name)
    return m


def margins(cg: ContextGate, models: list[MechModel], per_band: int = 6) -> np.ndarray:
    """Per model: the smallest band margin over the input grid (loaded.point_margins; -1 where a point has
    no stable state), each point judged on the model whose load positions match NOR's output there:
    models = [loads held for output '0', loads held for output '1'] per sample, flattened pairwise."""
    p = models[0].params
    lv, ex = loaded.input_grid(per_band, p.levels)
    st = steady_batch.stack([reduced(cg, m) for m in models], cg.input_groups(), cg.gate.channel)
    out = []
    for b in range(0, len(models), 2):
        worst = np.inf
        for want in (0, 1):
            sel = ex == want
            r = steady_batch.roots(st, b + want, lv[sel])
            worst = min(worst, float(loaded.point_margins(r, ex[sel], p.u_r, p.levels).min()))
        out.append(worst)
    return np.array(out)
