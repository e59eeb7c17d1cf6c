"""Run a synthesised design on a backend and decode its outputs from amplitudes.

Physical backends run in chunks until every output has settled (amplitude
change over the last window below a tolerance and inside a band) or the
period budget is spent.  A bit outside both bands is reported as invalid,
never rounded.
"""
from __future__ import annotations

import time

import numpy as np

from .backends import logic, rk4
from .physics import network
from .errors import Mech2SpiceError
from .physics.params import GateParams, band_of, margin
from .synthesis.synth import Netlist

BACKENDS = ("logic", "rk4", "envelope", "ngspice", "ngspice-envelope")
ENVELOPE_STEP = 4.0      # periods, at most; reports/envelope.md: no accuracy cost on the adder (bound 15.1)
SETTLE_TOL = 2e-3        # u_R change over SETTLE_WINDOW periods that counts as settled
SETTLE_WINDOW = 100
CHUNK = 100


def period_budget(netlist: Netlist) -> int:
    """Enough periods for the slowest measured gate delay (~225) through the deepest path, plus settling."""
    return 800 + 300 * network.logic_depth(netlist)


def decode(netlist: Netlist, amplitudes: dict[str, float], const: dict[str, int]) -> dict:
    """bits / outputs / valid / min_margin from output amplitudes (u_R)."""
    bits, margins = {}, []
    for bit in logic.output_bits(netlist):
        if bit in const:
            bits[bit] = const[bit]
            continue
        b = band_of(amplitudes[bit])
        bits[bit] = b
        margins.append(margin(amplitudes[bit], b))
    outputs = {}
    for port, width in netlist.outputs.items():
        vals = [bits[f"{port}[{i}]"] for i in range(width)]
        outputs[port] = None if None in vals else sum(v << i for i, v in enumerate(vals))
    return {"outputs": outputs, "bits": bits, "valid": all(v is not None for v in bits.values()),
            "min_margin": float(min(margins)) if margins else None}


def run_logic(netlist: Netlist, values: dict[str, int]) -> dict:
    t0 = time.time()
    bits = logic.evaluate_bits(netlist, values)
    out = {b: bits[b] for b in logic.output_bits(netlist)}
    outputs = logic.evaluate(netlist, values)
    return {"backend": "logic", "outputs": outputs, "bits": out, "amplitudes": {}, "valid": True,
            "min_margin": None, "periods": 0, "wall_s": time.time() - t0}


def run_physical(netlist: Netlist, p: GateParams, values: list[dict[str, int]], backend: str = "rk4",
                 periods: int | None = None, steps: int | None = None, progress: bool = False,
                 spice_options=None) -> list[dict]:
    """Simulate one batch of input assignments from rest; one result dict per member."""
    t0 = time.time()
    for v in values:
        logic.pack_inputs(netlist, v)                  # validates ports and widths up front
    model = network.build(netlist, p)
    stim = network.stimulus(model, netlist, p, [(0, values)])
    budget = periods or period_budget(netlist)
    outs = [b for b in logic.output_bits(netlist) if b in model.probes]
    if not outs:
        amps, used = np.zeros((0, len(values))), 0
    elif backend in ("rk4", "envelope"):
        amps, used = _settle(_chunker(model, stim, backend, steps, outs), model, budget, progress,
                             fixed=periods is not None)
    elif backend == "ngspice":
        amps, used = _run_ngspice(model, stim, budget, spice_options, outs)
    elif backend == "ngspice-envelope":
        amps, used = _run_ngspice_envelope(model, stim, budget, spice_options, outs)
    else:
        raise Mech2SpiceError(f"unknown backend '{backend}' (choose from {', '.join(BACKENDS)})")
    wall = time.time() - t0
    names = outs
    results = []
    for b in range(len(values)):
        a = {n: float(amps[k, b]) for k, n in enumerate(names)}
        res = {"backend": backend, **decode(netlist, a, model.design.const_outputs),
               "amplitudes": a, "periods": used, "wall_s": wall}
        results.append(res)
    return results


