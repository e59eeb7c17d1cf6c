"""A fingerprint of what a design builds: its NOR/latch graph (every node and edge with attributes), its
mechanical model (every array, drive and clock drive) and its clock schedule, one line per design.  Run it in
two trees and diff the output to show a change leaves the designs' networks as they were.

    python scripts/model_fingerprint.py [DESIGN.v ...]      (default: the processor, sqrt, counter4, fsm, dff)
"""
from __future__ import annotations

import hashlib
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from mech2spice.cpu.netlist import CPU_VERILOG, cpu_netlist          # noqa: E402
from mech2spice.experiments.clocking import clock_timing              # noqa: E402
from mech2spice.physics import network                                # noqa: E402
from mech2spice.physics.params import DEFAULT                         # noqa: E402
from mech2spice.synthesis.synth import synthesize                     # noqa: E402

DEFAULTS = ["verilog/cpu.v", "verilog/sqrt.v", "verilog/counter4.v", "verilog/fsm.v", "verilog/dff.v"]


def fingerprint(design: str) -> str:
    nl = (cpu_netlist(str(CPU_VERILOG), max_fanout=network.MAX_FANOUT) if Path(design).name == "cpu.v"
          else synthesize(ROOT / design if not Path(design).is_absolute() else design))
    m = network.build(nl, DEFAULT)
    h = hashlib.sha256()
    h.update(repr(sorted(nl.graph.nodes(data=True))).encode())
    h.update(repr(sorted(nl.graph.edges(data=True))).encode())
    h.update(repr(m.names).encode())
    h.update(repr([(d.dof, d.amplitude, d.phase, d.name) for d in m.drives]).encode())
    for key, value in sorted(vars(m).items()):
        if isinstance(value, np.ndarray):
            h.update(key.encode())
            h.update(value.tobytes())
    h.update(repr(m.design.clock_drives).encode())
    schedule = clock_timing(nl) if nl.clock else {"logic_depth": network.logic_depth(nl)}
    return f"{design} {len(m.names)} oscillators {h.hexdigest()[:16]} {schedule}"


def main(argv: list[str]) -> int:
    for design in argv or DEFAULTS:
        print(fingerprint(design), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
