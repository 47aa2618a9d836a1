"""What the solvers need of a region is the region's own (issue 18 item 3): its extent (the box of the
rigorous margin), its conic form (the certified uncertainty and its dilation), whether it is a point or a
disc (the fast paths).  A user-defined region -- the Disc of docs/regions.md, copied here as the docs show
it -- gets exactly the rigour of the equivalent built-in Ellipse; one without ``extent()`` is refused with
a TypeError naming it, never certified without the PSD-defect margin.

References are independent of the code under test: the built-in Ellipse (another implementation of the
same set), a dense multi-start minimisation of gamma, sampled region points for the extents."""
import math
import sys
from dataclasses import dataclass

import numpy as np
import pytest
from scipy import optimize

import sospoly.analysis
import tritools
from tritools import Ellipse, EllipseBorder, Point, Polytope, Segment
from tritools.model.regions import (ConeKind, ConicForm, Region, RegionExtent, RegionPolynomials, as_regions,
                                    dilate)
from tritools.solve.report import region_extent


# ----------------------------------------------------------------------------- the docs' Disc, as shown there
@dataclass(frozen=True, eq=False)
class Disc(tritools.Region):
    cx: float
    cy: float
    radius: float
    kind = "disc"

    @property
    def n_aux(self):
        return 2

    def polynomials(self, x, y):
        f = (x[0] - y[0]) ** 2 + (x[1] - y[1]) ** 2
        h = self.radius**2 - (y[0] - self.cx) ** 2 - (y[1] - self.cy) ** 2
        return RegionPolynomials(f, eq=(), ineq=(h,))

    def closest_point(self, points):
        P = np.asarray(points, dtype=float)
        d = P - self.center
        norm = np.linalg.norm(d, axis=-1, keepdims=True)
        outside = norm > self.radius
        return np.where(outside, self.center + d * self.radius / np.where(outside, norm, 1.0), P)

    @property
    def center(self):
        return np.array([self.cx, self.cy])

    def similarity(self, scale, shift):
        return Disc(scale * (self.cx - shift[0]), scale * (self.cy - shift[1]), scale * self.radius)

    def extent(self):               # y is a point of the disc: |y_k| <= ||y|| <= ||c|| + r
        rho = math.hypot(self.cx, self.cy) + self.radius
        return RegionExtent.outward(rho, rho)

    def conic_form(self):           # (y - c)' D^-1 (y - c) <= 1 with D = r^2 I
        r2 = self.radius**2
        return ConicForm(ConeKind.ELLIPSE, self.center, D=r2 * np.eye(2), Dinv=np.eye(2) / r2)

    @property
    def disc_radius(self):
        return self.radius


# ----------------------------------------------------------------------------- the same disc, without extent()
@dataclass(frozen=True, eq=False)
class BareDisc(tritools.Region):
    """The docs' Disc with only the model declared (no extent, conic form, disc radius)."""
    cx: float
    cy: float
    radius: float
    kind = "test_bare_disc"

    @property
    def n_aux(self):
        return 2

    def polynomials(self, x, y):
        f = (x[0] - y[0]) ** 2 + (x[1] - y[1]) ** 2
        h = self.radius**2 - (y[0] - self.cx) ** 2 - (y[1] - self.cy) ** 2
        return RegionPolynomials(f, eq=(), ineq=(h,))

    def closest_point(self, points):
        P = np.asarray(points, dtype=float)
        d = P - self.center
        norm = np.linalg.norm(d, axis=-1, keepdims=True)
        outside = norm > self.radius
        return np.where(outside, self.center + d * self.radius / np.where(outside, norm, 1.0), P)

    @property
    def center(self):
        return np.array([self.cx, self.cy])

    def similarity(self, scale, shift):
        return BareDisc(scale * (self.cx - shift[0]), scale * (self.cy - shift[1]), scale * self.radius)


