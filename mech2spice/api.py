"""The Python API: the command line's `synth`, `simulate` and `emit` as functions returning its JSON fields.

Every argument goes through the command line's checks (inputs.py, the engines' Options, load_params) with
its caps, before any work: a bad one raises Mech2SpiceError with one line, never TypeError or KeyError."""
from __future__ import annotations

import os

from . import inputs as check
from . import simulation
from .backends import BACKENDS, engine_class, engine_options
from .errors import Mech2SpiceError
from .experiments import clocking
from .physics import network
from .physics.params import PRESETS, GateParams, load_params, params_file
from .synthesis import synth
from .synthesis.ports import pack_inputs
from .synthesis.synth import Netlist, observe


def synthesize(design, top: str | None = None, *, max_fanout: int | None = None) -> Netlist:
    """Synthesize the Verilog file `design` into a Netlist of 2-input NOR gates (and latches)."""
    path = check.path_value(design, "design")
    if top is not None and not isinstance(top, str):
        raise Mech2SpiceError(f"top must be a module name (a string), not {check.value_kind(top)}")
    if max_fanout is not None:
        max_fanout = check.whole_number(max_fanout, "max_fanout", 2, check.MAX_FANOUT_LIMIT)
    return synth.synthesize(path, top=top, max_fanout=max_fanout)


def _netlist(design, top: str | None = None, observe_ports: list[str] | None = None) -> Netlist:
    nl = design if isinstance(design, Netlist) else synthesize(design, top=top, max_fanout=network.MAX_FANOUT)
    return observe(nl, observe_ports) if observe_ports else nl


def _params(params) -> GateParams:
    if isinstance(params, GateParams):
        params.validate()
        return params
    return load_params(params)


def _periods(periods) -> int | None:
    return None if periods is None else check.whole_number(periods, "periods", 1, check.MAX_PERIODS)


def _progress(progress):
    """True (a bar on stderr), False, or a callable taking one progress line at a time."""
    if not (isinstance(progress, bool) or callable(progress)):
        raise Mech2SpiceError(f"progress must be True, False or a callable, not {check.value_kind(progress)}")
    return progress


def simulate(design, inputs: dict[str, int] | None = None, *, backend: str = "rk4", params="default",
             options=None, periods: int | None = None, cycles: int | None = None, stimulus=None,
             progress: bool = False) -> dict:
    """Run a design (a Verilog path or a Netlist) on a backend and decode its outputs.

    Combinational designs take `inputs` (port -> integer, unset ports are 0).  Clocked designs also take
    `cycles` (the inputs held for that many clock cycles) or `stimulus` ([{"set": {...}, "cycles": N}, ...]
    or a JSON file of that).  `options` is the backend's Options dataclass (`BACKENDS[name].Options`).
    Returns the fields of `mech2spice simulate --json`."""
    options = engine_options(backend, options)
    values, periods, progress = check.port_values(inputs), _periods(periods), _progress(progress)
    steps = _steps(values, backend, cycles, stimulus)
    p = _params(params)
    nl = _netlist(design)
    if nl.clocked:
        if steps is None:
            raise Mech2SpiceError(f"{nl.top} is clocked by {nl.clock_text()}: give cycles=N or a stimulus")
        cycle_values = simulation.expand_steps(steps)
        timing = clocking.clock_timing(nl, p=p)
        return simulation.run_clocked_physical(nl, p, cycle_values, backend, timing, progress=progress,
                                               options=options)
    if steps is not None:
        raise Mech2SpiceError(f"{nl.top} has no flip-flops: cycles and stimulus apply to clocked designs")
    pack_inputs(nl, values)
    res = simulation.run_physical(nl, p, [values], backend, periods=periods, progress=progress, options=options)[0]
    return {**res, "inputs": values}


def _steps(values: dict, backend: str, cycles, stimulus) -> list[dict] | None:
    """The clocked stimulus from `cycles` or `stimulus` (a list or a JSON file), checked; None without either."""
    if cycles is not None and stimulus is not None:
        raise Mech2SpiceError("give cycles or stimulus, not both")
    if cycles is not None:
        cycles = check.whole_number(cycles, "cycles", 1, check.MAX_CYCLES)
        check.check_cycles(cycles, engine_class(backend), "cycles asks for")
        return [{"set": values, "cycles": cycles}]
    if stimulus is None:
        return None
    if isinstance(stimulus, list):
        return check.check_steps(stimulus, values, engine_class(backend))
    return check.stimulus_steps(check.path_value(stimulus, "stimulus (a list of steps or a JSON file)"),
                                values, engine_class(backend))


def emit(design, inputs: dict[str, int] | None = None, *, params="default", periods: int | None = None,
         options=None, path=None, force: bool = False) -> str:
    """The carrier-level ngspice netlist of a combinational design with these inputs (also written to `path`:
    never the design or parameter file, nor an existing file that is not a netlist unless `force`).  It reads
    its own result: `ngspice -b FILE` prints each output bit and port (docs/spice.md)."""
    from .spice import NETLIST, combinational_only
    from .spice.oscillator_netlist import emit as emit_netlist
    from .spice.readout import about
    options = engine_options("ngspice", options)
    values, periods, p = check.port_values(inputs), _periods(periods), _params(params)
    if path is not None:                          # the command line's rule, before any work
        read = [*check.design_inputs(getattr(design, "source", None) or design),    # a Netlist names its file
                ("the params file", params_file(params) if isinstance(params, (str, os.PathLike)) else None)]
        path = check.check_output_file(check.path_value(path, "path"), read, "netlist file", kind=NETLIST,
                                       force=force is True, remedy="force=True replaces it")
    nl = _netlist(design)
    combinational_only(nl)
    pack_inputs(nl, values)
    model = network.build(nl, p)
    stim = network.stimulus(model, nl, p, [(0, [values])])
    title = f"mech2spice: {nl.top} with {', '.join(f'{k}={v}' for k, v in values.items()) or 'inputs 0'}"
    source = os.fspath(design) if isinstance(design, (str, os.PathLike)) else "(a Netlist)"
    text = emit_netlist(model, periods or clocking.period_budget(nl), stim, options=options, title=title,
                        about=about(source, nl.top, values))
    if path is not None:
        check.write_text(path, text, encoding="ascii")
    return text


__all__ = ["BACKENDS", "GateParams", "emit", "simulate", "synthesize"]
