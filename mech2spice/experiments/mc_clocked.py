"""Monte-Carlo of clocked designs and of the processor: one sampled model per run, compared cycle by cycle.

* `ClockedMC`: a clocked design (sqrt.v, counters ...) under a stimulus of clock cycles, run through
  simulation.run_clocked_physical on the sample's model; it passes when every cycle's outputs equal the
  clocked logic oracle's.  Every element is spread as in experiments/montecarlo.py, drives included.
* `CpuMC`: the processor (cpu/physical.PhysicalCPU on the sample's model) running a program for N cycles;
  it passes when every cycle's record (pc, phase, read address and data, write enable; write address and
  data when it writes) equals the instruction-set simulator's.  The oscillator network's elements are spread (the gates' source drives included); the
  memory's data forces and the clock/reset drives are external and stay nominal.

Neither checks gate channels one by one (a clocked run keeps only its outputs), so no per-gate failure
rate is measured: `gates` is empty and the summary's rate is None.  Samples run one per engine run (CpuMC with batch=K: K processors as one union model, cpu/batch.py).
"""
from __future__ import annotations

import math

from .. import simulation
from ..backends import continuing, names
from ..errors import DivergenceError
from ..errors import Mech2SpiceError
from . import clocking
from ..physics import network, spread
from ..physics.noise import check_temperature
from ..synthesis.ports import output_bits
from .montecarlo import SpreadSpec, noise_seed

CLOCKED_BACKENDS = names(continuing, first="envelope")   # one sample per run, cycle after cycle


def sampled(model, elems, spec: SpreadSpec, seed: int, i: int):
    """Sample i of `model`: (its model, the factor of every drive); (model, None) when nothing is spread."""
    import numpy as np
    if spec.zero:
        return model, None
    sample, f = spec.sample(model, elems, seed, i)
    fd = np.ones(len(model.drives))
    for e, x in zip(elems, f):
        if e.kind == "drive":
            fd[e.index] = x
    return sample, fd


def _failed(i: int, e: Exception) -> dict:
    return {"i": i, "pass": False, "margin": -math.inf, "failing_bits": {}, "failing_gates": [],
            "reason": str(e).splitlines()[0]}


class ClockedMC:
    """A clocked design under a stimulus of cycles; evaluates samples against the clocked logic oracle."""

    def __init__(self, netlist, p, steps: list[dict], backend: str, spec: SpreadSpec, seed: int,
                 options=None, noise: float = 0.0):
        if not netlist.clocked:
            raise Mech2SpiceError(f"{netlist.top} is not clocked")
        if backend not in CLOCKED_BACKENDS:
            raise Mech2SpiceError(f"clocked montecarlo runs on {', '.join(CLOCKED_BACKENDS)}, not '{backend}'")
        self.netlist, self.p, self.backend, self.spec, self.seed = netlist, p, backend, spec, seed
        self.options, self.noise = options, check_temperature(noise)
        self.cycles = simulation.expand_steps(steps)
        self.timing = clocking.clock_timing(netlist, p=p)
        self.want = simulation.run_clocked_logic(netlist, self.cycles)["trace"]
        self.model = network.build(netlist, p)
        self.elems = spread.elements(self.model)
        self.outs = output_bits(netlist)
        self.gates, self.union = [], 1

    def evaluate(self, indices: list[int]) -> list[dict]:
        """One record per sample index."""
        return [self._one(i) for i in indices]

    def _one(self, i: int) -> dict:
        model, fd = sampled(self.model, self.elems, self.spec, self.seed, i)
        try:
            res = simulation.run_clocked_physical(self.netlist, self.p, self.cycles, self.backend, self.timing,
                                                  options=self.options, sample=(model, fd),
                                                  noise=(self.noise, noise_seed(self.seed, i)))
        except (DivergenceError, Mech2SpiceError) as e:
            return _failed(i, e)
        wrong, first = {}, None
        for got, want in zip(res["trace"], self.want):
            bad = [b for b in self.outs if got["bits"].get(b) != want["bits"][b]]
            for b in bad:
                wrong[b] = wrong.get(b, 0) + 1
            if bad and first is None:
                first = got["cycle"]
        return {"i": i, "pass": not wrong, "margin": res["min_margin"], "failing_bits": wrong, "failing_gates": [],
                "first_bad_cycle": first, "periods": res["periods"]}


