"""reports/cpu.md and reports/cpu_*.png: the 8-bit processor, its programs, Turing machines, rendered from
cpu.json (mech2spice/studies/cpu.py measures it).

Run: mech2spice report cpu [--skip-slow] [--render]

Every number in the report is measured by the study on the machine named in the JSON.  --skip-slow leaves out
the logic-level run of Minsky's machine (about 2.5 minutes); --render measures nothing.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib
from matplotlib.patches import Rectangle

from ._common import md_table, out_dir, pyplot, read_json, save_figure, stored, write_json

plt = pyplot()

PAPER = {"gates": 1959, "oscillators": 11754, "linear_springs": 2744, "nonlinear_springs": 9795,
         "dashpots": 2744, "sieve_cycles": 719, "sieve_bytes": 48}

# --------------------------------------------------------------------------- figures

def _grid_xy(addr: int) -> tuple[int, int]:
    return addr % 16, addr // 16               # address 0 bottom-left, along rows, then up


def fig_sieve(moments: list[dict], path, source: str) -> None:
    """The paper's Fig. 8: memory at four moments (each its cycle's ports and the memory after it)."""
    fig, axes = plt.subplots(1, 4, figsize=(14, 5.6))
    norm = matplotlib.colors.PowerNorm(0.3, vmin=0, vmax=255)     # marks are small values (2..5)
    for ax, rec in zip(axes, moments):
        mem = rec["memory"]
        img = [[mem[16 * r + c] for c in range(16)] for r in range(16)]
        ax.imshow(img, origin="lower", cmap="viridis", norm=norm, extent=(0, 16, 0, 16))
        # magnified primality region (addresses 128..159 = n 0..31) above the grid
        for n in range(32):
            x, y = (n % 16), 17.2 + 2 * (n // 16)
            val = mem[128 + n]
            ax.add_patch(Rectangle((x, y), 1, 2, facecolor=plt.cm.viridis(norm(val)), edgecolor="w", lw=0.5))
            ax.text(x + 0.5, y + 1, str(n), ha="center", va="center", fontsize=5.5,
                    color="w" if norm(val) < 0.5 else "k")
        ax.add_patch(Rectangle((0, 8), 16, 2, fill=False, ls=":", ec="w", lw=1.2))
        for addr, color in ((rec["raddr"], "lime"), (rec["waddr"] if rec["we"] else None, "red")):
            if addr is not None:
                x, y = _grid_xy(addr)
                ax.add_patch(Rectangle((x, y), 1, 1, fill=False, ec=color, lw=2))
        ax.set_xlim(0, 16)
        ax.set_ylim(0, 21.4)
        ax.set_xticks([])
        ax.set_yticks([])
        what = f"{rec['instr']}" if rec["instr"] else f"{rec['phase']} data"
        wrote = f", write {rec['waddr']}" if rec["we"] else ""
        ax.set_title(f"cycle {rec['cycle']} ({what})\nread {rec['raddr']}{wrote}", fontsize=9)
    fig.suptitle(f"Sieve of Eratosthenes on {source}: memory (address 0 bottom left, 16 per row); green: read, "
                 "red: write;\ndotted: primality array 128..159, magnified above (label n, non-zero = composite)",
                 fontsize=10)
    fig.tight_layout(rect=(0, 0, 1, 0.9))
    save_figure(fig, path, dpi=130, tight=False)


def plot_traffic(ax, rows, read_label: str) -> None:
    """Memory traffic per cycle, rows of (cycle, raddr, we, waddr): reads green, writes red, over the
    primality array (grey)."""
    rows = list(rows)
    ax.plot([r[0] for r in rows], [r[1] for r in rows], ".", ms=2.5, color="tab:green", label=read_label)
    w = [r for r in rows if r[2]]
    ax.plot([r[0] for r in w], [r[3] for r in w], "s", ms=3.5, color="tab:red", label="write address")
    ax.axhspan(128, 159, color="0.9", zorder=0)
    ax.set_xlabel("clock cycle")
    ax.set_ylabel("address")


def fig_iss_sieve(s: dict, path: Path) -> None:
    """Fig. 8 (memory at four moments) from the ISS's sieve run."""
    fig_sieve(s["moments"], path, "the ISS")


