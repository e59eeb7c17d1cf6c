"""Outputs never lose an input (issue #26, "Lost inputs"): one rule for every file a command writes.

An output is never an input of the same command, never an existing file of another kind without --force,
and its folder is checked before any work.  Each refusal is one line on stderr and exit 2, and every file
the command named keeps its bytes and its modification time.  Commands run in-process; `no_work` makes
any simulation, search or machine build fail the test, so a refusal must come before them.
"""
import json
import os
from pathlib import Path

import pytest

from mech2spice.physics.params import BLOCK_PRESETS

from mech2spice import api, data
from mech2spice.cli import main
from mech2spice.errors import Mech2SpiceError

ROOT = Path(__file__).resolve().parents[1]
ADDER, SIEVE = ROOT / "verilog/adder2.v", ROOT / "programs/sieve.asm"
PAST = 1_000_000_000 * 10 ** 9                   # an old mtime (ns): any rewrite moves it
NOR = "module t(input a, input b, output y);\n  assign y = ~(a | b);\nendmodule\n"
DESIGN = ["design", "--structures", "classic", "--samples", "2", "--maxiter", "1", "--popsize", "2",
          "--budget-s", "1", "--tol-samples", "100"]
SETTINGS = {"sigma": 0.01, "samples": 2, "seed": 0, "maxiter": 1, "popsize": 2, "budget_s": 1.0, "tol_samples": 100}


def keep(*files: Path) -> dict:
    """Each file's bytes and mtime, the mtime first set in the past so that any rewrite shows."""
    for f in files:
        os.utime(f, ns=(PAST, PAST))
    return {f: (f.read_bytes(), f.stat().st_mtime_ns) for f in files}


def intact(kept: dict) -> None:
    for f, (content, mtime) in kept.items():
        assert f.read_bytes() == content and f.stat().st_mtime_ns == mtime, f"{f} was changed"


def refused(capsys, kept: dict, *argv, needle: str) -> str:
    """Exit 2, one line on stderr holding `needle`, nothing on stdout, every kept file intact."""
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert rc == 2, (rc, out, err)
    assert err.count("\n") == 1 and "Traceback" not in err and not out, err
    assert needle in err, err
    intact(kept)
    return err


def ok(capsys, *argv) -> str:
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert rc in (0, 1), (rc, out, err)
    return out


@pytest.fixture
def no_work(monkeypatch):
    """Synthesis of a model, machines, Monte-Carlo runs and design searches all fail the test."""
    from mech2spice.cpu import run as cpu_run
    from mech2spice.design import search
    from mech2spice.experiments import mc_run
    from mech2spice.physics import network

    def boom(*args, **kwargs):
        raise AssertionError("work started before the output path was checked")
    for module, name in ((cpu_run, "make_cpu"), (search, "search_structure"), (mc_run, "run"),
                         (network, "build")):
        monkeypatch.setattr(module, name, boom)


def write(path: Path, content) -> Path:
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    return path


# ------------------------------------------------------------------ montecarlo --out: never an input

@pytest.fixture
def mc_files(tmp_path):
    """A design, and --spread, --stimulus and --params files written as one JSON line without a newline
    (the shape a results file's torn-line repair used to cut away)."""
    return {"design": write(tmp_path / "t.v", NOR),
            "spread": write(tmp_path / "spread.json", json.dumps({"local": 0.01})),
            "stimulus": write(tmp_path / "stim.json", json.dumps([{"set": {"a": 1}}])),
            "params": write(tmp_path / "params.json", json.dumps({"q_c": 190.0}))}


def _mc_argv(f: dict, out: Path) -> list:
    return ["montecarlo", f["design"], "--samples", "1", "--scheduler", "inline", "--spread", f["spread"],
            "--stimulus", f["stimulus"], "--params", f["params"], "--out", out]


@pytest.mark.parametrize("which", ["spread", "stimulus", "params", "design"])
def test_montecarlo_out_is_never_one_of_its_inputs(capsys, no_work, mc_files, which):
    refused(capsys, keep(*mc_files.values()), *_mc_argv(mc_files, mc_files[which]), needle="refusing")


def test_cpu_montecarlo_out_is_never_its_spread_or_program(tmp_path, capsys, no_work):
    spread, prog = write(tmp_path / "s.json", '{"local": 0.01}'), write(tmp_path / "p.asm", SIEVE.read_text())
    kept = keep(spread, prog)
    for out in (spread, prog):
        refused(capsys, kept, "cpu", "montecarlo", prog, "--samples", "1", "--spread", spread,
                "--scheduler", "inline", "--out", out, needle="refusing")


