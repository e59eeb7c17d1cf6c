"""mech2spice/schema.py: the one language the read-back files are checked in (stored report JSON, centering
records, Monte-Carlo lines): what each spec accepts and refuses, and the JSON path a refusal names."""
import math

import pytest

from mech2spice.errors import Mech2SpiceError
from mech2spice.schema import (ANY, BOOL, COUNT, INT, NUMBER, STR, Either, Map, Obj, Opt, SchemaError, check,
                               child, non_finite_path)

SPEC = Obj({"n": COUNT, "t": [NUMBER], "amp": [NUMBER], "name?": STR,
            "rows": [{"ok": BOOL, "x": Opt(NUMBER), "tag": Either(INT, STR)}], "by": Map(COUNT), "free": ANY},
           same=(("t", "amp"),))
GOOD = {"n": 2, "t": [0, 1.5], "amp": [0.1, 0.2], "rows": [{"ok": True, "x": None, "tag": "a"},
                                                          {"ok": False, "x": 1e-3, "tag": -4}],
        "by": {"weird key\n\"q\"": 3}, "free": {"anything": [1, "x"]}}


def test_a_fitting_document_passes():
    check(GOOD, SPEC)


@pytest.mark.parametrize("change, path, message", [
    (lambda d: d.pop("n"), "$.n", "missing"),
    (lambda d: d.update(n=True), "$.n", "true/false, not a whole number >= 0"),
    (lambda d: d.update(n=-1), "$.n", "-1, not a whole number >= 0"),
    (lambda d: d.update(n=2.0), "$.n", "a number, not a whole number >= 0"),
    (lambda d: d.update(n="2"), "$.n", "a string, not a whole number >= 0"),
    (lambda d: d.update(n=10 ** 400), "$.n", "beyond the float range"),
    (lambda d: d["t"].__setitem__(1, math.nan), "$.t[1]", "nan, not a finite number"),
    (lambda d: d["t"].__setitem__(0, -math.inf), "$.t[0]", "-inf, not a finite number"),
    (lambda d: d["amp"].append(0.3), "$", "lists of different lengths (t 2, amp 3)"),
    (lambda d: d.update(name=3), "$.name", "a whole number, not a string"),
    (lambda d: d["rows"][1].update(x="1"), "$.rows[1].x", "a string, not a finite number"),
    (lambda d: d["rows"][0].update(tag=1.5), "$.rows[0].tag", "a number, not a string"),
    (lambda d: d.update(rows={}), "$.rows", "an object, not a list"),
    (lambda d: d["rows"].__setitem__(0, []), "$.rows[0]", "a list, not an object"),
    (lambda d: d["by"].update({"weird key\n\"q\"": "3"}), '$.by["weird key\\n\\"q\\""]', "a string"),
], ids=["missing", "bool-for-count", "negative-count", "float-for-count", "string-for-count", "huge-int", "nan",
        "infinity", "paired-lengths", "optional-typed", "opt-string", "either", "object-for-list",
        "list-for-object", "odd-key"])
def test_a_misfit_names_its_path(change, path, message):
    import copy
    doc = copy.deepcopy(GOOD)
    change(doc)
    with pytest.raises(SchemaError) as err:
        check(doc, SPEC)
    assert err.value.path == path and message in err.value.message, (err.value.path, err.value.message)
    assert isinstance(err.value, Mech2SpiceError) and "\n" not in str(err.value)


def test_non_finite_numbers_are_found_where_the_schema_takes_anything():
    assert non_finite_path(GOOD) is None
    assert non_finite_path({"free": {"a": [1, math.inf]}}) == "$.free.a[1]"


def test_paths_quote_keys_that_are_not_identifiers():
    assert child("$", "rows") == "$.rows" and child("$.rows", 3) == "$.rows[3]"
    assert child("$", "sqrt, robust") == '$["sqrt, robust"]' and child("$", "1%") == '$["1%"]'
    assert len(child("$", "k" * 500)) < 60


def test_a_schema_mistake_is_the_codes_not_the_files():
    with pytest.raises(TypeError):
        check(1, "not a spec")
