"""The problem file's common case (plain finite numbers of the right shapes) is validated without building a
location per number; the located walks still run, with the same messages, whenever anything else is seen."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from tritools.io import problem_file as pf
from tritools.model.regions import base as region_base
from tritools.scene import random_scene


def _document(n_problems: int, n_views: int = 4) -> dict:
    sc = random_scene(n_views, n_problems, 1.0, seed=3)
    C, x = np.asarray(sc.cameras), np.asarray(sc.points2d)
    return {"problems": [pf.problem_to_dict(C, x[j], name=f"p{j}") for j in range(n_problems)]}


def test_locations_are_built_per_field_not_per_number(monkeypatch):
    calls = []
    real_join = pf._join
    monkeypatch.setattr(pf, "_join", lambda loc, key: calls.append(key) or real_join(loc, key))
    doc = _document(50)
    specs = pf.parse_problem_text(json.dumps(doc))
    assert len(specs) == 50
    numbers = 50 * 4 * (12 + 2)
    assert len(calls) < numbers / 4, len(calls)   # a few per problem and view, none per number


def test_fast_paths_give_the_arrays_of_the_located_paths():
    doc = _document(20, 5)
    specs = pf.parse_problems(doc)
    for spec, p in zip(specs, doc["problems"]):
        assert np.array_equal(spec.cameras, np.array(p["cameras"], dtype=float))
        assert pf._nested_shape(p["cameras"], "c", 3) == (5, 3, 4)
        for r, d in zip(spec.regions, p["regions"]):
            assert np.array_equal(r.x, np.array(d["x"]))


@pytest.mark.parametrize("value", [
    [[1.0, 2.0], [3, 4]], {"a": [1.0, "s", None, True]}, [1e308, -1e308, 0.0, -0.0, 2 ** 60],
])
def test_plainly_finite_accepts_plain_documents(value):
    assert pf._plainly_finite(value)
    pf._find_non_finite(value, "")


@pytest.mark.parametrize("value, location", [
    ([[1.0, math.nan]], "[0][1]"), ({"a": [1.0, -math.inf]}, "a[1]"), ([2 ** 1100], "[0]"),
    ({"a": (1.0, math.inf)}, "a[1]"), ([np.float64(math.nan)], "[0]"),
])
def test_non_finite_numbers_are_still_located(value, location):
    assert not pf._plainly_finite(value)
    with pytest.raises(pf.ProblemFileError) as err:
        pf._find_non_finite(value, "")
    assert err.value.location == location


@pytest.mark.parametrize("value", [
    [[1.0, 2.0, 3.0, 4.0]] * 3, [[1, 2, 3, 4]] * 3,
])
def test_plain_shape_accepts_plain_numbers(value):
    assert pf._plain_shape(value, (3, 4))


@pytest.mark.parametrize("value", [
    [[1.0, 2.0, 3.0, 4.0]] * 2, [[1.0, 2.0, 3.0]] * 3, [[1.0, 2.0, 3.0, True]] * 3, [[1.0, 2.0, 3.0, "4"]] * 3,
    ((1.0, 2.0, 3.0, 4.0),) * 3, [[1.0, 2.0, 3.0, [4.0]]] * 3, [[np.float32(1.0), 2.0, 3.0, 4.0]] * 3,
])
def test_anything_else_takes_the_located_path(value):
    assert not pf._plain_shape(value, (3, 4))


def test_bad_numbers_keep_their_messages():
    doc = _document(3)
    doc["problems"][2]["cameras"][1][2][3] = True
    with pytest.raises(pf.ProblemFileError, match=r"problems\[2\]\.cameras\[1\]\[2\]\[3\]: expected a number, got "
                                                   r"boolean"):
        pf.parse_problems(doc)
    doc = _document(3)
    doc["problems"][1]["regions"][0]["x"] = [1.0, True]
    with pytest.raises(pf.ProblemFileError, match=r"problems\[1\]\.regions\[0\]\.x"):
        pf.parse_problems(doc)


def test_real_array_still_refuses_booleans_and_converts_other_dtypes():
    assert region_base.real_array([1.0, 2], "x").dtype == np.float64
    assert region_base.real_array(np.array([1, 2], np.int32), "x").dtype == np.float64
    with pytest.raises(ValueError, match="x must be real numbers, got bool"):
        region_base.real_array([1.0, True], "x")
    with pytest.raises(ValueError, match="bool"):
        region_base.real_array([[1.0], [np.bool_(True)]], "x")
    a = np.array([1.0, 2.0])
    b = region_base.real_array(a, "x")
    assert b is not a and np.array_equal(a, b)
