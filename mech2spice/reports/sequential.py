"""reports/sequential.md and sqrt.md: the mechanical latch, clocked designs, the FSM and sqrt(2809), rendered from
sequential.json (mech2spice/studies/sequential.py measures it).

Run: mech2spice report sequential [--sqrt-rk4] [--render]
(--sqrt-rk4 adds the oscillator-level RK4 run of the square root: ~15-30 min on 2 cores.)
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ._common import md_table, measured_on, non_finite, out_dir, pyplot, save_figure, shade_bands, stored, write_json

plt = pyplot()

PAPER_SQRT = {"gates": 501, "oscillators": 3006, "linear_springs": 685, "nonlinear_springs": 2505, "dashpots": 685}


def _periods(c: dict) -> tuple[np.ndarray, np.ndarray]:
    """A stored curve's amplitudes and the (1-based) periods they stand for."""
    amp = np.asarray(c["amplitude"], float)
    return amp, c["every"] * np.arange(1, amp.shape[0] + 1)


def plot_latch(res: dict, path: Path) -> None:
    """Plot the latch's output and loop-node amplitudes through its pulse sequence (enable pulses shaded)."""
    fig, ax = plt.subplots(figsize=(11, 3.4))
    shade_bands(ax)
    amp, t = _periods(res)
    ax.plot(t, amp[:, 0], label="latch output q")
    ax.plot(t, amp[:, 1], lw=0.8, alpha=0.7, label="loop node m (before the delay line)")
    for (name, d, c, _), t0, t1 in zip(res["phases"], res["starts"][:-1], res["starts"][1:]):
        if c:
            ax.axvspan(t0, t1, color="k", alpha=0.15, lw=0)
        ax.text((t0 + t1) / 2, 1.12, f"d={d}", ha="center", fontsize=8)
    ax.set_ylim(0, 1.2)
    ax.set_xlabel("drive periods")
    ax.set_ylabel("amplitude / $u_R$")
    ax.set_title(f"mechanical latch ({res['backend']}): grey = enable pulse ({res['pulse']} periods)")
    ax.legend(fontsize=8, loc="lower right")
    save_figure(fig, path)


def plot_trace(res: dict, path: Path, title: str) -> None:
    """Output-bit amplitudes over the whole clocked run, read points marked (paper Fig. 6b style)."""
    (amp, t), names = _periods(res["waveform"]), res["waveform"]["probes"]
    fig, ax = plt.subplots(figsize=(11, 0.55 * len(names) + 1.5))
    for k, n in enumerate(names):
        off = 1.3 * k
        shade_bands(ax, off)
        ax.plot(t, off + amp[:, k], lw=0.9)
        ax.text(-0.01 * t[-1], off + 0.7, n, ha="right", fontsize=8)
    for r in res["waveform"]["reads"]:
        ax.axvline(r, color="k", lw=0.4, ls=":")
    ax.set_yticks([])
    ax.set_xlabel("drive periods")
    ax.set_title(title)
    save_figure(fig, path)


def _trace_table(runs: dict[str, dict]) -> str:
    names = list(runs)
    physical = [n for n in names if n != "logic"]
    rows = []
    for k in range(len(runs[names[0]]["trace"])):
        cells = [", ".join(f"{p}={v}" for p, v in runs[n]["trace"][k]["outputs"].items()) for n in names]
        rows.append([k, *cells, ", ".join(f"{runs[n]['trace'][k]['min_margin']:+.3f}" for n in physical)])
    return "\n".join(md_table(["cycle", *names, f"min margin ({', '.join(physical)})"], rows))


def write(directory="reports", sqrt_rk4: bool = False, render: bool = False) -> Path:
    """Measure into sequential.json (`sqrt_rk4`: also the ~20-min RK4 square root; `render`: nothing measured) and
    write sequential.md and sqrt.md with their figures from it."""
    d = out_dir(directory)
    if not render:
        from ..studies import sequential as study      # measuring loads the engines; rendering does not
        write_json(d / "sequential.json", study.measure(sqrt_rk4=sqrt_rk4))
    # a latch output that never crossed the mid threshold has a NaN delay, null in the JSON
    res = non_finite(stored(d / "sequential.json", "sequential"), ("output_delays",), math.nan)
    latch, ctr, fsm, sq = res["latch"], res["counter"], res["fsm"], res["sqrt"]
    plot_latch(latch, d / "latch.png")
    plot_trace(fsm["rk4"], d / "fsm.png", "FSM (1101 detector), RK4: output amplitudes; dotted = read points")
    plot_trace(sq["envelope"], d / "sqrt.png", "sqrt(2809), envelope model: |root[i]| over time; dotted = read points")
    counts, machine = res["sqrt_counts"], measured_on(res["conditions"])
    latch_rows = "\n".join(f"| {ph['phase']} | {ph['d']} | {ph['clock']} | {ph['output']:.3f} | {ph['logic']} |"
                           for ph in latch["decoded"])
    fmt_t = lambda t: f"pulse {t['pulse']}, pause {t['pause']} periods (logic depth {t['logic_depth']})"
    fmt_w = lambda runs: ", ".join(f"{b} {r['wall_s']:.1f} s" for b, r in runs.items())
    counts_md = "\n".join(f"| {k} | {counts[k]} | {PAPER_SQRT[k]} |" for k in PAPER_SQRT)
    sq_rk4_md = "" if res["sqrt_rk4"] else ("The oscillator-level RK4 run of the square root is optional "
                                            "(`--sqrt-rk4`, ~15-30 min here) and was not part of this report run.")
    env_desc = (f"envelope model at {res['envelope_step']:g}-period steps (clocked runs end each pause once "
                f"every channel has settled within {res['clocked_settle_tol']} u_R: `fidelity.md`)")
    text = SEQ_MD.replace("{fsm_x}", str(res["fsm_x"])).format(
        env_desc=env_desc, machine=machine, latch_rows=latch_rows, delays=latch["output_delays"],
        env_delays=res["latch_envelope"]["output_delays"], pulse=latch["pulse"],
        short_ok=[ph["logic"] for ph in res["short_pulse"]["decoded"]][6:8],
        ctr_table=_trace_table(ctr), ctr_timing=fmt_t(res["counter_timing"]), ctr_wall=fmt_w(ctr),
        ctr_periods=ctr["rk4"]["periods"], fsm_table=_trace_table(fsm), fsm_wall=fsm["rk4"]["wall_s"],
        fsm_periods=fsm["rk4"]["periods"], sq_table=_trace_table(sq), sq_t=fmt_t(res["sqrt_timing"]),
        sq_wall=fmt_w(sq), sq_periods=sq["envelope"]["periods"])
    (d / "sequential.md").write_text(text)
    (d / "sqrt.md").write_text(SQRT_MD.format(env_desc=env_desc, machine=machine, sq_table=_trace_table(sq),
                                              sq_t=fmt_t(res["sqrt_timing"]), sq_wall=fmt_w(sq),
                                              sq_periods=sq["envelope"]["periods"], counts=counts_md,
                                              sq_latches=res["sqrt_latches"], sq_logic=res["sqrt_logic"],
                                              sq_rk4=sq_rk4_md))
    return d / "sequential.md"


