"""Bounds of a rounded frame next to very oblique rays (review 24a F2/F3).

A view whose observation lies 1e9..1e11 px off-axis sees its point along a ray with sec theta ~ 1e7..1e9 (theta the
angle to the principal axis): the depth of a point on that ray, and with it the projection, moves by ~sec theta times
any relative perturbation of the camera.  The normalised frame is the caller's problem up to a few roundings per
entry, so a bound computed there held the caller's float problem only to |x_i| sec theta_i units of round-off, not
|x_i|: the reviewer found float points whose exact (rational) cost lies below reported lower bounds -- 0.51 px under
a certified TLS gamma_LB of 13.5 px, 3.3 px under a certified 654 px in a world moved by 5e7.  gamma_LB is now lowered
by the obliquity too (:func:`tritools.model.magnitude.magnitudes` with the cameras).
"""
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

import tritools
from tritools.model.normalize import magnitudes
from tritools.model.oblique import obliquities

DATA = Path(__file__).parent / "data" / "oblique_views.npz"


def _exact_gamma(P, x, X, c):
    """gamma_TLS (c = inf: gamma) of the float data at the float X, the distances in rational arithmetic."""
    Xf = [Fraction(float(v)) for v in X] + [Fraction(1)]
    total = Fraction(0)
    for Pi, xi in zip(P, x):
        h = [sum(Fraction(float(Pi[r, k])) * Xf[k] for k in range(4)) for r in range(3)]
        d2 = (h[0] / h[2] - Fraction(float(xi[0]))) ** 2 + (h[1] / h[2] - Fraction(float(xi[1]))) ** 2
        total += d2 if not np.isfinite(c) else min(d2, Fraction(float(c)) ** 2)
    return float(total / (2 * len(P))) ** 0.5


@pytest.mark.parametrize("k", range(5))
def test_no_lower_bound_above_a_float_point_next_to_an_oblique_ray(k):
    d = np.load(DATA)
    P, x, c, X = d[f"P_{k}"], d[f"x_{k}"], float(d[f"c_{k}"]), d[f"X_{k}"]
    g = _exact_gamma(P, x, X, c)
    r = tritools.triangulate(P, x, robust=c) if np.isfinite(c) else tritools.triangulate(P, x)
    assert r.gamma_lb is None or r.gamma_lb <= g
    assert not r.optimal or r.gamma_lb <= g
    if np.isfinite(c):                       # the batch paths take the same rule
        for b in (tritools.triangulate_many([(P, x)], robust=c)[0],):
            assert b.gamma_lb is None or b.gamma_lb <= g
        pts = tritools.triangulate_points(P, x[None], robust=c)
        assert not pts.optimal[0] or pts.gamma_lb[0] <= g
    else:
        b = tritools.triangulate_many([(P, x)])[0]
        assert b.gamma_lb is None or b.gamma_lb <= g


def test_obliquity_of_a_pinhole_camera():
    K = np.array([[1000.0, 0, 320], [0, 1000, 240], [0, 0, 1]])
    R = np.linalg.qr(np.random.default_rng(0).normal(size=(3, 3)))[0]
    R *= np.linalg.det(R)
    P = K @ np.hstack([R, [[0.3], [-2.0], [5.0]]])
    x = np.array([[320.0, 240.0], [1320.0, 240.0], [320.0, 240.0 + 1e9]])
    sec = obliquities(np.broadcast_to(P, (3, 3, 4)), x)
    np.testing.assert_allclose(sec, [1.0, np.sqrt(2.0), np.hypot(1.0, 1e6)], rtol=1e-9)
    # the camera's scale, an image similarity moving the point with it, a world similarity: the same angle
    S = np.array([[2.0, 0, 17], [0, 2, -5], [0, 0, 1]])
    H = np.diag([3.0, 3.0, 3.0, 1.0])
    H[:3, 3] = [1e6, -2e6, 7.0]
    Pt = -7.5 * S @ P @ H
    xt = x * 2.0 + [17.0, -5.0]
    np.testing.assert_allclose(obliquities(np.broadcast_to(Pt, (3, 3, 4)), xt), sec, rtol=1e-6)
    # an affine camera (no depth): 1
    A = np.array([[1.0, 0, 0, 3], [0, 1, 0, 4], [0, 0, 0, 1]])
    assert obliquities(A[None], np.array([[1e9, 0.0]]))[0] == 1.0


def test_magnitudes_with_cameras_count_the_obliquity():
    K = np.array([[1000.0, 0, 0], [0, 1000, 0], [0, 0, 1]])
    P = K @ np.hstack([np.eye(3), np.zeros((3, 1))])
    x = np.array([[[10.0, 20.0], [1e9, 0.0]]])
    C = np.broadcast_to(P, (1, 2, 3, 4))
    assert magnitudes(x)[0] == 1e9
    assert magnitudes(x, C)[0] == pytest.approx(1e9 * np.hypot(1.0, 1e6), rel=1e-9)
    assert magnitudes(np.array([[[10.0, 20.0], [30.0, 0.0]]]), C)[0] == pytest.approx(30.0 * np.hypot(1, 0.03))


def test_the_scalar_obliquity_is_the_vectorised_one_bit_for_bit():
    """:func:`obliquity_one` (one problem's magnitude) against :func:`obliquities`, over random cameras of every scale,
    points on and far off the axis, affine cameras and cameras whose centre is at infinity."""
    from tritools.model.cameras import power2_scale
    from tritools.model.magnitude import _obliquities_one
    from tritools.model.oblique import obliquity_one

    rng = np.random.default_rng(5)
    for _ in range(200):
        N = int(rng.integers(1, 7))
        C = rng.normal(size=(N, 3, 4)) * 10.0 ** rng.uniform(-6, 8)
        x = rng.normal(size=(N, 2)) * 10.0 ** rng.uniform(-3, 12, size=(N, 1))
        if rng.random() < 0.2:
            C[0, 2, :3] = 0.0                                      # affine: no depth
        if rng.random() < 0.2:
            C[-1, 2, :3] = C[-1, 0, :3] * 0.5 + C[-1, 1, :3] * 0.25   # a centre at infinity (a dyadic combination)
        vec = obliquities(C, x)
        one = [obliquity_one(P, p) for P, p in zip((C / power2_scale(C, (1, 2))).tolist(), x.tolist())]
        np.testing.assert_array_equal(vec, np.array(one))
        np.testing.assert_array_equal(vec, np.array(_obliquities_one(C, x)))
        assert magnitudes(x[None], C[None])[0] == magnitudes(np.concatenate([x[None], x[None]]),
                                                            np.concatenate([C[None], C[None]]))[0]


def test_an_l2_certificate_whose_bound_exceeded_its_own_estimate_s_exact_cost():
    """Review 24c k = 191: three views, one observed 2.7e6 px off-axis; before the obliquity term the L2 call was
    ``optimal`` with gamma_LB = gamma_UB = 0.274201525684449 while the exact cost at its own float X is
    0.2742015250090409 (so gamma* is lower).  Every path's gamma_LB is now at most the exact cost at its X."""
    d = np.load(Path(__file__).parent / "data" / "oblique_l2_certified.npz")
    P, x = d["P"], d["x"]
    for r in (tritools.triangulate(P, x), tritools.triangulate_many([(P, x)])[0]):
        g = _exact_gamma(P, x, np.asarray(r.X, float), np.inf)
        assert r.gamma_ub >= g
        assert r.gamma_lb is None or r.gamma_lb <= g
    pts = tritools.triangulate_points(P, x[None])
    assert pts.gamma_lb[0] <= _exact_gamma(P, x, pts.X[0], np.inf)
