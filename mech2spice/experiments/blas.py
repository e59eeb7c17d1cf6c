"""How many threads the OpenBLAS libraries loaded in this process use.

A Monte-Carlo sample's setup (the envelope's spectral rate by ARPACK, the insulators' 2 x 2 propagators by
scipy's expm, one per insulator) calls BLAS many times on tiny operands.  On a shared, loaded machine
OpenBLAS's worker threads then spin on each call: one 2-cycle processor sample cost 2.97 core-s with
them against 1.17 with one thread, its power-up 2.40 against 0.54 (scripts/cpu_mc_profile.py at load 6-7,
docs/design.md).  Dask's workers get one BLAS thread from their nanny; `cpu montecarlo --scheduler inline`
runs in the command's own process, so the sweep sets it there.  Operands this small run on one thread
whatever the setting, so the arithmetic, and every result, is the same.
"""
from __future__ import annotations

import ctypes

SETTERS = ("scipy_openblas_set_num_threads64_", "scipy_openblas_set_num_threads", "openblas_set_num_threads64_",
           "openblas_set_num_threads")
GETTERS = tuple(name.replace("set_", "get_") for name in SETTERS)


def _openblas_libraries() -> list[str]:
    """Paths of the OpenBLAS libraries mapped into this process (numpy's and scipy's are separate copies)."""
    import numpy  # noqa: F401  (loads numpy's copy)
    import scipy.linalg  # noqa: F401  (loads scipy's copy)
    try:
        with open("/proc/self/maps", encoding="utf-8") as fh:
            paths = {line.split()[-1] for line in fh if "openblas" in line.lower() and ".so" in line}
    except OSError:                      # not Linux: leave the libraries as they are
        return []
    return sorted(paths)


def _functions(names: tuple) -> list:
    """The first of `names` each loaded OpenBLAS library exports."""
    out = []
    for path in _openblas_libraries():
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        fn = next((getattr(lib, name) for name in names if hasattr(lib, name)), None)
        if fn is not None:
            out.append(fn)
    return out


def set_blas_threads(n: int) -> int:
    """Set every loaded OpenBLAS library to n threads; the number of libraries set (0 where none is found)."""
    setters = _functions(SETTERS)
    for setter in setters:
        setter(ctypes.c_int(n))
    return len(setters)


def blas_threads() -> list[int]:
    """Each loaded OpenBLAS library's thread count."""
    return [int(get()) for get in _functions(GETTERS)]