SQRT_MD = """# The square root of 2809 (paper Fig. 6)

Generated by `mech2spice report sequential` on {machine}; {env_desc}, default gate
parameters.

`verilog/sqrt.v`: binary search, 16 lines.

The all-zero state is the start state, so `mech2spice simulate verilog/sqrt.v --set n=2809 --clock clk
--cycles 6 --backend logic` ends with 53; the physical run below resets first (cycle 0), since from
rest latches take their D values (see `sequential.md`, Power-up).

| | ours | paper |
|---|---|---|
{counts}

Ours: {sq_logic} logic gates + {sq_latches} latches x 10 gates (6 result bits and a 3-bit step counter). Timing: {sq_t}; {sq_periods} drive
periods (the paper: ~2e5). Wall time: {sq_wall}. {sq_rk4}

![sqrt](sqrt.png)

{sq_table}

One result bit is decided per cycle, from the top: 32, 48, 48 (bit 3 rejected: 56^2 > 2809), 52,
52 (bit 1 rejected), 53.
"""

SEQ_MD = """# Memory and time: the latch, clocked designs, the FSM and sqrt(2809)

Generated by `mech2spice report sequential`; measured on {machine}. RK4 at 80 steps
per drive period, {env_desc}, default gate parameters (`gate.md`).

## The mechanical latch (paper Fig. 5a, 5b)

Each Yosys flip-flop (`$_DFF_P_`) becomes the paper's symmetric NOR latch followed by a delay line
(`network._add_latch`):

    ne = NOR(EN, 0)   a = NOR(D, ne) = !D.EN   b = NOR(m, EN) = !m.!EN   m = NOR(a, b) = Q
    output = m after 3 identity pairs (x NOR 0) NOR 0

D and the held value Q each reach the loop node m through exactly one gate (the symmetry that avoids
hazards); 10 NOR gates per latch. The clock is an external drive on the `ne` and `b` input pairs.

![latch](latch.png)

Pulse sequence (RK4; `characterise.latch_sequence`), output decoded at the end of each phase. At the
end of a storing pulse the output still shows the old value - by design, it moves only afterwards:

| phase | d | enable | output (u_R) | decoded |
|---|---|---|---|---|
{latch_rows}

Output delay, enable-pulse start to output crossing the mid threshold: {delays} periods (RK4),
{env_delays} (envelope) - well after the {pulse}-period pulse has ended, so a register's output cannot
race through the logic while it is still latching. The two values are storing 1 and storing 0. The paper's latch (13 gates at ~500 periods/gate)
took ~6500 periods; ours has 1 gate to the loop plus 6 delay gates at our measured 126-225
periods/gate. A 300-period pulse does not store a 0 (decoded after it: {short_ok}); 500 periods does,
so the default pulse is 800 (1.6x the shortest that works).

**Power-up.** From rest a latch settles to the value at its D input, not necessarily 0 (measured: with
d = 1 during power-up it holds 1). The logic backend starts registers at 0, so designs reset
synchronously in their first cycle; `simulate --help` says so.

## Clocked designs from Verilog

A cycle is a settle phase with the clock at '0' and then an enable pulse. Pulse and pause are derived
from the measured latch delay (at most 1650 periods), the worst gate delay (225 periods) and the design's
logic depth: pause = (1650 - pulse) + 225 x (depth + 1) + 600, printed by `simulate` and overridable
(`--pulse`, `--pause`). Trace entry k is read at the end of the settle phase after clock edge k.

### Counter with enable and synchronous reset (`verilog/counter4.v`)

Timing: {ctr_timing}; {ctr_periods} drive periods in all. Wall time: {ctr_wall}.

{ctr_table}

### Finite-state machine (paper Fig. 5c; `verilog/fsm.v`)

A one-hot state register of 4 latches and a registered `found` flag detect the input sequence 1,1,0,1
(overlapping). Input x per cycle after reset: {fsm_x}. RK4: {fsm_periods} periods, {fsm_wall:.0f} s.

![fsm](fsm.png)

{fsm_table}

## The square root of 2809

See [sqrt.md](sqrt.md).
"""
