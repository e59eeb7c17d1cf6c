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

import numpy as np

from .. import network, simulate
from ..errors import Mech2SpiceError
from ..params import DEFAULT, band_of
from .iss import FETCH, LDNX, LOAD, REGISTERS, Cycle
from .isa import mnemonic
from .memory import Memory

ENVELOPE_STEP = 2.0     # periods; pulse and pause are even, so stimulus changes fall on step boundaries


class PhysicalCPU:
    def __init__(self, memory: Memory, backend: str = "envelope", p=DEFAULT):
        from ..synth import synthesize
        from .run import CPU_VERILOG, register_map
        if backend not in ("envelope", "rk4"):
            raise Mech2SpiceError(f"no physical processor backend '{backend}'")
        self.netlist = synthesize(CPU_VERILOG, max_fanout=network.MAX_FANOUT)
        self.model = network.build(self.netlist, p)
        self.regmap = register_map(self.netlist)
        for q, block in self.model.meta["latch_outputs"].items():
            self.model.add_probe(f"latch.{q}", block.channel)
        self.probes = list(self.model.probes)
        t = simulate.clock_timing(self.netlist)
        self.pulse, self.pause = t["pulse"], t["pause"] + t["pause"] % 2
        self.backend, self.p, self.mem = backend, p, memory
        self.state, self.period, self.rdata = None, 0, 0
        self.cycle, self.halted = 0, False
        self.amps = self._reset()

    # --- integration -----------------------------------------------------------------------
    def _run(self, periods: int, values: dict, clock: int) -> dict[str, float]:
        from .. import envelope, rk4
        stim = network.stimulus(self.model, self.netlist, self.p, [(0, [values])], clock=[[clock]])
        if self.backend == "envelope":
            run = envelope.integrate(self.model, periods, step_periods=ENVELOPE_STEP, stimulus=stim,
                                     state=self.state, start_period=self.period, probes=self.probes)
            self.state = run.extra["envelope_state"]
        else:
            run = rk4.integrate(self.model, periods, stimulus=stim, state=self.state, start_period=self.period,
                                probes=self.probes)
            self.state = (run.x, run.v)
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
        raise Mech2SpiceError("a physical run cannot resume from a checkpoint's registers; "
                              "restart it (checkpoints of physical runs are for inspection)")

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
