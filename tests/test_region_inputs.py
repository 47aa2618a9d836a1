"""The input boundary of regions: as_regions (sequences, dicts, 2-vectors, (N, 2) arrays), error
messages naming the element, and numeric validation refusing complex, object, string, boolean
and non-finite data by name while allowing any finite magnitude."""
import numpy as np
import pytest

import tritools.model.regions as regions_pkg
from tritools.model.regions import (Ellipse, EllipseBorder, Point, Polytope, Region, Segment, as_matrix, as_points,
                                    as_region, as_regions, as_vector, positive_number, real_array)

OLD_ALL = ["Region", "RegionPolynomials", "Point", "Segment", "Polytope", "EllipseBorder", "Ellipse",
           "as_region", "as_regions"]


# ---------------------------------------------------------------- package layout
def test_package_exports_the_old_names_and_the_modules_stay_small():
    import pathlib

    assert set(OLD_ALL) <= set(regions_pkg.__all__)
    for name in regions_pkg.__all__:
        assert hasattr(regions_pkg, name), name
    # the names the old module had besides __all__ (used elsewhere in the code base)
    for name in ("positive_number", "POLYTOPE_RANK_RTOL", "POLYTOPE_VERTEX_RTOL", "SYMMETRY_RTOL", "PD_RTOL",
                 "ELLIPSE_MAX_ITER", "ELLIPSE_SCALAR_MAX"):
        assert hasattr(regions_pkg, name), name
    root = pathlib.Path(regions_pkg.__file__).parent
    sizes = {p.name: len(p.read_text().splitlines()) for p in root.glob("*.py")}
    assert set(sizes) >= {"__init__.py", "base.py", "point.py", "polytope.py", "ellipse.py", "coerce.py"}
    assert max(sizes.values()) <= 420, sizes
    # no module imports another's private names
    for p in root.glob("*.py"):
        for line in p.read_text().splitlines():
            if line.startswith("from .") and " import " in line:
                names = line.split(" import ", 1)[1].strip("()").split(",")
                assert not any(n.strip().startswith("_") for n in names), (p.name, line)


# ---------------------------------------------------------------- as_regions
def test_as_regions_accepts_an_n_by_2_array():
    x = np.array([[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]])
    out = as_regions(x, n_views=3)
    assert out == (Point([1, 2]), Point([3, 4]), Point([5, 6]))
    assert as_regions(x.astype(np.float32)) == out
    assert as_regions(np.array([[1, 2], [3, 4]])) == out[:2]            # integers are real numbers
    assert as_regions(np.empty((0, 2))) == ()
    # the result does not share memory with the caller's array
    x[0, 0] = 99.0
    assert out[0] == Point([1, 2])


def test_as_regions_mixed_sequence_and_iterables():
    seg = Segment([0, 0], [1, 0])
    out = as_regions([seg, {"type": "point", "x": [1, 2]}, (3.0, 4.0), np.array([5.0, 6.0])], n_views=4)
    assert out == (seg, Point([1, 2]), Point([3, 4]), Point([5, 6]))
    assert out[0] is seg
    assert as_regions(p for p in [[0, 0], [1, 1]]) == (Point([0, 0]), Point([1, 1]))
    objs = np.empty(2, dtype=object)
    objs[0], objs[1] = seg, Point([1, 1])
    assert as_regions(objs) == (seg, Point([1, 1]))


@pytest.mark.parametrize("regions,match", [
    (np.array([[1.0, 2.0, 3.0]]), r"regions given as an array must have shape \(N, 2\)"),
    (np.array([1.0, 2.0]), r"regions given as an array must have shape \(N, 2\).*\(2,\)"),
    (np.array([[1.0, 2.0], [np.nan, 0.0]]), r"regions\[1\] must be finite"),
    (np.array([[1.0, 2.0], [0.0, np.inf]]), r"regions\[1\] must be finite"),
    (np.array([[1 + 2j, 2.0]]), r"regions must be real numbers, got complex128"),
    (np.array([[True, False]]), r"regions must be real numbers, got bool"),
    (np.array([["a", "b"]]), r"regions must be real numbers, got str"),
    ([Point([0, 0]), Point([1, 1]), Point([2, 2]), "nonsense"], r"regions\[3\]: cannot interpret 'nonsense'"),
    ([Point([0, 0]), [1.0, 2.0, 3.0]], r"regions\[1\]: cannot interpret \[1.0, 2.0, 3.0\]"),
    ([[0, 0], {"type": "ellipse", "center": [0, 0]}],
     r"regions\[1\]: region of type 'ellipse' is missing the field 'D'"),
    ([[0, 0], {"type": "hexagon"}], r"regions\[1\]: unknown region field 'type'"),
    ([[0, 0], [1j, 0]], r"regions\[1\] must be real numbers, got complex128"),
    ([[0, 0], [None, 0]], r"regions\[1\] must be real numbers, got object"),
    ([[0, 0], [True, False]], r"regions\[1\] must be real numbers, got bool"),
    ([[0, 0], [np.nan, 0]], r"regions\[1\] must be finite"),
    ([[0, 0], {"type": "polytope", "B": [[1, 0], [2, 0]], "c": [0, 0]}], r"regions\[1\]: B has rank < 2"),
    (Point([0, 0]), "regions must be a sequence"),
    ({"type": "point", "x": [0, 0]}, "regions must be a sequence"),
    ("ab", "regions must be a sequence"),
    (5, "regions must be a sequence"),
])
def test_as_regions_errors_name_the_element(regions, match):
    with pytest.raises(ValueError, match=match):
        as_regions(regions)


