"""A machine's state file beside its checkpoint: numpy arrays, written durably and named with its sha256 by
the checkpoint, read back only if it is still the file written."""
from __future__ import annotations

import hashlib
import io
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
        with np.load(io.BytesIO(data)) as z:
            restore(z)
    except (OSError, ValueError, KeyError, IndexError, EOFError, zipfile.BadZipFile) as err:
        raise Mech2SpiceError(f"cannot read the {what} {path}: {err}") from None
