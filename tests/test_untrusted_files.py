"""Files the tool reads back are data, never code (issue #26, "Running a stranger's code").

A checkpoint, a state file, a results file, a cache or a block file may come from someone else: whatever it
holds, the tool refuses it in one line (exit 2) or ignores it where that is the cache's contract, and never
runs it.  Each payload here would create a marker file if it ran; the tests assert the marker is absent.
"""
import ast
import hashlib
import io
import json
from pathlib import Path

import numpy as np
import pytest

from cli_helpers import run, refused

ROOT = Path(__file__).resolve().parents[1]
SIEVE = str(ROOT / "programs/sieve.asm")
PACKAGE = ROOT / "mech2spice"






def _npz(**arrays) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def _checkpoint(tmp_path, backend: str, state_bytes: bytes, cycle: int, registers: dict) -> Path:
    """A version-2 processor checkpoint of the sieve at `cycle` naming a state file with these bytes."""
    from mech2spice.cpu.run import CHECKPOINT_FORMAT, load_program
    prog = load_program(SIEVE)
    ckpt = tmp_path / "run.json"
    name = f"{ckpt.name}.state-{'0' * 16}.npz"
    (tmp_path / name).write_bytes(state_bytes)
    image = list(prog.image) + [0] * (256 - len(prog.image))
    ckpt.write_text(json.dumps({
        "format": CHECKPOINT_FORMAT, "version": 2, "backend": backend,
        "program_sha256": hashlib.sha256(prog.image).hexdigest(), "cycle": cycle, "halted": False,
        "registers": registers, "memory": image, "devices": {}, "state_file": name,
        "state_sha256": hashlib.sha256(state_bytes).hexdigest()}))
    return ckpt


# ------------------------------------------------------------------ a circuit checkpoint that injects code

SETTLE = 200          # settle periods per cycle: keeps the (unfixed) simulator run that would follow short


def _circuit_state(names: list[str], values: list[float], **override) -> bytes:
    """A vacask-envelope state file resuming at cycle 1: every probe in band 0 (registers all 0, fetch)."""
    from mech2spice.cpu.circuit import NAME, emit_cpu
    from mech2spice.physics.params import DEFAULT, NOMINAL0
    probes = emit_cpu([0], 1, first=0, settle=SETTLE).probes
    arrays = dict(names=np.array(names), values=np.array(values, float), state_cycle=1, period=1000.0,
                  pending=np.array([1], np.int64), probes=np.array(probes), amps=np.full((1, len(probes)), 0.5),
                  levels=np.full((1, 8), DEFAULT.force(NOMINAL0)), backend=NAME,
                  settings=json.dumps({"settle": SETTLE, "max_step": 32.0, "reltol": 0.01}),
                  memory=np.array([], np.int64), simulated=0.0,
                  cost=json.dumps({"time_points": 0, "simulator_wall_s": 0.0, "segments": 1}))
    return _npz(**{**arrays, **override})


def _zero_registers() -> dict:
    """What every latch in band 0 decodes to."""
    from mech2spice.cpu.iss import FETCH
    return {"pc": 0, "a": 0, "b": 0, "c": 0, "d": 0, "ov": 0, "phase": FETCH}


def _payload(marker: Path) -> str:
    """A node name that closes the initial-condition list and adds a statement running Python."""
    code = f"open('{marker}', 'w').write('ran')"
    return f'ar_x", 0.0}}\n  postprocess(PYTHON, "-c", "{code}")\n  var junk={{"ar_x'


