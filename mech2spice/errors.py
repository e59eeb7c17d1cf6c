"""Errors the command line turns into one clear line on stderr (no traceback)."""


class Mech2SpiceError(Exception):
    """Any user-facing failure: bad input, missing tool, diverging simulation."""


class DivergenceError(Mech2SpiceError):
    """A simulation blew up; names the degree of freedom and the time."""

    def __init__(self, dof: str, t: float, period: float, value: float):
        self.dof, self.t, self.value = dof, t, value
        super().__init__(
            f"simulation diverged: DOF '{dof}' reached |u| = {value:.3g} at t = {t:.4g} "
            f"({t / period:.1f} drive periods); check for negative total stiffness "
            f"or damping, or a step too large for the integrator")


class ToolMissingError(Mech2SpiceError):
    """An external program (ngspice, yosys) cannot be found."""
