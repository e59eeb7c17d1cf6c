"""The whole processor in a circuit simulator: the envelope-level VACASK netlist with the memory inside it.

`emit_cpu` writes one netlist: the 6486-oscillator processor as m2s_env_* devices (spice/vacask.py's
envelope emitter), the 256-byte memory as m2s_mem_* devices (spice/memory.py) holding the program, bus
decoders on the raddr / waddr / wdata / we amplitude nodes, the memory's read stage driving the rdata
pair drives, and the whole clock schedule (reset, then N cycles) as periodic pulse sources.  Nothing
outside the simulator takes part: `vacask cpu.sim` runs the program.

Schedule (drive periods): reset = `pause` with rst = 1, a clock pulse with rst = 1; then cycle k is a
settle of `settle` periods (default one pause) (the latch outputs, raddr, the memory's rdata and the datapath settle) and a
clock pulse, during which the memory writes (window `wclk`, the read stage holding).  Cycle k is sampled
just before its pulse: registers (latch outputs), raddr, rdata, we, waddr, wdata.

`CircuitCPU` (the machine `vacask-envelope`) runs that netlist once for the cycles asked and replays the
decoded cycles through the Machine interface (cpu/machines.py); the final memory is the circuit's own
(the byte cells print their bits over the run's last half period) and is checked against the writes decoded
cycle by cycle.  A checkpointed run is a chain of segments, each a simulator process continuing the last
one's unknowns (`CircuitCPU`'s docstring, docs/cpu_circuit.md).
"""
from __future__ import annotations

import json
import math
import re
import time
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import Mech2SpiceError
from ..experiments import clocking
from ..inputs import is_number
from ..physics import network
from ..physics.params import DEFAULT
from ..spice import memory as vmem
from ..spice import num
from . import state_file
from ..spice.vacask import ENVELOPE, OSDI, VacaskEnvelopeOptions, _Emitter, netlist_unknowns, run_netlist_raws
from .isa import MEM_SIZE, mnemonic
from .iss import FETCH, Cycle
from .memory import Memory
from .netlist import CPU_VERILOG, cpu_netlist, register_map, registers_from_amplitudes

NAME = "vacask-envelope"
BUSES = ("raddr", "waddr", "wdata", "we")
BUS_NODE = {"raddr": "mr", "waddr": "mw", "wdata": "md", "we": "mwe"}
SAMPLE_BEFORE = 2.0          # periods before a pulse's ramp at which a cycle is sampled
WINDOW = 0.1                 # the write window leaves this fraction of the pulse at each end
MAX_STEP = 32.0              # periods; with RELTOL: 31 sieve cycles = ISS, within 0.015 u_R of the envelope
RELTOL = 1e-2                # engine, the cheapest setting measured (reports/cpu_circuit.md)
_DUMP = re.compile(r"m2s_mem\s+(\S+)((?:\s+\S+){8})")


@dataclass(frozen=True)
class Schedule:
    """The netlist's clock schedule in drive periods (absolute: from the power-up).  A segment of a
    checkpointed run simulates cycles first .. first + cycles - 1 from the state at absolute period `offset`
    (the netlist's t = 0) and ends at its last sample (`to_sample`)."""
    pulse: int
    pause: int            # the reset's first pause
    settle: int           # each cycle's settle before its pulse
    cycles: int
    first: int = 0
    offset: float = 0.0
    to_sample: bool = False

    @property
    def length(self) -> int:
        """Periods per cycle (settle + pulse)."""
        return self.settle + self.pulse

    def start(self, k: int) -> int:
        """Period at which cycle k begins (after the reset pulse)."""
        return self.pause + self.pulse + k * self.length

    def pulse_at(self, k: int) -> int:
        """Period at which cycle k's clock pulse begins."""
        return self.start(k) + self.settle

    def sample_at(self, k: int) -> float:
        """Period at which cycle k is sampled (its state: settled, before its pulse)."""
        return self.pulse_at(k) - SAMPLE_BEFORE

    @property
    def stop(self) -> float:
        """The run ends one settle after the last pulse (so the state after it is sampled), or at that
        sample (`to_sample`: where the next segment starts)."""
        end = self.first + self.cycles
        return self.sample_at(end) if self.to_sample else self.pulse_at(end)

    @property
    def resets(self) -> bool:
        """Whether this netlist starts from rest with the reset (else: from a saved state, rst released)."""
        return self.offset == 0 and self.first == 0

    def samples(self) -> np.ndarray:
        """Sample periods: one before each cycle's pulse, and one after the last (cycles + 1)."""
        return np.array([self.sample_at(k) for k in range(self.first, self.first + self.cycles + 1)], float)

    def segment(self, first: int, cycles: int) -> "Schedule":
        """The schedule of `cycles` cycles from cycle `first`'s sample, ending at its last sample."""
        return replace(self, first=first, cycles=cycles, offset=self.sample_at(first) if first else 0.0,
                       to_sample=True)


