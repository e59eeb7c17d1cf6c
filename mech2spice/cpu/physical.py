"""The processor at oscillator level (envelope or RK4) against the behavioural memory.

Each clock cycle, as in the paper, the memory "actively monitors the output degrees of freedom":
1. the state after the previous edge is visible (settled): decode the read address from the raddr
   channels' amplitudes (an invalid bit stops the run, naming the cycle and bit);
2. drive rdata with mem[raddr] as forces and let the datapath settle (skipped if rdata is unchanged);
3. decode we / waddr / wdata, pulse the clock, commit the write at the edge;
4. settle again: the new register values (read from the latch outputs) become visible.
The halt is the logic backend's: no register changed at the edge.
"""
from __future__ import annotations

import re

import numpy as np

from dataclasses import replace

from ..backends import continuing, engine_class, envelope, make_engine, names
from ..errors import Mech2SpiceError
from ..experiments import clocking
from ..physics import network
from ..physics.params import DEFAULT
from . import state_file
from .isa import mnemonic
from .iss import FETCH, Cycle
from .memory import Memory
from .settle_check import SettleCheck
from .netlist import CPU_VERILOG, cpu_netlist, register_map, registers_from_amplitudes

PHYSICAL = names(continuing, first="envelope")   # engines that continue from a state, so a cycle can follow the last
# The defaults: 0.0098 u_R from the full envelope at step 2 over the first 30 sieve cycles, 7.2x faster than
# step 8 + settle alone (reports/fidelity.md; latency 0.2: 0.042 u_R, over the 0.02 bound; step 20: slower)
PROCESSOR_STEP = 16.0   # envelope periods with the exponential step (its bound: 27.5)
ETD_PROCESSOR_STEP = 20.0   # ... where ETDRK4 steps the amplitudes (engine.takes_etd): centered_fc2's first 30 sieve
                            # cycles read within 0.0051 u_R of step 2 (0.0037 at 16), against the insulators-only
                            # step's 0.0098 at 16 on the default block; 24 saved only 2 % more block-steps (docs/latency.md)
RK4_PROCESSOR_STEP = 8.0   # the step without it (RK4's bound: 15.1 periods)
SETTLE_TOL = 0.1        # u_R: end a pause once the channels settle (reports/fidelity.md)
LATENCY = envelope.PROCESSOR_LATENCY   # u_R: the envelope's per-gate latency threshold (docs/latency.md)
LATENCY_CALM = 40.0     # the calm rule: a gate block freezes once its own channel stayed calm this many periods and
                        # its input channels the envelope's LATENCY_HOLD (200); 20 % fewer block-steps, reads as
                        # close to step 2 (docs/latency.md, "The calm rule"); None: the hold rule before it
LATENCY_WAKE = 0.05     # u_R: a frozen gate block wakes once an input channel moved this much; at the threshold, 0.1,
                        # a gate frozen while its driver drifted below it was read up to 0.3 of a margin short of
                        # rest (centered_fc2: 420 of the sieve's 914 reads, now 0; docs/latency.md, "The wake
                        # threshold"); None: the threshold
OWN_LATENCY = "own"     # latency: the engine's own default (Engine.processor_latency; rk4 has none)
READ_PERIODS = 10       # periods a read averages over, at the end of each pulse or pause: all a run keeps
EXPONENTIAL = True      # insulators stepped exactly (lifts the step's stability bound; docs/latency.md)


def _options(backend: str, **settings):
    """The engine's options from the processor's settings: each engine takes those among its own fields
    (envelope: step_periods, latency, exponential, etd, parallel; carrier: latency, threads, steps_per_period;
    rk4: steps_per_period); steps_per_period only where given, else the engine's default."""
    from dataclasses import fields
    cls = engine_class(backend).Options
    settings = {"step_periods": settings.pop("step"), **settings, "latency": settings["latency"] or None}
    if not settings["steps_per_period"]:
        del settings["steps_per_period"]
    own = {f.name for f in fields(cls)}
    return cls(**{k: v for k, v in settings.items() if k in own})


def _no_inf(a: np.ndarray, key: str) -> np.ndarray:
    if a.dtype.kind in "fc" and np.isinf(a).any():
        raise ValueError(f"field '{key}' holds infinite values")
    return a


