"""Processor Monte-Carlo samples integrated together (cpu/batch.py) and the fan-out limit as a processor option:
the batched records equal the lone runs', a copy that fails stops without disturbing the others, the flags."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mech2spice.cli import main
from mech2spice.cpu.batch import BatchCPU, union_model
from mech2spice.cpu.iss import ISS
from mech2spice.cpu.physical import PhysicalCPU
from mech2spice.cpu.run import load_program, make_memory
from mech2spice.experiments import montecarlo as mc
from mech2spice.experiments.mc_clocked import CpuMC
from mech2spice.physics import network
from mech2spice.physics.params import load_params
from mech2spice.synthesis.synth import synthesize

ROOT = Path(__file__).resolve().parents[1]
SIEVE = str(ROOT / "programs/sieve.asm")
KEYS = ("pass", "failing_bits", "first_bad_cycle", "cycles_run", "reason")


def _trimmed(sigma: float):
    return mc.spec_of({"local": sigma, "trim": "fc", "trim_residual": 1e-4})


def test_union_model_keeps_each_copys_gate_blocks():
    """The union's gate blocks are each copy's, moved to its DOFs (the settle watch and latency blocks read them)."""
    p = load_params("default")
    one = network.build(synthesize(ROOT / "verilog/counter4.v", max_fanout=network.MAX_FANOUT), p)
    big = union_model([one, one], ["s0/", "s1/"])
    assert big.n == 2 * one.n and len(big.design.gates) == 2 * len(one.design.gates)
    for k, pre in enumerate(("s0/", "s1/")):
        for g, h in zip(one.design.gates, big.design.gates[k * len(one.design.gates):]):
            assert big.names[h.channel] == pre + one.names[g.channel]
            assert [big.names[d] for d in h.dofs] == [pre + one.names[d] for d in g.dofs]
            assert big.names[h.insulator] == pre + one.names[g.insulator]


@pytest.mark.slow
def test_batched_samples_give_their_lone_records():
    """Spread 1.5 %, trimmed: sample 2 runs 3 cycles equal to the ISS, 4 differs from the ISS in cycle 0 (and is
    retired: frozen from then on), 3 stops on an invalid register bit (nx, 0.542 u_R; measured on the lone path).
    Samples 2 and 4 in one union model get their lone records.  Sample 3 is marginal: alone, its cycle-0 pause
    ends at its own settle and reads the latch invalid in cycle 1; in the union the pause runs on until the
    others settled and it reads invalid in cycle 2 (docs/design.md, "The processor under spread, round 2")."""
    lone = CpuMC(SIEVE, 3, load_params("centered_fc2"), "envelope", _trimmed(0.015), 7)
    batched = CpuMC(SIEVE, 3, load_params("centered_fc2"), "envelope", _trimmed(0.015), 7, batch=3)
    want, got = lone.evaluate([2, 3, 4]), batched.evaluate([2, 3, 4])
    assert [r["pass"] for r in want] == [True, False, False]        # the three paths are all exercised
    assert "invalid" in want[1]["reason"] and want[2]["first_bad_cycle"] == 0
    for w, g in (want[0], got[0]), (want[2], got[2]):
        assert {k: w.get(k) for k in KEYS} == {k: g.get(k) for k in KEYS}
    assert not got[1]["pass"] and "register nx bit 0 (latch q42) is invalid" in got[1]["reason"]


@pytest.mark.slow
def test_batched_copies_hold_their_lone_amplitudes():
    """Two passing samples (1 %, trimmed) after 4 cycles: every register latch's amplitude within 0.02 u_R of
    its lone run's (a union pause ends when both copies settled, a lone one at its own settle: the settle
    tolerance is 0.1 u_R)."""
    m = CpuMC(SIEVE, 4, load_params("centered_fc2"), "envelope", _trimmed(0.01), 7)
    lone = [m._machine(i) for i in (0, 1)]
    bc = BatchCPU([m._machine(i, power_up=False) for i in (0, 1)])
    for _ in range(4):
        got = bc.step()
        want = [c.step() for c in lone]
        assert got == want
    for c, b in zip(lone, bc.cpus):
        latches = [k for k in c.amps if k.startswith("latch.")]
        diff = max(abs(c.amps[k] - b.amps[k]) for k in latches)
        assert diff < 0.02, diff


def test_max_fanout_builds_buffer_trees_and_runs_as_the_iss():
    """--max-fanout 4: no gate drives more than 4 loads, more gates; nominal cycles equal the ISS's."""
    p = load_params("centered_fc2")
    wide = PhysicalCPU(make_memory(load_program(SIEVE)), "envelope", p, power_up=False)
    cpu = PhysicalCPU(make_memory(load_program(SIEVE)), "envelope", p, max_fanout=4)
    g = cpu.netlist.graph
    assert max(g.out_degree(n) for n in cpu.netlist.gates()) <= 4
    assert max(wide.netlist.graph.out_degree(n) for n in wide.netlist.gates()) > 4
    assert len(cpu.model.design.gates) > len(wide.model.design.gates)
    iss = ISS(make_memory(load_program(SIEVE)))
    for _ in range(3):
        assert cpu.step() == iss.step()


