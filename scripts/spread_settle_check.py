"""Are a spread processor's reads settled?  cpu run --settle-check on Monte-Carlo samples (docs/stability.md).

    python scripts/spread_settle_check.py INDEX [--wake own|none] [--cycles 457] [--params centered_fc2]
        [--spread 0.01] [--trim fcb] [--trim-residual 1e-4] [--seed 7] [--max-fanout 12]

Builds sample INDEX as `cpu montecarlo` builds it (experiments/mc_clocked.CpuMC, powered up), runs the sieve's
cycles with every pause's read continued 6000 periods with nothing skipped (cpu/settle_check.py), and prints one
JSON line: the cycles whose compared fields differ from the ISS, block-steps, and the settle check's figures.
--wake none: a frozen gate wakes at the latency threshold (the calm rule before cpu/physical.LATENCY_WAKE).
"""
import argparse
import json
import time

from mech2spice.cpu.settle_check import PERIODS, SettleCheck
from mech2spice.experiments.mc_clocked import add_sample_options, cpu_mc_of


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("index", type=int)
    ap.add_argument("--wake", choices=["own", "none"], default="own")
    ap.add_argument("--cycles", type=int, default=457)
    add_sample_options(ap)
    a = ap.parse_args()
    mcx = cpu_mc_of(a, a.cycles, latency_wake=None if a.wake == "none" else "own")
    p = mcx.p
    t0 = time.time()
    cpu = mcx._machine(a.index)                  # powered up: the power-up's own reads are not checked
    cpu.settle_check = SettleCheck(PERIODS, p.levels)
    cpu._check_engine = cpu.settle_check.engine_for(cpu.pause_engine)
    differ = 0
    for want in mcx.want:
        got = cpu.step()
        differ += any(getattr(got, f) != getattr(want, f) for f in mcx.compared(want))
    sc = cpu.settle_check.to_json()
    print(json.dumps({"sample": a.index, "wake": cpu.latency_wake, "cycles": a.cycles,
                      "cycles_differing_from_iss": differ, "block_steps": cpu.block_steps,
                      "wall_s": round(time.time() - t0, 1),
                      **{k: sc[k] for k in ("reads", "reads_not_settled", "worst_still_to_come_bw",
                                            "p99_still_to_come_bw", "largest_margin_share", "reads_unconverged",
                                            "worst")}}))


if __name__ == "__main__":
    main()
