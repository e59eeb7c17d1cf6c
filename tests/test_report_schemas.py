"""`mech2spice report NAME --render` reads its stored JSON against reports/schemas.py before drawing anything
(issue 37): every committed reports/*.json fits its schema and renders; a damaged copy (a field deleted, of
another type, NaN, a string where a count was, a list where an object was, paired lists of different
lengths, an unknown version) is one line naming the file and the JSON path of the field, exit 2, and the
report's folder is left as it was (bytes and mtimes)."""
from __future__ import annotations

import copy
import json
import math
import re
import shutil
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from cli_helpers import run

from mech2spice.reports import REPORTS
from mech2spice.reports.schemas import READS, files_read
from mech2spice.schema import ANY, BOOL, COUNT, INT, NUMBER, STR, Either, Leaf, Map, Obj, Opt

ROOT = Path(__file__).resolve().parents[1]
STORED = [name for name in REPORTS if (ROOT / "reports" / f"{name}.json").is_file()]


def _copy(report: str, folder: Path) -> Path:
    """The committed JSON files `report --render` reads, copied into `folder`."""
    folder.mkdir(exist_ok=True)
    for name, _ in files_read(report):
        if (ROOT / "reports" / name).is_file():
            shutil.copy2(ROOT / "reports" / name, folder / name)
    return folder


def _state(folder: Path) -> dict:
    return {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in sorted(folder.iterdir())}


def test_every_report_with_stored_json_has_a_schema():
    assert len(STORED) >= 15, STORED
    for name in STORED:
        assert files_read(name)[0][0] == f"{name}.json"


def _required(spec, found):
    """Every required field name in `spec`."""
    if isinstance(spec, (Opt, Map)):
        _required(spec.spec, found)
    elif isinstance(spec, Either):
        for s in spec.specs:
            _required(s, found)
    elif isinstance(spec, list):
        _required(spec[0], found)
    elif isinstance(spec, (dict, Obj)):
        for name, sub in (spec.fields if isinstance(spec, Obj) else spec).items():
            if not name.endswith("?"):
                found.add(name)
            _required(sub, found)
    return found


def test_a_field_is_required_only_where_a_renderer_reads_it_by_name():
    """A field no renderer names is optional (typed where present): a study that stops writing a field no
    report reads must not make --render refuse its JSON."""
    import ast
    named = set()
    for f in (ROOT / "mech2spice/reports").glob("*.py"):
        if f.name != "schemas.py":
            named |= {n.value for n in ast.walk(ast.parse(f.read_text()))
                      if isinstance(n, ast.Constant) and isinstance(n.value, str)}
    for name in STORED:
        unread = _required(dict(files_read(name))[f"{name}.json"], set()) - named
        assert not unread, (name, sorted(unread))


@pytest.mark.parametrize("report", STORED)
def test_the_committed_json_fits_and_renders(capsys, tmp_path, report):
    out = _copy(report, tmp_path / "r")
    rc, _, err = run(capsys, "report", report, "--render", "--out", out)
    assert rc == 0 and "Traceback" not in err, err[-2000:]
    assert (out / f"{report}.md").read_text().strip()


# --- mutations at the places the schema names -------------------------------------------------------------

def _path(keys: tuple) -> str:
    """The JSON path the refusal must name (written here again, not imported: the test checks the format)."""
    text = "$"
    for k in keys:
        text += f"[{k}]" if isinstance(k, int) else f".{k}" if re.fullmatch(r"[A-Za-z_]\w*", k) else f'["{k}"]'
    return text


def _places(value, spec, keys=()):
    """(keys, kind, required) of the fields `value` holds where `spec` is strict: kind is number, count,
    string, bool, object or list; lists are sampled at their first, second and last items."""
    if isinstance(spec, Opt):
        if value is not None:
            yield from _places(value, spec.spec, keys)
        return
    if isinstance(spec, (Either,)) or spec is ANY:
        return
    if isinstance(spec, Leaf):
        kind = {NUMBER: "number", COUNT: "count", INT: "number", STR: "string", BOOL: "bool"}.get(spec)
        if kind:
            yield keys, kind
        return
    if isinstance(spec, list):
        yield keys, "list"
        idx = sorted({0, 1, len(value) - 1} & set(range(len(value))))
        for i in idx:
            yield from _places(value[i], spec[0], keys + (i,))
        return
    yield keys, "object"
    if isinstance(spec, Map):
        for k in list(value)[:2]:
            yield from _places(value[k], spec.spec, keys + (k,))
        return
    fields = spec.fields if isinstance(spec, Obj) else spec
    for name, sub in fields.items():
        key = name.rstrip("?")
        if key in value:
            yield from _places(value[key], sub, keys + (key,))
            if not name.endswith("?"):
                yield keys + (key,), "required"