class CpuMC:
    """The processor running a program for `cycles` cycles; evaluates samples against the ISS cycle by cycle."""

    def __init__(self, program: str, cycles: int, p, backend: str, spec: SpreadSpec, seed: int, noise: float = 0.0,
                 batch: int = 1, max_fanout: int | None = None, step: float | None = None, etd: bool = True,
                 etd_step: float | None = None, latency_calm: float | None | str = "own",
                 latency_wake: float | None | str = "own"):
        from ..cpu.physical import ETD_PROCESSOR_STEP, LATENCY_CALM, LATENCY_WAKE, PHYSICAL
        if backend not in PHYSICAL:
            raise Mech2SpiceError(f"cpu montecarlo runs on {', '.join(PHYSICAL)}, not '{backend}'")
        self.program, self.cycles, self.p, self.backend = program, cycles, p, backend
        self.noise = check_temperature(noise)
        self.max_fanout = max_fanout or network.MAX_FANOUT
        # samples per union model (cpu/batch.py); with noise one per run, as DesignMC does
        self.batch = 1 if self.noise else batch
        self.spec, self.seed = spec, seed
        self.step, self.etd = step, etd      # etd: the envelope's exponential step with ETDRK4 (backends/envelope.py)
        # the processor's step cap where ETDRK4 steps it (16: files written before ETD_PROCESSOR_STEP)
        self.etd_step = etd_step or ETD_PROCESSOR_STEP
        # the processor's calm rule ("own": LATENCY_CALM; None: the hold rule, for files written before it)
        self.latency_calm = LATENCY_CALM if latency_calm == "own" else latency_calm
        self.latency_wake = LATENCY_WAKE if latency_wake == "own" else latency_wake     # None: files before it
        if step is not None:
            self._check_step()
        self.want = self._iss()
        self.gates, self.union, self.outs = [], 1, ["pc", "phase", "raddr", "rdata", "we", "waddr", "wdata"]

    def _check_step(self) -> None:
        """An explicit envelope step, checked once on the nominal machine (not found out sample by sample as
        a refusal that would count as a failed processor)."""
        from ..backends import envelope
        from ..cpu.physical import EXPONENTIAL, PhysicalCPU
        from ..cpu.run import load_program, make_memory
        if self.backend != "envelope":
            raise Mech2SpiceError(f"a step applies to the envelope backend, not {self.backend}")
        cpu = PhysicalCPU(make_memory(load_program(self.program)), self.backend, self.p, power_up=False,
                          step=self.step, max_fanout=self.max_fanout, etd=self.etd, etd_step=self.etd_step,
                          latency_calm=self.latency_calm, latency_wake=self.latency_wake)
        envelope._check_step(cpu.model, self.step, EXPONENTIAL, self.etd)

    def compared(self, want) -> list[str]:
        """The fields a cycle must match: the write address and data only when the ISS writes (else they
        are don't-cares the memory ignores)."""
        return self.outs if want.we else [f for f in self.outs if f not in ("waddr", "wdata")]

    def _iss(self) -> list:
        from ..cpu.iss import ISS
        from ..cpu.run import load_program, make_memory
        iss = ISS(make_memory(load_program(self.program)))
        out = []
        while len(out) < self.cycles:
            out.append(iss.step())
        return out

    def evaluate(self, indices: list[int]) -> list[dict]:
        """One record per sample index, `self.batch` samples per union model."""
        if self.batch <= 1:
            return [self._one(i) for i in indices]
        out = []
        for k in range(0, len(indices), self.batch):
            group = list(indices[k:k + self.batch])
            out += self._batch(group) if len(group) > 1 else [self._one(group[0])]
        return out

    def _machine(self, i: int, power_up: bool = True):
        """The processor on sample i's model, powered up (or not: cpu/batch.py powers copies up together)."""
        from ..cpu.physical import PhysicalCPU
        from ..cpu.run import load_program, make_memory
        cpu = PhysicalCPU(make_memory(load_program(self.program)), self.backend, self.p, power_up=False,
                          noise=(self.noise, noise_seed(self.seed, i)), max_fanout=self.max_fanout,
                          step=self.step, etd=self.etd, etd_step=self.etd_step, latency_calm=self.latency_calm,
                          latency_wake=self.latency_wake)
        nominal = cpu.model
        model, _ = sampled(nominal, spread.elements(nominal), self.spec, self.seed, i)
        cpu.model = model               # the probes (latch outputs) are copied with the model
        if power_up:
            cpu.amps = cpu._reset()
        return cpu

    def _batch(self, idx: list[int]) -> list[dict]:
        """Samples idx as one union model (cpu/batch.BatchCPU), compared cycle by cycle as _one does; if the
        union run stops (a divergence or an engine refusal), each sample runs alone instead."""
        from ..cpu.batch import BatchCPU
        recs = {i: {"wrong": {}, "first": None, "n": 0} for i in idx}
        try:
            bc = BatchCPU([self._machine(i, power_up=False) for i in idx])
            for want in self.want:
                if not any(bc.alive):
                    break
                got = bc.step()
                for k, i in enumerate(idx):
                    if got[k] is None:
                        continue
                    r = recs[i]
                    r["n"] += 1
                    bad = [f for f in self.compared(want) if getattr(got[k], f) != getattr(want, f)]
                    for f in bad:
                        r["wrong"][f] = r["wrong"].get(f, 0) + 1
                    if bad:
                        r["first"] = got[k].cycle
                        bc.retire(k)          # the programs diverge: later cycles compare nothing
        except (DivergenceError, Mech2SpiceError):
            return [self._one(i) for i in idx]
        out = []
        for k, i in enumerate(idx):
            r, err = recs[i], bc.errors.get(k)
            if err is not None:
                out.append({**_failed(i, err), "cycles_run": r["n"]})
            else:
                out.append({"i": i, "pass": not r["wrong"], "margin": None, "failing_bits": r["wrong"],
                            "failing_gates": [], "first_bad_cycle": r["first"], "cycles_run": r["n"]})
        return out

    def _one(self, i: int) -> dict:
        wrong, first, n = {}, None, 0
        try:
            cpu = self._machine(i)
            for want in self.want:
                got = cpu.step()
                n += 1
                bad = [f for f in self.compared(want) if getattr(got, f) != getattr(want, f)]
                for f in bad:
                    wrong[f] = wrong.get(f, 0) + 1
                if bad:
                    first = got.cycle if first is None else first
                    break                     # the programs diverge: later cycles compare nothing
        except (DivergenceError, Mech2SpiceError) as e:
            return {**_failed(i, e), "cycles_run": n}
        return {"i": i, "pass": not wrong, "margin": None, "failing_bits": wrong, "failing_gates": [],
                "first_bad_cycle": first, "cycles_run": n}


def add_sample_options(ap) -> None:
    """A script's options naming processor Monte-Carlo samples (`cpu montecarlo`'s): block, spread, trim, seed,
    fan-out limit and program (scripts/latency_rule_check.py, scripts/spread_settle_check.py)."""
    ap.add_argument("--params", default="centered_fc2")
    ap.add_argument("--spread", type=float, default=0.01, help="local spread of every element kind")
    ap.add_argument("--trim", default="fcb")
    ap.add_argument("--trim-residual", type=float, default=1e-4)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--max-fanout", type=int, default=12)
    ap.add_argument("--program", default="programs/sieve.asm")


def cpu_mc_of(args, cycles: int, **options) -> CpuMC:
    """The envelope processor Monte-Carlo that add_sample_options' `args` name, over `cycles` cycles."""
    from ..physics.params import load_params
    from .montecarlo import spec_of
    spec = spec_of({"local": args.spread, "trim": args.trim, "trim_residual": args.trim_residual})
    return CpuMC(args.program, cycles, load_params(args.params), "envelope", spec, args.seed,
                 max_fanout=args.max_fanout, **options)
