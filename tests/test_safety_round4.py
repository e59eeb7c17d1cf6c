"""Safe with anyone's files, round 4: what the hostile-input pass of session 26 found (its reproducers were
outside the repository; each test below fails on the code before its fix)."""
from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from test_output_paths import intact, keep, refused, write

from mech2spice import api
from mech2spice.errors import Mech2SpiceError

PROGRAM = Path(__file__).resolve().parents[1] / "programs" / "tm_increment.asm"
INVERTER = "module inv(input a, output y);\n  assign y = ~a;\nendmodule\n"


# ------------------------------------------------------------------ a checkpoint replaced whole, never a device

def test_a_checkpoint_is_never_put_in_place_of_a_pipe(capsys, tmp_path):
    """`cpu run --checkpoint /dev/null` replaced the system's /dev/null with a file (the pass ran as root): a
    rename puts a file where the device was.  A named pipe stands in for the device here."""
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    refused(capsys, {}, "cpu", "run", PROGRAM, "--backend", "iss", "--checkpoint", fifo,
            needle="is not a regular file (a device or a pipe)")
    assert stat.S_ISFIFO(fifo.stat().st_mode)


def test_a_link_left_under_the_temporary_name_is_never_written_through(capsys, tmp_path):
    """The temporary file had a fixed name (PATH.tmp), opened through any link found there."""
    precious = write(tmp_path / "keep.txt", "precious\n")
    kept = keep(precious)
    (tmp_path / "ck.json.tmp").symlink_to(precious)
    from mech2spice.cli import main
    assert main(["cpu", "run", str(PROGRAM), "--backend", "iss", "--checkpoint", str(tmp_path / "ck.json")]) == 0
    capsys.readouterr()
    intact(kept)
    assert (tmp_path / "ck.json").is_file() and not (tmp_path / "ck.json").is_symlink()


def test_a_resumed_trace_is_never_put_in_place_of_a_pipe(capsys, tmp_path):
    from mech2spice.cli import main
    ck = tmp_path / "ck.json"
    assert main(["cpu", "run", str(PROGRAM), "--backend", "iss", "--checkpoint", str(ck), "--checkpoint-every", "5",
                 "--max-cycles", "20"]) in (0, 1)
    capsys.readouterr()
    fifo = tmp_path / "trace"
    os.mkfifo(fifo)
    refused(capsys, {}, "cpu", "run", PROGRAM, "--backend", "iss", "--checkpoint", ck, "--resume", "--trace", fifo,
            needle="trace")
    assert stat.S_ISFIFO(fifo.stat().st_mode)


# ------------------------------------------------------------------ --force never replaces a file the design reads

@pytest.fixture
def including(tmp_path):
    design = write(tmp_path / "ci.v", '`include "inc.vh"\nmodule ci(input clk, input rst, output reg q);\n'
                                      " always @(posedge clk) q <= `V;\nendmodule\n")
    inc = write(tmp_path / "inc.vh", "`define V ~rst\n")
    return design, inc


def test_simulate_vcd_with_force_never_writes_over_an_included_file(capsys, tmp_path, including):
    design, inc = including
    stim = write(tmp_path / "st.json", '[{"set": {"rst": 1}, "cycles": 2}]')
    refused(capsys, keep(design, inc, stim), "simulate", design, "--backend", "logic", "--stimulus", stim,
            "--vcd", inc, "--force", needle='is `include "inc.vh" of')


def test_domain_map_with_force_never_writes_over_an_included_file(capsys, tmp_path):
    design = write(tmp_path / "aj.v", '`include "m.json"\nmodule aj(input [1:0] a, output [1:0] y);\n'
                                      "  assign y = `W;\nendmodule\n")
    inc = write(tmp_path / "m.json", "`define W ~a\n")
    refused(capsys, keep(design, inc), "domain", design, "--sweep", "freq=0:1e-3:2", "--sweep", "amp=0:0.1:2",
            "-o", tmp_path / "m.png", "--force", needle='is `include "m.json" of')


def test_no_output_writes_over_a_rom_the_design_reads(capsys, tmp_path):
    design = write(tmp_path / "rom.v", "module rom(input [1:0] a, output [7:0] q);\n  reg [7:0] mem [0:3];\n"
                                       '  initial $readmemh("rom.hex", mem);\n  assign q = mem[a];\nendmodule\n')
    rom = write(tmp_path / "rom.hex", "12 34 56 78\n")
    refused(capsys, keep(design, rom), "verify", design, "--junit", rom, "--force",
            needle='the $readmem file "rom.hex" of')


