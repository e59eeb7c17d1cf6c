"""experiments/blas.py: the Monte-Carlo's inline sweep runs OpenBLAS on one thread (its setup's tiny BLAS calls
spin worker threads on a loaded machine); the setting reaches every loaded library and can be put back."""
import json

import pytest

from mech2spice.experiments.blas import blas_threads, set_blas_threads


def test_set_blas_threads_reaches_every_loaded_openblas():
    before = blas_threads()
    if not before:
        pytest.skip("no OpenBLAS library in this process")
    try:
        assert set_blas_threads(1) == len(before)
        assert blas_threads() == [1] * len(before)
        set_blas_threads(2)
        assert blas_threads() == [2] * len(before)
    finally:
        for n in set(before):
            set_blas_threads(n)


def test_an_inline_sweep_runs_blas_on_one_thread_with_the_same_records(tmp_path):
    """The inline sweep sets one BLAS thread, and its records are those the same samples give at two."""
    from mech2spice.experiments import mc_run
    from mech2spice.experiments import montecarlo as mc
    from mech2spice.physics import network
    from mech2spice.synthesis.synth import synthesize
    before = blas_threads()
    if not before:
        pytest.skip("no OpenBLAS library in this process")
    nor = tmp_path / "nor1.v"
    nor.write_text("module nor1(input a, input b, output y);\n  assign y = ~(a | b);\nendmodule\n")
    nl = synthesize(str(nor), max_fanout=network.MAX_FANOUT)
    job = {"design": str(nor), "params": "default", "vectors": mc.all_vectors(nl), "backend": "envelope",
           "spread": mc.parse_spread("0.02").describe(), "seed": 3, "periods": None, "union": 2}
    try:
        set_blas_threads(2)
        mc_run._DESIGNS.clear()         # samples built anew at two threads
        two = mc_run.task(job, [0, 1, 2, 3])
        mc_run._DESIGNS.clear()
        mc_run.run(job, 4, tmp_path / "one.jsonl", scheduler="inline")
        assert blas_threads() == [1] * len(before)
        one = [json.loads(line) for line in (tmp_path / "one.jsonl").read_text().splitlines()[1:]]
        fields = lambda r: (r["i"], r["pass"], r["margin"], r["failing_bits"])
        assert sorted(map(fields, one)) == sorted(fields(json.loads(json.dumps(r))) for r in two)
    finally:
        for n in set(before):
            set_blas_threads(n)