def _chunker(model, stim, backend: str, steps: int | None, probes: list[str]):
    """A function (n periods, state, start period) -> (run, new state) for one backend."""
    if backend == "rk4":
        def chunk(n, state, start):
            run = rk4.integrate(model, n, steps_per_period=steps or rk4.DEFAULT_STEPS_PER_PERIOD,
                                stimulus=stim, state=state, start_period=start, probes=probes)
            return run, (run.x, run.v)
    else:
        from .physics import envelope

        step = 1.0 / steps if steps else envelope_step(model)

        def chunk(n, state, start):
            run = envelope.integrate(model, n, step_periods=step,
                                     stimulus=stim, state=state, start_period=start, probes=probes)
            return run, run.extra["envelope_state"]
    return chunk


def envelope_step(model) -> float:
    """The default envelope step: ENVELOPE_STEP whole periods, less where the model's stability bound
    is lower (and a divisor of CHUNK, so chunks end on step boundaries)."""
    from .physics import envelope
    bound = envelope.max_step_periods(model)
    for step in (4, 2, 1):
        if step <= min(ENVELOPE_STEP, bound):
            return float(step)
    return 0.5


def _settle(chunk, model, budget: int, progress: bool, fixed: bool):
    state, done, history = None, 0, []
    bar = rk4._progress(budget, progress)
    while done < budget:
        n = min(CHUNK, budget - done)
        run, state = chunk(n, state, done)
        done += n
        history.append(np.abs(run.amp[-1]) / model.params.u_r)
        bar.update(n)
        if not fixed and _settled(history, done):
            break
    bar.close()
    return history[-1], done


def _settled(history: list[np.ndarray], done: int) -> bool:
    k = SETTLE_WINDOW // CHUNK
    if len(history) <= k:
        return False
    now, before = history[-1], history[-1 - k]
    inside = np.vectorize(lambda a: band_of(a) is not None)(now)
    return bool(np.all(np.abs(now - before) < SETTLE_TOL) and np.all(inside))


def _run_ngspice(model, stim, periods: int, options, probes: list[str]):
    """ngspice has no cheap restart, so it runs the whole period budget; batch members in parallel."""
    from .spice import runner as ngspice
    from .spice.carrier import SpiceOptions
    run = ngspice.run_batch(model, periods, stimulus=stim, options=options or SpiceOptions())
    rows = [run.probe_names.index(n) for n in probes]
    return np.abs(run.amp[-1, rows, :]) / model.params.u_r, periods


def _run_ngspice_envelope(model, stim, periods: int, options, probes: list[str]):
    """The envelope equations as an ngspice netlist (spice_envelope.py): the whole budget in one run per
    batch member, steps of whole drive periods."""
    from .spice.envelope import EnvelopeSpiceOptions, run_envelope_spice
    run = run_envelope_spice(model, periods, stimulus=stim, opts=options or EnvelopeSpiceOptions())
    rows = [run.probe_names.index(n) for n in probes]
    return np.abs(run.amp[-1, rows, :]) / model.params.u_r, periods


# --- clocked designs -------------------------------------------------------------------------
# Measured on verilog/dff.v (reports/sequential.md, RK4 and envelope agree within 4 periods): a 300-period
# enable pulse does not capture a 0, 500 does; the latch output (3 delay pairs) moves 1282 (storing 1)
# to 1648 (storing 0) periods after the pulse starts. Gate delays are at most 225 periods (reports/gate.md).
LATCH_MIN_PULSE = 500
LATCH_OUTPUT_DELAY_MIN = 1280
LATCH_OUTPUT_DELAY = 1650
GATE_DELAY_MAX = 225
SETTLE_MARGIN = 600