@pytest.fixture
def margins(monkeypatch):
    """Every rigorous_psatz_bound computed during the test: (c given, RigorousBound).  Patched wherever tritools
    imported it by name (the module that calls it may move)."""
    calls = []
    original = sospoly.analysis.rigorous_psatz_bound

    def spy(psatz, sol, c, radius, ball=None, eq_error=None):
        out = original(psatz, sol, c, radius, ball=ball, eq_error=eq_error)
        calls.append((float(c), out))
        return out

    patched = 0
    for name, mod in list(sys.modules.items()):
        if name.startswith("tritools") and getattr(mod, "rigorous_psatz_bound", None) is original:
            monkeypatch.setattr(mod, "rigorous_psatz_bound", spy)
            patched += 1
    assert patched, "no tritools module calls sospoly.analysis.rigorous_psatz_bound"
    return calls


def _pixel_frame(scale: float, shift: float):
    """(cameras, disc centre, radius, other regions) of the paper's example in an image frame x' = scale x + shift
    (the same problem: gamma' = scale gamma)."""
    cams, regs = tritools.paper_example(4)
    T = np.array([[scale, 0.0, shift], [0.0, scale, shift], [0.0, 0.0, 1.0]])
    C = np.array([T @ P for P in cams[:3]])
    others = [Point(scale * r.x + shift) for r in regs[1:3]]
    return C, scale * np.array([0.6, 0.3]) + shift, 0.15 * scale, others


def _gamma_min(C, regions, starts) -> float:
    """min gamma over Nelder-Mead runs from the given start points (an upper bound of gamma*)."""
    best = np.inf
    for X0 in starts:
        f0 = float(tritools.gamma(X0, C, regions))
        res = optimize.minimize(lambda X: tritools.gamma(X, C, regions), X0, method="Nelder-Mead",
                                options={"xatol": 1e-10 * (1 + np.max(np.abs(X0))), "fatol": 1e-13 * max(1.0, f0),
                                         "maxiter": 4000})
        best = min(best, float(res.fun))
    return best


# ----------------------------------------------------------------------------- the user region's rigour
@pytest.mark.parametrize("scale, shift", [(1.0, 0.0), (800.0, 1e5)])
def test_user_disc_gets_the_margin_of_the_equivalent_ellipse(margins, scale, shift):
    """The same data with the docs' Disc and with Ellipse(D = r^2 I): each solve charges its certificate's PSD
    defect on the same box (the extents agree), the margin is subtracted from the level, and the two certified
    intervals agree with each other and with a dense multi-start minimum of gamma (also in pixel coordinates
    around 1e5)."""
    C, c, r, others = _pixel_frame(scale, shift)
    out = {}
    for name, region in (("disc", Disc(c[0], c[1], r)), ("ellipse", Ellipse(c, r * r * np.eye(2)))):
        margins.clear()
        res = tritools.triangulate(C, [region, *others], "corollary1", path="sdp")    # (the ellipse verifies too)
        assert res.optimal and res.certified_by == "sdp", res
        assert len(margins) >= 1, f"{name}: certified without the rigorous margin"
        c_level, rb = margins[-1]
        assert rb.margin > 0 and rb.lower_bound == c_level - rb.margin
        out[name] = (res, rb)
    (rd, bd), (re_, be) = out["disc"], out["ellipse"]
    assert bd.radius == pytest.approx(be.radius, rel=1e-12)            # the same box for the margin
    assert 1e-3 < bd.margin / be.margin < 1e3                          # the same order: both charge a defect
    tol = 1e-7 * scale
    assert rd.gamma_lb == pytest.approx(re_.gamma_lb, abs=tol) and rd.gamma_ub == pytest.approx(re_.gamma_ub, abs=tol)
    ref = _gamma_min(C, [Ellipse(c, r * r * np.eye(2)), *others], [rd.X, re_.X, rd.X * 1.01])
    for res in (rd, re_):
        assert res.gamma_lb <= ref * (1 + 1e-9) and res.gamma_ub == pytest.approx(ref, rel=1e-6)


