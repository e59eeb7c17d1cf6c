"""`mech2spice verify`: is the NOR network the same logic as the Verilog, and does the physics compute it?

Two independent checks of one synthesised design:

* equivalence -- the NOR netlist is written back as structural Verilog and proved equal to the source:
  first by Berkeley ABC when it is installed (the miter as AIGER: pdr, or iprove without latches), then by
  Yosys (a miter, SAT with x modelled, memories mapped: an induction step, and a bounded check from the
  all-zero state with the design's resets asserted in the first cycle), within a time budget; a
  counterexample is replayed on Icarus and the logic backend before it is reported.  See docs/verify.md
  for what each engine proves.
* co-simulation -- the source runs on Icarus Verilog (an independent simulator), the network on a
  backend, on the same vectors (clocked: a reset cycle, then random inputs per cycle); every
  differing output bit is listed.
"""
from __future__ import annotations

import contextlib
import os
import re
import secrets
import shutil
import subprocess
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING, Iterator
from xml.sax.saxutils import quoteattr, escape

import numpy as np

from . import identifiers as ids
from .errors import Mech2SpiceError, ToolMissingError
from .synthesis import maps, yosys
from .inputs import read_input
from .synthesis.ports import input_bits, output_bits
from .synthesis.verilog_text import link_readmem_files

if TYPE_CHECKING:
    from .synthesis.synth import Netlist

INDUCTION_STEPS = 20          # sat -tempinduct -maxsteps: base case (BMC) and induction depth
PROOF_BUDGET_S = 120          # default wall-clock budget of the whole proof (--proof-time)
MAX_EXHAUSTIVE_BITS = 20      # --exhaustive refuses wider inputs (2^20 vectors)
ICARUS_TIMEOUT_S = 600        # iverilog's compile; a co-simulation's run is --cosim-time's
COSIM_BUDGET_S = 600          # default wall-clock budget of each Icarus run of the co-simulation (--cosim-time)
RESET_HIGH = ("rst", "reset")
RESET_LOW = ("rst_n", "rstn", "reset_n", "resetn")
RESET_AGAIN = 1 / 16          # after the first cycle a reset port is asserted this often (resets mid-run)
PREFIX = "m2s__"              # internal net names of the written-back network


# --------------------------------------------------------------------------- the network as Verilog

def _expr(netlist: Netlist, node: str, rename: dict[str, str] | None = None) -> str:
    """A netlist node as a Verilog expression: a port bit as the port's (escaped) name, gates and latches
    prefixed (`m2s__g3`; no port may start with the prefix, `check_names`)."""
    if node == "const0":
        return "1'b0"
    if node == "const1":
        return "1'b1"
    attrs = netlist.graph.nodes[node]
    if attrs["kind"] == "input":
        port = attrs["port"]
        return ids.verilog_bit((rename or {}).get(port, port), attrs["bit"], netlist.inputs[port])
    return PREFIX + node


def _decl(width: int) -> str:
    return f"[{width - 1}:0] " if width > 1 else ""


def check_names(netlist: Netlist) -> None:
    """Refuse, before any work, a design whose names the generated Verilog cannot hold: a name that cannot
    be written (ids.verilog), or a port whose name starts with the prefix of the generated ones."""
    for name in [netlist.top, *netlist.inputs, *netlist.outputs, *([netlist.clock] if netlist.clock else [])]:
        ids.verilog(name)
        if name == "#":                         # measured on Icarus 11: `\\# ` alone is not bound ("sorry")
            raise Mech2SpiceError(f"{netlist.top}: a name that is only '#' (written `\\# `) is not bound by "
                                  "Icarus Verilog, which co-simulates the source: rename it")
        if name.startswith(PREFIX):
            raise Mech2SpiceError(f"{netlist.top}: the name {name!r} starts with {PREFIX!r}, which verify "
                                  "keeps for the names it generates: rename it")


def write_verilog(netlist: Netlist, module: str, expose: list[tuple[str, str]] = (),
                  rename: dict[str, str] | None = None) -> str:
    """The netlist as structural Verilog: one `assign` per NOR, one register per latch (initialised
    at its power-up value: 0, or 1 for an inverted latch, as the logic backend starts it).  `expose`: (port name,
    latch) pairs made extra 1-bit outputs, for the register-correspondence proof; `rename`: port -> the name
    it gets (the proof's, `proof_ports`).  Every user name is written by ids.verilog (escaped where it is
    not a plain identifier)."""
    g = netlist.graph
    rename = rename or {}

    def v(name: str) -> str:
        return ids.verilog(rename.get(name, name))
    ports = ([f"input {v(netlist.clock)}"] if netlist.clock else []) \
        + [f"input {_decl(w)}{v(p)}" for p, w in netlist.inputs.items()] \
        + [f"output {_decl(w)}{v(p)}" for p, w in netlist.outputs.items()] \
        + [f"output {name}" for name, _ in expose]
    lines = [f"module {ids.verilog(module)}({', '.join(ports)});"]
    for q in netlist.latches():                 # every power-up written: the proof starts from them
        lines.append(f"  reg {_expr(netlist, q, rename)} = {g.nodes[q].get('inverted', 0)};")
    for gate in netlist.gates():
        a, b = (_expr(netlist, u, rename) for u, _, _ in sorted(g.in_edges(gate, data="pin"), key=lambda e: e[2]))
        lines.append(f"  wire {_expr(netlist, gate, rename)} = ~({a} | {b});")
    lines += [_register(netlist, q, rename) for q in netlist.latches()]
    for out in output_bits(netlist):
        (src,) = g.predecessors(out)
        port, bit = g.nodes[out]["port"], g.nodes[out]["bit"]
        lines.append(f"  assign {ids.verilog_bit(rename.get(port, port), bit, netlist.outputs[port])} = {_expr(netlist, src, rename)};")
    lines += [f"  assign {name} = {_expr(netlist, q, rename)};" for name, q in expose]
    return "\n".join(lines + ["endmodule", ""])


def _register(netlist: Netlist, q: str, rename: dict[str, str] | None = None) -> str:
    """A latch as a register on the source's clock edge: an inverted latch's D pin carries the complement; a forced one is reset
    (or set, when inverted) asynchronously while F is high, as the mechanical latch is."""
    from .synthesis.synth import latch_inputs
    d, f = latch_inputs(netlist.graph, q)
    inverted = netlist.graph.nodes[q].get("inverted", 0)
    reg = _expr(netlist, q, rename)
    nxt = f"~{_expr(netlist, d, rename)}" if inverted else _expr(netlist, d, rename)
    if netlist.sampled:                         # a register of the mechanical clock itself: Yosys's $ff
        return f"  always @($global_clock) {reg} <= {nxt};"
    clock = ids.verilog((rename or {}).get(netlist.clock, netlist.clock))
    edge = netlist.clock_edge
    if f is None:
        return f"  always @({edge} {clock}) {reg} <= {nxt};"
    force = _expr(netlist, f, rename)
    return (f"  always @({edge} {clock} or posedge {force}) if ({force}) {reg} <= "
            f"1'b{inverted}; else {reg} <= {nxt};")


_NET = re.compile(r"(.+?)(?:\[(\d+)\])?")      # a wire (a user's, or Yosys's `$...` that both sides have), its bit


def register_names(netlist: Netlist) -> list[tuple[str, str, str]]:
    """(latch, source wire, bit) for every latch whose Q net kept a user name: the source's register it
    implements (a memory word too: `mem[7][0]` is bit 0 of the word `mem[7]` that the proof's `memory`
    pass makes), to be exposed on both sides of the miter so that induction sees the hidden state.  A name
    a Yosys script cannot hold (ids.yosys) is not matched; nor is any where clocks are sampled (a latch holds
    a register's previous sample there, not the register), nor a level-sensitive latch's `held` (the value at
    the last edge, which no source wire carries)."""
    out = []
    if netlist.sampled:
        return out
    for q in netlist.latches():
        if netlist.graph.nodes[q].get("held"):
            continue
        m = _NET.fullmatch(netlist.graph.nodes[q].get("net", "$"))
        if m and _yosys_writable(m.group(1)):
            out.append((q, m.group(1), m.group(2) or "0"))
    return out


def _yosys_writable(name: str) -> bool:
    try:
        ids.yosys(name)
    except Mech2SpiceError:
        return False
    return True


# --------------------------------------------------------------------------- equivalence (Yosys)

def proof_ports(netlist: Netlist) -> dict[str, str]:
    """Port -> its name inside the proof (`m2s__i0`, `m2s__o0`, `m2s__clk`): Yosys's `sat` parses port names
    as signal expressions, where a name such as `,` or `{a}` is not one; the source keeps its own names
    behind a wrapper (`_wrapper`)."""
    names = {netlist.clock: f"{PREFIX}clk"} if netlist.clock else {}
    names.update({p: f"{PREFIX}i{k}" for k, p in enumerate(netlist.inputs)})
    names.update({p: f"{PREFIX}o{k}" for k, p in enumerate(netlist.outputs)})
    return names


def _wrapper(netlist: Netlist, names: dict[str, str], nregs: int) -> str:
    """Module m2s__gold: the source (renamed m2s__src) behind the proof's port names, its exposed registers
    passed through."""
    widths = {netlist.clock: 1, **netlist.inputs} if netlist.clock else dict(netlist.inputs)
    ports = [f"input {_decl(w)}{names[p]}" for p, w in widths.items()] \
        + [f"output {_decl(w)}{names[p]}" for p, w in netlist.outputs.items()] \
        + [f"output {PREFIX}r{k}" for k in range(nregs)]
    conns = [f".{ids.verilog(p)}({names[p]})" for p in [*widths, *netlist.outputs]] \
        + [f".{PREFIX}r{k}({PREFIX}r{k})" for k in range(nregs)]
    return "\n".join([f"module {PREFIX}gold({', '.join(ports)});",
                      f"  {PREFIX}src {PREFIX}u({', '.join(conns)});", "endmodule", ""])


def _read_command(netlist: Netlist) -> str:
    """Yosys's reading of the source, as synthesis read it (SystemVerilog for a `.v` only that reads)."""
    return "read_verilog -sv" if netlist.systemverilog or Path(netlist.source or "").suffix == ".sv" \
        else "read_verilog"


def _reading(netlist: Netlist, path: Path, tmp: str) -> str:
    """The Yosys command that reads the source (`path`, maybe a rewritten copy) in a script run in `tmp`, as
    synthesis reads it: -defer (each module elaborated once, at its instance's parameters), and -I the
    original's folder, where its `include files are (a copy in a scratch folder has none beside it)."""
    rel = Path(os.path.relpath(Path(path).resolve(), Path(tmp).resolve())).as_posix()
    original = Path(netlist.source).resolve().parent if netlist.source else Path(path).resolve().parent
    folder = Path(os.path.relpath(original, Path(tmp).resolve())).as_posix()
    return f'{_read_command(netlist)} -defer{ids.yosys_include(folder)} {ids.yosys_path(rel, "Verilog file")}'


