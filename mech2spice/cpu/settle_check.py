"""Is each processor read settled?  Checked against the read's own future (issue #25).

A processor pause ends early: idle skipping holds the state once the channels stop moving by the settle
tolerance, and per-gate latency freezes settled gates.  The clocked runs of `simulate` judge each read by
the stability verdict, whose eigenvalue search costs 10-30 s on the processor's 12972 unknowns
(docs/stability.md); here each read is judged by what the same engine does next: a copy of the state
continues `periods` more with nothing skipped (no idle skipping, no latency), and every probed bit's
amplitude there is where the read was heading.  Its distance from the read is what was still to come.

The rule is the bands' and the margins', as in verdict.settled: a read is settled when no bit changes band
and each bit's still-to-come is at most MARGIN_SHARE of its margin (so its decoded value and, to that
share, its margin stand).  Bits with more than verdict.SETTLED_BW band widths still to come, the clocked
runs' tolerance, are counted too.  The continuation must itself have come to rest (its last periods within
SETTLED_BW of its middle ones), else the read is counted unconverged: a slower mode than `periods` covers.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace, fields

import numpy as np

from ..backends import make_engine
from ..verdict import SETTLED_BW, band_width

PERIODS = 6000          # ~7 of the sieve's slowest decays at its halt (880 periods, docs/stability.md)
MARGIN_SHARE = 0.25     # what is still to come may take at most this share of a bit's margin
READ = 10               # periods averaged, as the processor reads (physical.READ_PERIODS)


@dataclass
class SettleCheck:
    """The record over every read checked; `engine` continues each read with nothing skipped."""
    periods: int
    levels: object
    reads: int = 0
    worst_bw: float = 0.0                 # largest still-to-come, in its band's widths
    worst: dict = field(default_factory=dict)
    over_settled_bw: int = 0              # bits with more than SETTLED_BW band widths still to come
    failures: list = field(default_factory=list)   # reads that are not settled (the first few)
    n_failures: int = 0
    unconverged: int = 0
    wall_s: float = 0.0
    bits: list = field(default_factory=list)      # per bit read: (still-to-come in band widths, share of its margin)
                                                  # (1.0 where it has none: such a read is not settled)

    def engine_for(self, engine):
        """The engine continuing a read: `engine`'s options without idle skipping or latency, keeping the
        second half of the continuation (the periods judged)."""
        own = {f.name for f in fields(engine.options)}
        off = {k: None for k in ("settle_tol", "latency") if k in own}
        if "keep_periods" in own:
            off["keep_periods"] = self.periods // 2 + READ
        return make_engine(engine.name, replace(engine.options, **off))

    def check(self, engine, model, stim, state, start_period: int, probes: list[str], read: dict, cycle: int,
              u_r: float) -> bool:
        """Continue `state` and judge the read `read` (probe -> u_R); True when it is settled."""
        t0 = time.perf_counter()
        state = engine.dynamical_state(tuple(np.array(a) for a in state))
        run = engine.run(model, self.periods, stim, state=state, start_period=start_period, probes=probes)
        amp = np.abs(run.amp[:, :, 0]) / u_r
        half = self.periods // 2
        reached, middle = amp[-READ:].mean(axis=0), amp[-(half + READ):-half].mean(axis=0)   # the end; halfway
        bad = [self._bit(name, read[name], float(a), cycle) for name, a in zip(probes, reached)]
        converged = all(abs(a - m) <= SETTLED_BW * band_width(a, self.levels) for a, m in zip(reached, middle))
        self.reads += 1
        self.n_failures += any(bad)
        self.unconverged += not converged
        self.wall_s += time.perf_counter() - t0
        return not any(bad)

    def _bit(self, name: str, x: float, a: float, cycle: int) -> bool:
        """Record bit `name` read at x, heading to a; True if it is not settled (changes band, or moves by more
        than MARGIN_SHARE of its margin)."""
        lv = self.levels
        still = float(abs(a - x) / band_width(x, lv))
        margin = lv.margin(x) * lv.width(0)
        self.bits.append((still, abs(a - x) / margin if margin > 0 else 1.0))   # no margin: fails below
        self.over_settled_bw += int(still > SETTLED_BW)
        where = {"cycle": cycle, "bit": name, "read": float(x), "reached": a}
        if still > self.worst_bw:
            self.worst_bw, self.worst = still, where
        bad = lv.band_of(x) != lv.band_of(a) or abs(a - x) > MARGIN_SHARE * max(margin, 0.0)
        if bad and len(self.failures) < 10:
            self.failures.append(where)
        return bad

    def to_json(self) -> dict:
        still, share = np.array(self.bits or [(0.0, 0.0)]).T
        return {"periods": self.periods, "reads": self.reads, "bits_checked": len(self.bits),
                "settled": self.n_failures == 0, "reads_not_settled": self.n_failures, "not_settled": self.failures,
                "worst_still_to_come_bw": self.worst_bw, "worst": self.worst,
                "p99_still_to_come_bw": float(np.quantile(still, 0.99)), "median_still_to_come_bw": float(np.median(still)),
                "largest_margin_share": float(share.max()), "margin_share": MARGIN_SHARE,
                "bits_over_settled_bw": self.over_settled_bw, "settled_bw": SETTLED_BW,
                "reads_unconverged": self.unconverged, "wall_s": self.wall_s}
