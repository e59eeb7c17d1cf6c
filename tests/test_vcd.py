"""`--vcd FILE` on clocked `simulate` and on `cpu run`: the waveform, read back by an independent reader
(vcdvcd), equals the JSON trace (`simulate --json`, `cpu run --trace`) cycle by cycle; the file obeys the
output rule (never an input, another kind of file only with --force)."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from conftest import run_main

from mech2spice import identifiers as ids, simulation
from mech2spice.cpu.isa import OPCODES
from mech2spice.cpu.run import PHASES, run_program
from mech2spice.synthesis import synth

vcdvcd = pytest.importorskip("vcdvcd")

REPO = Path(__file__).resolve().parent.parent
COUNTER = REPO / "verilog" / "counter4.v"
SIEVE = REPO / "programs" / "sieve.asm"


def cli(*args):
    return run_main(*args)        # in this process (conftest.run_main): the command's own handler, no new interpreter


def _wire(v, name: str, width: int, t: int) -> str:
    """A wire's value at time t as `width` characters, MSB first (vcdvcd keeps what the file wrote)."""
    ref = f"{name}[{width - 1}:0]" if width > 1 else name
    return v[ref][t].rjust(width, "0")


def _bits(bits: dict, port: str, width: int) -> str:
    return "".join("x" if bits[f"{port}[{i}]"] is None else str(bits[f"{port}[{i}]"]) for i in reversed(range(width)))


def _check_simulate_vcd(vcd: Path, res: dict, stimulus: list[dict], inputs: dict, outputs: dict, top: str):
    v = vcdvcd.VCDVCD(str(vcd))
    cycles = simulation.expand_steps(stimulus)
    assert "$timescale" in vcd.read_text()
    for e in res["trace"]:
        t = e["cycle"]
        for port, width in outputs.items():
            assert _wire(v, f"{top}.outputs.{port}", width, t) == _bits(e["bits"], port, width), (port, t)
        for port, width in inputs.items():
            assert int(_wire(v, f"{top}.inputs.{port}", width, t), 2) == cycles[t].get(port, 0), (port, t)
        for bit, amp in (e.get("amplitudes") or {}).items():
            assert float(v[f"{top}.amplitudes.{bit}"][t]) == pytest.approx(amp, rel=1e-14), (bit, t)
    return v


def test_simulate_logic_vcd_equals_the_json_trace(tmp_path):
    stim = [{"set": {"rst": 1}, "cycles": 1}, {"set": {"rst": 0, "en": 1}, "cycles": 18}, {"set": {"en": 0}, "cycles": 2}]
    (tmp_path / "stim.json").write_text(json.dumps(stim))
    vcd = tmp_path / "c.vcd"
    rc, out, err = cli("simulate", str(COUNTER), "--backend", "logic", "--stimulus", str(tmp_path / "stim.json"),
                       "--vcd", str(vcd), "--json")
    assert rc == 0, err
    res = json.loads(out)
    assert [e["outputs"]["q"] for e in res["trace"]][:18] == [0, *range(1, 16), 0, 1]     # it counts and wraps
    v = _check_simulate_vcd(vcd, res, stim, {"rst": 1, "en": 1}, {"q": 4}, "counter4")
    assert not [s for s in v.signals if ".amplitudes." in s]                          # logic: no amplitudes


def test_simulate_envelope_vcd_has_the_amplitudes_of_the_json_trace(tmp_path):
    vcd = tmp_path / "c.vcd"
    rc, out, err = cli("simulate", str(COUNTER), "--backend", "envelope", "--set", "en=1", "--cycles", "3",
                       "--vcd", str(vcd), "--json")
    assert rc == 0, err
    res = json.loads(out)
    v = _check_simulate_vcd(vcd, res, [{"set": {"en": 1}, "cycles": 3}], {"rst": 1, "en": 1}, {"q": 4}, "counter4")
    assert {s for s in v.signals if ".amplitudes." in s} == {f"counter4.amplitudes.q[{i}]" for i in range(4)}


