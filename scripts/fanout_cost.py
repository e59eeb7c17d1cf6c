"""What a fan-out limit costs the processor: gates, oscillators, largest fan-out and clock periods per cycle.

    python scripts/fanout_cost.py [--params centered_fc2] [--max-fanout 12 4 2]

Builds the processor (cpu/physical.PhysicalCPU, not powered up) at each limit and prints one JSON line per limit:
NOR blocks (gates + buffers), DOFs, the largest fan-out left, the logic depth and the clock schedule's pulse and
pause (experiments/clocking.clock_timing) with their sum, the periods one cycle takes at least (a pause ends early
once settled; the pulse and the rdata pause do not).
"""
import argparse
import json

from mech2spice.cpu.physical import PhysicalCPU
from mech2spice.cpu.run import load_program, make_memory
from mech2spice.physics import network
from mech2spice.physics.params import load_params


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--params", default="centered_fc2")
    ap.add_argument("--max-fanout", type=int, nargs="+", default=[12, 4, 2])
    a = ap.parse_args()
    p = load_params(a.params)
    for f in a.max_fanout:
        cpu = PhysicalCPU(make_memory(load_program("programs/sieve.asm")), "envelope", p, power_up=False, max_fanout=f)
        g = cpu.netlist.graph
        print(json.dumps({"max_fanout": f, "blocks": len(cpu.model.design.gates), "dofs": cpu.model.n,
                          "largest_fanout": max(g.out_degree(n) for n in cpu.netlist.gates()),
                          "logic_depth": network.logic_depth(cpu.netlist), "pulse": cpu.pulse, "pause": cpu.pause,
                          "pulse_plus_pause": cpu.pulse + cpu.pause}), flush=True)


if __name__ == "__main__":
    main()
