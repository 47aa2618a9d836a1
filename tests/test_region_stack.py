"""RegionStack (tritools.model.regions.stack): one closest point per view, stacked by region kind, equal bit for bit
to each region's own single-point ``closest_point`` / ``distance``; and the callers that use it (the local
refinement's residuals, gamma of one point, the point report) give the numbers of the loop over the views."""
from __future__ import annotations

import numpy as np
import pytest

from tritools.model import refine
from tritools.model.geometry import gamma_validated, project_homogeneous
from tritools.model.regions import (Ellipse, EllipseBorder, Point, Polytope, Region, RegionStack, Segment,
                                    as_points)
from tritools.scene import uncertain_problem
from tritools.solve.report import point_report


class _Shifted(Point):
    """A user region class the stack does not know: its own closest_point is used."""

    def closest_point(self, points):
        P, single = as_points(points)
        C = np.broadcast_to(self.x + 1.0, P.shape).copy()
        return C[0] if single else C


def _regions(rng, scale: float) -> list[Region]:
    c = lambda: rng.normal(size=2) * scale          # noqa: E731
    out = [Point(c()), Segment(c(), rng.normal(size=2) * scale * 0.01), Segment(c(), [0.0, 0.0]),
           Segment(c(), [scale * 1e-3, 0.0]), EllipseBorder(c(), np.diag([4.0, 1.0]) * (scale * 1e-3) ** 2),
           EllipseBorder.circle(c(), scale * 1e-3),
           Ellipse(c(), np.array([[3.0, 1.0], [1.0, 2.0]]) * (scale * 1e-3) ** 2),
           Ellipse(c(), np.eye(2) * (scale * 1e-3) ** 2), Polytope.box(c(), [scale * 1e-3, scale * 2e-3]),
           _Shifted(c())]
    rng.shuffle(out)
    return out


@pytest.mark.parametrize("scale", [1e-3, 1.0, 1e3, 1e6])
def test_closest_points_and_distances_are_the_regions_own_bit_for_bit(scale):
    rng = np.random.default_rng(int(np.log10(scale)) + 10)
    for _ in range(30):
        regions = _regions(rng, scale)
        stack = RegionStack(regions)
        centres = np.array([r.center for r in regions])
        for spread in (0.0, 1e-4, 1e-3, 1e-2, 1.0):         # on the centre, inside the uncertain regions, far
            U = centres + rng.normal(size=centres.shape) * spread * scale
            U[0] = centres[0]
            want = np.array([r.closest_point(u) for r, u in zip(regions, U)])
            assert np.array_equal(stack.closest(U), want)
            assert np.array_equal(stack.distances(U), np.array([r.distance(u) for r, u in zip(regions, U)]))


def test_points_on_an_axis_and_inside_filled_ellipses():
    e = Ellipse([10.0, -5.0], np.diag([9.0, 1.0]))
    b = EllipseBorder([10.0, -5.0], np.diag([9.0, 1.0]))
    regions = [e, b, e, b, e, b]
    U = np.array([[10.0, -5.0], [10.0, -5.0], [11.0, -5.0], [10.0, -3.0], [20.0, -5.0], [12.0, -5.0]])
    stack = RegionStack(regions)
    assert np.array_equal(stack.closest(U), np.array([r.closest_point(u) for r, u in zip(regions, U)]))
    assert stack.distances(U)[0] == 0.0 and stack.distances(U)[2] == 0.0      # inside the filled ellipse


def test_bad_points_are_refused_like_the_regions():
    stack = RegionStack([Point([0.0, 0.0]), Segment([1.0, 1.0], [1.0, 0.0])])
    with pytest.raises(ValueError, match="finite"):
        stack.closest(np.array([[0.0, 0.0], [np.inf, 1.0]]))
    with pytest.raises(ValueError, match="finite"):
        Segment([1.0, 1.0], [1.0, 0.0]).closest_point([np.inf, 1.0])
    with pytest.raises(ValueError, match="shape"):
        stack.closest(np.zeros((3, 2)))


@pytest.mark.parametrize("seed", range(6))
def test_gamma_of_one_point_and_the_report_are_the_loop_over_the_views(seed):
    rng = np.random.default_rng(seed)
    cams, regions, X = uncertain_problem(int(rng.integers(2, 31)), seed=seed, kinds="mixed")
    for _ in range(5):
        Y = np.asarray(X, float) + rng.normal(size=3) * 0.05
        Xh = np.append(Y, 1.0)[None]
        total = np.zeros(1)                       # the former loop of gamma_validated for one point
        for P, R in zip(cams, regions):
            d = float(R.distance(project_homogeneous(Xh, P)[0]))
            total[0] += d * d
        assert gamma_validated(Y[None], cams, regions)[0] == np.sqrt(total / (2 * len(cams)))[0]
        u = np.array([project_homogeneous(Xh, P)[0] for P in cams])
        rep = point_report(Y, cams, regions)
        assert np.array_equal(rep.residuals, np.array([r.distance(x) for r, x in zip(regions, u)]))