def _read_source(netlist: Netlist, reading: str) -> list[str]:
    """`reading` (`_reading`), then the source as the proof compares it."""
    # `memory`: the source's memories as flip-flops and multiplexers, as synthesis maps them (sat has no
    # model for $mem cells); its memory_dff folds a read register into the port only as synthesis does.
    # sampled clocks: the source's flip-flops sampled as synthesis samples them, both sides on one global clock
    sample = list(yosys.SAMPLE_CLOCKS) if netlist.sampled else []
    return [reading, _hierarchy(netlist.top), yosys.COMB_AS_STAR, "proc", yosys.DROP_PRINTS,
            "flatten", maps.MAP_POW, "memory", "opt_clean", *sample, f"rename -top {PREFIX}src"]


def _hierarchy(top: str) -> str:
    """Yosys's `hierarchy` selecting the top module: by name, or, for a name a Yosys script cannot hold
    (ids.yosys), by the rule synthesis found it with (-auto-top; a --top is always a plain name)."""
    try:
        return f"hierarchy -check -top {ids.yosys_module(top)}"
    except Mech2SpiceError:
        return "hierarchy -check -auto-top"


def _script(reading: str, netlist: Netlist, regs: list, resets=(), mode: str = "induct",
            steps: int | None = None) -> str:
    """Read source and network, expose the matched registers on both, build the miter and prove it."""
    steps = steps or INDUCTION_STEPS
    lines = _read_source(netlist, reading)
    if regs:
        lines.append(f"cd {PREFIX}src")
        for k, (_, wire, bit) in enumerate(regs):
            lines += [f"add -output {PREFIX}r{k} 1", f"connect -set {PREFIX}r{k} {ids.yosys(wire)}[{bit}]"]
        lines.append("cd ..")
    lines += ["read_verilog wrap.v", "read_verilog gate.v", "proc", "opt_clean",
              f"miter -equiv -flatten -make_assert -ignore_gold_x {PREFIX}gold {PREFIX}gate {PREFIX}miter",
              f"hierarchy -top {PREFIX}miter", "opt_clean"]
    # sat has no model of an asynchronous flip-flop; async2sync gives both sides the cycle view the logic
    # backend and co-simulation read: the output forced while the reset is high, the next state too.  Also
    # where the network has no forced latch: the source's may be one synthesis folded to a constant.
    lines.append("async2sync")
    # Induction even for a combinational network: the source may keep registers that synthesis folded
    # away (`q <= q` is a constant 0), which a plain SAT proof cannot model.  It closes at step 1 otherwise.
    # -enable_undef: without it sat reads the miter's `x` as 0, so -ignore_gold_x's `gold === x` becomes
    # `~gold` and each output check only "gold 1 => gate 1" (a stuck-at-1 output passed).  Inputs and the
    # start state are defined; the induction step's state may hold x (a source register assigned x).
    # The base case applies the resets in its first cycle (-set-at 1, which sat leaves out of the induction
    # step): both sides leave the all-zero start through the state the source's reset defines, whatever
    # encoding synthesis chose for it.  -tempinduct-def: the induction step starts from defined registers
    # (a source register holding x stands for one of its refinements, the one synthesis implements).
    names = proof_ports(netlist)
    at = "".join(f" -set-at 1 in_{names[r['port']]} {r['level']}" for r in resets)
    # The base case is a bounded check (-seq): with -tempinduct-baseonly, sat 0.70 applied -set-at in every
    # cycle, so a reset held forever hid a broken counter (tests/test_verify.py, the broken counter4).
    half = (f"-tempinduct -tempinduct-inductonly -tempinduct-def -maxsteps {steps}" if mode == "induct" else
            f"-seq {steps} {_initial_state(netlist)}{at}")
    lines.append(f"sat -prove-asserts {half} -enable_undef -set-def-inputs -show-inputs {PREFIX}miter")
    return "\n".join(lines + [""])


def _initial_state(netlist: Netlist) -> str:
    """The bounded check's start: every network register at its power-up value (an init attribute, gate.v),
    the source's registers without an initial value undefined (x: any power-up value refines it, as on
    Icarus).  An all-zero source start instead made a register that synthesis fixed at 1 (rom_dds's `done`,
    x in the source until loaded) look like a difference the replay from power-up never showed."""
    return "-set-init-undef"


def equivalence(path, netlist: Netlist, budget_s: float = PROOF_BUDGET_S, resets: list[dict] = (),
                engine: str = "auto") -> dict:
    """Prove the network equal to the source within `budget_s` seconds: {status: proved | counterexample |
    unknown, method, counterexample (input ports per cycle) or None, detail, depth (cycles from the start
    the base case covered; None for ABC's unbounded proof), budget_s, wall_s, equivalence_engine (abc |
    sat: the one that decided, or ran last), engine_note (why ABC did not decide, or None)}.  `engine`:
    auto (ABC first with ABC_SHARE of the budget when it is installed and applies, then sat), abc, sat."""
    t0 = time.time()
    note = None
    if engine in ("auto", "abc") and abc_tool() is None:
        note = "berkeley-abc not found: proved with Yosys sat alone"
    elif engine in ("auto", "abc"):
        res = _abc_prove(Path(path), netlist, budget_s * (1 if engine == "abc" else ABC_SHARE), resets)
        if res["applies"] and res["cex"]:
            res = _replayed(path, netlist, res, resets)
        if res["applies"] and (res["status"] != "unknown" or engine == "abc"):
            return _result(res, _abc_method(netlist, resets, budget_s), budget_s, t0, "abc", None)
        note = res["detail"] if not res.get("replay") else (
            "ABC: a counterexample the replay did not confirm (a value ABC chose for an x of the source, or the "
            "start, made the difference): sat decided")
    out = _sat_equivalence(path, netlist, budget_s - (time.time() - t0), resets, budget_s)
    return {**out, "budget_s": budget_s, "wall_s": time.time() - t0, "equivalence_engine": "sat",
            "engine_note": note}


def _result(res: dict, method: str, budget_s: float, t0: float, engine: str, note) -> dict:
    out = {"status": res["status"], "method": method, "counterexample": res["cex"], "detail": res["detail"],
           "depth": res["depth"], "budget_s": budget_s, "wall_s": time.time() - t0,
           "equivalence_engine": engine, "engine_note": note}
    if "replay" in res:
        out["replay"] = res["replay"]
    return out


def _start_text(netlist: Netlist, resets) -> str:
    reset = ", ".join(f"{r['port']}={r['level']}" for r in resets)
    state = "the power-up state"
    return f"{state}, reset {reset} in cycle 0" if resets else state


def _abc_method(netlist: Netlist, resets, budget_s: float) -> str:
    if netlist.latches():
        return (f"yosys miter as AIGER + ABC scorr, pdr (IC3: every cycle from {_start_text(netlist, resets)}); "
                f"budget {budget_s:.0f} s")
    return f"yosys miter as AIGER + ABC iprove (all input vectors); budget {budget_s:.0f} s"


def _sat_equivalence(path, netlist: Netlist, budget_s: float, resets, shown_s: float) -> dict:
    """The two sat runs (`_prove`) within `budget_s`, the plain miter after an undecided strengthened one: as
    `equivalence`; the texts name `shown_s`, the whole proof's budget (ABC may have used part of it)."""
    t0 = time.time()
    sequential = bool(netlist.latches())
    regs = register_names(netlist) if sequential else []
    res = _prove(Path(path), netlist, regs, budget_s, resets, shown_s)
    if res["cex"]:
        res = _replayed(path, netlist, res, resets)
    left = budget_s - (time.time() - t0)
    if regs and res["status"] not in ("proved", "counterexample") and left > 1:
        # The strengthened miter also compares the matched registers: a failure there may be a wrong match,
        # not a wrong output.  A counterexample its replay confirms stands; otherwise the plain miter decides.
        plain = _prove(Path(path), netlist, [], left, resets, shown_s)
        res = _replayed(path, netlist, plain, resets) if plain["cex"] else plain
    n = len(res["regs"])
    matched = f", {n} matched register{'s' * (n != 1)}" if n else ""
    start = _start_text(netlist, resets)
    method = (f"yosys miter: sat induction step (length <= {INDUCTION_STEPS}{matched}) + bounded check from "
              f"{start} (sat -seq); budget {shown_s:.0f} s" if sequential else
              f"yosys miter + sat (all input vectors: induction step and one-cycle check); budget {shown_s:.0f} s")
    out = {"status": res["status"], "method": method, "counterexample": res["cex"], "detail": res["detail"],
           "depth": res["depth"], "budget_s": budget_s, "wall_s": time.time() - t0}
    if "replay" in res:
        out["replay"] = res["replay"]
    return out


def replay(path, netlist: Netlist, cex: list[dict]) -> dict:
    """Run a counterexample's inputs on the network (logic backend, latches from 0) and on the source (Icarus,
    registers from x, as a simulator starts them), cycle k before clock edge k: {reproduced, cycle (the first
    where a bit the source defines differs, or None), bits (those bits), source, network (every output port
    there, MSB first)}.  Where the source reads x on every differing bit the proof's all-zero start was
    the difference, not the mapping; so too where Icarus started at the network's power-up state
    (`power_up_start`) shows no difference."""
    from .backends.logic import ClockedLogic, evaluate_bits
    from .synthesis.ports import pack_inputs
    order = input_bits(netlist)
    x = np.array([[pack_inputs(netlist, step["inputs"])[b] for b in order] for step in cex], bool)
    clocked = netlist.clocked
    ref = icarus(path, netlist, x, clocked, first_read=True)
    net, sim = [], ClockedLogic(netlist) if clocked else None
    for step in cex:
        net.append(sim.evaluate_bits(step["inputs"]) if clocked else evaluate_bits(netlist, step["inputs"]))
        if clocked:
            sim.tick(step["inputs"])
    first, bits = _first_difference(netlist, ref, net)
    start = power_up_start(netlist) if clocked and first is not None else []
    if start:
        # from the network's power-up state too (a start the source allows): Icarus's `if (x)` at an
        # uninitialised register is no difference of the mapping
        started = icarus(path, netlist, x, clocked, first_read=True, start=start)
        if _first_difference(netlist, started, net)[0] is None:
            ref, (first, bits) = started, (None, [])
    at = first if first is not None else len(cex) - 1
    trace = [{"source": _port_values(netlist, r), "network": _port_values(netlist, g)} for r, g in zip(ref, net)]
    return {"reproduced": first is not None, "cycle": first, "bits": bits, **trace[at], "trace": trace}


def _first_difference(netlist: Netlist, ref: list[dict], net: list[dict]) -> tuple[int | None, list[str]]:
    """The first cycle where a bit the source defines differs from the network, and those bits."""
    for k, (r, g) in enumerate(zip(ref, net)):
        bits = [b for b in output_bits(netlist) if r[b] in "01" and int(r[b]) != g[b]]
        if bits:
            return k, bits
    return None, []


def _port_values(netlist: Netlist, bits: dict) -> dict[str, str]:
    """Output bits (bit name -> '0'/'1'/'x'/'z' or 0/1, None: invalid) as a string per port, MSB first."""
    return {p: "".join("x" if bits.get(f"{p}[{i}]") is None else str(bits[f"{p}[{i}]"]).lower()
                       for i in reversed(range(w))) for p, w in netlist.outputs.items()}


