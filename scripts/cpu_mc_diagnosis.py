"""Why a processor Monte-Carlo sample fails: the gates that compute a wrong value, per sample.

    python3 scripts/cpu_mc_diagnosis.py SAMPLE ... [--params centered_fc2] [--spread 0.01 --trim fc
        --trim-residual 1e-4] [--program programs/sieve.asm] [--cycles 30] [--seed 0]

Runs sample i's processor exactly as `cpu montecarlo` does (CpuMC._machine), and after every settled pause
checks each NOR block locally: a *root* failure is a block whose decoded output differs from NOR of its own
decoded inputs while those inputs are in band.  After each edge it also checks that every latch took the
value its D input held before the pulse (a capture failure, which a locally consistent latch would hide).
Prints JSON: per sample, the first cycle that differs from the ISS and the first root/capture failures with
amplitudes (u_R), fan-out, fan-in sources, latch membership and the block's own sampled element deviations.
"""
import argparse, json, re, sys
import numpy as np
from mech2spice.backends.logic import evaluate_bits
from mech2spice.cpu.physical import PhysicalCPU
from mech2spice.cpu.run import load_program, make_memory
from mech2spice.experiments import montecarlo as mc
from mech2spice.experiments.mc_clocked import CpuMC, sampled
from mech2spice.physics import loaded, spread, steady_batch
from mech2spice.physics.model import MechModel
from mech2spice.physics.envelope import Envelope
from mech2spice.physics.params import load_params


def local_gate(net, p, b, pins, loads=None, nominal=None, s_of=None):
    """Block b cut out of `net` (sample values) as a loaded gate: stand-in upstream channels (loaded.build's),
    its own DOFs and the input pairs of its loads (first `loads` of them, None: all), their insulators at rest.
    With `nominal`, the elements take the nominal network's values instead; with s_of (slow DOF -> position),
    the loads' insulators sit where the network holds them (their quadratic coupling: stiffness 2 gamma s).  Returns (model, groups, channel)."""
    src = nominal or net
    ch = b.channel
    sinks = [j for i, j, _ in net.springs if i == ch] + [j for i, j, _ in net.dashpots if i == ch]
    pair_of = {j: k for k, j in enumerate(j for i, j, _ in net.springs if i == ch)}
    keep_loads = sinks if loads is None else [j for j in sinks if pair_of.get(j, pair_of.get(j - 1, 0)) < loads]
    dofs = list(b.dofs) + keep_loads
    m = MechModel(omega=p.omega)
    out = p.structure.dof(p.structure.output)
    z_c = abs(out.k - out.m * p.omega ** 2 + 1j * p.omega * out.c)
    ups = [m.add_dof(f"in{k}.C", out.m, out.k, out.c) for k in (1, 2)]
    loc = {d: m.add_dof(src.names[d], src.mass[d], src.k_total[d], src.c_total[d], slow=src.slow[d]) for d in dofs}
    m.add_drive(loc[b.source], src.drives[[d.dof for d in src.drives].index(b.source)].amplitude, 0.0, "src")
    for k, ((kind, s), pair) in enumerate(zip(pins, b.inputs)):
        m.add_drive(ups[k], z_c * p.u_r, 0.0, f"in{k}")
        look = lambda links, j: next((v for i, jj, v in links if i == s and jj == j), None) if kind == "ch" else None
        m.add_spring(ups[k], loc[pair[0]], look(src.springs, pair[0]) or p.k_couple)
        m.add_dashpot(ups[k], loc[pair[1]], look(src.dashpots, pair[1]) or p.c_couple)
    for links, add in ((src.springs, m.add_spring), (src.dashpots, m.add_dashpot), (src.quads, m.add_quad)):
        for i, j, v in links:
            if i in loc and j in loc:
                add(loc[i], loc[j], v)
            elif add == m.add_quad and i in loc and s_of is not None:
                m.k_total[loc[i]] += 2 * v * s_of[j]
    return m, np.array([0, 1, 2]), loc[ch]