def test_montecarlo_out_of_another_kind_is_refused_before_truncation(tmp_path, capsys, no_work, mc_files):
    notes = write(tmp_path / "notes.txt", "line one\nline two without a newline")
    refused(capsys, keep(notes, *mc_files.values()), *_mc_argv(mc_files, notes),
            needle="not a montecarlo results file")


def _header(f: dict) -> str:
    """The header line a montecarlo run of these files writes (its job key)."""
    from mech2spice.cli import build_parser
    from mech2spice.cli import montecarlo as mc_cli
    from mech2spice.experiments import montecarlo as mc
    job = mc_cli.job_of(build_parser().parse_args([str(a) for a in _mc_argv(f, Path("x"))]))
    return json.dumps({"type": "header", "key": mc.job_key(job), "job": job}) + "\n"


@pytest.mark.parametrize("body,needle", [
    (b"\x00\xff\xfe binary", "not a montecarlo results file"),
    (b'[{"type": "header"}]\n', "not a montecarlo results file"),
    (b'{"type": "header"}\n', "not a montecarlo results file"),          # no job key
    ("HEADER" + '{"type": "sample", "i": 0, "pass": true}\n{"type": "sa\n{"type": "sample", "i": 1, "pass": true}\n',
     "line 3"),                                                             # a damaged line before the last
    ("HEADER" + '{"type": "sample", "pass": true}\n', "line 2"),           # a sample without its index
    ("HEADER" + '{"type": "sample", "i": 0}\n', "line 2"),                 # nor its verdict
], ids=["binary", "list", "no-key", "damaged", "no-index", "no-pass"])
def test_damaged_montecarlo_results_are_one_line_and_untouched(tmp_path, capsys, mc_files, body, needle):
    out = write(tmp_path / "r.jsonl", body.replace("HEADER", _header(mc_files)) if isinstance(body, str) else body)
    refused(capsys, keep(out, *mc_files.values()), *_mc_argv(mc_files, out), needle=needle)


def test_results_of_another_kind_are_not_cut_by_the_runner(tmp_path):
    """mc_run.run itself (the API under the command) checks the header before repairing a torn line."""
    from mech2spice.experiments import mc_run
    notes = write(tmp_path / "notes.txt", "no newline at the end")
    kept = keep(notes)
    with pytest.raises(Mech2SpiceError, match="not a montecarlo results file"):
        mc_run.run({"design": "x"}, 1, notes, scheduler="inline")
    intact(kept)


# ------------------------------------------------------------------ cpu run --trace / --checkpoint

def _params(tmp_path) -> Path:
    return write(tmp_path / "p.json", '{"q_c": 190.0}')


def test_cpu_run_trace_is_never_its_params_file(tmp_path, capsys, no_work):
    params = _params(tmp_path)
    refused(capsys, keep(params), "cpu", "run", SIEVE, "--backend", "envelope", "--params", params,
            "--max-cycles", "1", "--trace", params, needle="refusing")


def test_cpu_run_checkpoint_is_never_its_params_file(tmp_path, capsys, no_work):
    params = _params(tmp_path)
    refused(capsys, keep(params), "cpu", "run", SIEVE, "--backend", "envelope", "--params", params,
            "--max-cycles", "1", "--checkpoint", params, needle="refusing")


def test_cpu_run_trace_and_checkpoint_are_not_one_file(tmp_path, capsys):
    ck = tmp_path / "ck.json"
    assert main(["cpu", "run", str(SIEVE), "--max-cycles", "3", "--checkpoint", str(ck)]) == 1
    capsys.readouterr()
    refused(capsys, keep(ck), "cpu", "run", SIEVE, "--max-cycles", "3", "--checkpoint", ck, "--trace", ck,
            needle="refusing")


def test_cpu_run_trace_onto_another_kind_needs_force(tmp_path, capsys):
    notes = write(tmp_path / "notes.txt", "my notes\n")
    refused(capsys, keep(notes), "cpu", "run", SIEVE, "--max-cycles", "3", "--trace", notes, needle="--force")
    ok(capsys, "cpu", "run", SIEVE, "--max-cycles", "3", "--trace", notes, "--force")
    assert len(notes.read_text().splitlines()) == 3
    ok(capsys, "cpu", "run", SIEVE, "--max-cycles", "2", "--trace", notes)      # now a trace: replaced
    assert len(notes.read_text().splitlines()) == 2


