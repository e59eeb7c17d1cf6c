"""ngspice as two engines: the carrier-level electrical analogy and the envelope equations as a circuit.

The netlists come from spice.oscillator_netlist and spice.envelope_netlist; spice.runner runs ngspice.  ngspice has no
cheap restart, so neither engine continues from a state: a run always starts from rest.
"""
from __future__ import annotations

from ..spice import runner
from ..spice.oscillator_netlist import SpiceOptions
from ..spice.envelope_netlist import EnvelopeSpiceOptions, run_envelope_spice
from ._base import Capabilities, CircuitSimulator, require_rest


class NgspiceEngine(CircuitSimulator):
    """The mobility analogy (VCCS springs, B-source couplings) under ngspice, prewarped trapezoidal steps."""

    name = "ngspice"
    capabilities = Capabilities(batch=True, noise=True, simulator="ngspice")
    Options = SpiceOptions

    def run(self, model, periods, stimulus=None, *, state=None, start_period=0, probes=None, progress=False):
        """Every batch member as its own ngspice process; amplitudes demodulated per period."""
        require_rest(self.name, state, start_period)
        return runner.run_batch(model, periods, stimulus=stimulus, options=self.options)


class NgspiceEnvelopeEngine(CircuitSimulator):
    """The envelope equations as an ngspice netlist (two 1 F nodes per oscillating DOF), steps of whole periods."""

    name = "ngspice-envelope"
    capabilities = Capabilities(batch=True, simulator="ngspice")
    Options = EnvelopeSpiceOptions

    def run(self, model, periods, stimulus=None, *, state=None, start_period=0, probes=None, progress=False):
        """Every batch member as its own ngspice process; the envelope at each period's end."""
        require_rest(self.name, state, start_period)
        return run_envelope_spice(model, periods, stimulus=stimulus, opts=self.options)