def test_a_circuit_checkpoint_whose_state_injects_a_statement_is_refused(tmp_path, capsys):
    """(a) The state file's node names go into the netlist's ic list: one that is not a node of the
    processor's netlist is refused before any simulator runs, and its code never runs."""
    marker = tmp_path / "INJECTED"
    names = ["ar_g0_c", _payload(marker)]
    ckpt = _checkpoint(tmp_path, "vacask-envelope", _circuit_state(names, [0.0, 0.0]), 1, _zero_registers())
    err = refused(capsys, "cpu", "run", SIEVE, "--backend", "vacask-envelope", "--checkpoint", ckpt, "--resume",
                  "--max-cycles", 2, "--checkpoint-every", 1, "--settle-periods", SETTLE,
                  needle="not a node of the processor's netlist")
    assert "postprocess" not in err or "\\n" in err          # the name is quoted, never a line of its own
    assert not marker.exists()


def test_a_circuit_state_that_is_not_every_node_of_the_netlist_is_refused(tmp_path, capsys):
    """A foreign or cut state file (names that are nodes, but not all of them) is refused, not resumed from
    zeros for the rest."""
    ckpt = _checkpoint(tmp_path, "vacask-envelope", _circuit_state(["ar_g0_c"], [0.0]), 1, _zero_registers())
    refused(capsys, "cpu", "run", SIEVE, "--backend", "vacask-envelope", "--checkpoint", ckpt, "--resume",
            "--max-cycles", 2, "--checkpoint-every", 1, "--settle-periods", SETTLE,
            needle="does not hold each of the netlist's")


def test_the_circuit_netlist_takes_only_its_own_nodes_and_finite_values():
    """emit_cpu itself (the API) checks a state before pasting it into the netlist."""
    from mech2spice.cpu.circuit import emit_cpu
    from mech2spice.errors import Mech2SpiceError
    with pytest.raises(Mech2SpiceError, match="not a node of the processor's netlist"):
        emit_cpu([0], 1, first=1, state={'ar_g0_c", 0}\npostprocess(PYTHON, "x.py")': 0.0})
    for value in (float("nan"), float("inf"), "0"):
        with pytest.raises(Mech2SpiceError, match="not a finite number"):
            emit_cpu([0], 1, first=1, state={"ar_g0_c": value})


def test_netlist_unknowns_are_the_nodes_vacask_reports():
    """The set a state is checked against: instance nodes (not ground) and each device's internal nodes."""
    from mech2spice.spice.vacask import netlist_unknowns
    lib = ("module m_in(a, b);\n  inout a, b;\n  electrical a, b;\n  electrical h, k;\n  analog begin\n  end\n"
           "endmodule\nmodule m_plain(a);\n  electrical a;\nendmodule\n")
    text = ("title\nground 0\nmodel dev m_in\nmodel pl m_plain\nx1 (n1 0) dev\nx2 (N2) pl\n"
            "control\n  analysis t tran stop=1\nendc\n")
    assert netlist_unknowns(text, (lib,)) == {"n1", "n2", "x1:h", "x1:k"}


def test_a_trace_whose_cycles_are_not_numbers_is_refused_on_resume(tmp_path, capsys):
    """A resumed `cpu run --trace` keeps the lines before its checkpoint's cycle: each must say its cycle."""
    ck, trace = tmp_path / "ck.json", tmp_path / "t.jsonl"
    assert run(capsys, "cpu", "run", SIEVE, "--max-cycles", 3, "--checkpoint", ck, "--trace", trace)[0] == 1
    trace.write_text('{"cycle": "0"}\n')
    refused(capsys, "cpu", "run", SIEVE, "--max-cycles", 4, "--checkpoint", ck, "--resume", "--trace", trace,
            needle="is not a cpu run trace")


# ------------------------------------------------------------------ oscillator-level checkpoints

def _probes() -> list[str]:
    from mech2spice.cpu.circuit import emit_cpu
    return emit_cpu([0], 1).probes


def _physical_state(engine: str, state: list[np.ndarray], **override) -> bytes:
    """An envelope / carrier state file: every probe in band 0 (registers all 0, fetch)."""
    probes = _probes()
    arrays = {**{f"state{k}": a for k, a in enumerate(state)}, "period": 0, "rdata": 0, "simulated": 0,
              "block_steps": 0, "probes": np.array(probes), "amps": np.full(len(probes), 0.5),
              "backend": engine, "step": 1.0}
    return _npz(**{**arrays, **override})


