"""Bad input never gives a traceback, a silent wrong answer or lost data (issue #12): one test per class.

The command line runs in-process (mech2spice.cli.main) unless a test needs a real process (signals, kills).
"""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from mech2spice.cli import main

ROOT = Path(__file__).resolve().parents[1]
ADDER, COUNTER = str(ROOT / "verilog/adder2.v"), str(ROOT / "verilog/counter4.v")
SIEVE = str(ROOT / "programs/sieve.asm")


def run(capsys, *argv):
    """(exit code, stdout, stderr) of one in-process command."""
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def refused(capsys, *argv, needle: str) -> str:
    """Assert the command exits 2 with one line on stderr containing `needle`; returns that line."""
    rc, out, err = run(capsys, *argv)
    assert rc == 2, (rc, out, err)
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert needle in err, err
    return err


def verilog(tmp_path, text: str, name: str = "d.v") -> str:
    path = tmp_path / name
    path.write_text(text)
    return str(path)


# ------------------------------------------------------------------ silent wrong answers

def test_json_keeps_every_user_named_port(tmp_path, capsys):
    """Ports named like internal keys (`run`, `_x`) or CLI words survive --json exactly as declared."""
    src = verilog(tmp_path, "module t(input run, input _x, input json, output backend, output _y, output run2);\n"
                            "  assign backend = run & _x; assign _y = ~json; assign run2 = run;\nendmodule\n")
    rc, out, _ = run(capsys, "synth", src, "--json")
    d = json.loads(out)
    assert rc == 0 and d["inputs"] == {"run": 1, "_x": 1, "json": 1}
    assert d["outputs"] == {"backend": 1, "_y": 1, "run2": 1}
    rc, out, _ = run(capsys, "simulate", src, "--backend", "logic", "--set", "run=1", "--set", "_x=1", "--json")
    d = json.loads(out)
    assert rc == 0 and d["inputs"] == {"run": 1, "_x": 1}
    assert d["outputs"] == {"backend": 1, "_y": 1, "run2": 1}
    assert d["bits"] == {"backend[0]": 1, "_y[0]": 1, "run2[0]": 1}


def test_declaration_initialiser_is_refused_with_its_line(tmp_path, capsys):
    src = verilog(tmp_path, "module t(input clk, input a,\n  output reg q = 1'b1);\n"
                            "  always @(posedge clk) q <= a;\nendmodule\n")
    refused(capsys, "synth", src, needle="line 2: 'q' has an initial value in its declaration")
    src = verilog(tmp_path, "module t(input clk, input a, output y);\n  reg [1:0] r = 2'd2;\n"
                            "  always @(posedge clk) r <= {r[0], a};\n  assign y = r[1];\nendmodule\n")
    refused(capsys, "synth", src, needle="line 2: 'r' has an initial value")


def test_wire_with_initialiser_is_an_assignment_not_refused(tmp_path, capsys):
    src = verilog(tmp_path, "module t(input a, input b, output y);\n  wire w = a & b;\n  assign y = ~w;\nendmodule\n")
    rc, out, _ = run(capsys, "simulate", src, "--backend", "logic", "--set", "a=1", "--set", "b=1", "--json")
    assert rc == 0 and json.loads(out)["outputs"] == {"y": 0}


@pytest.mark.parametrize("body,needle", [
    ("output y, output z);\n  assign y = a;", "'z' is used but nothing drives it"),
    ("output [1:0] z);\n  assign z[0] = a;", "'z[1]' is used but nothing drives it"),
    ("output y);\n  wire w;\n  assign y = a & w;", "'w' is used but nothing drives it"),
])
def test_undriven_net_is_refused(tmp_path, capsys, body, needle):
    src = verilog(tmp_path, f"module t(input a, {body}\nendmodule\n")
    refused(capsys, "simulate", src, "--backend", "logic", needle=needle)


def test_yosys_stack_exhaustion_is_explained(tmp_path, capsys):
    expr = "a"
    for _ in range(2000):
        expr = f"(~{expr})"
    src = verilog(tmp_path, f"module t(input a, output y);\n  assign y = {expr};\nendmodule\n")
    refused(capsys, "synth", src, needle="nested too deeply")
