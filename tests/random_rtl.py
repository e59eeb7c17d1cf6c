"""Random single-clock designs for verify's co-simulation (tests/test_rtl_constructs.py): registers with and
without reset or power-up value, next states through `if`, `case` and `?:` on other registers, and an output
decided by a combinational `if`, so Icarus's reading of x (an `if (x)` takes the else branch) meets the
network's power-up.  `edge`: every register on `posedge` or `negedge` of clk; `mixed`: each register on a
random edge of clk; `two`: each on a random edge of clk or clk2 (the last two are sampled, docs/rtl.md).
`design(seed, edge)` is deterministic."""
from __future__ import annotations

import random


def design(seed: int, edge: str = "posedge") -> str:
    rng = random.Random(seed)
    ins = [(f"i{k}", rng.choice([1, 2, 3])) for k in range(rng.randint(1, 3))]
    regs = [(f"r{k}", rng.choice([1, 2, 3, 4])) for k in range(rng.randint(2, 5))]
    clocks = "input clk, input clk2, " if edge == "two" else "input clk, "
    lines = [f"module fz({clocks}input rst, " + ", ".join(f"input [{w - 1}:0] {n}" for n, w in ins)
             + ", output [7:0] y, output z);"]
    kinds = {n: rng.choice(["none", "none", "sync", "async", "init"]) for n, _ in regs}
    for n, w in regs:
        lines.append(f"  reg [{w - 1}:0] {n}" + (f" = {rng.randrange(1 << w)}" if kinds[n] == "init" else "") + ";")
    for n, _ in regs:
        sens = f"{_edge(rng, edge)}" + (" or posedge rst" if kinds[n] == "async" else "")
        body = [f"if (rst) {n} <= 0; else"] if kinds[n] in ("sync", "async") else []
        style = rng.choice(["plain", "if", "case"])
        if style == "plain":
            body.append(f"{n} <= {_expr(rng, regs, ins)};")
        elif style == "if":
            body.append(f"if ({_expr(rng, regs, ins)}) {n} <= {_expr(rng, regs, ins)}; "
                        f"else if ({_expr(rng, regs, ins)}) {n} <= {_expr(rng, regs, ins)};")
        else:
            sel = rng.choice(regs)[0]
            body.append(f"case ({sel}) 0: {n} <= {_expr(rng, regs, ins)}; 1: {n} <= {_expr(rng, regs, ins)}; "
                        f"default: {n} <= {n}; endcase")
        lines.append(f"  always @({sens}) begin " + " ".join(body) + " end")
    lines.append(f"  assign y = {_expr(rng, regs, ins)};")
    lines.append(f"  reg zz; always @* if ({_expr(rng, regs, ins)}) zz = 1'b1; else zz = 1'b0;")
    lines += ["  assign z = zz;", "endmodule"]
    return "\n".join(lines) + "\n"


def _edge(rng: random.Random, edge: str) -> str:
    if edge in ("posedge", "negedge"):
        return f"{edge} clk"
    return f"{rng.choice(['posedge', 'negedge'])} {rng.choice(['clk', 'clk2']) if edge == 'two' else 'clk'}"


def _expr(rng: random.Random, regs, ins, depth: int = 0) -> str:
    widths = dict(regs + ins)
    if depth > 2 or rng.random() < 0.3:
        leaf = rng.choice(list(widths) + [str(rng.randint(0, 7))])
        if leaf in widths and widths[leaf] > 1 and rng.random() < 0.3:
            return f"{leaf}[{rng.randrange(widths[leaf])}]"
        return leaf
    op = rng.choice(["+", "^", "&", "|", "-", "?", "==", "<", "~"])
    a, b = _expr(rng, regs, ins, depth + 1), _expr(rng, regs, ins, depth + 1)
    if op == "?":
        return f"(({_expr(rng, regs, ins, depth + 1)}) ? ({a}) : ({b}))"
    return f"(~({a}))" if op == "~" else f"(({a}) {op} ({b}))"