def default_schedule(netlist, cycles: int, settle: int | None = None, p=DEFAULT) -> Schedule:
    """clocking.clock_timing's pulse and pause; each cycle settles one pause (derived for the longest NOR
    path, 44 gates: the path latch -> raddr -> memory -> rdata -> latch is 5 + 30, `memory_path`, and the
    memory adds ~5 periods, its read stage's time constants, to a pause of 11575)."""
    t = clocking.clock_timing(netlist, p=p)
    return Schedule(t["pulse"], t["pause"], settle or t["pause"], cycles)


def memory_path(netlist) -> dict:
    """NOR depths of the paths through the memory: latches -> raddr, rdata -> any gate; and the longest path."""
    import networkx as nx
    from ..synthesis.synth import combinational_view
    g, gates = combinational_view(netlist.graph), set(netlist.gates())

    def depths(sources: set) -> dict:
        d = dict.fromkeys(sources, 0)
        for node in nx.topological_sort(g):
            pre = [d[q] for q in g.predecessors(node) if q in d]
            if pre and node in gates:
                d[node] = 1 + max(pre)
        return d
    attrs = netlist.graph.nodes
    rdata = {x for x in attrs if attrs[x].get("kind") == "input" and attrs[x].get("port") == "rdata"}
    raddr = [x for x in attrs if attrs[x].get("kind") == "output" and attrs[x].get("port") == "raddr"]
    d = depths(set(netlist.latches()))
    to_raddr = max(max((d.get(q, 0) for q in g.predecessors(r)), default=0) for r in raddr)
    return {"latch_to_raddr": to_raddr, "rdata_to_any": max(depths(rdata).values()),
            "longest": network.logic_depth(netlist)}


# --- the netlist -------------------------------------------------------------------------------------------
@dataclass
class CpuNetlist:
    """An emitted processor netlist and what decoding its raw file needs."""
    text: str
    schedule: Schedule
    probes: list[str]                   # model probe names, in order
    vectors: list[str]                  # raw vectors: (ar, ai) per probe, then rdata's amplitude nodes
    rdata: list[str]
    period: float
    stats: dict = field(default_factory=dict)


