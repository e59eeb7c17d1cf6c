"""Nested measurement results as a data file, never a pickle: a report's --cache may hold anyone's files.

One uncompressed .npz: `format`, `version`, `tree` (the structure as JSON, each node tagged with its type)
and the arrays `a0`, `a1`, ... it refers to.  Reading it runs nothing: numpy's loader with pickles off, the
JSON with every node's tag, type and array reference checked; anything else is one Mech2SpiceError line.

Stored types: None, bool, int, float (NaN and infinities too), complex, str, list, tuple, dict (keys of
these types but list and dict) and numpy arrays of numbers, booleans or strings; numpy scalars become the
Python ones.
"""
from __future__ import annotations

import io
import json
import math
import os
import zipfile
from pathlib import Path

import numpy as np

from ..errors import Mech2SpiceError

FORMAT, VERSION = "mech2spice-results", 1
ARRAY_KINDS = "biufcU"           # dtype kinds stored: no object ('O') or structured ('V') arrays
_SPECIAL = {"nan": math.nan, "inf": math.inf, "-inf": -math.inf}


class _Bad(ValueError):
    """What is wrong with a file (load() adds the file's name)."""


# --- writing --------------------------------------------------------------------------------------------
def dump(path, obj) -> None:
    """Write `obj` to `path` (atomically: a crash leaves the old file or the new one)."""
    arrays: list[np.ndarray] = []
    tree = json.dumps(_encode(obj, arrays), allow_nan=False)
    buf = io.BytesIO()
    np.savez(buf, format=FORMAT, version=VERSION, tree=tree, **{f"a{k}": a for k, a in enumerate(arrays)})
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_bytes(buf.getvalue())
    os.replace(tmp, path)


def _encode(x, arrays: list):
    if x is None or isinstance(x, (bool, str)):
        return x
    if isinstance(x, np.generic) and not isinstance(x, np.str_):
        return _encode(x.item(), arrays)
    if isinstance(x, int):
        return int(x)
    if isinstance(x, float):
        return float(x) if math.isfinite(x) else {"$f": repr(float(x))}
    if isinstance(x, complex):
        return {"$c": [_encode(x.real, arrays), _encode(x.imag, arrays)]}
    if isinstance(x, np.ndarray):
        if x.dtype.kind not in ARRAY_KINDS:
            raise TypeError(f"cannot store an array of dtype {x.dtype} (numbers, booleans, strings only)")
        arrays.append(x)
        return {"$a": len(arrays) - 1}
    if isinstance(x, list):
        return [_encode(v, arrays) for v in x]
    if isinstance(x, tuple):
        return {"$t": [_encode(v, arrays) for v in x]}
    if isinstance(x, dict):
        return {"$d": [[_encode(k, arrays), _encode(v, arrays)] for k, v in x.items()]}
    raise TypeError(f"cannot store a {type(x).__name__} in a results file")


# --- reading --------------------------------------------------------------------------------------------
def load(path):
    """The object dump() wrote to `path`; a file that is anything else is refused in one line."""
    try:
        with np.load(io.BytesIO(Path(path).read_bytes()), allow_pickle=False) as z:
            return _read(z)
    except OSError as err:
        raise Mech2SpiceError(f"cannot read {path}: {err.strerror or err}") from None
    except (_Bad, ValueError, KeyError, EOFError, RecursionError, zipfile.BadZipFile, AttributeError) as err:
        raise Mech2SpiceError(f"{path} is not a mech2spice results file: {str(err)[:200] or type(err).__name__}") \
            from None


def _read(z):
    if not isinstance(z, np.lib.npyio.NpzFile):
        raise _Bad("not an .npz archive")
    for key, want in (("format", FORMAT), ("version", VERSION)):
        if key not in z.files or z[key].ndim or z[key].item() != want:
            raise _Bad(f"'{key}' is not {want!r}")
    if "tree" not in z.files or z["tree"].dtype.kind != "U" or z["tree"].ndim:
        raise _Bad("no 'tree'")
    tree = json.loads(str(z["tree"]), parse_constant=_no_constant)
    arrays = {}

    def array(k):
        if not (isinstance(k, int) and not isinstance(k, bool) and f"a{k}" in z.files):
            raise _Bad(f"array reference {k!r} names no array in the file")
        if k not in arrays:
            a = z[f"a{k}"]                         # an object array raises: pickles are off
            if a.dtype.kind not in ARRAY_KINDS:
                raise _Bad(f"array a{k} has dtype {a.dtype}")
            arrays[k] = a
        return arrays[k]
    return _decode(tree, array)


def _decode(node, array):
    if node is None or isinstance(node, (bool, int, float, str)):
        return node
    if isinstance(node, list):
        return [_decode(v, array) for v in node]
    if not (isinstance(node, dict) and len(node) == 1):
        raise _Bad("a node is not a value, a list or one tagged object")
    (tag, v), = node.items()
    if tag == "$f" and v in _SPECIAL:
        return _SPECIAL[v]
    if tag == "$c" and isinstance(v, list) and len(v) == 2:
        re_, im = (_decode(x, array) for x in v)
        if all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in (re_, im)):
            return complex(re_, im)
    if tag == "$a":
        return array(v)
    if tag == "$t" and isinstance(v, list):
        return tuple(_decode(x, array) for x in v)
    if tag == "$d" and isinstance(v, list) and all(isinstance(kv, list) and len(kv) == 2 for kv in v):
        return {_key(_decode(k, array)): _decode(x, array) for k, x in v}
    raise _Bad(f"unknown or malformed node {ascii(tag)[:40]}")


def _key(k):
    """A dict key: hashable values only (a tuple of lists would not be)."""
    try:
        hash(k)
    except TypeError:
        raise _Bad("a dict key is a list, a dict or an array") from None
    return k


def _no_constant(name: str):
    raise _Bad(f"{name} is not a JSON number")
