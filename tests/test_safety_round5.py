"""Safe with anyone's files, round 5: the session-26 hostile pass's findings left open then, fixed in session 27
(each test fails on the code before its fix)."""
from __future__ import annotations

import json

import pytest

from mech2spice import api
from mech2spice.errors import Mech2SpiceError

INVERTER = "module inv(input a, output y);\n  assign y = ~a;\nendmodule\n"


# ------------------------------------------------------------------ a drive no engine can step with the gates

@pytest.mark.parametrize("omega", [1e-300, 1e300])
@pytest.mark.parametrize("backend", ["carrier", "rk4", "envelope"])
def test_a_drive_frequency_far_from_every_oscillator_is_refused_not_decoded(tmp_path, backend, omega):
    """The carrier at omega = 1e-300 decoded a NaN phasor as amplitude 0.0 and reported 'invalid' (exit 1)."""
    design = tmp_path / "inv.v"
    design.write_text(INVERTER)
    params = tmp_path / "p.json"
    params.write_text(json.dumps({"omega": omega}))
    with pytest.raises(Mech2SpiceError, match="own frequency sqrt"):
        api.simulate(str(design), {"a": 1}, backend=backend, params=str(params))


# ------------------------------------------------------------------ a source no simulator accepts is not built

def test_a_net_assigned_in_an_always_block_is_refused_with_its_line(tmp_path):
    """VTR's multiclock_reader_writer.v assigns `output out` (a net) in an always block: Icarus and every
    simulator refuse the file, Yosys warned and synth built a network from it without a word."""
    from mech2spice.synthesis.synth import synthesize
    bad = tmp_path / "t.v"
    bad.write_text("module t(input clk, input d, output out);\n  always @(posedge clk) out <= d;\nendmodule\n")
    with pytest.raises(Mech2SpiceError, match=r"t\.v, line 2: 'out' is a net .* declare it `reg`"):
        synthesize(bad)
    good = tmp_path / "g.v"
    good.write_text("module t(input clk, input d, output reg out);\n  always @(posedge clk) out <= d;\nendmodule\n")
    assert synthesize(good).outputs == {"out": 1}


FUNCTION_ASSIGNS_ITS_INPUT = """module f #(parameter N = 8, W = clogb2(N)) (input [W-1:0] a, output [W-1:0] y,
                                         output [3:0] ones_a);
  function integer clogb2;
    input [31:0] depth;
    for (clogb2 = 0; depth > 0; clogb2 = clogb2 + 1)
      depth = depth >> 1;
  endfunction
  function [3:0] ones;
    input [3:0] v;
    integer i;
    begin
      ones = 0;
      for (i = 0; i < 4; i = i + 1) begin
        ones = ones + v[0];
        v = v >> 1;
      end
    end
  endfunction
  assign y = ~a;
  assign ones_a = ones(a);
endmodule
"""


def test_a_function_that_assigns_its_own_input_is_verilog_and_is_built(tmp_path):
    """Public RTL pass 10: a function's inputs are its variables (IEEE 1364 10.4.1), and a clog2 that shifts its
    `depth` in a parameter's default was refused as a net assigned in an always block (Yosys warns about the
    function's variables as it does about nets).  Built, and equal to Icarus on every input."""
    from mech2spice import verify
    src = tmp_path / "f.v"
    src.write_text(FUNCTION_ASSIGNS_ITS_INPUT)
    result = verify.verify(str(src), backend="logic")
    assert result["verdict"] == "pass" and result["equivalence"]["status"] == "proved"
    assert result["cosim"]["exhaustive"] and result["cosim"]["mismatches"] == []


# ------------------------------------------------------------------ an output port nothing drives

UNUSED_FLAGS = """module alu(input [1:0] a, input [1:0] b, output [2:0] s, output carry, output [1:0] flags);
  assign s[1:0] = a ^ b;
  assign flags[0] = a[0] & b[0];
endmodule
"""