# ------------------------------------------------------------------ named pipes: never a wait for ever

def test_a_named_pipe_given_as_an_input_is_refused_at_once(capsys, tmp_path):
    design = write(tmp_path / "inv.v", INVERTER)
    fifo = tmp_path / "params.json"
    os.mkfifo(fifo)
    refused(capsys, keep(design), "synth", design, "--params", fifo, needle="a named pipe, not a file")


def test_a_named_pipe_nothing_reads_is_refused_as_an_output(capsys, tmp_path, including):
    design, inc = including
    stim = write(tmp_path / "st.json", '[{"set": {"rst": 1}, "cycles": 2}]')
    fifo = tmp_path / "wave.vcd"
    os.mkfifo(fifo)
    refused(capsys, keep(design, stim), "simulate", design, "--backend", "logic", "--stimulus", stim,
            "--vcd", fifo, needle="a named pipe that nothing reads")


# ------------------------------------------------------------------ parameters the envelope cannot hold

def test_an_omega_whose_square_overflows_is_one_line_and_the_apis_error(capsys, tmp_path):
    """{"omega": 1e300}: numpy's LinAlgError from ARPACK, a traceback (exit 3), and the same error from the API.
    Since session 27 the model's own check refuses it first (every oscillator's frequency ~1e-298 of the drive's)."""
    design = write(tmp_path / "inv.v", INVERTER)
    params = write(tmp_path / "huge.json", '{"omega": 1e300}')
    refused(capsys, keep(design, params), "simulate", design, "--backend", "envelope", "--set", "a=1",
            "--params", params, needle="times the drive's (omega = 1e+300 rad/s)")
    with pytest.raises(Mech2SpiceError, match="own frequency"):
        api.simulate(str(design), {"a": 1}, backend="envelope", params=str(params))


def test_a_port_named_with_a_leading_dollar_is_refused_in_one_line(capsys, tmp_path):
    """`input \\$a `: Yosys keeps its backslash (its own names start with `$`), so `--set '$a=1'` was an unknown
    port and verify's testbench named a port the design does not have (an Icarus error about it)."""
    design = write(tmp_path / "d.v", "module t(input \\$a , output y);\n  assign y = ~\\$a ;\nendmodule\n")
    refused(capsys, keep(design), "synth", design, needle="port '$a' (written `\\$a `) begins with `$`")


@pytest.mark.parametrize("text", ["", "; only a comment\n\n"], ids=["empty", "comment_only"])
def test_an_assembly_file_with_nothing_in_it_is_refused_not_run(capsys, tmp_path, text):
    """It ran an all-zero memory and said "did not halt" (exit 1); `cpu asm` wrote a 0-byte image."""
    src = write(tmp_path / "empty.asm", text)
    refused(capsys, keep(src), "cpu", "run", src, "--backend", "iss", "--max-cycles", "100",
            needle="assembles to no bytes")
    refused(capsys, keep(src), "cpu", "asm", src, "-o", tmp_path / "out.bin", needle="assembles to no bytes")
    assert not (tmp_path / "out.bin").exists()


@pytest.mark.parametrize("sweep, needle", [("freq=0:inf:2", "HI is 'inf': a finite number is needed"),
                                           ("freq=nan", "VALUE is 'nan'"),
                                           ("freq=0:1e-3:2.5", "N is '2.5': a whole number of points")])
def test_a_sweep_bound_that_is_no_finite_number_is_named(capsys, sweep, needle):
    """`freq=0:inf:2` made numpy warn and read the axis as nan; `N = 2.5` got Python's int() wording."""
    refused(capsys, {}, "domain", "gate", "--sweep", sweep, "--sweep", "amp=0:0.1:2", needle=needle)


def test_control_characters_from_a_file_are_escaped_in_the_message(capsys, tmp_path):
    """A NUL hid the rest of a port's name on a terminal, and an ESC sequence reached it (turning it red)."""
    stim = write(tmp_path / "st.json", '[{"set": {"r\\u001b[31mst\\u0000": 1}, "cycles": 1}]')
    counter = Path(__file__).resolve().parents[1] / "verilog" / "counter4.v"
    err = refused(capsys, keep(stim), "simulate", counter, "--backend", "logic", "--stimulus", stim,
                  needle="'r\\x1b[31mst\\x00'")
    assert "\x1b" not in err and "\x00" not in err