def test_user_region_without_extent_is_refused_not_certified(margins):
    """The Disc without extent(): triangulate raises a TypeError naming it (no result, certified or not);
    triangulate_many reports the item invalid_input with that message; gamma still works."""
    cams, regs = tritools.paper_example(4)
    bare = BareDisc(0.6, 0.3, 0.15)
    with pytest.raises(TypeError, match=r"BareDisc does not declare extent\(\)"):
        tritools.triangulate(cams[:3], [bare, regs[1], regs[2]], "corollary1")
    with pytest.raises(TypeError, match=r"extent\(\)"):
        tritools.triangulate(cams[:3], [bare, regs[1], regs[2]])                # the default plan too
    assert margins == []                                                         # never got to a bound
    [item] = tritools.triangulate_many([(cams[:3], [bare, regs[1], regs[2]])])
    assert item.status == tritools.Status.INVALID_INPUT and not item.optimal and "extent()" in item.message
    X = np.array([0.3, -0.2, 0.5])
    assert tritools.gamma(X, cams[:3], [bare, regs[1], regs[2]]) == pytest.approx(
        tritools.gamma(X, cams[:3], [Ellipse([0.6, 0.3], 0.0225 * np.eye(2)), regs[1], regs[2]]), rel=1e-12)


def test_an_extent_or_conic_form_of_the_wrong_type_is_refused():
    @dataclass(frozen=True, eq=False)
    class TupleExtent(Disc):
        kind = "test_tuple_extent"

        def extent(self):
            return (1.0, 1.0)

    with pytest.raises(TypeError, match=r"TupleExtent.extent\(\) must return a RegionExtent, got tuple"):
        region_extent(TupleExtent(0.0, 0.0, 1.0))

    @dataclass(frozen=True, eq=False)
    class DictForm(Disc):
        kind = "test_dict_form"

        def conic_form(self):
            return {"kind": "ellipse"}

    with pytest.raises(TypeError, match=r"DictForm.conic_form\(\) must return a ConicForm, got dict"):
        dilate(DictForm(0.0, 0.0, 1.0), 0.5)


def test_region_extent_checks_its_fields():
    assert RegionExtent(np.float32(2.0), 1).radius == 2.0
    with pytest.raises(ValueError, match="RegionExtent.radius must be finite and >= 0"):
        RegionExtent(-1.0, 0.0)
    with pytest.raises(ValueError, match="RegionExtent.aux must be finite"):
        RegionExtent(1.0, np.inf)
    with pytest.raises(ValueError, match="RegionExtent.radius must not be NaN"):
        RegionExtent(np.nan, 0.0)
    with pytest.raises(TypeError, match="RegionExtent.aux must be a real number, got str"):
        RegionExtent(1.0, "1")
    with pytest.raises(TypeError, match="RegionExtent.radius must be a real number, got bool"):
        RegionExtent(True, 1.0)


# ----------------------------------------------------------------------------- the fast paths, by declaration
def test_user_disc_takes_the_disc_fast_path_like_the_ellipse():
    """All views Discs (disc_radius declared): the vectorised disc verification certifies, with the numbers of
    the same data given as Ellipses."""
    cams, _ = tritools.paper_example(4)
    X = np.array([0.2, -0.1, 0.4])
    centres = [tritools.project(X, P) + d for P, d in zip(cams, [[0.3, 0.1], [-0.2, 0.2], [0.1, -0.3], [0, 0.25]])]
    mine = tritools.triangulate(cams, [Disc(p[0], p[1], 0.1) for p in centres], "corollary1")
    ref = tritools.triangulate(cams, [Ellipse(p, 0.01 * np.eye(2)) for p in centres], "corollary1")
    assert ref.certified_by == "verification" and mine.certified_by == "verification"
    assert mine.gamma_lb == pytest.approx(ref.gamma_lb, rel=1e-12) and mine.gamma_ub == pytest.approx(ref.gamma_ub,
                                                                                                      rel=1e-12)
    assert np.allclose(mine.X, ref.X, rtol=1e-10, atol=1e-12)


