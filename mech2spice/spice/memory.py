"""The processor's 256-byte memory as Verilog-A devices for the envelope-level VACASK netlist (docs/cpu_circuit.md).

OpenVAF (the Verilog-A compiler VACASK loads) has no arrays of variables and no events (`@(cross)`,
`@(timer)`; only `@(initial_step)` / `@(final_step)`), and its variables do not persist between time steps.
So the memory is analogue, event-free: every stored bit is the voltage of a node that only a write moves.

* ``m2s_mem_bit(ar, ai, q)``: a bus bit from its envelope amplitude, V(q) = 1/2 (1 + tanh((|A|^2 - th^2) /
  (2 th w))) with |A|^2 = V(ar)^2 + V(ai)^2 in u_R^2: 0 or 1 to 1e-10 anywhere inside the logic bands.
* ``m2s_mem_byte(r0..r7, w0..w7, d0..d7, we, wclk, o0..o7)``: one address (parameters a0..a7 its bits, i0..i7
  the program's byte).  Bit b is i_b + V(s_b); s_b holds (only a capacitance, tau ddt V) unless
  g = V(wclk) V(we) sel_w > 0, which pulls i_b + V(s_b) to V(d_b) with time constant tau / g; sel_w, sel_r are
  products over the address bits of V(x) or 1 - V(x).  Reading injects sel_r (i_b + V(s_b)) into the sum node
  o_b: the selected byte appears there.  All nodes start at 0 (uic), so the memory starts with the program.
* ``m2s_mem_read(o, wclk, amp)``: the sum node's resistor, a track-and-hold (holds while V(wclk) = 1, the
  write window, so a write never changes the byte being read within the clock pulse) and the force level
  V(amp) = F0 + (F1 - F0) h the rdata pair drives read.
"""
from __future__ import annotations

from pathlib import Path

from ..physics.params import DEFAULT, GateParams
from .openvaf import compile_va, module_text

FILE = "m2s_memory.va"
BITS = 8
WIDTH = 0.01                      # u_R: the decoders' tanh width (bands are >= 0.125 u_R from the threshold)
THRESHOLD = (DEFAULT.levels.band0[1] + DEFAULT.levels.band1[0]) / 2   # the default block's; a block's own: threshold(p)


def threshold(p: GateParams) -> float:
    """The amplitude (u_R) between p's bands at which a memory cell reads a written bit as '1'."""
    return (p.levels.band0[1] + p.levels.band1[0]) / 2


def _select(addr: str, bus: str) -> str:
    """Product over the address bits: 1 when the bus decodes to this cell's address (a0..a7 in {0, 1})."""
    return "*".join(f"({addr}{b}*V({bus}{b}) + (1 - {addr}{b})*(1 - V({bus}{b})))" for b in range(BITS))


def modules(p: GateParams = DEFAULT) -> list[str]:
    """The three memory modules' Verilog-A text."""
    bit = module_text("m2s_mem_bit", ["ar", "ai", "q"], [], [("th", threshold(p), False), ("w", WIDTH, False)],
                      ["I(q) <+ V(q) - 0.5*(1 + tanh((V(ar)*V(ar) + V(ai)*V(ai) - th*th)/(2*th*w)));"],
                      "m2s_mem_bit: a bus bit (0/1 voltage) from an envelope amplitude node pair (u_R).")
    r, w, d, o = ([f"{x}{b}" for b in range(BITS)] for x in "rwdo")
    s = [f"s{b}" for b in range(BITS)]
    body = [f"selr = {_select('a', 'r')};", f"g = V(wclk)*V(we)*{_select('a', 'w')};"]
    for b in range(BITS):
        body += [f"I(s{b}) <+ ddt(tau*V(s{b})) - g*(V(d{b}) - i{b} - V(s{b}));",
                 f"I(o{b}) <+ -selr*(i{b} + V(s{b}));"]
    addr = " + ".join(f"{1 << b}*a{b}" for b in range(BITS))
    stored = ", ".join(f"i{b} + V(s{b})" for b in range(BITS))
    # the final memory, read by cpu/circuit.py from the simulator's output (no variable outlives a step).
    # Not @(final_step): VACASK raises that flag at every time point (256 cells x every step: ~1 GB of log)
    body.append(f'if ($abstime >= tend) $strobe("m2s_mem %g{" %g" * BITS}", {addr}, {stored});')
    params = [("tau", p.period, False), ("tend", 1e30, False)] + [(f"a{b}", 0.0, True) for b in range(BITS)] \
        + [(f"i{b}", 0.0, True) for b in range(BITS)]
    byte = module_text("m2s_mem_byte", [*r, *w, *d, "we", "wclk", *o], s, params, body,
                       "m2s_mem_byte: one memory address: bits i_b + V(s_b), written while V(wclk) V(we) and the\n"
                       "write address select it, read into the sum nodes o_b while the read address selects it;\n"
                       "prints 'm2s_mem ADDR BITS' at the time points from tend on (a model parameter: the run's end).")
    byte = byte.replace("  analog begin", "  real selr, g;\n  analog begin", 1)
    read = module_text("m2s_mem_read", ["o", "wclk", "amp"], ["h"],
                       [("tau", p.period, False), ("f0", p.force(p.levels.nominal0), False), ("f1", p.force(p.levels.nominal1), False)],
                       ["I(o) <+ V(o);", "I(h) <+ ddt(tau*V(h)) + (1 - V(wclk))*(V(h) - V(o));",
                        "I(amp) <+ V(amp) - (f0 + (f1 - f0)*V(h));"],
                       "m2s_mem_read: one rdata bit: the sum node's resistor, a track-and-hold (holding while\n"
                       "V(wclk) = 1) and the pair drives' force level V(amp) = f0 + (f1 - f0) V(h).")
    return [bit, byte, read]


def library(p: GateParams = DEFAULT) -> str:
    """The memory library's text (defaults from `p`)."""
    head = ("// mech2spice Verilog-A memory (envelope level), generated by `python -m mech2spice.spice.memory`;\n"
            "// Edit mech2spice/spice/memory.py, not this file.\n"
            '`include "disciplines.vams"\n\n')
    return head + "\n".join(modules(p))


def compiled(p: GateParams = DEFAULT) -> Path:
    """The memory library compiled to OSDI (cached)."""
    return compile_va(library(p), FILE)[0]


def byte_line(addr: int, value: int, stem: str = "") -> str:
    """One m2s_mem_byte instance on the standard bus nodes (mr*, mw*, md*, mwe, mwclk, mo*)."""
    ports = [f"mr{b}" for b in range(BITS)] + [f"mw{b}" for b in range(BITS)] + [f"md{b}" for b in range(BITS)] \
        + ["mwe", "mwclk"] + [f"mo{b}" for b in range(BITS)]
    par = " ".join(f"a{b}={(addr >> b) & 1}" for b in range(BITS))
    par += " " + " ".join(f"i{b}={(value >> b) & 1}" for b in range(BITS))
    return f"xm{stem}{addr} ({' '.join(ports)}) mem_byte {par}"


def main(argv: list[str] | None = None) -> int:
    """`python -m mech2spice.spice.memory [DIR]`: regenerate the checked-in veriloga/m2s_memory.va."""
    import sys
    args = sys.argv[1:] if argv is None else argv
    path = Path(args[0] if args else "veriloga") / FILE
    path.write_text(library(), encoding="ascii", newline="\n")
    print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
