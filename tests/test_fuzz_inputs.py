"""A bounded hypothesis campaign on the input boundaries (issue #14): whatever comes in,

* ``parse_problem_text`` / ``parse_problem_bytes`` parse it or raise ``ProblemFileError`` -- never another
  exception;
* ``tritools.triangulate`` (short budget) returns a ``TriangulationResult`` or raises ``ValueError`` /
  ``TypeError`` with a message -- never another exception, never ``MemoryError``, never hangs;
* ``tritools.as_regions`` returns Regions or raises ``ValueError`` / ``TypeError`` with a message;
* ``sospoly.Polynomial`` refuses exponents that are not integers (a float 1.5, a bool, a numpy float)
  instead of truncating them, naming the exponent.

Every test has ``max_examples`` and ``deadline=None`` so that the file runs in well under a minute.
"""
import json
import math
import time

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

import sospoly
import tritools
from sospoly import Polynomial
from tritools.io.problem_file import ProblemFileError, ProblemSpec, parse_problem_bytes, parse_problem_text
from tritools.model.regions import Region

FUZZ = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
#: the budget of a fuzzed triangulation and the wall time allowed beyond it before calling it a hang.
BUDGET = sospoly.Budget(time_limit=5)
HANG_SLACK = 20.0

CAMS = [[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 1]],
        [[1, 0, 0, 1], [0, 1, 0, 0], [0, 0, 1, 1]],
        [[1, 0, 0, 0], [0, 1, 0, 1], [0, 0, 1, 1]]]
GOOD_REGIONS = [[0.2, -0.1], {"type": "point", "x": [0.6, -0.05]},
                {"type": "ellipse", "center": [0.1, 0.45], "D": [[0.01, 0], [0, 0.01]]}]

# ----------------------------------------------------------------------------- JSON values
#: stands for a 5000-digit integer literal (beyond int()'s 4300-digit limit; not representable by hypothesis)
HUGE = "<5000 digits>"
numbers = st.one_of(
    st.integers(min_value=-10, max_value=10),
    st.integers(),
    st.sampled_from([0, 1, 2, 3, 4, -2, 10 ** 308, 2 * 10 ** 308, -(10 ** 400), HUGE]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, 1e-320, 1e308, -1e308, 2.0, 4.0, 2.5]),
)
scalars = st.one_of(st.none(), st.booleans(), numbers, st.text(max_size=8),
                    st.sampled_from(["point", "segment", "polytope", "ellipse", "ellipse_border", "auto",
                                     "theorem1", "corollary1", "sdp", "NaN"]))
keys = st.sampled_from(["name", "cameras", "regions", "method", "delta", "max_delta", "path", "comment",
                        "problems", "type", "x", "center", "direction", "B", "c", "D", "delat"]) | st.text(max_size=5)
json_values = st.recursive(scalars, lambda inner: st.lists(inner, max_size=5) | st.dictionaries(keys, inner,
                                                                                                  max_size=5),
                           max_leaves=30)


def _dumps(value) -> str:
    """JSON text (NaN/Infinity written as the literals Python's parser accepts), HUGE as a 5000-digit integer."""
    return json.dumps(value).replace(json.dumps(HUGE), "-1" + "0" * 4999)


def _set_path(doc, path, value):
    """``doc`` with the entry at ``path`` (indices into nested lists/dicts, taken modulo their size) replaced."""
    if not path or not isinstance(doc, (list, dict)) or not doc:
        return value
    if isinstance(doc, list):
        i = path[0] % len(doc)
        return doc[:i] + [_set_path(doc[i], path[1:], value)] + doc[i + 1:]
    k = sorted(doc)[path[0] % len(doc)]
    return {**doc, k: _set_path(doc[k], path[1:], value)}


def _problem(**extra):
    return {"name": "p", "cameras": CAMS, "regions": GOOD_REGIONS, **extra}


near_valid = st.builds(
    lambda doc, path, value, drop: (_set_path(doc, path, value) if drop is None
                                    else {k: v for k, v in doc.items() if k != drop} if isinstance(doc, dict)
                                    else doc),
    st.sampled_from([_problem(), {"problems": [_problem(), _problem(delta=4)]}, [_problem(method="corollary1")],
                     _problem(delta=2, max_delta=4, path="auto")]),
    st.lists(st.integers(min_value=0, max_value=50), max_size=5),
    json_values,
    st.none() | st.sampled_from(["cameras", "regions", "name", "problems"]),
)


