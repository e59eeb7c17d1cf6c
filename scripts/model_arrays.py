"""Dump the MechModel arrays of a fixed set of circuits, and compare two dumps exactly.

Shows that a change of the model builder changed no model (issue #13: blocks as data):

    PYTHONPATH=OLD_TREE python scripts/model_arrays.py dump before.pkl
    python scripts/model_arrays.py dump after.pkl [--params classic]
    python scripts/model_arrays.py compare before.pkl after.pkl     # exit 1 on any difference

Compared: DOF names, masses, total stiffness and damping, slow flags, springs, dashpots, quads, drives
(DOF, amplitude, phase, name) and probes, exactly (==, no tolerance).
"""
from __future__ import annotations

import argparse
import pickle
import sys


def circuits(params: str):
    from mech2spice.physics import loaded, network, nor
    from mech2spice.physics.params import load_params
    from mech2spice.synthesis.synth import synthesize
    from mech2spice import data
    p = load_params(params)
    out = {"single_gate": nor.single_gate(p, 0.97, 0.5), "chain": nor.chain(p, 3),
           "fanout": nor.fanout(p, 4), "loaded_pair": loaded.build(p).model,
           "loaded_gate": loaded.build(p, "gate").model}
    for design in ("adder2.v", "sqrt.v", "counter4.v"):
        out[design] = network.build(synthesize(data.verilog(design)), p)
    return out


def arrays(m) -> dict:
    return {"names": list(m.names), "mass": list(m.mass), "k_total": list(m.k_total), "c_total": list(m.c_total),
            "slow": list(m.slow), "springs": list(m.springs), "dashpots": list(m.dashpots), "quads": list(m.quads),
            "drives": [(d.dof, d.amplitude, d.phase, d.name) for d in m.drives], "probes": dict(m.probes),
            "omega": m.omega}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    d = sub.add_parser("dump")
    d.add_argument("out")
    d.add_argument("--params", default="default")
    c = sub.add_parser("compare")
    c.add_argument("a")
    c.add_argument("b")
    args = ap.parse_args()
    if args.cmd == "dump":
        with open(args.out, "wb") as f:
            pickle.dump({k: arrays(m) for k, m in circuits(args.params).items()}, f)
        return 0
    a, b = (pickle.load(open(x, "rb")) for x in (args.a, args.b))
    diffs = 0
    for name in sorted(set(a) | set(b)):
        if name not in a or name not in b:
            print(f"{name}: only in one dump")
            diffs += 1
            continue
        for key in a[name]:
            if a[name][key] != b[name][key]:
                print(f"{name}/{key}: differs")
                diffs += 1
    n = sum(len(v["names"]) for v in a.values())
    print(f"{len(a)} circuits ({n} DOFs) compared exactly, {diffs} differences")
    return 1 if diffs else 0


if __name__ == "__main__":
    sys.exit(main())
