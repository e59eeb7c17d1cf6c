"""Verilog the NOR mapping cannot represent faithfully is refused with the file and line, or handled and
checked against Icarus Verilog (issue #26, silent wrong answers): one test per class.

The command line runs in-process (mech2spice.cli.main).  The Icarus comparisons skip when `iverilog` is
absent (`make setup` installs it).
"""
import json
import shutil
import subprocess
from pathlib import Path

import pytest

from mech2spice.cli import main

ROOT = Path(__file__).resolve().parents[1]
ICARUS = shutil.which("iverilog") and shutil.which("vvp")
needs_icarus = pytest.mark.skipif(not ICARUS, reason="Icarus Verilog (iverilog, vvp) is not installed")


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


# ------------------------------------------------------------------ a design path is only that path

def test_montecarlo_on_a_missing_path_never_runs_the_shipped_design(tmp_path, capsys, monkeypatch):
    """`montecarlo DIR/adder2.v` with no such file used to run verilog/adder2.v instead."""
    monkeypatch.chdir(tmp_path)
    for missing in (tmp_path / "nowhere" / "adder2.v", "adder2.v"):
        refused(capsys, "montecarlo", missing, "--samples", "1", "--spread", "0", "--scheduler", "inline",
                needle=f"no such file: {missing}")
    for command in (["synth"], ["simulate", "--backend", "logic"], ["emit", "-o", tmp_path / "x.cir"]):
        refused(capsys, command[0], "adder2.v", *command[1:], needle="adder2.v: No such file")


# ------------------------------------------------------------------ the assembler's .tape

def test_tape_over_the_programs_own_code_is_refused(tmp_path, capsys):
    """A tape mapped over code used to assemble; the processor then fetched tape symbols and never halted."""
    source = (ROOT / "programs/tm_increment.asm").read_text()
    assert "        .equ MMR 255\n" in source
    over = tmp_path / "over.asm"
    over.write_text(source.replace(".equ MMR 255", ".equ MMR 3"))      # address 3: the loop's code
    line = 1 + source.splitlines().index("        .tape MMR 0 21222")
    err = refused(capsys, "cpu", "run", over, "--backend", "logic", "--max-cycles", "2000",
                  needle=f"{over}: line {line}: .tape at address 3 lies over the program")
    assert "line 11 puts a byte there" in err                           # LDNX_AB MMR: bytes 3, 4
    twice = tmp_path / "twice.asm"
    twice.write_text(source + "        .tape 254 0 1\n")
    refused(capsys, "cpu", "run", twice, "--backend", "logic", needle="a second .tape")
    rc, out, _ = run(capsys, "cpu", "run", ROOT / "programs/tm_increment.asm", "--backend", "logic")
    assert rc == 0 and "tape at 255" in out
