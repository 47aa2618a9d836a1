"""Caller's-frame projections in georeferenced worlds: a view is undefined only where its compensated denominator
is at round-off (review 23a F2).

``tritools.model.frame.project_world`` recomputes every view that cancels by the compensated dot product, accurate to
~eps^2 of sum |p3_k X~_k|; the plain dot product's rule (1e-10 of that sum) called views whose depth is 55-1e5 times
its round-off undefined, so robust results reported ``residuals[i] = inf``, ``inliers[i] = False`` and counted c_i^2
in gamma_UB although d_i(X) < c_i.  The reviewer's three tracks (worlds moved by 1e6-1e7; X near a camera centre in
two, not in the third) against exact rational evaluation at the reported X.
"""
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

import tritools
from tritools.model.frame import COMPENSATED_DENOM_RTOL, project_world_one, project_world_views

DATA = Path(__file__).parent / "data" / "georef_defined_views.npz"


def _exact_distances(P, x, X):
    Xf = [Fraction(float(v)) for v in X] + [Fraction(1)]
    out = []
    for Pi, xi in zip(P, x):
        h = [sum(Fraction(float(Pi[r, k])) * Xf[k] for k in range(4)) for r in range(3)]
        dx, dy = h[0] / h[2] - Fraction(float(xi[0])), h[1] / h[2] - Fraction(float(xi[1]))
        out.append(float(dx * dx + dy * dy) ** 0.5)
    return np.array(out)


@pytest.mark.parametrize("tag", ["a", "b", "c"])
def test_residuals_inliers_and_gamma_ub_are_those_of_the_reported_x(tag):
    d = np.load(DATA)
    P, x, c = d[f"P_{tag}"], d[f"x_{tag}"], float(d[f"c_{tag}"])
    r = tritools.triangulate(P, x, robust=c)
    X = np.asarray(r.X, float)
    exact = _exact_distances(P, x, X)
    res = np.asarray(r.residuals, float)
    assert np.all(np.isfinite(res))
    np.testing.assert_allclose(res, exact, rtol=1e-9, atol=1e-9)
    np.testing.assert_array_equal(r.inliers, exact < c)
    g_tls = float(np.sqrt(np.sum(np.minimum(exact, c) ** 2) / (2 * len(P))))
    assert g_tls * (1 - 1e-12) <= r.gamma_ub <= g_tls * (1 + 1e-8)        # an upper bound, the value at X
    assert r.gamma_lb is None or r.gamma_lb <= r.gamma_ub


def test_the_scalar_twin_applies_the_same_rule():
    d = np.load(DATA)
    P = d["P_c"]
    X = np.asarray(tritools.triangulate(P, d["x_c"], robust=float(d["c_c"])).X, float)
    u, _, defined = project_world_views(P[None], X[None])
    u1, defined1 = project_world_one(P.tolist(), X.tolist())
    assert defined[0].all() and all(defined1)
    np.testing.assert_array_equal(u[0], np.array(u1))



def test_a_point_exactly_at_a_camera_centre_stays_undefined_and_one_ulp_off_is_defined():
    """A georeferenced camera K [I | -C] with an integer centre C: at X = C the denominator is 0 (undefined in both
    twins); one ulp away along the optical axis it is ~1e-16 of the magnitude, far above COMPENSATED_DENOM_RTOL, and the
    projection is that of the float point (the principal point), as exact arithmetic has it."""
    C = np.array([4_000_001.0, -2_500_003.0, 1_200_007.0])
    K = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
    P = np.array([K @ np.hstack([np.eye(3), -C[:, None]]), K @ np.hstack([np.eye(3), -(C + 5.0)[:, None]])])
    for X, want in ((C, False), (np.array([C[0], C[1], np.nextafter(C[2], np.inf)]), True)):
        _, _, defined = project_world_views(P[None], X[None])
        u1, defined1 = project_world_one(P.tolist(), X.tolist())
        assert bool(defined[0, 0]) is want and defined1[0] is want
        if want:
            h = P[0] @ np.append(X, 1.0)
            assert abs(h[2]) > COMPENSATED_DENOM_RTOL * float(np.abs(P[0, 2]) @ np.abs(np.append(X, 1.0)))
            np.testing.assert_allclose(u1[0], (320.0, 240.0), rtol=1e-12)      # the principal point