class _CpuEmitter(_Emitter):
    """The envelope emitter with the input drives taken over: rdata from the memory, rst and clk scheduled."""

    def __init__(self, model, netlist, p, sched: Schedule, options):
        super().__init__(model, math.ceil(sched.stop - sched.offset), None, 0, options, ENVELOPE)
        self.p_gate, self.sched = p, sched
        self.taken: dict[int, str] = {}
        for b in range(netlist.inputs["rdata"]):
            for d in model.design.bit_drives[f"rdata[{b}]"]:
                self.taken[d] = f"amp_rdata{b}"
        for d in model.design.bit_drives["rst[0]"]:
            self.taken[d] = "amp_rst"
        for d in model.design.clock_drives:
            self.taken[d] = "amp_clk"

    def amp_node(self, d: int, share: int | None = None) -> str:
        """Memory and schedule nodes for the taken drives; the emitter's own sources for the rest."""
        return self.taken.get(d) or super().amp_node(d, share)

    def sources(self) -> list[str]:
        """rst (1 through the reset pulse), the clock and the write window as pulse sources; times are
        local (absolute period - the schedule's offset)."""
        p, s, T = self.p_gate, self.sched, self.T
        f0, f1 = p.force(p.levels.nominal0), p.force(p.levels.nominal1)
        ramp = self.opt.RAMP_PERIODS * T
        w0, w1 = s.pulse * WINDOW, s.pulse * (1 - WINDOW)
        first_pulse = s.pause if s.resets else s.pulse_at(s.first)    # the reset pulse, or cycle first's
        rst = (f"vrst (amp_rst 0) vsource type=\"pulse\" val0={num(f1)} val1={num(f0)} "
               f"delay={num(s.start(0) * T - ramp / 2)} rise={num(ramp)} fall={num(ramp)} width={num(10 * s.stop * T)}"
               if s.resets else f"vrst (amp_rst 0) vsource dc={num(f0)}")
        return [
            rst,
            f"vclk (amp_clk 0) vsource type=\"pulse\" val0={num(f0)} val1={num(f1)} "
            f"delay={num((first_pulse - s.offset) * T - ramp / 2)} "
            f"rise={num(ramp)} fall={num(ramp)} width={num(s.pulse * T - ramp)} period={num(s.length * T)}",
            f"vwclk (mwclk 0) vsource type=\"pulse\" val0=0 val1=1 "
            f"delay={num((s.pulse_at(s.first) + w0 - s.offset) * T)} "
            f"rise={num(ramp)} fall={num(ramp)} width={num((w1 - w0) * T - ramp)} period={num(s.length * T)}"]

    def memory(self, image: list[int], netlist) -> list[str]:
        """Bus decoders, 256 byte cells with the program, the read stage (spice/memory.py)."""
        out = []
        for port in BUSES:
            for b in range(netlist.outputs[port]):
                node = BUS_NODE[port] + ("" if port == "we" else str(b))
                ar, ai = self.nodes(self.m.probes[f"{port}[{b}]"])
                out.append(f"xmb_{node} ({ar} {ai} {node}) mem_bit")
        out += [vmem.byte_line(a, image[a]) for a in range(MEM_SIZE)]
        out += [f"xmr{b} (mo{b} mwclk amp_rdata{b}) mem_read" for b in range(vmem.BITS)]
        return out


STATE = "tstate"            # the analysis that writes a segment's final state (every unknown) to its raw file


