"""reports/carrier.py without integrating anything: the markdown and the blocks other reports append, rendered
from a small synthetic JSON; the sieve section on a tiny synthetic pair of `cpu run --trace` files (a partial
carrier run, a torn last line, one probe off by a known amount, registers differing at one cycle)."""
import json

import pytest

from mech2spice.errors import Mech2SpiceError
from mech2spice.reports import REPORTS, carrier as R
from mech2spice.studies import carrier as study
from mech2spice.reports._common import write_json


def _row(method, steps, err=None, wall=1.0, failed=None):
    r = {"method": method, "steps": steps, "wall_s": wall}
    if err is not None:
        r.update(err_ur=err, final_ur=err / 2)
    if failed:
        r["failed"] = failed
    return r


def synthetic() -> dict:
    conv = {"reference": "RK4 at 640 steps per period", "fail_ur": 0.1, "load": [1.0, 1.2], "scenes": {"gate": {
        "description": "single NOR gate", "periods": 600, "members": 4, "oscillators": 6, "ref_wall_s": 2.0,
        "rows": [_row("carrier", 4, wall=0.01, failed="diverged"), _row("carrier", 12, 8e-5, 0.1),
                 _row("rk4", 20, 0.5, 0.2, "error > 0.1 u_R"), _row("rk4", 80, 1.2e-3, 0.5),
                 _row("rk4", 160, 7.5e-5, 1.0), _row("ngspice", 40, 2e-2, 3.0)]}}}
    proc = {"oscillators": 6486, "periods": 200, "repeats": 3, "load": [2.0], "rows": [
        {"method": m, "steps": n, "walls_s": [w], "median_s": w, "periods_per_s": 200 / w,
         "osc_steps_per_s": 6486 * n * 200 / w}
        for m, n, w in (("carrier N=12, 1 thread", 12, 0.33), ("carrier N=12, 2 threads", 12, 0.22),
                        ("rk4 numpy N=80", 80, 3.5), ("rk4 numpy N=160", 160, 7.0), ("rk4 compiled N=80", 80, 5.0))]}
    acc = {"steps": 12, "ref_steps": 160, "load": 1.0, "rows": [
        {"scene": "gate (nominal)", "description": "", "periods": 2500, "members": 4, "oscillators": 6,
         "rk4_wall_s": 1.0, "carrier_wall_s": 0.1, "amp_ur": 2.1e-4, "phase_deg": 0.05, "bits_equal": True,
         "pass": True},
        {"scene": "adder2 (16 inputs)", "description": "", "periods": 5800, "members": 16, "oscillators": 102,
         "rk4_wall_s": 35.0, "carrier_wall_s": 3.0, "amp_ur": 2e-3, "phase_deg": 0.05, "bits_equal": True,
         "pass": False}]}
    return {"machine": "test", "accuracy": acc, "convergence": conv, "processor": proc}


def test_markdown_and_blocks_render_from_json(tmp_path):
    write_json(tmp_path / "carrier.json", synthetic())
    R.write(tmp_path, render=True)
    md = (tmp_path / "carrier.md").read_text()
    assert "| gate (nominal) |" in md and "PASS" in md and "**FAIL**" in md
    # equal accuracy: carrier@12 (8e-5) is nearest RK4@160 (7.5e-5): 606 periods/s against 28.6 on numpy
    eq = R.equal_accuracy(synthetic()["convergence"])
    assert eq["rk4_steps"] == 160
    b = R.ratios(synthetic()["processor"], eq)["b"]
    assert b["carrier N=12, 1 thread / rk4 numpy N=160"] == pytest.approx((200 / 0.33) / (200 / 7.0))
    assert "rk4: fewest steps within 0.001 u_R: 160" in md and "4 (diverged)" in md
    assert (tmp_path / "carrier_speed_accuracy.png").exists()
    block = R.block(tmp_path)
    assert block.startswith("## Carrier-level Lawson RK4 beside RK4 and ngspice")
    assert R.roofline_block(tmp_path) == "" and R.sieve_block(tmp_path) == ""


def _trace(path, rows, torn=False):
    text = "".join(json.dumps(r) + "\n" for r in rows)
    path.write_text(text + ('{"cycle": 9, "amps": {' if torn else ""))


def _cycle(k, amps, regs=None, sim=100):
    return {"cycle": k, "registers": regs or {"pc": k, "a": 0}, "simulated_periods": sim * (k + 1), "amps": amps}


