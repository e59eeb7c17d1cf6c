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

import os
from pathlib import Path

import numpy as np

from .. import simulate
from ..physics import network
from ..errors import Mech2SpiceError
from ..physics.params import DEFAULT, band_of
from .iss import FETCH, LDNX, LOAD, REGISTERS, Cycle
from .isa import mnemonic
from .memory import Memory

ENVELOPE_STEP = 8.0     # periods: within tolerance with SETTLE (reports/fidelity.md), 1.9x below the bound
SETTLE = 0.1            # u_R: end a pause once the channels settle (envelope.integrate); benchmarks/fidelity.py


class PhysicalCPU:
    def __init__(self, memory: Memory, backend: str = "envelope", p=DEFAULT, *, step: float = ENVELOPE_STEP,
                 settle: float | None = SETTLE, power_up: bool = True):
        from ..synthesis.synth import synthesize
        from .run import CPU_VERILOG, register_map
        if backend not in ("envelope", "rk4"):
            raise Mech2SpiceError(f"no physical processor backend '{backend}'")
        self.netlist = synthesize(CPU_VERILOG, max_fanout=network.MAX_FANOUT)
        self.model = network.build(self.netlist, p)
        self.regmap = register_map(self.netlist)
        for q, block in self.model.design.latch_outputs.items():
            self.model.add_probe(f"latch.{q}", block.channel)
        self.probes = list(self.model.probes)
        t = simulate.clock_timing(self.netlist)
        whole = max(1, int(round(step)))            # stimulus changes fall on step boundaries
        self.pulse, self.pause = -(-t["pulse"] // whole) * whole, -(-t["pause"] // whole) * whole
        self.backend, self.p, self.mem = backend, p, memory
        self.step_periods, self.settle = step, settle
        self.simulated = 0          # periods actually integrated (a settled pause skips the rest)
        self.state, self.period, self.rdata = None, 0, 0
        self.cycle, self.halted = 0, False
        self.amps = self._reset() if power_up else None      # else: load() a checkpoint

    # --- integration -----------------------------------------------------------------------
    def _run(self, periods: int, values: dict, clock: int) -> dict[str, float]:
        from ..physics import envelope
        from ..backends import rk4
        stim = network.stimulus(self.model, self.netlist, self.p, [(0, [values])], clock=[[clock]])
        if self.backend == "envelope":
            run = envelope.integrate(self.model, periods, step_periods=self.step_periods, stimulus=stim,
                                     state=self.state, start_period=self.period, probes=self.probes,
                                     settle=self.settle if clock == 0 else None)
            self.state = run.extra["envelope_state"]
            self.simulated += periods - run.extra["settled_periods"]
        else:
            run = rk4.integrate(self.model, periods, stimulus=stim, state=self.state, start_period=self.period,
                                probes=self.probes)
            self.state = (run.x, run.v)
            self.simulated += periods
        self.period += periods
        amp = np.abs(run.amp[-10:, :, 0]).mean(axis=0) / self.p.u_r
        return dict(zip(self.probes, amp))

    def _reset(self) -> dict[str, float]:
        """Power up from rest with rst = 1, clock one edge, release rst."""
        self._run(self.pause, {"rst": 1}, 0)
        self._run(self.pulse, {"rst": 1}, 1)
        return self._run(self.pause, {"rst": 0}, 0)

    # --- decoding --------------------------------------------------------------------------
    def _port(self, amps, port: str, what: str) -> int:
        bits = [band_of(amps[f"{port}[{i}]"]) for i in range(self.netlist.outputs[port])]
        return Memory.decode_address(bits, self.cycle, what)

    def registers(self, amps=None) -> dict:
        amps = amps or self.amps
        vals = dict.fromkeys(("pc", "a", "b", "c", "d", "ov", "ld", "nx"), 0)
        for q, (reg, bit) in self.regmap.items():
            b = band_of(amps[f"latch.{q}"])
            if b is None:
                raise Mech2SpiceError(f"cycle {self.cycle}: register {reg} bit {bit} (latch {q}) is invalid "
                                      f"(amplitude {amps[f'latch.{q}']:.3f} u_R)")
            vals[reg] |= b << bit
        ld, nx = vals.pop("ld"), vals.pop("nx")
        return {**{r: vals[r] for r in REGISTERS if r != "phase"},
                "phase": LOAD if ld else LDNX if nx else FETCH}

    def set_registers(self, regs: dict) -> None:
        """Registers cannot be forced into oscillators: after load(), check that the restored state
        decodes to the checkpoint's registers."""
        if self.amps is None:
            raise Mech2SpiceError("a physical run resumes from its saved oscillator state (load() it first)")
        if self.registers() != regs:
            raise Mech2SpiceError(f"the saved oscillator state decodes to {self.registers()}, not the "
                                  f"checkpoint's registers {regs}")

    # --- checkpoints: the whole dynamical state, so a resumed run continues exactly ----------
    def save(self, path) -> None:
        path = Path(path)
        tmp = path.with_name(path.name + ".tmp.npz")
        arrays = {f"state{k}": np.asarray(a) for k, a in enumerate(self.state)}
        np.savez(tmp, **arrays, period=self.period, rdata=self.rdata, simulated=self.simulated,
                 probes=np.array(self.probes), amps=np.array([self.amps[k] for k in self.probes]),
                 backend=self.backend, step=self.step_periods)
        os.replace(tmp, path)            # a crash mid-write leaves the previous file intact

    def load(self, path) -> None:
        try:
            z = np.load(path)
        except (OSError, ValueError) as err:
            raise Mech2SpiceError(f"cannot read the oscillator state {path}: {err}") from None
        with z:
            if str(z["backend"]) != self.backend or list(z["probes"]) != self.probes:
                raise Mech2SpiceError(f"{path} holds the state of a different processor model or backend")
            n = sum(1 for k in z.files if k.startswith("state"))
            self.state = tuple(z[f"state{k}"] for k in range(n))
            self.period, self.rdata = int(z["period"]), int(z["rdata"])
            self.simulated = int(z["simulated"])
            self.amps = dict(zip(self.probes, map(float, z["amps"])))

    # --- one clock cycle --------------------------------------------------------------------
    def step(self) -> Cycle:
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