def test_an_envelope_state_of_the_wrong_shape_is_refused_before_the_kernels_see_it(tmp_path, capsys):
    """(c) Arrays of another model (here 3 oscillators) would make the compiled loops read and write out of
    bounds: refused in one line, naming the field."""
    state = [np.zeros((3, 1), complex), np.zeros((1, 1)), np.zeros((1, 1))]
    ckpt = _checkpoint(tmp_path, "envelope", _physical_state("envelope", state), 1, _zero_registers())
    refused(capsys, "cpu", "run", SIEVE, "--backend", "envelope", "--checkpoint", ckpt, "--resume",
            "--max-cycles", 2, needle="state arrays, the envelope engine keeps")


def test_a_carrier_state_with_an_infinite_or_mistyped_value_is_refused(tmp_path, capsys):
    from mech2spice.cpu.physical import PhysicalCPU
    from mech2spice.cpu.run import load_program, make_memory
    cpu = PhysicalCPU(make_memory(load_program(SIEVE)), "carrier", power_up=False)
    fresh = list(cpu._fresh_state())
    x = fresh[0].copy()
    x[5, 0] = np.inf
    ckpt = _checkpoint(tmp_path, "carrier", _physical_state("carrier", [x, *fresh[1:]]), 1, _zero_registers())
    argv = ["cpu", "run", SIEVE, "--backend", "carrier", "--checkpoint", ckpt, "--resume", "--max-cycles", 2]
    refused(capsys, *argv, needle="field 'state0' holds values that are not finite")
    ckpt = _checkpoint(tmp_path, "carrier", _physical_state("carrier", [fresh[0].astype(np.float32), *fresh[1:]]),
                       1, _zero_registers())
    refused(capsys, *argv, needle="field 'state0' must be float64 of shape")


class _Payload:
    """Unpickling this runs code: it writes `marker`."""

    def __init__(self, marker: Path):
        self.marker = str(marker)

    def __reduce__(self):
        return exec, (f"open({self.marker!r}, 'w').write('ran')",)


def test_a_state_file_holding_a_pickle_is_never_unpickled(tmp_path, capsys):
    """(c) A state file whose arrays are pickled objects (np.savez stores object arrays as pickles)."""
    import pickle
    marker = tmp_path / "UNPICKLED"
    payload = np.empty(1, object)
    payload[0] = _Payload(marker)
    ckpt = _checkpoint(tmp_path, "envelope", _physical_state("envelope", [], backend=payload), 1, _zero_registers())
    refused(capsys, "cpu", "run", SIEVE, "--backend", "envelope", "--checkpoint", ckpt, "--resume",
            "--max-cycles", 2, needle="cannot read the oscillator state")
    assert not marker.exists()
    ckpt = _checkpoint(tmp_path, "envelope", pickle.dumps(_Payload(marker)), 1, _zero_registers())
    refused(capsys, *["cpu", "run", SIEVE, "--backend", "envelope", "--checkpoint", ckpt, "--resume"],
            needle="cannot read the oscillator state")
    assert not marker.exists()


# ------------------------------------------------------------------ report caches

def _render(capsys, out: Path, needle: str) -> str:
    """`report envelope --render` refused: exit 2, one error line, the last (after the report's progress)."""
    rc, _, err = run(capsys, "report", "envelope", "--render", "--out", out)
    errors = [s for s in err.splitlines() if "error" in s.lower()]
    assert rc == 2 and "Traceback" not in err and errors == err.splitlines()[-1:], err
    assert needle in errors[0], err
    return errors[0]


def test_a_pickle_as_the_rendered_json_is_never_loaded(tmp_path, capsys):
    """(b) `report envelope --render` reads OUT/envelope.json as JSON: a pickle put there is refused, never
    opened."""
    import pickle
    marker, out = tmp_path / "UNPICKLED", tmp_path / "out"
    out.mkdir()
    (out / "envelope.json").write_bytes(pickle.dumps(_Payload(marker)))
    _render(capsys, out, needle="is not the JSON a report wrote")
    assert not marker.exists()