def test_an_invalid_bit_is_x_in_the_waveform():
    nl = synth.synthesize(str(COUNTER))
    trace = [{"cycle": 0, "bits": {"q[0]": 1, "q[1]": None, "q[2]": 0, "q[3]": 1},
              "amplitudes": {f"q[{i}]": 0.5 + i / 10 for i in range(4)}}]
    wave = simulation.clocked_waveform(nl, [{"en": 1}], {"trace": trace})
    assert wave.signal("counter4.outputs.q").values == ("10x1",)
    assert wave.signal("counter4.amplitudes.q[2]").values == (0.7,)


def test_simulate_vcd_follows_the_output_rule(tmp_path):
    other = tmp_path / "notes.txt"
    other.write_text("mine\n")
    args = ["simulate", str(COUNTER), "--backend", "logic", "--cycles", "2"]
    rc, _, err = cli(*args, "--vcd", str(COUNTER))
    assert rc == 2 and "refusing to overwrite" in err and COUNTER.read_text().startswith("module") is not None
    rc, _, err = cli(*args, "--vcd", str(other))
    assert rc == 2 and "is not a VCD file" in err and other.read_text() == "mine\n"
    rc, _, err = cli(*args, "--vcd", str(other), "--force")
    assert rc == 0, err
    assert "$enddefinitions" in other.read_text()
    rc, _, err = cli(*args, "--vcd", str(other))              # a VCD file it wrote is replaced without --force
    assert rc == 0, err
    rc, _, err = cli("simulate", str(REPO / "verilog" / "adder2.v"), "--vcd", str(tmp_path / "a.vcd"))
    assert rc == 2 and "clocked designs" in err and not (tmp_path / "a.vcd").exists()


def _check_cpu_vcd(vcd: Path, trace: Path) -> list[dict]:
    v = vcdvcd.VCDVCD(str(vcd))
    rows = [json.loads(line) for line in trace.read_text().splitlines()]
    for row in rows:
        t = row["cycle"]
        for name in ("pc", "raddr", "rdata", "waddr", "wdata"):
            assert int(_wire(v, f"cpu.cycle.{name}", 8, t), 2) == row[name], (name, t)
        assert int(v["cpu.cycle.we"][t]) == row["we"]
        assert int(_wire(v, "cpu.cycle.phase", 2, t), 2) == PHASES[row["phase"]]
        op = _wire(v, "cpu.cycle.opcode", 4, t)
        assert op == "xxxx" if row["instr"] is None else int(op, 2) == OPCODES[row["instr"]]
        regs = row["registers"]
        for name in ("pc", "a", "b", "c", "d"):
            assert int(_wire(v, f"cpu.registers.{name}", 8, t), 2) == regs[name], (name, t)
        assert int(v["cpu.registers.ov"][t]) == regs["ov"]
        assert int(_wire(v, "cpu.registers.phase", 2, t), 2) == PHASES[regs["phase"]]
        for probe, amp in row.get("amps", {}).items():
            assert float(v[f"cpu.amplitudes.{probe}"][t]) == pytest.approx(amp, abs=5e-7), (probe, t)
    return rows


def test_cpu_run_logic_vcd_equals_the_trace(tmp_path):
    vcd, trace = tmp_path / "s.vcd", tmp_path / "s.jsonl"
    rc, _, err = cli("cpu", "run", str(SIEVE), "--backend", "logic", "--max-cycles", "40", "--trace", str(trace),
                     "--vcd", str(vcd))
    assert rc == 1, err                                        # not halted after 40 cycles
    rows = _check_cpu_vcd(vcd, trace)
    assert len(rows) == 40 and any(r["we"] for r in rows) and any(r["instr"] is None for r in rows)


