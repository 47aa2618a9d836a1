"""Structured input errors (issue #18 item 5): regions and options name the field that is wrong
(:class:`tritools.errors.FieldError`), and the problem-file reader places the message by that field -- no
message parsing."""
import json
import pickle

import numpy as np
import pytest

import tritools
from tritools.errors import MISSING, FieldError
from tritools.io.problem_file import ProblemFileError, parse_problem_text
from tritools.io.problem_file import problem_to_dict
from tritools.model.regions import Region
from tritools.solve.options import OptionError


@pytest.mark.parametrize("make, field", [
    (lambda: tritools.Ellipse([0.0, 0.0], [[1.0, 2.0], [3.0, 4.0]]), "D"),            # not symmetric
    (lambda: tritools.Ellipse([0.0, 0.0], [[1.0, 0.0], [0.0, -1.0]]), "D"),           # not positive definite
    (lambda: tritools.Ellipse([np.nan, 0.0], np.eye(2)), "center"),
    (lambda: Region.from_dict({"type": "ellipse", "center": [0, 0]}), "D"),           # missing
    (lambda: Region.from_dict({"type": "ellipse", "center": [10 ** 400, 0], "D": np.eye(2).tolist()}), "center"),
])
def test_regions_name_the_field(make, field):
    with pytest.raises(FieldError) as info:
        make()
    err = info.value
    assert isinstance(err, ValueError) and err.field == field
    assert str(err).startswith(field) or f"'{field}'" in str(err)
    back = pickle.loads(pickle.dumps(err))                      # crosses process executors intact
    assert (back.field, back.reason, str(back)) == (err.field, err.reason, str(err))


def test_missing_field_has_the_missing_reason():
    with pytest.raises(FieldError) as info:
        Region.from_dict({"type": "segment", "center": [0, 0]})
    assert info.value.reason == MISSING and info.value.field == "direction"


def test_option_error_is_a_field_error():
    with pytest.raises(OptionError) as info:
        tritools.TriangulationOptions(max_delta=-3)
    assert isinstance(info.value, FieldError) and info.value.field == "max_delta"


def _doc_with_region(region: dict) -> str:
    cams, regions = tritools.paper_example(4)
    doc = problem_to_dict(cams, regions, "p")
    doc["regions"][1] = region
    return json.dumps(doc)


@pytest.mark.parametrize("region, where, says", [
    ({"type": "ellipse", "center": [0, 0], "D": [[1, 2], [3, 4]]}, "regions[1].D", "must be symmetric"),
    ({"type": "ellipse", "center": [0, 0]}, "regions[1].D", "missing required field"),
    ({"type": "segment", "center": [0, "a"], "direction": [1, 0]}, "regions[1].center", "must be"),
])
def test_problem_file_places_region_errors_by_field(region, where, says):
    with pytest.raises(ProblemFileError) as info:
        parse_problem_text(_doc_with_region(region), "p.json")
    assert where in info.value.location and says in str(info.value)
