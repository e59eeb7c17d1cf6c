"""mech2spice: Verilog -> networks of nonlinear mechanical NOR gates -> RK4, envelope and circuit simulators.

    import mech2spice as m2s
    adder = m2s.synthesize("verilog/adder2.v")
    m2s.simulate(adder, {"a": 3, "b": 2}, backend="envelope")["outputs"]     # {'s': 5}

The pipeline and how to add an engine: docs/architecture.md.
"""
from .api import emit, simulate, synthesize
from .backends import BACKENDS
from .errors import Mech2SpiceError
from .physics.params import DEFAULT, PRESETS, PRINTED, GateParams, load_params
from .synthesis.synth import Netlist

__version__ = "0.2.0"
__all__ = ["BACKENDS", "DEFAULT", "GateParams", "Mech2SpiceError", "Netlist", "PRESETS", "PRINTED", "emit",
           "load_params", "simulate", "synthesize"]
