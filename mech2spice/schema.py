"""Schemas for the JSON files the tool reads back (docs/architecture.md, "Files the tool reads back").

One small language, so every file is checked the same way and every refusal names the JSON path of the bad
field (``$.rows[3].cycle``):

- ``NUMBER`` a finite number (an integer or a float, not true/false, not NaN/Infinity), ``COUNT`` a whole
  number >= 0, ``INT`` a whole number, ``STR``, ``BOOL``, ``ANY`` (anything: a field only shown as is);
- ``{"field": spec, "other?": spec}`` an object with these fields (``?``: may be absent; others are allowed);
- ``Obj({...}, same=(("t", "amp"),))`` the same, and the lists named in each group are equally long;
- ``[spec]`` a list of items of that spec; ``Map(spec)`` an object of any keys whose values are of that spec;
- ``Opt(spec)`` that spec or null; ``Either(spec, ...)`` the first spec that fits.

`check(data, spec)` raises `SchemaError(path, message)` at the first field that does not fit; the caller
names the file (one Mech2SpiceError line).  No third-party validator: jsonschema is not among the tool's
dependencies, and this language is what the file readers need (paired lengths, finite numbers, bool is no
number) in a few lines.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

from .errors import Mech2SpiceError


class SchemaError(Mech2SpiceError):
    """A value that does not fit its schema: `path` is where (JSON path), the message what."""

    def __init__(self, path: str, message: str):
        super().__init__(f"{path}: {message}")
        self.path, self.message = path, message


@dataclass(frozen=True)
class Leaf:
    """A scalar kind: `test` says whether a value is one, `what` names it in messages."""
    what: str
    test: object

    def __repr__(self) -> str:
        return self.what


def _finite(v) -> bool:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return False
    try:
        return math.isfinite(v)
    except OverflowError:                               # an integer beyond the float range
        return False


NUMBER = Leaf("a finite number", _finite)
INT = Leaf("a whole number", lambda v: isinstance(v, int) and not isinstance(v, bool) and _finite(v))
COUNT = Leaf("a whole number >= 0", lambda v: INT.test(v) and v >= 0)
STR = Leaf("a string", lambda v: isinstance(v, str))
BOOL = Leaf("true or false", lambda v: isinstance(v, bool))
ANY = Leaf("anything", lambda v: True)


@dataclass(frozen=True)
class Opt:
    """`spec` or null."""
    spec: object


@dataclass(frozen=True)
class Map:
    """An object of any keys, each value of `spec`."""
    spec: object


@dataclass(frozen=True)
class Either:
    """The first of `specs` that fits (the message is the last one's)."""
    specs: tuple

    def __init__(self, *specs):
        object.__setattr__(self, "specs", specs)


@dataclass(frozen=True)
class Obj:
    """An object with `fields` (a name ending in '?' may be absent) whose lists named in each group of `same`
    have one length (paired arrays: times and amplitudes, cycles and rows)."""
    fields: dict
    same: tuple = ()


def kind_of(value) -> str:
    """How a message names a value: its JSON type, or the number itself where it is not finite."""
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if isinstance(value, int) and not isinstance(value, bool) and not _finite(value):
        return "a whole number beyond the float range"
    return {dict: "an object", list: "a list", str: "a string", bool: "true/false", int: "a whole number",
            float: "a number", type(None): "null"}.get(type(value), type(value).__name__)


def _named(value, spec) -> str:
    """kind_of, or the number itself where its kind is the one the spec asks for (-1, not 'a whole number
    >= 0'; "a whole number, not a whole number >= 0" read as a contradiction)."""
    kind = kind_of(value)
    if isinstance(value, (int, float)) and not isinstance(value, bool) and spec.what.startswith(kind):
        return f"{value:g}" if isinstance(value, float) else (str(value) if abs(value) < 10 ** 40 else kind)
    return kind


_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")


def child(path: str, key) -> str:
    """The JSON path of `key` under `path`: $.a.b, $.rows[3], $["odd key"]."""
    if isinstance(key, int):
        return f"{path}[{key}]"
    if _IDENT.match(key) and len(key) <= 40:
        return f"{path}.{key}"
    return f"{path}[{_quoted(key)}]"


def _quoted(key: str) -> str:
    """A key as a JSON string, cut to 40 characters: a newline or a quote in it stays on the message's line."""
    import json
    return json.dumps(key[:40] + ("..." if len(key) > 40 else ""))


def check(value, spec, path: str = "$") -> None:
    """Raise SchemaError at the first place `value` does not fit `spec`."""
    if isinstance(spec, Leaf):
        if not spec.test(value):
            raise SchemaError(path, f"{_named(value, spec)}, not {spec.what}")
    elif isinstance(spec, Opt):
        if value is not None:
            check(value, spec.spec, path)
    elif isinstance(spec, Either):
        _either(value, spec, path)
    elif isinstance(spec, list):
        _list(value, spec[0], path)
    elif isinstance(spec, Map):
        _object(value, path)
        for key, item in value.items():
            check(item, spec.spec, child(path, key))
    elif isinstance(spec, (dict, Obj)):
        _fields(value, spec if isinstance(spec, Obj) else Obj(spec), path)
    else:                                               # a schema's own mistake, not the file's
        raise TypeError(f"not a schema: {spec!r}")


def _either(value, spec: Either, path: str) -> None:
    err = None
    for option in spec.specs:
        try:
            return check(value, option, path)
        except SchemaError as e:
            err = e
    raise err


def _object(value, path: str) -> None:
    if not isinstance(value, dict):
        raise SchemaError(path, f"{kind_of(value)}, not an object")


def _list(value, item, path: str) -> None:
    if not isinstance(value, list):
        raise SchemaError(path, f"{kind_of(value)}, not a list")
    for k, v in enumerate(value):
        check(v, item, child(path, k))


def _fields(value, spec: Obj, path: str) -> None:
    _object(value, path)
    for name, field_spec in spec.fields.items():
        key = name[:-1] if name.endswith("?") else name
        if key in value:
            check(value[key], field_spec, child(path, key))
        elif key == name:
            raise SchemaError(child(path, key), "missing")
    for group in spec.same:
        lengths = {k: len(value[k]) for k in group if isinstance(value.get(k), list)}
        if len(set(lengths.values())) > 1:
            told = ", ".join(f"{k} {n}" for k, n in lengths.items())
            raise SchemaError(path, f"lists of different lengths ({told}), paired item by item")


def check_finite(value, spec, path: str = "$", why: str = "not a finite number") -> None:
    """`check`, then no NaN or Infinity anywhere, not even where the spec says ANY (`why` says so)."""
    check(value, spec, path)
    where = non_finite_path(value, path)
    if where:
        raise SchemaError(where, why)


def non_finite_path(value, path: str = "$") -> str | None:
    """The path of the first NaN or Infinity anywhere in `value` (None: none): a file read with Python's
    lenient parser may hold them wherever a schema says ANY."""
    if isinstance(value, float):
        return None if math.isfinite(value) else path
    items = value.items() if isinstance(value, dict) else enumerate(value) if isinstance(value, list) else ()
    for key, item in items:
        found = non_finite_path(item, child(path, key))
        if found:
            return found
    return None
