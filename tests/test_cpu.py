"""The 8-bit processor: ISA on the ISS and on the synthesized netlist (cycle for cycle), the
assembler, the sieve, the Turing-machine emulator, checkpoints and the command line."""

import argparse
import json
import random
import re
from pathlib import Path

import pytest

from mech2spice.cpu import tm
from mech2spice.cpu.asm import assemble, assemble_program
from mech2spice.cli.cpu import add_parser
from mech2spice.cpu.isa import CYCLES, MEM_SIZE, OPCODES
from mech2spice.cpu.iss import FETCH, ISS
from mech2spice.cpu.memory import Memory
from mech2spice.cpu.machines import LogicCPU
from mech2spice.cpu.netlist import cpu_netlist, register_map
from mech2spice.cpu.run import load_program, make_memory, run_program
from mech2spice.errors import Mech2SpiceError
from mech2spice.physics.params import load_params

ROOT = Path(__file__).resolve().parent.parent
PROGRAMS = ROOT / "programs"
A, B, C, D = 0xC5, 0x5A, 0x3C, 0x96       # A + B = 0x11F overflows; D has bit 7 set


@pytest.fixture(scope="module")
def netlist():
    return cpu_netlist()


def setup(a=A, b=B, c=C, d=D, *, tail="", data=""):
    """Load the registers (12 cycles), then `tail`; `data` goes at 0xC0 and up."""
    return (f"LDNX_AB {d}\nSWAP_AB\nSWAP_BD\nLDNX_AB {b}\nSWAP_AB\nLDNX_AB {c}\nSWAP_AC\n"
            f"LDNX_AB {a}\nunder_test: {tail}\n" + (f".org 0xC0\n{data}\n" if data else ""))


SETUP_CYCLES = 12


def lockstep(image, cycles, netlist=None):
    """Step the ISS (and the netlist, if given) `cycles` times, asserting identical cycles."""
    iss = ISS(Memory(image))
    logic = LogicCPU(Memory(image), netlist) if netlist is not None else None
    for _ in range(cycles):
        rec = iss.step()
        if logic is not None:
            assert logic.step() == rec
            assert logic.registers() == iss.registers(), f"cycle {rec.cycle} ({rec.instr})"
    if logic is not None:
        assert logic.mem.snapshot() == iss.mem.snapshot()
    return iss


# Each instruction from the same register values: expected registers (changed ones) after it.
EXPECTED = {
    "SWAP_AC": {"a": C, "c": A},
    "COPY_AC": {"c": A},
    "SWAP_AB": {"a": B, "b": A},
    "SWAP_BD": {"b": D, "d": B},
    "RSL_D": {"d": 0x4B},
    "RSA_D": {"d": 0xCB},
    "APLUSB_TO_D": {"d": 0x1F, "ov": 1},
    "ANORB_TO_C": {"c": 0x20},
    "NOT_C": {"c": 0xC3},
    "JMP_C": {"pc": C},
    "SAVE_AB": {},
    "LOAD_AB": {"b": 0x77},
    "SKPNX_A_GRT_B": {"pc": "+2"},                  # A > B: skips
    "SKPNX_A_DIF_B": {"pc": "+2"},                  # A != B: skips
    "SKPNX_OVER": {"pc": "+1"},                     # no add has overflowed yet
    "LDNX_AB": {"a": 0x42, "pc": "+2"},
}


def test_isa_has_the_16_named_instructions():
    assert sorted(OPCODES.values()) == list(range(16))
    assert set(OPCODES) == set(EXPECTED)
    assert {k for k, v in CYCLES.items() if v == 2} == {"LOAD_AB", "LDNX_AB"}


@pytest.mark.parametrize("name", list(OPCODES))
@pytest.mark.parametrize("level", ["iss", "logic"])
def test_each_instruction(name, level, request):
    tail = f"{name}\n.byte 0x42" if name == "LDNX_AB" else name
    image, _, sym = assemble(setup(tail=tail, data=".org 0xC5\n.byte 0x77"))
    net = request.getfixturevalue("netlist") if level == "logic" else None
    iss = lockstep(image, SETUP_CYCLES, net)
    start = dict(iss.registers(), pc=sym["under_test"])
    assert iss.registers() == start and start == {"pc": sym["under_test"], "a": A, "b": B, "c": C,
                                                    "d": D, "ov": 0, "phase": FETCH}
    iss = lockstep(image, SETUP_CYCLES + CYCLES[name], net)
    want = dict(start, pc=start["pc"] + 1)
    for reg, v in EXPECTED[name].items():
        want[reg] = start["pc"] + int(v) if isinstance(v, str) else v
    assert iss.registers() == want
    assert iss.mem.snapshot()[B] == (A if name == "SAVE_AB" else 0)


