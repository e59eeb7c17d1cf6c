"""The reports in reports/*.md: one module each, one entry point (`mech2spice report NAME`).

Every module in REPORTS exposes ``write(directory, **options) -> Path`` (the markdown it wrote) and is the
only writer of the files listed in its entry.  Importing this package imports none of them (the command
line lists reports without loading numpy, matplotlib or numba).
"""
from __future__ import annotations

from dataclasses import dataclass
from importlib import import_module


@dataclass(frozen=True)
class Report:
    """One report: what it shows, roughly how long it takes, what it writes and the options of its write()."""
    description: str
    cost: str
    writes: tuple[str, ...]
    options: tuple[str, ...] = ()


# In `all` order: a report reading another's JSON comes after it (cpu_physical reads fidelity.json; cpu and
# performance read cpu_physical.json).  spice reads speed_accuracy.json, the last one written;
# speed_accuracy.md appends carrier.json's section.
REPORTS: dict[str, Report] = {
    "gate": Report("the NOR gate against the paper's six requirements; why the printed parameters fail",
                   "~1 min", ("gate.md", "gate.json"), ("quick", "render")),
    "adder": Report("the 2-bit adder from Verilog, all 16 sums on RK4 (paper Fig. 4)", "~1 min", ("adder.md", "adder.json"),
                    ("render",)),
    "sequential": Report("the latch, a counter, the FSM and sqrt(2809) = 53 (paper Figs. 5, 6)", "~4 min",
                         ("sequential.md", "sqrt.md", "sequential.json"), ("sqrt_rk4", "render")),
    "spice": Report("the electrical analogy; ngspice against RK4 on four scenes", "~4 min", ("spice.md", "spice.json"),
                    ("render",)),
    "fidelity": Report("what each envelope speed-up (step, settle detection, cone pruning) costs in accuracy; are the processor's reads settled",
                       "~30 min", ("fidelity.md", "fidelity.json", "fidelity_options.png"), ("only", "cycles", "render")),
    "cpu_physical": Report("the processor as 6486 oscillators against the ISS, cycle by cycle, to the halt",
                           "~5 min", ("cpu_physical.md", "cpu_physical.json"),
                           ("cycles", "program", "backend", "step", "settle", "checkpoint", "resume", "name",
                            "render")),
    "cpu_circuit": Report("the whole processor and its memory in VACASK (envelope level): cycles against the ISS, "
                          "amplitudes against the envelope engine, the simulator's cost", "~30 min",
                          ("cpu_circuit.md", "cpu_circuit.json", "cpu_circuit.png"),
                          ("cycles", "only", "render")),
    "cpu": Report("the 8-bit processor: ISA, gate counts, the sieve, Turing machines", "~2 min", ("cpu.md", "cpu.json"),
                  ("skip_slow", "render")),
    "envelope": Report("where the envelope model agrees with RK4, why it differs, the step bound", "~10 min",
                       ("envelope.md", "envelope.json"), ("quick", "cache", "render")),
    "performance": Report("what every fidelity level costs as circuits grow, and where the time goes",
                          "~15 min", ("performance.md", "performance.json"), ("only", "quick", "sqrt_rk4_full", "render")),
    "carrier": Report("the carrier engine (Lawson RK4): accuracy against RK4, convergence against wall time, its rate "
                      "and roofline on the processor, processor cycles against RK4, the whole sieve against the envelope "
                      "and with per-gate latency",
                      "~10 min",
                      ("carrier.md", "carrier.json", "carrier_speed_accuracy.png", "carrier_roofline.png",
                       "carrier_sieve_fidelity.png", "carrier_latency_sieve.png"),
                      ("only", "quick", "render", "carrier_trace", "envelope_trace", "processor_check", "latency_trace")),
    "speed_accuracy": Report("RK4 and ngspice (carrier and envelope netlists): speed, accuracy, failure points",
                             "~40 min", ("speed_accuracy.md", "speed_accuracy.json"), ("only", "design", "quick", "render")),
    "robustness": Report("yield of the gate, a 3-gate chain and the adder under per-element spread (Monte-Carlo "
                         "on Dask), per-gate failure rate, the processor extrapolated", "~30 min",
                         ("robustness.md", "robustness.json", "robustness_yield.png", "robustness_noise.png"),
                         ("quick", "render")),
    "domain": Report("the operating domain of the gate, the adder and the processor (30 cycles): drive frequency "
                     "x supply drive (and x stiffness drift for the gate), without and with 1 % trimmed spread",
                     "~40 min", ("domain.md", "domain.json", "domain_gate.png", "domain_adder.png", "domain_cpu.png"),
                     ("only", "quick", "render")),
    "design": Report("automated block design: the structures searched, tolerance/margin/delay/energy Pareto "
                     "front, what limits each, the best block on the adder, sqrt and the sieve (needs "
                     "`mech2spice design`)", "~20 min", ("design.md", "design.json", "design_pareto.png"),
                     ("skip_slow", "render")),
}


def module(name: str):
    """The module behind report `name` (imported on first use)."""
    return import_module(f"{__name__}.{name}")
