"""Blocks as data (issue #13): the classic block file builds today's model exactly, a non-classic block
builds, simulates and its batched steady state matches a settled RK4 run, bad block files give one line."""
import json

import numpy as np
import pytest

from mech2spice.backends import rk4
from mech2spice.design import grammar
from mech2spice.errors import Mech2SpiceError
from mech2spice.physics import loaded, network, nor, steady_batch
from mech2spice.physics.params import DEFAULT, load_params


@pytest.fixture(scope="module")
def adder_netlist():
    from mech2spice import data
    from mech2spice.synthesis.synth import synthesize
    return synthesize(data.verilog("adder2.v"))


def arrays(m):
    return (m.names, m.mass, m.k_total, m.c_total, m.slow, m.springs, m.dashpots, m.quads,
            [(d.dof, d.amplitude, d.phase, d.name) for d in m.drives], m.probes)


def test_classic_block_file_builds_the_default_model_exactly(adder_netlist):
    classic = load_params("classic")
    assert classic.block is not None and classic.structure.name == "classic"
    for build in (lambda p: nor.single_gate(p, 0.97, 0.5), lambda p: nor.fanout(p, 3),
                  lambda p: loaded.build(p).model, lambda p: network.build(adder_netlist, p)):
        assert arrays(build(classic)) == arrays(build(DEFAULT))


def buffer_block():
    """The classic core at the default point plus a light low-Q buffer oscillator as the output."""
    st = grammar.Structure("buffer")
    v = dict(zip(st.bounds, grammar.x_default("buffer")), d_b=0.0, lq_b=0.3, lk_cb=2.0, lm_b=0.0)
    return st.params([v[k] for k in st.bounds])


def test_non_classic_block_steady_state_matches_settled_rk4():
    p = buffer_block()
    assert p.structure.output == "B" and p.structure.n_dofs == 7
    lg = loaded.build(p)
    points = np.array([[1.0, 0.5, 0.5], [1.0, 0.97, 0.5]])
    st = steady_batch.stack([lg.model], lg.input_groups(), lg.gate.channel)
    r = steady_batch.roots(st, 0, points)
    models = [loaded.at_inputs(lg, *pt[1:]) for pt in points]
    from mech2spice.experiments.tolerance import union
    big = union(models, ["a/", "b/"])
    run = rk4.integrate(big, 2500, probes=["a/gate.B", "b/gate.B"])
    amp = np.abs(run.amp[-20:, :, 0]).mean(axis=0)
    for k in range(2):
        stable = r.amp[(r.point == k) & r.stable]
        assert stable.size == 1
        assert abs(stable[0] - amp[k]) < 2e-3 * p.u_r, (k, stable, amp[k])
    assert amp[0] > 1.5 * amp[1]                         # the inputs switch the buffered output


def write(tmp_path, data, name="b.json"):
    f = tmp_path / name
    f.write_text(json.dumps(data))
    return str(f)


def classic_file():
    return json.loads(json.dumps({"block": DEFAULT.structure.to_dict(), "f_r": 0.7, "u_r": 0.0182}))


@pytest.mark.parametrize("edit, message", [
    (lambda d: d["block"]["springs"].append(["C", "X", 10.0]), "unknown DOF 'X'"),
    (lambda d: d["block"]["dofs"]["C"].update(m=-6.0), "DOF C: m = -6.0 must be a positive number"),
    (lambda d: d["block"].pop("output"), "missing 'output'"),
    (lambda d: d["block"].update(output="I"), "output DOF 'I' must oscillate"),
    (lambda d: d["block"]["inputs"][1].pop(), "both inputs must have the same links"),
    (lambda d: d["block"]["quads"].append(["I", "C", 1.0]), "quad I-C must join an oscillating DOF to a slow"),
    (lambda d: d.update(colour="red"), "unknown key(s) colour"),
])
def test_bad_block_files_give_one_line(tmp_path, edit, message):
    d = classic_file()
    edit(d)
    with pytest.raises(Mech2SpiceError) as e:
        load_params(write(tmp_path, d))
    assert message in str(e.value) and "\n" not in str(e.value)


def test_bad_block_file_on_the_command_line(tmp_path, capsys):
    from mech2spice.cli import main
    d = classic_file()
    d["block"]["dofs"]["G1s"]["q"] = 0
    assert main(["gate", "--params", write(tmp_path, d), "--quick"]) == 2
    err = capsys.readouterr().err.strip()
    assert "DOF G1s: q = 0.0 must be a positive number" in err and len(err.splitlines()) == 1


def test_gate_params_files_still_load(tmp_path):
    p = load_params(write(tmp_path, {"q_c": 150}))
    assert p.q_c == 150 and p.block is None and p.structure.dof("C").q == 150


@pytest.mark.skipif(__import__("shutil").which("ngspice") is None, reason="ngspice not installed")
@pytest.mark.parametrize("x1", [0.5, 0.97])
def test_non_classic_block_emits_dof_by_dof_and_ngspice_matches_rk4(x1):
    from mech2spice.spice import runner as ngspice
    from mech2spice.spice.oscillator_netlist import emit
    p = buffer_block()
    m = nor.single_gate(p, x1, 0.5)
    assert "m2s_nor2" not in emit(m, 10).split(".ends")[-1]       # no classic instance for this block
    ref = rk4.integrate(m, 600, steps_per_period=40)
    got = ngspice.run(m, 600)
    a, b = ref.amp[-20:].mean(axis=0), got.amp[-20:].mean(axis=0)
    assert np.abs(np.abs(a) - np.abs(b)).max() < 0.01 * p.u_r
    assert np.abs(np.degrees(np.angle(b / a))).max() < 2.0


def test_coupled_block_steady_outputs_agree_with_the_scan_on_the_classic_gate():
    from mech2spice.experiments import characterise
    x1, x2 = np.array([0.5, 0.97, 0.5, 0.97]), np.array([0.5, 0.5, 0.97, 0.97])
    ref = characterise.steady_outputs(DEFAULT, x1, x2)
    got = characterise._coupled_steady_outputs(DEFAULT, x1, x2)
    for a, b in zip(ref, got):
        assert len(a) == len(b) and all(abs(u - v) < 1e-9 and s == t for (u, s), (v, t) in zip(a, b))
    assert characterise.steady_outputs(buffer_block(), x1, x2)[0]      # a coupled block: no error
