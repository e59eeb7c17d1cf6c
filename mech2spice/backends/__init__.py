"""The engines, by name.  Each is one module; adding one is a module and a line in `_ENGINES`."""
from __future__ import annotations

from dataclasses import replace

from ..errors import Mech2SpiceError
from ..physics.noise import check_temperature
from ..run_result import Run
from ._base import Capabilities, Engine, progress_bar
from .carrier import CarrierEngine
from .envelope import EnvelopeEngine
from .logic import LogicEngine
from .ngspice import NgspiceEngine, NgspiceEnvelopeEngine
from .rk4 import RK4Engine
from .vacask import VacaskEngine, VacaskEnvelopeEngine
from ._noise_envelope import NoisyEnvelopeEngine, NoisyEnvelopeOptions

_ENGINES = (LogicEngine, RK4Engine, CarrierEngine, EnvelopeEngine, NgspiceEngine, NgspiceEnvelopeEngine, VacaskEngine, VacaskEnvelopeEngine)
BACKENDS: dict[str, type] = {e.name: e for e in _ENGINES}


def names(capable, first: str | None = None) -> tuple[str, ...]:
    """The registered engines whose Capabilities satisfy `capable`, in the registry's order (`first`, a
    command's default, leading)."""
    found = [name for name, cls in BACKENDS.items() if capable(cls.capabilities)]
    return tuple(sorted(found, key=lambda name: name != first))


def continuing(caps: Capabilities) -> bool:
    """An engine a processor or a clocked sweep can run cycle after cycle on: it continues from its own
    state and that state can be saved."""
    return caps.physical and caps.state and caps.checkpoint


def engine_class(name: str) -> type:
    """The engine class registered under `name`."""
    if not isinstance(name, str) or name not in BACKENDS:
        raise Mech2SpiceError(f"unknown backend {name!r} (choose from {', '.join(BACKENDS)})")
    return BACKENDS[name]


def engine_options(name: str, options=None):
    """`options` for the engine `name` checked: its own Options class (another engine's would be misread),
    validated; None gives the defaults."""
    cls = engine_class(name).Options
    if options is None:
        return cls()
    if type(options) is not cls:
        raise Mech2SpiceError(f"options for the {name} backend must be {cls.__name__} "
                              f"(BACKENDS[{name!r}].Options), not {type(options).__name__}")
    options.validate()
    return options


def make_engine(name: str, options=None):
    """An engine by name, with its options (validated) or its defaults."""
    return engine_class(name)(engine_options(name, options))


def noisy_engine(backend: str, options, temperature: float, seed: int):
    """The engine `backend` with thermal noise T = `temperature` (model units) and `seed`; T = 0 gives the
    plain engine with its options unchanged (the deterministic result, bit for bit)."""
    T = check_temperature(temperature)
    if T == 0:
        return make_engine(backend, options)
    if backend == "envelope":
        step = getattr(options, "step_periods", None)
        return NoisyEnvelopeEngine(NoisyEnvelopeOptions(T, int(seed), step if step and step <= 1 else None))
    base = make_engine(backend, options).options
    if not hasattr(base, "noise_temperature"):
        raise Mech2SpiceError(f"the {backend} backend has no thermal noise (rk4, envelope and ngspice do)")
    if backend == "ngspice":
        from ..spice.oscillator_netlist import noisy_options
        return make_engine(backend, noisy_options(base, T, int(seed)))
    return make_engine(backend, replace(base, noise_temperature=T, noise_seed=int(seed)))


__all__ = ["BACKENDS", "Capabilities", "Engine", "Run", "continuing", "engine_class", "engine_options", "make_engine",
           "names", "noisy_engine"]