@pytest.mark.parametrize("name,a,b,skips", [
    ("SKPNX_A_GRT_B", 5, 5, False), ("SKPNX_A_GRT_B", 4, 5, False), ("SKPNX_A_GRT_B", 255, 0, True),
    ("SKPNX_A_DIF_B", 7, 7, False), ("SKPNX_A_DIF_B", 0, 128, True)])
def test_skip_conditions(name, a, b, skips):
    image, _, sym = assemble(setup(a=a, b=b, tail=name))
    iss = lockstep(image, SETUP_CYCLES + 1)
    assert iss.pc == sym["under_test"] + 1 + skips


@pytest.mark.parametrize("a,b,ov", [(0xC5, 0x5A, 1), (0x80, 0x7F, 0), (0xFF, 0x01, 1), (0, 0, 0)])
def test_add_and_overflow_skip(a, b, ov, netlist):
    image, _, sym = assemble(setup(a=a, b=b, tail="APLUSB_TO_D\nSKPNX_OVER"))
    iss = lockstep(image, SETUP_CYCLES + 2, netlist)
    assert (iss.d, iss.ov) == ((a + b) & 0xFF, ov)
    assert iss.pc == sym["under_test"] + 2 + ov


def test_halt_is_a_jump_to_itself():
    image, _, sym = assemble("LDNX_AB stop\nCOPY_AC\nstop: JMP_C")
    iss = ISS(image)
    assert iss.run(100) == (4, True) and iss.pc == sym["stop"]


def test_netlist_matches_iss_on_random_memory(netlist):
    """Random bytes as a program: every instruction with arbitrary operands, flow and writes."""
    rng = random.Random(7)
    for _ in range(3):
        image = bytes(rng.randrange(256) for _ in range(256))
        lockstep(image, 150, netlist)


def test_reset_from_any_power_up_state(netlist):
    """rst zeroes pc and the phase bits and blocks writes; the sieve then runs as from all-zero."""
    regmap = register_map(netlist)
    rng = random.Random(1)
    for _ in range(3):
        cpu = LogicCPU(make_memory(load_program(PROGRAMS / "sieve.asm")), netlist)
        cpu.logic.state = {q: rng.randrange(2) for q in cpu.logic.state}
        for rdata in (OPCODES["SAVE_AB"], rng.randrange(256)):
            assert cpu.logic.evaluate({"rst": 1, "rdata": rdata})["we"] == 0
            cpu.logic.tick({"rst": 1, "rdata": rdata})
            assert all(cpu.logic.state[q] == 0 for q in regmap if regmap[q][0] in ("pc", "ld", "nx"))
        assert cpu.run(1000) == (SIEVE_CYCLES, True)
        check_sieve({"memory": cpu.mem.snapshot(), "halted": True, "cycles": SIEVE_CYCLES})


def test_verilog_contract(netlist):
    src = (ROOT / "verilog" / "cpu.v").read_text()
    assert not re.search(r"\b(initial|negedge|tri)\b|'bz", src)
    assert netlist.clock == "clk"
    assert netlist.inputs == {"rst": 1, "rdata": 8}
    assert netlist.outputs == {"raddr": 8, "waddr": 8, "wdata": 8, "we": 1}
    assert len(netlist.latches()) == 43                  # pc, A..D (40), overflow, 2 phase bits
    assert len(netlist.gates()) < 1959                   # the paper's processor


# ------------------------------------------------------------------ assembler

def test_assembler_syntax():
    image, listing, sym = assemble("""
        .equ K 0x10        ; constants
    top: LDNX_AB K+1
         jmp_c             ; case-insensitive
    tab: .byte 0b101, top, tab+2, 255
         .org 12
    end: .byte K - 1
    """)
    assert list(image) == [0x0F, 0x11, 0x09, 5, 0, 5, 255, 0, 0, 0, 0, 0, 15]
    assert sym == {"K": 16, "top": 0, "tab": 3, "end": 12}
    assert "  0  0F 11" in listing and " 12  0F" in listing