def test_a_user_point_region_takes_the_point_fast_path():
    """is_point declared (with extent): the vectorised point verification, as for Point."""

    @dataclass(frozen=True, eq=False)
    class Dot(tritools.Region):
        px: float
        py: float
        kind = "test_dot"
        n_aux = 0

        def polynomials(self, x, y):
            return RegionPolynomials((x[0] - self.px) ** 2 + (x[1] - self.py) ** 2)

        def closest_point(self, points):
            return np.broadcast_to(self.center, np.shape(points)).copy()

        @property
        def center(self):
            return np.array([self.px, self.py])

        def similarity(self, scale, shift):
            return Dot(scale * (self.px - shift[0]), scale * (self.py - shift[1]))

        def extent(self):
            return RegionExtent.outward(math.hypot(self.px, self.py), 0.0)

        @property
        def is_point(self):
            return True

    cams, _ = tritools.paper_example(4)
    X = np.array([0.2, -0.1, 0.4])
    x = [tritools.project(X, P) + d for P, d in zip(cams, [[3e-3, 1e-3], [-2e-3, 2e-3], [1e-3, -3e-3], [0, 2e-3]])]
    mine = tritools.triangulate(cams, [Dot(*p) for p in x])
    ref = tritools.triangulate(cams, [Point(p) for p in x])
    assert ref.certified_by == "verification" and mine.certified_by == "verification"
    assert mine.gamma_lb == ref.gamma_lb and mine.gamma_ub == ref.gamma_ub and np.array_equal(mine.X, ref.X)


# ----------------------------------------------------------------------------- the built-ins' declarations
def _region_points(region, rng, n=4000):
    """Points of the region: closest points of random points near and far (boundary), and the centre."""
    c = np.asarray(region.center, float)
    P = c + rng.normal(size=(n, 2)) * rng.choice([0.1, 1.0, 10.0, 1e3], size=(n, 1))
    return np.vstack([np.atleast_2d(region.closest_point(P)), c[None]])


BUILTINS = {
    "point": Point([3.0, -4.0]),
    "segment": Segment([3.0, -4.0], [2.0, 1.0]),
    "zero_segment": Segment([3.0, -4.0], [0.0, 0.0]),
    "polytope": Polytope([[1.0, 0.0], [0.0, 2.0], [1.0, 1.0]], [-3.0, 8.0, 0.5]),
    "box": Polytope.box([1e5, -2e5], [3.0, 0.5]),
    "border": EllipseBorder([3.0, -4.0], [[9.0, 2.0], [2.0, 4.0]]),
    "ellipse": Ellipse([-1e4, 2.0], [[9.0, -2.0], [-2.0, 4.0]]),
    "disc": Disc(3.0, -4.0, 2.5),
}


@pytest.mark.parametrize("name", sorted(BUILTINS))
def test_extents_bound_the_region_and_its_auxiliaries(name):
    """||p|| <= radius for sampled region points p, before and after a similarity; the auxiliaries: the segment
    parameter is in [-1, 1] (aux = 1), the others' auxiliary is a region point (|p_k| <= aux)."""
    rng = np.random.default_rng(7)
    region = BUILTINS[name]
    for R in (region, region.similarity(0.01, region.center + [1.0, -2.0])):
        ext = R.extent()
        pts = _region_points(R, rng)
        assert np.max(np.hypot(pts[:, 0], pts[:, 1])) <= ext.radius
        assert ext.radius <= np.max(np.hypot(pts[:, 0], pts[:, 1])) + 2.0 * np.max(np.abs(pts - R.center)) + 1e-9
        if isinstance(R, Segment):
            assert ext.aux >= 1.0
        elif R.n_aux:
            assert np.max(np.abs(pts)) <= ext.aux
        else:
            assert ext.aux == 0.0