def _replayed(path, netlist: Netlist, res: dict, resets=()) -> dict:
    """A counterexample stands only when its replay shows the source and the network differing: cut to the
    first such cycle; otherwise the status is `unknown`, saying so."""
    rep = replay(path, netlist, res["cex"])
    if rep["reproduced"]:
        cex = res["cex"][:rep["cycle"] + 1]
        cex[-1].update(source=rep["source"], network=rep["network"])
        rep["trace"] = rep["trace"][:len(cex)]
        edges = f" (sequence), read after {len(cex) - 1} clock edges" if "cycle" in cex[0] else ""
        return {**res, "cex": cex, "replay": rep, "depth": len(cex),
                "detail": f"the outputs differ on this input{edges}; replayed: Icarus and the network (logic "
                          f"backend) differ on {', '.join(rep['bits'])}"}
    if not netlist.clocked:             # no start state: the source's own x or z was the difference
        return {**res, "status": "unknown", "replay": rep,
                "detail": f"the proof found inputs on which the outputs differ, but replayed, the source (Icarus) "
                          f"and the network (logic backend) do not differ on any bit the source defines (source "
                          f"{rep['source']}, network {rep['network']}): the source reads x or z where they differ "
                          "(a released tri-state output, an x it assigns), where the network computes a 0 or 1"}
    return {**res, "status": "unknown", "replay": rep,
            "detail": f"the proof found inputs on which the outputs differ from its all-zero start, but replayed "
                      f"from power-up the source (Icarus) and the network (logic backend) do not differ on any "
                      f"bit the source defines (source {rep['source']}, network {rep['network']}): "
                      + _start_hint(netlist, resets)}


def _start_hint(netlist: Netlist, resets) -> str:
    """Why an unconfirmed counterexample differed, and what would fix it: a reset verify did not find, or,
    with none to give, the source's own power-up values (a register it never initialises is x, and synthesis
    may pick any value for it).  With a reset already applied, the source's own x is what is left: one the
    reset does not reach, or one it assigns, which the proof may take as either value (ABC: a free input)."""
    if resets:
        given = ", ".join(f"{r['port']}={r['level']}" for r in resets)
        return (f"the reset ({given}) was applied in cycle 0 of both, so what made the difference is the source's "
                "own x (a register or memory the reset does not reach, or an x it assigns), which the proof starts "
                "at 0 or takes as either value and Icarus reads as x, not the mapping")
    prefix = "the start state, not the mapping, made the difference; "
    if any(w == 1 for w in netlist.inputs.values()):
        return prefix + "give the reset with --reset PORT=LEVEL"
    return prefix + ("the source has no 1-bit input to reset it with: its registers that are never initialised power up "
            "x, and synthesis may choose their value (a register only ever loaded with a constant becomes that "
            "constant); give them power-up values (`reg q = 0;`) to make the start defined")


def _run_yosys(script: str, workdir: str, budget_s: float) -> tuple[yosys.YosysResult, bool]:
    """Run the proof's script with a wall-clock budget: (the run, whether the budget ran out).  Cut short,
    the run keeps the log it wrote so far, which says how deep the proof got."""
    (Path(workdir) / "flow.ys").write_text(script)
    try:
        proc = subprocess.run([*yosys.yosys_command(), "-s", "flow.ys"], cwd=workdir, capture_output=True,
                              text=True, timeout=max(1.0, budget_s))
    except subprocess.TimeoutExpired as cut:
        return yosys.YosysResult(-1, _text(cut.stdout), _text(cut.stderr)), True
    return yosys.YosysResult(proc.returncode, proc.stdout, proc.stderr), False


def _text(out) -> str:
    return out.decode(errors="replace") if isinstance(out, bytes) else (out or "")


def _prove(path: Path, netlist: Netlist, regs: list, budget_s: float = PROOF_BUDGET_S, resets=(),
           shown_s: float | None = None) -> dict:
    """The two halves of the temporal induction as two sat runs: the induction step alone (no start state,
    no reset: the length k at which it closes), then the base case from the start (all-zero, the resets
    asserted in its first cycle) for k cycles, or for INDUCTION_STEPS when the step did not close (a bounded
    search for a counterexample).  Split because sat applies -set-at to the induction step too, where a
    reset would make every step trivially safe."""
    t0 = time.time()
    with tempfile.TemporaryDirectory(prefix="mech2spice_verify_") as tmp:
        maps.write_maps(tmp)
        reading = _reading(netlist, path, tmp)
        expose = [(f"{PREFIX}r{k}", q) for k, (q, _, _) in enumerate(regs)]
        names = proof_ports(netlist)
        (Path(tmp) / "gate.v").write_text(write_verilog(netlist, f"{PREFIX}gate", expose, names))
        (Path(tmp) / "wrap.v").write_text(_wrapper(netlist, names, len(regs)))
        step, cut = _run_yosys(_script(reading, netlist, regs, resets, "induct"), tmp, budget_s)
        closed = not cut and _PROVED.search(step.stdout) is not None
        tried = max(map(int, _TRYING.findall(step.stdout)), default=0)
        if not cut and not closed and not _GAVE_UP.search(step.stdout):
            return {"regs": regs, "depth": 0, **_failed_run(step, bool(regs))}
        left = budget_s - (time.time() - t0)
        steps = tried if closed else INDUCTION_STEPS
        steps = max(steps, 1)
        base, cut = _run_yosys(_script(reading, netlist, regs, resets, "base", steps), tmp, left) \
            if left > 1 else (yosys.YosysResult(-1, "", ""), True)
    depth = steps if _PROVED.search(base.stdout) else 0
    if cut:
        return {"regs": regs, "status": "unknown", "cex": None, "depth": depth, "budget_spent": True,
                "detail": f"the proof's time budget ({shown_s or budget_s:.0f} s) ran out: the bounded check of {steps} cycles from "
                          f"the start was not finished, and the induction " +
                          (f"closed at length {tried} but its base case was not finished" if closed else
                           f"had not closed (tried up to length {tried})")}
    failed = _FAILED.search(base.stdout)
    if failed:
        cex = _counterexample(base.stdout[failed.end():], netlist)
        if cex is not None:
            return {"regs": regs, "depth": depth, "status": "counterexample", "cex": cex,
                    "detail": "the outputs differ on this input" +
                              (f" (sequence), read after {len(cex) - 1} clock edges" if "cycle" in cex[0] else "")}
    if not depth:
        return {"regs": regs, "depth": depth, **_failed_run(base, bool(regs))}
    if closed:
        return {"regs": regs, "depth": depth, "status": "proved", "cex": None,
                "detail": f"no input (sequence) makes an output differ (induction closed at length {tried})"}
    return {"regs": regs, "depth": depth, "status": "unknown", "cex": None,
            "detail": f"no counterexample within {depth} cycles of the start, but the induction did not close "
                      f"within {INDUCTION_STEPS} steps ({time.time() - t0:.0f} s of the proof's "
                      f"{shown_s or budget_s:.0f} s budget used)"}


# sat's lines (Yosys 0.3x-0.70): the step proved, a counterexample, the step giving up, the base case.
_PROVED = re.compile(r"^(?:SAT proof finished - no model found: SUCCESS|Induction step proven: SUCCESS)", re.M)
_FAILED = re.compile(r"^SAT (?:temporal induction )?proof finished - model found(?: for base case)?: FAIL", re.M)
_GAVE_UP = re.compile(r"^Reached maximum number of time steps -> proof failed", re.M)
_TRYING = re.compile(r"^\*\* Trying induction with length (\d+) \*\*", re.M)


def _failed_run(result, strengthened: bool) -> dict:
    """A sat run that ended without a verdict: `unknown` for the strengthened miter (e.g. a register name the
    source does not have: the plain miter decides), else the one-line refusal."""
    if strengthened:
        return {"status": "unknown", "cex": None, "detail": f"yosys: {yosys.error_line(result)}"}
    raise Mech2SpiceError(f"yosys equivalence check failed: {yosys.error_line(result)}")


_ROW = re.compile(r"^\s*(?:(\d+)\s+)?\\in_(\S+)\s+(\S+)\s+(\S+)\s+([01xz]+)\s*$")


def _counterexample(log: str, netlist: Netlist) -> list[dict] | None:
    """The failing inputs from sat's -show-inputs table (the log after the FAIL line): [{"cycle": k, "inputs":
    {port: int}}], cycle 0 the first from the zero state, the outputs differing in the last one (after its
    cycle's predecessors' clock edges, with its inputs applied); a combinational design: one entry."""
    port_of = {v: p for p, v in proof_ports(netlist).items()}
    rows: dict[int, dict] = {}
    for line in log.splitlines():
        m = _ROW.match(line)
        if m and m.group(2) in port_of:
            step = int(m.group(1) or 1)
            value = int(m.group(5).replace("x", "0").replace("z", "0"), 2)
            rows.setdefault(step, {})[port_of[m.group(2)]] = value
    if not rows:
        return None
    out = []
    for step in sorted(rows):
        ins = {p: _signed(netlist, p, rows[step].get(p, 0)) for p in netlist.inputs}
        out.append({"cycle": step - 1, "inputs": ins} if len(rows) > 1 or netlist.latches() else {"inputs": ins})
    return out


def _signed(netlist: Netlist, port: str, value: int) -> int:
    w = netlist.inputs[port]
    return value - (1 << w) if port in netlist.signed and value >> (w - 1) & 1 else value


# --------------------------------------------------------------------------- equivalence (ABC)

ABC_SHARE = 0.75              # of the budget, ABC's first: the sat runs get the rest when ABC is undecided


def abc_tool() -> str | None:
    """Berkeley ABC's executable (Debian's `berkeley-abc`), or None: verify then proves with sat alone."""
    return shutil.which("berkeley-abc")


def _abc_top(netlist: Netlist, names: dict[str, str], resets) -> str:
    """Module m2s__top around the miter: the resets forced to their level in the first cycle (a register
    that powers up 1 and is 0 ever after), every other input free in every cycle."""
    widths = {netlist.clock: 1, **netlist.inputs} if netlist.clock else dict(netlist.inputs)
    level = {r["port"]: r["level"] for r in resets}
    ports = [f"input {_decl(w)}{names[p]}" for p, w in widths.items()] + ["output trigger"]
    lines = [f"module {PREFIX}top({', '.join(ports)});"]
    if level:
        event = "$global_clock" if netlist.sampled else f"{netlist.clock_edge} {names[netlist.clock]}"
        lines += [f"  reg {PREFIX}first = 1'b1;", f"  always @({event}) {PREFIX}first <= 1'b0;"]
    conns = [f".in_{names[p]}({PREFIX}first ? 1'b{level[p]} : {names[p]})" if p in level else
             f".in_{names[p]}({names[p]})" for p in widths]
    lines += [f"  {PREFIX}miter {PREFIX}m({', '.join(conns + ['.trigger(trigger)'])});", "endmodule", ""]
    return "\n".join(lines)


