"""Tests of tritools.model.regions: exact distances vs brute force, polynomial descriptions
(SPEC §2), similarity invariance, serialisation and input validation."""
import json

import numpy as np
import pytest
from scipy.spatial import HalfspaceIntersection

from sospoly.algebra.polynomial import variables
from tritools.model.regions import (Ellipse, EllipseBorder, Point, Polytope, Region, RegionPolynomials, Segment,
                                    as_region, as_regions)

RNG = np.random.default_rng(12345)
X1, X2, Y1, Y2 = variables("x1 x2 y1 y2")


def ev(p, x, y=()):
    """Evaluate a Polynomial (over x1 x2 y1 y2) at x (2,), y."""
    vals = {"x1": x[0], "x2": x[1], "y1": y[0] if len(y) > 0 else 0.0, "y2": y[1] if len(y) > 1 else 0.0}
    return p.evaluate(np.array([vals[g] for g in p.gens])) if p.gens else float(p.coefficient(()))


def query_points(center, spread, n=60):
    return np.asarray(center) + spread * RNG.normal(size=(n, 2))


# ---------------------------------------------------------------- brute-force references
def brute_curve_distance(points, curve):
    """min over dense samples of a curve (k, 2) -> upper bound of the true distance."""
    out = np.empty(len(points))
    for k, p in enumerate(points):
        out[k] = np.sqrt(np.min(np.sum((curve - p) ** 2, axis=1)))
    return out


def ellipse_samples(center, D, n=400_000):
    lam, Q = np.linalg.eigh(D)
    th = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return center + (np.c_[np.cos(th), np.sin(th)] * np.sqrt(lam)) @ Q.T


def polytope_boundary_distance(B, c, points, lo, hi, n=200_001):
    """Distance via dense samples of the 2m boundary lines (B y + c)_k = +-1 clipped to the
    window [lo, hi]^2 and to the feasible set (no vertex computation); 0 for inside points.
    Returns (distances, sample spacing bound)."""
    samples, spacing = [], 0.0
    for k in range(len(B)):
        a = B[k]
        for rhs in (1.0 - c[k], -1.0 - c[k]):
            p0 = a * rhs / (a @ a)
            u = np.array([-a[1], a[0]]) / np.linalg.norm(a)
            L = 2 * max(abs(lo), abs(hi)) * np.sqrt(2) + np.linalg.norm(p0)
            t = np.linspace(-L, L, n)
            spacing = max(spacing, 2 * L / (n - 1))
            S = p0 + t[:, None] * u
            samples.append(S[np.all(np.abs(S @ B.T + c) <= 1.0 + 1e-12, axis=1)])
    S = np.vstack(samples)
    d = brute_curve_distance(points, S)
    d[np.all(np.abs(points @ B.T + c) <= 1.0, axis=1)] = 0.0
    return d, spacing


# ---------------------------------------------------------------- point
def test_point_distance_and_polynomial():
    R = Point([0.4, 0.8])
    P = query_points([0, 0], 2.0)
    d = R.distance(P)
    assert np.allclose(d, np.hypot(P[:, 0] - 0.4, P[:, 1] - 0.8), rtol=0, atol=1e-14)
    assert R.distance([0.4, 0.8]) == 0.0
    assert isinstance(R.distance([1.0, 1.0]), float)
    polys = R.polynomials((X1, X2), ())
    assert R.n_aux == 0 and polys.eq == () and polys.ineq == ()
    for p in P[:10]:
        assert ev(polys.f, p) == pytest.approx(R.distance(p) ** 2, abs=1e-12)


# ---------------------------------------------------------------- segment
@pytest.mark.parametrize("center,direction", [([0.8, 0.2], [1.0, 0.5]), ([0.4, 0.8], [0.5, 0.5]),
                                              ([-3.0, 2.0], [0.0, 2.0])])
def test_segment_distance_vs_dense_sampling(center, direction):
    R = Segment(center, direction)
    t = np.linspace(-1, 1, 200_001)
    samples = np.asarray(center) + t[:, None] * np.asarray(direction)
    P = np.vstack([query_points(center, 2.0), samples[[0, -1, 100_000]]])
    d = R.distance(P)
    ref = brute_curve_distance(P, samples)
    spacing = 2 * np.linalg.norm(direction) / 200_000
    # exact distance is <= every sampled distance, and within half a sample spacing of the best
    assert np.all(d <= ref + 1e-12)
    assert np.all(ref - d <= spacing / 2 + 1e-12)


