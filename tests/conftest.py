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


@pytest.fixture
def generic_model():
    """Two coupled oscillators and a slow DOF: no NOR block, so emitters fall back to single elements."""
    from mech2spice.physics.model import MechModel
    m = MechModel(omega=2.0)
    a, b = m.add_dof("a", 1.0, 4.0, 0.1), m.add_dof("b", 1.0, 4.0, 0.1)
    s = m.add_dof("s", 1.0, 1.0, 0.5, slow=True)
    m.add_spring(a, b, 1.0)
    m.add_dashpot(a, b, 0.2)
    m.add_quad(a, s, 0.3)
    m.add_drive(a, 1.0)
    m.add_probe("a", a)
    return m


def run_main(*args) -> tuple[int, str, str]:
    """`mech2spice ARGS` in this process: (exit code, stdout, stderr).  The same handler as the command's (one
    line and exit 2 for bad input), without the 3 s an interpreter takes to import the engines."""
    import contextlib
    import io

    from mech2spice.cli import main
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main([str(a) for a in args])
        except SystemExit as stop:              # argparse's --help and usage errors
            code = stop.code if isinstance(stop.code, int) else 1
    return code, out.getvalue(), err.getvalue()
