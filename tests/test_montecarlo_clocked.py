"""Monte-Carlo of clocked designs (`montecarlo DESIGN.v --stimulus F`) and of the processor
(`cpu montecarlo`): spread 0 is the deterministic clocked run, spread is seen, records are complete."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from mech2spice import simulation
from mech2spice.cli import main
from mech2spice.experiments import clocking, mc_clocked
from mech2spice.experiments import montecarlo as mc
from mech2spice.physics import network
from mech2spice.physics.params import DEFAULT
from mech2spice.synthesis.synth import synthesize

ROOT = Path(__file__).resolve().parent.parent
DFF_STEPS = [{"set": {"d": 1}, "cycles": 1}, {"set": {"d": 0}, "cycles": 1}]


def _dff():
    return synthesize(ROOT / "verilog/dff.v", max_fanout=network.MAX_FANOUT)


def test_clocked_spread_zero_is_the_deterministic_clocked_run():
    nl = _dff()
    d = mc_clocked.ClockedMC(nl, DEFAULT, DFF_STEPS, "envelope", mc.parse_spread("0"), 1)
    rec = d.evaluate([0])[0]
    ref = simulation.run_clocked_physical(nl, DEFAULT, simulation.expand_steps(DFF_STEPS), "envelope",
                                          clocking.clock_timing(nl))
    assert rec["pass"] and rec["margin"] == ref["min_margin"] and rec["periods"] == ref["periods"]


def test_clocked_spread_is_seen_and_large_spread_fails():
    nl = _dff()
    d = mc_clocked.ClockedMC(nl, DEFAULT, DFF_STEPS, "envelope", mc.parse_spread("0.01"), 1)
    recs = d.evaluate([0, 1])
    nominal = mc_clocked.ClockedMC(nl, DEFAULT, DFF_STEPS, "envelope", mc.parse_spread("0"), 1).evaluate([0])[0]
    assert all(r["margin"] != nominal["margin"] for r in recs)
    assert not all(r["pass"] for r in recs)          # 1 % spread: far beyond the gate's 1e-4 tolerance


def test_clocked_cli(tmp_path, capsys):
    stim = tmp_path / "s.json"
    stim.write_text(json.dumps(DFF_STEPS))
    code = main(["montecarlo", str(ROOT / "verilog/dff.v"), "--stimulus", str(stim), "--spread", "1e-5",
                 "--samples", "2", "--scheduler", "inline", "--json"])
    res = json.loads(capsys.readouterr().out)
    assert code == 0 and res["samples"] == 2 and res["yield"] == 1.0 and res["gate_failure_rate"] is None
    assert main(["montecarlo", str(ROOT / "verilog/dff.v"), "--spread", "0", "--samples", "1"]) == 2
    assert "--stimulus" in capsys.readouterr().err


def test_processor_with_noise_runs_on_the_noisy_envelope_each_sample_its_own_seed(monkeypatch):
    """cpu montecarlo --noise T: sample i's processor runs every cycle on the noisy engine, seeded from (seed, i)
    (the power-up itself is skipped here: on the noisy envelope it takes about a minute)."""
    from mech2spice.backends._noise_envelope import NoisyEnvelopeEngine
    from mech2spice.cpu.physical import PhysicalCPU
    monkeypatch.setattr(PhysicalCPU, "_reset", lambda self: None)
    noisy = mc_clocked.CpuMC(str(ROOT / "programs/sieve.asm"), 1, DEFAULT, "envelope", mc.parse_spread("0"), 5,
                             noise=1e-6)
    cpus = [noisy._machine(i) for i in (0, 1)]
    for cpu in cpus:
        assert isinstance(cpu.pulse_engine, NoisyEnvelopeEngine) and cpu.pause_engine is cpu.pulse_engine
        assert cpu.pulse_engine.options.noise_temperature == 1e-6
    assert cpus[0].pulse_engine.options.noise_seed != cpus[1].pulse_engine.options.noise_seed
    quiet = mc_clocked.CpuMC(str(ROOT / "programs/sieve.asm"), 1, DEFAULT, "envelope", mc.parse_spread("0"), 5)
    assert not isinstance(quiet._machine(0).pulse_engine, NoisyEnvelopeEngine)

@pytest.mark.slow
def test_cpu_montecarlo_spread_zero_matches_the_iss(capsys):
    """Two cycles of the sieve on the nominal processor: equal to the ISS (about 20 s)."""
    code = main(["cpu", "montecarlo", str(ROOT / "programs/sieve.asm"), "--cycles", "2", "--samples", "1",
                 "--spread", "0", "--scheduler", "inline", "--json"])
    res = json.loads(capsys.readouterr().out)
    assert code == 0 and res["failures"] == 0 and res["cycles"] == 2


@pytest.mark.slow
def test_cpu_montecarlo_with_thermal_noise_below_the_onset_matches_the_iss(capsys):
    """One sieve cycle with k_B T = 1e-6 (the gate's bits start to flip near 6e-5: reports/robustness.md) on
    the noisy envelope: the noise reaches the processor (a noisy job keys its own results) and the cycle still
    equals the ISS (about 90 s: the noisy envelope steps one period and freezes no gate)."""
    code = main(["cpu", "montecarlo", str(ROOT / "programs/sieve.asm"), "--cycles", "1", "--samples", "1",
                 "--spread", "0", "--noise", "1e-6", "--scheduler", "inline", "--json"])
    res = json.loads(capsys.readouterr().out)
    assert code == 0 and res["failures"] == 0 and res["noise"] == 1e-6