def _check_parse(text_or_bytes):
    try:
        if isinstance(text_or_bytes, bytes):
            specs = parse_problem_bytes(text_or_bytes, "<fuzz>")
        else:
            specs = parse_problem_text(text_or_bytes, "<fuzz>")
    except ProblemFileError as exc:
        assert str(exc) and "\n" not in str(exc)
        assert len(str(exc)) < 2000, str(exc)[:200]
        return None
    assert isinstance(specs, list) and specs and all(isinstance(s, ProblemSpec) for s in specs)
    for s in specs:
        assert s.cameras.shape == (len(s.regions), 3, 4) and np.all(np.isfinite(s.cameras))
        assert all(isinstance(r, Region) for r in s.regions)
    return specs


@FUZZ
@given(json_values)
def test_random_json_documents_parse_or_raise_problem_file_error(value):
    _check_parse(_dumps(value))


@FUZZ
@given(near_valid)
def test_mutated_valid_documents_parse_or_raise_problem_file_error(doc):
    _check_parse(_dumps(doc))


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=64) | st.text(max_size=64).map(str.encode))
def test_random_bytes_parse_or_raise_problem_file_error(raw):
    _check_parse(raw)


@settings(max_examples=100, deadline=None)
@given(st.text(alphabet='[]{}",:0123456789.eE+-truefalsnNaIinfy \n', max_size=80))
def test_json_like_text_parses_or_raises_problem_file_error(text):
    _check_parse(text)


def test_the_valid_seeds_parse():
    assert len(_check_parse(json.dumps({"problems": [_problem(), _problem(delta=4)]}))) == 2
    assert _check_parse(json.dumps(_problem(method="auto", delta=2, max_delta=4, path="sdp")))[0].max_delta == 4


# ----------------------------------------------------------------------------- triangulate
reals = st.one_of(st.floats(min_value=-10, max_value=10, allow_nan=False),
                  st.sampled_from([0.0, 1.0, -1.0, np.nan, np.inf, -np.inf, 1e300, -1e300, 1e-300, 5e-324]))
entries = st.one_of(reals, reals, reals, st.booleans(), st.just(1 + 2j), st.just("1"), st.none())