def fig_trace(s: dict, path: Path) -> None:
    """The sieve's memory traffic per cycle on the ISS."""
    fig, ax = plt.subplots(figsize=(10, 3.4))
    plot_traffic(ax, s["traffic"], "read address")
    ax.legend(loc="center right", fontsize=8)
    ax.set_title("Sieve on the ISS: memory traffic per cycle (grey band: primality array)", fontsize=10)
    save_figure(fig, path, dpi=130)


def fig_tm(t: dict, path: Path) -> None:
    """The tape of Minsky's U(7,4) after every 4th step, as an image."""
    row = t["tm_minsky.asm"]
    log = row["tape_log"]                                   # (head, symbol written) per step
    cells = {i: int(c) for i, c in enumerate(row["tape_in"]) if c != "0"}
    lo = min(h for h, *_ in log + [(0,)]) - 1
    hi = max(max(h for h, *_ in log), len(row["tape_in"])) + 1
    rows = []
    for k, (h, write) in enumerate(log):
        cells[h] = write
        if k % 4 == 0:
            rows.append([cells.get(i, 0) for i in range(lo, hi + 1)])
    fig, ax = plt.subplots(figsize=(8, 6))
    ax.imshow(rows, aspect="auto", cmap=matplotlib.colors.ListedColormap(["white", "0.3", "tab:blue", "tab:orange"]),
              interpolation="nearest", extent=(lo - 0.5, hi + 0.5, len(log), 0))
    ax.set_xlabel("tape cell (symbols 0 white, 1 grey, y blue, A orange)")
    ax.set_ylabel("Turing-machine step")
    ax.set_title("Minsky's U(7,4) emulated on the ISS, tape after each step (every 4th shown)", fontsize=10)
    save_figure(fig, path, dpi=130)


# --------------------------------------------------------------------------- report