def test_conic_forms_and_flags_of_the_builtins():
    kinds = {k: BUILTINS[k].conic_form() for k in BUILTINS}
    assert {k: f.kind for k, f in kinds.items()} == {
        "point": ConeKind.POINT, "segment": ConeKind.SEGMENT, "zero_segment": ConeKind.POINT,
        "polytope": ConeKind.POLYTOPE, "box": ConeKind.POLYTOPE, "border": ConeKind.ELLIPSE,
        "ellipse": ConeKind.ELLIPSE, "disc": ConeKind.ELLIPSE}
    assert [k for k, f in kinds.items() if f.convexified] == ["border"]
    assert np.allclose(kinds["ellipse"].D @ kinds["ellipse"].Dinv, np.eye(2))
    assert [k for k in BUILTINS if BUILTINS[k].is_point] == ["point"]
    assert {k: BUILTINS[k].disc_radius for k in BUILTINS if BUILTINS[k].disc_radius is not None} == {"disc": 2.5}
    assert Ellipse([0, 0], 4.0 * np.eye(2)).disc_radius == 2.0 and EllipseBorder([0, 0], 4.0 * np.eye(2)).disc_radius \
        is None
    with pytest.raises(ValueError, match="ConicForm.direction of a segment must have shape"):
        ConicForm(ConeKind.SEGMENT, [0.0, 0.0])
    with pytest.raises(ValueError, match="ConicForm.kind must be one of"):
        ConicForm("cone", [0.0, 0.0])


def test_dilation_of_a_user_region_is_that_of_its_conic_form():
    """dilate reads the conic form: the Disc dilates exactly as the equivalent Ellipse, and holds the
    r-neighbourhood (sampled)."""
    rng = np.random.default_rng(3)
    d, e = Disc(3.0, -4.0, 2.5), Ellipse([3.0, -4.0], 6.25 * np.eye(2))
    bd, be = dilate(d, 0.7), dilate(e, 0.7)
    assert np.array_equal(bd.D, be.D) and np.array_equal(bd.center, be.center)
    P = d.center + rng.uniform(-4, 4, size=(20000, 2))
    near = P[np.hypot(*(P - d.center).T) <= 2.5 + 0.7]
    assert len(near) > 1000 and np.all(bd.distance(near) == 0.0)


def test_uncertainty_of_a_user_region_and_the_refusal_without_conic_form():
    cams, regs = tritools.paper_example(4)
    mine = tritools.uncertainty(cams[:3], [Disc(0.6, 0.3, 0.15), regs[1], regs[2]])
    ref = tritools.uncertainty(cams[:3], [Ellipse([0.6, 0.3], 0.0225 * np.eye(2)), regs[1], regs[2]])
    assert mine.status == ref.status and np.allclose(mine.lo, ref.lo, rtol=1e-9) and np.allclose(mine.hi, ref.hi,
                                                                                                 rtol=1e-9)
    with pytest.raises(TypeError, match=r"BareDisc does not declare conic_form\(\)"):
        tritools.uncertainty(cams[:3], [BareDisc(0.6, 0.3, 0.15), regs[1], regs[2]])


def test_nothing_outside_the_regions_package_tests_region_classes():
    """The solvers ask the region: no isinstance / type() test on a built-in region class in tritools outside
    tritools/model/regions (the plot's singledispatch registrations are drawing rules, not tests)."""
    import ast
    import pathlib

    root = pathlib.Path(tritools.__file__).parent
    names = {"Point", "Segment", "Polytope", "Ellipse", "EllipseBorder"}
    found = []
    for path in root.rglob("*.py"):
        if "model/regions" in path.as_posix():
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call) and getattr(node.func, "id", "") in ("isinstance", "type"):
                used = {getattr(x, "id", getattr(x, "attr", "")) for arg in node.args for x in ast.walk(arg)}
                if used & names:
                    found.append(f"{path.relative_to(root)}:{node.lineno}")
            if isinstance(node, ast.Compare) and any(isinstance(op, (ast.Is, ast.IsNot)) for op in node.ops):
                used = {getattr(x, "id", "") for x in ast.walk(node)}
                if used & names and any(getattr(x.func, "id", "") == "type" for x in ast.walk(node)
                                        if isinstance(x, ast.Call)):
                    found.append(f"{path.relative_to(root)}:{node.lineno}")
    assert found == []


def test_as_regions_keeps_user_regions():
    d = Disc(1.0, 2.0, 3.0)
    assert as_regions([d, [0.0, 0.0]])[0] is d and isinstance(as_regions([d])[0], Region)