def test_the_refinement_residuals_through_the_stack_equal_the_loop():
    cams, regions, X = uncertain_problem(12, seed=3, kinds="mixed")
    cams = np.asarray(cams, float)
    fun, vectorised = refine.residual_function(cams, regions)
    assert not vectorised
    rng = np.random.default_rng(0)
    for _ in range(10):
        Y = np.asarray(X, float) + rng.normal(size=3) * 0.1
        x = (cams @ np.append(Y, 1.0))
        x = x[:, :2] / x[:, 2:]
        loop = np.concatenate([xi - r.closest_point(xi) for xi, r in zip(x, regions)])     # one view at a time
        assert np.array_equal(fun(Y), loop)


@pytest.mark.parametrize("seed", range(4))
def test_the_analytic_jacobian_matches_central_differences(seed):
    """d r / d X through RegionStack.residual_derivatives (segments, ellipse borders and filled ellipses by their
    curvature, polygons by edge / vertex) against central differences of the residuals, away from kinks."""
    rng = np.random.default_rng(seed)
    cams, regions, X = uncertain_problem(10, seed=seed, kinds="mixed")
    cams = np.asarray(cams, float)
    stack = RegionStack(regions)
    for _ in range(5):
        Y = np.asarray(X, float) + rng.normal(size=3) * 0.05
        J = refine.stacked_jacobian(Y, cams, stack)
        F = np.zeros_like(J)
        for j in range(3):
            e = np.zeros(3)
            e[j] = 1e-6
            r = refine._looped_residuals
            F[:, j] = (r(Y + e, cams, stack) - r(Y - e, cams, stack)) / 2e-6
        assert np.abs(J - F).max() <= 1e-5 * max(1.0, np.abs(F).max())


def test_the_remembered_closest_points_are_never_stale():
    regions = [Segment([0.0, 0.0], [1.0, 0.0]), EllipseBorder.circle([5.0, 5.0], 1.0), Point([1.0, 2.0])]
    stack = RegionStack(regions)
    U1 = np.array([[0.5, 1.0], [7.0, 5.0], [0.0, 0.0]])
    U2 = U1 + 0.25
    a = stack.closest(U1)
    a[:] = 99.0                                   # the caller's copy, not the remembered one
    b = stack.closest(U2)
    c = stack.closest(U1)
    assert np.array_equal(c, np.array([r.closest_point(u) for r, u in zip(regions, U1)]))
    assert np.array_equal(b, np.array([r.closest_point(u) for r, u in zip(regions, U2)]))


def test_the_local_estimate_of_mixed_regions_is_as_good_as_with_differences():
    """The analytic Jacobian steers LM to the same local minimum as scipy's forward differences did."""
    from scipy.optimize import least_squares

    for seed in range(4):
        cams, regions, X = uncertain_problem(8, seed=seed, kinds="mixed")
        cams = np.asarray(cams, float)
        f, _ = refine.residual_function(cams, regions)
        calls = []

        def fun(Y):
            calls.append(1)
            return f(Y)

        X0 = np.asarray(X, float) + 0.02
        a = least_squares(fun, X0, jac=refine.residual_jacobian(cams, regions), method="lm", xtol=1e-15, ftol=1e-15,
                          gtol=1e-15)
        n_analytic = len(calls)
        b = least_squares(fun, X0, jac="2-point", method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
        assert a.cost <= b.cost * (1 + 1e-9) + 1e-20
        assert n_analytic < len(calls) - n_analytic         # fewer evaluations of the residuals


def test_one_stack_serves_the_residuals_and_the_jacobian():
    """Review 17: residual_function and residual_jacobian each built their own stack from the list, so the
    Jacobian never found the closest points just computed; a RegionStack is now a sequence of its regions (it
    passes disc_shapes) and refine_l2 hands one stack to both."""
    from tritools.model.geometry import refine_l2

    cams, regions, X = uncertain_problem(12, seed=5, kinds="mixed")
    stack = RegionStack(regions)
    assert list(stack) == list(regions) and stack[3] is regions[3] and refine.disc_shapes(stack) is None
    calls = {"closest": 0, "memo": 0}
    real = RegionStack.closest

    def counted(self, U):
        calls["closest"] += 1
        calls["memo"] += self._memo is not None and np.array_equal(np.asarray(U, float), self._memo[0])
        return real(self, U)

    RegionStack.closest = counted
    try:
        refine_l2(np.asarray(X, float) + 0.05, np.asarray(cams, float), list(regions))
    finally:
        RegionStack.closest = real
    assert calls["memo"] >= 1
