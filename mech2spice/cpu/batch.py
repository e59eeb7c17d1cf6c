"""Several processors, each on its own sampled model, integrated together as one union model.

A Monte-Carlo sample of the processor (experiments/mc_clocked.CpuMC) is a PhysicalCPU on a sampled model.
`BatchCPU` holds K of them as the block-diagonal union of their models (each copy's DOFs, links, drives
and gate blocks, its DOF names prefixed "s{k}/"), so one engine call integrates every copy: one compiled
call per pulse or pause instead of K, and the latency record freezes each copy's settled blocks on their
own (copies share no link, so no block reads another copy's DOFs).  Each copy keeps its own memory,
decodes its own ports and drives its own rdata and clock; a cycle runs the steps of PhysicalCPU.step
for every live copy at once.

What differs from K separate runs: a pause ends when every copy has settled (a lone copy would end at its
own settle), and a copy whose rdata did not change still integrates through a pause another copy needs
(a lone run skips it).  Both only continue a settled state further, within the settle tolerance (0.1 u_R);
tests/test_cpu_batch.py checks that the decoded cycles of each copy equal its lone run's, and shows the
exception: a marginal copy (a latch drifting at 0.54 u_R) that the lone run reads invalid one cycle earlier.
A copy that fails stops being compared: its inputs are held and its blocks frozen, so it costs no more
integration.

It buys no speed (scripts/cpu_mc_batch_speed.py, docs/design.md "The processor under spread, round 2"): the
compiled latency loop's cost is its active blocks' arithmetic, per copy; even K identical columns of one
model (the envelope's own batch) cost K times one.  Hence no command-line flag; CpuMC(batch=K) keeps it
for a kernel that shares work across members.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..errors import Mech2SpiceError
from ..physics.model import Design
from ..physics.stimulus import Stimulus
from .iss import FETCH, Cycle
from .isa import mnemonic
from .physical import READ_PERIODS, PhysicalCPU


def union_model(models: list, prefixes: list[str]):
    """experiments/tolerance.union plus the copies' gate blocks (offset), so the envelope's settle watch and
    its latency blocks see every copy's gates; the params of the first (the decoding levels)."""
    from ..experiments.tolerance import union
    big = union(models, prefixes)
    big.params = models[0].params
    gates, base = [], 0
    for m in models:
        gates += [_shifted(g, base) for g in m.design.gates]
        base += m.n
    big.design = Design(gates=gates)
    return big


def _shifted(block, base: int):
    return replace(block, channel=block.channel + base, insulator=block.insulator + base,
                   inputs=[tuple(d + base for d in pair) for pair in block.inputs],
                   dofs=tuple(d + base for d in block.dofs), source=block.source + base if block.source >= 0 else -1)


