import numpy as np
import pytest

from mech2spice.physics import nor, params
from mech2spice.experiments.characterise import run_from_rest
from mech2spice.experiments.scenes import LEVEL, PAIRS


@pytest.fixture(scope="session")
def p():
    return params.DEFAULT


@pytest.fixture(scope="session")
def gate_run(p):
    """Single gate, the four nominal input pairs as one RK4 batch, settled from rest."""
    levels = np.array([[LEVEL[a], LEVEL[b]] for a, b in PAIRS])
    run, amp = run_from_rest(nor.single_gate(p), p, levels, 2000)
    return run, amp[0]