def test_max_fanout_flag_is_refused_off_the_oscillator_level(capsys):
    assert main(["cpu", "run", SIEVE, "--max-fanout", "4"]) == 2
    assert "--max-fanout applies to" in capsys.readouterr().err
    assert main(["cpu", "montecarlo", SIEVE, "--samples", "1", "--spread", "0.01", "--max-fanout", "1"]) == 2


def test_cpu_job_keys_stay_for_the_defaults():
    """Results files written before --batch and --max-fanout keep their keys: batch 1 is the old union 1 and
    the network's own limit adds no field; another limit or batch is another job."""
    import argparse
    from mech2spice.cli.montecarlo import cpu_job_of
    base = dict(program=SIEVE, cycles=30, params="centered_fc2", backend="envelope", spread="0.01", trim="fc",
                trim_residual=1e-4, drift=None, seed=7, noise=0.0)
    job = lambda **kw: cpu_job_of(argparse.Namespace(**{**base, "max_fanout": None, **kw}))
    assert job()["union"] == 1 and "max_fanout" not in job()
    assert mc.job_key(job(max_fanout=network.MAX_FANOUT)) == mc.job_key(job())
    assert mc.job_key(job(max_fanout=4)) != mc.job_key(job())


def test_cpu_job_step_enters_the_key_only_when_set():
    """--step: files of the processor's own step keep their keys; another step is another job; off the
    envelope backend it is refused before any work."""
    import argparse
    from mech2spice.cli.montecarlo import cpu_job_of
    from mech2spice.errors import Mech2SpiceError
    base = dict(program=SIEVE, cycles=30, params="centered_fc2", backend="envelope", spread="0.01", trim="fc",
                trim_residual=1e-4, drift=None, seed=7, noise=0.0, max_fanout=4)
    job = lambda **kw: cpu_job_of(argparse.Namespace(**{**base, **kw}))
    assert "step" not in job() and mc.job_key(job(step=None)) == mc.job_key(job())
    assert job(step=10.0)["step"] == 10.0 and mc.job_key(job(step=10.0)) != mc.job_key(job())
    with pytest.raises(Mech2SpiceError, match="envelope backend"):
        job(step=10.0, backend="rk4")


def test_cpu_job_records_the_processors_etd_step_cap():
    """A new envelope job records the step cap under ETDRK4 (20) and is a job of its own; a results file written
    before it (its job names the integrator but no cap) resumes at the 16 it was run at."""
    import argparse
    from mech2spice.cli.montecarlo import cpu_job_of
    from mech2spice.cpu.physical import ETD_PROCESSOR_STEP
    from mech2spice.experiments import mc_run
    base = dict(program=SIEVE, cycles=2, params="centered_fc2", backend="envelope", spread="0.01", trim="fc",
                trim_residual=1e-4, drift=None, seed=7, noise=0.0, max_fanout=4, step=None)
    job = cpu_job_of(argparse.Namespace(**base))
    assert job["integrator"] == "etd" and job["etd_step"] == ETD_PROCESSOR_STEP == 20.0
    old = {k: v for k, v in job.items() if k != "etd_step"}
    assert mc.job_key(old) != mc.job_key(job)
    assert mc_run.design_for(old)._machine(0, power_up=False).step_periods == 16.0
    assert mc_run.design_for(job)._machine(0, power_up=False).step_periods == 20.0
    assert "etd_step" not in cpu_job_of(argparse.Namespace(**{**base, "backend": "rk4"}))