@pytest.mark.parametrize("text,needle", [
    ("NOP", "line 1: unknown mnemonic 'NOP'"),
    ("\nLDNX_AB nowhere", "line 2: undefined label 'nowhere'"),
    (".byte 256", "line 1: value 256 = 256 is out of range"),
    (".byte 3-4", "out of range"),
    (".org 250\n.byte 1,2,3,4,5,6,7", "line 2: program too long"),
    ("x: SWAP_AC\nx: SWAP_AC", "line 2: 'x' is defined twice"),
    ("SWAP_AC 3", "line 1: SWAP_AC takes no operand"),
    (".org 5\n.org 2", "line 2: .org 2 would move backwards"),
    (".word 3", "unknown directive '.word'"),
    (".byte 0x1G", "cannot read the number '0x1G'"),
])
def test_assembler_errors(text, needle):
    with pytest.raises(Mech2SpiceError, match=needle.replace("(", r"\(").replace(".", r"\.")):
        assemble(text)


# ------------------------------------------------------------------ memory

def test_memory_decode_address_names_cycle_and_bit():
    assert Memory.decode_address([1, 0, 1, 0, 0, 0, 0, 1], 3, "raddr") == 133
    with pytest.raises(Mech2SpiceError, match=r"cycle 17: raddr bit 5 is invalid"):
        Memory.decode_address([0, 0, 0, 0, 0, None, 0, 0], 17, "raddr")


# ------------------------------------------------------------------ the sieve

COMPOSITES = [n for n in range(32) if any(n % k == 0 for k in range(2, n))]
SIEVE_CYCLES = 457          # measured; the paper's processor took 719


def check_sieve(res):
    arr = res["memory"][128:160]
    assert [n for n in range(32) if arr[n]] == COMPOSITES
    assert arr[0] == arr[1] == 0                       # 0 and 1 are never marked
    assert all(arr[n] == 0 for n in (2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31))
    assert res["halted"] and res["cycles"] == SIEVE_CYCLES


def test_sieve_on_iss():
    prog = load_program(PROGRAMS / "sieve.asm")
    assert len(prog.image) <= 48 and prog.symbols["halt"] == 6   # the program uses 6 as both
    res = run_program(PROGRAMS / "sieve.asm", "iss")
    check_sieve(res)
    untouched = [a for a in range(256) if not 128 <= a < 160]
    assert [res["memory"][a] for a in untouched] == [(prog.image + bytes(256))[a] for a in untouched]


def test_sieve_on_logic_level_netlist():
    iss, logic = (run_program(PROGRAMS / "sieve.asm", b) for b in ("iss", "logic"))
    check_sieve(logic)
    assert logic["memory"] == iss["memory"] and logic["registers"] == iss["registers"]


# ------------------------------------------------------------------ Turing machines

def test_generated_programs_are_up_to_date():
    for name, text in tm.program_sources().items():
        assert (PROGRAMS / name).read_text() == text, f"regenerate programs/{name}"


def test_minsky_table_simulates_tag_systems():
    """The transcribed table is checked by what it computes: the tag words appear on the tape."""
    for rules, word in ([[0], [1, 2], None], [1, 1, 1]), ([[1, 0, 0], [2], None], [0, 0, 0]):
        words, ref = tm.utm_words(rules, word, 20000)
        assert ref.halted and words == tm.tag_system_run(rules, word, 50)[1:]


def emulate(name, machine, cpu_factory=None, max_cycles=200_000):
    text = (PROGRAMS / name).read_text()
    prog = assemble_program(text)
    emu = tm.run_emulation(text, max_cycles, cpu_factory)
    ref = tm.compare_emulation(machine, prog.tape.cells, prog.tape.head, emu)
    return emu, ref


def test_increment_machine_on_iss_and_netlist(netlist):
    emu, ref = emulate("tm_increment.asm", tm.INCREMENT)
    assert emu["halted"] and ref.halted and len(ref.steps) == emu["tape"].steps == 10
    assert emu["tape"].digits() == tm.INCREMENT.encode("11000")       # 10111 + 1
    emu2, _ = emulate("tm_increment.asm", tm.INCREMENT, lambda mem: LogicCPU(mem, netlist))
    assert emu2["cycles"] == emu["cycles"] and emu2["tape"].log == emu["tape"].log