def emit_cpu(image, cycles: int, p=DEFAULT, *, settle: int | None = None, max_step: float = MAX_STEP,
             reltol: float = RELTOL, standalone: bool = False, title: str = "", memory: bool = True,
             first: int | None = None, state: dict | None = None) -> CpuNetlist:
    """The processor with `image` in its memory, clocked `cycles` times, as one VACASK netlist.  Standalone:
    the Verilog-A is embedded (VACASK compiles it on load); else the compiled .osdi are expected beside it.
    memory=False (a cost profile only): no memory devices, rdata held at 0 by sources.
    first (a segment of a checkpointed run): cycles first .. first + cycles - 1, ending at the last one's
    sample, where a second analysis (STATE) writes every unknown; with `state` (node -> value, that
    analysis' output of the previous segment) the run starts from it instead of from the reset."""
    image = list(image) + [0] * (MEM_SIZE - len(image))
    if not 1 <= cycles:
        raise Mech2SpiceError("the processor netlist needs at least one cycle")
    if (state is not None) != bool(first):
        raise Mech2SpiceError("a segment after the first starts from a saved state, and only it does")
    net = cpu_netlist(str(CPU_VERILOG), max_fanout=network.MAX_FANOUT)
    model = network.build(net, p)
    for q, block in model.design.latch_outputs.items():
        model.add_probe(f"latch.{q}", block.channel)
    sched = default_schedule(net, cycles, settle, p)
    if first is not None:
        sched = sched.segment(first, cycles)
    e = _CpuEmitter(model, net, p, sched, VacaskEnvelopeOptions(max_step_periods=max_step, reltol=reltol))
    e.circuit()
    e.amp_lines += e.sources()
    rdata = [f"amp_rdata{b}" for b in range(vmem.BITS)]
    if memory:
        e.lines += ["// --- the memory (spice/memory.py)", *e.memory(image, net)]
    else:
        e.amp_lines += [f"vrd{b} ({node} 0) vsource dc={num(p.force(p.levels.nominal0))}" for b, node in enumerate(rdata)]
    osdi = OSDI[ENVELOPE].replace(".osdi", ".va") if standalone else OSDI[ENVELOPE]
    mem_ref = vmem.FILE if standalone else vmem.FILE.replace(".va", ".osdi")
    span = sched.stop - sched.offset
    tran = [f"analysis tran1 tran stop={num(span * e.T)} step={num(max_step * e.T)} "
            f"maxstep={num(max_step * e.T)} icmode=\"uic\"" + (' store="end"' if first is not None else "")]
    if first is not None:      # every unknown at the end: the next segment's initial condition
        # its first point is the stored end state; one period, because a much shorter run fails Newton
        # at its second point (18k unknowns, steps of 1e-3 T: measured)
        tran += ["save default", f'analysis {STATE} tran stop={num(e.T)} step={num(e.T)} maxstep={num(e.T)} '
                 'icmode="uic" ic="end"']
    tend = (span - 0.5) * e.T          # the cells print the memory over the last half period
    head = [f'load "{mem_ref}"', "model mem_bit m2s_mem_bit", f"model mem_byte m2s_mem_byte tend={num(tend)}",
            "model mem_read m2s_mem_read"]
    text = e.text(title or f"mech2spice processor, {cycles} cycles", osdi, tran)
    text = text.replace("\nground 0\n", "\nground 0\n" + "\n".join(head) + "\n", 1)
    text = text.replace("\n  analysis tran1", f"\n  save {' '.join(f'v({v})' for v in rdata)}\n  analysis tran1", 1)
    text = text.replace("\nendc\n", "\n  print stats\nendc\n", 1)     # the cost profile, read by run_cpu_netlist
    if standalone:
        from ..spice import veriloga as va
        text += f'\nembed "{va.FILES[ENVELOPE]}" <<<FILE\n{va.library(DEFAULT)[va.FILES[ENVELOPE]]}>>>FILE\n'
        text += f'\nembed "{vmem.FILE}" <<<FILE\n{vmem.library(p)}>>>FILE\n'
    if state is not None:            # the initial conditions go in last, once the circuit's nodes are known
        text = text.replace(' icmode="uic"', f' icmode="uic"{_ic(state, unknowns(text))}', 1)
    vectors = e.probe_vectors() + rdata
    return CpuNetlist(text, sched, list(model.probes), vectors, rdata, 2 * np.pi / model.omega,
                      {"dofs": model.n, "nor_blocks": len(e.plan.gates)})


def unknowns(text: str) -> set[str]:
    """The node unknowns of a processor netlist (what its STATE analysis writes), lower case."""
    from ..spice import veriloga as va
    return netlist_unknowns(text, (va.library(DEFAULT)[va.FILES[ENVELOPE]], vmem.library(DEFAULT)))


def check_state(state: dict, known: set[str], where: str = "the saved circuit state") -> None:
    """Every name a node of the netlist (a name is pasted into it: anything else could add a statement)
    and every value a finite number; one Mech2SpiceError line otherwise."""
    for n, v in state.items():
        if not (isinstance(n, str) and n in known):
            raise Mech2SpiceError(f"{where}: {ascii(n)[:80]} is not a node of the processor's netlist")
        if isinstance(v, bool) or not isinstance(v, (int, float, np.floating)) or not math.isfinite(v):
            raise Mech2SpiceError(f"{where}: node {n} has the value {ascii(v)[:40]}, not a finite number")


