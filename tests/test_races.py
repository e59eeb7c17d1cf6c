"""Races between clocked always blocks (synthesis/races.py, docs/rtl.md "Races between clocked blocks"):
crafted racy and race-free pairs, the warning and JSON field of `synth`, the note in `verify`'s verdict, the
shipped designs (none races), and ITC'99 b12/b13 (VIS translations) when MECH2SPICE_BENCHMARKS holds rtl/."""
import json
import os
import shutil
from pathlib import Path

import pytest

from mech2spice import cli, verify
from mech2spice.errors import Mech2SpiceError
from mech2spice.synthesis import yosys
from mech2spice.synthesis.races import find
from mech2spice.synthesis.synth import synthesize

ROOT = Path(__file__).resolve().parent.parent
ICARUS = shutil.which("iverilog") and shutil.which("vvp")
needs_icarus = pytest.mark.skipif(not ICARUS, reason="Icarus Verilog (iverilog, vvp) is not installed")
SUITE = Path(os.environ.get("MECH2SPICE_BENCHMARKS", "/nonexistent")) / "rtl"
needs_suite = pytest.mark.skipif(not (SUITE / "manifest.json").is_file(),
                                 reason="MECH2SPICE_BENCHMARKS/rtl (the public RTL suite) not present")


def _design(first: str, second: str, edge2: str = "posedge clk", decls: str = "") -> str:
    """Two clocked blocks: `first` (lines 4-6) and `second` (lines 7-9); z driven on line 3 when they don't."""
    drive_z = "" if "z <=" in first + second else " always @(posedge clk) z <= b;"
    return (f"module t(input clk, input clk2, input rst, input a, input b, output reg y, output reg z);\n"
            f"  reg t1, t2;{decls}\n"
            f"  initial y = 0;{drive_z}\n"
            f"  always @(posedge clk) begin\n    {first}\n  end\n"
            f"  always @({edge2}) begin\n    {second}\n  end\n"
            f"endmodule\n")


def _races(tmp_path, text: str) -> list:
    path = tmp_path / "t.v"
    path.write_text(text)
    return list(synthesize(path).races)


def test_a_blocking_write_read_by_another_block_on_the_same_edge_is_a_race(tmp_path, capsys):
    found = _races(tmp_path, _design("t1 = a;", "y <= t1;"))
    assert [(r.variable, r.write_line, r.read_line, r.edge) for r in found] == [("t1", 5, 8, "posedge clk")]
    err = capsys.readouterr().err
    assert err.count("mech2spice: warning: ") == 1
    assert f"{tmp_path / 't.v'}, line 5: 't1' is written with a blocking '=' in one clocked block and read at line 8" in err


def test_a_block_with_an_asynchronous_reset_shares_the_clock_edge(tmp_path):
    found = _races(tmp_path, _design("t1 = a;", "if (rst) y <= 0; else y <= t1;", "posedge clk or posedge rst"))
    assert [r.variable for r in found] == ["t1"]


@pytest.mark.parametrize("first, second", [
    ("t1 <= a;", "y <= t1;"),                                 # non-blocking: the next edge, by Verilog
    ("t1 = a; z <= t1 & b;", "y <= b;"),                      # a blocking temporary read in its own block
    ("t1 = a; z <= t1;", "t1 = b; y <= t1;"),                 # ... by each block, written before it is read
    ("if (b) t1 = a; else t1 = 0; z <= t1;", "t2 = b; y <= t2;"),   # defined on every path before the read
])
def test_race_free_pairs_are_not_reported(tmp_path, first, second):
    text = _design(first, second)
    ast = _ast(tmp_path, text)
    assert find(ast, tmp_path / "t.v") == []


def test_a_read_before_the_write_on_some_path_is_exposed(tmp_path):
    """`if (b) t1 = a;` leaves t1 from before the block on the other path: B's read there races with A."""
    ast = _ast(tmp_path, _design("t1 = a;", "if (b) t1 = 0; y <= t1;"))
    assert [(r.variable, r.write_line, r.read_line) for r in find(ast, tmp_path / "t.v")] == [("t1", 5, 8)]


@pytest.mark.parametrize("edge2", ["negedge clk", "posedge clk2"])
def test_blocks_on_different_edges_or_clocks_are_not_paired(tmp_path, edge2):
    """Verilog orders those events in time (a derived clock whose edge coincides is not looked for)."""
    assert find(_ast(tmp_path, _design("t1 = a;", "y <= t1;", edge2)), tmp_path / "t.v") == []


def test_a_variable_written_by_two_clocked_blocks_is_refused_before_the_race_check(tmp_path):
    """The write-write race: two drivers (refusals.py), whatever the assignment."""
    with pytest.raises(Mech2SpiceError, match=r"'y' has more than one driver \(lines 4, 7\)"):
        _races(tmp_path, _design("if (a) y <= 1;", "if (b) y <= 0;"))