def test_minsky_utm_on_iss_to_its_halt():
    emu, ref = emulate("tm_minsky.asm", tm.MINSKY)
    assert emu["halted"] and ref.halted
    assert emu["tape"].steps == len(ref.steps) == 1869 and emu["tape"].idle == 1
    assert emu["tape"].state()["cells"] == ref.tape.state()["cells"]


@pytest.mark.slow
def test_minsky_utm_on_netlist(netlist):
    emu, ref = emulate("tm_minsky.asm", tm.MINSKY, lambda mem: LogicCPU(mem, netlist))
    assert emu["halted"] and emu["tape"].steps == 1869


# ------------------------------------------------------------------ runner, checkpoints, CLI

@pytest.mark.parametrize("backend,program,stop", [("iss", "sieve.asm", 200), ("logic", "sieve.asm", 150),
                                                  ("iss", "tm_increment.asm", 100)])
def test_checkpoint_resume_gives_the_same_result(tmp_path, backend, program, stop):
    path, ck = PROGRAMS / program, tmp_path / "ck.json"
    whole = run_program(path, backend, 100_000)
    part = run_program(path, backend, stop, checkpoint=ck, checkpoint_every=40)
    assert not part["halted"] and part["cycles"] == stop and json.loads(ck.read_text())["cycle"] == stop
    done = run_program(path, backend, 100_000, checkpoint=ck, resume=True)
    for key in ("cycles", "halted", "memory", "registers", "devices"):
        assert done.get(key) == whole.get(key), key


def test_checkpoint_errors(tmp_path):
    ck = tmp_path / "ck.json"
    run_program(PROGRAMS / "sieve.asm", "iss", 10, checkpoint=ck)
    with pytest.raises(Mech2SpiceError, match="different program"):
        run_program(PROGRAMS / "tm_increment.asm", "iss", 10, checkpoint=ck, resume=True)
    with pytest.raises(Mech2SpiceError, match="written by the iss backend"):
        run_program(PROGRAMS / "sieve.asm", "logic", 10, checkpoint=ck, resume=True)
    with pytest.raises(Mech2SpiceError, match="needs a checkpoint"):
        run_program(PROGRAMS / "sieve.asm", "iss", 10, resume=True)
    ck.write_text("{")
    with pytest.raises(Mech2SpiceError, match="not valid JSON"):
        run_program(PROGRAMS / "sieve.asm", "iss", 10, checkpoint=ck, resume=True)


def test_unknown_backend_is_refused():
    with pytest.raises(Mech2SpiceError, match="unknown backend 'spice'"):
        run_program(PROGRAMS / "sieve.asm", "spice", 10)


def cli(argv):
    ap = argparse.ArgumentParser()
    add_parser(ap.add_subparsers(dest="command", required=True))
    args = ap.parse_args(argv)
    return args.func(args)