def write(directory="reports", skip_slow: bool = False, render: bool = False) -> Path:
    """Measure into cpu.json (unless `render`; `skip_slow`: no logic-level Minsky run) and write cpu.md with its
    figures from it."""
    out = out_dir(directory)
    if not render:
        from ..studies import cpu as study            # measuring loads the processor's runners; rendering does not
        write_json(out / "cpu.json", study.measure(skip_slow=skip_slow))
    res = stored(out / "cpu.json", "cpu")
    hw, s, t = res["hardware"], res["sieve"], res["tm"]
    fig_iss_sieve(s, out / "cpu_sieve.png")
    fig_trace(s, out / "cpu_trace.png")
    fig_tm(t, out / "cpu_tm.png")
    L = []
    add = L.append
    add("# The 8-bit mechanical processor, its programs, and Turing completeness\n")
    add(f"Generated by `mech2spice report cpu` in {res['wall_s']:.0f} s on {res['platform']}; every number "
        "below was measured by that run unless it is marked as the paper's.\n")
    add("```sh\nmech2spice cpu asm programs/sieve.asm -o sieve.bin --listing\n"
        "mech2spice cpu run programs/sieve.asm --backend logic          # or iss\n"
        "mech2spice cpu run programs/tm_minsky.asm --checkpoint ck.json  # then --resume continues\n```\n")
    add("## Instruction set\n")
    add("One byte per instruction: the opcode is the low nibble, the high nibble is ignored (the assembler "
        "writes 0). The opcodes are grouped by bits 3..2 so the NOR decoder can share terms. 256 bytes of "
        "memory, 8-bit registers A, B, C, D, pc, an overflow flag.\n")
    add("**A cycle** is one clock period = one memory read. Every instruction takes one cycle, except "
        "LOAD_AB and LDNX_AB, which read a second byte and take two (in the second, the byte read is data, "
        "not an opcode). A SAVE_AB write is committed at the clock edge that ends its cycle. The processor "
        "**halts** when it executes JMP_C with C equal to its own address; that cycle is counted. The ISS "
        "(`mech2spice/cpu/iss.py`) is cycle-exact with `verilog/cpu.v`: the tests step both and compare "
        "every cycle's read address, data, write port and all registers.\n")
    L.extend(md_table(["opcode", "mnemonic", "operation", "cycles"],
                      ([f"0x{op:X}", f"`{name}`", semantics, cycles] for op, name, semantics, cycles in res["isa"])))
    add("")
    add("## Hardware: `verilog/cpu.v`\n")
    add("Paper Fig. 7 architecture: registers (pc, A, B, C, D, overflow, and two phase bits saying that "
        "this cycle's byte is LOAD_AB / LDNX_AB data), a datapath computing every candidate next value, "
        "and per register a chain of 2:1 multiplexers (3 NOR gates per bit) selected by the decoded "
        "opcode. The design is written at the NOR-gate level with `(* keep *)` so Yosys/ABC keep its "
        "structure: the same processor written behaviourally (`BEHAVIOURAL` in `mech2spice/studies/cpu.py`) "
        f"synthesizes to {hw['behavioural']['logic']} logic gates and {hw['behavioural']['latches']} latches, against "
        f"{hw['plain']['logic']} (it runs the sieve with the same port activity every cycle as the ISS: "
        f"{hw['behavioural']['sieve_same']}). Differences from the paper's register list, to "
        "save gates: the write port is wired straight to the registers (waddr = B, wdata = A, we decoded "
        "from the opcode: SAVE_AB writes in its own cycle), and the read address is pc, or A in a LOAD_AB "
        "data cycle, through one multiplexer instead of a read-address register. `rst` (synchronous) "
        "zeroes pc and the phase bits and blocks writes; the logic backend starts with every flip-flop at 0, "
        "the state after `rst`. No tri-states, one clock, positive-edge flip-flops only.\n")
    p_, b_ = hw["plain"], hw["buffered"]
    add(f"Measured with `mech2spice.synthesis.synth.synthesize` (Yosys {hw['synth_s']:.1f} s) and "
        "`network.build(netlist, params.DEFAULT).counts()`; a latch is the paper's NOR latch, 4 gates plus "
        f"a delay line of 6, i.e. 10 gate blocks. Logic depth (longest NOR chain between latches/ports): "
        f"{hw['depth']}.\n")
    add("| | paper | ours, no fan-out limit | ours, fan-out <= 12 (buffered) |\n|---|---|---|---|")
    add(f"| logic NOR gates | | {p_['logic']} | {b_['logic']} |")
    add(f"| latches (flip-flop bits) | | {hw['latches']} | {hw['latches']} |")
    add(f"| NOR gate blocks (logic + 10 per latch) | {PAPER['gates']} | {p_['blocks']} | {b_['blocks']} |")
    for k in ("oscillators", "linear_springs", "nonlinear_springs", "dashpots"):
        add(f"| {k.replace('_', ' ')} | {PAPER[k]} | {p_[k]} | {b_[k]} |")
    add("")
    add("Logic gates by block (no fan-out limit):\n")
    L.extend(md_table(["block", "NOR gates"], sorted(hw["by_block"].items(), key=lambda kv: -kv[1])))
    add("")
    add("## The sieve of Eratosthenes (`programs/sieve.asm`)\n")
    r_iss, r_log = s["runs"]["iss"], s["runs"]["logic"]
    arr = r_iss["memory"][128:160]
    add(f"{s['bytes']} bytes including constants (paper: {PAPER['sieve_bytes']}). It marks the "
        "multiples 2p, 3p, ... of every p = 2..5 (p*p < 32) in the array at 128..159 and halts. Unlike the "
        "paper's program it does not skip p = 4 (already marked): that costs 6 redundant marks. 0 and 1 are "
        "left 0 (never marked). The halt trick: the constant 6 (first p not needed) is also the address of "
        "a JMP_C; when p reaches 6 it is copied into C and the loop's jump lands there, a jump to itself.\n")
    add("| | cycles | halted | wall time |\n|---|---|---|---|")
    add(f"| paper's processor (paper: 50 h 22 min of simulation on a 2015 laptop) | {PAPER['sieve_cycles']} | "
        "yes | |")
    add(f"| ISS | {r_iss['cycles']} | {r_iss['halted']} | {r_iss['wall_s']:.3f} s |")
    add(f"| logic level (synthesized NOR netlist) | {r_log['cycles']} | {r_log['halted']} | "
        f"{r_log['wall_s']:.2f} s |")
    add("")
    add(f"Final memory identical on both: {r_iss['memory'] == r_log['memory']}; registers identical: "
        f"{r_iss['registers'] == r_log['registers']}. Writes: {s['writes']}. Non-zero cells of the array "
        f"(composites): {[n for n in range(32) if arr[n]]}.\n")
    add("![sieve memory](cpu_sieve.png)\n")
    add("![sieve trace](cpu_trace.png)\n")
    physical_section(add, out)
    add("## Turing completeness (Appendix B)\n")
    add("The tape is outside the processor, behind a memory-mapped register at address 255 "
        "(`mech2spice/cpu/tm.py`, `Tape`, mapped into the memory stand-in): reading 255 gives the symbol "
        "under the head; writing it is a command, bits 2..0 the symbol, bit 3 the move (1 right, 0 left), "
        "bit 7 'do nothing' (used for halting entries). The emulator is the appendix's algorithm: the state "
        "p_i is held as a_out + i*n; it reads the symbol j, fetches the output byte at a_out + i*n + j and "
        "writes it to the register, adds a_trans - a_out and fetches the next state at "
        "a_trans + i*n + j. The halting state is the address of the final JMP_C, so halting costs one "
        "compare. 28 cycles per Turing-machine step. `programs/tm_*.asm` are generated from the machine "
        "definitions by `tm.emulator_source` (a test checks they are current).\n")
    add("Each run below is checked step by step against a direct Python simulation (`tm.simulate`): "
        "state, head position, symbol read, symbol written and move at every step.\n")
    add("| program | machine | bytes | TM steps | cycles | halted (CPU / reference) | ISS time | logic-level |")
    add("|---|---|---|---|---|---|---|---|")
    for name, label in (("tm_increment.asm", "binary increment"), ("tm_minsky.asm", "Minsky U(7,4)")):
        row = t[name]
        logic = (f"identical trace, {row['logic_s']:.1f} s" if row.get("logic_same") else
                 ("differs" if "logic_same" in row else "not run (--skip-slow)"))
        add(f"| `{name}` | {label} | {row['bytes']} | {row['steps']} | {row['cycles']} | "
            f"{row['halted']} / {row['ref_halted']} | {row['iss_s']:.2f} s | {logic} |")
    lg = t["long"]
    add(f"| (generated, not checked in) | Minsky U(7,4), tag system {lg['rules']} from {lg['word']} | | "
        f"{lg['steps']} | {lg['cycles']} | {lg['halted']} / {lg['ref_halted']} | {lg['iss_s']:.2f} s | |")
    add("")
    inc, ex = t["tm_increment.asm"], t["increment_example"]
    add(f"Binary increment: tape {ex['digits']} ({ex['tape']}) becomes {inc['tape_out']} ({ex['out_symbols']}).\n")
    add("**Which universal machine, and how its table was checked.** The paper uses Neary and Woods' "
        "U(5,5); no transcription of its table that could be checked was found (the sources searched gave the paper's text without the table), so this uses Minsky's "
        "7-state, 4-symbol machine (M. Minsky, *Computation: Finite and Infinite Machines*, 1967, "
        "Sec. 14.8), transcribed from `pseudo_asm/minsky_utm.s` in the GitHub repository "
        "Ngoguey42/ft_turing, whose header says it was copied from Minsky's text "
        "(cba.mit.edu/events/03.11.ASE/docs/Minsky.pdf). The transcription is checked by what it "
        "computes: it simulates 2-tag systems. With the tape encoding in `tm.tag_system_tape` (letter i = "
        "N_i y's, productions to the left), the words read off the tape each time the machine finishes "
        "appending a production are exactly the tag system's successive words:\n")
    add(f"- worked example of the source (a1 -> a1, a2 -> a2 a3, a3 halts; from a2 a2 a2): UTM words "
        f"{t['example_words']}, tag system {t['example_tag'][1:]}; the machine halts after "
        f"{t['tm_minsky.asm']['steps']} steps, when the halting letter reaches the front.")
    add(f"- {lg['rules']} from {lg['word']}: UTM words {lg['words']}, tag system {lg['tag'][1:]}.\n")
    add("Known limit of this encoding (seen while checking it, not fixed): a tag system that stops because "
        "its word shrinks below two letters is not detected; the machine halts only on the halting letter.\n")
    add("![Minsky tape](cpu_tm.png)\n")
    add("## What is missing\n")
    add("- The sieve does not skip composite p (the paper's does); the paper's Neary-Woods U(5,5) is not "
        "run (see above).")
    add("- The logic-level run of Minsky's machine is in the slow test set "
        "(`tests/test_cpu.py::test_minsky_utm_on_netlist`).")
    (out / "cpu.md").write_text("\n".join(L) + "\n")
    return out / "cpu.md"