def test_a_json_that_is_not_the_reports_is_refused_in_one_line(tmp_path, capsys):
    """(b) JSON that lacks what the envelope report renders: one line, no traceback."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "envelope.json").write_text('{"scenes": [{"scene": "x"}]}')
    _render(capsys, out, needle="envelope.json: $.scenes[0].")


def test_the_measurement_cache_refuses_foreign_entries_and_never_reads_pickles(tmp_path):
    """(b) report envelope's per-run cache: a key's .npz that is no results file, or not the kind of result
    kept under that key, is refused; a .pkl beside it is ignored (measured again)."""
    import pickle
    from mech2spice.errors import Mech2SpiceError
    from mech2spice.studies import _datafile
    from mech2spice.studies.envelope import _is_run, cached
    marker = tmp_path / "UNPICKLED"
    (tmp_path / "k.pkl").write_bytes(pickle.dumps(_Payload(marker)))
    run = {"amp": np.zeros((2, 1, 1)), "t": np.arange(2.0), "wall_s": 0.5}
    assert cached(tmp_path, "k", lambda: run, _is_run)["wall_s"] == 0.5 and not marker.exists()
    again = cached(tmp_path, "k", lambda: pytest.fail("measured again"), _is_run)
    assert np.array_equal(again["amp"], run["amp"])
    _datafile.dump(tmp_path / "k.npz", {"amp": "not an array"})
    with pytest.raises(Mech2SpiceError, match="does not hold what `report envelope` keeps there"):
        cached(tmp_path, "k", lambda: run, _is_run)
    (tmp_path / "k.npz").write_bytes(pickle.dumps(_Payload(marker)))
    with pytest.raises(Mech2SpiceError, match="is not a mech2spice results file"):
        cached(tmp_path, "k", lambda: run, _is_run)
    assert not marker.exists()


def test_results_files_round_trip_every_stored_type(tmp_path):
    from mech2spice.studies import _datafile
    obj = ({"a": np.arange(3.0), 2.0: {"x": (1, 2.5, None, True)}, (1, "b"): [np.float64(3.5), np.bool_(True),
            complex(1, -2), float("nan"), -np.inf]}, [np.array(["u", "vv"]), np.zeros((2, 3), complex)], "end")
    _datafile.dump(tmp_path / "r.npz", obj)
    back = _datafile.load(tmp_path / "r.npz")
    assert back[0][2.0] == {"x": (1, 2.5, None, True)} and back[2] == "end"
    assert back[0][(1, "b")][:3] == [3.5, True, complex(1, -2)] and np.isnan(back[0][(1, "b")][3])
    assert np.array_equal(back[0]["a"], obj[0]["a"]) and back[1][1].dtype == complex
    with pytest.raises(TypeError):
        _datafile.dump(tmp_path / "r.npz", {"f": len})


# ------------------------------------------------------------------ block, params, design and results files

@pytest.mark.parametrize("edit,needle", [
    (lambda d: d["block"]["dofs"]["I"].update(slow="no"), "slow must be true or false"),
    (lambda d: d.update(name="x\n.control\nshell touch PWNED\n.endc"), "printable characters"),
    (lambda d: d["block"].update(name=["x"]), "'name' must be a string"),
    (lambda d: d["block"]["source"].update(extra=1), "'source' must be"),
    (lambda d: d["block"]["dofs"].update({'C"\npostprocess': d["block"]["dofs"]["C"]}), "DOF name"),
    (lambda d: d["block"]["dofs"]["C"].update(m="6"), "m, k, q must be finite numbers"),
])
def test_a_block_file_of_wrong_types_is_refused(tmp_path, capsys, edit, needle):
    """(d) Every field of a block file has its type: none is coerced (bool("no") is True) or pasted."""
    data = json.loads((PACKAGE / "data/blocks/robust.json").read_text())
    edit(data)
    params = tmp_path / "b.json"
    params.write_text(json.dumps(data))
    refused(capsys, "emit", ROOT / "verilog/adder2.v", "--params", params, "-o", tmp_path / "a.sim",
            "--format", "vacask", needle=needle)
    assert not (tmp_path / "a.sim").exists()


def test_a_params_name_never_becomes_a_netlist_line(tmp_path, capsys):
    """(d) A parameter file's name reaches netlist comments only, and only as printable text."""
    params = tmp_path / "p.json"
    params.write_text(json.dumps({"name": "q\n.control\nshell touch PWNED\n.endc", "q_c": 150}))
    refused(capsys, "emit", ROOT / "verilog/adder2.v", "--params", params, "-o", tmp_path / "a.cir",
            needle="name must be a string of at most 80 printable characters, not 'q\\n.control")   # which
    params.write_text(json.dumps({"name": 'q" .endc .control shell', "q_c": 150}))
    for fmt, ext in (("ngspice", "cir"), ("vacask", "sim")):
        rc, _, err = run(capsys, "emit", ROOT / "verilog/adder2.v", "--params", params, "-o", tmp_path / f"a.{ext}",
                         "--format", fmt)
        assert rc == 0, err
        lines = (tmp_path / f"a.{ext}").read_text().splitlines()
        assert not [s for s in lines if s.lstrip().lower().startswith((".control", "shell", "control"))
                    and "shell" in s.lower()]


