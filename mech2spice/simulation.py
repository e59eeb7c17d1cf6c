"""Run a synthesised design on an engine and decode its outputs from amplitudes.

Engines that continue from a state run in chunks until every output has settled (amplitude change
over the last window below a tolerance and inside a band) or the period budget is spent; the others
run the whole budget.  A bit outside both bands is reported as invalid, never rounded.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from . import verdict
from .backends import logic, make_engine
from .backends import progress_bar
from .errors import Mech2SpiceError
from .experiments.clocking import period_budget
# re-exported for cli.py and reports/, which are being moved (#28); new code imports experiments.clocking
from .experiments.clocking import (GATE_DELAY_MAX, LATCH_MIN_PULSE, LATCH_OUTPUT_DELAY,  # noqa: F401
                                   LATCH_OUTPUT_DELAY_MIN, SETTLE_MARGIN, block_slowdown, clock_timing)
from .physics import network
from .physics.envelope import Envelope
from .physics.model import MechModel
from .physics.params import DEFAULT_LEVELS, GateParams, Levels
from .physics.stimulus import Stimulus
from .synthesis.ports import output_bits, pack_inputs, port_values
from .synthesis.synth import Netlist

SETTLED_CHANGE = 2e-3    # u_R: an output that moved less than this over SETTLE_WINDOW periods has settled
SETTLE_WINDOW = 100      # periods
CHUNK = 100              # periods per engine call in the settle loop
EXTENSION = 4            # a run the verdict finds unsettled at its period budget goes on, up to this many budgets
NO_FIXED_POINT_WAIT = 0.25   # of the budget: how long to go on before judging again a state with no fixed point near
MAX_TRACE_BYTES = 2e9    # amplitudes a clocked run keeps in memory (one complex per period, probe, batch member)
ESTIMATE_LOG_S = 10.0    # runs estimated to take longer than this say so before they start


def decode(netlist: Netlist, amplitudes: dict[str, float], const: dict[str, int],
           levels: Levels = DEFAULT_LEVELS) -> dict:
    """bits / outputs / valid / min_margin from output amplitudes (u_R), in the block's `levels`."""
    bits, margins = {}, []
    for bit in output_bits(netlist):
        if bit in const:
            bits[bit] = const[bit]
            continue
        b = levels.band_of(amplitudes[bit])
        bits[bit] = b
        margins.append(levels.margin(amplitudes[bit], b))
    return {"outputs": port_values(netlist, bits), "bits": bits, "valid": all(v is not None for v in bits.values()),
            "min_margin": float(min(margins)) if margins else None}


def run_logic(netlist: Netlist, values: dict[str, int]) -> dict:
    """The logic backend's result for one input assignment (the oracle)."""
    t0 = time.time()
    bits = logic.evaluate_bits(netlist, values)
    out = {b: bits[b] for b in output_bits(netlist)}
    return {"backend": "logic", "outputs": port_values(netlist, bits), "bits": out, "amplitudes": {},
            "valid": True, "min_margin": None, "periods": 0, "wall_s": time.time() - t0}


def _engine_fields(engine) -> dict:
    """Result fields naming a circuit simulator's settings: `ngspice_options` / `vacask_options`."""
    simulator = engine.capabilities.simulator
    return {f"{simulator}_options": engine.describe()} if simulator else {}


def _observed(netlist: Netlist, model: MechModel) -> list[str]:
    return [b for b in output_bits(netlist) if b in model.probes]


def estimate_seconds(engine, model: MechModel, periods: int, batch: int = 1) -> float | None:
    """The engine's own estimate of a run's wall time (None where it has none)."""
    est = getattr(engine, "estimate_seconds", None)
    return est(model, periods, batch) if est else None


def _announce(engine, model, periods: int, batch: int, log) -> None:
    """Say how long a long run will take before it starts (the resource guard's time half)."""
    secs = estimate_seconds(engine, model, periods, batch)
    if log is not None and secs is not None and secs > ESTIMATE_LOG_S:
        log(f"{engine.name}: {model.n} oscillators x {batch} x {periods} periods, estimated {secs / 60:.1f} min")


def _engine(backend: str, options, noise: tuple[float, int] | None):
    """The engine, with thermal noise (T, seed) when T > 0 (backends.noisy_engine)."""
    if noise and noise[0]:
        from .backends import noisy_engine
        return noisy_engine(backend, options, *noise)
    return make_engine(backend, options)


