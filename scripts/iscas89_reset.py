"""ISCAS-89 netlists -> the s344_reset.v form: posedge flip-flops with a synchronous reset RST (to 0), exposed as STATE.

The public netlists come as ISCAS '.bench' text or as the ispras/hdl-benchmarks structural Verilog, whose `dff`
module is a switch-level (nmos/trireg) master-slave latch pair. Neither has a reset, so a random-stimulus run would
start from an unknown state; both are rewritten here, mechanically, to the same form as
/work/shared/reference/cases/s344_reset.v:

* every flip-flop becomes `dff_rst NAME(CK,Q,D,RST)`:  always @(posedge CK) Q <= RST ? 0 : D;
* the top module gains the ports RST (input) and STATE (output, STATE[i] = Q of the i-th flip-flop in file order);
* gates and port names are kept as they are (a .bench net name becomes a Verilog identifier unchanged).

Usage:  python3 scripts/iscas89_reset.py $MECH2SPICE_BENCHMARKS/iscas89/s27.bench [...]   (writes $MECH2SPICE_BENCHMARKS/iscas89/reset/)
        python3 scripts/iscas89_reset.py --tie-undriven $MECH2SPICE_BENCHMARKS/iscas89/s400.bench   (s400_tied_reset.v)
"""
from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

DFF_RST = """module dff_rst (CK,Q,D,R);
input CK,D,R;
output Q;
reg Q;
always @(posedge CK) Q <= R ? 1'b0 : D;
endmodule
"""
BENCH_GATES = {"NOT": "not", "BUF": "buf", "AND": "and", "OR": "or", "NAND": "nand", "NOR": "nor",
               "XOR": "xor", "XNOR": "xnor"}
TRANSFORM_NOTE = ("// Transformed by scripts/iscas89_reset.py (do not edit): every flip-flop is a posedge flip-flop with a\n"
                  "// synchronous reset RST (to 0), and the flip-flops are exposed as the output port STATE\n"
                  "// (STATE[i] = the i-th flip-flop of the netlist, in file order).\n")


def comment_lines(text: str, prefix: str) -> list[str]:
    """The leading comment block (provenance + the benchmark's own header), kept verbatim as // comments."""
    out = []
    for line in text.splitlines():
        if line.startswith(prefix):
            out.append("//" + line[len(prefix):])
        elif line.strip():
            break
    return out


def state_port(qs: list[str]) -> str:
    """STATE as a concatenation, MSB first, so that STATE[i] is the i-th flip-flop."""
    return f"output [{len(qs) - 1}:0] STATE;\nassign STATE = {{{','.join(reversed(qs))}}};\n"


# --- .bench -----------------------------------------------------------------------------------------------------
def parse_bench(text: str) -> tuple[list[str], list[str], list[tuple[str, str, list[str]]]]:
    """(inputs, outputs, [(out, GATE, args)]) of an ISCAS .bench netlist, in file order."""
    ins, outs, gates = [], [], []
    for raw in text.splitlines():
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        if m := re.fullmatch(r"(INPUT|OUTPUT)\(\s*(\S+?)\s*\)", line):
            (ins if m[1] == "INPUT" else outs).append(m[2])
        elif m := re.fullmatch(r"(\S+)\s*=\s*(\w+)\((.*)\)", line):
            gates.append((m[1], m[2].upper(), [a.strip() for a in m[3].split(",")]))
        else:
            raise ValueError(f"unrecognised .bench line: {raw!r}")
    return ins, outs, gates


def undriven(text: str) -> list[str]:
    """Nets a .bench netlist reads but nothing drives (s400's clock phase Phi1H): the NOR mapping refuses them."""
    ins, _, gates = parse_bench(text)
    return sorted({a for g in gates for a in g[2]} - {g[0] for g in gates} - set(ins))


