"""The processor in VACASK (#17): the Verilog-A memory alone (fast), the whole processor netlist (slow)."""
from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest

from mech2spice.errors import Mech2SpiceError, ToolMissingError
from mech2spice.physics.params import DEFAULT, NOMINAL0, NOMINAL1


def _vacask():
    from mech2spice.spice import openvaf
    try:
        return openvaf.tools()
    except ToolMissingError:
        pytest.skip("VACASK not installed")


def _bus(name: str, value: int, bits: int) -> list[str]:
    """Amplitude sources (u_R: band 1 at 0.97, band 0 at 0.5) and a decoder per bit."""
    out = []
    for b in range(bits):
        level = 0.97 if (value >> b) & 1 else 0.5
        out += [f"v{name}{b} ({name}a{b} 0) vsource dc={level}", f"xb{name}{b} ({name}a{b} 0 m{name}{b}) mem_bit"]
    return out


def _memory_bench(we: int) -> tuple[list[int], dict[int, int]]:
    """Cells 4 (0x11) and 5 (0x3C); read address 5; a write window at 1..3 s of 0xA5 to address 5 with
    write enable `we`.  Returns (rdata before, during and after the window, decoded from the read stage's
    force level) and the final memory the cells print."""
    from mech2spice.cpu.circuit import final_memory
    from mech2spice.spice import memory
    from mech2spice.spice.vacask import run_netlist
    lines = ["memory bench", 'load "m2s_memory.osdi"', "model vsource vsource", "model mem_bit m2s_mem_bit",
             "model mem_byte m2s_mem_byte tend=5.9", "model mem_read m2s_mem_read", "ground 0"]
    lines += _bus("r", 5, 8) + _bus("w", 5, 8) + _bus("d", 0xA5, 8)
    lines += [f"vwe (wea 0) vsource dc={0.97 if we else 0.5}", "xwe (wea 0 mwe) mem_bit",
              'vwclk (mwclk 0) vsource type="pulse" val0=0 val1=1 delay=1 rise=0.1 fall=0.1 width=2',
              memory.byte_line(4, 0x11), memory.byte_line(5, 0x3C)]
    lines += [f"xr{b} (mo{b} mwclk amp{b}) mem_read" for b in range(8)]
    lines += ["control", "  options strictoutput=0", "  save " + " ".join(f"v(amp{b})" for b in range(8)),
              '  analysis tran1 tran stop=6 step=0.05 maxstep=0.05 icmode="uic"', "endc"]
    names, data, log = run_netlist("\n".join(lines) + "\n", extra_files={"m2s_memory.osdi": memory.compiled()})
    t = data[:, 0].real
    f0, f1 = DEFAULT.force(NOMINAL0), DEFAULT.force(NOMINAL1)
    reads = []
    for at in (0.9, 2.0, 5.9):
        x = np.array([np.interp(at, t, data[:, names.index(f"amp{b}")].real) for b in range(8)])
        bits = (x - f0) / (f1 - f0)
        assert np.all(np.abs(bits - np.round(bits)) < 0.05), bits      # every level is a clean bit
        reads.append(int(sum(int(round(v)) << b for b, v in enumerate(bits))))
    mem = {}
    for line in log.splitlines():
        if "m2s_mem " in line:
            addr, *bits = line.split("m2s_mem ")[1].split()
            mem[int(float(addr))] = sum(int(round(float(v))) << b for b, v in enumerate(bits))
    return reads, mem


def test_memory_writes_then_reads_one_byte():
    """The Verilog-A memory alone: the program's byte is read, held through the write window, then the
    written byte is read; the neighbouring cell keeps its byte; the cells print the final memory."""
    _vacask()
    reads, mem = _memory_bench(we=1)
    assert reads == [0x3C, 0x3C, 0xA5]
    assert mem == {4: 0x11, 5: 0xA5}


def test_memory_without_write_enable_keeps_the_byte():
    _vacask()
    reads, mem = _memory_bench(we=0)
    assert reads == [0x3C, 0x3C, 0x3C]
    assert mem == {4: 0x11, 5: 0x3C}


def test_final_memory_parses_the_last_print_per_address():
    from mech2spice.cpu.circuit import final_memory
    log = "\n".join(f"OSDI xm{a}: m2s_mem {a} 0 0 0 0 0 0 0 0" for a in range(256))
    log += "\nOSDI xm7: m2s_mem 7 1 1 0 0 0 0 0 1.0000001"
    mem = final_memory(log)
    assert mem[7] == 0b10000011 and mem.count(0) == 255
    assert final_memory(log.split("\n", 1)[1]) is None         # one address missing: no memory


def test_bad_input(tmp_path):
    """One-line errors (exit 2): too many cycles for one process, options of the wrong backend."""
    from mech2spice.cli import main
    cases = [["cpu", "run", "programs/sieve.asm", "--backend", "vacask-envelope"],
             ["cpu", "run", "programs/sieve.asm", "--backend", "iss", "--max-step", "4"],
             ["cpu", "emit", "programs/sieve.asm", "-o", str(tmp_path / "x.sim"), "--cycles", "5000"]]
    for argv in cases:
        assert main(argv) == 2