def test_cpu_run_checkpoint_onto_another_kind_needs_force(tmp_path, capsys):
    notes = write(tmp_path / "notes.txt", "my notes\n")
    refused(capsys, keep(notes), "cpu", "run", SIEVE, "--max-cycles", "3", "--checkpoint", notes,
            needle="not a processor checkpoint")
    ok(capsys, "cpu", "run", SIEVE, "--max-cycles", "3", "--checkpoint", notes, "--force")
    assert json.loads(notes.read_text())["cycle"] == 3


# ------------------------------------------------------------------ emit, cpu emit, cpu asm, the API

def test_emit_output_is_never_its_params_file(tmp_path, capsys, no_work):
    params = _params(tmp_path)
    refused(capsys, keep(params), "emit", ADDER, "--params", params, "-o", params, needle="refusing")


def test_emit_through_a_link_to_its_design_is_refused(tmp_path, capsys, no_work):
    src = write(tmp_path / "d.v", NOR)
    link = tmp_path / "link.cir"
    link.symlink_to(src)
    refused(capsys, keep(src), "emit", src, "-o", link, needle="refusing")


def test_emit_onto_another_kind_needs_force(tmp_path, capsys):
    notes = write(tmp_path / "notes.txt", "my notes\n")
    refused(capsys, keep(notes), "emit", ADDER, "-o", notes, needle="--force")
    ok(capsys, "emit", ADDER, "-o", notes, "--force")
    assert "mech2spice" in notes.read_text().splitlines()[0]
    ok(capsys, "emit", ADDER, "-o", notes, "--format", "veriloga")       # its own kind: replaced


@pytest.mark.parametrize("argv", [["cpu", "emit", SIEVE, "--cycles", "2"], ["cpu", "asm", SIEVE]],
                         ids=["cpu-emit", "cpu-asm"])
def test_cpu_outputs_onto_another_kind_need_force(tmp_path, capsys, no_work, argv):
    notes = write(tmp_path / "notes.txt", "my notes\n")
    refused(capsys, keep(notes), *argv, "-o", notes, needle="--force")


def test_cpu_asm_replaces_its_own_image_and_with_force_another_file(tmp_path, capsys):
    image, notes = tmp_path / "s.bin", write(tmp_path / "notes.txt", "my notes\n")
    ok(capsys, "cpu", "asm", SIEVE, "-o", image)
    ok(capsys, "cpu", "asm", SIEVE, "-o", image)
    ok(capsys, "cpu", "asm", SIEVE, "-o", notes, "--force")
    assert notes.read_bytes() == image.read_bytes()


def test_api_emit_never_writes_over_its_design(tmp_path):
    src, notes = write(tmp_path / "d.v", NOR), write(tmp_path / "notes.txt", "my notes\n")
    kept = keep(src, notes)
    with pytest.raises(Mech2SpiceError, match="refusing"):
        api.emit(str(src), path=src)
    with pytest.raises(Mech2SpiceError, match="force=True"):
        api.emit(str(src), path=notes)
    intact(kept)
    text = api.emit(str(src), path=notes, force=True)
    assert notes.read_text() == text


# ------------------------------------------------------------------ design --out / --merge / --install-robust

def _record(margin: float = 0.05, **block_changes) -> dict:
    """A complete design search record of one structure, from the shipped robust block."""
    block = json.loads(data.path("blocks", "robust.json").read_text())
    block_file = {k: block[k] for k in ("block", "f_r", "u_r", "omega", "search", "measured")}
    block_file["block"] = {**block_file["block"], **block_changes}
    rec = {"structure": "classic", "parameters": {"x": 1.0}, "score": -2.5, "search": block["search"],
           "measured": {**block["measured"], "nominal_margin": margin}, "block_file": block_file}
    return {"settings": dict(SETTINGS), "structures": {"classic": rec}}


def _missing_measured() -> str:
    rec = _record()
    del rec["structures"]["classic"]["measured"]["tolerance"]
    return json.dumps(rec)


DAMAGED = {"binary": b"\x89PNG\r\n\x1a\n\x00\x00", "list": "[1, 2, 3]", "truncated": json.dumps(_record())[:200],
           "not-a-record": '{"my": "notes"}', "missing-field": _missing_measured()}


@pytest.mark.parametrize("name", list(DAMAGED))
def test_design_out_of_another_kind_or_damaged_is_refused_before_the_search(tmp_path, capsys, no_work, name):
    out = write(tmp_path / "out.json", DAMAGED[name])
    refused(capsys, keep(out), *DESIGN, "--out", out, needle=str(out))