def _ast(tmp_path: Path, text: str) -> str:
    """Yosys's `read_verilog -dump_ast1` of `text` (what synthesis reads races from)."""
    (tmp_path / "t.v").write_text(text)
    result = yosys.run_script("tee -o ast.txt read_verilog -dump_ast1 t.v", tmp_path)
    assert result.returncode == 0, result.stderr
    return (tmp_path / "ast.txt").read_text()


def test_the_race_is_reported_again_from_the_synthesis_cache(tmp_path, capsys):
    text = _design("t1 = a;", "y <= t1;")
    _races(tmp_path, text)
    capsys.readouterr()
    assert [r.variable for r in _races(tmp_path, text)] == ["t1"]
    assert "'t1' is written with a blocking '='" in capsys.readouterr().err


def test_synth_json_lists_the_races(tmp_path, capsys):
    path = tmp_path / "t.v"
    path.write_text(_design("t1 = a;", "y <= t1;"))
    assert cli.main(["synth", str(path), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["races"] == [{"module": "t", "variable": "t1", "edge": "posedge clk", "write_line": 5,
                             "read_line": 8}]


@needs_icarus
def test_verify_names_the_race_and_says_a_mismatch_may_be_the_simulators_order(tmp_path):
    path = tmp_path / "t.v"
    path.write_text(_design("t1 = a;", "y <= t1;"))
    res = verify.verify(path, vectors=200, equivalence_check=False)
    assert [r["variable"] for r in res["races"]] == ["t1"]
    line = verify.text(res).splitlines()[-1]
    assert "'t1' (written line 5, read line 8)" in line
    # Icarus (measured) runs the writer first, so y takes this cycle's a: a mismatch, kept as a failure.
    assert res["cosim"]["mismatches"] and res["verdict"] == "fail"
    assert "depends on the simulator's order" in line


def test_the_shipped_designs_have_no_race(tmp_path):
    for path in sorted((ROOT / "verilog").glob("*.v")):
        if path.name == "bad_syntax.v":
            continue
        shutil.copy(path, tmp_path / path.name)
        result = yosys.run_script(f"tee -o ast.txt read_verilog -dump_ast1 {path.name}", tmp_path)
        assert result.returncode == 0, (path.name, result.stderr)
        assert find((tmp_path / "ast.txt").read_text(), path) == [], path.name


@needs_suite
@pytest.mark.parametrize("name, expected", [
    ("b12", {"num", "data_out", "play", "wr", "address", "data_in", "sound"}),
    ("b13", {"send_data", "rdy", "shot", "load", "confirm", "send", "send_en", "out_reg", "tx_end"}),
])
def test_itc99_b12_and_b13_race(name, expected):
    nl = synthesize(SUITE / f"itc99_{name}_vis" / f"itc99_{name}_vis.sv", top=name)
    assert {r.variable for r in nl.races} == expected
    if name == "b13":      # docs/rtl.md: `tx_end = 1` in one block, `if (tx_end)` in another
        assert any(r.variable == "tx_end" and r.write_line == 220 and r.read_line == 169 for r in nl.races)


def test_a_cache_entry_with_malformed_races_is_rebuilt(tmp_path, capsys, monkeypatch):
    """The cache is anyone's data: races that are not (str, str, str, int|None, int|None) rows send the
    design through Yosys again, which finds the race anew."""
    from mech2spice.synthesis import synth
    text = _design("t1 = a;", "y <= t1;")
    _races(tmp_path, text)
    key = synth._cache_key((tmp_path / "t.v").read_text(), None, name="t.v")
    entry = json.loads(synth._cache_path(key).read_text())
    for bad in (None, [{"variable": 3}], [{**entry["races"][0], "write_line": "5"}]):
        synth._cache_path(key).write_text(json.dumps({**entry, "races": bad}))
        assert synth._cache_read(key) is None
    capsys.readouterr()
    assert [r.variable for r in _races(tmp_path, text)] == ["t1"]



def test_the_verdict_note_says_order_only_when_the_co_simulation_mismatches():
    race = {"variable": "t1", "write_line": 5, "read_line": 8}
    agreed = verify._race_text({"races": [race], "cosim": {"mismatches": []}})
    assert "'t1' (written line 5, read line 8)" in agreed and "simulator's order" not in agreed
    differed = verify._race_text({"races": [race], "cosim": {"mismatches": [{}]}})
    assert "depends on the simulator's order" in differed
    assert verify._race_text({"races": [], "cosim": {"mismatches": [{}]}}) == ""