def test_segment_f_equals_squared_distance_at_minimising_t():
    R = Segment([0.8, 0.2], [1.0, 0.5])
    polys = R.polynomials((X1, X2), (Y1,))
    assert R.n_aux == 1 and len(polys.ineq) == 1 and polys.eq == ()
    for p in query_points([0.8, 0.2], 2.0, 30):
        t = R.parameter(p)
        assert -1 <= t <= 1
        assert ev(polys.f, p, (t,)) == pytest.approx(R.distance(p) ** 2, abs=1e-12)
        # f(x, t) >= d^2 for every admissible t (t* minimises)
        for tt in np.linspace(-1, 1, 21):
            assert ev(polys.f, p, (tt,)) >= R.distance(p) ** 2 - 1e-12
    h = polys.ineq[0]
    assert ev(h, [0, 0], (0.5,)) > 0 and ev(h, [0, 0], (1.0,)) == 0 and ev(h, [0, 0], (1.5,)) < 0


def test_segment_endpoints_and_zero_direction():
    R = Segment.from_endpoints([0, 0], [2, 0])
    assert np.allclose(R.center, [1, 0]) and np.allclose(R.direction, [1, 0])
    assert R.distance([3, 0]) == pytest.approx(1.0)
    Z = Segment([1.0, 1.0], [0.0, 0.0])
    assert Z.distance([4.0, 5.0]) == pytest.approx(5.0)


# ---------------------------------------------------------------- polytope
def random_polytope(m):
    ang = np.sort(RNG.uniform(0, np.pi, m))
    B = np.c_[np.cos(ang), np.sin(ang)] * RNG.uniform(0.5, 2.0, (m, 1))
    c = RNG.uniform(-0.5, 0.5, m)
    return B, c


@pytest.mark.parametrize("m", [2, 3, 5])
def test_polytope_vertices_match_scipy_halfspace_intersection(m):
    B, c = random_polytope(m)
    R = Polytope(B, c)
    # halfspaces A y + b <= 0:  B y + c - 1 <= 0, -B y - c - 1 <= 0; the least-squares point is interior
    hs = np.vstack([np.c_[B, c - 1], np.c_[-B, -c - 1]])
    interior = np.linalg.lstsq(B, -c, rcond=None)[0]
    ref = HalfspaceIntersection(hs, interior).intersections
    ref = np.unique(np.round(ref, 9), axis=0)
    assert len(R.vertices) == len(ref)
    for v in R.vertices:
        assert np.min(np.linalg.norm(ref - v, axis=1)) < 1e-8
    # ordered by angle: consecutive edges turn the same way (convex polygon)
    V = R.vertices
    e = np.roll(V, -1, axis=0) - V
    cross = e[:, 0] * np.roll(e, -1, axis=0)[:, 1] - e[:, 1] * np.roll(e, -1, axis=0)[:, 0]
    assert np.all(cross > 0) or np.all(cross < 0)


@pytest.mark.parametrize("m", [2, 3, 6])
def test_polytope_distance_vs_boundary_sampling(m):
    B, c = random_polytope(m)
    R = Polytope(B, c)
    lo, hi = R.vertices.min() - 0.1, R.vertices.max() + 0.1
    P = query_points(R.center, 1.5 * (hi - lo), 25)
    ref, h = polytope_boundary_distance(B, c, P, lo, hi)
    d = R.distance(P)
    assert np.all(d <= ref + 1e-12)
    assert np.all(ref - d <= h + 1e-12)
    assert R.distance(R.center) == 0.0


def test_polytope_polynomials_signs_and_f():
    R = Polytope.box([1.0, 2.0], [0.5, 0.25])
    polys = R.polynomials((X1, X2), (Y1, Y2))
    assert R.n_aux == 2 and len(polys.ineq) == 2 and polys.eq == ()
    inside, outside = [1.2, 2.1], [1.2, 2.4]
    assert all(ev(h, [0, 0], inside) > 0 for h in polys.ineq)
    assert any(ev(h, [0, 0], outside) < 0 for h in polys.ineq)
    for p in query_points([1, 2], 2.0, 20):
        y = R.closest_point(p)
        assert all(ev(h, [0, 0], y) >= -1e-12 for h in polys.ineq)
        assert ev(polys.f, p, y) == pytest.approx(R.distance(p) ** 2, abs=1e-12)
    assert R.distance([3.0, 2.0]) == pytest.approx(1.5)
    assert np.allclose(R.center, [1.0, 2.0])