def test_cpu_montecarlo_step_above_the_bound_is_refused_up_front(capsys):
    assert main(["cpu", "montecarlo", SIEVE, "--samples", "1", "--cycles", "1", "--spread", "0.01",
                 "--max-fanout", "4", "--params", "centered_fc2", "--scheduler", "inline", "--step", "50"]) == 2
    assert "exceeds the stability limit" in capsys.readouterr().err


def test_the_etd_step_gives_a_sample_the_same_cycles():
    """The processor's own step under ETDRK4 (20: the fan-out-4 processor's bound is ~24) against 16, the cap before
    it (as older Monte-Carlo files ask): the sample really runs at 20 and its cycles (read and write addresses and
    data) are the ones step 16 gives, and the ISS's."""
    p, spec = load_params("centered_fc2"), _trimmed(0.01)
    runs = {}
    for cap in (None, 16.0):
        mcx = CpuMC(SIEVE, 2, p, "envelope", spec, 7, max_fanout=4, etd_step=cap)
        cpu = mcx._machine(1)
        runs[cap] = (cpu.step_periods, [cpu.step() for _ in mcx.want], mcx.want)
    assert runs[None][0] == 20.0 and runs[16.0][0] == 16.0
    assert runs[16.0][1] == runs[None][1]
    assert [(c.pc, c.raddr, c.rdata) for c in runs[None][1]] == [(c.pc, c.raddr, c.rdata) for c in runs[None][2]]


def test_cpu_job_records_the_processors_calm_rule():
    """A new envelope job records the latency calm rule (cpu/physical.LATENCY_CALM) and wake threshold
    (LATENCY_WAKE) and is a job of its own; a results file written before either resumes under the rule it was
    run with (latency_calm, latency_wake None)."""
    import argparse
    from mech2spice.cli.montecarlo import cpu_job_of
    from mech2spice.cpu.physical import LATENCY_CALM, LATENCY_WAKE
    from mech2spice.experiments import mc_run
    base = dict(program=SIEVE, cycles=2, params="centered_fc2", backend="envelope", spread="0.01", trim="fc",
                trim_residual=1e-4, drift=None, seed=7, noise=0.0, max_fanout=4, step=None)
    job = cpu_job_of(argparse.Namespace(**base))
    assert job["latency_calm"] == LATENCY_CALM == 40.0
    old = {k: v for k, v in job.items() if k != "latency_calm"}
    assert mc.job_key(old) != mc.job_key(job)
    assert mc_run.design_for(old)._machine(0, power_up=False).latency_calm is None
    assert mc_run.design_for(job)._machine(0, power_up=False).latency_calm == 40.0
    assert "latency_calm" not in cpu_job_of(argparse.Namespace(**{**base, "backend": "rk4"}))
    assert job["latency_wake"] == LATENCY_WAKE == 0.05
    calm_only = {k: v for k, v in job.items() if k != "latency_wake"}
    assert mc.job_key(calm_only) != mc.job_key(job)
    assert mc_run.design_for(calm_only)._machine(0, power_up=False).latency_wake is None
    assert mc_run.design_for(job)._machine(0, power_up=False).latency_wake == 0.05


def test_the_calm_rule_integrates_fewer_blocks_to_the_same_cycles():
    """A spread sample under the calm rule and under the hold rule before it: the same cycle records (the ISS's),
    every latch and port bit read in the same band within 0.02 u_R, and fewer gate-block steps (docs/latency.md:
    20 % fewer on the fan-out-12 processor's first 30 sieve cycles)."""
    p, spec = load_params("centered_fc2"), _trimmed(0.01)
    runs = {}
    for calm in ("own", None):
        mcx = CpuMC(SIEVE, 3, p, "envelope", spec, 7, max_fanout=4, latency_calm=calm)
        cpu = mcx._machine(1)
        cycles = [cpu.step() for _ in mcx.want]
        runs[calm] = (cpu.latency_calm, cycles, np.array([cpu.amps[q] for q in cpu.probes]), cpu.block_steps)
    assert runs["own"][0] == 40.0 and runs[None][0] is None
    assert runs["own"][1] == runs[None][1]
    assert [(c.pc, c.raddr, c.rdata) for c in runs["own"][1]] == [(c.pc, c.raddr, c.rdata) for c in mcx.want]
    bands = np.vectorize(p.levels.band_of)
    assert (bands(runs["own"][2]) == bands(runs[None][2])).all()
    assert np.abs(runs["own"][2] - runs[None][2]).max() < 0.02
    assert runs["own"][3] < 0.95 * runs[None][3]