def run_physical(netlist: Netlist, p: GateParams, values: list[dict[str, int]], backend: str = "rk4",
                 periods: int | None = None, progress: bool = False, options=None, log=None,
                 noise: tuple[float, int] | None = None) -> list[dict]:
    """Simulate one batch of input assignments from rest; one result dict per member (`noise`: (k_B T, seed)).
    Each member's bits are judged by verdict.apply: valid only at a stable fixed point, settled onto it."""
    t0 = time.time()
    for v in values:
        pack_inputs(netlist, v)                  # validates ports and widths up front
    engine = _engine(backend, options, noise)
    if not engine.capabilities.physical:
        return [run_logic(netlist, v) for v in values]
    model = network.build(netlist, p)
    stim = network.stimulus(model, netlist, p, [(0, values)])
    budget = periods or period_budget(netlist)
    outs = _observed(netlist, model)
    _announce(engine, model, budget, len(values), log)
    judged, source, clock = None, "run", VerdictClock()
    if not outs:
        amps, used = np.zeros((0, len(values))), 0
    elif engine.capabilities.state:
        amps, used, judged = _run_until_settled(engine, model, stim, outs, budget, progress,
                                                fixed=periods is not None, clock=clock)
    else:
        run = engine.run(model, budget, stim, probes=outs, progress=progress)
        amps, used = run.final_amplitudes(outs, model.amplitude_unit), budget
        judged, source = _reference_judged(model, stim, outs, budget, clock), "envelope"
    wall = time.time() - t0
    results = []
    for b in range(len(values)):
        a = {n: float(amps[k, b]) for k, n in enumerate(outs)}
        v, ok = judged[b] if judged else (None, False)
        res = verdict.apply(decode(netlist, a, model.design.const_outputs, model.levels), a, v, ok, source, model.levels)
        results.append({"backend": backend, **res, "amplitudes": a, "periods": used, "wall_s": wall,
                        "verdict_s": clock.seconds, **_engine_fields(engine)})
    return results


def _reference_judged(model: MechModel, stim, outs: list[str], budget: int, clock: "VerdictClock") -> list:
    """For engines that return no state (the circuit simulators): the verdict at the envelope's settled state
    under the same stimulus; the mechanical model, and so its fixed points and modes, are the same."""
    return _run_until_settled(make_engine("envelope"), model, stim, outs, budget, False, fixed=False, clock=clock)[2]


def _run_until_settled(engine, model, stim, probes: list[str], budget: int, progress: bool, fixed: bool,
                       watch: list[int] | None = None, clock: "VerdictClock | None" = None):
    """CHUNK periods at a time, each continuing from the last state, until the watched probes (rows `watch`
    of `probes`, default all) settle: the cheap rule (_settled: nothing moved much over a window) first, then
    the verdict's (verdict.settled: stable, and less than verdict.SETTLED_BW band widths still to come).
    While an output is still moving, the next verdict waits for the slowest mode to close the gap.

    One stop rule: the run stops where the verdict says settled (or unstable at a fixed point: no wait helps).
    A run the verdict finds unsettled when the budget is spent (no fixed point near its state, or one still
    to be reached) goes on, up to EXTENSION x the budget in all (`fixed`, a set period count: not extended).
    Returns (every probe's final amplitudes, periods, [(verdict, settled)] per batch member)."""
    rows = list(range(len(probes))) if watch is None else list(watch)
    names = [probes[k] for k in rows]
    cap = budget if fixed else EXTENSION * budget
    state, done, history, judged, next_check, target, last = None, 0, [], None, 0, budget, None
    bar = progress_bar(budget, progress)
    while done < target:
        n = min(CHUNK, target - done)
        run = engine.run(model, n, stim, state=state, start_period=done, probes=probes)
        state = run.state
        done += n
        history.append(_chunk_summary(run, probes, model.amplitude_unit))
        bar.update(n)
        judged = None
        due = done >= target or _settled(_rows(history[-2:], rows), model.levels)
        if not fixed and done >= next_check and due:
            judged = last = _judge(engine, model, run, stim, names, done, _rows(history[-3:], rows), clock=clock,
                                   previous=last)
            wait = _periods_to_settle(judged, _rows(history[-3:], rows), names, budget, model.levels)
            if wait == 0:
                break
            next_check = done + wait
            if done >= target:           # unsettled at the budget: go on until the verdict's wait, within the cap
                target = min(cap, max(next_check, done + CHUNK))
    bar.close()
    if judged is None:
        judged = _judge(engine, model, run, stim, names, done, _rows(history[-3:], rows), clock=clock, previous=last)
    return history[-1][0], done, judged