class BatchCPU:
    """K PhysicalCPUs (each on its own model, built with power_up=False) integrated as one union model."""

    def __init__(self, cpus: list[PhysicalCPU]):
        self.cpus = cpus
        self.prefixes = [f"s{k}/" for k in range(len(cpus))]
        self.model = union_model([c.model for c in cpus], self.prefixes)
        self.bases = list(np.cumsum([0] + [c.model.n for c in cpus[:-1]]))
        for pre, base, c in zip(self.prefixes, self.bases, cpus):
            for name in c.probes:
                self.model.add_probe(pre + name, int(base) + c.model.probes[name])
        self.probes = list(self.model.probes)
        self.pulse_engine, self.pause_engine = cpus[0].pulse_engine, cpus[0].pause_engine
        self.pulse, self.pause, self.p = cpus[0].pulse, cpus[0].pause, cpus[0].p
        self.state, self.period = None, 0
        self.alive = [True] * len(cpus)
        self.held: dict[int, dict] = {}        # dead copy -> the inputs it keeps
        self._frozen: set[int] = set()
        self.errors: dict[int, Exception] = {}
        for c in cpus:
            c.rdata, c.cycle = 0, 0
        self._reset()

    # --- integration ------------------------------------------------------------------------
    def _stimulus(self, values: list[dict], clock: int) -> Stimulus:
        """Each copy's own stimulus (its own model's drives), side by side; dead copies at their held inputs."""
        parts = []
        for k, c in enumerate(self.cpus):
            v, ck = (values[k], clock) if self.alive[k] else (self.held[k], 0)
            parts.append(c._stimulus(v, ck))
        return Stimulus(parts[0].times, np.concatenate([s.amps for s in parts], axis=1))

    def _run(self, periods: int, values: list[dict], clock: int) -> list[dict[str, float]]:
        stim = self._stimulus(values, clock)
        engine = self.pulse_engine if clock else self.pause_engine
        if self.state is not None and set(self.held) - self._frozen:
            self._freeze_dead(stim)
        run = engine.run(self.model, periods, stim, state=self.state, start_period=self.period, probes=self.probes)
        self.state = run.state
        self.period += periods
        mean = np.abs(run.amp[-READ_PERIODS:, :, 0]).mean(axis=0) / self.p.u_r
        amp = dict(zip(self.probes, mean))
        return [{name: amp[pre + name] for name in c.probes} for pre, c in zip(self.prefixes, self.cpus)]

    def _freeze_dead(self, stim: Stimulus) -> None:
        """Freeze every block of the newly dead copies: inactive, with their latency record at the present
        state and at the forcing of their held inputs, so nothing wakes them (copies share no link)."""
        from ..backends.envelope import kernel
        from ..physics.envelope import Envelope
        kern = kernel(self.model)
        if kern is None or kern.blocks is None or len(self.state) != 8:
            return                                  # no latency record: dead copies just keep integrating
        A, s = self.state[0], self.state[1]
        active, quiet, snap_f, snap_s, snap_F = self.state[3:]
        F = Envelope.of(self.model).forcing(stim.at(self.period * self.model.period))
        blk = kern.blocks
        for k in sorted(set(self.held) - self._frozen):
            first = sum(len(c.model.design.gates) for c in self.cpus[:k])
            for b in range(first, first + len(self.cpus[k].model.design.gates)):
                lo, hi = blk.ext_f[0][b], blk.ext_f[0][b + 1]
                snap_f[lo:hi] = A[blk.ext_f[1][lo:hi]]
                lo, hi = blk.ext_s[0][b], blk.ext_s[0][b + 1]
                snap_s[lo:hi] = s[blk.ext_s[1][lo:hi]]
                lo, hi = blk.res[0][b], blk.res[0][b + 1]
                snap_F[lo:hi] = F[blk.res[1][lo:hi]]
                active[b], quiet[b] = 0, 0
            self._frozen.add(k)

    def _reset(self) -> None:
        """Power up every copy from rest with rst = 1, clock one edge, release rst (PhysicalCPU._reset)."""
        n = len(self.cpus)
        self._run(self.pause, [{"rst": 1}] * n, 0)
        self._run(self.pulse, [{"rst": 1}] * n, 1)
        for c, a in zip(self.cpus, self._run(self.pause, [{"rst": 0}] * n, 0)):
            c.amps = a

    def _kill(self, k: int, err: Exception, values: dict) -> None:
        self.errors[k] = err
        self.retire(k, values)

    # --- one clock cycle for every live copy --------------------------------------------------
    def step(self) -> list[Cycle | None]:
        """PhysicalCPU.step for every live copy; None for a copy that is (or now became) dead, its error
        in `errors`."""
        live = [k for k, a in enumerate(self.alive) if a]
        regs, rdata = {}, {}
        for k in live:
            c = self.cpus[k]
            try:
                regs[k] = c.registers()
                raddr = c._port(c.amps, "raddr", "read address")
                rdata[k] = (raddr, c.mem.read(raddr))
            except Mech2SpiceError as e:
                self._kill(k, e, {"rdata": c.rdata})
        values = [{"rdata": rdata[k][1]} if k in rdata else self.held.get(k, {"rdata": c.rdata})
                  for k, c in enumerate(self.cpus)]
        changed = [k for k in rdata if rdata[k][1] != self.cpus[k].rdata]
        paused = self._run(self.pause, values, 0) if changed else None
        ports = {}
        for k in list(rdata):
            c = self.cpus[k]
            amps = paused[k] if k in changed else c.amps
            c.rdata = rdata[k][1]
            try:
                ports[k] = tuple(c._port(amps, port, what) for port, what in
                                 (("we", "write enable"), ("waddr", "write address"), ("wdata", "write data")))
            except Mech2SpiceError as e:
                self._kill(k, e, {"rdata": c.rdata})
        self._run(self.pulse, values, 1)
        for k, (we, waddr, wdata) in ports.items():
            self.cpus[k].mem.commit(waddr, wdata, we)
        after = self._run(self.pause, values, 0)
        out = [None] * len(self.cpus)
        for k, (we, waddr, wdata) in ports.items():
            c = self.cpus[k]
            c.amps = after[k]
            raddr, data = rdata[k]
            r = regs[k]
            out[k] = Cycle(c.cycle, r["pc"], r["phase"], mnemonic(data) if r["phase"] == FETCH else None,
                           raddr, data, we, waddr, wdata)
            c.cycle += 1
        return out

    def retire(self, k: int, values: dict | None = None) -> None:
        """Stop running copy k (its record is complete): its inputs held, its blocks frozen at the next run."""
        if self.alive[k]:
            self.alive[k], self.held[k] = False, values or {"rdata": self.cpus[k].rdata}
