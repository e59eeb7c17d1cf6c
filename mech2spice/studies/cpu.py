"""The 8-bit processor measured into cpu.json (mech2spice/reports/cpu.py renders reports/cpu.md and its figures
from it): the ISA table, the synthesised hardware (counts, gates by block, the behavioural version), the sieve on
the ISS and at logic level, the Turing-machine programs against their reference machines.  One section, `all`
(~2 min; `skip_slow` leaves out the logic-level run of Minsky's machine, ~2.5 min more).
"""
from __future__ import annotations

import collections
import os
import platform
import time
from pathlib import Path

from .. import data
from ..cpu import tm
from ..cpu.asm import assemble_program
from ..cpu.isa import CYCLES, OPCODES, SEMANTICS
from ..cpu.iss import ISS
from ..cpu.machines import LogicCPU
from ..cpu.netlist import CPU_VERILOG, cpu_netlist
from ..cpu.run import load_program, make_memory, run_program
from ..physics import network, params
from ..synthesis.synth import synthesize
from ._common import conditions

SECTIONS = ("all",)

# The same processor written behaviourally, for comparison: what Yosys/ABC alone make of it.
BEHAVIOURAL = """
module cpu(input clk, input rst, input [7:0] rdata, output [7:0] raddr, output [7:0] waddr,
           output [7:0] wdata, output we);
  reg [7:0] pc, a, b, c, d;
  reg ov, ld, nx;
  wire fetch = ~(ld | nx | rst);
  wire [3:0] op = rdata[3:0];
  wire [15:0] is = fetch ? (16'd1 << op) : 16'd0;
  wire [8:0] sum = a + b;
  wire skip = is[12] & (a > b) | is[13] & (a != b) | is[14] & ov;
  assign raddr = ld ? a : pc;
  assign waddr = b;
  assign wdata = a;
  assign we = is[10];
  always @(posedge clk) begin
    ld <= is[11];
    nx <= is[15];
    pc <= rst ? 8'd0 : is[9] ? c : pc + {6'd0, skip, ~(skip | ld)};
    a <= nx ? rdata : is[2] ? b : is[0] ? c : a;
    b <= ld ? rdata : is[2] ? a : is[3] ? d : b;
    c <= is[7] ? ~(a | b) : is[8] ? ~c : (is[0] | is[1]) ? a : c;
    d <= (is[4] | is[5]) ? {is[5] & d[7], d[7:1]} : is[6] ? sum[7:0] : is[3] ? b : d;
    ov <= is[6] ? sum[8] : ov;
  end
endmodule
"""

# Gate nets of verilog/cpu.v by block (prefix before '[' or '.'); ABC's own inverters feed the adder.
BLOCKS = {
    "decoder and selects": "no f0 nf0 f nf g0 g1 ng0 ng1 H nH L nL s_ac s_c s_ab s_bd s_sh s_add s_nor "
                           "s_not s_jmp we next_ld next_nx n_ac n_c n_ab n_bd n_sh n_add n_nor n_not n_jmp "
                           "n_ld n_nx",
    "adder A+B (9-NOR full adders)": "n t u x xo m v w s cy $abc",
    "A>B and A==B": "ngt gq p np r nr eq",
    "skip condition": "nov t_gt t_ne t_ov k1 k2 nin skip",
    "pc + 1 + skip": "np_ pn pk ps ki nki nk",
    "register multiplexers (A, B, C, D, pc, overflow)": "ma1 ma2 ma3 mb1 mb2 mb3 mc1 mc2 mc3 md1 md2 md3 mp "
                                                        "next_a next_b next_c next_d p1 nc nd7 sh7 ot ou next_ov",
    "synchronous reset of pc": "np1 next_pc",
    "read-address multiplexer (pc / A)": "mr raddr",
}


def block_of(net: str) -> str:
    """The block of BLOCKS a gate's Yosys net belongs to ('other' if none)."""
    top = "$abc" if net.startswith("$abc") else net.split("[")[0].split(".")[0]
    for block, names in BLOCKS.items():
        if top in names.split():
            return block
    return "other"