def _ic(state: dict, known: set[str]) -> str:
    """The tran analysis' initial conditions: exact values (repr); subnormals are out of range for
    VACASK's parser: they are 0 to the circuit."""
    check_state(state, known)
    return " ic={" + ", ".join(f'"{n}", {float(v) if abs(v) > 1e-300 else 0.0!r}' for n, v in state.items()) + "}"


# --- running and decoding ---------------------------------------------------------------------------------
def run_cpu_netlist(cpu: CpuNetlist, timeout: float | None = None, keep_dir=None) -> dict:
    """Run the netlist under VACASK and decode it (`decode`); adds the simulator's wall time and, for a
    segment, its final state (every differential unknown: node -> value)."""
    t0 = time.perf_counter()
    segment = cpu.schedule.to_sample
    try:
        raws, log = run_netlist_raws(cpu.text, ("tran1", STATE) if segment else ("tran1",), timeout=timeout,
                                     workdir=keep_dir, forms=(ENVELOPE,),
                                     extra_files={vmem.FILE.replace(".va", ".osdi"): vmem.compiled()})
    except Mech2SpiceError as err:
        data = getattr(err, "data", None)
        raise Mech2SpiceError(f"{err} (after {0 if data is None else len(data)} time points)") from None
    out = {**decode(cpu, *raws["tran1"], log), "wall_s": time.perf_counter() - t0}
    if segment:
        names, data = raws[STATE]
        if not len(data):
            raise Mech2SpiceError("VACASK wrote no final state for the segment (its state analysis failed)")
        out["state"] = {n: float(data[0, k].real) for k, n in enumerate(names)
                        if n != "time" and ":flow(" not in n}     # branch flows are algebraic: not state
    return out


def decode(cpu: CpuNetlist, names: list[str], data: np.ndarray, log: str) -> dict:
    """From a run's raw file and output: the probes' amplitudes (u_R) and rdata levels at every sample, the
    circuit's final memory, the time points (periods) and VACASK's cost counters."""
    t = data[:, 0].real / cpu.period + cpu.schedule.offset        # absolute periods
    at = cpu.schedule.samples()
    if t[-1] < at[-1] - 1e-6:
        raise Mech2SpiceError(f"the run stopped at period {t[-1]:.0f}, before the last sample ({at[-1]:.0f})")
    col = {n: data[:, names.index(n)].real for n in cpu.vectors}
    interp = lambda v: np.interp(at, t, col[v])
    amps = np.stack([np.hypot(interp(a), interp(b)) for a, b in zip(cpu.vectors[0::2], cpu.vectors[1::2])
                     if a not in cpu.rdata], axis=1)
    levels = np.stack([interp(v) for v in cpu.rdata], axis=1)
    return {"amps": amps, "rdata_levels": levels, "memory": final_memory(log), "points": int(t.size),
            "t_periods": t, "stats": simulator_stats(log)}


_STATS = {"unknowns": "Number of unknowns", "nonzeros": "Initial number of nonzeros",
          "accepted": "Accepted timepoints", "rejected": "Rejected timepoints",
          "newton_iterations": "NR solver iterations", "newton_s": "NR solver time",
          "eval_s": "Eval and load time", "refactor_s": "Real refactorization time", "solve_s": "Real solve time"}


def simulator_stats(log: str) -> dict:
    """VACASK's `print stats` counters (the cost profile): time points, Newton iterations, where time went."""
    out = {}
    for key, label in _STATS.items():
        m = re.search(rf"^\s*{label}:\s+(\S+)", log, re.M)
        if m:
            out[key] = float(m.group(1))
    return out