def _pairs(value, spec, keys=()):
    """keys of each object holding paired lists (Obj.same), with the first list's name."""
    if isinstance(spec, Opt):
        spec = spec.spec
    if value is None:
        return
    if isinstance(spec, list) and value:
        yield from _pairs(value[0], spec[0], keys + (0,))
    elif isinstance(spec, Map) and value:
        k = next(iter(value))
        yield from _pairs(value[k], spec.spec, keys + (k,))
    elif isinstance(spec, (dict, Obj)):
        fields = spec.fields if isinstance(spec, Obj) else spec
        for group in getattr(spec, "same", ()):
            present = [k for k in group if isinstance(value.get(k), list)]
            if len(present) > 1:
                yield keys, present[0]
        for name, sub in fields.items():
            if name.rstrip("?") in value:
                yield from _pairs(value[name.rstrip("?")], sub, keys + (name.rstrip("?"),))


WRONG = {"number": "x", "count": "3", "string": 7, "bool": "yes", "object": [], "list": {}}


def _mutated(data, keys: tuple, how: str):
    """A copy of `data` with the field at `keys` deleted ('delete'), NaN ('nan') or of the wrong type."""
    data = copy.deepcopy(data)
    parent = data
    for k in keys[:-1]:
        parent = parent[k]
    if how == "delete":
        del parent[keys[-1]]
    elif how == "grow":
        parent[keys[-1]].append(parent[keys[-1]][-1] if parent[keys[-1]] else 0)
    else:
        parent[keys[-1]] = math.nan if how == "nan" else WRONG[how]
    return data


def _refused_naming(capsys, tmp_path, report: str, file: str, data, where: str, writer: str = ""):
    out = _copy(report, tmp_path / "r")
    (out / file).write_text(json.dumps(data))             # Python writes NaN as NaN: the lenient form
    before = _state(out)
    rc, stdout, err = run(capsys, "report", report, "--render", "--out", out)
    assert rc == 2 and "Traceback" not in err and err.count("\n") == 1, err[-2000:]
    assert f"{out / file}: {where}:" in err, (where, err)
    assert f"`{writer or 'mech2spice report ' + report}` writes" in err, err
    assert _state(out) == before and not stdout


def _load(report: str, file: str | None = None):
    file = file or f"{report}.json"
    return json.loads((ROOT / "reports" / file).read_text()), dict(files_read(report))[file]


def _first(report: str, kind: str):
    data, spec = _load(report)
    return data, next((keys for keys, k in _places(data, spec) if k == kind and keys), None)


CASES = [(r, how) for r in STORED for how in ("delete", "number", "nan", "count", "object", "list", "string")]


@pytest.mark.parametrize("report, how", CASES, ids=[f"{r}-{h}" for r, h in CASES])
def test_a_damaged_field_is_one_line_naming_its_path(capsys, tmp_path, report, how):
    kind = {"delete": "required", "nan": "number"}.get(how, how)
    data, keys = _first(report, kind)
    if keys is None:
        pytest.skip(f"{report}.json has no {kind} field")
    what = {"delete": "delete", "nan": "nan"}.get(how, how)
    _refused_naming(capsys, tmp_path, report, f"{report}.json", _mutated(data, keys, what), _path(keys))


PAIRED = [r for r in STORED if next(_pairs(*_load(r)), None)]


def test_paired_lists_are_declared_where_the_renderers_zip_them():
    assert {"gate", "sequential", "envelope", "carrier", "cpu_circuit"} <= set(PAIRED), PAIRED


@pytest.mark.parametrize("report", PAIRED)
def test_paired_lists_of_different_lengths_are_refused(capsys, tmp_path, report):
    data, spec = _load(report)
    keys, first = next(_pairs(data, spec))
    _refused_naming(capsys, tmp_path, report, f"{report}.json", _mutated(data, keys + (first,), "grow"),
                    _path(keys))


@pytest.mark.parametrize("version", [2, "1", True, None, [1]])
def test_an_unknown_report_version_is_refused(capsys, tmp_path, version):
    data, _ = _load("adder")
    _refused_naming(capsys, tmp_path, "adder", "adder.json", {**data, "report_version": version},
                    "$.report_version")