def physical_section(add, out: Path) -> None:
    """The sieve at oscillator level, from the last `mech2spice report cpu_physical` run (cpu_physical.json)."""
    r = read_json(out / "cpu_physical.json")
    if r is None:
        add("## The sieve at oscillator level\n\nNot run yet: `mech2spice report cpu_physical`.\n")
        return
    add("## The sieve at oscillator level (envelope)\n")
    add(f"Measured by `{r['command']}` on the {r['machine']} (details, every cycle and what each speed-up "
        f"costs: [cpu_physical.md](cpu_physical.md)). The processor runs as {6486} oscillators at envelope "
        f"fidelity against the behavioural memory, which reads the address from the channels' amplitudes "
        f"and drives the data back as forces.\n")
    add(f"- {'halted' if r['halted'] else 'did not halt'} after **{r['cycles']} cycles** "
        f"(paper: {PAPER['sieve_cycles']}); every cycle identical to the ISS: {r['agree_every_cycle']}; final "
        f"memory equal to the ISS's: {r['final_memory_equals_iss']}; primes left at zero: {r['primes']}.")
    add(f"- wall time **{r['wall_s'] / 60:.1f} min** ({r['s_per_cycle']:.2f} s per cycle"
        f"{', this session of a resumed run' if r.get('resumed') else ''}), against the paper's 50 h 22 min "
        f"for its (larger) processor; {r['periods']:,} drive periods of processor time, "
        f"{r['simulated_periods']:,} of them integrated (step {r['step']:g} periods, settle {r['settle']}).\n")
    add("![sieve memory, physical run](cpu_sieve_physical.png)\n")
    r = read_json(out / "cpu_physical_tm_increment.json")
    if r is not None:
        tape = next(iter(r.get("devices", {}).values()), None)
        add(f"**Binary increment on the oscillators** (`{r['command']}`, "
            f"[cpu_physical_tm_increment.md](cpu_physical_tm_increment.md)): "
            f"{'halted' if r['halted'] else 'did not halt'} after {r['cycles']} cycles"
            + (f", {tape['steps']} Turing-machine steps on the memory-mapped tape" if tape else "")
            + f"; every cycle (ports, registers, memory, tape) identical to the ISS: {r['agree_every_cycle']}; "
              f"wall time {r['wall_s']:.0f} s.\n")