def _aiger_script(reading: str, netlist: Netlist) -> str:
    """The miter of the sat runs as 2-valued AIGER for ABC.  Where sat reads an `x` of the source as "either
    value agrees" (-ignore_gold_x), here every x constant and undriven net of the source is a free input in
    every cycle ($anyseq): the network must agree for every choice, a stronger claim.  Every register without
    a power-up value starts at 0 (the sat runs' all-zero start; with power-up values, where sat starts such a
    source register at x, 0 is one of its refinements).  Asynchronous flip-flops in the cycle view
    (async2sync), as for sat."""
    # Tri-state buses as synthesis resolves them (a write_aiger wire has one driver; conflict checks dropped,
    # as synthesis drops them), before setundef makes "no driver enabled" a free value.
    lines = _read_source(netlist, reading) + [
        "tribuf -formal", "delete n:$tribuf_conflict*", "setundef -undriven -anyseq", "read_verilog wrap.v", "read_verilog gate.v", "read_verilog top.v",
        "proc", "opt_clean", f"miter -equiv -flatten {PREFIX}gold {PREFIX}gate {PREFIX}miter",
        f"hierarchy -top {PREFIX}top", "flatten", "async2sync", "dffunmap", "techmap", "setundef -zero -init",
        "aigmap", "opt_clean", "write_aiger -zinit -map m.map m.aig"]
    return "\n".join(lines + [""])


def _aiger_inputs(mapfile: Path) -> dict[int, tuple[str, int]]:
    """write_aiger's map: AIGER input index -> (port, bit), for the named inputs (the free values that stand
    for the source's x have no name)."""
    out = {}
    for line in mapfile.read_text().splitlines():
        parts = line.split()
        if len(parts) == 4 and parts[0] == "input":
            out[int(parts[1])] = (parts[3], int(parts[2]))
    return out


_ABC_PROVED = re.compile(r"^Property proved\.|^UNSATISFIABLE\b", re.M)          # pdr, iprove
_ABC_FAILED = re.compile(r"was asserted in frame \d+|^SATISFIABLE\b", re.M)
_AIGER_HEADER = re.compile(r"^aig \d+ (\d+) (\d+) ")


def _abc_run(workdir: str, budget_s: float) -> tuple[str, str, tuple[int, int]]:
    """ABC on m.aig: `pdr` (IC3) with a latch, else `iprove` (combinational): (verdict: proved, counterexample
    (in cex.txt) or undecided; ABC's log; the AIGER's (inputs, latches))."""
    with open(Path(workdir) / "m.aig", "rb") as fh:
        head = _AIGER_HEADER.match(fh.readline().decode(errors="replace"))
    size = (int(head.group(1)), int(head.group(2))) if head else (0, 1)
    engine = f"scorr; pdr -T {max(1, int(budget_s))}" if size[1] else "iprove"
    try:
        proc = subprocess.run([abc_tool(), "-c", f"read_aiger m.aig; {engine}; write_cex -a cex.txt"],
                              cwd=workdir, capture_output=True, text=True, timeout=max(1.0, budget_s) + 5)
    except subprocess.TimeoutExpired as cut:
        return "undecided", _text(cut.stdout), size
    log = proc.stdout + proc.stderr
    if _ABC_FAILED.search(log) and (Path(workdir) / "cex.txt").exists():
        return "counterexample", log, size
    return ("proved" if _ABC_PROVED.search(log) else "undecided"), log, size


def _abc_cex(workdir: str, netlist: Netlist, resets, size: tuple[int, int]) -> list[dict] | None:
    """ABC's counterexample (write_cex -a: the latches' start values when there are latches, then a line per
    frame, a 0/1 per AIGER input) as sat's: [{"cycle": k, "inputs": {port: int}}], the resets at their level
    in cycle 0 as the miter forced them; None when the file does not read as one.  The free values standing
    for the source's x are no port: the replay decides whether they made the difference."""
    names = {v: p for p, v in proof_ports(netlist).items()}
    inputs = _aiger_inputs(Path(workdir) / "m.map")
    rows = [ln.split("#")[0].strip() for ln in (Path(workdir) / "cex.txt").read_text().splitlines()]
    rows = [r for r in rows if re.fullmatch(r"[01x]+", r)][1 if size[1] else 0:]
    if not rows or any(len(r) != size[0] for r in rows):
        return None
    level = {r["port"]: r["level"] for r in resets}
    out = []
    for k, frame in enumerate(rows):
        vals = dict.fromkeys(netlist.inputs, 0)
        for i, ch in enumerate(frame):
            port, bit = inputs.get(i, (None, 0))
            if names.get(port) in vals and ch == "1":
                vals[names[port]] |= 1 << bit
        if k == 0:
            vals.update(level)
        ins = {p: _signed(netlist, p, v) for p, v in vals.items()}
        out.append({"cycle": k, "inputs": ins} if netlist.latches() or len(rows) > 1 else {"inputs": ins})
    return out


def _abc_prove(path: Path, netlist: Netlist, budget_s: float, resets=()) -> dict:
    """The miter proved by ABC within `budget_s`: as `_prove`'s result, with `applies` False (and the reason in
    `detail`) when Yosys cannot write it as AIGER (e.g. a level-sensitive latch in the source)."""
    t0 = time.time()
    with tempfile.TemporaryDirectory(prefix="mech2spice_abc_") as tmp:
        maps.write_maps(tmp)
        reading = _reading(netlist, path, tmp)
        names = proof_ports(netlist)
        (Path(tmp) / "gate.v").write_text(write_verilog(netlist, f"{PREFIX}gate", (), names))
        (Path(tmp) / "wrap.v").write_text(_wrapper(netlist, names, 0))
        (Path(tmp) / "top.v").write_text(_abc_top(netlist, names, resets))
        built, cut = _run_yosys(_aiger_script(reading, netlist), tmp, budget_s)
        if cut or built.returncode != 0 or not (Path(tmp) / "m.aig").exists():
            why = "the budget ran out writing the miter" if cut else f"yosys: {yosys.error_line(built)}"
            return {"applies": False, "detail": f"ABC not used: {why}"}
        verdict, log, size = _abc_run(tmp, budget_s - (time.time() - t0))
        cex = _abc_cex(tmp, netlist, resets, size) if verdict == "counterexample" else None
    base = {"applies": True, "regs": [], "cex": cex}
    if verdict == "proved":
        return {**base, "status": "proved", "depth": None,
                "detail": "no input (sequence) makes an output differ (ABC " +
                          ("pdr: an inductive invariant)" if size[1] else "iprove)")}
    if cex:
        return {**base, "status": "counterexample", "depth": len(cex),
                "detail": "the outputs differ on this input" +
                          (f" (sequence), read after {len(cex) - 1} clock edges" if "cycle" in cex[0] else "")}
    frames = re.findall(r"frame (\d+)", log)
    return {**base, "status": "unknown", "depth": 0,
            "detail": f"ABC undecided within {budget_s:.0f} s" + (f" (pdr reached frame {frames[-1]})" if frames else "")}


# --------------------------------------------------------------------------- Icarus Verilog

def _icarus_tools() -> tuple[str, str]:
    iverilog, vvp = shutil.which("iverilog"), shutil.which("vvp")
    if not (iverilog and vvp):
        raise ToolMissingError("Icarus Verilog not found (iverilog, vvp): install it, e.g. `apt install iverilog`")
    return iverilog, vvp


# Between a testbench event and the next (ns): a source's own delays shorter than this settle before a read.
SETTLE_NS = 1000


def _testbench(netlist: Netlist, n: int, clocked: bool, first_read: bool = False, tag: str = f"{PREFIX}row",
               start: list[str] = ()) -> str:
    """Apply vectors.txt (one line of input bits per vector / cycle, ports in declaration order with the
    first port leftmost) and $display the outputs.  Clocked: the inputs of cycle k are on before edge k;
    a while after it cycle k+1's are applied, and a while after that the outputs read, as
    simulation.run_clocked_logic.  "A while" is `SETTLE_NS`: delays the source writes (`q <= #1 d`, which
    synthesis ignores) have run out by then; compiled after this file, a source without `timescale reads its
    delays in its nanoseconds.
    `first_read`: also read once before the first edge (a counterexample's replay: its cycle 0).  Each result
    line starts with `tag` (a fresh random word per run), so a line the design itself prints (`$display`,
    kept on Icarus) is never read as a result.  `start`: statements run at time 0 (`power_up_start`'s).
    Every user name is written by ids.verilog; the testbench's own names carry the prefix no port has.
    Sampled clocks (`Netlist.sampled`): the testbench has no clock of its own.  Every input goes to 0 (where
    the network's samples power up) after time 0, the clocks first (#1) and the rest later (#3): in
    Verilog-2005 an input's first value is an edge (x -> 0 is a falling one), which at time 0 races the source's
    own processes starting.  The starts (`start`: `restart`'s and the power-up start's) come between (#2):
    after the clocks' first edge, before the data's first values, so an asynchronous reset held from the start
    acts after them, as in the network.  Then each cycle's clocks are applied first, the rest a
    while later: a flip-flop takes the data of the cycle before its edge, as the sampled network does."""
    v = ids.verilog
    ins, outs = [v(p) for p in netlist.inputs], [v(p) for p in netlist.outputs]
    width = max(1, sum(netlist.inputs.values()))
    mem, k = f"{PREFIX}mem", f"{PREFIX}k"
    lines = ["`timescale 1ns/1ns", f"module {PREFIX}tb;"]
    wait = f"#{SETTLE_NS}"
    lines += [f"  reg {_decl(w)}{v(p)};" for p, w in netlist.inputs.items()]
    lines += [f"  wire {_decl(w)}{v(p)};" for p, w in netlist.outputs.items()]
    conns = [f".{p}({p})" for p in ins + outs]
    clock = v(netlist.clock) if netlist.clock else None
    idle, edge = ("1", "0") if netlist.clock_edge == "negedge" else ("0", "1")    # the capturing edge: idle -> edge
    if clock:
        lines.append(f"  reg {clock} = {idle};")
        conns.insert(0, f".{clock}({clock})")
    lines += [f"  {v(netlist.top)} {PREFIX}dut({', '.join(conns)});",
              f"  reg [{width - 1}:0] {mem} [0:{n - 1}];", f"  integer {k};"]
    def apply(index: str) -> str:                  # a function, not `%`: a name may hold a `%`
        if netlist.sampled:
            return _apply_sampled(netlist, f"{mem}[{index}]", wait)
        return f"{{{', '.join(ins)}}} = {mem}[{index}];" if ins else ";"
    # flushed: a run cut at its budget (`_run_cut`) leaves every row it printed
    show = f'$display("{tag} ' + " ".join(["%b"] * len(outs)) + '", ' + ", ".join(outs) + "); $fflush;"
    if start:
        after = ["    #2;"] if netlist.sampled else []        # sampled: after the clocks' first values
        lines += ["  initial begin"] + after + [f"    {st}" for st in start] + ["  end"]
    lines += ["  initial begin", f'    $readmemb("vectors.txt", {mem});']
    if netlist.sampled:
        lines.append("    " + _apply_sampled(netlist, None, "#2", first="#1"))
    if clocked:
        lines += [f"    {wait} {apply('0')}" if netlist.sampled else f"    {apply('0')}"]
        lines += ([f"    {wait} {show}"] if first_read else []) + [
                  f"    for ({k} = 0; {k} < {n}; {k} = {k} + 1) begin"]
        lines += [] if netlist.sampled else [f"      {wait} {clock} = {edge};"]
        lines += [f"      {wait} {apply(f'{k} + 1 < {n} ? {k} + 1 : {k}')}", f"      {wait} {show}"]
        lines += ["    end"] if netlist.sampled else [f"      {wait} {clock} = {idle};", "    end"]
    else:
        lines += [f"    for ({k} = 0; {k} < {n}; {k} = {k} + 1) begin",
                  f"      {apply(k)}", f"      {wait} {show}", "    end"]
    return "\n".join(lines + ["    $finish;", "  end", "endmodule", ""])


