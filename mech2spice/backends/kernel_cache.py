"""Which compiled kernels a process loaded from numba's on-disk cache and which it compiled (issue 26).

Every kernel is compiled with cache=True, so only the first process on a machine should compile it.  A
kernel whose signature holds a compiled function (a dispatcher argument) never matches its cache entry
in another process: it is recompiled and a new entry appended every run (numba issue 2956).

    python -m mech2spice.backends.kernel_cache --out STATS.json [ENGINE ... | -- MECH2SPICE ARGS ...]

runs the small built-in exercise of the named engines (envelope, rk4, carrier; default envelope), or one
mech2spice command in this process, then writes per kernel the signatures loaded from the cache and
those compiled, and the kernels with a function in a signature.  The exit code is the command's (0 for
the exercise).  scripts/kernel_cache_soak.py and tests/test_kernel_cache.py use it.
"""
from __future__ import annotations

import importlib
import sys
import time

MODULES = ("_envelope_kernel", "_envelope_latency", "_rk4_kernel", "_carrier_kernel", "_carrier_latency")
ENGINES = ("envelope", "rk4", "carrier")


def dispatchers() -> dict:
    """{'module.function': dispatcher} of every cached numba kernel in MODULES."""
    from numba.core.dispatcher import Dispatcher
    out = {}
    for mod in MODULES:
        m = importlib.import_module(f"{__package__}.{mod}")
        for name, obj in vars(m).items():
            if isinstance(obj, Dispatcher) and obj.stats.cache_path:      # cache=True
                out[f"{mod}.{name}"] = obj
    return out


def stats() -> dict:
    """Per kernel used in this process: signatures loaded from the cache and compiled."""
    out = {}
    for name, d in dispatchers().items():
        loaded, compiled = sum(d.stats.cache_hits.values()), sum(d.stats.cache_misses.values())
        if loaded or compiled:
            out[name] = {"loaded": loaded, "compiled": compiled}
    return out


def function_arguments() -> list[str]:
    """Kernels compiled in this process with a function (dispatcher or first-class function) argument."""
    from numba.core import types
    bad = (types.Dispatcher, types.FunctionType)
    return sorted(name for name, d in dispatchers().items()
                  if any(isinstance(t, bad) for sig in d.signatures for t in sig))


def exercise(engines=("envelope",)) -> None:
    """Every compiled path of these engines once, on a two-gate chain for a few periods."""
    from ..physics import nor
    from ..physics.params import load_params
    from . import carrier, envelope, rk4
    m = nor.chain(load_params(None), 2)
    if "envelope" in engines:
        for kw in ({}, {"parallel": True}, {"latency": 0.01}, {"latency": 0.01, "exponential": True}):
            envelope.integrate(m, 40, step_periods=1.0, **kw)
    if "rk4" in engines:
        rk4.integrate(m, 3)
    if "carrier" in engines:
        for kw in ({}, {"threads": 2}, {"latency": 0.01}):
            carrier.integrate(m, 3, **kw)


def _parse(argv: list[str]) -> tuple[str, list[str], list[str]]:
    """(stats path, engines, mech2spice command); exits 2 with one line on stderr on bad arguments."""
    if len(argv) < 2 or argv[0] != "--out":
        _usage("give --out STATS.json first")
    out, rest = argv[1], argv[2:]
    if rest[:1] == ["--"]:
        if len(rest) == 1:
            _usage("no mech2spice command after --")
        return out, [], rest[1:]
    unknown = [e for e in rest if e not in ENGINES]
    if unknown:
        _usage(f"unknown engine {unknown[0]!r} (one of {', '.join(ENGINES)}, or -- and a mech2spice command)")
    return out, rest or ["envelope"], []


def _usage(msg: str):
    print(f"kernel_cache: {msg}", file=sys.stderr)
    raise SystemExit(2)


def main(argv: list[str] | None = None) -> int:
    """Run the exercise or the command, then write the kernels' cache statistics as JSON to --out."""
    out, engines, command = _parse(sys.argv[1:] if argv is None else argv)
    try:
        import numba  # noqa: F401
        f = open(out, "w")                     # refused before the work, not after it
    except (ImportError, OSError) as e:
        _usage(f"{out}: {e.strerror}" if isinstance(e, OSError) else "numba is not installed")
    with f:
        t0 = time.perf_counter()
        if command:
            from .. import cli
            rc = cli.main(command)
        else:
            exercise(engines)
            rc = 0
        report = {"rc": rc, "wall_s": time.perf_counter() - t0, "kernels": stats(),
                  "function_arguments": function_arguments()}
        report["compiled"] = sum(k["compiled"] for k in report["kernels"].values())
        from ..inputs import strict_json
        f.write(strict_json(report))
    return rc


if __name__ == "__main__":
    sys.exit(main())
