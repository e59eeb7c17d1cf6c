"""The Python API: the command line's `synth`, `simulate` and `emit` as functions returning its JSON fields."""
from __future__ import annotations

from pathlib import Path

from . import simulation
from .backends import BACKENDS
from .errors import Mech2SpiceError
from .inputs import check_output_file, params_file, stimulus_steps, write_text
from .physics import network
from .physics.params import GateParams, load_params
from .synthesis.ports import pack_inputs
from .synthesis.synth import Netlist, observe, synthesize


def _netlist(design, top: str | None = None, observe_ports: list[str] | None = None) -> Netlist:
    nl = design if isinstance(design, Netlist) else synthesize(design, top=top, max_fanout=network.MAX_FANOUT)
    return observe(nl, observe_ports) if observe_ports else nl


def _params(params) -> GateParams:
    return params if isinstance(params, GateParams) else load_params(params)


def simulate(design, inputs: dict[str, int] | None = None, *, backend: str = "rk4", params="default",
             options=None, periods: int | None = None, cycles: int | None = None, stimulus=None,
             progress: bool = False) -> dict:
    """Run a design (a Verilog path or a Netlist) on a backend and decode its outputs.

    Combinational designs take `inputs` (port -> integer, unset ports are 0).  Clocked designs also take
    `cycles` (the inputs held for that many clock cycles) or `stimulus` ([{"set": {...}, "cycles": N}, ...]
    or a JSON file of that).  `options` is the backend's Options dataclass (`BACKENDS[name].Options`).
    Returns the fields of `mech2spice simulate --json`."""
    nl = _netlist(design)
    p, inputs = _params(params), dict(inputs or {})
    if nl.clock:
        steps = _clocked_steps(nl, inputs, backend, cycles, stimulus)
        cycle_values = simulation.expand_steps(steps)
        timing = simulation.clock_timing(nl, p=p)
        return simulation.run_clocked_physical(nl, p, cycle_values, backend, timing, progress=progress,
                                               options=options)
    if cycles or stimulus:
        raise Mech2SpiceError(f"{nl.top} has no flip-flops: cycles and stimulus apply to clocked designs")
    pack_inputs(nl, inputs)
    res = simulation.run_physical(nl, p, [inputs], backend, periods=periods, progress=progress, options=options)[0]
    return {**res, "inputs": inputs}


def _clocked_steps(nl: Netlist, inputs: dict, backend: str, cycles, stimulus) -> list[dict]:
    if stimulus is not None:
        if isinstance(stimulus, (str, Path)):
            return stimulus_steps(stimulus, inputs, backend)
        return [{"set": {**inputs, **s.get("set", {})}, "cycles": s.get("cycles", 1)} for s in stimulus]
    if not cycles:
        raise Mech2SpiceError(f"{nl.top} is clocked by '{nl.clock}': give cycles=N or a stimulus")
    return [{"set": inputs, "cycles": cycles}]


def emit(design, inputs: dict[str, int] | None = None, *, params="default", periods: int | None = None,
         options=None, path=None, force: bool = False) -> str:
    """The carrier-level ngspice netlist of a combinational design with these inputs (also written to `path`:
    never the design or parameter file, nor an existing file that is not a netlist unless `force`)."""
    from .spice.carrier import SpiceOptions, emit as emit_netlist
    if path is not None:                          # the command line's rule, before any work
        from .spice._common import NETLIST
        read = {"the design": design, "the params file": params_file(params) if isinstance(params, str) else None}
        check_output_file(path, read, "netlist file", kind=NETLIST, force=force, remedy="force=True replaces it")
    nl, p, inputs = _netlist(design), _params(params), dict(inputs or {})
    pack_inputs(nl, inputs)
    model = network.build(nl, p)
    stim = network.stimulus(model, nl, p, [(0, [inputs])])
    options = options or SpiceOptions()
    options.validate()
    title = f"mech2spice: {nl.top} with {', '.join(f'{k}={v}' for k, v in inputs.items()) or 'inputs 0'}"
    text = emit_netlist(model, periods or simulation.period_budget(nl), stim, options=options, title=title)
    if path is not None:
        write_text(path, text, encoding="ascii")
    return text


__all__ = ["BACKENDS", "GateParams", "emit", "simulate", "synthesize"]