def _apply_sampled(netlist: Netlist, row: str | None, wait: str, first: str = "") -> str:
    """One cycle's inputs where clocks are sampled: the clock ports, then a while later the others (each
    port its slice of the row, first port leftmost; every port 0 where `row` is None); `first`: a delay
    before it all."""
    v, top, later = ids.verilog, sum(netlist.inputs.values()), []
    clocks = [first] if first else []
    for p, w in netlist.inputs.items():
        value = "0" if row is None else f"{row}[{top - 1}:{top - w}]"
        (clocks if p in netlist.sampled else later).append(f"{v(p)} = {value};")
        top -= w
    return " ".join(clocks + [wait] + later) if later else " ".join(clocks)


COERCED = re.compile(r"output port (\S+) is coerced to inout")   # iverilog: the source never drives it

# A generate scope in a register's flattened name (`g[0].r`), or a memory word (`mem[5]`): written as it is.
_SCOPE = re.compile(r"[A-Za-z_][A-Za-z0-9_$]*(?:\[\d+\])?")


def power_up_start(netlist: Netlist) -> list[list[str]]:
    """Where the network starts the source's registers that have no power-up value (synthesis's `registers`
    on each latch): one entry per register bit, the testbench statements that may write it (the register's
    hierarchical name read with generate scopes, then as one escaped name: Yosys joins both with a dot),
    each setting it to the latch's power-up, as the logic backend starts it, or the constant synthesis
    made of the bit (`Netlist.constant_registers`).  A name Verilog cannot hold is left out."""
    powered = {(path, index) for path, index, _ in netlist.initial_registers}    # restart's, not these
    start = [(path, index, netlist.graph.nodes[q].get("inverted", 0))
             for q in netlist.latches() for path, index in netlist.graph.nodes[q].get("registers", ())
             if (path, index) not in powered]
    return _start_entries(start + list(netlist.constant_registers), only_x=True)


def restart(netlist: Netlist) -> list[list[str]]:
    """A sampled design's registers that have a power-up value, put back to it after the testbench's first
    clock values: in Verilog-2005 a clock's first value is an edge (x -> 0 falls), and a flip-flop on it takes
    data that is still x there, where the network's samples power up at 0 and see no edge."""
    return _start_entries(netlist.initial_registers) if netlist.sampled else []


def _start_entries(rows, only_x: bool = False) -> list[list[str]]:
    """Per (path, index, value): the testbench statements that may set that register bit (`_reg_names`);
    `only_x`: each sets the bit only where Icarus holds it at x, so a value the source gives that synthesis
    did not see (an `initial` in a `translate_off` region) is kept, and its difference from the network shows."""
    out = []
    for path, index, value in rows:
        ways = _reg_names(path)
        if ways:
            bit = "" if index is None else f"[{int(index)}]"
            names = [f"{PREFIX}dut.{w}{bit}" for w in ways]
            out.append([f"if ({r} === 1'bx) {r} = 1'b{int(value)};" if only_x else f"{r} = 1'b{int(value)};"
                        for r in names])
    return out


def _reg_names(path) -> list[str]:
    """A register's hierarchical name below the testbench's instance, in the ways it may be written."""
    try:
        instances = [ids.verilog(p) for p in path[:-1]]
        parts = path[-1].split(".")
        scoped = ".".join(parts) if all(
            _SCOPE.fullmatch(x) and x.split("[")[0] not in ids.VERILOG_KEYWORDS for x in parts) else None
        whole = ids.verilog(path[-1])
    except Mech2SpiceError:
        return []
    return [".".join(instances + [w]) for w in dict.fromkeys(([scoped] if scoped else []) + [whole])]


def icarus(path, netlist: Netlist, vectors: np.ndarray, clocked: bool, warnings: list | None = None,
           info: dict | None = None, first_read: bool = False, start=None,
           budget_s: float | None = None) -> list[dict[str, str]]:
    """Run the source on Icarus: per vector (or cycle), output bit -> '0', '1', 'x' or 'z'.  `budget_s`: the
    run's wall-clock budget; where it runs out, the vectors (cycles) read so far, and `info["cut"]` says so
    (at least one, else an error); None: every vector, or an error after ICARUS_TIMEOUT_S.  `warnings`, if
    given, receives iverilog's lines on output ports it coerced to inout: ports the source never drives
    (an `assign internal = port` written backwards), which read z on Icarus while Yosys joins the two nets;
    `info`, if given, the generation iverilog compiled with (`generations`) and, with `start`
    (`power_up_start`'s entries), how many register bits were started and how many Icarus could not find."""
    iverilog, vvp = _icarus_tools()
    path = Path(path).resolve()
    order = input_bits(netlist)
    with tempfile.TemporaryDirectory(prefix="mech2spice_icarus_") as tmp:
        tb = Path(tmp) / "tb.v"
        tag = f"{PREFIX}{secrets.token_hex(8)}"
        tb.write_text(_testbench(netlist, len(vectors), clocked, first_read, tag))
        (Path(tmp) / "vectors.txt").write_text("".join(_vector_line(netlist, order, v) for v in vectors))
        link_readmem_files(read_input(path, "Verilog file").decode("utf-8", "replace"), path.parent, tmp)
        built, gen = _compile(iverilog, path, tmp)
        entries = restart(netlist) + list(start or [])
        if entries:
            ways = _bind_start(iverilog, gen, path, tmp, entries,
                               lambda st: _testbench(netlist, len(vectors), clocked, first_read, tag, st))
            if info is not None and start:
                bound = sum(any(w in ways for w in entry) for entry in start)
                info["started"] = {"register_bits": bound, "not_found": len(start) - bound}
        if budget_s is None:
            out, cut = _run_tool([vvp, "-n", "sim.vvp"], tmp, "vvp").stdout, False
        else:
            out, cut = _run_cut([vvp, "-n", "sim.vvp"], tmp, budget_s)
    if info is not None:
        info["icarus_generation"] = gen
    if warnings is not None:
        warnings += sorted({f"output port {m.group(1)} is coerced to inout (iverilog): the source never drives it"
                            for m in COERCED.finditer(built.stderr)})
    # after the tag: a source's `$write` without a newline puts its text before it on the same line
    rows = [ln[ln.index(tag) + len(tag):].split() for ln in out.splitlines() if tag in ln]
    rows = [r for r in rows if len(r) == len(netlist.outputs) and all(re.fullmatch(r"[01xzXZ]+", s) for s in r)]
    if cut:
        if not rows:
            raise Mech2SpiceError(f"Icarus read no {'cycle' if clocked else 'vector'} of the co-simulation within "
                                  f"its budget ({budget_s:g} s, --cosim-time)")
        if info is not None:
            info["cut"] = {"read": len(rows), "of": len(vectors), "budget_s": budget_s}
    elif len(rows) != len(vectors) + (first_read and clocked):
        raise Mech2SpiceError(f"Icarus printed {len(rows)} result lines for {len(vectors)} vectors")
    return [_bits_of(netlist, r) for r in rows]


def _run_cut(cmd: list[str], cwd: str, budget_s: float) -> tuple[str, bool]:
    """A simulation's stdout, and whether its budget ran out first: then what it printed in whole lines so far
    (the testbench flushes each row).  A failure is an error, as `_run_tool`'s."""
    try:
        proc = subprocess.run(cmd, cwd=cwd, capture_output=True, timeout=budget_s)
    except subprocess.TimeoutExpired as e:
        printed = (e.stdout or b"").decode("utf-8", "replace")
        return printed[:printed.rfind("\n") + 1], True
    text = proc.stdout.decode("utf-8", "replace")
    if proc.returncode != 0:
        raise Mech2SpiceError(f"vvp failed on the source design: "
                              f"{_first_error(proc.stderr.decode('utf-8', 'replace') + text)}")
    return text, False


def generations(path: Path) -> tuple[str, ...]:
    """The language generations iverilog tries on a source, in order: SystemVerilog for `.sv`; Verilog-2005
    for `.v` (where `logic` or `bit` may still be a name), then SystemVerilog (`.v` files written with SV
    constructs, e.g. `[size]` dimensions or `always_ff`)."""
    return ("-g2012",) if path.suffix == ".sv" else ("-g2005", "-g2012")


def _compile(iverilog: str, path: Path, tmp: str) -> tuple[subprocess.CompletedProcess, str]:
    """Compile source + tb.v into sim.vvp with the first generation that takes the source (the run, the
    generation); a source no generation compiles is refused with the first one's error."""
    first = None
    for gen in generations(path):
        # tb.v first: its `timescale carries on to a source without one (else Icarus reads that source's `#1`
        # as 1 s, and every output is still x at each read)
        cmd = [iverilog, gen, "-o", "sim.vvp", "-s", f"{PREFIX}tb", "-I", str(path.parent), "tb.v", str(path)]
        try:
            return _run_tool(cmd, tmp, f"iverilog {gen}"), gen
        except Mech2SpiceError as err:
            first = first or err
    raise first


_TB_ERROR = re.compile(r"^tb\.v:(\d+): error", re.M)


