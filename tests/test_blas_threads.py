"""experiments/blas.py: the Monte-Carlo's inline sweep runs OpenBLAS on one thread (its setup's tiny BLAS calls
spin worker threads on a loaded machine); the setting reaches every loaded library and can be put back."""
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