def bench_to_verilog(text: str, top: str, tie: bool = False) -> str:
    ins, outs, gates = parse_bench(text)
    clash = {"RST", "STATE", "CK"} & set(ins + outs + [g[0] for g in gates])
    if clash:
        raise ValueError(f"{top}: net names {sorted(clash)} clash with the added ports")
    qs = [g[0] for g in gates if g[1] == "DFF"]
    wires = sorted({n for g in gates for n in [g[0], *g[2]]} - set(ins) - set(outs))
    body = []
    for k, (out, kind, args) in enumerate(gates):
        if kind == "DFF":
            body.append(f"  dff_rst DFF_{qs.index(out)}(CK,{out},{args[0]},RST);")
        elif kind in BENCH_GATES:
            body.append(f"  {BENCH_GATES[kind]} G_{k}({out},{','.join(args)});")
        else:
            raise ValueError(f"{top}: gate type {kind} has no Verilog primitive here")
    head = [f"module {top}(RST,STATE,CK,{','.join(ins + outs)});",
            "input RST,CK;", state_port(qs).rstrip("\n")]
    head += [f"input {','.join(ins)};", f"output {','.join(outs)};", f"  wire {','.join(wires)};", ""]
    if tie:   # --tie-undriven: what Yosys would fold them to anyway, made explicit so the mapping accepts it
        head += [f"  assign {n} = 1'b0;  // undriven in the public netlist; tied by --tie-undriven" for n in undriven(text)]
    return "\n".join(head + body + ["", "endmodule", "", DFF_RST])


# --- ispras structural Verilog ------------------------------------------------------------------------------------
def verilog_to_reset(text: str, top: str) -> str:
    body = re.sub(r"^//.*\n", "", text, flags=re.M)                       # header: re-emitted by transform()
    body, n = re.subn(r"module dff \(CK,Q,D\);.*?endmodule\s*", "", body, count=1, flags=re.S)
    if n != 1:
        raise ValueError(f"{top}: no switch-level `module dff (CK,Q,D)` to replace")
    qs = re.findall(r"^\s*dff \w+\(CK,(\w+),\w+\);", body, flags=re.M)
    body, n = re.subn(r"^(\s*)dff (\w+)\((CK,\w+,\w+)\);", r"\1dff_rst \2(\3,RST);", body, flags=re.M)
    if n != len(qs) or not qs:
        raise ValueError(f"{top}: {n} dff instances rewritten, {len(qs)} found")
    body, n = re.subn(rf"module {top}\(", f"module {top}(RST,STATE,", body, count=1)
    if n != 1:
        raise ValueError(f"{top}: module {top} not found")
    header_end = re.search(rf"module {top}\(.*?\);\n", body, flags=re.S).end()
    body = body[:header_end] + "input RST;\n" + state_port(qs) + body[header_end:]
    return body.strip("\n") + "\n\n" + DFF_RST


def transform(path: Path, tie: bool = False) -> str:
    """The reset form of one netlist file, with its provenance comments first."""
    text, top = path.read_text(), path.name.split(".")[0]
    if path.suffix == ".bench":
        comments, verilog = comment_lines(text, "#"), bench_to_verilog(text, top, tie)
    else:
        comments, verilog = comment_lines(text, "//"), verilog_to_reset(text, top)
    return "\n".join(comments) + "\n" + TRANSFORM_NOTE + "\n" + verilog


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("netlists", nargs="+", type=Path)
    ap.add_argument("--tie-undriven", action="store_true",
                    help=".bench: tie nets that nothing drives to 0 (written as NAME_tied_reset.v)")
    ap.add_argument("--out", type=Path, default=None, help="output folder (default: <netlist folder>/reset)")
    args = ap.parse_args(argv)
    for path in args.netlists:
        out_dir = args.out or path.parent / "reset"
        out_dir.mkdir(parents=True, exist_ok=True)
        tied = "_tied" if args.tie_undriven else ""
        dest = out_dir / f"{path.name.split('.')[0]}{tied}_reset.v"
        dest.write_text(transform(path, args.tie_undriven))
        print(dest)
    return 0


if __name__ == "__main__":
    sys.exit(main())