def test_cpu_run_envelope_vcd_has_every_probed_amplitude(tmp_path):
    vcd, trace = tmp_path / "s.vcd", tmp_path / "s.jsonl"
    run_program(SIEVE, "envelope", 3, trace=trace, vcd=vcd)
    rows = _check_cpu_vcd(vcd, trace)
    v = vcdvcd.VCDVCD(str(vcd))
    assert len(rows) == 3 and len([s for s in v.signals if ".amplitudes." in s]) == len(rows[0]["amps"]) > 50


def test_cpu_run_vcd_follows_the_output_rule(tmp_path):
    trace = tmp_path / "t.jsonl"
    args = ["cpu", "run", str(SIEVE), "--backend", "logic", "--max-cycles", "3"]
    for target, message in ((SIEVE, "is the program"), (trace, "is the --trace file")):
        rc, _, err = cli(*args, "--trace", str(trace), "--vcd", str(target))
        assert rc == 2 and message in err, err
    other = tmp_path / "keep.txt"
    other.write_text("mine\n")
    rc, _, err = cli(*args, "--vcd", str(other))
    assert rc == 2 and "is not a VCD file" in err and other.read_text() == "mine\n"
    rc, _, err = cli(*args, "--vcd", str(other), "--force")
    assert rc == 1 and "$enddefinitions" in other.read_text(), err


def test_surfers_parser_reads_the_waveform(tmp_path):
    """wellen (the parser of the Surfer viewer, as pywellen) reads what `simulate --vcd` wrote: the same
    values as the JSON trace, vectors at their width, amplitudes as reals."""
    pywellen = pytest.importorskip("pywellen")
    stim = [{"set": {"rst": 1}, "cycles": 1}, {"set": {"rst": 0, "en": 1}, "cycles": 5}]
    (tmp_path / "stim.json").write_text(json.dumps(stim))
    vcd = tmp_path / "c.vcd"
    rc, out, err = cli("simulate", str(COUNTER), "--backend", "logic", "--stimulus", str(tmp_path / "stim.json"),
                       "--vcd", str(vcd), "--json")
    assert rc == 0, err
    w = pywellen.Waveform(str(vcd))
    found = {v.full_name: v for v in w.all_vars()}
    q = found["counter4.outputs.q"]
    assert q.bitwidth == 4 and str(w.timescale) == "1ns"
    assert [q.signal.value_at(e["cycle"]) for e in json.loads(out)["trace"]] == \
           [e["outputs"]["q"] for e in json.loads(out)["trace"]]
    from mech2spice.waveform import Waveform, write_vcd
    wave = Waveform([0, 1, 2])
    wave.add_real(["top", "amplitudes"], "q[0]", [0.5, 0.99, 0.52])
    write_vcd(tmp_path / "r.vcd", wave)
    (amp,) = list(pywellen.Waveform(str(tmp_path / "r.vcd")).all_vars())
    assert amp.is_real and [amp.signal.value_at(t) for t in range(3)] == [0.5, 0.99, 0.52]


# --------------------------------------------------------------------------- verify --vcd

needs_icarus = pytest.mark.skipif(not (shutil.which("iverilog") and shutil.which("vvp")),
                                  reason="Icarus Verilog (iverilog, vvp) not installed")


def _verify(capsys, *argv):
    from mech2spice import cli as main
    code = main.main(["verify", *map(str, argv)])
    out, err = capsys.readouterr()
    return code, out, err


def _broken(monkeypatch, how):
    """verify's synthesis made to return a wrongly mapped network (tests/test_verify.py's breakages)."""
    import mech2spice.synthesis.synth as synth_mod
    from tests.test_verify import _flip_gate_input, _swap_outputs
    real = synth_mod.synthesize
    broken = {"swap p0 p1": lambda nl: _swap_outputs(nl, "p[0]", "p[1]"), "flip a gate": _flip_gate_input}[how]
    monkeypatch.setattr(synth_mod, "synthesize", lambda *a, **k: broken(real(*a, **k)))


def _value(v, scope: str, name: str, width: int, t: int) -> str:
    return _wire(v, f"{scope}.{name}", width, t)