def margins_of(p, model, groups, ch, x):
    """Loaded-gate margin over the input grid, and the stable output amplitudes (u_R) at input levels x."""
    st = steady_batch.stack([model], groups, ch)
    lv, ex = loaded.input_grid(loaded.PER_BAND, p.levels)
    pm = loaded.point_margins(steady_batch.roots(st, 0, lv), ex, p.u_r, p.levels)
    r = steady_batch.roots(st, 0, np.array([[1.0, *x]]))
    return dict(grid_margin=round(float(pm.min()), 4), worst_inputs=[round(float(v), 3) for v in lv[pm.argmin(), 1:]],
                stable_at_point=sorted(round(float(a) / p.u_r, 4) for a in r.amp[r.stable]))


def wiring(model):
    """Per block: per pin, ('ch', upstream channel DOF) or ('drive', drive index); per channel: its fan-out."""
    chans = {b.channel: b for b in model.design.gates}
    into = {}
    for i, j, _ in model.springs:
        if i in chans:
            into.setdefault(j, i)
    drv = {d.dof: k for k, d in enumerate(model.drives)}
    fan = {c: 0 for c in chans}
    pins = {}
    for b in model.design.gates:
        pins[b.name] = [("ch", into[p[0]]) if p[0] in into else ("drive", drv[p[0]]) for p in b.inputs]
        for kind, s in pins[b.name]:
            if kind == "ch":
                fan[s] += 1
    return chans, pins, fan