@pytest.mark.parametrize("report, file", [(r, f) for r, files in READS.items() for f in files if f != r])
def test_a_damaged_file_read_beside_the_reports_own_is_refused(capsys, tmp_path, report, file):
    if not (ROOT / "reports" / f"{file}.json").is_file():
        pytest.skip(f"no committed {file}.json")
    data, spec = _load(report, f"{file}.json")
    keys = next(keys for keys, k in _places(data, spec) if k == "number" and keys)
    writer = {"envelope_spice": "mech2spice report speed_accuracy", "vacask": "python -m mech2spice.studies.vacask",
              "cpu_physical_tm_increment": "mech2spice report cpu_physical"}.get(file, f"mech2spice report {file}")
    _refused_naming(capsys, tmp_path, report, f"{file}.json", _mutated(data, keys, "nan"), _path(keys), writer)


@pytest.mark.parametrize("content, where", [("[]", "$: a list, not an object"), ("{}", "$: an empty object"),
                                            ('"x"', "$: a string, not an object"), ("3", "$: a whole number")])
def test_a_stored_json_that_is_no_object_is_refused(capsys, tmp_path, content, where):
    out = _copy("gate", tmp_path / "r")
    (out / "gate.json").write_text(content)
    before = _state(out)
    rc, _, err = run(capsys, "report", "gate", "--render", "--out", out)
    assert rc == 2 and err.count("\n") == 1 and where in err and "Traceback" not in err, err
    assert _state(out) == before


@settings(max_examples=40, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(data=st.data())
def test_any_damaged_field_anywhere_is_one_line_naming_its_path(capsys, tmp_path_factory, data):
    """Property: a mutation drawn at any place the schema is strict, in any report."""
    report = data.draw(st.sampled_from(STORED))
    doc, spec = _load(report)
    places = [(keys, k) for keys, k in _places(doc, spec) if keys]
    keys, kind = data.draw(st.sampled_from(places))
    how = "delete" if kind == "required" else data.draw(st.sampled_from(["nan", kind] if kind == "number" else [kind]))
    _refused_naming(capsys, tmp_path_factory.mktemp("m"), report, f"{report}.json", _mutated(doc, keys, how),
                    _path(keys))


def test_the_any_fields_refuse_non_finite_numbers_too(capsys, tmp_path):
    """A NaN where the schema takes anything (a field only shown as is) is still not a finite number."""
    data, _ = _load("cpu_physical")
    data["first_mismatch"] = [1, math.inf]
    _refused_naming(capsys, tmp_path, "cpu_physical", "cpu_physical.json", data, "$.first_mismatch[1]")


def test_a_pipe_or_a_folder_in_place_of_the_json_is_refused_not_read(capsys, tmp_path):
    """A FIFO named gate.json would block the read for ever: refused before it is opened."""
    import os
    out = tmp_path / "r"
    out.mkdir()
    os.mkfifo(out / "gate.json")
    rc, _, err = run(capsys, "report", "gate", "--render", "--out", out)
    assert rc == 2 and err.count("\n") == 1 and "is not a regular file" in err, err


def test_a_stored_json_larger_than_any_report_is_refused_unread(capsys, tmp_path, monkeypatch):
    from mech2spice.reports import schemas
    monkeypatch.setattr(schemas, "MAX_BYTES", 1000)
    out = _copy("spice", tmp_path / "r")
    rc, _, err = run(capsys, "report", "spice", "--render", "--out", out)
    assert rc == 2 and err.count("\n") == 1 and "more than any `mech2spice report spice` writes" in err, err


# Objects keyed by data that the renderer iterates are Maps: a scene, design or backend a run did not measure
# renders without it (no "missing" refusal, no traceback).
ABSENT = [("carrier", "carrier.json", ("convergence", "scenes", "gate")),
          ("robustness", "robustness.json", ("noise", "gate")),
          ("speed_accuracy", "envelope_spice.json", ("failures", "large_steps", "adder"))]


@pytest.mark.parametrize("report, file, keys", ABSENT, ids=[f"{r}-{k[-2]}" for r, _, k in ABSENT])
def test_a_scene_the_renderer_iterates_may_be_absent(capsys, tmp_path, report, file, keys):
    if not (ROOT / "reports" / file).is_file():
        pytest.skip(f"no committed {file}")
    out = _copy(report, tmp_path / "r")
    data = json.loads((out / file).read_text())
    (out / file).write_text(json.dumps(_mutated(data, keys, "delete")))
    rc, _, err = run(capsys, "report", report, "--render", "--out", out)
    assert rc == 0 and "Traceback" not in err, err[-2000:]
    assert (out / f"{report}.md").read_text().strip()