def test_cli_asm_and_run(tmp_path, capsys):
    out = tmp_path / "sieve.bin"
    assert cli(["cpu", "asm", str(PROGRAMS / "sieve.asm"), "-o", str(out), "--listing"]) == 0
    assert out.read_bytes() == load_program(PROGRAMS / "sieve.asm").image
    assert "SAVE_AB" in capsys.readouterr().out
    assert cli(["cpu", "run", str(out), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["halted"] and res["cycles"] == SIEVE_CYCLES and res["backend"] == "iss"
    assert cli(["cpu", "run", str(PROGRAMS / "sieve.asm"), "--max-cycles", "5"]) == 1
    assert "did not halt after 5 cycles" in capsys.readouterr().out


def test_cli_user_errors(tmp_path):
    bad = tmp_path / "bad.asm"
    bad.write_text("SWAP_AC\nFLY\n")
    with pytest.raises(Mech2SpiceError, match=r"bad\.asm: line 2: unknown mnemonic 'FLY'"):
        cli(["cpu", "run", str(bad)])
    with pytest.raises(Mech2SpiceError, match="cannot read program"):
        cli(["cpu", "run", str(tmp_path / "missing.asm")])
    with pytest.raises(Mech2SpiceError, match="expected an assembly source"):
        cli(["cpu", "asm", str(tmp_path / "x.bin"), "-o", str(tmp_path / "y.bin")])


@pytest.mark.parametrize("name, content, needle", [
    ("empty.bin", b"", "is empty"),
    ("tiny.s", b"halt: JMP_C\n", "is text, not a memory image"),      # ran its letters as opcodes, exit 1
    ("adder2.v", (ROOT / "verilog" / "adder2.v").read_bytes(), "is text"),
    ("big.bin", bytes(MEM_SIZE + 1), "at most 256"),
])
def test_a_program_that_is_no_memory_image_is_refused(tmp_path, name, content, needle):
    """Any file not named .asm ran as raw machine code (hostile-input pass, session 21): a source under another
    name, an empty file."""
    (tmp_path / name).write_bytes(content)
    with pytest.raises(Mech2SpiceError, match=needle):
        cli(["cpu", "run", str(tmp_path / name)])


def test_sieve_at_envelope_fidelity_matches_iss_and_resumes_exactly(tmp_path):
    """The processor as 6486 oscillators (envelope model, settle detection on) against the behavioural
    memory: the first cycles equal the ISS, and a run interrupted at a checkpoint continues from the saved
    oscillator state to exactly the same amplitudes as an uninterrupted run."""
    from mech2spice.cpu import run as R
    from mech2spice.cpu.iss import ISS
    prog = R.load_program(PROGRAMS / "sieve.asm")
    iss = ISS(R.make_memory(prog))
    seen = []

    def trace(rec, cpu):
        seen.append((rec == iss.step(), cpu.registers() == iss.registers(), dict(cpu.amps)))

    whole = run_program(PROGRAMS / "sieve.asm", "envelope", 4, trace=trace)
    assert all(a and b for a, b, _ in seen) and len(seen) == 4
    assert whole["simulated_periods"] < whole["periods"]          # settled pauses were skipped
    ck = tmp_path / "ck.json"
    run_program(PROGRAMS / "sieve.asm", "envelope", 2, checkpoint=ck)
    state_file = R.checkpoint_state_file(ck)
    assert state_file.exists() and len(list(tmp_path.glob("ck.json.state-*.npz"))) == 1   # old ones removed
    amps = []
    done = run_program(PROGRAMS / "sieve.asm", "envelope", 4, checkpoint=ck, resume=True,
                       trace=lambda rec, cpu: amps.append(dict(cpu.amps)))
    for key in ("cycles", "memory", "registers", "periods", "simulated_periods"):
        assert done[key] == whole[key], key
    assert amps == [a for _, _, a in seen[2:]]                    # bit-for-bit the same trajectory
    R.checkpoint_state_file(ck).write_bytes(b"junk")
    with pytest.raises(Mech2SpiceError, match="does not match its checkpoint"):
        run_program(PROGRAMS / "sieve.asm", "envelope", 4, checkpoint=ck, resume=True)


def test_processor_step_within_a_faster_blocks_bound():
    """centered2 (low Qs: envelope rates bound its ETDRK4 step at 15.6 periods, its RK4 one at 6.4) runs the
    processor at the longest whole step within that bound, not the default block's 16 (which the engine
    refuses), and its first cycle equals the ISS."""
    res = run_program(PROGRAMS / "sieve.asm", "envelope", 1, p=load_params("centered2"))
    assert res["step"] == 8.0 and res["cycles"] == 1 and res["iss_check"]["mismatches"] == 0


def test_register_map_refuses_a_latch_with_a_set_or_reset(tmp_path):
    """The processor's state is read from D latches fed by next_<reg> nets; an asynchronously reset register
    (a latch with a forcing input) is one clear refusal, not an unpacking error."""
    from mech2spice import Mech2SpiceError
    from mech2spice.synthesis import synth
    src = tmp_path / "r.v"
    src.write_text("module r(input clk, input rst, input d, output reg q);\n"
                   "  always @(posedge clk or posedge rst) if (rst) q <= 1'b0; else q <= d;\nendmodule\n")
    with pytest.raises(Mech2SpiceError, match="set/reset"):
        register_map(synth.synthesize(str(src)))