def test_as_regions_count():
    with pytest.raises(ValueError, match=r"regions: expected one region per camera \(3\), got 2"):
        as_regions([[0, 0], [1, 1]], n_views=3)
    with pytest.raises(ValueError, match="one region per view"):
        as_regions(np.zeros((4, 2)), n_views=3)


def test_as_region_single():
    assert as_region([1.0, 2.0]) == Point([1.0, 2.0])
    assert as_region({"type": "point", "x": [1, 2]}) == Point([1, 2])
    with pytest.raises(ValueError, match=r"^region: cannot interpret"):
        as_region("nonsense")
    with pytest.raises(ValueError, match=r"^view 2 must be real numbers, got complex128"):
        as_region(np.array([1j, 0]), name="view 2")


# ---------------------------------------------------------------- numeric validation
@pytest.mark.parametrize("value,match", [
    ([1 + 0j, 2.0], "center must be real numbers, got complex128"),
    (np.array([1.0, 2.0], dtype=np.complex64), "center must be real numbers, got complex64"),
    ([True, False], "center must be real numbers, got bool"),
    (["1", "2"], "center must be real numbers, got str"),
    ([b"1", b"2"], "center must be real numbers, got bytes"),
    ([1.0, None], "center must be real numbers, got object"),
    (np.array([1.0, 2.0], dtype=object), "center must be real numbers, got object"),
    ([[1.0], [2.0, 3.0]], r"center must be a numeric vector of length 2, got \[\[1.0\], \[2.0, 3.0\]\]"),
    ([1.0, np.inf], "center must be finite"),
    ([np.nan, 0.0], "center must be finite"),
    ([1.0, 2.0, 3.0], r"center must have shape \(2,\)"),
])
def test_vector_validation(value, match):
    with pytest.raises(ValueError, match=match):
        as_vector(value, "center")
    with pytest.raises(ValueError, match=match):
        Segment(value, [1.0, 0.0])


def test_real_array_accepts_integers_floats_and_array_likes():
    class Wrapped:
        def __array__(self, dtype=None, copy=None):
            return np.array([1.5, 2.5])

    assert real_array(Wrapped(), "w").tolist() == [1.5, 2.5]
    assert real_array(np.array([1, 2], dtype=np.uint8), "u").dtype == np.float64
    assert real_array(np.float32(2.5), "f").shape == ()
    # the result is a copy
    a = np.array([1.0, 2.0])
    b = real_array(a, "a")
    b[0] = 5.0
    assert a[0] == 1.0


def test_matrix_and_points_validation():
    with pytest.raises(ValueError, match="D must be real numbers, got complex128"):
        Ellipse([0, 0], [[1, 0], [0, 1j]])
    with pytest.raises(ValueError, match="D must be real numbers, got bool"):
        EllipseBorder([0, 0], [[True, False], [False, True]])
    with pytest.raises(ValueError, match=r"B must be a mx2 matrix"):
        as_matrix([[1.0, 2.0, 3.0]], "B", (None, 2))
    with pytest.raises(ValueError, match="points must be real numbers, got complex128"):
        Point([0, 0]).distance([1j, 0])
    with pytest.raises(ValueError, match="points must be finite"):
        Polytope.box([0, 0], [1, 1]).closest_point([[0.0, np.nan]])
    P, single = as_points([1, 2])
    assert single and P.shape == (1, 2)