@pytest.mark.slow
def test_emitted_processor_runs_standalone_and_matches_the_iss(tmp_path, capsys):
    """`cpu emit` -> `vacask` alone (the Verilog-A embedded) -> its first 2 cycles decode to the ISS's
    (31-136 s on the shared 2-core machine, by its load)."""
    exe, _ = _vacask()
    from mech2spice.cpu.circuit import CircuitCPU, emit_cpu
    from mech2spice.cpu.iss import ISS
    from mech2spice.cpu.run import load_program, make_memory
    from mech2spice.spice.vacask import read_raw_any
    from mech2spice.cli import main
    out = tmp_path / "cpu.sim"
    assert main(["cpu", "emit", "programs/sieve.asm", "-o", str(out), "--cycles", "2", "--max-step", "32",
                 "--reltol", "1e-2", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["cycles"] == 2
    proc = subprocess.run([exe, "-qp", out.name], cwd=tmp_path, capture_output=True, text=True, timeout=1800)
    assert proc.returncode == 0, proc.stdout[-2000:]
    names, data = read_raw_any(tmp_path / "tran1.raw")
    # decode the standalone run's raw file as the backend does
    prog = load_program("programs/sieve.asm")
    net = emit_cpu(prog.image, 2, max_step=32, reltol=1e-2)
    from mech2spice.cpu import circuit
    cpu = CircuitCPU.replay(make_memory(prog), DEFAULT, net, circuit.decode(net, names, data, proc.stdout + proc.stderr), 2)
    iss = ISS(make_memory(prog))
    for _ in range(2):
        assert cpu.step() == iss.step()
        assert cpu.registers() == iss.registers()


def test_a_segment_starts_at_its_first_cycles_sample_from_the_saved_state():
    """A checkpointed run's segment: times shifted to its first sample, rst released, the clock's first
    edge SAMPLE_BEFORE periods in, every unknown given as an initial condition (subnormals as 0, which
    VACASK's parser refuses), its end state written by a second analysis."""
    from mech2spice.cpu import circuit
    from mech2spice.cpu.run import load_program
    prog = load_program("programs/sieve.asm")
    whole = circuit.emit_cpu(prog.image, 8)
    seg = circuit.emit_cpu(prog.image, 3, first=5, state={"ar_g0_c": 0.25, "xmr0:h": 5e-324})
    s, w = seg.schedule, whole.schedule
    assert (s.first, s.cycles, s.offset) == (5, 3, w.sample_at(5)) and not s.resets
    assert np.allclose(s.samples(), w.samples()[5:9]) and s.stop == w.sample_at(8)
    T = seg.period
    text = seg.text
    assert f"vrst (amp_rst 0) vsource dc=" in text
    clk = next(line for line in text.splitlines() if line.startswith("vclk "))
    delay = float(clk.split("delay=")[1].split()[0])
    ramp = circuit.VacaskEnvelopeOptions().RAMP_PERIODS * T
    assert delay == pytest.approx(circuit.SAMPLE_BEFORE * T - ramp / 2)
    assert 'ic={"ar_g0_c", 0.25, "xmr0:h", 0.0}' in text and 'store="end"' in text
    assert f'analysis {circuit.STATE} tran' in text and "save default" in text
    with pytest.raises(Mech2SpiceError):
        circuit.emit_cpu(prog.image, 3, first=5)          # a later segment needs the saved state


@pytest.mark.slow
def test_a_resumed_circuit_run_continues_exactly(tmp_path):
    """vacask-envelope with --checkpoint: 2 cycles in one go (one simulator process per cycle) against 1
    cycle, then --resume to 2: the same trace, bit for bit (~2 x 1 min per cycle here)."""
    _vacask()
    from mech2spice.cli import main
    base = ["cpu", "run", "programs/sieve.asm", "--backend", "vacask-envelope", "--checkpoint-every", "1", "--json"]
    assert main(base + ["--max-cycles", "2", "--checkpoint", str(tmp_path / "a.json"),
                        "--trace", str(tmp_path / "a.jsonl")]) == 1
    assert main(base + ["--max-cycles", "1", "--checkpoint", str(tmp_path / "b.json"),
                        "--trace", str(tmp_path / "b.jsonl")]) == 1
    assert main(base + ["--max-cycles", "2", "--checkpoint", str(tmp_path / "b.json"), "--resume",
                        "--trace", str(tmp_path / "b.jsonl")]) == 1
    strip = lambda path: [{k: v for k, v in json.loads(line).items() if k != "unix_time"}
                          for line in open(path)]
    a, b = strip(tmp_path / "a.jsonl"), strip(tmp_path / "b.jsonl")
    assert len(a) == 2 and a == b


def test_a_circuit_state_file_that_is_not_the_one_saved_is_refused(tmp_path):
    """Resuming a circuit run: a damaged state file, or one whose digest differs from the checkpoint's, is
    one clear error (no VACASK run: the resumed machine only emits its netlist until it loads)."""
    from mech2spice.cpu.circuit import CircuitCPU
    from mech2spice.cpu.run import load_program, make_memory
    cpu = CircuitCPU(make_memory(load_program("programs/sieve.asm")), cycles=4, segment=2, power_up=False)
    bad = tmp_path / "state.npz"
    bad.write_bytes(b"not an npz")
    with pytest.raises(Mech2SpiceError, match="cannot read the circuit state"):
        cpu.load(bad)
    with pytest.raises(Mech2SpiceError, match="does not match its checkpoint"):
        cpu.load(bad, sha256="0" * 64)
    with pytest.raises(Mech2SpiceError, match="resumes only a checkpointed run"):
        CircuitCPU(make_memory(load_program("programs/sieve.asm")), cycles=4, power_up=False)