def final_memory(log: str) -> list[int] | None:
    """The byte cells' bits printed at the end of the run (the last print per address); None if missing."""
    cells: dict[int, int] = {}
    for m in _DUMP.finditer(log):
        bits = [float(x) for x in m.group(2).split()]
        cells[int(round(float(m.group(1))))] = sum(int(round(v)) << b for b, v in enumerate(bits))
    return [cells.get(a, -1) for a in range(MEM_SIZE)] if len(cells) == MEM_SIZE else None


class CircuitCPU:
    """The processor in VACASK (envelope level, memory inside the circuit), replayed cycle by cycle.

    Without `segment` the whole run is one simulator process (the netlist `cpu emit` writes).  With
    `segment` (a checkpointed run) it is a chain of processes of `segment` cycles each: a segment ends at its
    last cycle's sample, writes every unknown of the circuit there (oscillator amplitudes, insulators,
    the memory cells' stored bits, the read stage), and the next starts from them (tran icmode="uic" with
    those initial conditions), so `save` / `load` continue a run across processes."""

    def __init__(self, memory: Memory, p=DEFAULT, *, cycles: int = 30, settle: int | None = None,
                 max_step: float = MAX_STEP, reltol: float = RELTOL, timeout: float | None = None,
                 power_up: bool = True, keep_dir=None, segment: int | None = None):
        if memory.devices:
            raise Mech2SpiceError(f"the {NAME} backend has no memory-mapped devices (tapes): the memory "
                                  "inside the circuit is the 256-byte array only")
        if not power_up and not segment:
            raise Mech2SpiceError(f"the {NAME} backend resumes only a checkpointed run (one written with "
                                  "--checkpoint): run it again without --resume")
        self._blank(memory, {"settle": settle, "max_step": max_step, "reltol": reltol}, timeout, keep_dir, segment)
        net = emit_cpu(self.image, min(segment, cycles) if segment else cycles, p, **self.settings,
                       first=0 if segment else None)
        self.result = {"memory": None}
        if power_up:                             # else: load() a checkpoint
            self.result = self._absorb(net, run_cpu_netlist(net, timeout, keep_dir))
        self._setup(memory, p, net, cycles)

    def _blank(self, memory: Memory, settings: dict, timeout, keep_dir, segment) -> None:
        """Nothing simulated yet."""
        self.image = memory.snapshot()           # the program: the cells' parameters in every segment
        self.settings, self.timeout, self.keep_dir, self.segment = settings, timeout, keep_dir, segment
        self.samples: dict[int, tuple[dict, np.ndarray]] = {}   # cycle -> (probe amplitudes, rdata levels)
        self.state, self.state_cycle = None, 0   # every unknown at cycle state_cycle's sample (segments)
        self.cost = {"time_points": 0, "simulator_wall_s": 0.0, "segments": 0}
        self.simulated = 0.0                     # periods the simulator ran in this process

    @classmethod
    def replay(cls, memory: Memory, p, net: CpuNetlist, result: dict, cycles: int) -> "CircuitCPU":
        """A run decoded elsewhere (`decode` of `vacask` run on the netlist `cpu emit` wrote), cycle by cycle."""
        cpu = cls.__new__(cls)
        cpu._blank(memory, {}, None, None, None)
        cpu.result = cpu._absorb(net, {"wall_s": 0.0, **result})
        cpu._setup(memory, p, net, cycles)
        return cpu

    def _absorb(self, net: CpuNetlist, result: dict) -> dict:
        """Keep a run's decoded samples (by absolute cycle), its final state and its cost."""
        for j, k in enumerate(range(net.schedule.first, net.schedule.first + net.schedule.cycles + 1)):
            self.samples[k] = (dict(zip(net.probes, result["amps"][j])), result["rdata_levels"][j])
        if "state" in result:
            self.state, self.state_cycle = result["state"], net.schedule.first + net.schedule.cycles
        self.simulated += net.schedule.stop - net.schedule.offset
        self.cost["time_points"] += result["points"]
        self.cost["simulator_wall_s"] += result["wall_s"]
        self.cost["segments"] += 1
        return result

    def _setup(self, memory: Memory, p, net: CpuNetlist, cycles: int) -> None:
        """Replay state over a decoded run (`self.result`): also for a netlist run standalone."""
        self.mem, self.p, self.net = memory, p, net
        self.netlist = cpu_netlist(str(CPU_VERILOG), max_fanout=network.MAX_FANOUT)
        self.regmap = register_map(self.netlist)
        self.cycle, self.halted = 0, False
        self.period = net.schedule.stop
        self.cycles_run = cycles

    @property
    def amps(self) -> dict:
        """Probe amplitudes (u_R) now: at the sample of the next cycle (the state after the last one)."""
        return self._sample(self.cycle)[0]

    def _sample(self, k: int) -> tuple[dict, np.ndarray]:
        """Cycle k's sample, simulating the next segment from the saved state if it is not there yet."""
        while k not in self.samples and self.segment and self.state is not None and self.state_cycle < k:
            first = self.state_cycle
            n = min(self.segment, self.cycles_run - first)
            if n < 1:
                break
            net = emit_cpu(self.image, n, self.p, **self.settings, first=first, state=self.state)
            self.result = self._absorb(net, run_cpu_netlist(net, self.timeout, self.keep_dir))
            self.period = net.schedule.stop
        if k not in self.samples:
            raise Mech2SpiceError(f"the circuit was simulated for {self.cycles_run} cycles only")
        return self.samples[k]

    # --- checkpoints: the circuit's unknowns at the last segment's end, and the samples not yet replayed
    def save(self, path) -> str:
        """Write the circuit state to `path` (durably); returns its sha256."""
        if self.state is None:
            raise Mech2SpiceError(f"the {NAME} backend checkpoints only a segmented run")
        pending = sorted(k for k in self.samples if k >= self.cycle)
        return state_file.write(
            path, names=np.array(list(self.state)), values=np.array(list(self.state.values())),
            state_cycle=self.state_cycle, period=self.period, pending=np.array(pending, np.int64),
            probes=np.array(self.net.probes),
            amps=np.array([[self.samples[k][0][n] for n in self.net.probes] for k in pending]),
            levels=np.array([self.samples[k][1] for k in pending]), backend=NAME,
            settings=json.dumps(self.settings), memory=np.array(self.result["memory"] or [], np.int64),
            simulated=self.simulated, cost=json.dumps(self.cost))

    def load(self, path, sha256: str | None = None) -> None:
        """Restore the state save() wrote; with `sha256`, the file must be exactly the one saved."""
        state_file.read(path, sha256, "circuit state", lambda z: self._load_arrays(z, path))

    def _load_arrays(self, z: state_file.Fields, path) -> None:
        """Every field checked against this netlist before any of it is used (the names go into the next
        segment's netlist: each must be one of its nodes, and all of them there)."""
        if z.text("backend") != NAME or z.texts("probes") != self.net.probes:
            raise Mech2SpiceError(f"{path} holds the state of a different processor model or backend")
        settings = z.json("settings")
        if settings != self.settings:
            raise Mech2SpiceError(f"{path} was written with other circuit settings {ascii(settings)[:200]}: "
                                  "resume with those")
        names = z.texts("names")
        values = z.array("values", float, (len(names),))
        state = dict(zip(names, map(float, values)))
        known = unknowns(self.net.text)
        check_state(state, known, f"{path}")
        if len(state) != len(names) or set(state) != known:
            raise Mech2SpiceError(f"{path}: the saved circuit state does not hold each of the netlist's "
                                  f"{len(known)} nodes once (it has {len(names)} names)")
        pending = z.array("pending", np.int64, (None,))
        if not (pending.size and np.all(np.diff(pending) > 0) and pending[0] >= 0):
            raise Mech2SpiceError(f"{path}: 'pending' must list increasing cycles")
        amps = z.array("amps", float, (pending.size, len(self.net.probes)))
        levels = z.array("levels", float, (pending.size, vmem.BITS))
        memory = z.array("memory", np.int64, (None,))
        if memory.size not in (0, MEM_SIZE) or not np.all((memory >= 0) & (memory <= 255)):
            raise Mech2SpiceError(f"{path}: 'memory' must be empty or {MEM_SIZE} bytes")
        cost = z.json("cost")
        if set(cost) != set(self.cost) or not all(is_number(v) and v >= 0 for v in cost.values()):
            raise Mech2SpiceError(f"{path}: 'cost' must hold {', '.join(self.cost)} as numbers >= 0")
        self.state = state
        self.state_cycle, self.period = z.integer("state_cycle", 1), z.number("period")
        self.samples = {int(k): (dict(zip(self.net.probes, map(float, a))), lv)
                        for k, a, lv in zip(pending, amps, levels)}
        self.cycle = int(pending[0])
        self.simulated, self.cost = z.number("simulated"), cost
        self.result = {**self.result, "memory": [int(v) for v in memory] or None}

    def _port(self, k: int, port: str, what: str) -> int:
        amps = self._sample(k)[0]
        bits = [self.p.levels.band_of(amps[f"{port}[{i}]"]) for i in range(self.netlist.outputs[port])]
        return Memory.decode_address(bits, k, what)

    def _rdata(self, k: int) -> int:
        f0, f1 = self.p.force(self.p.levels.nominal0), self.p.force(self.p.levels.nominal1)
        x = (self._sample(k)[1] - f0) / (f1 - f0)
        if np.any(np.abs(x - np.round(x)) > 0.1):
            raise Mech2SpiceError(f"cycle {k}: the memory's rdata levels {np.round(x, 3).tolist()} are not bits")
        return int(sum(int(round(v)) << b for b, v in enumerate(x)))

    def registers(self, k: int | None = None) -> dict:
        """The registers decoded from the latch outputs at sample k (default: now)."""
        k = self.cycle if k is None else k
        return registers_from_amplitudes(self.regmap, self.p.levels, self._sample(k)[0], k)

    def set_registers(self, regs: dict) -> None:
        """Registers cannot be forced into the circuit: after load(), check that the restored samples
        decode to the checkpoint's registers."""
        if self.state is None:
            raise Mech2SpiceError(f"the {NAME} backend resumes from its saved circuit state (load() it first)")
        if self.registers() != regs:
            raise Mech2SpiceError(f"the saved circuit state decodes to {self.registers()}, not the checkpoint's "
                                  f"registers {regs}")

    def step(self) -> Cycle:
        """The next simulated cycle, decoded; its write is committed to `mem` (checked at the end against the
        circuit's own memory)."""
        k = self.cycle
        if k >= self.cycles_run:
            raise Mech2SpiceError(f"the circuit was simulated for {self.cycles_run} cycles only")
        regs = self.registers(k)
        raddr, rdata = self._port(k, "raddr", "read address"), self._rdata(k)
        we, waddr, wdata = (self._port(k, "we", "write enable"), self._port(k, "waddr", "write address"),
                            self._port(k, "wdata", "write data"))
        self.mem.commit(waddr, wdata, we)
        self.cycle += 1
        mem, printed_at = self.result["memory"], self.state_cycle if self.segment else self.cycles_run
        self.halted = self.registers(k + 1) == regs           # may simulate the next segment
        if (self.halted or self.cycle == printed_at) and mem is not None and mem != self.mem.snapshot():
            raise Mech2SpiceError("the circuit's final memory differs from the writes decoded cycle by cycle")
        return Cycle(k, regs["pc"], regs["phase"], mnemonic(rdata) if regs["phase"] == FETCH else None,
                     raddr, rdata, we, waddr, wdata)

    def extra(self) -> dict:
        """What the run cost and how it ended, for the result JSON (time points and simulator time of this
        process's simulator runs; `segments`: how many)."""
        return {"simulator": "vacask", "periods": self.period, **self.cost,
                "cycles_simulated": self.cycles_run, "circuit_memory": self.result["memory"],
                "schedule": vars(self.net.schedule)}
