"""numba's njit, with an on-disk cache that processes compiling at the same time cannot corrupt.

numba's cache (cache=True) keeps, per kernel, an index (signature -> data file name) and one data file per
signature.  Its save reads the index, takes the first free name and writes the index, then the data, with no
lock: two processes that compile different signatures of one kernel at once both take name 1, and when the
index of one lands with the data of the other, every later process loads machine code compiled for other
argument types and crashes (numba issues #4807 and #10128; a clean clone's parallel test workers and CLI
subprocesses did exactly this in session 28, `_envelope_kernel.run` segfaulting in every later process).

Our kernels' saves therefore run under an exclusive lock on a file beside the index, read the index again
under it and write the data before the index; and every data file carries the key it was compiled for, which
a load checks, so a file written by another numba, an older mech2spice or a race of the past is recompiled,
never called.
"""
from __future__ import annotations

import contextlib
import itertools
import os

try:
    import numba
    from numba.core.caching import IndexDataCacheFile
    AVAILABLE = True
except ImportError:            # pragma: no cover - exercised only without numba
    AVAILABLE = False
    IndexDataCacheFile = object

try:
    import fcntl
except ImportError:            # pragma: no cover - not POSIX: saves unlocked, loads still checked
    fcntl = None

KEYED = "mech2spice-keyed-1"   # a data file's first field: the format that carries its key


@contextlib.contextmanager
def _exclusive(path: str):
    """An exclusive advisory lock on `path` (created if needed) while the block runs; no lock where the
    file cannot be opened (a read-only cache folder: numba then cannot save either)."""
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError:
        yield
        return
    try:
        if fcntl is not None:
            fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)           # closing releases the lock


class LockedIndexDataCacheFile(IndexDataCacheFile):
    """numba's index and data files, saved under a lock and loaded only for the key they were written for."""

    def save(self, key, data):
        with _exclusive(self._index_path + ".lock"):
            overloads = self._load_index()             # again, under the lock: other processes' entries
            name = overloads.get(key)
            if name is None:
                used = set(overloads.values())
                name = next(n for n in map(self._data_name, itertools.count(1)) if n not in used)
            self._save_data(name, (KEYED, key, data))  # the data first: a name in the index always holds it
            overloads[key] = name
            self._save_index(overloads)

    def load(self, key):
        stored = super().load(key)
        if isinstance(stored, tuple) and len(stored) == 3 and stored[0] == KEYED and stored[1] == key:
            return stored[2]
        return None            # absent, another format, or another signature's code: compile again


def guard(dispatcher):
    """Give a cached dispatcher the locked, keyed cache file; returns it.  A no-op for an uncached one."""
    cache = getattr(dispatcher, "_cache", None)
    cache_file = getattr(cache, "_cache_file", None)
    if type(cache_file) is IndexDataCacheFile:
        cache_file.__class__ = LockedIndexDataCacheFile      # same state, locked save and keyed load
    return dispatcher


def guarded(dispatcher) -> bool:
    """Whether a cached dispatcher saves and loads through LockedIndexDataCacheFile."""
    return isinstance(getattr(getattr(dispatcher, "_cache", None), "_cache_file", None), LockedIndexDataCacheFile)


def njit(*args, **flags):
    """numba.njit; with cache=True the kernel's cache is guarded (above).  Without numba, the identity."""
    if not AVAILABLE:
        return args[0] if args and callable(args[0]) else (lambda f: f)
    decorate = numba.njit(**flags)
    wrap = (lambda f: guard(decorate(f))) if flags.get("cache") else decorate
    return wrap(args[0]) if args and callable(args[0]) else wrap