@st.composite
def camera_arrays(draw, n):
    """(n, 3, 4) arrays: mostly well-posed cameras (a rig of translated cameras, perturbed), sometimes arbitrary
    values (non-finite, huge, tiny), another shape, or an object array with a stray non-real entry."""
    base = np.array([np.eye(3, 4) + [[0, 0, 0, k % 3], [0, 0, 0, k // 3], [0, 0, 0, 2]] for k in range(n)])
    kind = draw(st.sampled_from(["rig"] * 5 + ["values", "shape", "object"]))
    if kind == "rig":
        noise = draw(st.lists(st.floats(-0.3, 0.3), min_size=12 * n, max_size=12 * n))
        return base + np.array(noise).reshape(n, 3, 4)
    if kind == "shape":
        shape = draw(st.sampled_from([(n, 3, 3), (3, 4), (n, 4, 3), (n,), (0, 3, 4), (n, 3, 4, 1)]))
        return np.ones(shape) + np.arange(int(np.prod(shape))).reshape(shape)
    arr = np.array(draw(st.lists(reals, min_size=12 * n, max_size=12 * n)), dtype=float).reshape(n, 3, 4)
    if kind == "object":
        arr = arr.astype(object)
        arr.flat[draw(st.integers(0, arr.size - 1))] = draw(entries)
    return arr


@st.composite
def region_inputs(draw, n):
    kind = draw(st.sampled_from(["points"] * 4 + ["array", "list", "dicts", "wrong"]))
    if kind == "points":        # finite image points near the rig's projections
        xy = draw(st.lists(st.floats(-2, 2), min_size=2 * n, max_size=2 * n))
        return np.array(xy).reshape(n, 2)
    if kind == "array":
        rows = draw(st.sampled_from([n, n, n + 1, max(n - 1, 0)]))
        return np.array(draw(st.lists(reals, min_size=2 * rows, max_size=2 * rows)), dtype=float).reshape(rows, 2)
    if kind == "list":
        return [[draw(entries), draw(entries)] for _ in range(n)]
    if kind == "dicts":
        return [draw(region_dicts) for _ in range(n)]
    return draw(st.sampled_from([None, 3, "regions", {"type": "point"}, [], [[1, 2, 3]] * n]))


@st.composite
def triangulation_inputs(draw):
    n = draw(st.integers(min_value=1, max_value=4))
    return draw(camera_arrays(n)), draw(region_inputs(n)), draw(st.sampled_from(["auto", "corollary1", "theorem1"]))


def _check_triangulate(cams, regions, method):
    t0 = time.perf_counter()
    try:
        res = tritools.triangulate(cams, regions, method, budget=BUDGET)
    except (ValueError, TypeError) as exc:
        assert str(exc).strip(), f"{type(exc).__name__} without a message"
        res = None
    except MemoryError:                              # pragma: no cover - the failure this test looks for
        pytest.fail("MemoryError")
    elapsed = time.perf_counter() - t0
    assert elapsed < BUDGET.time_limit + HANG_SLACK, f"took {elapsed:.1f} s"
    if res is not None:
        assert isinstance(res, tritools.TriangulationResult)
        assert isinstance(res.status, tritools.Status)
        if res.optimal:
            assert res.X is not None and np.all(np.isfinite(res.X))
            assert res.gamma_lb <= res.gamma_ub + 1e-6 * max(1.0, abs(res.gamma_ub))
        json.dumps(res.to_dict(), allow_nan=False)   # the one JSON form: NaN-free whatever came in


@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(triangulation_inputs())
def test_triangulate_returns_a_result_or_raises_value_or_type_error(args):
    _check_triangulate(*args)


@pytest.mark.parametrize("cams,regions", [
    (np.array(CAMS, float), np.full((3, 2), np.nan)),
    (np.zeros((3, 3, 4)), np.zeros((3, 2))),
    (np.array([CAMS[0]] * 3, float), np.zeros((3, 2))),
    (np.array(CAMS, float) * 1e300, np.ones((3, 2))),
    (np.array(CAMS, float), np.ones((3, 2)) * 1e300),
    (np.array(CAMS, float) * 5e-324, np.ones((3, 2))),
    (np.array(CAMS, complex), np.ones((3, 2))),
    (np.array(CAMS, float)[:, :, :3], np.ones((3, 2))),
    (np.array(CAMS, float)[:1], np.ones((1, 2))),
    (np.array(CAMS, float), [[True, False]] * 3),
])
@pytest.mark.filterwarnings("error::RuntimeWarning")   # handled overflow stays inside
def test_triangulate_corner_cases(cams, regions):
    _check_triangulate(cams, regions, "auto")


# ----------------------------------------------------------------------------- as_regions
region_dicts = st.one_of(
    st.fixed_dictionaries({"type": st.sampled_from(["point", "segment", "polytope", "ellipse", "ellipse_border",
                                                    "circle", "", None, 3])},
                          optional={"x": json_values, "center": json_values, "direction": json_values,
                                    "B": json_values, "c": json_values, "D": json_values}),
    st.fixed_dictionaries({"type": st.just("point"), "x": st.lists(entries, min_size=0, max_size=3)}),
    st.fixed_dictionaries({"type": st.just("ellipse"), "center": st.lists(reals, min_size=2, max_size=2),
                           "D": st.lists(st.lists(reals, min_size=2, max_size=2), min_size=2, max_size=2)}),
    st.fixed_dictionaries({"type": st.just("polytope"),
                           "B": st.lists(st.lists(reals, min_size=2, max_size=2), min_size=0, max_size=5),
                           "c": st.lists(reals, min_size=0, max_size=5)}),
    st.fixed_dictionaries({"type": st.just("segment"), "center": st.lists(reals, min_size=2, max_size=2),
                           "direction": st.lists(reals, min_size=2, max_size=2)}),
    json_values,
)


@FUZZ
@given(st.lists(region_dicts, max_size=4), st.none() | st.integers(min_value=0, max_value=5))
def test_as_regions_returns_regions_or_raises_value_or_type_error(regions, n_views):
    try:
        out = tritools.as_regions(regions, n_views)
    except (ValueError, TypeError) as exc:
        assert str(exc).strip()
        return
    assert isinstance(out, tuple) and all(isinstance(r, Region) for r in out)
    assert n_views is None or len(out) == n_views
    for r in out:                                    # a Region that was accepted is usable
        assert r.to_dict()["type"] == r.kind
        with np.errstate(all="ignore"):
            d = r.distance(np.zeros(2))
        assert d >= 0, (r, d)


def test_segment_distance_with_a_subnormal_direction():
    """Was a NaN: (P - c) / s overflowed to inf for a subnormal direction entry and inf * 0 gave NaN."""
    seg = tritools.as_regions([{"type": "segment", "center": [1.0, 0.0], "direction": [0.0, 5e-324]}])[0]
    with np.errstate(all="ignore"):
        assert seg.distance(np.zeros(2)) == pytest.approx(1.0)


@FUZZ
@given(st.one_of(json_values, st.builds(np.array, st.lists(st.lists(reals, min_size=2, max_size=2), max_size=4))))
def test_as_regions_of_any_value(value):
    try:
        out = tritools.as_regions(value)
    except (ValueError, TypeError) as exc:
        assert str(exc).strip()
        return
    assert all(isinstance(r, Region) for r in out)


# ----------------------------------------------------------------------------- sospoly.Polynomial exponents
@pytest.mark.parametrize("bad", [1.5, 2.0, True, False, np.float64(1.0), np.float32(2.5), np.bool_(True), "1",
                                 None, 1 + 0j])
def test_polynomial_refuses_a_non_integer_exponent_naming_it(bad):
    with pytest.raises(TypeError, match="exponent") as info:
        Polynomial(("x", "y"), {(bad, 1): 1.0})
    assert repr(bad) in str(info.value)


@pytest.mark.parametrize("bad", [1, "xy", None, 2.0])
def test_polynomial_refuses_an_exponent_that_is_not_a_tuple(bad):
    with pytest.raises(TypeError, match="exponent"):
        Polynomial(("x",), {bad: 1.0})


@pytest.mark.parametrize("bad", ["1.5", True, np.bool_(False), 1j, np.complex128(1), [1.0], None])
def test_polynomial_refuses_a_coefficient_that_is_not_a_real_number(bad):
    with pytest.raises(TypeError, match="coefficient"):
        Polynomial(("x",), {(1,): bad})


def test_polynomial_integer_exponent_types_still_work():
    p = Polynomial(("x", "y"), {(np.int64(2), np.int32(1)): 1.0, (np.uint8(0), 3): np.float32(2.0)})
    x, y = sospoly.variables("x y")
    assert p == x ** 2 * y + 2 * y ** 3
    assert all(type(k) is int for e in p.terms for k in e)
    # the internal constructor is unchecked by design: callers pass clean data
    q = Polynomial.from_trusted_terms(("x",), {(1,): 2.0})
    assert q == 2 * x
    with pytest.raises(ValueError):
        x ** True
    with pytest.raises(ValueError):
        x ** 1.5
    with pytest.raises(ValueError):
        sospoly.variables("v", n=1.5)


@settings(max_examples=200, deadline=None)
@given(st.dictionaries(st.tuples(st.one_of(st.integers(0, 3), st.floats(0, 3), st.booleans()),
                                 st.integers(0, 3)),
                       st.floats(-5, 5), max_size=4))
def test_polynomial_exponents_fuzz(terms):
    integral = all(type(k) is int for e in terms for k in e)
    try:
        p = Polynomial(("x", "y"), terms)
    except TypeError as exc:
        assert not integral and "exponent" in str(exc)
        return
    assert integral
    assume(terms)
    point = np.array([1.3, -0.7])
    expected = sum(c * point[0] ** e[0] * point[1] ** e[1] for e, c in terms.items())
    assert math.isclose(p(point), expected, rel_tol=1e-9, abs_tol=1e-9)