def _check_verify_vcd(vcd: Path, res: dict, inputs: dict, outputs: dict) -> vcdvcd.VCDVCD:
    """Read back by vcdvcd: per compared vector/cycle the inputs, the source and network values and the
    mismatch bits equal verify's JSON (cosim.trace, cosim.mismatches); the counterexample's range, if any,
    equals equivalence.counterexample and its replay.  Names as ids.vcd writes them."""
    v = vcdvcd.VCDVCD(str(vcd))
    top = ids.vcd(res["top"])
    co = res["cosim"]
    key = "cycle" if res["clocked"] else "vector"
    wrong = {(m[key], m["bit"]) for m in co["mismatches"]}
    assert res["vcd"]["cosim"] == [0, len(co["trace"]) - 1]
    for step in co["trace"]:
        t = step[key]
        for port, w in inputs.items():
            assert int(_value(v, f"{top}.inputs", ids.vcd(port), w, t), 2) == step["inputs"][port] % (1 << w)
            if res["clocked"]:
                assert int(_value(v, f"{top}.inputs_at_read", ids.vcd(port), w, t), 2) == \
                       step["inputs_at_read"][port] % (1 << w)
        for port, w in outputs.items():
            name = ids.vcd(port)
            assert _value(v, f"{top}.source", name, w, t) == step["source"][port], (port, t)
            assert _value(v, f"{top}.network", name, w, t) == step["network"][port], (port, t)
            flags = _value(v, f"{top}.mismatch", name, w, t)
            assert {f"{port}[{w - 1 - j}]" for j in range(w) if flags[j] == "1"} == \
                   {b for k, b in wrong if k == t}, (port, t)
        for bit, amp in (step.get("amplitudes") or {}).items():
            port, _, index = bit.rpartition("[")
            assert float(v[f"{top}.amplitudes.{ids.vcd(port)}[{index}"][t]) == pytest.approx(amp, rel=1e-14)
    cex = (res.get("equivalence") or {}).get("counterexample")
    if not cex:
        assert res["vcd"]["counterexample"] is None and not [s for s in v.signals if ".counterexample." in s]
        return v
    first, last = res["vcd"]["counterexample"]
    assert last - first + 1 == len(cex) and first > res["vcd"]["cosim"][1]
    replay = res["equivalence"]["replay"]["trace"]
    for k, (step, rep) in enumerate(zip(cex, replay)):
        for port, w in inputs.items():
            assert int(_value(v, f"{top}.counterexample.inputs", ids.vcd(port), w, first + k), 2) == \
                   step["inputs"][port] % (1 << w)
        for port, w in outputs.items():
            assert _value(v, f"{top}.counterexample.source", ids.vcd(port), w, first + k) == rep["source"][port]
            assert _value(v, f"{top}.counterexample.network", ids.vcd(port), w, first + k) == rep["network"][port]
    for port, w in outputs.items():                           # the last cycle: the differing bits the replay named
        assert _value(v, f"{top}.counterexample.source", ids.vcd(port), w, last) == \
               res["equivalence"]["replay"]["source"][port]
        flags = _value(v, f"{top}.counterexample.mismatch", ids.vcd(port), w, last)
        assert {f"{port}[{w - 1 - j}]" for j in range(w) if flags[j] == "1"} == \
               {b for b in res["equivalence"]["replay"]["bits"] if b.rpartition("[")[0] == port}
    return v


@needs_icarus
def test_verify_vcd_of_a_broken_combinational_mapping(tmp_path, monkeypatch, capsys):
    """mult2 with two product bits swapped: the co-simulation's values and mismatches and the counterexample,
    read back, equal the JSON; the source side is the product of the inputs the file shows."""
    _broken(monkeypatch, "swap p0 p1")
    vcd = tmp_path / "m.vcd"
    code, out, err = _verify(capsys, REPO / "verilog" / "mult2.v", "--exhaustive", "--vcd", vcd, "--json")
    res = json.loads(out)
    assert code == 1 and res["equivalence"]["status"] == "counterexample" and res["cosim"]["mismatches"], err
    v = _check_verify_vcd(vcd, res, {"a": 2, "b": 2}, {"p": 4})
    for t in range(16):
        a, b = (int(_value(v, "mult2.inputs", x, 2, t), 2) for x in "ab")
        assert _value(v, "mult2.source", "p", 4, t) == format(a * b, "04b")
    assert res["vcd"]["counterexample"] == [17, 17]


