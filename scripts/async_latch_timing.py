"""The forced latch's own timing (docs/rtl.md): how long after a reset or set is asserted the output reaches
its band, that releasing it moves nothing, and how long after the next clock pulse starts the released latch
shows the captured bit (against the plain latch's LATCH_OUTPUT_DELAY_MIN .. LATCH_OUTPUT_DELAY, 1280 .. 1650).

    python scripts/async_latch_timing.py [--backend envelope|rk4|carrier] [--power-up]

Three one-bit registers, each with the sequence: capture the bit opposite to the forced value (cycle 0),
assert the forcing input (cycle 1's inputs, in the pause after edge 0), keep it over edge 1, release it with
the opposite bit at D (cycle 2), capture that bit at edge 2.  One row per register.  `--power-up` instead
runs `reg z = 1; always @(posedge clk) begin r <= z; z <= d; end` for 3 cycles (r reads z's power-up value
after the first edge) on the backend, against logic: any engine, the circuit simulators included.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from mech2spice import simulation                           # noqa: E402
from mech2spice.experiments.clocking import clock_timing     # noqa: E402
from mech2spice.physics.params import DEFAULT                # noqa: E402
from mech2spice.synthesis.synth import synthesize            # noqa: E402

DESIGNS = {   # name: (body, forcing port, level that asserts it, forced value)
    "reset, active high": ("always @(posedge clk or posedge f) if (f) q <= 1'b0; else q <= d;", 1, 0),
    "set, active high": ("always @(posedge clk or posedge f) if (f) q <= 1'b1; else q <= d;", 1, 1),
    "reset, active low": ("always @(posedge clk or negedge f) if (!f) q <= 1'b0; else q <= d;", 0, 0),
}


def measure(body: str, on: int, value: int, backend: str, tmp: Path) -> dict:
    src = tmp / "forced.v"
    src.write_text(f"module forced(input clk, input f, input d, output reg q);\n  {body}\nendmodule\n")
    nl = synthesize(src)
    other = 1 - value
    cycles = [{"f": 1 - on, "d": other}, {"f": on, "d": other}, {"f": 1 - on, "d": other}, {"f": 1 - on, "d": other}]
    res = simulation.run_clocked_physical(nl, DEFAULT, cycles, backend, clock_timing(nl), waveform=True)
    wave, timing = res["waveform"], res["timing"]
    segs, _, _ = simulation.clocked_schedule(cycles, timing)
    amp = wave.amplitude[:, wave.probes.index("q[0]")]
    levels = DEFAULT.levels

    def entered(start: int, bit: int) -> int:
        """Periods from `start` until the output enters `bit`'s band and stays there to the segment's end."""
        lo, hi = levels.band(bit)
        inside = (amp[start:] >= lo) & (amp[start:] <= hi)
        outside = np.flatnonzero(~inside[:timing["pause"]])
        return int(outside[-1] + 1) if len(outside) else 0

    assert_at, release_at, pulse2 = segs[2][0], segs[4][0], segs[5][0]
    pause = amp[release_at:pulse2]
    lo, hi = levels.band(value)
    return {"assert_to_band": entered(assert_at, value),
            "release_excursion": float(max(lo - pause.min(), pause.max() - hi, 0.0)),
            "release_min_margin": float(min(pause.min() - lo, hi - pause.max())),
            "pulse_to_band": entered(pulse2, other),
            "trace_ok": [t["bits"] for t in res["trace"]] == [t["bits"] for t in simulation.run_clocked_logic(nl, cycles)["trace"]],
            "held": (float(amp[assert_at + timing["pause"] - 10:assert_at + timing["pause"]].mean()),
                     float(pause.min()), float(pause.max())),
            "stable": res.get("stable"), "settled": res.get("settled"), "min_margin": res["min_margin"],
            "gates": len(nl.gates()), "logic_depth": timing["logic_depth"], "pause": timing["pause"]}


POWER_UP = ("module pu2(input clk, input d, output reg r);\n  reg z = 1'b1;\n"
            "  always @(posedge clk) begin r <= z; z <= d; end\nendmodule\n")


def power_up(backend: str, tmp: Path) -> str:
    import time
    src = tmp / "pu2.v"
    src.write_text(POWER_UP)
    nl = synthesize(src)
    cycles = [{"d": 0}, {"d": 0}, {"d": 1}]
    t0 = time.time()
    ref = [t["bits"] for t in simulation.run_clocked_logic(nl, cycles)["trace"]]
    got = simulation.run_clocked_physical(nl, DEFAULT, cycles, backend, clock_timing(nl))["trace"]
    ok = [t["bits"] for t in got] == ref and all(t["valid"] and t["stable"] and t["settled"] for t in got)
    return (f"power-up on {backend}: r per cycle {[t['bits']['r[0]'] for t in got]} (logic "
            f"{[b['r[0]'] for b in ref]}), {'equal, every read valid, stable and settled' if ok else 'DIFFERENT'}, "
            f"{time.time() - t0:.0f} s")


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--backend", default="envelope")
    ap.add_argument("--power-up", action="store_true", help="the power-up check instead of the timing table")
    args = ap.parse_args(argv)
    if args.power_up:
        with tempfile.TemporaryDirectory() as tmp:
            print(power_up(args.backend, Path(tmp)))
        return 0
    print(f"| register ({args.backend}) | assert -> output in band | release: output leaves its band by | "
          "next pulse -> captured bit in band | trace | stable, settled | min margin |")
    print("|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for name, (body, on, value) in DESIGNS.items():
            r = measure(body, on, value, args.backend, Path(tmp))
            print(f"| {name} | {r['assert_to_band']} periods | {r['release_excursion']:.3f} u_R (margin "
                  f"{r['release_min_margin']:+.3f}) | {r['pulse_to_band']} periods | "
                  f"{'as logic' if r['trace_ok'] else 'WRONG'} | {r['stable']}, {r['settled']} | "
                  f"{r['min_margin']:+.3f} |", flush=True)
            print(f"<!-- {name}: forced level {r['held'][0]:.4f} u_R; over the release pause {r['held'][1]:.4f} .. "
                  f"{r['held'][2]:.4f} u_R; gates {r['gates']}, depth {r['logic_depth']}, pause {r['pause']} -->")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
