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
from cli_helpers import run, refused, verilog

ROOT = Path(__file__).resolve().parents[1]
ADDER, COUNTER = str(ROOT / "verilog/adder2.v"), str(ROOT / "verilog/counter4.v")
SIEVE = str(ROOT / "programs/sieve.asm")








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


def test_declaration_initialiser_is_the_power_up_value(tmp_path, capsys):
    """`reg r = 2'd1` is the register's power-up value (it was refused before issue 34): the shift register
    moves its 1 out after the first edge, then the shifted-in 0s."""
    src = verilog(tmp_path, "module t(input clk, input a, output y);\n  reg [1:0] r = 2'd1;\n"
                            "  always @(posedge clk) r <= {r[0], a};\n  assign y = r[1];\nendmodule\n")
    rc, out, err = run(capsys, "simulate", src, "--backend", "logic", "--cycles", "3", "--set", "a=0", "--json")
    assert rc == 0, err
    assert [t["outputs"]["y"] for t in json.loads(out)["trace"]] == [1, 0, 0]   # r: 01 -> 10 -> 00 -> 00


def test_wire_with_initialiser_is_an_assignment_not_refused(tmp_path, capsys):
    src = verilog(tmp_path, "module t(input a, input b, output y);\n  wire w = a & b;\n  assign y = ~w;\nendmodule\n")
    rc, out, _ = run(capsys, "simulate", src, "--backend", "logic", "--set", "a=1", "--set", "b=1", "--json")
    assert rc == 0 and json.loads(out)["outputs"] == {"y": 0}