@needs_icarus
def test_verify_vcd_of_a_broken_clocked_mapping_has_the_replayed_sequence(tmp_path, monkeypatch, capsys):
    _broken(monkeypatch, "flip a gate")
    vcd = tmp_path / "c.vcd"
    code, out, err = _verify(capsys, COUNTER, "--cycles", 60, "--vcd", vcd, "--json")
    res = json.loads(out)
    eq = res["equivalence"]
    assert code == 1 and eq["status"] == "counterexample" and eq["replay"]["reproduced"], err
    assert len(eq["replay"]["trace"]) == len(eq["counterexample"]) >= 2
    _check_verify_vcd(vcd, res, {"rst": 1, "en": 1}, {"q": 4})


@needs_icarus
def test_a_clocked_cycle_names_the_inputs_it_captured_and_those_it_was_read_with(tmp_path, capsys):
    """A cycle's outputs are read after its edge with the next cycle's inputs on: a register shows `inputs`
    (what the edge captured), a path from an input shows `inputs_at_read`.  A mismatch listed only `inputs`,
    which made a bus Icarus read as z look driven (public RTL suite, cal_bus)."""
    src = tmp_path / "t.v"
    src.write_text("module t(input clk, input [2:0] a, output [2:0] y, output reg [2:0] q);\n"
                   "  assign y = a;\n  always @(posedge clk) q <= a;\nendmodule\n")
    vcd = tmp_path / "t.vcd"
    code, out, err = _verify(capsys, src, "--cycles", 40, "--vcd", vcd, "--json")
    res = json.loads(out)
    assert code == 0, err
    trace = res["cosim"]["trace"]
    assert [int(s["source"]["q"], 2) for s in trace] == [s["inputs"]["a"] for s in trace]
    assert [int(s["source"]["y"], 2) for s in trace] == [s["inputs_at_read"]["a"] for s in trace]
    assert [s["inputs_at_read"] for s in trace[:-1]] == [s["inputs"] for s in trace[1:]]
    _check_verify_vcd(vcd, res, {"a": 3}, {"y": 3, "q": 3})


@needs_icarus
def test_verify_vcd_of_escaped_names_on_a_physical_backend(tmp_path, capsys):
    """Escaped module and port names (dots, brackets, a comma) written as ids.vcd maps them; the envelope's
    amplitudes as reals; vcdvcd and Surfer's parser read the file."""
    from tests.test_verify import ESCAPED
    src = tmp_path / "escaped.v"
    src.write_text(ESCAPED)
    vcd = tmp_path / "e.vcd"
    code, out, err = _verify(capsys, src, "--backend", "envelope", "--cycles", 3, "--no-equivalence",
                             "--vcd", vcd, "--json")
    res = json.loads(out)
    assert code == 0, out + err
    v = _check_verify_vcd(vcd, res, {"opcode[0]": 1, "opcode[1]": 1, "logic": 2}, {"y[0]": 1, "q.r": 3})
    assert len([s for s in v.signals if ".amplitudes." in s]) == 4
    assert "\\top$2Elevel$241.source.\\q$2Er[2:0]" in v.signals
    pywellen = pytest.importorskip("pywellen")
    names = {x.full_name for x in pywellen.Waveform(str(vcd)).all_vars()}
    assert "\\top$2Elevel$241.network.\\opcode$5B0$5D" not in names          # an output scope holds outputs
    assert "\\top$2Elevel$241.inputs.\\opcode$5B0$5D" in names and "\\top$2Elevel$241.network.\\y$5B0$5D" in names