def _bind_start(iverilog: str, gen: str, path: Path, tmp: str, start, bench) -> list[str]:
    """Compile the testbench with `start`'s statements (`bench`: statements -> testbench text) into sim.vvp,
    each register written the first way Icarus finds it by (`power_up_start`); one Icarus cannot find in any
    way is left out.  The statements kept; none when the testbench still fails (sim.vvp is then rebuilt
    without them)."""
    choice = [0] * len(start)
    for _ in range(3):
        live = [k for k, c in enumerate(choice) if c < len(start[k])]
        stmts = [start[k][choice[k]] for k in live]
        text = bench(stmts)
        Path(tmp, "tb.v").write_text(text)
        cmd = [iverilog, gen, "-o", "sim.vvp", "-s", f"{PREFIX}tb", "-I", str(path.parent), "tb.v", str(path)]
        try:
            proc = subprocess.run(cmd, cwd=tmp, capture_output=True, text=True, timeout=ICARUS_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            break
        if proc.returncode == 0:
            return stmts
        first = text.splitlines().index(f"    {stmts[0]}") + 1 if stmts else 0     # tb.v's line of stmts[0]
        bad = {int(m.group(1)) - first for m in _TB_ERROR.finditer(proc.stderr + proc.stdout)}
        if not bad or not bad <= set(range(len(stmts))):
            break
        for row in bad:
            choice[live[row]] += 1
    Path(tmp, "tb.v").write_text(bench([]))
    _compile(iverilog, path, tmp)
    return []


def _vector_line(netlist: Netlist, order: list[str], v) -> str:
    """One vector as the bits of {port0, port1, ...}: port0's MSB first."""
    bits = dict(zip(order, v))
    line = "".join(str(int(bits[f"{p}[{i}]"])) for p, w in netlist.inputs.items() for i in reversed(range(w)))
    return (line or "0") + "\n"


def _bits_of(netlist: Netlist, row: list[str]) -> dict[str, str]:
    out = {}
    for (port, width), text in zip(netlist.outputs.items(), row):
        text = text.lower().rjust(width, "0")[-width:]
        out.update({f"{port}[{i}]": text[width - 1 - i] for i in range(width)})
    return out


def _run_tool(cmd: list[str], cwd: str, name: str) -> subprocess.CompletedProcess:
    try:
        proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=ICARUS_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        raise Mech2SpiceError(f"{name} did not finish within {ICARUS_TIMEOUT_S} s") from None
    if proc.returncode != 0:
        line = _first_error(proc.stderr + proc.stdout)
        if re.search(r"\bassert(ion)?\b.*\.cc:\d+|\.cc:\d+.*\bassert", line):   # pConst's fifo (public RTL pass 10)
            line += (" (an internal check of Icarus failing: a defect of Icarus, not a refusal of the source; "
                     "synth and simulate do not run Icarus)")
        raise Mech2SpiceError(f"{name} failed on the source design: {line}")
    return proc


def _first_error(log: str) -> str:
    """The line that says why a tool stopped: its first `error` line, else its first line (Icarus writes
    `sorry:` notices and warnings before the error that stops it, public RTL pass 10)."""
    lines = [ln.strip() for ln in log.splitlines() if ln.strip()]
    return next((ln for ln in lines if re.search(r"\berror\b", ln, re.I)), lines[0] if lines else "")


# --------------------------------------------------------------------------- vectors

def reset_ports(netlist: Netlist, given=None, path=None) -> list[dict]:
    """The resets verify asserts in cycle 0 (and now and then later): [{port, level, rule}], `rule` saying
    what chose it.  `given` (--reset, repeatable): 'PORT' or 'PORT=LEVEL' each, or ['none'].  Else, in
    order: the design's own flip-flops (Yosys's `$sdff*`/`$adff*` cells after `proc; opt_dff` name the
    input and its polarity: rule "design"), then the port's name as a last resort (rst/reset active high,
    rst_n/rstn/reset_n/resetn active low: rule "name")."""
    if isinstance(given, str):
        given = [given]
    if given:
        if list(given) == ["none"]:
            return []
        resets = [_given_reset(netlist, spec) for spec in given]
        ports = [r["port"] for r in resets]
        twice = next((p for p in ports if ports.count(p) > 1), None)
        if twice is not None:               # two levels for one port: a start state that cannot happen
            raise Mech2SpiceError(f"--reset {twice} is given twice: give each reset port once")
        return resets
    if path is not None:
        found = design_resets(path, netlist)
        if found:
            return found
    for port, w in netlist.inputs.items():
        if w == 1 and port.lower() in RESET_HIGH + RESET_LOW:
            return [{"port": port, "level": 0 if port.lower() in RESET_LOW else 1, "rule": "name"}]
    return []


def _given_reset(netlist: Netlist, spec: str) -> dict:
    name, sep, level = spec.partition("=")
    if sep and not level:               # `rst=` was read as `rst`, its level from the name
        raise Mech2SpiceError(f"--reset {spec}: nothing after '=': give the level, 0 or 1 (or the port alone)")
    if netlist.inputs.get(name) != 1 or name == netlist.clock:
        raise Mech2SpiceError(f"--reset {spec}: {netlist.top} has no 1-bit input '{name}' "
                              f"(inputs: {', '.join(netlist.inputs) or 'none'})")
    if level not in ("", "0", "1"):
        raise Mech2SpiceError(f"--reset {spec}: the level is 0 or 1 (PORT=0: active low)")
    if level == "":
        return {"port": name, "level": 0 if name.lower() in RESET_LOW else 1, "rule": "given (level from the name)"}
    return {"port": name, "level": int(level), "rule": "given"}


_RESET_CELL = re.compile(r"\$(?:_?)(s|a)dff")       # $sdff, $sdffe, $sdffce, $adff, $adffe (word-level cells)


def design_resets(path, netlist: Netlist) -> list[dict]:
    """The inputs the source's flip-flops reset on, with the level that resets them, from Yosys's cells after
    `proc; opt_dff` (`$sdff*`: SRST and SRST_POLARITY; `$adff*`: ARST and ARST_POLARITY); [] when none is
    an input port of the top or the run fails (the name rule then decides)."""
    import json as _json
    path = Path(path)
    with tempfile.TemporaryDirectory(prefix="mech2spice_resets_") as tmp:
        script = "\n".join([_reading(netlist, path, tmp), _hierarchy(netlist.top), yosys.COMB_AS_STAR, "proc", "flatten", "opt_dff", f"rename -top {PREFIX}src",
                            "write_json resets.json", ""])
        result, cut = _run_yosys(script, tmp, 60)
        if cut or result.returncode != 0:
            return []
        module = _json.loads((Path(tmp) / "resets.json").read_text())["modules"].get(f"{PREFIX}src")
    if module is None:
        return []
    port_of = {p["bits"][0]: name for name, p in module["ports"].items()
               if p["direction"] == "input" and len(p["bits"]) == 1}
    found = {}
    for cell in module["cells"].values():
        m = _RESET_CELL.match(cell["type"])
        if not m:
            continue
        pin = "SRST" if m.group(1) == "s" else "ARST"
        port = port_of.get((cell["connections"].get(pin) or [None])[0])
        if port is not None and port != netlist.clock:
            polarity = int(str(cell["parameters"].get(f"{pin}_POLARITY", "1")), 2) & 1
            found.setdefault(port, {"port": port, "level": polarity,
                                    "rule": f"design ({'synchronous' if pin == 'SRST' else 'asynchronous'} "
                                            f"reset of the source's flip-flops)"})
    return [found[p] for p in netlist.inputs if p in found]


def reset_notes(given: list[dict], found: list[dict]) -> list[str]:
    """Where the resets a user stated contradict the source's own flip-flops (`design_resets`): a level that
    does not reset them, or a reset port of theirs left out.  The run goes ahead as stated (the user may mean
    it); the notes say what cycle 0 then does."""
    level = {r["port"]: r["level"] for r in given}
    notes = []
    for r in found:
        kind = "asynchronously" if "asynchronous" in r["rule"] else "synchronously"
        if r["port"] not in level:
            notes.append(f"the source's flip-flops reset {kind} on {r['port']}={r['level']}, which --reset leaves "
                         f"out: {r['port']} is random from cycle 0, so they start where the network powers up")
        elif level[r["port"]] != r["level"]:
            notes.append(f"--reset {r['port']}={level[r['port']]}, but the source's flip-flops reset {kind} on "
                         f"{r['port']}={r['level']}: cycle 0 holds them out of reset")
    return notes


def make_vectors(netlist: Netlist, n: int | None, exhaustive: bool, seed: int) -> tuple[np.ndarray, bool]:
    """(B, input bits) bool: every vector when asked or when there are no more than n, else n random ones."""
    nbits = len(input_bits(netlist))
    if exhaustive and nbits > MAX_EXHAUSTIVE_BITS:
        raise Mech2SpiceError(f"--exhaustive: {netlist.top} has {nbits} input bits ({2 ** nbits:,} vectors); "
                              f"at most {MAX_EXHAUSTIVE_BITS} bits: give --vectors N instead")
    if exhaustive or (nbits <= MAX_EXHAUSTIVE_BITS and 2 ** nbits <= n):
        k = np.arange(2 ** nbits)
        return ((k[:, None] >> np.arange(nbits)) & 1).astype(bool), True
    return np.random.default_rng(seed).integers(0, 2, (n, nbits)).astype(bool), False


def make_cycles(netlist: Netlist, n: int, seed: int, resets) -> np.ndarray:
    """(n, input bits) bool: random inputs per cycle; the resets (`reset_ports`' dicts, or one (port, level)
    pair) asserted together in cycle 0 (cycles 0-2 where clocks are sampled), and now and then later."""
    order = input_bits(netlist)
    rng = np.random.default_rng(seed)
    x = rng.integers(0, 2, (n, len(order))).astype(bool)
    if isinstance(resets, tuple):
        resets = [{"port": resets[0], "level": resets[1]}]
    again = rng.random(n) < RESET_AGAIN
    # sampled clocks: 0, 1, 0 first, so that no edge falls in cycle 0 (where a flip-flop's previous data
    # sample is its power-up, not its data) and each edge of each clock sees the resets asserted
    first = min(n, 3) if netlist.sampled else 1
    for p in netlist.sampled:
        for i in range(netlist.inputs[p]):
            x[:first, order.index(f"{p}[{i}]")] = [False, True, False][:first]
    for r in resets or []:
        j, level = order.index(f"{r['port']}[0]"), r["level"]
        x[:, j] = np.where(again, level, 1 - level).astype(bool)
        x[:first, j] = bool(level)
    _hold_clocks_at_releases(netlist, x, order, resets or [])
    return x


def _hold_clocks_at_releases(netlist: Netlist, x: np.ndarray, order: list[str], resets) -> None:
    """Where a reset is itself a sampled clock it changes in the clocks' instant, so its release could fall in
    the instant of another clock's edge: an edge inside the reset's recovery time, which the source leaves
    undefined (Icarus runs the flip-flop once both changed and takes D; Yosys's clk2fflogic, and so the
    network, keeps the reset value).  The other clocks hold their value in each such cycle: no edge there."""
    for r in resets:
        if r["port"] not in netlist.sampled:
            continue
        j = order.index(f"{r['port']}[0]")
        released = np.flatnonzero((x[:-1, j] == bool(r["level"])) & (x[1:, j] != bool(r["level"]))) + 1
        others = [order.index(f"{p}[{i}]") for p in netlist.sampled if p != r["port"]
                  for i in range(netlist.inputs[p])]
        for c in others:
            x[released, c] = x[released - 1, c]


def _as_ports(netlist: Netlist, v) -> dict[str, int]:
    bits = dict(zip(input_bits(netlist), (int(b) for b in v)))
    vals = {p: sum(bits[f"{p}[{i}]"] << i for i in range(w)) for p, w in netlist.inputs.items()}
    return {p: _signed(netlist, p, x) for p, x in vals.items()}


# --------------------------------------------------------------------------- co-simulation

def _physical(backend: str) -> bool:
    """Whether the backend integrates the mechanical model (else it is the logic oracle)."""
    from .backends import engine_class
    return engine_class(backend).capabilities.physical


def run_backend(netlist: Netlist, x: np.ndarray, clocked: bool, backend: str, params, progress) -> list[dict]:
    """Per vector / cycle: {bits, valid, stable, min_margin, amplitudes} of the network on the backend."""
    from . import simulation
    from .backends import progress_bar
    from .experiments import clocking
    from .backends.logic import evaluate_batch
    physical = _physical(backend)
    if not physical and not clocked:
        bar = progress_bar(len(x), progress, unit="vector")
        out = []
        for start in range(0, len(x), 4096):
            chunk = evaluate_batch(netlist, x[start:start + 4096])
            out += [{"bits": dict(zip(output_bits(netlist), map(int, row))), "valid": True} for row in chunk]
            bar.update(len(chunk))
        bar.close()
        return out
    cycles = [_as_ports(netlist, v) for v in x]
    if clocked and not physical:
        return simulation.run_clocked_logic(netlist, cycles)["trace"]
    if clocked:
        timing = clocking.clock_timing(netlist, p=params)
        return simulation.run_clocked_physical(netlist, params, cycles, backend, timing, progress=progress)["trace"]
    return simulation.run_physical(netlist, params, cycles, backend, progress=progress)


def compare(netlist: Netlist, x: np.ndarray, ref: list[dict], got: list[dict], clocked: bool,
            levels=None) -> list[dict]:
    """Every output bit where Icarus and the backend differ (an invalid bit included); margins in the block's
    `levels` (default: the default block's).  Where Icarus reads x (a register the source never defines, e.g.
    without a reset) any valid bit agrees, as `-ignore_gold_x` in the proof: the source allows either value.
    A z, or an invalid bit against an x, is a mismatch, except on an output bit the source drives with nothing
    (`netlist.undriven`): neither reading has a value there, and it is not compared."""
    from .physics.params import DEFAULT_LEVELS
    levels = levels or DEFAULT_LEVELS
    mismatches = []
    for k, (r, g) in enumerate(zip(ref, got)):
        for bit in output_bits(netlist):
            want, have = r[bit], g["bits"].get(bit)
            if have is not None and (want in "xX" or (want in "01" and int(want) == have)):
                continue
            if want in "xXzZ" and bit in netlist.undriven:
                continue
            amp = g.get("amplitudes", {}).get(bit)
            m = {("cycle" if clocked else "vector"): k, "inputs": _as_ports(netlist, x[k]), "bit": bit,
                 "icarus": want, "backend": have, "amplitude": amp,
                 "margin": None if amp is None else float(levels.margin(amp, have if have is not None else levels.band_of(amp)))}
            if clocked:
                m["inputs_at_read"] = _inputs_at_read(netlist, x, k)
            mismatches.append(m)
    return mismatches


def _inputs_at_read(netlist: Netlist, x: np.ndarray, k: int) -> dict:
    """The inputs on when cycle k's outputs are read: cycle k+1's, applied after edge k (the last cycle's own).
    `inputs` (cycle k's) are what edge k captured; a path from an input to an output sees these."""
    return _as_ports(netlist, x[min(k + 1, len(x) - 1)])


def cosim_trace(netlist: Netlist, x: np.ndarray, ref: list[dict], got: list[dict], clocked: bool) -> list[dict]:
    """Every compared value, per vector / cycle k: {cycle or vector: k, inputs (port -> int; clocked: those
    edge k captured, and inputs_at_read, those on at the read: `_inputs_at_read`), source (Icarus,
    port -> "01xz" MSB first), network (the backend, port -> "01x", x an invalid bit), amplitudes (physical
    backends: output bit -> u_R)}; what `verify --vcd` writes."""
    out = []
    for k, (r, g) in enumerate(zip(ref, got)):
        step = {("cycle" if clocked else "vector"): k, "inputs": _as_ports(netlist, x[k]),
                "source": _port_values(netlist, r),
                "network": _port_values(netlist, {b: g["bits"].get(b) for b in output_bits(netlist)})}
        if clocked:
            step["inputs_at_read"] = _inputs_at_read(netlist, x, k)
        if g.get("amplitudes"):
            step["amplitudes"] = {b: float(a) for b, a in g["amplitudes"].items()}
        out.append(step)
    return out


def undefined_by_port(netlist: Netlist, ref: list[dict]) -> dict:
    """Per output port, of the bits compared: how many the source left x and z (Icarus), and how many in all."""
    out = {}
    for port, w in netlist.outputs.items():
        vals = [r[b] for r in ref for i in range(w) if (b := f"{port}[{i}]") not in netlist.undriven]
        out[port] = {"x": sum(v in "xX" for v in vals), "z": sum(v in "zZ" for v in vals), "compared": len(vals)}
    return out


def cosim(path, netlist: Netlist, backend: str, n: int | None, exhaustive: bool, seed: int, params=None,
          progress=False, reset=None, resets: list[dict] | None = None, keep_trace: bool = False,
          budget_s: float = COSIM_BUDGET_S) -> dict:
    """Icarus against the backend on the same vectors (clocked: cycles after a reset): the mismatches;
    `keep_trace`: also every compared value ("trace", `cosim_trace`).  `budget_s`: each Icarus run's; where it
    runs out, the vectors it read are the ones compared (`cut`: {read, of, budget_s})."""
    t0 = time.time()
    clocked = netlist.clocked
    physical = _physical(backend)
    n = n or (16 if physical and not clocked else 8 if physical else 2000 if not clocked else 1000)
    rst = reset_ports(netlist, reset, path) if clocked and resets is None else (resets or [])
    if clocked:
        if exhaustive:
            raise Mech2SpiceError(f"--exhaustive applies to combinational designs; {netlist.top} is clocked: "
                                  "give --cycles N")
        x, complete = make_cycles(netlist, n, seed, rst), False
    else:
        x, complete = make_vectors(netlist, n, exhaustive, seed)
        if physical and not exhaustive and len(x) > n:
            x = x[np.random.default_rng(seed).permutation(len(x))[:n]]
            complete = False
    warnings, info = [], {}
    ref = icarus(path, netlist, x, clocked, warnings, info, budget_s=budget_s)
    # cut at the budget: the rows Icarus read, the last of them (clocked) with the next cycle's inputs on
    x, complete = x[:len(ref) + 1], complete and len(ref) == len(x)
    got = run_backend(netlist, x, clocked, backend, params, progress)[:len(ref)]
    levels = None if params is None else params.levels
    mismatches = compare(netlist, x, ref, got, clocked, levels)
    driven = _driven(netlist, ref)
    # where Icarus disagrees, or agrees only because it reads x: again from where the network powers up
    start = power_up_start(netlist) if clocked and (mismatches or _mostly_undefined(driven)
                                                    or _undefined_ports(netlist, ref)) else []
    compared = None
    if start:
        mismatches, compared = _from_power_up(path, netlist, x, got, levels, start, mismatches, info, budget_s)
    if keep_trace:
        info["trace"] = cosim_trace(netlist, x, compared or ref, got, clocked)
    out = {"backend": backend, ("cycles" if clocked else "vectors"): len(ref), "exhaustive": complete,
           "seed": seed, "mismatches": mismatches, "agree": not mismatches, "wall_s": time.time() - t0,
           "undefined_bits": sum(v in "xX" for r in driven for v in r.values()),
           "undriven_bits": sum(v in "zZ" for r in driven for v in r.values()),
           "driven_by_nothing": list(netlist.undriven), "source_warnings": warnings, **info,
           "undefined_by_port": undefined_by_port(netlist, ref)}
    out["mostly_undefined"] = _mostly_undefined(_driven(netlist, compared or ref))   # in the run the verdict compared
    out["ports_mostly_undefined"] = _undefined_ports(netlist, compared or ref)
    out["ports_never_compared"] = _undefined_ports(netlist, compared or ref, every=True)
    out["compared_run"] = "as_written" if compared is None else "power_up_start"
    if clocked:
        out["reset"] = {k: rst[0][k] for k in ("port", "level")} if rst else None
        out["resets"] = rst
    if physical:
        margins = [g["min_margin"] for g in got if g.get("min_margin") is not None]
        out.update(valid=all(g["valid"] for g in got), stable=all(g.get("stable", True) for g in got),
                   min_margin=min(margins) if margins else None)
        out["agree"] = out["agree"] and out["valid"]
    return out


def _driven(netlist: Netlist, ref: list[dict]) -> list[dict]:
    """Icarus's values less the output bits the source drives with nothing (not compared)."""
    if not netlist.undriven:
        return ref
    return [{b: v for b, v in r.items() if b not in netlist.undriven} for r in ref]


def _mostly_undefined(ref: list[dict]) -> bool:
    """Whether x or z is more than half the bits of an Icarus run: agreement there says little."""
    compared = sum(len(r) for r in ref)
    return compared > 0 and sum(v in "xXzZ" for r in ref for v in r.values()) * 2 > compared


def _undefined_ports(netlist: Netlist, ref: list[dict], every: bool = False) -> list[str]:
    """The output ports more than half of whose bits an Icarus run left x or z (`every`: all of them, so
    that Icarus never checked the port): the whole run may be mostly defined while one port never is
    (oc_usb_phy's DataIn_o, public RTL pass 8)."""
    found = []
    for port, n in undefined_by_port(netlist, ref).items():
        undefined = n["x"] + n["z"]
        if n["compared"] and (undefined == n["compared"] if every else 2 * undefined > n["compared"]):
            found.append(port)
    return found


def _from_power_up(path, netlist: Netlist, x, got, levels, start, mismatches, info, budget_s=COSIM_BUDGET_S):
    """Icarus again, each register the source leaves without a power-up value started where the network
    starts it (x on Icarus until written, and an `if (x)` takes the else branch: a run from no state any
    circuit has).  That run is one the source allows: where it agrees, the as-written mismatches were
    Icarus's reading of x; where the as-written run agreed only by reading x, its mismatches stand.
    Returns (mismatches, the Icarus run they are counted on, None for the as-written one).
    `info["power_up_start"]` says what was done."""
    sub = {}
    ref = icarus(path, netlist, x, True, info=sub, start=start, budget_s=budget_s)
    if len(ref) < len(got):                     # this run's budget ran out first: the as-written run stands
        info["power_up_start"] = {**sub["started"], "cut": sub["cut"], "mismatches": None,
                                  "as_written_mismatches": len(mismatches)}
        return mismatches, None
    ref = ref[:len(got)]                        # the rows compared (x may hold the next cycle's inputs too)
    again = compare(netlist, x, ref, got, True, levels)
    info["power_up_start"] = {**sub["started"], "mismatches": len(again), "as_written_mismatches": len(mismatches)}
    if sub["started"]["register_bits"] and (not again or not mismatches):
        return again, ref
    return mismatches, None


# --------------------------------------------------------------------------- the command

def verify(path, top: str | None = None, backend: str = "logic", vectors: int | None = None,
           exhaustive: bool = False, seed: int = 0, params=None, progress=False, log=None,
           netlist: Netlist | None = None, reset=None, equivalence_check: bool = True,
           proof_time: float = PROOF_BUDGET_S, keep_trace: bool = False, proof_engine: str = "auto",
           max_fanout: int | None = None, cosim_time: float = COSIM_BUDGET_S) -> dict:
    """Equivalence and co-simulation of one design; `cosim_time`: each Icarus run's budget (`cosim`);
    `netlist` replaces the synthesised one (tests), which
    is otherwise built with `simulate`'s buffer trees (`max_fanout`, default network.MAX_FANOUT);
    `keep_trace`: the co-simulation's compared values too (cosim.trace, for --vcd); `proof_engine`: auto, abc
    or sat (`equivalence`)."""
    t0 = time.time()
    from .synthesis.dialect import standard_source
    from .synthesis.synth import synthesize
    log = log or (lambda msg: None)
    from .physics.network import MAX_FANOUT
    nl = netlist if netlist is not None else synthesize(path, top=top, max_fanout=max_fanout or MAX_FANOUT)
    check_names(nl)
    out = {"design": str(path), "top": nl.top, "clocked": nl.clocked, "sampled_clocks": list(nl.sampled),
           "gates": len(nl.gates()), "logic_gates": len(nl.gates()), "latches": len(nl.latches()), "races": [r.as_dict() for r in nl.races],
           "translate_off": [list(r) for r in nl.translate_off]}
    with standard_source(path) as src, _named_as(src, path):   # the text synthesis read (docs/rtl.md)
        resets = reset_ports(nl, reset, src) if nl.clocked else []
        if nl.clocked and reset:
            out["reset_notes"] = reset_notes(resets, design_resets(src, nl))
        if equivalence_check:
            log(f"{nl.top}: proving the {len(nl.gates())}-gate network equal to the source ({proof_engine}, at "
                f"most {proof_time:.0f} s)")
            out["equivalence"] = equivalence(src, nl, proof_time, resets, proof_engine)
            log(f"equivalence: {out['equivalence']['status']} ({out['equivalence']['wall_s']:.1f} s)")
        log(f"co-simulation against Icarus on {backend}")
        out["cosim"] = cosim(src, nl, backend, vectors, exhaustive, seed, params, progress, reset, resets,
                             keep_trace, budget_s=cosim_time)
    eq = out.get("equivalence", {}).get("status", "proved")
    out["verdict"] = "pass" if eq == "proved" and out["cosim"]["agree"] else \
        "fail" if eq == "counterexample" or not out["cosim"]["agree"] else "unknown"
    out["wall_s"] = time.time() - t0
    return out


@contextlib.contextmanager
def _named_as(src: Path, path) -> Iterator[None]:
    """A tool's refusal of the rewritten copy (`standard_source`'s scratch file, gone when it is read) names
    the user's file: the copy keeps every line, so the line numbers stand."""
    try:
        yield
    except Mech2SpiceError as err:
        if Path(src) == Path(path):
            raise
        raise Mech2SpiceError(str(err).replace(str(src), str(path))) from None


def exit_code(result: dict) -> int:
    """0 when everything agrees and equivalence is proved; 1 otherwise (mismatch, counterexample, unknown)."""
    return 0 if result["verdict"] == "pass" else 1


def junit_xml(result: dict) -> str:
    """One testsuite: testcases `equivalence` and `cosim:<backend>`, a <failure> listing what differs."""
    cases = []
    eq = result.get("equivalence")
    if eq is not None:
        fail = None if eq["status"] == "proved" else (
            eq["status"], f"{eq['detail']}; counterexample: {eq['counterexample']}")
        cases.append(("equivalence", eq["wall_s"], fail))
    co = result["cosim"]
    fail = None if co["agree"] else (
        f"{len(co['mismatches'])} mismatches" + ("" if co.get("valid", True) else ", invalid outputs"),
        "\n".join(_mismatch_text(m) for m in co["mismatches"][:1000]))
    cases.append((f"cosim:{co['backend']}", co["wall_s"], fail))
    body = []
    for name, secs, failure in cases:
        body.append(f'  <testcase classname={quoteattr("mech2spice.verify." + result["top"])} '
                    f'name={quoteattr(name)} time="{secs:.3f}"' + (">" if failure else "/>"))
        if failure:
            body += [f"    <failure message={quoteattr(failure[0])}>{escape(failure[1])}</failure>", "  </testcase>"]
    nfail = sum(1 for *_, f in cases if f)
    return "\n".join(['<?xml version="1.0" encoding="UTF-8"?>',
                      f'<testsuite name={quoteattr("verify " + result["top"])} tests="{len(cases)}" '
                      f'failures="{nfail}" errors="0" time="{result["wall_s"]:.3f}">', *body, "</testsuite>", ""])


def _mismatch_text(m: dict) -> str:
    where = f"cycle {m['cycle']}" if "cycle" in m else f"vector {m['vector']}"
    amp = "" if m["amplitude"] is None else f", amplitude {m['amplitude']:.4f} u_R, margin {m['margin']:+.3f}"
    got = "invalid" if m["backend"] is None else m["backend"]
    read = f", read with {m['inputs_at_read']}" if "inputs_at_read" in m else ""
    return f"{where} {m['inputs']}{read}: {m['bit']} Icarus {m['icarus']}, network {got}{amp}"


def _bits_text(bits: list[str]) -> str:
    """Output bits named per port, highest first: `o[2,1], carry[0]`."""
    by_port: dict[str, list[int]] = {}
    for b in bits:
        port, index = b.rsplit("[", 1)
        by_port.setdefault(port, []).append(int(index.rstrip("]")))
    return ", ".join(f"{p}[{','.join(map(str, sorted(ix, reverse=True)))}]" for p, ix in by_port.items())


def _undefined_text(co: dict) -> str:
    """The verdict line's note on bits the source left undefined: per port, and a warning when most were."""
    ports = [f"{p} {n['x'] + n['z']}/{n['compared']}" for p, n in co.get("undefined_by_port", {}).items()
             if n["x"] + n["z"]]
    if not ports:
        return ""
    started = co.get("compared_run") == "power_up_start"
    note = (f"; x/z in the source as written (per port, of {'its' if started else 'the'} bits"
            f"{'; compared from the power-up start above' if started else ' compared'}): " + ", ".join(ports))
    if co.get("mostly_undefined"):
        note += " -- MOST compared bits were undefined in the source: agreement there says little"
    if co.get("ports_never_compared"):
        names = ", ".join(co["ports_never_compared"])
        note += f" -- {names}: undefined in every compared bit, so never checked against Icarus"
    return note


def text(result: dict) -> str:
    """The human-readable report."""
    lines = [f"{result['top']}: {result['gates']} NOR gates, {result['latches']} latches"]
    lines += [f"  reset: {n}" for n in result.get("reset_notes", [])]
    eq = result.get("equivalence")
    if eq is not None:
        lines.append(f"equivalence: {eq['status']} ({eq['method']}, {eq['wall_s']:.1f} s)")
        if eq.get("engine_note"):
            lines.append(f"  {eq['engine_note']}")
        if eq["status"] != "proved":
            lines.append(f"  {eq['detail']}")
        if eq.get("replay"):
            rep = eq["replay"]
            lines.append("  replay (Icarus vs the network on the logic backend): " +
                         (f"reproduced in cycle {rep['cycle']} on {', '.join(rep['bits'])}" if rep["reproduced"]
                          else "not reproduced: no bit the source defines differs"))
        for step in eq["counterexample"] or []:
            lines.append(f"  counterexample{' cycle ' + str(step['cycle']) if 'cycle' in step else ''}: "
                         f"{step['inputs']}" + (f" -> source {step['source']}, network {step['network']}"
                                                if "source" in step else ""))
    co = result["cosim"]
    n = co.get("vectors", co.get("cycles"))
    what = "cycles" if "cycles" in co else ("vectors (exhaustive)" if co["exhaustive"] else "random vectors")
    lines.append(f"co-simulation vs Icarus on {co['backend']}: {n} {what}, "
                 f"{len(co['mismatches'])} mismatches ({co['wall_s']:.1f} s)"
                 + (f"; {co['undefined_bits']} bits the source leaves undefined (x: either value agrees)"
                    if co.get("undefined_bits") else "")
                 + (f"; {co['undriven_bits']} bits the source does not drive (z on Icarus: a mismatch)"
                    if co.get("undriven_bits") else "")
                 + (f"; not compared: {_bits_text(co['driven_by_nothing'])}, which the source drives with nothing"
                    if co.get("driven_by_nothing") else "")
                 + (f"; valid {co['valid']}, stable {co['stable']}, min margin {co['min_margin']:+.3f}"
                    if "valid" in co and co["min_margin"] is not None else ""))
    if co.get("cut"):
        lines.append(f"  Icarus's budget ({co['cut']['budget_s']:g} s, --cosim-time) ran out: {co['cut']['read']} of "
                     f"{co['cut']['of']} {'cycles' if 'cycles' in co else 'vectors'} read, and compared")
    lines += [f"  source: {w} (Yosys joins the nets, so the proof is of that reading)"
              for w in co.get("source_warnings", [])]
    if co.get("power_up_start"):
        lines.append("  " + _power_up_text(co["power_up_start"]))
    lines += ["  " + _mismatch_text(m) for m in co["mismatches"][:20]]
    if len(co["mismatches"]) > 20:
        lines.append(f"  ... {len(co['mismatches']) - 20} more (--json lists all)")
    if result.get("vcd"):
        w = result["vcd"]
        cex = w["counterexample"]
        lines.append(f"waveform: {w['file']} (co-simulation at times {w['cosim'][0]}-{w['cosim'][1]}"
                     + (f", counterexample at times {cex[0]}-{cex[1]})" if cex else ")"))
    lines.append(f"verdict: {result['verdict']} ({result['wall_s']:.1f} s)" + _undefined_text(co)
                 + _race_text(result) + _readings_text(result))
    return "\n".join(lines)


def _power_up_text(st: dict) -> str:
    """What the second Icarus run, from the network's power-up state (`_from_power_up`), found."""
    lost = f"; {st['not_found']} Icarus could not find by name (left x)" if st["not_found"] else ""
    head = (f"Icarus as written: {st['as_written_mismatches']} mismatches; again with the {st['register_bits']} "
            f"register bits the source gives no power-up value started where the network starts them{lost}: ")
    if not st["register_bits"]:
        return head + "none could be set, so the as-written comparison stands"
    if not st["as_written_mismatches"]:
        return head + (f"{st['mismatches']} mismatches; the as-written run agreed only by reading x, so this run "
                       "is the one compared" + (", and the design fails" if st["mismatches"] else ""))
    if not st["mismatches"]:
        return head + ("0 mismatches, so the as-written ones were Icarus's reading of x (an `if (x)` takes the "
                       "else branch, a start no circuit has), not the network: the mismatches above are that run's, "
                       "the x counts the source's as written")
    return head + f"still {st['mismatches']} mismatches, so the as-written comparison stands"


def _readings_text(result: dict) -> str:
    """The verdict line's note where the proof holds and Icarus still disagrees without a race: the two tools
    read the source differently, and the usual cause is an x that Icarus resolves at an `if`."""
    if result.get("equivalence", {}).get("status") != "proved" or not result["cosim"]["mismatches"] \
            or result.get("races"):
        return ""
    skipped = ", ".join(f"{a}-{b}" for a, b in result.get("translate_off") or [])
    if skipped:
        return ("; the network equals Yosys's reading of the source (proved), so Icarus reads it otherwise: first "
                f"suspect the source's `translate_off` text (lines {skipped}), which Icarus runs and synthesis "
                "leaves out (a power-up value there is one the network does not have), then a register with "
                "neither reset nor power-up value (docs/verify.md)")
    return ("; the network equals Yosys's reading of the source (proved), so Icarus reads it otherwise: most "
            "often a register with neither reset nor power-up value, x on Icarus, whose `if (x)` takes the "
            "else branch, a power-up no circuit need share (give it a reset or an initial value), or a delay "
            f"in the source longer than the testbench's {SETTLE_NS} ns (docs/verify.md)")


def _race_text(result: dict) -> str:
    """The verdict line's note on races between clocked blocks (synthesis/races.py): with one, a mismatch
    may be the simulator's choice of order, not an error of the network."""
    found = result.get("races") or []
    if not found:
        return ""
    named = ", ".join(f"'{r['variable']}' (written line {r['write_line']}, read line {r['read_line']})"
                      for r in found)
    mismatches = result["cosim"]["mismatches"]
    return (f"; the source races: clocked blocks pass {named} through blocking '=' on the same edge"
            + ("; the source's meaning depends on the simulator's order of those blocks (IEEE 1364 section 11), "
               "so these mismatches may be Icarus's order, not an error of the network (synthesis reads "
               "flip-flops)" if mismatches else ""))
