"""Thermal noise in whole-design runs: `--spread 0 --noise 0` is the deterministic result bit for bit on
every noisy backend, a sample's noise depends only on (seed, sample), the CLI options."""
from __future__ import annotations

import json

import numpy as np
import pytest

from mech2spice import simulation
from mech2spice.cli import main
from mech2spice.cli import montecarlo as mc_cli
from mech2spice.experiments import montecarlo as mc
from mech2spice.physics import network
from mech2spice.physics.params import DEFAULT
from mech2spice.synthesis.synth import synthesize


@pytest.fixture
def nor_v(tmp_path):
    path = tmp_path / "nor1.v"
    path.write_text("module nor1(input a, input b, output y);\n  assign y = ~(a | b);\nendmodule\n")
    return path


def _design(path, backend, noise, periods=None):
    nl = synthesize(path, max_fanout=network.MAX_FANOUT)
    return nl, mc.DesignMC(nl, DEFAULT, mc.all_vectors(nl), backend, mc.parse_spread("0"), 3, periods=periods,
                           noise=noise)


@pytest.mark.parametrize("backend", ["envelope", "rk4"])
def test_spread_zero_noise_zero_is_the_deterministic_run_bit_for_bit(backend, nor_v):
    nl, d = _design(nor_v, backend, 0.0)
    amps, used = d.amplitudes([0])
    ref = simulation.run_physical(nl, DEFAULT, d.vectors, backend)
    assert used == ref[0]["periods"]
    for b, r in enumerate(ref):
        assert [amps[0, k, b] for k in range(len(d.outs))] == [r["amplitudes"][o] for o in d.outs]
    via_noise = simulation.run_physical(nl, DEFAULT, d.vectors, backend, noise=(0.0, 9))
    assert [r["amplitudes"] for r in via_noise] == [r["amplitudes"] for r in ref]


def test_ngspice_noise_zero_is_the_deterministic_netlist(nor_v):
    from mech2spice.backends import noisy_engine
    from mech2spice.spice.oscillator_netlist import emit
    _, d = _design(nor_v, "ngspice", 0.0)
    eng = noisy_engine("ngspice", None, 0.0, 4)
    assert emit(d.model, 20, d.stim, options=eng.options) == emit(d.model, 20, d.stim)


def test_noisy_sample_does_not_depend_on_its_task(nor_v):
    """Sample 1 alone and sample 1 after sample 0: the same record; another sample, other noise."""
    _, d = _design(nor_v, "envelope", 3e-4, periods=300)
    both = d.evaluate([0, 1])
    alone = d.evaluate([1])
    assert both[1] == alone[0]
    assert both[0]["margin"] != both[1]["margin"]
    assert d.union == 1


def test_noise_is_seen_and_grows_with_temperature(nor_v):
    """The output margin's spread over samples grows with T (1e-5 -> 3e-4)."""
    spreads = []
    for T in (1e-5, 3e-4):
        _, d = _design(nor_v, "rk4", T, periods=600)
        spreads.append(np.std([r["margin"] for r in d.evaluate(list(range(6)))]))
    assert 0 < spreads[0] < spreads[1]


def test_noise_zero_keeps_results_file_keys(nor_v):
    """A noiseless job has no 'noise' field, so results files of earlier sweeps still resume."""
    import argparse
    p = argparse.ArgumentParser()
    sub = p.add_subparsers()
    mc_cli.add_parser(sub)
    a = p.parse_args(["montecarlo", str(nor_v), "--samples", "2", "--spread", "0"])
    assert "noise" not in mc_cli.job_of(a)
    a = p.parse_args(["montecarlo", str(nor_v), "--samples", "2", "--spread", "0", "--noise", "1e-4"])
    assert mc_cli.job_of(a)["noise"] == 1e-4


def test_cli_noise(nor_v, capsys):
    code = main(["montecarlo", str(nor_v), "--samples", "2", "--spread", "0", "--noise", "1e-5",
                 "--periods", "300", "--scheduler", "inline", "--json"])
    res = json.loads(capsys.readouterr().out)
    assert code in (0, 1) and res["samples"] == 2 and res["noise"] == 1e-5
    assert main(["montecarlo", str(nor_v), "--samples", "2", "--spread", "0", "--noise", "-1"]) == 2
    assert main(["simulate", str(nor_v), "--set", "a=0", "--backend", "logic", "--noise", "1e-4"]) == 2
    err = capsys.readouterr().err
    assert "no thermal noise" in err and len(err.strip().splitlines()) >= 1
