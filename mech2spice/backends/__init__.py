"""The engines, by name.  Each is one module; adding one is a module and a line in `_ENGINES`."""
from __future__ import annotations

from ..errors import Mech2SpiceError
from ._base import Capabilities, Engine, Run
from .carrier import CarrierEngine
from .envelope import EnvelopeEngine
from .logic import LogicEngine
from .ngspice import NgspiceEngine, NgspiceEnvelopeEngine
from .rk4 import RK4Engine
from .vacask import VacaskEngine, VacaskEnvelopeEngine

_ENGINES = (LogicEngine, RK4Engine, CarrierEngine, EnvelopeEngine, NgspiceEngine, NgspiceEnvelopeEngine, VacaskEngine, VacaskEnvelopeEngine)
BACKENDS: dict[str, type] = {e.name: e for e in _ENGINES}


def engine_class(name: str) -> type:
    """The engine class registered under `name`."""
    try:
        return BACKENDS[name]
    except KeyError:
        raise Mech2SpiceError(f"unknown backend '{name}' (choose from {', '.join(BACKENDS)})") from None


def make_engine(name: str, options=None):
    """An engine by name, with its options (validated) or its defaults."""
    return engine_class(name)(options)


__all__ = ["BACKENDS", "Capabilities", "Engine", "Run", "engine_class", "make_engine"]