@pytest.mark.parametrize("value", [0.0, -1.0, np.inf, np.nan, True, "2", 1j, [1.0], None])
def test_positive_number_refuses(value):
    with pytest.raises(ValueError, match="scale must be a positive"):
        positive_number(value, "scale")


def test_positive_number_accepts():
    assert positive_number(2, "s") == 2.0 and positive_number(np.float32(0.5), "s") == 0.5
    assert positive_number(1e300, "s") == 1e300


def test_similarity_refuses_complex_shift():
    with pytest.raises(ValueError, match="shift must be real numbers, got complex128"):
        Point([0, 0]).similarity(2.0, [1j, 0])


# ---------------------------------------------------------------- large finite values
def test_huge_and_tiny_finite_values_are_allowed():
    p = Point([1e300, -1e300])
    assert p.distance([1e300, -1e300]) == 0.0
    assert p.distance([-1e300, -1e300]) == pytest.approx(2e300)
    s = Segment.from_endpoints([-1e308, 0.0], [1e308, 0.0])       # (b - a) / 2 would overflow
    assert np.isfinite(s.direction).all() and s.distance([0.0, 1.0]) == 1.0
    assert s.distance([1.5e308, 0.0]) == pytest.approx(0.5e308)
    tiny = Segment([0.0, 0.0], [1e-300, 1e-300])                    # ||d||^2 underflows
    assert tiny.parameter([1e-300, 1e-300]) == pytest.approx(1.0)
    assert tiny.parameter([0.5e-300, 0.5e-300]) == pytest.approx(0.5)
    big = Segment([0.0, 0.0], [1e300, 0.0])                         # ||d||^2 overflows
    assert big.parameter([0.5e300, 7.0]) == pytest.approx(0.5)
    e = EllipseBorder.circle([1e300, 0.0], 1e150)
    assert e.distance([1e300, 0.0]) == pytest.approx(1e150)
    assert Ellipse([0, 0], 1e300 * np.eye(2)).distance([0.0, 2e150]) == pytest.approx(1e150)
    assert Region.from_dict(p.to_dict()) == p


def test_points_from_an_array_equal_points_built_one_by_one():
    """as_regions of an (N, 2) array (Point.from_checked_rows, no per-row checks): the Points of Point(row), each
    x a read-only float64 copy (the caller's array is not shared), the same refusals of bad arrays."""
    import numpy as np

    from tritools.model.regions import Point, as_regions

    X = np.array([[1.5, -2.0], [-0.0, 3e300], [7, 8]])
    got = as_regions(X)
    ref = tuple(Point(row) for row in X)
    for p, q in zip(got, ref):
        assert type(p) is Point and p == q and p.x.dtype == np.float64 and p.x.shape == (2,)
        assert np.array_equal(p.x, q.x) and np.array_equal(np.signbit(p.x), np.signbit(q.x))
        assert not p.x.flags.writeable and not np.shares_memory(p.x, X)
    assert as_regions(np.array([[1, 2], [3, 4]]))[1] == Point([3.0, 4.0])         # integers: floats
    for bad in (np.array([[1.0, np.nan]]), np.array([[1.0, 2.0, 3.0]]), np.array([[1 + 1j, 2]])):
        with pytest.raises(ValueError):
            as_regions(bad)


def test_as_points_fast_path_for_one_float_point_is_the_checked_conversion():
    """as_points takes a finite float64 (2,) array without real_array's conversions: the same (1, 2) result, a new
    array (writing to it leaves the caller's point alone), and every other input -- NaN / inf, other dtypes,
    subclasses, (m, 2) -- goes through the checks with their messages."""
    import numpy as np
    import pytest

    from tritools.model.regions.base import as_points

    rng = np.random.default_rng(0)
    for p in list(rng.normal(size=(20, 2)) * 10.0 ** rng.integers(-300, 300, size=(20, 1))) + [np.array([-0.0, 0.0])]:
        P, single = as_points(p)
        Q, single_q = as_points(p.tolist())                      # the checked path
        assert single and single_q and P.shape == (1, 2) and P.dtype == np.float64
        np.testing.assert_array_equal(P, Q)
        P[0, 0] = 12345.0
        assert p[0] != 12345.0
    for bad in (np.array([np.nan, 1.0]), np.array([1.0, np.inf]), np.array([1.0, 2.0, 3.0])):
        with pytest.raises(ValueError, match="points"):
            as_points(bad)
    P, single = as_points(np.array([1, 2], dtype=np.int32))
    assert single and P.dtype == np.float64
    P, single = as_points(np.zeros((3, 2)))
    assert not single and P.shape == (3, 2)