def test_sieve_section_reads_a_partial_trace_pair(tmp_path):
    env = [_cycle(k, {"x[0]": 0.5, "x[1]": 0.97}, sim=60) for k in range(5)]
    car = [_cycle(0, {"x[0]": 0.5, "x[1]": 0.97}), _cycle(1, {"x[0]": 0.53, "x[1]": 0.96}),
           _cycle(2, {"x[0]": 0.5, "x[1]": 0.97}, regs={"pc": 2, "a": 1})]
    _trace(tmp_path / "sieve_carrier.jsonl", car, torn=True)
    _trace(tmp_path / "sieve_envelope.jsonl", env)
    (tmp_path / "sieve_carrier.json").write_text("")                 # a run in progress: its result not written
    (tmp_path / "sieve_envelope.json").write_text(json.dumps({"cycles": 5, "halted": True, "wall_s": 3.0,
                                                               "periods": 900, "simulated_periods": 300}))
    s = study.sieve(tmp_path / "sieve_carrier.jsonl", tmp_path / "sieve_envelope.jsonl")
    assert s["cycles_compared"] == 3 and s["total_cycles"] == 5 and not s["complete"]
    assert s["worst_ur"] == pytest.approx([0.0, 0.03, 0.0]) and s["max_probe"] == "x[0]"
    assert s["registers_equal"] == [True, True, False]
    assert s["carrier_iss_mismatches"] == [0, 1, 2]         # synthetic registers: none is the ISS's
    assert s["periods_carrier"] == [100, 100, 100] and s["periods_envelope"] == [60, 60, 60]
    assert s["min_margin_carrier"][1] == pytest.approx(min((0.53 - 0.365) / 0.305, (0.67 - 0.53) / 0.305,
                                                          (0.96 - 0.92) / 0.105))
    out = tmp_path / "rep"
    R.write(out, only=["sieve"], carrier_trace=str(tmp_path / "sieve_carrier.jsonl"),
            envelope_trace=str(tmp_path / "sieve_envelope.jsonl"))
    block = R.sieve_block(out)
    assert "3 of 5 cycles so far" in block and "registers equal at every compared cycle: **no**" in block
    assert (out / "carrier_sieve_fidelity.png").exists()


def test_latency_section_compares_the_latency_trace_with_the_carrier_and_the_iss(tmp_path):
    """Per-cycle differences against the carrier trace, block-steps per cycle from the cumulative count, the
    ISS check on the real sieve's registers, and the processor_check --latency table."""
    iss_registers = study.iss_registers
    regs = iss_registers(3)
    car = [_cycle(k, {"x[0]": 0.5, "x[1]": 0.97}, regs=regs[k]) for k in range(3)]
    lat = [{**_cycle(k, {"x[0]": 0.5 + 0.01 * k, "x[1]": 0.97}, regs=regs[k]), "block_steps": 1000 * (k + 1) ** 2,
            "unix_time": 10.0 * k} for k in range(3)]
    _trace(tmp_path / "car.jsonl", car)
    _trace(tmp_path / "lat.jsonl", lat, torn=True)
    (tmp_path / "lat.json").write_text(json.dumps({"cycles": 3, "halted": True, "wall_s_total": 600.0,
                                                   "cpu_s_total": 540.0, "periods": 1000, "step": 1 / 12,
                                                   "latency": 0.05, "simulated_periods": 300}))
    check = {"settle_vs_full": [{"cycle": 30, "amp_diff": 0.01, "phase_diff_deg": 3.0, "registers_equal": True}],
             "settle_periods": 100, "settle_wall_s": 9.0, "full_periods": 300, "full_wall_s": 30.0,
             "latency": [{"tol": 0.05, "periods": 80, "wall_s": 2.0, "vs_full": [
                 {"cycle": 30, "amp_diff": 0.012, "phase_diff_deg": 3.1, "registers_equal": True}]}]}
    write_json(tmp_path / "check.json", check)
    s = study.latency(tmp_path / "lat.jsonl", tmp_path / "car.jsonl", tmp_path / "none.jsonl", [tmp_path / "check.json"])
    assert s["vs_carrier"]["worst_ur"] == pytest.approx([0.0, 0.01, 0.02]) and s["max_at_cycle"] == 2
    assert s["block_steps"] == [1000, 3000, 5000] and s["iss_mismatches"] == [] and s["complete"]
    assert s["vs_envelope"] == [] and s["blocks"] == 1081 and s["steps_per_period"] == 12
    md = "\n".join(R.latency_md(s, None))
    assert "halted **True**" in md and "**3 of 3 equal**" in md and "| 30-30 | + latency 0.05 | 0.0120 |" in md
    assert f"{9000 / (1081 * 12 * 1000):.1%} of all 1081 blocks" in md


