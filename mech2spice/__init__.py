"""mech2spice: Verilog -> networks of nonlinear mechanical oscillators -> RK4 / envelope / ngspice."""

__version__ = "0.1.0"
