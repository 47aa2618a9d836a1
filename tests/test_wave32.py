"""Wave 32: certificates invariant under a rescaling of the images (review 31b F10).

The coordinates' resolution and the round-off lowering of gamma_LB took a magnitude floored at 1 px, so below pixel
scale ~1e-9 a gap of ~7e-15 px (absolute) let results be certified at relative gaps up to 1e-3 (L2 and TLS decided
differently at 1e-12).  The floor is now relative to the views' focal length (``magnitude.pixel_floors``): images
scaled by s = 2^k (exact in floating point, so the scaled problem's optimum is exactly s times the original's)
give the same decisions and the same relative gaps at every scale.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

import tritools
from tritools.scene import random_scene

SCALES = [2.0 ** k for k in (-40, -30, -20, 0, 20)]


def _look_at(centre, f=800.0):
    z = -centre / np.linalg.norm(centre)
    up = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(up, z)
    x /= np.linalg.norm(x)
    R = np.stack([x, np.cross(z, x), z])
    return np.diag([f, f, 1.0]) @ np.hstack([R, (-R @ centre)[:, None]])


def _disc_scene():
    """4 views of 1 px discs, 1 px noise, one view 50 px off (review 31b's F10 case)."""
    rng = np.random.default_rng(0)
    cams = np.array([_look_at(rng.normal(size=3) * 2 + np.array([0.0, 0.0, 8.0])) for _ in range(4)])
    X = rng.normal(size=3) * 0.3
    xs = np.array([(P @ np.append(X, 1.0))[:2] / (P @ np.append(X, 1.0))[2] for P in cams]) + rng.normal(size=(4, 2))
    xs[2] += [40.0, -30.0]
    return cams, xs


def _disc_f(C, xs, radius, X, c=None):
    """sum_i min(d_i^2, c^2), d_i the distance of the projection to disc i: evaluated here, not by the library."""
    h = C @ np.append(X, 1.0)
    d = np.maximum(0.0, np.linalg.norm(h[:, :2] / h[:, 2:] - xs, axis=1) - radius)
    return float(np.sum(d * d if c is None else np.minimum(d * d, c * c)))


@pytest.mark.parametrize("robust", [False, True])
def test_disc_certificates_are_the_same_at_every_image_scale(robust):
    cams, xs = _disc_scene()
    c = 5.0 if robust else None
    base = tritools.triangulate(cams, [tritools.Ellipse.circle(x, 1.0) for x in xs], robust=c)
    assert base.optimal, base.message
    attained = math.sqrt(_disc_f(cams, xs, 1.0, base.X, c) / 8)       # a value the problem attains, at s = 1
    for s in SCALES:
        S = np.diag([s, s, 1.0])
        r = tritools.triangulate(S @ cams, [tritools.Ellipse.circle(x * s, s) for x in xs],
                                 robust=None if c is None else c * s)
        assert r.optimal, (s, r.message)
        assert 1.0 - (r.gamma_lb / r.gamma_ub) ** 2 <= 1e-7, s        # the tolerance's relative scale, not 1 px
        assert r.gamma_lb / s <= attained * (1 + 1e-12), s             # a valid bound of the scaled problem
        assert r.gamma_ub / s == pytest.approx(base.gamma_ub, rel=1e-9)
        if robust:
            np.testing.assert_array_equal(r.inliers, base.inliers)


def test_point_batches_decide_alike_at_every_image_scale():
    sc = random_scene(5, 12, noise_px=1.0, seed=32)
    C, x = np.asarray(sc.cameras), np.asarray(sc.points2d)
    base = tritools.triangulate_many([(C, x[j]) for j in range(12)], progress=False)
    assert all(r.optimal for r in base)
    for s in SCALES:
        S = np.diag([s, s, 1.0])
        many = tritools.triangulate_many([(S @ C, x[j] * s) for j in range(12)], progress=False)
        single = tritools.triangulate(S @ C, x[3] * s)
        for r, b in zip(list(many) + [single], list(base) + [base[3]]):
            assert r.optimal, (s, r.message)
            assert 1.0 - (r.gamma_lb / r.gamma_ub) ** 2 <= 1e-7, s
            assert r.gamma_ub / s == pytest.approx(b.gamma_ub, rel=1e-9)


def test_pixel_floor_is_relative_to_the_focal_length():
    from tritools.model.magnitude import PIXEL_FLOOR_REL, pixel_floors

    cams, xs = _disc_scene()
    f1 = float(pixel_floors(cams[None], xs[None])[0])
    assert 0.5 < f1 / (800 * PIXEL_FLOOR_REL) < 2.0                  # ~1 px at f = 800 px, as the old floor
    S = np.diag([1e-9, 1e-9, 1.0])
    assert float(pixel_floors((S @ cams)[None], 1e-9 * xs[None])[0]) == pytest.approx(1e-9 * f1, rel=1e-12)
    affine = np.zeros((1, 2, 3, 4))
    affine[..., 0, 0] = affine[..., 1, 1] = 1.0                         # no depth direction: no pixel scale
    assert float(pixel_floors(affine, np.zeros((1, 2, 2)))[0]) == 1.0
    assert pixel_floors(medians=float("nan")) == 1.0


def test_no_certificate_with_a_gap_beyond_the_tolerance_far_below_pixel_scale():
    """At pixel scale ~1e-15 the old floor certified every point with gamma_LB = 0 < gamma_UB (a 100 % gap): the
    cameras' rows are then too unbalanced for their centres, and a result must say so rather than certify."""
    sc = random_scene(5, 12, noise_px=1.0, seed=32)
    C, x = np.asarray(sc.cameras), np.asarray(sc.points2d)
    for k in (-50, -45):
        S = np.diag([2.0 ** k, 2.0 ** k, 1.0])
        for r in tritools.triangulate_many([(S @ C, x[j] * 2.0 ** k) for j in range(3)], progress=False):
            if r.optimal:
                assert 1.0 - (r.gamma_lb / r.gamma_ub) ** 2 <= 1e-5, (k, r.gamma_lb, r.gamma_ub)


def test_minimize_reports_a_search_the_time_limit_cut_as_time_limit():
    """Review 32b L4: chained singular (a sum of squares, minimum 0) under a 4 s limit returned `unproven_bound` at
    3.7 s, its last step stopped by the limit; the docs promise `time_limit` with the best bounds found."""
    import sospoly as sp

    v = sp.variables("v", n=4)
    f = (v[0] + 10 * v[1]) ** 2 + 5 * (v[2] - v[3]) ** 2 + (v[1] - 2 * v[2]) ** 4 + 10 * (v[0] - 10 * v[3]) ** 4
    r = sp.minimize(f, budget=sp.Budget(time_limit=4.0))
    assert r.lower_bound is None or r.lower_bound <= 0.0
    if not r.optimal and any(a.status == "time_limit" for a in r.attempts):
        assert r.status == sp.SolveStatus.TIME_LIMIT, (r.status, [a.status for a in r.attempts])