def test_a_design_checkpoint_of_wrong_types_is_refused(tmp_path, capsys):
    """(d) `mech2spice design` resumes from its checkpoint: its fields are checked, and each entry's block
    file is validated as a block file before --install-robust could copy it into the package."""
    ck = tmp_path / "search.json"
    good = json.loads((ROOT / "reports/design_search.json").read_text())
    for bad, needle in ((["a list"], "is not a design search record"),
                        ({**good, "settings": {"sigma": "0.1"}}, "settings 'sigma' is missing or not a number"),
                        ({**good, "structures": {"nope": {}}}, "is not a structure of the grammar")):
        ck.write_text(json.dumps(bad))
        refused(capsys, "design", "--out", ck, "--structures", "classic", needle=needle)
    name = next(iter(good["structures"]))
    good["structures"][name]["block_file"]["block"]["dofs"]["I"]["slow"] = "yes"
    ck.write_text(json.dumps(good))
    refused(capsys, "design", "--out", ck, "--structures", "classic", needle="slow must be true or false")


def test_a_damaged_montecarlo_results_file_is_one_line(tmp_path, monkeypatch):
    """(d) The JSON-lines results a rerun resumes from: each line is checked before it is counted."""
    from mech2spice.errors import Mech2SpiceError
    from mech2spice.experiments import mc_run
    monkeypatch.setattr(mc_run.mc, "job_key", lambda job: "k")     # the header's job is this one
    out = tmp_path / "mc.jsonl"
    for text, line in (('{"type": "header", "key": "k"}\nnot json\n', 2),
                       ('{"type": "header", "key": "k"}\n{"type": "sample", "i": "0", "pass": true}\n', 2),
                       ('{"type": "header", "key": "k"}\n{"type": "sample", "i": 0, "pass": "yes"}\n', 2),
                       ('[1, 2]\n', 1)):
        out.write_text(text)
        with pytest.raises(Mech2SpiceError, match=f"line {line}: (not a Monte-Carlo results record|damaged)|"
                                                  "not a montecarlo results file"):
            mc_run.read_results(out, {})