def test_processor_check_refuses_a_bad_latency_before_running(tmp_path):
    from mech2spice.experiments import processor_check as pc
    rows = tmp_path / "rows.jsonl"
    for bad in ("nan", "5", "-1"):
        with pytest.raises(Mech2SpiceError, match="latency threshold"):
            pc.main(["ck.json", "--latency", bad, "--rows", str(rows)])
    assert not rows.exists()


def test_bad_section_and_missing_trace_are_one_line_errors(tmp_path):
    with pytest.raises(Mech2SpiceError, match="unknown section"):
        R.write(tmp_path, only=["nope"])
    with pytest.raises(Mech2SpiceError, match="no trace file"):
        R.write(tmp_path, only=["sieve"], carrier_trace=str(tmp_path / "none.jsonl"))
    assert "carrier_trace" in REPORTS["carrier"].options


def test_processor_check_keeps_each_finished_cycle_and_reads_a_complete_run_back(tmp_path):
    """The RK4 side of processor_check runs for hours: each cycle is appended as it finishes, and a run
    already complete in the file is read back (amplitudes exact) instead of run again."""
    import numpy as np
    from mech2spice.experiments import processor_check as pc
    rows = tmp_path / "rows.jsonl"
    amp = np.array([0.5 + 0.25j, -1e-3 + 2j])
    for k in (30, 31):
        pc._append_row(str(rows), "rk4", "ck.json", 160, {"cycle": k, "instr": None, "registers": {"pc": k},
                                                          "amp": amp * k, "simulated": 10 * k, "wall_s": 1.0},
                       ["a", "b"], 2.0)
    pc._append_row(str(rows), "carrier", "ck.json", None, {"cycle": 30, "instr": None, "registers": {},
                                                           "amp": amp, "simulated": 1, "wall_s": 1.0}, ["a", "b"], 2.0)
    pc._append_row(str(rows), "rk4", "ck.json", 160, {"cycle": 30, "instr": None, "registers": {"pc": 30},
                                                      "amp": amp * 30, "simulated": 300, "wall_s": 1.0},
                   ["a", "b"], 2.0)                # a run started over writes its cycles again
    with open(rows, "a") as f:
        f.write('{"cut short')                     # an interrupted write is skipped
    got = pc.continue_cycles("ck.json", "unused.asm", "rk4", 2, 160, rows_file=str(rows))
    assert [r["cycle"] for r in got["rows"]] == [30, 31] and got["probes"] == ["a", "b"] and got["unit"] == 2.0
    assert np.array_equal(got["rows"][1]["amp"], amp * 31)
    assert len(pc._read_rows(str(rows), "carrier", "ck.json", None)) == 1
    assert pc._read_rows(str(tmp_path / "none.jsonl"), "rk4", "ck.json", 160) == []
    merged = pc.merge([str(rows)], 160, {"settle_vs_full": [1], "other": 2})
    assert [r["cycle"] for r in merged["cycles"]] == [30]          # the cycles both engines finished
    assert merged["cycles"][0]["amp_diff"] == pytest.approx(abs(abs(amp * 30) - abs(amp)).max() * 2.0)
    assert merged["settle_vs_full"] == [1] and "other" not in merged and merged["rk4_periods"] == 300


@pytest.mark.slow
def test_processor_check_continues_an_unfinished_run_exactly(tmp_path, capsys):
    """A processor_check run stopped after its first cycle continues from the state kept beside its rows:
    its second cycle equals an unbroken run's, bit for bit (carrier; ~3 min here)."""
    import numpy as np
    from mech2spice.cli import main
    from mech2spice.experiments import processor_check as pc
    ck = tmp_path / "ck.json"
    assert main(["cpu", "run", "programs/sieve.asm", "--backend", "carrier", "--max-cycles", "1",
                 "--checkpoint", str(ck), "--json"]) == 1
    args = [str(ck), "--steps", "0", "--rows"]
    assert pc.main(args + [str(tmp_path / "a.jsonl"), "--cycles", "1"]) == 0
    assert pc.main(args + [str(tmp_path / "a.jsonl"), "--cycles", "2"]) == 0
    assert "continuing after cycle 1" in capsys.readouterr().err
    assert pc.main(args + [str(tmp_path / "b.jsonl"), "--cycles", "2"]) == 0
    a, b = ([json.loads(line) for line in open(tmp_path / f)] for f in ("a.jsonl", "b.jsonl"))
    assert [r["cycle"] for r in a] == [1, 2] == [r["cycle"] for r in b]
    for x, y in zip(a, b):
        assert np.array_equal(np.array(x["amp"]), np.array(y["amp"])) and x["registers"] == y["registers"]
