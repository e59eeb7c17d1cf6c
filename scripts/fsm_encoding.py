"""State machines as written or recoded: what Yosys's FSM recoding (`fsm`, one-hot for small machines) does to
the mechanical network, on the public RTL suite (docs/rtl.md, "State machines").

Synthesis runs `synth -flatten -nofsm`: a state register keeps the source's encoding.  This script synthesises
each design of `$MECH2SPICE_BENCHMARKS/rtl/manifest.json` both ways (the flow with and without `-nofsm`) and
counts NOR gates, latches and the mechanical model's oscillators (physics.model, default parameters); designs
whose counts do not change are left out of the table.

Usage:  MECH2SPICE_BENCHMARKS=DIR python scripts/fsm_encoding.py [--out reports/fsm_encoding.json]
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from mech2spice.physics import network           # noqa: E402
from mech2spice.errors import Mech2SpiceError     # noqa: E402
from mech2spice.physics import params             # noqa: E402
from mech2spice.synthesis import synth            # noqa: E402

SKIP = {"itc99_b14", "epfl_bar", "epfl_max", "epfl_adder"}     # combinational or slow in Yosys: no state machine
_AS_WRITTEN = synth._flow


def _recoding(*args, **kwargs) -> str:
    """The flow as it was before synthesis kept the source's encoding: Yosys's own `fsm` pass runs."""
    return _AS_WRITTEN(*args, **kwargs).replace("synth -flatten -nofsm", "synth -flatten")


def _counts(path: Path, top: str | None) -> dict:
    nl = synth.synthesize(path, top=top)
    model = network.build(nl, params.DEFAULT)
    return {"gates": len(nl.gates()), "latches": len(nl.latches()), "oscillators": model.counts()["oscillators"]}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=ROOT / "reports" / "fsm_encoding.json")
    args = p.parse_args(argv)
    root = Path(os.environ.get("MECH2SPICE_BENCHMARKS", "")) / "rtl"
    if not (root / "manifest.json").is_file():
        sys.exit("fsm_encoding.py: MECH2SPICE_BENCHMARKS/rtl/manifest.json not found")
    rows = []
    for d in json.loads((root / "manifest.json").read_text())["designs"]:
        if d["name"] in SKIP:
            continue
        try:
            kept = _counts(root / d["file"], d.get("top"))
            synth._flow = _recoding
            recoded = _counts(root / d["file"], d.get("top"))
        except Mech2SpiceError:
            continue                                   # refused either way: not this script's question
        finally:
            synth._flow = _AS_WRITTEN
        if kept != recoded:
            rows.append({"design": d["name"], "as_written": kept, "recoded": recoded})
            print(d["name"], "as written", kept, "recoded", recoded, flush=True)
    out = {"script": "scripts/fsm_encoding.py", "date": datetime.datetime.now(datetime.timezone.utc).isoformat(),
           "machine": platform.platform(), "rows": rows}
    args.out.write_text(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