def _rows(summaries: list, rows: list[int]) -> list:
    """Chunk summaries (last, mean, swing) cut down to the watched probes' rows."""
    return [tuple(x[rows] for x in h) for h in summaries]


def _chunk_summary(run, probes: list[str], unit: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(last, mean, swing) of each probe's |A| / unit over one chunk, each (probes, B)."""
    a = np.abs(run.amp[:, [run.probe(n) for n in probes], :]) / unit
    return a[-1], a.mean(axis=0), a.max(axis=0) - a.min(axis=0)


class VerdictClock:
    """The wall time a run spends in stability verdicts (`verdict_s`)."""
    def __init__(self):
        self.seconds = 0.0

    def add(self, seconds: float) -> None:
        self.seconds += seconds


def _judge(engine, model: MechModel, run, stim, outs: list[str], t_periods: int, history: list,
           held: bool = False, clock: VerdictClock | None = None, previous: list | None = None) -> list | None:
    """(verdict, settled) of each batch member at the run's final state (None: the engine returns no state).
    `previous`: the same run's last judgement, whose eigenvectors start each member's sparse search (a nearby
    state: ARPACK converges in far fewer products)."""
    ph = engine.phasors(model, run.state, run.t)
    if ph is None:
        return None
    t0 = time.perf_counter()
    A, s = ph
    F = Envelope.of(model).forcing(stim.at((t_periods - 1e-6) * model.period))
    out = []
    for b in range(A.shape[1]):
        start = previous[b][0].start if previous and previous[b] else None
        v = verdict.judge(model, A[:, b], s[:, b], F[:, b], outs, start=start)
        a, swing, step = _recent(history, outs, b)
        out.append((v, verdict.settled(v, a, swing, step, CHUNK, engine.rests_on_fixed_point(), held, model.levels)))
    if clock is not None:
        clock.add(time.perf_counter() - t0)
    return out


def _recent(history: list, outs: list[str], b: int) -> tuple[dict, dict, dict]:
    """Member b's latest amplitudes, their swing over the last chunk, and the change of the chunk mean."""
    last, mean, swing = (h[:, b] for h in history[-1])
    step = np.abs(mean - history[-2][1][:, b]) if len(history) > 1 else np.full(len(outs), np.inf)
    as_dict = lambda x: {n: float(x[k]) for k, n in enumerate(outs)}
    return as_dict(last), as_dict(swing), as_dict(step)


def _settled(history: list[np.ndarray], levels: Levels = DEFAULT_LEVELS) -> bool:
    """The cheap first test: every output moved less than SETTLED_CHANGE over SETTLE_WINDOW and is in a band."""
    k = SETTLE_WINDOW // CHUNK
    if len(history) <= k:
        return False
    now, before = history[-1][0], history[-1 - k][0]
    inside = np.vectorize(lambda a: levels.band_of(a) is not None)(now)
    return bool(np.all(np.abs(now - before) < SETTLED_CHANGE) and np.all(inside))


def _periods_to_settle(judged, history: list, probes: list[str], budget: int, levels: Levels = DEFAULT_LEVELS) -> int:
    """0 when every member is settled or unstable at a fixed point (no wait helps); else the periods for the
    slowest decaying mode to bring what is still to come down to verdict.SETTLED_BW (at least one chunk), or,
    where no fixed point lies near a member's state (still on its way), NO_FIXED_POINT_WAIT of the budget."""
    wait = 0
    for b, (v, ok) in enumerate(judged or []):
        if ok or (v.converged and not v.stable):
            continue
        if not v.converged:
            wait = max(wait, CHUNK, int(budget * NO_FIXED_POINT_WAIT) // CHUNK * CHUNK)
            continue
        a, swing, step = _recent(history, probes, b)
        left = max(verdict.still_to_come(v, a, swing, step, CHUNK, levels), verdict.drift(v, a, levels))
        wait = max(wait, CHUNK, int(min(v.slowest_decay * np.log(max(left / verdict.SETTLED_BW, 1.0)), 1e7)))
    return wait


# --- clocked designs (their pulse and pause: experiments/clocking.clock_timing) -------------------


def expand_steps(steps: list[dict]) -> list[dict[str, int]]:
    """[{"set": {...}, "cycles": N}, ...] -> the input values of every cycle (settings persist)."""
    values, out = {}, []
    for k, step in enumerate(steps):
        if not isinstance(step, dict) or not isinstance(step.get("cycles", 1), int) or step.get("cycles", 1) < 0:
            raise Mech2SpiceError(f"stimulus step {k}: expected {{\"set\": {{PORT: INT}}, \"cycles\": N}}")
        values = {**values, **step.get("set", {})}
        out += [dict(values)] * step.get("cycles", 1)
    if not out:
        raise Mech2SpiceError("the stimulus has no clock cycles")
    return out


def run_clocked_logic(netlist: Netlist, cycles: list[dict[str, int]]) -> dict:
    """Trace entry k: outputs after clock edge k, read with the next cycle's inputs applied."""
    t0 = time.time()
    sim = logic.ClockedLogic(netlist)
    trace = []
    for k, v in enumerate(cycles):
        sim.tick(v)
        bits = sim.evaluate_bits(cycles[min(k + 1, len(cycles) - 1)])
        out = {b: bits[b] for b in output_bits(netlist)}
        trace.append({"cycle": k, "outputs": port_values(netlist, bits), "bits": out, "valid": True,
                      "min_margin": None})
    return {"backend": "logic", **_final(trace), "trace": trace, "periods": 0, "wall_s": time.time() - t0}


def _final(trace: list[dict]) -> dict:
    last = trace[-1]
    out = {"outputs": last["outputs"], "bits": last["bits"], "valid": all(t["valid"] for t in trace),
           "min_margin": min((t["min_margin"] for t in trace if t["min_margin"] is not None), default=None)}
    if all("stable" in t for t in trace):
        out.update(stable=all(t["stable"] for t in trace), settled=all(t["settled"] for t in trace))
    return out


def _run_cycles(engine, model: MechModel, stim, reads: list[int], outs: list[str], progress: bool,
                pause: int = 0, clock: VerdictClock | None = None):
    """A clocked run read by read (each part continuing from the last one's state, so the whole equals one
    run), judged at each read: (the whole run, [(verdict, settled) per cycle, or None], the period of the
    whole run at which each read was taken).  A read the verdict finds unsettled even integrated without
    skipping is held (its inputs kept) up to (EXTENSION - 1) x `pause` more periods: the one stop rule of
    _run_until_settled; the schedule after it is unchanged, only later."""
    state, t, parts, judged, read_at, length = None, 0, [], [], [], 0
    full = _without_skipping(engine)
    bar = progress_bar(reads[-1], progress)
    for r in reads:
        prev = next((q for q in reversed(judged) if q), None)
        part = engine.run(model, r - t, stim, state=state, start_period=t, probes=outs)
        j = _judge_read(engine, model, part, stim, outs, r, clock, prev)
        if j and j[0].stable and not j[1] and part.settled_periods and full is not None:
            # idle skipping held a state that had not settled: this cycle again, integrated throughout
            part = full.run(model, r - t, stim, state=state, start_period=t, probes=outs)
            j = _judge_read(full, model, part, stim, outs, r, clock, j)
            part.extra["reintegrated"] = True
        bar.update(part.amp.shape[0])
        parts.append(part)
        holds, j = _hold_until_settled(full or engine, model, part, stim.at((r - 1e-6) * model.period), outs, j,
                                       (EXTENSION - 1) * pause, clock)
        parts += holds
        state, t = parts[-1].state, r
        length += sum(q.amp.shape[0] for q in [part, *holds])
        read_at.append(length)
        judged.append(j)
    bar.close()
    whole = replace(parts[-1], amp=np.concatenate([q.amp for q in parts]), mean=np.concatenate([q.mean for q in parts]),
                    t_end=np.concatenate([q.t_end for q in parts]),
                    settled_periods=sum(q.settled_periods for q in parts),
                    extra={**parts[-1].extra, "reintegrated": sum(bool(q.extra.get("reintegrated")) for q in parts),
                           "held": sum(bool(q.extra.get("held")) for q in parts)})
    return whole, judged, read_at


def _unsettled(j) -> bool:
    """A read that more integration may settle: judged, not settled, and not unstable at a fixed point."""
    return bool(j) and not j[1] and not (j[0].converged and not j[0].stable)


def _hold_until_settled(engine, model: MechModel, part, amps: np.ndarray, outs: list[str], j, cap: int,
                        clock: VerdictClock | None):
    """Keep integrating a read's state under its inputs (`amps`, constant) while the verdict finds it
    unsettled, up to `cap` periods: (the extra parts, the last judgement)."""
    hold = Stimulus(np.zeros(1), amps[None])
    holds, extra = [], 0
    step = max(2 * CHUNK, int(cap * NO_FIXED_POINT_WAIT / (EXTENSION - 1)) // CHUNK * CHUNK)
    while _unsettled(j) and extra < cap:
        n = min(step, cap - extra)
        if n < 2 * CHUNK:
            break
        part = engine.run(model, n, hold, state=part.state, start_period=0, probes=outs)
        part.extra["held"] = True
        j = _judge_read(engine, model, part, hold, outs, n, clock, j)
        holds.append(part)
        extra += n
    return holds, j


def _without_skipping(engine):
    """The same engine with idle skipping off (None if it skips none)."""
    if not engine.capabilities.settle or getattr(engine.options, "settle_tol", None) is None:
        return None
    return make_engine(engine.name, replace(engine.options, settle_tol=None))


def _judge_read(engine, model: MechModel, part, stim, outs: list[str], t_periods: int,
                clock: VerdictClock | None = None, previous=None):
    """(verdict, settled) of a single-member run at a clock read: its summary over the last 2 CHUNKs
    (`previous`: the last read's, whose eigenvectors start the search)."""
    if part.amp.shape[0] < 2 * CHUNK:
        return None
    a = np.abs(part.amp[-2 * CHUNK:, [part.probe(n) for n in outs], :]) / model.amplitude_unit
    history = [(a[CHUNK - 1], a[:CHUNK].mean(axis=0), np.ptp(a[:CHUNK], axis=0)),
               (a[-1], a[CHUNK:].mean(axis=0), np.ptp(a[CHUNK:], axis=0))]
    judged = _judge(engine, model, part, stim, outs, t_periods, history, held=part.settled_periods > 0,
                    clock=clock, previous=[previous] if previous else None)
    return judged[0] if judged else None


def clocked_schedule(cycles: list[dict[str, int]], timing: dict):
    """Segments (start period, values, clock level) and the period at which each trace entry is read:
    settle S_0, then per cycle k a pulse P_k and the settle S_{k+1} (with cycle k+1's inputs) after it."""
    pulse, pause = timing["pulse"], timing["pause"]
    segs, reads, t = [(0, cycles[0], 0)], [], pause
    for k, v in enumerate(cycles):
        segs.append((t, v, 1))
        t += pulse
        segs.append((t, cycles[min(k + 1, len(cycles) - 1)], 0))
        t += pause
        reads.append(t)
    return segs, reads, t


CLOCKED_SETTLE_TOL = 0.1   # u_R; envelope pauses end once the channels settle: within 0.012 u_R (reports/fidelity.md)


@dataclass
class Waveform:
    """A clocked run's output amplitudes per period (u_R) and the periods at which each cycle was read."""
    amplitude: np.ndarray      # (periods, probes)
    reads: list[int]
    probes: list[str]


def _whole_steps(timing: dict, step: float) -> dict:
    """Pause and pulse rounded up to whole engine steps, so every stimulus change falls on a step boundary."""
    whole = max(1, int(round(step)))
    return {**timing, "pause": -(-timing["pause"] // whole) * whole, "pulse": -(-timing["pulse"] // whole) * whole}


def _check_trace_memory(total: int, probes: int, batch: int = 1) -> None:
    need = 16.0 * total * max(probes, 1) * batch
    if need > MAX_TRACE_BYTES:
        raise Mech2SpiceError(f"this clocked run would keep {need / 1e9:.1f} GB of amplitudes ({total:,} periods "
                              f"x {probes} outputs): run fewer cycles (limit {MAX_TRACE_BYTES / 1e9:g} GB)")


def run_clocked_physical(netlist: Netlist, p: GateParams, cycles: list[dict[str, int]], backend: str,
                         timing: dict, progress: bool = False, options=None,
                         settle_tol: float | None = CLOCKED_SETTLE_TOL, waveform: bool = False, log=None,
                         noise: tuple[float, int] | None = None, sample=None) -> dict:
    """Trace entry k: outputs after clock edge k.  On engines that skip idle time, `settle_tol` (u_R) ends
    a stretch of constant inputs once every channel is steady (unless the options set their own);
    `waveform=True` adds the per-period amplitudes (a Waveform) under "waveform".  `sample`: (model, drive
    factors or None), a Monte-Carlo sample of the design's model to run instead of the nominal one."""
    t0 = time.time()
    for v in cycles:
        pack_inputs(netlist, v)
    engine = _engine(backend, options, noise)
    if not engine.capabilities.physical:
        return run_clocked_logic(netlist, cycles)
    if engine.capabilities.settle and engine.options.settle_tol is None and settle_tol:
        engine = make_engine(backend, replace(engine.options, settle_tol=settle_tol))
    model = nominal = network.build(netlist, p)
    if sample is not None:
        model = sample[0]
    step = engine.step(model)
    if step is not None:
        timing = _whole_steps(timing, step)
    segs, reads, total = clocked_schedule(cycles, timing)
    outs = _observed(netlist, model)
    _check_trace_memory(total, len(outs))
    _announce(engine, model, total, 1, log)
    stim = network.stimulus(nominal, netlist, p, [(t, [v]) for t, v, _ in segs], clock=[[c] for *_, c in segs])
    if sample is not None and sample[1] is not None:
        stim = Stimulus(stim.times, stim.amps * sample[1][None, :, None])
    source, clock, read_at = "run", VerdictClock(), reads
    if engine.capabilities.state:
        run, judged, read_at = _run_cycles(engine, model, stim, reads, outs, progress, timing["pause"], clock)
    else:
        run = engine.run(model, total, stim, probes=outs, progress=progress)
        reference = make_engine("envelope", make_engine("envelope").Options(settle_tol=CLOCKED_SETTLE_TOL))
        judged, source = _run_cycles(reference, model, stim, reads, outs, False, timing["pause"], clock)[1], "envelope"
    amp = np.abs(run.amp[:, [run.probe(n) for n in outs], 0]) / p.u_r
    trace = []
    for k, t in enumerate(read_at):
        a = {n: float(amp[t - 10:t, j].mean()) for j, n in enumerate(outs)}
        v, ok = judged[k] if judged and judged[k] else (None, False)
        decoded = verdict.apply(decode(netlist, a, model.design.const_outputs, model.levels), a, v, ok, source, model.levels)
        trace.append({"cycle": k, **decoded, "amplitudes": a})
    total = read_at[-1] + total - reads[-1]                  # with the periods held at unsettled reads
    extra = {"envelope_step": step, "settle": engine.options.settle_tol,
             "simulated_periods": total - run.settled_periods,
             "cycles_reintegrated": run.extra.get("reintegrated", 0)} if engine.capabilities.settle else {}
    res = {"backend": backend, **_final(trace), "amplitudes": trace[-1]["amplitudes"], "trace": trace,
           "periods": total, "timing": timing, "wall_s": time.time() - t0, "verdict_s": clock.seconds,
           "cycles_held": run.extra.get("held", 0), **extra, **_engine_fields(engine)}
    if waveform:
        res["waveform"] = Waveform(amp, list(read_at), outs)
    return res


CLOCKED_VCD_COMMENT = ("mech2spice simulate: one time unit per clock cycle; at time k the inputs clocked in at "
                       "edge k and the outputs read after it (x: a bit outside both bands), amplitudes in u_R")


def clocked_waveform(netlist: Netlist, cycles: list[dict[str, int]], res: dict):
    """A clocked run (run_clocked_logic / run_clocked_physical) as a waveform.Waveform: per cycle k the inputs
    of cycle k, the output ports of trace entry k as vectors (an invalid bit x) and, on a physical engine,
    each output bit's amplitude in u_R as a real; scopes TOP.inputs, TOP.outputs, TOP.amplitudes.  Names as
    identifiers.vcd writes them (an escaped Verilog name's dots and brackets escaped)."""
    from .identifiers import vcd
    from .waveform import Waveform
    trace = res["trace"]
    wave = Waveform([e["cycle"] for e in trace], comment=CLOCKED_VCD_COMMENT)
    top = vcd(netlist.top)
    for port, width in netlist.inputs.items():
        wave.add_wire([top, "inputs"], vcd(port), width, [cycles[e["cycle"]].get(port, 0) for e in trace])
    for port, width in netlist.outputs.items():
        wave.add_bits([top, "outputs"], vcd(port), [[e["bits"][f"{port}[{i}]"] for i in range(width)] for e in trace])
    for bit in (trace[0].get("amplitudes") or {}) if trace else {}:
        port, _, index = bit.rpartition("[")
        wave.add_real([top, "amplitudes"], f"{vcd(port)}[{index}", [e["amplitudes"][bit] for e in trace])
    return wave