@pytest.mark.parametrize("body,needle", [
    # an output port nothing drives is accepted where nothing inside reads it (test_safety_round5.py)
    ("output y, output z);\n  assign y = a & z;", "'z' is used but nothing drives it"),
    ("output y, output z);\n  wire w;\n  assign w = z;\n  assign y = ~w;", "'z' is used but nothing drives it"),
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


def test_gate_divergence_is_an_error_on_stderr(tmp_path, capsys):
    params = tmp_path / "wild.json"
    params.write_text('{"gamma_ic": 1e9}')
    err = refused(capsys, "gate", "--params", params, "--quick", "--json", needle="diverged")
    assert "RK4 truth-table run failed" in err


# ------------------------------------------------------------------ never overwrite an input

def test_outputs_never_overwrite_inputs(tmp_path, capsys):
    src = tmp_path / "a.v"
    src.write_text(Path(ADDER).read_text())
    before = src.read_text()
    refused(capsys, "emit", src, "-o", src, needle="refusing to overwrite")
    refused(capsys, "emit", ADDER, "-o", ADDER, needle="refusing to overwrite")
    prog = tmp_path / "p.asm"
    prog.write_text(Path(SIEVE).read_text())
    refused(capsys, "cpu", "run", prog, "--checkpoint", prog, needle="refusing to overwrite")
    refused(capsys, "cpu", "asm", prog, "-o", prog, needle="refusing to overwrite")
    notes = tmp_path / "notes.txt"
    notes.write_text("my notes")
    refused(capsys, "cpu", "run", prog, "--checkpoint", notes, needle="not a processor checkpoint")
    assert src.read_text() == before and prog.read_text() == Path(SIEVE).read_text()
    assert notes.read_text() == "my notes"
    refused(capsys, "cpu", "run", prog, "--trace", prog, needle="refusing to overwrite")
    assert prog.read_text() == Path(SIEVE).read_text()


def test_carrier_options_belong_to_their_backend(capsys):
    refused(capsys, "cpu", "run", SIEVE, "--backend", "envelope", "--threads", "2", needle="carrier backend only")
    refused(capsys, "cpu", "run", SIEVE, "--backend", "logic", "--steps", "20", needle="carrier and rk4 backends only")
    refused(capsys, "cpu", "run", SIEVE, "--backend", "carrier", "--step", "4", needle="the carrier backend's are --steps")
    refused(capsys, "cpu", "run", SIEVE, "--backend", "rk4", "--latency", "0.05", needle="the rk4 backend's are --steps")
    refused(capsys, "cpu", "run", SIEVE, "--backend", "carrier", "--latency", "0.05", "--threads", "2",
            needle="choose latency or threads")
    refused(capsys, "simulate", ADDER, "--backend", "carrier", "--exponential", "on", needle="not carrier's")
    refused(capsys, "simulate", ADDER, "--backend", "carrier", "--noise", "1e-4", needle="no thermal noise")


# ------------------------------------------------------------------ resource guards

def test_cycle_caps_refuse_before_any_work(tmp_path, capsys):
    stim = tmp_path / "huge.json"
    stim.write_text(json.dumps([{"set": {"rst": 1}, "cycles": 1}, {"set": {"rst": 0}, "cycles": 10 ** 15}]))
    refused(capsys, "simulate", COUNTER, "--backend", "logic", "--stimulus", stim, needle="limited to 1,000,000")
    refused(capsys, "simulate", COUNTER, "--backend", "logic", "--cycles", 10 ** 7, needle="1,000,000")
    refused(capsys, "simulate", COUNTER, "--backend", "envelope", "--cycles", 20_000, needle="limited to 10,000")
    refused(capsys, "simulate", COUNTER, "--backend", "logic", "--cycles", -3,
            needle="argument --cycles: must be from 1")


NUMERIC = [  # (command line before the option, option, the values that must be refused)
    (["simulate", ADDER, "--backend", "logic"], "--periods", ["-1", "0", "nan", "inf", "1.5", "1e400"]),
    (["simulate", ADDER, "--backend", "logic"], "--steps", ["-1", "0", "nan", "inf"]),
    (["simulate", COUNTER, "--backend", "logic"], "--cycles", ["-3", "0", "nan", "inf"]),
    (["simulate", COUNTER, "--backend", "logic", "--cycles", "1"], "--pulse", ["-1", "0", "nan", "inf"]),
    (["simulate", COUNTER, "--backend", "logic", "--cycles", "1"], "--pause", ["-1", "0", "nan", "inf"]),
    (["simulate", ADDER, "--backend", "ngspice"], "--max-step", ["-1", "0", "nan", "inf", "-inf"]),
    (["simulate", ADDER, "--backend", "ngspice"], "--ngspice-timeout", ["-1", "0", "nan", "inf"]),
    (["emit", ADDER, "-o", "x.cir"], "--periods", ["-1", "0", "nan"]),
    (["emit", ADDER, "-o", "x.cir"], "--max-step", ["-1", "0", "nan", "inf"]),
    (["synth", ADDER], "--max-fanout", ["-1", "0", "1", "nan"]),
    (["gate"], "--spread", ["-1", "0", "nan", "inf", "2"]),
    (["gate", "--spread", "0.01"], "--samples", ["-1", "0", "nan"]),
    (["gate", "--spread", "0.01"], "--seed", ["-1", "nan", "1.5"]),
    (["cpu", "run", SIEVE, "--backend", "envelope"], "--step", ["-1", "0", "nan", "inf"]),
    (["cpu", "run", SIEVE, "--backend", "envelope"], "--settle", ["-1", "nan", "inf"]),
    (["cpu", "run", SIEVE], "--max-cycles", ["-1", "nan", "inf", "1e3"]),
    (["cpu", "run", SIEVE, "--checkpoint", "ck.json"], "--checkpoint-every", ["-1", "0", "nan"]),
    (["cpu", "run", SIEVE, "--backend", "carrier"], "--steps", ["-1", "0", "3", "nan", "12.5"]),
    (["cpu", "run", SIEVE, "--backend", "carrier"], "--threads", ["-1", "0", "nan", "65"]),
]


@pytest.mark.parametrize("before,option,values", NUMERIC, ids=[f"{b[0]}{o}" for b, o, _ in NUMERIC])
def test_numeric_options_refuse_negative_zero_nan_inf(tmp_path, capsys, monkeypatch, before, option, values):
    monkeypatch.chdir(tmp_path)
    for value in values:
        refused(capsys, *before, f"{option}={value}", needle=f"argument {option}:")
    assert list(tmp_path.iterdir()) == []             # nothing was written


# ------------------------------------------------------------------ output paths

@pytest.mark.parametrize("argv", [["emit", ADDER, "-o", "{out}"], ["cpu", "run", SIEVE, "--checkpoint", "{out}"],
                                  ["cpu", "asm", SIEVE, "-o", "{out}"]], ids=["emit", "checkpoint", "asm"])
def test_output_file_problems_are_one_line(tmp_path, capsys, argv):
    (tmp_path / "adir").mkdir()
    cases = {str(tmp_path / "missing" / "f"): "does not exist", str(tmp_path / "adir"): "is a directory",
             "/sys/mech2spice-test.out": "/sys"}
    for out, needle in cases.items():
        refused(capsys, *[a.format(out=out) for a in argv], needle=needle)


@pytest.mark.parametrize("argv", [["subckts", "-o", "{out}"], ["gate", "--quick", "--report", "{out}"]],
                         ids=["subckts", "gate-report"])
def test_output_directory_problems_are_refused_before_work(tmp_path, capsys, argv):
    (tmp_path / "afile").write_text("x")
    cases = {str(tmp_path / "missing" / "d"): "does not exist", str(tmp_path / "afile"): "not a directory"}
    for out, needle in cases.items():
        refused(capsys, *[a.format(out=out) for a in argv], needle=needle)


def test_full_disk_is_one_line(tmp_path, capsys, monkeypatch):
    refused(capsys, "emit", ADDER, "-o", "/dev/full", needle="No space left on device")
    refused(capsys, "cpu", "asm", SIEVE, "-o", "/dev/full", needle="No space left on device")
    ck = tmp_path / "ck.json"
    assert main(["cpu", "run", SIEVE, "--checkpoint", str(ck), "--max-cycles", "20", "--json"]) == 1
    capsys.readouterr()
    from mech2spice import inputs as inputs_module

    def full(fd):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(inputs_module.os, "fsync", full)     # the checkpoint's writer (inputs.replace_file)
    refused(capsys, "cpu", "run", SIEVE, "--checkpoint", ck, "--resume", needle="No space left on device")
    assert json.loads(ck.read_text())["cycle"] == 20                 # the previous checkpoint is intact


def test_closed_stdout_pipe_is_one_line(tmp_path):
    p = subprocess.Popen([sys.executable, "-m", "mech2spice.cli", "simulate", COUNTER, "--backend", "logic",
                          "--cycles", "3000", "--json"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT)
    p.stdout.close()                                  # like `| head -0`: the reader is gone
    err = p.stderr.read().decode()
    assert p.wait() == 2 and err.count("\n") == 1 and "pipe was closed" in err, err


# ------------------------------------------------------------------ JSON input files

BAD_JSON = {
    "not-utf8": b"\xff\xfe{}", "truncated": b'{"q_c": 1', "string": b'"abc"', "list": b"[1, 2]", "null": b"null",
    "nan": b'{"q_c": NaN}', "huge-int": b'{"q_c": ' + b"9" * 5000 + b"}", "deep": b"[" * 100_000,
}


@pytest.mark.parametrize("name", sorted(BAD_JSON))
def test_bad_json_files_are_one_line(tmp_path, capsys, name):
    bad = tmp_path / "bad.json"
    bad.write_bytes(BAD_JSON[name])
    refused(capsys, "synth", ADDER, "--params", bad, needle=str(bad))
    refused(capsys, "simulate", COUNTER, "--backend", "logic", "--stimulus", bad, needle=str(bad))
    prog = tmp_path / "p.asm"
    prog.write_text(Path(SIEVE).read_text())
    refused(capsys, "cpu", "run", prog, "--checkpoint", bad, "--resume", needle=str(bad))


@pytest.mark.parametrize("content,needle", [
    ('"abc"', "must hold a JSON object"), ('{"q_c": "150"}', "q_c must be a finite number"),
    ('{"q_c": true}', "q_c must be a finite number"), ('{"q_c": 1e999}', "q_c must be a finite number"),
    ('{"name": 3}', "name must be a string"), ('{"qc": 1}', "unknown field(s) qc"), ('{"q_c": -1}', "positive"),
])
def test_params_file_fields(tmp_path, capsys, content, needle):
    params = tmp_path / "p.json"
    params.write_text(content)
    refused(capsys, "synth", ADDER, "--params", params, needle=needle)


@pytest.mark.parametrize("content,needle", [
    ('{"set": {}}', "must hold a list of steps"), ('[3]', "step 0: expected an object"),
    ('[{"set": {"rst": 1}, "cycle": 3}]', "unknown field(s) 'cycle'"),
    ('[{"set": {"rst": "1"}, "cycles": 1}]', "'set' must map port names to integers"),
    ('[{"set": {"rst": true}, "cycles": 1}]', "'set' must map port names to integers"),
    ('[{"set": [1], "cycles": 1}]', "'set' must map"), ('[{"cycles": -1}]', "'cycles' must be a whole number"),
    ('[{"cycles": 1.5}]', "'cycles' must be a whole number"), ('[{"cycles": 0}]', "no clock cycles"),
    ('[]', "no clock cycles"), ('[{"set": {"nope": 1}, "cycles": 1}]', "unknown input port 'nope'"),
    ('[{"set": {"rst": 2}, "cycles": 1}]', "does not fit"),
])
def test_stimulus_file_fields(tmp_path, capsys, content, needle):
    stim = tmp_path / "s.json"
    stim.write_text(content)
    refused(capsys, "simulate", COUNTER, "--backend", "logic", "--stimulus", stim, needle=needle)


@pytest.fixture(scope="module")
def checkpoint_state(tmp_path_factory):
    """A real ISS checkpoint after 20 cycles of the sieve."""
    from mech2spice.cpu.run import run_program
    ck = tmp_path_factory.mktemp("ck") / "ck.json"
    run_program(SIEVE, "iss", 20, checkpoint=ck)
    return json.loads(ck.read_text())


@pytest.mark.parametrize("edit,needle", [
    (lambda s: s.pop("cycle"), "field 'cycle' is missing"), (lambda s: s.update(cycle="3"), "'cycle'"),
    (lambda s: s.update(cycle=-1), "'cycle'"), (lambda s: s.update(cycle=10**30), "'cycle'"),
    (lambda s: s.update(halted=0), "'halted'"),
    (lambda s: s.update(version=9), "unknown version 9"), (lambda s: s.pop("registers"), "'registers'"),
    (lambda s: s["registers"].update(a=256), "out of range"), (lambda s: s["registers"].update(phase="x"), "range"),
    (lambda s: s["registers"].pop("pc"), "'registers' must hold"), (lambda s: s.update(memory=[0] * 10), "'memory'"),
    (lambda s: s["memory"].__setitem__(3, -1), "'memory'"), (lambda s: s.update(devices=[]), "'devices'"),
    (lambda s: s.update(devices={"255": {"cells": {}}}), "'devices'"),
    (lambda s: s.update(devices={"254": {"cells": {}, "head": 0, "steps": 0, "idle": 0}}), "does not map"),
    (lambda s: s.update(program_sha256="0" * 64), "different program"),
    (lambda s: s.update(format="other"), "not a processor checkpoint"),
])
def test_checkpoint_fields(tmp_path, capsys, checkpoint_state, edit, needle):
    state = json.loads(json.dumps(checkpoint_state))
    edit(state)
    ck = tmp_path / "ck.json"
    ck.write_text(json.dumps(state))
    refused(capsys, "cpu", "run", SIEVE, "--checkpoint", ck, "--resume", needle=needle)


def test_a_checkpoint_without_its_tape_does_not_resume(tmp_path, capsys):
    """A checkpoint of a program that maps a tape, its 'devices' field removed, resumed on a blank tape and
    halted at another cycle, exit 0 (hostile-input pass, session 21)."""
    from mech2spice.cpu.run import run_program
    program, ck = ROOT / "programs" / "tm_increment.asm", tmp_path / "ck.json"
    run_program(program, "iss", 20, checkpoint=ck)
    state = json.loads(ck.read_text())
    assert state["devices"], "the program maps a tape"
    del state["devices"]
    ck.write_text(json.dumps(state))
    refused(capsys, "cpu", "run", program, "--checkpoint", ck, "--resume", needle="holds no state for the device")


def _physical_checkpoint(tmp_path) -> Path:
    """A version-2 envelope checkpoint of the sieve's first cycles, written by save_checkpoint from an
    ISS standing in for the oscillators (the JSON and the state-file pair are what is tested here)."""
    from mech2spice.cpu.iss import ISS
    from mech2spice.cpu.run import load_program, make_memory, save_checkpoint

    class Stand(ISS):
        def save(self, path):
            import hashlib
            Path(path).write_bytes(b"state")
            return hashlib.sha256(b"state").hexdigest()

    cpu = Stand(make_memory(load_program(SIEVE)))
    for _ in range(3):
        cpu.step()
    ck = tmp_path / "ck.json"
    for _ in range(3):                        # each save replaces the pair and removes the old state file
        save_checkpoint(cpu, ck, load_program(SIEVE), "envelope")
    return ck


def test_checkpoint_state_file_problems_are_caught_before_the_build(tmp_path, capsys):
    """A physical checkpoint names its state file and its sha256: a missing, damaged or foreign file is
    refused at once (before the ~10 s model build)."""
    ck = _physical_checkpoint(tmp_path)
    (state_file,) = tmp_path.glob("ck.json.state-*.npz")
    assert json.loads(ck.read_text())["state_file"] == state_file.name
    argv = ["cpu", "run", SIEVE, "--backend", "envelope", "--checkpoint", ck, "--resume"]
    state_file.write_bytes(b"stat")                                      # truncated
    refused(capsys, *argv, needle="does not match its checkpoint")
    state_file.unlink()
    refused(capsys, *argv, needle="cannot read the oscillator state")
    for name in ("../../etc/passwd", "other.npz", 3):
        d = json.loads(ck.read_text())
        d["state_file"] = name
        ck.write_text(json.dumps(d))
        refused(capsys, *argv, needle="does not name a valid oscillator-state file")


def _cpu_run(ck: Path, backend: str, *extra: str) -> subprocess.Popen:
    argv = [sys.executable, "-m", "mech2spice.cli", "cpu", "run", SIEVE, "--backend", backend,
            "--checkpoint", str(ck), "--json", *extra]
    return subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT)


def _kill_and_resume(tmp_path, capsys, backend: str, kills: int, delays: tuple, extra: tuple) -> dict:
    """kill -9 a checkpointing run at random instants, resuming each time; then run to the end.  After
    every kill the checkpoint on disk is either absent (and --resume says so) or resumable."""
    import random
    import signal
    import time

    from mech2spice.cpu.run import load_program, read_checkpoint
    rng, ck, program = random.Random(1212), tmp_path / "ck.json", load_program(SIEVE)
    cycles = []
    for k in range(kills):
        p = _cpu_run(ck, backend, *extra, *(["--resume"] if ck.exists() else []))
        if k == 0:
            time.sleep(rng.uniform(0.1, 0.5))           # before the first save
        else:                                           # once it saves (start-up time varies), at random
            _wait_for_save(ck, p)
            time.sleep(rng.uniform(*delays))
        p.send_signal(signal.SIGKILL)
        out, err = p.communicate()
        assert p.returncode in (-signal.SIGKILL, 0, 1), err.decode()[-2000:]
        if ck.exists():
            cycles.append(read_checkpoint(ck, program, backend)["cycle"])   # parses, fields and state file check
        else:
            refused(capsys, "cpu", "run", SIEVE, "--backend", backend, "--checkpoint", ck, "--resume",
                    needle="no checkpoint at")
    p = _cpu_run(ck, backend, *extra, *(["--resume"] if ck.exists() else []))
    out, err = p.communicate(timeout=600)
    assert p.returncode in (0, 1), err.decode()[-2000:]
    print("checkpointed cycle after each kill:", cycles)
    assert len(set(cycles)) >= 2, cycles                 # the kills really landed at different points
    return json.loads(out)


def _wait_for_save(ck: Path, p: subprocess.Popen, timeout: float = 120) -> None:
    """Until the run writes a checkpoint (or exits)."""
    import time
    before = ck.stat().st_mtime_ns if ck.exists() else None
    end = time.time() + timeout
    while p.poll() is None and time.time() < end:
        if ck.exists() and ck.stat().st_mtime_ns != before:
            return
        time.sleep(0.01)


def test_kill_9_at_random_instants_during_checkpointing_logic_run(tmp_path, capsys):
    """9 kills of `cpu run sieve.asm --backend logic --checkpoint F --checkpoint-every 1`: every resume
    continues, and the run ends at the ISS's result."""
    from mech2spice.cpu.run import run_program
    res = _kill_and_resume(tmp_path, capsys, "logic", 9, (0.0, 0.8), ("--checkpoint-every", "1"))
    iss = run_program(SIEVE, "iss")
    for key in ("cycles", "halted", "memory", "registers"):
        assert res[key] == iss[key], key


@pytest.mark.slow
def test_kill_9_at_random_instants_during_checkpointing_envelope_run(tmp_path, capsys):
    """The same for the oscillators (envelope): the JSON and its state file always form a usable pair."""
    from mech2spice.cpu.run import run_program
    res = _kill_and_resume(tmp_path, capsys, "envelope", 4, (0.0, 3.0),
                           ("--checkpoint-every", "1", "--max-cycles", "24"))
    iss = run_program(SIEVE, "iss", 24)
    for key in ("cycles", "memory", "registers"):
        assert res[key] == iss[key], key
    assert len(list(tmp_path.glob("ck.json.state-*.npz"))) == 1         # no state file left behind


# ------------------------------------------------------------------ ngspice: timeout, interrupts

@pytest.mark.ngspice
def test_ngspice_timeout_is_one_line_and_leaves_no_temp_dir(tmp_path, capsys, monkeypatch):
    import tempfile
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    refused(capsys, "simulate", ADDER, "--backend", "ngspice", "--periods", "200000", "--ngspice-timeout", "0.5",
            needle="ngspice did not finish within 0.5 s")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.ngspice
def test_sigterm_stops_ngspice_and_removes_its_temp_dir(tmp_path):
    import signal
    import time
    env = {**os.environ, "TMPDIR": str(tmp_path)}
    p = subprocess.Popen([sys.executable, "-m", "mech2spice.cli", "simulate", ADDER, "--backend", "ngspice",
                          "--periods", "200000"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT, env=env)
    deadline = time.time() + 60
    while not list(tmp_path.glob("m2s_ng_*/circuit.cir")) and time.time() < deadline:
        time.sleep(0.05)
    work = list(tmp_path.glob("m2s_ng_*"))
    assert work, "ngspice never started"
    time.sleep(0.3)
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=30)
    assert p.returncode == 130 and "interrupted" in err.decode(), err.decode()
    assert not any(d.exists() for d in work)                          # the temporary directory is gone
    for proc in Path("/proc").glob("[0-9]*"):                         # and no ngspice still runs in it
        try:
            assert not os.readlink(proc / "cwd").startswith(str(tmp_path)), proc
        except OSError:
            pass


# ------------------------------------------------------------------ the handler

def test_a_bug_gives_a_traceback_a_report_line_and_exit_3(capsys, monkeypatch):
    from mech2spice import cli

    def broken(args):
        return 1 / 0
    monkeypatch.setattr(cli.simulate, "cmd_synth", broken)
    rc, _, err = run(capsys, "synth", ADDER)
    assert rc == cli.BUG_EXIT == 3 and "Traceback" in err and "ZeroDivisionError" in err
    assert "please report it" in err.splitlines()[-1]


def test_usage_errors_and_help(capsys):
    rc, out, err = run(capsys, "simulate")
    assert rc == 2 and err.count("\n") == 1 and "the following arguments are required: design" in err
    rc, out, err = run(capsys, "frobnicate")
    assert rc == 2 and err.count("\n") == 1 and "invalid choice" in err
    rc, out, _ = run(capsys, "cpu", "run", "--help")
    assert rc == 0 and "--checkpoint" in out


def test_cpu_run_progress_bar_only_when_asked(capsys):
    """The physical backends' cycle bar (tqdm, with rate and ETA) goes to stderr when progress is on (a
    terminal); the CLI turns it off for --json, and gives a non-terminal stderr a line every
    PROGRESS_EVERY_S instead (none in a run this short; tests/test_first_run.py)."""
    from mech2spice.cpu.run import run_program
    run_program(SIEVE, "logic", 30, progress=True)
    err = capsys.readouterr().err
    assert "cycle/s" in err and "/30 " in err
    run_program(SIEVE, "logic", 30, progress=False)
    assert capsys.readouterr().err == ""
    assert main(["cpu", "run", SIEVE, "--backend", "logic", "--max-cycles", "30"]) == 1
    assert capsys.readouterr().err == ""                               # not a terminal, and quick


@pytest.mark.skipif(not Path("/dev/zero").exists(), reason="no /dev/zero")
@pytest.mark.parametrize("argv", [["synth", "/dev/zero"],
                                  ["simulate", str(ROOT / "verilog/counter4.v"), "--stimulus", "/dev/zero"],
                                  ["cpu", "run", "/dev/zero"]], ids=["design", "stimulus", "program"])
def test_an_endless_input_is_refused_by_its_size(capsys, argv):
    """/dev/zero was read until the memory ran out, then the design was blamed for its size (hostile-input pass,
    session 21)."""
    refused(capsys, *argv, needle="MiB: not a file this reads")


@pytest.mark.parametrize("argv, needle", [
    (["simulate", str(ROOT / "verilog/adder2.v"), "--set", "a=1", "--set", "a=2", "--backend", "logic"], "given twice"),
    (["simulate", str(ROOT / "verilog/counter4.v"), "--stimulus", "{dup}", "--backend", "logic"], "appears twice"),
    (["montecarlo", str(ROOT / "verilog/adder2.v"), "--stimulus", "{cycles}", "--spread", "1e-5", "--samples", "1",
      "--scheduler", "inline"], "'cycles' applies to clocked designs"),
], ids=["set-twice", "json-key-twice", "mc-cycles"])
def test_a_value_given_twice_or_a_field_with_no_use_is_refused(tmp_path, capsys, argv, needle):
    """The last of two values won, and a combinational montecarlo dropped 'cycles', each with exit 0
    (hostile-input pass, session 21)."""
    (tmp_path / "dup.json").write_text('[{"set": {"en": 1, "en": 0}, "cycles": 2}]')
    (tmp_path / "cycles.json").write_text('[{"set": {"a": 1}, "cycles": 3}]')
    files = {"{dup}": str(tmp_path / "dup.json"), "{cycles}": str(tmp_path / "cycles.json")}
    refused(capsys, *[files.get(a, a) for a in argv], needle=needle)


def test_a_port_whose_name_holds_an_equals_sign_can_be_set(tmp_path, capsys):
    """`--set a=1=1` for `input \\a=1`: the value was read as '1=1' (hostile-input pass, session 21)."""
    src = tmp_path / "eq.v"
    src.write_text("module t(input \\a=1 , output y);\n  assign y = ~\\a=1 ;\nendmodule\n")
    for value, y in ((0, 1), (1, 0)):
        assert main(["simulate", str(src), "--set", f"a=1={value}", "--backend", "logic", "--json"]) == 0
        assert json.loads(capsys.readouterr().out)["outputs"] == {"y": y}


def test_merging_into_a_record_that_does_not_exist_names_it(tmp_path, capsys):
    refused(capsys, "design", "--merge", tmp_path / "other.json", "--out", tmp_path / "new.json",
            needle="--merge merges into the search record --out")


@pytest.mark.parametrize("argv, needle", [
    (["verify", str(ROOT / "verilog/sqrt.v"), "--reset", "rst", "--reset", "rst=0", "--cycles", "5"], "given twice"),
    (["design", "--structures", " , ", "--out", "{out}"], "--structures names none"),
], ids=["verify-reset-twice", "design-no-structures"])
def test_a_contradiction_or_an_empty_selection_is_refused(tmp_path, capsys, argv, needle):
    """Two levels for one reset port were proved as one start state, and an empty --structures searched
    nothing with exit 0 (second hostile-input pass, session 21)."""
    refused(capsys, *[a.replace("{out}", str(tmp_path / "d.json")) for a in argv], needle=needle)


def test_emit_refuses_a_clocked_design(tmp_path, capsys):
    """A netlist of one input vector has no clock edges: a clocked design's flip-flops would only read their
    power-up values (written with exit 0 before: hostile-input pass, session 21)."""
    out = tmp_path / "counter.cir"
    for fmt in ("ngspice", "vacask"):
        refused(capsys, "emit", COUNTER, "--format", fmt, "-o", str(out), needle="is clocked by 'clk'")
    assert not out.exists()