def clock_timing(netlist: Netlist, pulse: int | None = None, pause: int | None = None) -> dict:
    """Pulse and pause (drive periods) from the measured latch and gate delays and the logic depth."""
    pulse = pulse or int(1.6 * LATCH_MIN_PULSE)
    if pulse >= LATCH_OUTPUT_DELAY_MIN:
        raise Mech2SpiceError(f"a {pulse}-period clock pulse outlasts the latch's shortest output delay "
                              f"({LATCH_OUTPUT_DELAY_MIN} periods): outputs would change while it latches")
    if pulse < LATCH_MIN_PULSE:
        raise Mech2SpiceError(f"a {pulse}-period clock pulse is shorter than the {LATCH_MIN_PULSE} periods "
                              "the latch was measured to need")
    need = LATCH_OUTPUT_DELAY - pulse + GATE_DELAY_MAX * (network.logic_depth(netlist) + 1) + SETTLE_MARGIN
    return {"pulse": pulse, "pause": pause or need, "derived_pause": need,
            "logic_depth": network.logic_depth(netlist)}


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
        out = {b: bits[b] for b in logic.output_bits(netlist)}
        trace.append({"cycle": k, "outputs": logic._ports(netlist, bits), "bits": out, "valid": True,
                      "min_margin": None})
    return {"backend": "logic", **_final(trace), "trace": trace, "periods": 0, "wall_s": time.time() - t0}


def _final(trace: list[dict]) -> dict:
    last = trace[-1]
    return {"outputs": last["outputs"], "bits": last["bits"], "valid": all(t["valid"] for t in trace),
            "min_margin": min((t["min_margin"] for t in trace if t["min_margin"] is not None), default=None)}


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


CLOCKED_SETTLE = 0.1     # u_R; envelope pauses end once the channels settle: within 0.012 u_R (reports/fidelity.md)


def run_clocked_physical(netlist: Netlist, p: GateParams, cycles: list[dict[str, int]], backend: str,
                         timing: dict, steps: int | None = None, progress: bool = False,
                         settle: float | None = CLOCKED_SETTLE) -> dict:
    """Trace entry k: outputs after clock edge k.  Envelope: step envelope_step(model) unless `steps`
    per period are given, the pause rounded up to whole steps; `settle` ends a stretch of constant
    inputs once every channel is steady (envelope.integrate)."""
    t0 = time.time()
    for v in cycles:
        logic.pack_inputs(netlist, v)
    model = network.build(netlist, p)
    if backend == "envelope":
        step = 1.0 / steps if steps else envelope_step(model)
        whole = max(1, int(round(step)))
        timing = {**timing, "pause": -(-timing["pause"] // whole) * whole,
                  "pulse": -(-timing["pulse"] // whole) * whole}
    segs, reads, total = clocked_schedule(cycles, timing)
    stim = network.stimulus(model, netlist, p, [(t, [v]) for t, v, _ in segs], clock=[[c] for *_, c in segs])
    outs = [b for b in logic.output_bits(netlist) if b in model.probes]
    if backend == "rk4":
        run = rk4.integrate(model, total, steps_per_period=steps or rk4.DEFAULT_STEPS_PER_PERIOD, stimulus=stim,
                            probes=outs, progress=progress)
    elif backend == "envelope":
        from .physics import envelope
        run = envelope.integrate(model, total, step_periods=step, stimulus=stim, probes=outs,
                                 progress=progress, settle=settle)
    elif backend == "ngspice":
        from .spice import runner as ngspice
        run = ngspice.run(model, total, stimulus=stim)
    elif backend == "ngspice-envelope":
        from .spice.envelope import run_envelope_spice
        run = run_envelope_spice(model, total, stimulus=stim)
    else:
        raise Mech2SpiceError(f"unknown backend '{backend}' (choose from {', '.join(BACKENDS)})")
    rows = [run.probe_names.index(n) for n in outs]
    amp = np.abs(run.amp[:, rows, 0]) / p.u_r
    trace = []
    for k, t in enumerate(reads):
        a = {n: float(amp[t - 10:t, j].mean()) for j, n in enumerate(outs)}
        trace.append({"cycle": k, **decode(netlist, a, model.design.const_outputs), "amplitudes": a})
    extra = {"envelope_step": step, "settle": settle,
             "simulated_periods": total - run.extra["settled_periods"]} if backend == "envelope" else {}
    return {"backend": backend, **_final(trace), "amplitudes": trace[-1]["amplitudes"], "trace": trace,
            "periods": total, "timing": timing, "wall_s": time.time() - t0, **extra,
            "_amplitude_trace": amp, "_reads": reads, "_probe_names": outs}