def test_polytope_degenerate_segment_is_accepted():
    # slabs 0 <= y1 <= 2 and 2 <= y1 <= 4 touch along y1 = 2; |y2| <= 1
    B = np.array([[1.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    c = np.array([-1.0, -3.0, 0.0])
    R = Polytope(B, c)
    assert len(R.vertices) == 2
    assert R.distance([5.0, 0.0]) == pytest.approx(3.0)
    assert R.distance([2.0, 3.0]) == pytest.approx(2.0)


@pytest.mark.parametrize("B,c,match", [
    ([[1.0, 0.0], [2.0, 0.0]], [0.0, 0.0], "rank"),
    ([[1.0, 0.0], [0.0, 1.0], [1.0, 0.0]], [0.0, 0.0, 5.0], "empty"),
    ([[1.0, 0.0], [0.0, 1.0]], [0.0], "c must have shape"),
    ([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], [0.0, 0.0], "B must be"),
    ([[1.0, np.nan], [0.0, 1.0]], [0.0, 0.0], "finite"),
    ([[1.0, 0.0]], [0.0], "at least 2 rows"),
])
def test_polytope_bad_input(B, c, match):
    with pytest.raises(ValueError, match=match):
        Polytope(B, c)


# ---------------------------------------------------------------- ellipses
ELLIPSES = [
    ([0.8, 0.2], (1 / 3) ** 2 * np.eye(2)),                 # Example 2's circle
    ([0.3, -0.2], np.array([[4.0, 1.0], [1.0, 1.0]])),      # rotated
    ([0.0, 0.0], np.diag([25.0, 0.04])),                   # elongated
    ([1.0, 1.0], np.diag([1.0 + 1e-9, 1.0])),               # near-circle
]


def special_points(R: EllipseBorder):
    """Centre, points on both axes inside/outside, points on the border."""
    Q = R._Q
    a, b = R.semi_axes
    pts = [R.center]
    for k, s in enumerate((a, b)):
        for f in (0.3, 0.999, 1.0, 1.5, 3.0, -0.5, -2.0):
            pts.append(R.center + f * s * Q[:, k])
    pts.append(R.center + 1e-9 * Q[:, 0] + 0.5 * a * Q[:, 0])
    pts.append(R.center + 1e-12 * Q[:, 1] + 0.2 * a * Q[:, 0])
    return np.array(pts)


@pytest.mark.parametrize("center,D", ELLIPSES)
def test_ellipse_border_distance_vs_dense_sampling(center, D):
    R = EllipseBorder(center, D)
    samples = ellipse_samples(np.asarray(center), D)
    P = np.vstack([query_points(center, 3.0, 40), special_points(R)])
    d = R.distance(P)
    ref = brute_curve_distance(P, samples)
    # arc length between samples <= 2 pi a / n
    spacing = 2 * np.pi * R.semi_axes[0] / len(samples)
    assert np.all(d <= ref + 1e-12), "exact distance exceeds a sampled distance"
    assert np.all(ref - d <= spacing + 1e-12)
    # one-point and many-point code paths agree
    single = np.array([R.distance(p) for p in P])
    assert np.allclose(single, d, rtol=0, atol=1e-12)
    # closest points lie on the border
    C = R.closest_point(P)
    assert np.allclose(R.level(C), 1.0, atol=1e-9)


def test_ellipse_center_and_axes_closed_forms():
    R = EllipseBorder([0, 0], np.diag([4.0, 1.0]))     # semi-axes 2 and 1
    assert R.distance([0.0, 0.0]) == pytest.approx(1.0)
    assert R.distance([3.0, 0.0]) == pytest.approx(1.0)
    assert R.distance([0.0, 3.0]) == pytest.approx(2.0)
    # inside on the major axis: closest point (e0^2 y0/(e0^2-e1^2), ...) = (2/3, sqrt(8)/3)
    assert np.allclose(np.abs(R.closest_point([0.5, 0.0])), [2 / 3, np.sqrt(8) / 3])
    C = EllipseBorder.circle([1.0, 1.0], 2.0)
    assert C.distance([1.0, 1.0]) == pytest.approx(2.0)
    assert C.distance([4.0, 5.0]) == pytest.approx(3.0)


@pytest.mark.parametrize("center,D", ELLIPSES[:2])
def test_ellipse_polynomials(center, D):
    border, filled = EllipseBorder(center, D), Ellipse(center, D)
    pb = border.polynomials((X1, X2), (Y1, Y2))
    pf = filled.polynomials((X1, X2), (Y1, Y2))
    assert len(pb.eq) == 1 and pb.ineq == () and len(pf.ineq) == 1 and pf.eq == ()
    g, h = pb.eq[0], pf.ineq[0]
    on = ellipse_samples(np.asarray(center), D, 50)
    for y in on:
        assert ev(g, [0, 0], y) == pytest.approx(0.0, abs=1e-12)
    assert ev(g, [0, 0], center) == pytest.approx(1.0)               # inside: g > 0
    assert ev(h, [0, 0], np.asarray(center) + 10.0) < 0               # outside: h < 0
    for p in query_points(center, 2.0, 20):
        y = border.closest_point(p)
        assert ev(pb.f, p, y) == pytest.approx(border.distance(p) ** 2, abs=1e-12)
        assert ev(g, [0, 0], y) == pytest.approx(0.0, abs=1e-9)
        yf = filled.closest_point(p)
        assert ev(h, [0, 0], yf) >= -1e-9
        assert ev(pf.f, p, yf) == pytest.approx(filled.distance(p) ** 2, abs=1e-12)


def test_filled_ellipse_distance():
    center, D = ELLIPSES[1]
    F, Bd = Ellipse(center, D), EllipseBorder(center, D)
    P = query_points(center, 3.0, 200)
    inside = Bd.level(P) <= 1
    assert inside.any() and (~inside).any()
    d = F.distance(P)
    assert np.all(d[inside] == 0.0)
    assert np.allclose(d[~inside], Bd.distance(P[~inside]), atol=1e-14)
    assert np.allclose(F.closest_point(P[inside]), P[inside])


@pytest.mark.parametrize("D,match", [
    ([[1.0, 0.0], [0.0, -1.0]], "positive definite"),
    ([[1.0, 0.0], [0.0, 0.0]], "positive definite"),
    ([[1.0, 0.5], [0.0, 1.0]], "symmetric"),
    ([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], "2x2"),
    ([[np.inf, 0.0], [0.0, 1.0]], "finite"),
    ([[1e-320, 0.0], [0.0, 1e-320]], "singular"),      # denormal: positive, but 1/D overflows
])
def test_ellipse_bad_input(D, match):
    for cls in (EllipseBorder, Ellipse):
        with pytest.raises(ValueError, match=match):
            cls([0.0, 0.0], D)


# ---------------------------------------------------------------- similarity
def all_regions():
    return [
        Point([0.4, 0.8]),
        Segment([0.8, 0.2], [1.0, 0.5]),
        Polytope(*random_polytope(4)),
        EllipseBorder(*ELLIPSES[1]),
        Ellipse(*ELLIPSES[1]),
    ]


@pytest.mark.parametrize("R", all_regions(), ids=lambda r: r.kind)
def test_similarity_scales_distances(R):
    s, t = 3.7, np.array([0.25, -1.5])
    R2 = R.similarity(s, t)
    assert type(R2) is type(R)
    P = query_points(R.center, 2.0, 50)
    P2 = s * (P - t)
    assert np.allclose(R2.distance(P2), s * R.distance(P), rtol=1e-10, atol=1e-12)
    assert np.allclose(R2.closest_point(P2), s * (R.closest_point(P) - t), rtol=1e-10, atol=1e-10)
    assert np.allclose(R2.center, s * (R.center - t))
    with pytest.raises(ValueError, match="scale"):
        R.similarity(0.0, t)
    with pytest.raises(ValueError, match="shift"):
        R.similarity(1.0, [1.0, 2.0, 3.0])


# ---------------------------------------------------------------- serialisation
@pytest.mark.parametrize("R", all_regions(), ids=lambda r: r.kind)
def test_dict_round_trip(R):
    d = json.loads(json.dumps(R.to_dict()))
    R2 = Region.from_dict(d)
    assert R2 == R and type(R2) is type(R) and hash(R2) == hash(R)
    P = query_points(R.center, 2.0, 10)
    assert np.array_equal(R2.distance(P), R.distance(P))


def test_from_dict_schema_and_errors():
    assert Region.from_dict({"type": "point", "x": [1, 2]}) == Point([1, 2])
    assert isinstance(Region.from_dict({"type": "ellipse_border", "center": [0, 0], "D": [[1, 0], [0, 1]],
                                        "printed_radius": 1.0}), EllipseBorder)
    with pytest.raises(ValueError, match="'type'"):
        Region.from_dict({"x": [1, 2]})
    with pytest.raises(ValueError, match="'type'"):
        Region.from_dict({"type": "hexagon"})
    with pytest.raises(ValueError, match="'direction'"):
        Region.from_dict({"type": "segment", "center": [0, 0]})
    with pytest.raises(ValueError, match="'D'"):
        Region.from_dict({"type": "ellipse", "center": [0, 0]})
    with pytest.raises(ValueError, match="'c'"):
        Region.from_dict({"type": "polytope", "B": [[1, 0], [0, 1]]})
    with pytest.raises(ValueError, match="mapping"):
        Region.from_dict([1, 2])


def test_as_region_and_as_regions():
    assert as_region([1.0, 2.0]) == Point([1.0, 2.0])
    assert as_region({"type": "point", "x": [1, 2]}) == Point([1, 2])
    with pytest.raises(ValueError):
        as_region("nonsense")
    with pytest.raises(ValueError, match=r"regions: expected one region per camera \(3\), got 2"):
        as_regions([[0, 0], [1, 1]], n_views=3)
    assert as_regions(np.array([[0.0, 0.0], [1.0, 1.0]]), n_views=2) == (Point([0, 0]), Point([1, 1]))


# ---------------------------------------------------------------- bad inputs
def test_point_and_segment_bad_input():
    with pytest.raises(ValueError, match="x must be finite"):
        Point([np.nan, 0.0])
    with pytest.raises(ValueError, match=r"x must have shape \(2,\)"):
        Point([1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="direction"):
        Segment([0, 0], [1.0])
    R = Point([0, 0])
    with pytest.raises(ValueError, match="points"):
        R.distance([[1.0, 2.0, 3.0]])
    with pytest.raises(ValueError, match="finite"):
        R.distance([np.inf, 0.0])
    with pytest.raises(ValueError, match="y must be a tuple of 1"):
        Segment([0, 0], [1, 0]).polynomials((X1, X2), ())
    with pytest.raises(ValueError, match="x must be a tuple of 2"):
        Point([0, 0]).polynomials((X1,), ())


def test_region_polynomials_is_frozen():
    rp = Point([0, 0]).polynomials((X1, X2), ())
    assert isinstance(rp, RegionPolynomials)
    with pytest.raises(Exception):
        rp.f = None
    assert Point([0, 0]).polynomials((X1, X2), ()).f.degree == 2


def test_new_region_type_only_needs_the_interface():
    """A user-defined region (a half-line) plugs in through the abstract interface alone."""
    from dataclasses import dataclass
    from typing import ClassVar

    @dataclass(frozen=True, eq=False)
    class HalfLine(Region):
        """{o + t d : t >= 0} with n = 1, f = ||x - o - y d||^2, h = y."""

        o: tuple
        d: tuple
        kind: ClassVar[str] = "test_half_line"

        @property
        def n_aux(self):
            return 1

        def polynomials(self, x, y):
            f = (x[0] - self.o[0] - y[0] * self.d[0]) ** 2 + (x[1] - self.o[1] - y[0] * self.d[1]) ** 2
            return RegionPolynomials(f, (), (y[0],))

        def closest_point(self, points):
            P = np.atleast_2d(np.asarray(points, float))
            o, d = np.asarray(self.o), np.asarray(self.d)
            t = np.maximum(0.0, (P - o) @ d / (d @ d))
            C = o + t[:, None] * d
            return C[0] if np.ndim(points) == 1 else C

        @property
        def center(self):
            return np.asarray(self.o, float)

        def similarity(self, scale, shift):
            o = scale * (np.asarray(self.o) - shift)
            return HalfLine(tuple(o), tuple(scale * np.asarray(self.d)))

        def _fields(self):
            return {"o": list(self.o), "d": list(self.d)}

    H = HalfLine((0.0, 0.0), (1.0, 0.0))
    assert H.distance([-3.0, 4.0]) == pytest.approx(5.0)
    assert H.distance([3.0, 4.0]) == pytest.approx(4.0)
    assert Region.from_dict(H.to_dict()) == H


def test_ellipse_with_entries_near_the_float_limit_is_accepted():
    """0.5 (D + D^T) overflowed for D = 1e308 I ("eigenvalues [nan, nan]"); D is positive definite."""
    e = Ellipse([0.0, 0.0], [[1e308, 0.0], [0.0, 1e308]])
    assert e.distance([0.0, 0.0]) == 0.0 and np.all(np.isfinite(e.semi_axes))