class PhysicalCPU:
    """The processor as oscillators (an engine that continues from a state) against the behavioural memory."""

    def __init__(self, memory: Memory, backend: str = "envelope", p=DEFAULT, *, step: float | None = None,
                 settle: float | None = SETTLE_TOL, latency: float | None | str = OWN_LATENCY,
                 exponential: bool = EXPONENTIAL, etd: bool = True, parallel: bool = False, power_up: bool = True,
                 noise: tuple[float, int] | None = None, steps_per_period: int | None = None, threads: int = 1,
                 settle_check: int | None = None, max_fanout: int | None = None,
                 etd_step: float = ETD_PROCESSOR_STEP, latency_calm: float | None = LATENCY_CALM,
                 latency_wake: float | None = LATENCY_WAKE):
        if backend not in PHYSICAL:
            raise Mech2SpiceError(f"no physical processor backend '{backend}' (choose from {', '.join(PHYSICAL)})")
        if settle_check and noise and noise[0]:
            raise Mech2SpiceError("a settle check needs a deterministic machine: not with thermal noise")
        # max_fanout: buffer trees above this many loads (synthesis.synth.limit_fanout); None: the network's limit
        self.netlist = cpu_netlist(str(CPU_VERILOG), max_fanout=max_fanout or network.MAX_FANOUT)
        self.model = network.build(self.netlist, p)
        self.regmap = register_map(self.netlist)
        for q, block in self.model.design.latch_outputs.items():
            self.model.add_probe(f"latch.{q}", block.channel)
        self.probes = list(self.model.probes)
        if latency == OWN_LATENCY:
            latency = engine_class(backend).processor_latency(threads)
        settings = dict(latency=latency, latency_calm=latency_calm, latency_wake=latency_wake,
                        exponential=exponential, etd=etd,
                        parallel=parallel, steps_per_period=steps_per_period,
                        threads=threads, keep_periods=READ_PERIODS)
        if not step:      # the processor's step, shortened where a block's faster envelope rates bound it
            cap = PROCESSOR_STEP if exponential else RK4_PROCESSOR_STEP
            engine = make_engine(backend, _options(backend, step=cap, **settings))
            if exponential and engine.takes_etd(self.model, etd_step):   # etd_step: older Monte-Carlo files' 16
                cap = etd_step
            step = engine.longest_step(self.model, cap)
        options = _options(backend, step=step, **settings)
        # only pauses may end early once settled; pulses always run in full
        self.pulse_engine = make_engine(backend, options)
        self.pause_engine = make_engine(backend, replace(options, settle_tol=settle or None))
        step = self.pulse_engine.reported_step(step)   # carrier: its own; rk4 the envelope's, as it always has
        if noise and noise[0]:          # thermal noise (k_B T, seed): the noisy engine, never settled or frozen
            from ..backends import noisy_engine
            self.pulse_engine = self.pause_engine = noisy_engine(backend, self.pulse_engine.options, *noise)
        t = clocking.clock_timing(self.netlist, p=p)
        averaged = engine_class(backend).capabilities.averaged      # steps of whole periods, `step` long
        whole = max(1, int(round(step))) if averaged else 1   # changes fall on step boundaries
        self.pulse, self.pause = -(-t["pulse"] // whole) * whole, -(-t["pause"] // whole) * whole
        self.backend, self.p, self.mem = backend, p, memory
        self.step_periods, self.settle, self.latency = step, settle, latency
        # where the engine takes a calm time (the envelope; the carrier's latency has its own rule)
        self.latency_calm = latency_calm if latency and hasattr(self.pause_engine.options, "latency_calm") else None
        self.latency_wake = latency_wake if latency and hasattr(self.pause_engine.options, "latency_wake") else None
        self.block_steps = 0        # gate blocks x steps integrated (latency); 0 without it
        self.simulated = 0          # periods actually integrated (a settled pause skips the rest)
        self.state, self.period, self.rdata = None, 0, 0
        self._stimuli = {}          # (model, inputs, clock) -> its Stimulus: built once, not 1372 times a sieve
        # every pause's read judged against its own future (cpu/settle_check.py); None: not checked
        self.settle_check = SettleCheck(settle_check, p.levels) if settle_check else None
        self._check_engine = self.settle_check.engine_for(self.pause_engine) if settle_check else None
        self.cycle, self.halted = 0, False
        self._eigen_start = None     # the last verdict's eigenvectors (stability())
        self.amps = self._reset() if power_up else None      # else: load() a checkpoint

    # --- integration -----------------------------------------------------------------------
    def _stimulus(self, values: dict, clock: int):
        key = (id(self.model), tuple(sorted(values.items())), clock)    # a Monte-Carlo sample swaps the model
        if key not in self._stimuli:
            self._stimuli[key] = network.stimulus(self.model, self.netlist, self.p, [(0, [values])], clock=[[clock]])
        return self._stimuli[key]

    def _run(self, periods: int, values: dict, clock: int) -> dict[str, float]:
        stim = self._stimulus(values, clock)
        engine = self.pulse_engine if clock else self.pause_engine
        run = engine.run(self.model, periods, stim, state=self.state, start_period=self.period, probes=self.probes)
        self.state = run.state
        self.simulated += periods - run.settled_periods
        self.block_steps += run.extra.get("block_steps", 0)
        self.period += periods
        amp = dict(zip(self.probes, np.abs(run.amp[-READ_PERIODS:, :, 0]).mean(axis=0) / self.p.u_r))
        if self.settle_check is not None and not clock:
            self.settle_check.check(self._check_engine, self.model, stim, self.state, self.period, self.probes,
                                    amp, self.cycle, self.p.u_r)
        return amp

    def _reset(self) -> dict[str, float]:
        """Power up from rest with rst = 1, clock one edge, release rst."""
        self._run(self.pause, {"rst": 1}, 0)
        self._run(self.pulse, {"rst": 1}, 1)
        return self._run(self.pause, {"rst": 0}, 0)

    # --- decoding --------------------------------------------------------------------------
    def _port(self, amps, port: str, what: str) -> int:
        bits = [self.p.levels.band_of(amps[f"{port}[{i}]"]) for i in range(self.netlist.outputs[port])]
        return Memory.decode_address(bits, self.cycle, what)

    def registers(self, amps=None) -> dict:
        """The architectural registers decoded from the latch outputs' amplitudes (an invalid bit stops the run)."""
        return registers_from_amplitudes(self.regmap, self.p.levels, amps or self.amps, self.cycle)

    def set_registers(self, regs: dict) -> None:
        """Registers cannot be forced into oscillators: after load(), check that the restored state
        decodes to the checkpoint's registers."""
        if self.amps is None:
            raise Mech2SpiceError("a physical run resumes from its saved oscillator state (load() it first)")
        if self.registers() != regs:
            raise Mech2SpiceError(f"the saved oscillator state decodes to {self.registers()}, not the "
                                  f"checkpoint's registers {regs}")

    # --- checkpoints: the whole dynamical state, so a resumed run continues exactly ----------
    def save(self, path) -> str:
        """Write the dynamical state to `path` (durably: the checkpoint names it next); returns its sha256."""
        arrays = {f"state{k}": np.asarray(a) for k, a in enumerate(self.state)}
        return state_file.write(path, **arrays, period=self.period, rdata=self.rdata, simulated=self.simulated,
                                block_steps=self.block_steps,
                                probes=np.array(self.probes), amps=np.array([self.amps[k] for k in self.probes]),
                                backend=self.backend, step=self.step_periods)

    def load(self, path, sha256: str | None = None) -> None:
        """Restore the state save() wrote; with `sha256`, the file must be exactly the one saved."""
        state_file.read(path, sha256, "oscillator state", lambda z: self._load_arrays(z, path))

    def _load_arrays(self, z: state_file.Fields, path) -> None:
        """Every array checked against what this engine's own state holds (count, dtype, shape) before the
        compiled kernels see it: a foreign shape would make them read and write out of bounds."""
        if z.text("backend") != self.backend or z.texts("probes") != self.probes:
            raise Mech2SpiceError(f"{path} holds the state of a different processor model or backend")
        fresh = self._fresh_state()
        n = sum(1 for k in z.files if re.fullmatch(r"state\d+", k))
        if n != len(fresh):
            raise Mech2SpiceError(f"{path}: {n} state arrays, the {self.backend} engine keeps {len(fresh)}")
        # arrays at rest are finite; the latency record's not-yet-recorded entries are NaN (never infinite)
        self.state = tuple(_no_inf(z.array(f"state{k}", f.dtype, f.shape, finite=bool(np.isfinite(f).all())),
                                   f"state{k}") for k, f in enumerate(fresh))
        self.period, self.rdata = z.integer("period"), z.integer("rdata", 0, 255)
        self.simulated = z.integer("simulated")
        self.block_steps = z.integer("block_steps") if "block_steps" in z.files else 0     # older files: not kept
        self.amps = dict(zip(self.probes, map(float, z.array("amps", float, (len(self.probes),)))))

    def _fresh_state(self) -> tuple:
        """The engine's state at rest, as it would continue from it (a run of no periods integrates nothing)."""
        return tuple(np.asarray(a) for a in self.pulse_engine.run(self.model, 0).state)

    def stability(self):
        """The stability verdict (physics/stability.py) of the machine as it stands, after its last pause:
        the fixed point nearest its state under the inputs it holds, and the least stable mode there."""
        from ..physics import stability
        from ..physics.envelope import Envelope
        A, s = self.pause_engine.phasors(self.model, self.state, self.period * self.model.period)
        stim = self._stimulus({"rdata": self.rdata}, 0)
        F = Envelope.of(self.model).forcing(stim.at(0))[:, 0]
        watch = {f"{g.name}.C": g.channel for g in self.model.design.gates}
        v = stability.verdict(self.model, A[:, 0], s[:, 0], F, watch, start=self._eigen_start)
        self._eigen_start = v.start          # the next cycle's state is near this one: start the search here
        return v

    # --- one clock cycle --------------------------------------------------------------------
    def step(self) -> Cycle:
        """One clock cycle: read, settle the datapath, pulse the clock, commit the write, settle again."""
        regs = self.registers()
        raddr = self._port(self.amps, "raddr", "read address")
        rdata = self.mem.read(raddr)
        amps = self.amps if rdata == self.rdata else self._run(self.pause, {"rdata": rdata}, 0)
        self.rdata = rdata
        we = self._port(amps, "we", "write enable")
        waddr, wdata = self._port(amps, "waddr", "write address"), self._port(amps, "wdata", "write data")
        self._run(self.pulse, {"rdata": rdata}, 1)
        self.mem.commit(waddr, wdata, we)
        self.amps = self._run(self.pause, {"rdata": rdata}, 0)
        self.halted = self.registers() == regs
        rec = Cycle(self.cycle, regs["pc"], regs["phase"], mnemonic(rdata) if regs["phase"] == FETCH else None,
                    raddr, rdata, we, waddr, wdata)
        self.cycle += 1
        return rec