def test_an_output_nothing_drives_is_built_warned_and_left_out_of_verify(tmp_path, capsys):
    """RTLLM's RISC-V ALU declares `carry`, `negative` and `overflow` and never assigns them: synth refused the
    whole design.  Verilog reads z there; the network has a constant 0; verify compares the other bits
    (exhaustively here) and says which it left out."""
    import json

    from mech2spice.cli import main
    from mech2spice.synthesis.synth import synthesize
    src = tmp_path / "alu.v"
    src.write_text(UNUSED_FLAGS)
    nl = synthesize(src)
    err = capsys.readouterr().err
    assert nl.undriven == ("s[2]", "carry[0]", "flags[1]")
    assert all(f"output {p} is driven by nothing" in err for p in ("s", "carry", "flags"))
    assert main(["verify", str(src), "--exhaustive", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    co = res["cosim"]
    assert res["verdict"] == "pass" and res["equivalence"]["status"] == "proved"
    assert co["driven_by_nothing"] == ["s[2]", "carry[0]", "flags[1]"] and co["undriven_bits"] == 0
    assert co["undefined_by_port"]["s"] == {"x": 0, "z": 0, "compared": 2 * 16}
    # a wrong network still fails on the bits that are compared
    from mech2spice import verify as v
    x = v.make_vectors(nl, 16, True, 0)[0]
    ref = v.icarus(str(src), nl, x, False, [], {})
    got = [{"bits": {**{b: int(r[b]) for b in r if r[b] in "01"}, "s[0]": 1 - int(r["s[0]"])}} for r in ref]
    assert {m["bit"] for m in v.compare(nl, x, ref, got, False)} == {"s[0]"}


def test_an_undriven_output_of_a_submodule_read_by_its_parent_is_still_refused(tmp_path):
    from mech2spice.synthesis.synth import synthesize
    src = tmp_path / "h.v"
    src.write_text("module sub(input a, output s, output t);\n  assign s = ~a;\nendmodule\n"
                   "module top(input a, output y, output w);\n  wire tt;\n  sub i(.a(a), .s(y), .t(tt));\n"
                   "  assign w = tt;\nendmodule\n")
    with pytest.raises(Mech2SpiceError, match="in module sub, 't' is used but nothing drives it"):
        synthesize(src, top="top")


# ------------------------------------------------------------------ a hand-edited checkpoint is not resumed

def _edited_checkpoint(tmp_path, edit):
    from pathlib import Path

    from mech2spice.cli import main
    program = Path(__file__).resolve().parents[1] / "programs" / "tm_increment.asm"
    ck = tmp_path / "ck.json"
    assert main(["cpu", "run", str(program), "--backend", "iss", "--checkpoint", str(ck), "--checkpoint-every", "5",
                 "--max-cycles", "50"]) == 1                  # not halted yet: exit 1
    state = json.loads(ck.read_text())
    edit(state)
    ck.write_text(json.dumps(state))
    return program, ck


def _tape(state):
    return state["devices"]["255"]


@pytest.mark.parametrize("edit, needle", [
    (lambda s: _tape(s)["cells"].__setitem__(str(_tape(s)["head"]), 999), "holds 999; a tape symbol is 0..7"),
    (lambda s: _tape(s)["cells"].__setitem__("1", 10 ** 30), "a tape symbol is 0..7"),
    (lambda s: _tape(s)["cells"].__setitem__("\u0663", 1), "is not a whole number in ASCII digits"),
    (lambda s: _tape(s).__setitem__("steps", -7), "'steps' must be a whole number >= 0"),
    (lambda s: s.__setitem__("halted", True), "'halted' is true but the machine is not at a halt"),
])
def test_a_checkpoint_edited_to_an_impossible_state_is_refused(tmp_path, capsys, edit, needle):
    """Tape cells of 999, 256 or 10**30, a cell keyed by an Arabic-Indic digit, negative counts and `halted`
    at a state that has not halted all resumed and exited 0 on wrong state."""
    from mech2spice.cli import main
    program, ck = _edited_checkpoint(tmp_path, edit)
    capsys.readouterr()
    assert main(["cpu", "run", str(program), "--backend", "iss", "--checkpoint", str(ck), "--resume"]) == 2
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1


def test_a_checkpoint_written_at_the_halt_resumes_as_halted(tmp_path, capsys):
    from pathlib import Path

    from mech2spice.cli import main
    program = Path(__file__).resolve().parents[1] / "programs" / "tm_increment.asm"
    ck = tmp_path / "ck.json"
    assert main(["cpu", "run", str(program), "--backend", "iss", "--checkpoint", str(ck)]) == 0
    assert json.loads(ck.read_text())["halted"] is True
    assert main(["cpu", "run", str(program), "--backend", "iss", "--checkpoint", str(ck), "--resume"]) == 0


# ------------------------------------------------------------------ a Monte-Carlo record the run could not write

@pytest.fixture(scope="module")
def mc_results(tmp_path_factory):
    """A genuine 2-sample results file of the inverter (envelope, 0.1 % spread), written once."""
    from mech2spice.cli import main
    folder = tmp_path_factory.mktemp("mc")
    design = folder / "inv.v"
    design.write_text(INVERTER)
    out = folder / "r.jsonl"
    assert main(["montecarlo", str(design), "--samples", "2", "--spread", "0.001", "--scheduler", "inline",
                 "--out", str(out), "--json"]) in (0, 1)
    return design, out.read_text().splitlines()


def _resumed(capsys, tmp_path, mc_results, edit):
    from mech2spice.cli import main
    design, lines = mc_results
    records = [json.loads(line) for line in lines]
    edit(records)
    out = tmp_path / "w.jsonl"
    out.write_text("".join(json.dumps(r) + "\n" for r in records))
    capsys.readouterr()
    code = main(["montecarlo", str(design), "--samples", "2", "--spread", "0.001", "--scheduler", "inline",
                 "--out", str(out), "--json"])
    return code, capsys.readouterr().err


def _flip(records):
    records[1].update({"pass": not records[1]["pass"]})


@pytest.mark.parametrize("edit, needle", [
    (_flip, "sample 0 "),
    (lambda r: r[1].update(failing_gates=["nonexistent"]), "names 'nonexistent', which is no output bit or gate"),
    (lambda r: r[1].update(failing_bits={"y[0]": 3}, **{"pass": False}), "failing more often than the 2 input"),
    (lambda r: r.append({**r[1], "margin": -5.0, "pass": False, "failing_bits": {"y[0]": 1}}),
     "sample 0 is given again with other values"),
])
def test_a_results_record_the_run_could_not_have_written_is_refused(capsys, tmp_path, mc_results, edit, needle):
    """A sample flipped to `pass: true` with a wrong bit and a negative margin counted as passing (yield 1.0,
    exit 0); a gate the design does not have was reported failing; a sample given twice was read silently."""
    code, err = _resumed(capsys, tmp_path, mc_results, edit)
    assert code == 2 and needle in err and err.count("\n") == 1, err


def test_a_genuine_results_file_resumes(capsys, tmp_path, mc_results):
    code, err = _resumed(capsys, tmp_path, mc_results, lambda r: None)
    assert code in (0, 1) and "error" not in err


# ------------------------------------------------------------------ a report refused before it writes anything

def test_a_report_refused_for_its_options_leaves_no_folder_and_no_file(tmp_path, capsys):
    """`report gate --render` created an empty --out folder before finding no gate.json in it, and `report
    cpu_physical --checkpoint PROGRAM` wrote cpu_physical_failed.md before refusing to overwrite the program."""
    from pathlib import Path

    from mech2spice.cli import main
    out = tmp_path / "r1"
    assert main(["report", "gate", "--render", "--out", str(out)]) == 2
    assert "does not exist: --render draws from the JSON" in capsys.readouterr().err and not out.exists()
    program = tmp_path / "p.asm"
    program.write_text((Path(__file__).resolve().parents[1] / "programs" / "tm_increment.asm").read_text())
    kept = program.read_text()
    out.mkdir()
    assert main(["report", "cpu_physical", "--program", str(program), "--checkpoint", str(program),
                 "--out", str(out), "--cycles", "5"]) == 2
    err = capsys.readouterr().err
    assert "is the program" in err.splitlines()[-1] and err.count("mech2spice: error:") == 1
    assert list(out.iterdir()) == [] and program.read_text() == kept


def test_an_unreproduced_counterexample_of_a_combinational_design_names_x_or_z_not_a_start_state(tmp_path, capsys):
    """RTLLM's ALU (a `reg` set to `'bz` in a case default, a tri-state flag): the proof's counterexample did not
    replay, and verify blamed "the start state" of a design that has none."""
    from mech2spice.cli import main
    src = tmp_path / "tri.v"
    src.write_text("module f(input [1:0] op, input a, output reg r, output flag);\n"
                   "  assign flag = (op == 2'd0) ? a : 1'bz;\n"
                   "  always @(op or a)\n    case (op)\n      2'd0: r <= a;\n      2'd1: r <= ~a;\n"
                   "      default: r <= 1'bz;\n    endcase\nendmodule\n")
    assert main(["verify", str(src), "--exhaustive", "--json"]) == 1
    eq = json.loads(capsys.readouterr().out)["equivalence"]
    assert eq["status"] == "unknown" and "the source reads x or z where they differ" in eq["detail"]
    assert "start state" not in eq["detail"]


# ------------------------------------------------------------------ messages that say what is wrong, in our words

ADDER = "module add(input [1:0] a, input [1:0] b, output [2:0] s);\n  assign s = a + b;\nendmodule\n"


@pytest.mark.parametrize("value, code, needle", [
    ("09", 2, "value 9 does not fit input 'a'"),   # a leading zero: decimal 9 (was "'09' is not an integer")
    ("0x2", 0, None),
    ("\u0663", 2, "is not a whole number (decimal, 0x, 0b or 0o)"),     # Arabic-Indic 3 was read as 3
    ("9" * 5000, 2, "a number of 5,000 characters (at most 1,000 are read)"),
])
def test_a_set_value_is_an_ascii_whole_number(tmp_path, capsys, value, code, needle):
    from mech2spice.cli import main
    src = tmp_path / "add.v"
    src.write_text(ADDER)
    assert main(["simulate", str(src), "--backend", "logic", "--set", f"a={value}", "--set", "b=1"]) == code
    err = capsys.readouterr().err
    assert (needle in err and len(err) < 300) if needle else err == ""


@pytest.mark.parametrize("content, needle", [
    (b"\xef\xbb\xbf[]", "begins with a UTF-8 byte-order mark"),
    (b'[{"cycles": ' + b"9" * 5000 + b"}]", "an integer of more than 4,300 digits"),
    (b'[{"cycles": true}]', "'cycles' must be a whole number >= 0, not true"),
    (b'[{"set": null, "cycles": 1}]', "'set' must map port names to integers, not null"),
])
def test_a_stimulus_file_is_described_in_json_terms(tmp_path, capsys, content, needle):
    """Python's advice ("use sys.set_int_max_str_digits()", "decode using utf-8-sig") and spellings ("got True")
    reached the user; `"set": null` was read as no inputs."""
    from mech2spice.cli import main
    src = tmp_path / "c.v"
    src.write_text("module c(input clk, input en, output reg q);\n  always @(posedge clk) if (en) q <= ~q;\n"
                   "endmodule\n")
    stim = tmp_path / "s.json"
    stim.write_bytes(content)
    assert main(["simulate", str(src), "--backend", "logic", "--stimulus", str(stim)]) == 2
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1 and "sys.set_int" not in err and "utf-8-sig" not in err


def test_a_reset_with_an_empty_level_is_refused(tmp_path, capsys):
    """`--reset rst=` was read as `--reset rst` (its level from the name)."""
    from mech2spice.cli import main
    src = tmp_path / "c.v"
    src.write_text("module c(input clk, input rst, output reg q);\n  always @(posedge clk) q <= rst ? 1'b0 : ~q;\n"
                   "endmodule\n")
    assert main(["verify", str(src), "--reset", "rst=", "--cycles", "4"]) == 2
    assert "nothing after '=': give the level" in capsys.readouterr().err


def test_an_assembly_number_too_long_is_one_short_line_and_a_bom_is_no_mnemonic(tmp_path, capsys):
    from mech2spice.cli import main
    src = tmp_path / "d.asm"
    src.write_text("LDNX_AB " + "9" * 5000 + "\n")
    assert main(["cpu", "asm", str(src), "-o", str(tmp_path / "d.img")]) == 2
    err = capsys.readouterr().err
    assert "(5,000 digits) is out of range" in err and len(err) < 300
    bom = tmp_path / "b.asm"
    bom.write_bytes(b"\xef\xbb\xbfstart: JMP_C\n")
    assert main(["cpu", "asm", str(bom), "-o", str(tmp_path / "b.img")]) == 0
    assert (tmp_path / "b.img").read_bytes() == bytes([0x09])


# ------------------------------------------------------------------ a stated reset the design contradicts

@pytest.mark.parametrize("reset, note", [
    ("rst=0", "--reset rst=0, but the source's flip-flops reset synchronously on rst=1"),
    ("en=1", "reset synchronously on rst=1, which --reset leaves out"),
    ("rst=1", None),
])
def test_a_stated_reset_that_contradicts_the_design_is_named(tmp_path, capsys, reset, note):
    """`verify counter4.v --reset rst=0` (its flip-flops reset on rst=1) passed without a word."""
    from pathlib import Path

    from mech2spice.cli import main
    src = Path(__file__).resolve().parents[1] / "verilog" / "counter4.v"
    main(["verify", str(src), "--reset", reset, "--cycles", "20", "--json"])
    res = json.loads(capsys.readouterr().out)
    assert len(res["reset_notes"]) == (0 if note is None else 1) and res["verdict"] == "pass"
    main(["verify", str(src), "--reset", reset, "--cycles", "20"])
    out = capsys.readouterr().out
    if note:
        assert note in res["reset_notes"][0] and f"  reset: {res['reset_notes'][0]}" in out
    else:
        assert "  reset:" not in out