@needs_icarus
def test_verify_vcd_follows_the_output_rule(tmp_path, capsys):
    design = tmp_path / "fsm.v"
    design.write_text((REPO / "verilog" / "fsm.v").read_text())
    before = design.read_text()
    junit, other = tmp_path / "r.xml", tmp_path / "notes.txt"
    other.write_text("mine\n")
    for target, args, words in ((design, (), "is the design"), (junit, ("--junit", junit), "is the --junit file"),
                                (other, (), "is not a VCD file")):
        code, _, err = _verify(capsys, design, "--cycles", 5, *args, "--vcd", target)
        assert code == 2 and words in err and err.count("\n") == 1, err
    assert design.read_text() == before and other.read_text() == "mine\n" and not junit.exists()
    code, out, err = _verify(capsys, design, "--cycles", 5, "--vcd", other, "--force")
    assert code == 0 and "$enddefinitions" in other.read_text(), err
    assert f"waveform: {other} (co-simulation at times 0-4)" in out


def test_simulate_vcd_of_escaped_names(tmp_path):
    """`simulate --vcd` on a design with escaped names (dots, brackets) writes them as ids.vcd maps them
    instead of refusing them after the run."""
    from tests.test_verify import ESCAPED
    src, vcd = tmp_path / "escaped.v", tmp_path / "s.vcd"
    src.write_text(ESCAPED)
    rc, out, err = cli("simulate", str(src), "--backend", "logic", "--set", "opcode[0]=1", "--cycles", "4",
                       "--vcd", str(vcd), "--json")
    assert rc == 0, err
    v = vcdvcd.VCDVCD(str(vcd))
    top = ids.vcd("top.level$1")
    for e in json.loads(out)["trace"]:
        assert _wire(v, f"{top}.outputs.{ids.vcd('q.r')}", 3, e["cycle"]) == _bits(e["bits"], "q.r", 3)
        assert _wire(v, f"{top}.outputs.{ids.vcd('y[0]')}", 1, e["cycle"]) == _bits(e["bits"], "y[0]", 1)
        assert _wire(v, f"{top}.inputs.{ids.vcd('opcode[0]')}", 1, e["cycle"]) == "1"


@needs_icarus
def test_verify_vcd_of_a_counterexample_the_replay_does_not_confirm(tmp_path):
    """An `unknown` status from an unconfirmed counterexample: its cycles are in the file all the same, the
    replay's values side by side and no mismatch bit set; the comment names the status."""
    from mech2spice import verify as V
    from mech2spice.verify_vcd import verify_waveform
    from mech2spice.waveform import write_vcd
    nl = synth.synthesize(str(COUNTER))
    res = V.verify(COUNTER, netlist=nl, vectors=10, equivalence_check=False, keep_trace=True)
    cex = [{"cycle": k, "inputs": {"rst": int(k == 0), "en": 1}} for k in range(4)]
    eq = V._replayed(COUNTER, nl, {"status": "counterexample", "cex": cex, "depth": 4, "detail": ""})
    res["equivalence"] = {"status": eq["status"], "counterexample": eq["cex"], "replay": eq["replay"]}
    wave, res["vcd"] = verify_waveform(nl, res)
    write_vcd(tmp_path / "u.vcd", wave)
    v = _check_verify_vcd(tmp_path / "u.vcd", res, {"rst": 1, "en": 1}, {"q": 4})
    assert res["vcd"]["counterexample"] == [11, 14]
    assert _value(v, "counter4.counterexample.source", "q", 4, 14) == \
           _value(v, "counter4.counterexample.network", "q", 4, 14) == "0010"      # reset at edge 0, counted twice
    assert {_value(v, "counter4.counterexample.mismatch", "q", 4, t) for t in range(11, 15)} == {"0000"}
    assert _value(v, "counter4.counterexample.source", "q", 4, 10) == "xxxx"        # the gap
    assert "scope counterexample: the proof's counterexample (unknown) replayed" in (tmp_path / "u.vcd").read_text()