def isa_table() -> list[list]:
    """The instruction set as rows: opcode, mnemonic, operation, cycles (in opcode order)."""
    return [[op, name, SEMANTICS[name], CYCLES[name]] for name, op in sorted(OPCODES.items(), key=lambda kv: kv[1])]


def hardware() -> dict:
    """Synthesize verilog/cpu.v: time, depth, counts with/without fan-out buffers, gates by block, behavioural."""
    t0 = time.perf_counter()
    plain = synthesize(CPU_VERILOG)
    synth_s = time.perf_counter() - t0
    buffered = synthesize(CPU_VERILOG, max_fanout=network.MAX_FANOUT)
    out = {"synth_s": synth_s, "latches": len(plain.latches()), "depth": network.logic_depth(plain)}
    for key, nl in (("plain", plain), ("buffered", buffered)):
        model = network.build(nl, params.DEFAULT)
        out[key] = {"logic": len(nl.gates()), "blocks": len(model.design.gates), **model.counts()}
    out["behavioural"] = behavioural_check()
    g = plain.graph
    out["by_block"] = dict(collections.Counter(block_of(str(g.nodes[n].get("net", "?"))) for n in plain.gates()))
    return out


def behavioural_check() -> dict:
    """Synthesize BEHAVIOURAL and check it against the ISS on the sieve, cycle by cycle (ports)."""
    import tempfile
    from ..backends.logic import ClockedLogic
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "cpu_behavioural.v"
        path.write_text(BEHAVIOURAL)
        nl = synthesize(path)
    prog = load_program(data.program("sieve.asm"))
    iss, mem, cl = ISS(make_memory(prog)), make_memory(prog), ClockedLogic(nl)
    same = True
    while not iss.halted:
        rec = iss.step()
        raddr = cl.evaluate({"rdata": 0})["raddr"]
        outs = cl.evaluate({"rdata": mem.read(raddr)})
        cl.tick({"rdata": mem.read(raddr)})
        mem.commit(outs["waddr"], outs["wdata"], outs["we"])
        same &= (raddr, outs["we"], outs["waddr"], outs["wdata"]) == (rec.raddr, rec.we, rec.waddr, rec.wdata)
    return {"logic": len(nl.gates()), "latches": len(nl.latches()), "sieve_same": same and
            mem.snapshot() == iss.mem.snapshot()}


def sieve_moments(frames) -> list[int]:
    """Four moments of the sieve like the paper's Fig. 8: the last mark of 2's multiples, of 3's, the
    first mark of 5's, and the end (frames: (Cycle, memory before, memory after))."""
    writes = [k for k, (rec, _, _) in enumerate(frames) if rec.we]
    last = {frames[k][0].wdata: k for k in writes}       # last write of each step p (the value written)
    first5 = next(k for k in writes if frames[k][0].wdata == 5)
    return [last[2], last[3], first5, len(frames) - 1]


def moment_frames(frames) -> list[dict]:
    """Fig. 8's four frames as JSON: the cycle's ports and the memory after it."""
    return [{"cycle": rec.cycle, "instr": rec.instr, "phase": rec.phase, "raddr": rec.raddr, "we": rec.we,
             "waddr": rec.waddr, "memory": list(mem)} for rec, _, mem in (frames[k] for k in sieve_moments(frames))]


def sieve_runs() -> dict:
    """The sieve on the ISS frame by frame (Fig. 8's moments, the traffic per cycle) and its ISS and logic runs."""
    prog = load_program(data.program("sieve.asm"))
    frames = []
    iss = ISS(make_memory(prog))
    while not iss.halted:
        mem_before = iss.mem.snapshot()
        rec = iss.step()
        frames.append((rec, mem_before, iss.mem.snapshot()))
    runs = {b: run_program(data.program("sieve.asm"), b) for b in ("iss", "logic")}
    return {"bytes": len(prog.image), "runs": runs, "moments": moment_frames(frames),
            "traffic": [[rec.cycle, rec.raddr, rec.we, rec.waddr] for rec, _, _ in frames],
            "writes": sum(1 for rec, _, _ in frames if rec.we)}


