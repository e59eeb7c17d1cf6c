"""A machine's state file beside its checkpoint: numpy arrays, written durably and named with its sha256 by
the checkpoint, read back only if it is still the file written.

The file may come from someone else (the sha256 is in the checkpoint beside it): it is read as plain arrays
(never pickles) and every field through `Fields`, against the key, type and shape its reader expects."""
from __future__ import annotations

import hashlib
import io
import json
import os
import zipfile
from pathlib import Path

import numpy as np

from ..errors import Mech2SpiceError


def write(path, **arrays) -> str:
    """Write `arrays` to `path` and fsync (the checkpoint names the file next); returns its sha256."""
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    data = buf.getvalue()
    with open(path, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    return hashlib.sha256(data).hexdigest()


def read(path, sha256: str | None, what: str, restore) -> None:
    """Call restore(arrays) with the file at `path`; with `sha256` it must be exactly the file written.
    Any fault is one Mech2SpiceError naming `what` (e.g. "oscillator state") and the file."""
    try:
        data = Path(path).read_bytes()
    except OSError as err:
        raise Mech2SpiceError(f"cannot read the {what} {path}: {err.strerror or err}") from None
    if sha256 is not None and hashlib.sha256(data).hexdigest() != sha256:
        raise Mech2SpiceError(f"the {what} {path} does not match its checkpoint (changed or damaged since it "
                              "was written)")
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            if not isinstance(z, np.lib.npyio.NpzFile):
                raise ValueError("not an .npz archive")
            restore(Fields(z))
    except (OSError, ValueError, KeyError, IndexError, EOFError, zipfile.BadZipFile) as err:
        raise Mech2SpiceError(f"cannot read the {what} {path}: {err}") from None


class Fields:
    """A state file's arrays, each taken with the type and shape its reader expects; anything else is a
    ValueError naming the field (read() makes it one line).  Keys the reader never asks for are ignored."""

    def __init__(self, z):
        self.z, self.files = z, z.files

    def _get(self, key: str) -> np.ndarray:
        if key not in self.files:
            raise ValueError(f"field '{key}' is missing")
        return self.z[key]            # an object array (a pickle) raises ValueError: allow_pickle is off

    def text(self, key: str) -> str:
        """A 0-d string."""
        a = self._get(key)
        if a.dtype.kind != "U" or a.ndim:
            raise ValueError(f"field '{key}' must be a string")
        return str(a)

    def texts(self, key: str) -> list[str]:
        """A list of strings (1-d)."""
        a = self._get(key)
        if a.dtype.kind != "U" or a.ndim != 1:
            raise ValueError(f"field '{key}' must be a list of strings")
        return [str(x) for x in a]

    def integer(self, key: str, lo: int = 0, hi: int = 2 ** 62) -> int:
        """A 0-d integer in [lo, hi]."""
        a = self._get(key)
        if a.dtype.kind not in "iu" or a.ndim or not lo <= int(a) <= hi:
            raise ValueError(f"field '{key}' must be a whole number from {lo} to {hi}")
        return int(a)

    def number(self, key: str, lo: float = 0.0) -> float:
        """A 0-d finite number >= lo."""
        a = self._get(key)
        if a.dtype.kind not in "iuf" or a.ndim or not (np.isfinite(a) and a >= lo):
            raise ValueError(f"field '{key}' must be a finite number >= {lo:g}")
        return float(a)

    def array(self, key: str, dtype, shape: tuple, finite: bool = True) -> np.ndarray:
        """An array of exactly this dtype and shape (None in `shape`: any length on that axis; finite: no NaN
        or infinity)."""
        a = self._get(key)
        fits = len(a.shape) == len(shape) and all(n is None or n == m for n, m in zip(shape, a.shape))
        if a.dtype != np.dtype(dtype) or not fits:
            raise ValueError(f"field '{key}' must be {np.dtype(dtype).name} of shape {tuple(shape)}, "
                             f"not {a.dtype.name} of shape {a.shape}")
        if finite and a.dtype.kind in "fc" and not np.isfinite(a).all():
            raise ValueError(f"field '{key}' holds values that are not finite")
        return a

    def json(self, key: str) -> dict:
        """A JSON object kept as a string."""
        try:
            out = json.loads(self.text(key), parse_constant=_no_constant)
        except RecursionError:
            out = None
        if not isinstance(out, dict):
            raise ValueError(f"field '{key}' must be a JSON object")
        return out


def _no_constant(name: str):
    raise ValueError(f"{name} is not a JSON number")