class Diagnosis:
    def __init__(self, job, i):
        self.job, self.i = job, i
        self.cpu = cpu = PhysicalCPU(make_memory(load_program(job.program)), job.backend, job.p, power_up=False)
        self.nominal = cpu.model
        cpu.model, _ = sampled(self.nominal, spread.elements(self.nominal), job.spec, job.seed, i)
        self.m, self.p, self.nl = cpu.model, job.p, cpu.netlist
        env = Envelope.of(self.m)
        self.row = np.full(self.m.n, -1)
        self.row[env.fast] = np.arange(env.fast.size)
        self.chans, self.pins, self.fan = wiring(self.m)
        self.latch_blocks = {b.name for b in self.m.design.latch_blocks}
        self.latch_q = {q: b.channel for q, b in self.m.design.latch_outputs.items()}
        self.found, self.pulsed, self.expect_q, self.seen = [], False, None, {}
        self.elems = spread.elements(self.nominal)
        self.f = dict(zip(self.elems, job.spec.factors(self.elems, job.seed, i)))
        run = cpu._run
        cpu._run = lambda periods, values, clock: self._after(run(periods, values, clock), values, clock)
        cpu.amps = cpu._reset()

    def amp(self, dof):
        return float(abs(self.cpu.state[0][self.row[dof], 0]) / self.p.u_r)

    def level(self, pin, values, clock=0):
        kind, s = pin
        if kind == "ch":
            return self.amp(s), self.chans[s].name
        stim = self.cpu._stimulus(values, clock)
        return float(stim.at(0)[s, 0] / self.p.f_r), self.m.drives[s].name

    def block(self, b, values, clock=0, **extra):
        ins = [self.level(pin, values, clock) for pin in self.pins[b.name]]
        bands = [self.p.levels.band_of(a) for a, _ in ins]
        return dict(gate=b.name, amplitude=round(self.amp(b.channel), 4), band=self.p.levels.band_of(self.amp(b.channel)),
                    inputs=[dict(source=n, amplitude=round(a, 4), band=bd,
                                 fanout_of_source=self.fan.get(self.pins[b.name][k][1]) if self.pins[b.name][k][0] == "ch" else None)
                            for k, ((a, n), bd) in enumerate(zip(ins, bands))],
                    nor=None if None in bands else int(not any(bands)), fanout=self.fan[b.channel],
                    latch=b.name in self.latch_blocks, deviations=self.deviations(b), **extra)

    def local(self, b, values):
        """The block's loaded-gate steady states at its inputs' levels: sample values with all its loads, with
        one load (the gate-level check's model), and nominal values with all its loads."""
        x = [self.level(pin, values)[0] for pin in self.pins[b.name]]
        pins, env = self.pins[b.name], Envelope.of(self.m)
        s_of = dict(zip(env.slow, np.real(self.cpu.state[1][:, 0])))
        return {name: margins_of(self.p, *local_gate(self.m, self.p, b, pins, loads, nom, s), x) for name, loads, nom, s in
                (("sample_all_loads", None, None, None), ("sample_all_loads_live_insulators", None, None, s_of),
                 ("sample_one_load", 1, None, None), ("nominal_all_loads", None, self.nominal, None))}

    def deviations(self, b):
        """The block's own elements: non-trimmed factors that differ most, and its DOFs' k/m, c/m, m after trim."""
        els = spread.elements(self.nominal, list(b.dofs))
        f = sorted(((e.name, round(self.f[e] - 1, 4)) for e in els if e.kind not in ("k", "c")), key=lambda t: -abs(t[1]))
        n, s = self.nominal, self.m
        per = {s.names[d]: [round(s.mass[d] / n.mass[d] - 1, 5), round(s.k_total[d] / s.mass[d] / (n.k_total[d] / n.mass[d]) - 1, 5),
                            round(s.c_total[d] / s.mass[d] / (n.c_total[d] / n.mass[d]) - 1, 5)] for d in b.dofs}
        return dict(largest=f[:6], dof_m_kpm_cpm=per)

    def roots(self, values, clock, where, val=None):
        """Blocks whose decoded output is not NOR of their in-band decoded inputs: first record per block."""
        for b in self.m.design.gates:
            if clock and re.search(r"\.d\d+$", b.name):      # a delay line lags the pulse by design
                continue
            ins = [self.p.levels.band_of(self.level(pin, values, clock)[0]) for pin in self.pins[b.name]]
            if None not in ins and self.p.levels.band_of(self.amp(b.channel)) != int(not any(ins)):
                key = ("root" if not clock else "root at pulse end", b.name)
                if key not in self.seen:
                    self.seen[key] = len(self.found)
                    self.found.append(dict(kind=key[0], at=where, pauses=0, **self.block(b, values, clock)))
                    if not clock:
                        self.found[-1]["local_gate"] = self.local(b, values)
                self.found[self.seen[key]]["pauses"] += 1

    def _after(self, amps, values, clock):
        if clock:
            self.pulsed = True
            self.roots(values, 1, f"cycle {self.cpu.cycle} end of pulse {values}")
            return amps
        q_band = {q: self.p.levels.band_of(self.amp(c)) for q, c in self.latch_q.items()}
        where = f"cycle {self.cpu.cycle} settled after {'edge' if self.pulsed else 'rdata'} {values}"
        if self.pulsed and self.expect_q is not None:       # the edge just taken
            for q, (want, d_amp, d_name) in self.expect_q.items():
                if q_band[q] != want and ("capture", q) not in self.seen:
                    self.seen[("capture", q)] = len(self.found)
                    self.found.append(dict(kind="capture", at=where, latch=q, expected=want, band=q_band[q],
                                           amplitude=round(self.amp(self.latch_q[q]), 4), D=d_name, D_amplitude=round(d_amp, 4)))
        state = {q: v if v is not None else 0 for q, v in q_band.items()}
        val = evaluate_bits(self.nl, values, state)
        self.roots(values, 0, where)
        g, outs = self.nl.graph, {**{n: b for n, b in self.m.design.blocks.items()}}
        self.expect_q = {}
        for q in self.latch_q:
            (d,) = g.predecessors(q)
            d_amp = self.amp(outs[d].channel) if d in outs else float("nan")
            self.expect_q[q] = (val[d], d_amp, d)
        self.pulsed = False
        return amps

    def run(self):
        first = None
        for want in self.job.want:
            got = self.cpu.step()
            bad = [f for f in self.job.compared(want) if getattr(got, f) != getattr(want, f)]
            if bad:
                first = dict(cycle=got.cycle, fields={f: [getattr(got, f), getattr(want, f)] for f in bad})
                break
        return dict(sample=self.i, first_bad=first, failures=self.found)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("samples", type=int, nargs="+")
    ap.add_argument("--params", default="centered_fc2"); ap.add_argument("--program", default="programs/sieve.asm")
    ap.add_argument("--spread", type=float, default=0.01); ap.add_argument("--trim", default="fc")
    ap.add_argument("--trim-residual", type=float, default=1e-4); ap.add_argument("--cycles", type=int, default=30)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    kinds = ("k", "m", "c", "spring", "dashpot", "gamma", "drive")
    spec = mc.spec_of({"local": {k: a.spread for k in kinds}, "trim": a.trim, "trim_residual": a.trim_residual})
    job = CpuMC(a.program, a.cycles, load_params(a.params), "envelope", spec, a.seed)
    for i in a.samples:
        print(json.dumps(Diagnosis(job, i).run()), flush=True)


if __name__ == "__main__":
    sys.exit(main())