def _tm_row(name: str, machine, net, skip_slow: bool) -> dict:
    """One TM program on the ISS (and at logic level unless skipped) against its reference machine."""
    text = data.program(name).read_text()
    prog = assemble_program(text)
    t0 = time.perf_counter()
    emu = tm.run_emulation(text, 10_000_000)
    iss_s = time.perf_counter() - t0
    ref = tm.compare_emulation(machine, prog.tape.cells, prog.tape.head, emu)
    row = {"bytes": len(prog.image), "cycles": emu["cycles"], "steps": emu["tape"].steps,
           "halted": emu["halted"], "ref_steps": len(ref.steps), "ref_halted": ref.halted,
           "iss_s": iss_s, "tape_in": prog.tape.cells, "tape_out": emu["tape"].digits(),
           "tape_log": [[h, write] for h, _, write, _ in emu["tape"].log]}   # (head, symbol written) per step
    if name == "tm_increment.asm" or not skip_slow:
        t0 = time.perf_counter()
        lemu = tm.run_emulation(text, 10_000_000, lambda mem: LogicCPU(mem, net))
        row["logic_s"] = time.perf_counter() - t0
        tm.compare_emulation(machine, prog.tape.cells, prog.tape.head, lemu)
        row["logic_same"] = lemu["cycles"] == emu["cycles"] and lemu["tape"].log == emu["tape"].log
    return row


def tm_runs(skip_slow: bool) -> dict:
    """The TM programs on the ISS (and logic level) checked against the reference machines; a tag-system run."""
    net = cpu_netlist()
    out = {name: _tm_row(name, machine, net, skip_slow)
           for name, machine in (("tm_increment.asm", tm.INCREMENT), ("tm_minsky.asm", tm.MINSKY))}
    del out["tm_increment.asm"]["tape_log"]            # only Minsky's tape is drawn
    rules, word = [[1, 0, 0], [2], None], [0, 0, 0]
    digits, head, _ = tm.tag_system_tape(rules, word)
    text = tm.emulator_source(tm.MINSKY, digits, head)
    t0 = time.perf_counter()
    emu = tm.run_emulation(text, 10_000_000)
    s = time.perf_counter() - t0
    ref = tm.compare_emulation(tm.MINSKY, digits, head, emu)
    words, _ = tm.utm_words(rules, word, 100_000)
    out["long"] = {"rules": rules, "word": word, "cycles": emu["cycles"], "steps": emu["tape"].steps,
                   "halted": emu["halted"], "ref_halted": ref.halted, "iss_s": s, "words": words,
                   "tag": tm.tag_system_run(rules, word, 50)}
    ex_words, _ = tm.utm_words(**tm.MINSKY_EXAMPLE, max_steps=100_000)
    out["example_words"] = ex_words
    out["example_tag"] = tm.tag_system_run(**tm.MINSKY_EXAMPLE, max_steps=50)
    inc = out["tm_increment.asm"]
    out["increment_example"] = {"tape": tm.INCREMENT_EXAMPLE["tape"],
                                "digits": tm.INCREMENT.encode(tm.INCREMENT_EXAMPLE["tape"]),
                                "out_symbols": "".join(tm.INCREMENT.symbols[int(c)] for c in inc["tape_out"])}
    return out


def measure(section: str = "all", quick: bool = False, skip_slow: bool = False) -> dict:
    """Everything cpu.md states, as JSON (`skip_slow`: no logic-level Minsky run; `quick` is `skip_slow`)."""
    t0 = time.perf_counter()
    res = {"isa": isa_table(), "hardware": hardware(), "sieve": sieve_runs(), "tm": tm_runs(skip_slow or quick)}
    res["wall_s"] = time.perf_counter() - t0
    res["platform"] = f"{platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}"
    res["conditions"] = conditions()
    return res