@pytest.mark.parametrize("name", list(DAMAGED))
def test_design_merge_of_a_damaged_record_is_one_line(tmp_path, capsys, name):
    out, other = write(tmp_path / "out.json", json.dumps(_record())), write(tmp_path / "o.json", DAMAGED[name])
    refused(capsys, keep(out, other), "design", "--merge", other, "--out", out, needle=str(other))


def test_design_merge_into_itself_is_refused(tmp_path, capsys):
    out = write(tmp_path / "out.json", json.dumps(_record()))
    refused(capsys, keep(out), "design", "--merge", out, "--out", out, needle="refusing")


@pytest.mark.parametrize("where", ["afile/out.json", "afile/new/out.json", "/sys/mech2spice-design.json",
                                   "/sys/new/out.json"])
def test_design_out_to_an_unwritable_place_fails_before_the_search(tmp_path, capsys, no_work, where):
    afile = write(tmp_path / "afile", "x")
    refused(capsys, keep(afile), *DESIGN, "--out", tmp_path / where, needle="cannot write")


@pytest.fixture
def package_blocks(tmp_path, monkeypatch):
    """The package's blocks/ folder, a copy under tmp_path: installs land there, never in the checkout."""
    real, blocks = data.path, tmp_path / "pkg" / "blocks"
    blocks.mkdir(parents=True)
    for f in real("blocks").iterdir():
        (blocks / f.name).write_bytes(f.read_bytes())
    monkeypatch.setattr(data, "path", lambda *parts: blocks.joinpath(*parts[1:]) if parts[:1] == ("blocks",)
                        else real(*parts))
    return blocks


@pytest.mark.parametrize("damage", [
    {"dofs": {}},                                                       # a block that does not build
    {"source": {"dof": "C", "force": 50.0}},                            # builds, but the gate does not work
], ids=["does-not-build", "fails-its-check"])
def test_install_robust_never_installs_a_damaged_block(tmp_path, capsys, package_blocks, damage):
    out, other = write(tmp_path / "out.json", json.dumps(_record())), tmp_path / "o.json"
    better = _record(**damage)
    better["structures"]["classic"]["measured"]["tolerance"] = 1.0      # wins the merge
    write(other, json.dumps(better))
    err = refused(capsys, keep(package_blocks / "robust.json"), "design", "--merge", other, "--out", out,
                  "--install-robust", "--json", needle="")
    assert "not installed" in err or "block_file" in err, err      # refused at install, or already when read


def test_install_robust_without_a_working_block_is_refused(tmp_path, capsys, package_blocks):
    out, other = (write(tmp_path / n, json.dumps(_record(margin=-0.1))) for n in ("out.json", "o.json"))
    refused(capsys, keep(package_blocks / "robust.json"), "design", "--merge", other, "--out", out,
            "--install-robust", "--json", needle="no structure")


def test_install_robust_installs_a_checked_block_atomically(tmp_path, capsys, package_blocks):
    out, other = write(tmp_path / "out.json", json.dumps(_record())), write(tmp_path / "o.json", json.dumps(_record()))
    ok(capsys, "design", "--merge", other, "--out", out, "--install-robust", "--json")
    installed = json.loads((package_blocks / "robust.json").read_text())
    assert installed["block"] == _record()["structures"]["classic"]["block_file"]["block"]
    assert installed["name"] == "robust"
    assert sorted(f.name for f in package_blocks.iterdir()) == sorted(f"{n}.json" for n in BLOCK_PRESETS)  # no temp file left


# ------------------------------------------------------------------ report --out

def test_report_out_under_a_file_is_refused_before_work(tmp_path, capsys, monkeypatch):
    from mech2spice.reports import cli as report_cli
    monkeypatch.setattr(report_cli, "module", lambda name: pytest.fail("the report ran"))
    afile = write(tmp_path / "afile", "x")
    refused(capsys, keep(afile), "report", "gate", "--out", afile / "sub", needle="not a directory")


def test_report_never_writes_over_a_file_its_options_read(tmp_path, capsys, monkeypatch):
    from mech2spice.reports import cli as report_cli
    monkeypatch.setattr(report_cli, "module", lambda name: pytest.fail("the report ran"))
    trace = write(tmp_path / "carrier.md", '{"cycle": 0, "registers": {}}\n')
    refused(capsys, keep(trace), "report", "carrier", "--render", "--out", tmp_path, "--carrier-trace", trace,
            needle="refusing")