def test_a_yosys_cache_entry_of_the_wrong_shape_is_ignored_and_rebuilt(tmp_path, monkeypatch):
    """The Yosys cache is rebuildable data: an entry that is not a module as build_netlist reads it is
    ignored, Yosys runs again and the entry is replaced."""
    from mech2spice.synthesis import synth
    from mech2spice.backends.logic import evaluate
    monkeypatch.setenv("MECH2SPICE_CACHE", str(tmp_path / "cache"))
    src = tmp_path / "t.v"
    src.write_text("module t(input a, input b, output y); assign y = ~(a | b); endmodule\n")
    synth.synthesize(src)
    (entry,) = (tmp_path / "cache/yosys").glob("*.json")
    entry.write_text(json.dumps({"top": "t", "module": {"ports": {"a": {"direction": "input", "bits": "x"}},
                                                        "cells": {}, "netnames": {}}}))
    assert evaluate(synth.synthesize(src), {"a": 0, "b": 0}) == {"y": 1}
    assert synth._is_module(json.loads(entry.read_text())["module"])


def test_a_compiled_model_others_can_write_is_refused(tmp_path, monkeypatch):
    """The OpenVAF cache holds code VACASK loads: a cached .osdi in a folder writable by others is refused."""
    from mech2spice.errors import Mech2SpiceError, ToolMissingError
    from mech2spice.spice import openvaf as va
    try:
        _, openvaf = va.tools()
    except ToolMissingError:
        pytest.skip("VACASK not installed")
    monkeypatch.setenv("MECH2SPICE_CACHE", str(tmp_path / "cache"))
    source = "module m(a); inout a; electrical a; analog I(a) <+ V(a); endmodule\n"
    osdi = va._osdi_path(source, "m.va", openvaf)
    osdi.parent.mkdir(parents=True)
    osdi.write_bytes(b"\x7fELF planted")
    for p in (tmp_path / "cache", tmp_path / "cache/osdi", osdi.parent):
        p.chmod(0o700)
    osdi.parent.chmod(0o777)
    with pytest.raises(Mech2SpiceError, match="writable by others"):
        va.compile_va(source, "m.va")


def test_a_verilog_path_with_a_quote_never_reaches_the_yosys_script(tmp_path, capsys):
    src = tmp_path / 'a".v'
    src.write_text("module t(input a, output y); assign y = ~a; endmodule\n")
    refused(capsys, "synth", src, needle="its path has a quote or a control character")


# ------------------------------------------------------------------ the package source

def _sources() -> list[Path]:
    return sorted(PACKAGE.rglob("*.py"))


def test_no_pickle_and_every_np_load_refuses_pickles():
    """(e) No module imports pickle (or its relatives); every np.load passes allow_pickle=False."""
    unsafe = {"pickle", "cPickle", "dill", "shelve", "marshal", "joblib", "cloudpickle"}
    for path in _sources():
        tree = ast.parse(path.read_text(), str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                assert not {a.name.split(".")[0] for a in node.names} & unsafe, f"{path}:{node.lineno}"
            elif isinstance(node, ast.ImportFrom):
                assert (node.module or "").split(".")[0] not in unsafe, f"{path}:{node.lineno}"
            elif isinstance(node, ast.Call) and _is_np_load(node.func):
                kw = {k.arg: k.value for k in node.keywords}
                ok = isinstance(kw.get("allow_pickle"), ast.Constant) and kw["allow_pickle"].value is False
                assert ok, f"{path}:{node.lineno}: np.load without allow_pickle=False"


def _is_np_load(func) -> bool:
    return (isinstance(func, ast.Attribute) and func.attr == "load" and isinstance(func.value, ast.Name)
            and func.value.id in ("np", "numpy"))


def test_no_eval_exec_or_shell_in_the_package():
    """(e) Nothing the tool reads can reach an interpreter through eval/exec or a shell."""
    for path in _sources():
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Call):
                if isinstance(node.func, ast.Name):
                    assert node.func.id not in ("eval", "exec", "compile"), f"{path}:{node.lineno}"
                for k in node.keywords:
                    shell = k.arg == "shell" and not (isinstance(k.value, ast.Constant) and k.value.value is False)
                    assert not shell, f"{path}:{node.lineno}: shell=True"
