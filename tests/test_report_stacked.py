"""The stacked report of one point (issue #22: no per-view Python loop after a time limit): the stacked projection
is the per-view projection bit for bit, the report's distances are the regions' own, and the closed-form count of
N_LMIVAR grouped by degree is the term-by-term sum."""
import math

import numpy as np
import pytest

from sospoly.algebra.basis import sigma, tau
from sospoly.analysis.complexity import n_lmivar_formula
from tritools.model.geometry import image_points, project_homogeneous, project_point_views, project_points_views, \
    project_views
from tritools.model.regions import Ellipse, Point
from tritools.solve.report import gamma_upper, point_report


def _cameras(rng, N, kind):
    C = rng.normal(size=(N, 3, 4)) * 10.0 ** rng.uniform(-5, 8)
    X = rng.normal(size=3) * 10.0 ** rng.uniform(-3, 7)
    if kind == "georeferenced":
        off = rng.normal(size=3) * 1e6
        C[:, :, 3] = -np.einsum("nij,j->ni", C[:, :, :3], off) + rng.normal(size=(N, 3))
        X = off + rng.normal(size=3)
    elif kind == "principal-plane":           # X on camera 0's principal plane in exact arithmetic (dyadic numbers
        X = rng.integers(-2 ** 20, 2 ** 20, size=3) * 2.0 ** -10     # of <= 41 bits: every product and sum exact)
        C[0, 2, :3] = rng.integers(-2 ** 10, 2 ** 10, size=3)
        C[0, 2, 3] = -C[0, 2, :3] @ X
    elif kind == "zero-camera":
        C[rng.integers(N)] = 0.0
    elif kind == "infinite-point":
        X = np.array([np.inf, 0.0, 1.0])
    return C, X


@pytest.mark.parametrize("kind", ["plain", "georeferenced", "principal-plane", "zero-camera", "infinite-point"])
def test_stacked_projection_is_the_per_view_projection(kind):
    rng = np.random.default_rng(["plain", "georeferenced", "principal-plane", "zero-camera",
                                 "infinite-point"].index(kind))
    for _ in range(300):
        C, X = _cameras(rng, int(rng.integers(1, 25)), kind)
        Xh = np.append(X, 1.0)[None]
        ref = np.vstack(project_views(Xh, C))
        assert np.array_equal(project_point_views(Xh, C), ref, equal_nan=True)
    if kind == "principal-plane":
        assert np.isinf(project_point_views(Xh, C)[0]).all()


@pytest.mark.parametrize("kind", ["plain", "georeferenced", "principal-plane", "zero-camera", "infinite-point"])
def test_stacked_projection_of_many_points_is_the_per_view_projection(kind):
    """(m, N, 2) for m points: the per-camera loop's numbers (points near, far, at infinity, NaN, behind)."""
    rng = np.random.default_rng(10 + len(kind))
    for _ in range(150):
        N, m = int(rng.integers(1, 20)), int(rng.integers(1, 9))
        C, X = _cameras(rng, N, kind)
        Xs = X + rng.normal(size=(m, 3)) * 10.0 ** rng.uniform(-8, 3, size=(m, 1))
        Xs[rng.random(m) < 0.1] = np.nan
        Xh = np.hstack([Xs, np.ones((m, 1))])
        ref = np.stack([project_homogeneous(Xh, P) for P in C], axis=1)
        got = project_points_views(Xh, C)
        assert got.shape == (m, N, 2) and np.array_equal(got, ref, equal_nan=True)
        one = np.vstack([project_homogeneous(Xh[:1], P) for P in C])     # (a batch of one: its own BLAS call)
        assert np.array_equal(project_point_views(Xh[:1], C), one, equal_nan=True)


@pytest.mark.parametrize("georeferenced", [False, True])
def test_image_points_is_the_per_camera_loop(georeferenced):
    """``image_points`` for (3,) and (m, 3) inputs: bit for bit the per-camera ``project_homogeneous`` loop."""
    from tritools.scene import random_scene

    rng = np.random.default_rng(int(georeferenced))
    for N in (1, 2, 5, 30):
        sc = random_scene(max(N, 2), 6, seed=N)
        C, X = np.asarray(sc.cameras, float)[:N], np.asarray(sc.points3d, float)
        if georeferenced:
            off = rng.normal(size=3) * 1e7
            C = C.copy()
            C[:, :, 3] -= np.einsum("nij,j->ni", C[:, :, :3], off)
            X = X + off
        C = C * 10.0 ** rng.uniform(-3, 6, size=(N, 1, 1))
        Xh = np.hstack([X, np.ones((len(X), 1))])
        ref = np.stack([project_homogeneous(Xh, P) for P in C], axis=1)
        assert np.array_equal(image_points(X, C), ref)
        one = np.stack([project_homogeneous(Xh[2:3], P) for P in C], axis=1)[0]
        assert image_points(X[2], C).shape == (N, 2) and np.array_equal(image_points(X[2], C), one)


def _looped_report(X, C, regions):
    """The report's numbers by the regions' own closest points, one view at a time (the reference)."""
    u = np.vstack(project_views(np.append(X, 1.0)[None], C))
    res = np.array([r.distance(x) if np.isfinite(x).all() else np.inf for x, r in zip(u, regions)])
    return res, np.hypot(u[:, 0], u[:, 1])


@pytest.mark.parametrize("shape", ["points", "discs", "mixed", "ellipses"])
def test_report_distances_are_the_regions_distances(shape):
    rng = np.random.default_rng(7)
    for _ in range(60):
        N = int(rng.integers(2, 40))
        C = rng.normal(size=(N, 3, 4))
        C[:, 2, 3] += 8.0                                   # the point in front of most cameras
        X = rng.normal(size=3)
        u = np.vstack(project_views(np.append(X, 1.0)[None], C))
        near = u + rng.normal(size=u.shape) * 10.0 ** rng.uniform(-3, 1)
        if shape == "points":
            regions = [Point(p) for p in near]
        elif shape == "discs":
            regions = [Ellipse(p, np.eye(2) * rng.uniform(0.01, 4.0)) for p in near]
        elif shape == "mixed":
            regions = [Point(p) if k % 2 else Ellipse(p, np.eye(2) * 0.5) for k, p in enumerate(near)]
        else:
            regions = [Ellipse(p, np.diag([1.0, 2.0])) for p in near]
        rep = point_report(X, C, regions)
        res, un = _looped_report(X, C, regions)
        if shape == "points":
            assert np.array_equal(rep.residuals, res)
        else:
            assert np.allclose(rep.residuals, res, rtol=1e-12, atol=1e-12 * np.max(un))
        assert rep.gamma == pytest.approx(gamma_upper(res, un), rel=1e-12)
        inside = (res == 0.0)
        assert np.all(rep.residuals[inside] <= 1e-12 * np.max(un))


def test_report_of_disc_regions_is_an_upper_bound_of_the_exact_cost():
    """gamma_UB of a disc problem never below the cost computed in exact rational arithmetic of the float data."""
    from fractions import Fraction
    rng = np.random.default_rng(3)
    for _ in range(40):
        N = int(rng.integers(2, 12))
        C = rng.normal(size=(N, 3, 4))
        C[:, 2, 3] += 8.0
        X = rng.normal(size=3)
        u = np.vstack(project_views(np.append(X, 1.0)[None], C))
        centres = u + rng.normal(size=u.shape)
        radii = rng.uniform(0.1, 1.5, N)
        regions = [Ellipse(c, np.eye(2) * r * r) for c, r in zip(centres, radii)]
        rep = point_report(X, C, regions)
        exact = 0.0
        Xq = [Fraction(v) for v in X] + [Fraction(1)]
        for P, c, r in zip(C, centres, [math.sqrt(v * v) for v in radii]):
            h = [sum(Fraction(P[i, k]) * Xq[k] for k in range(4)) for i in range(3)]
            dx, dy = float(h[0] / h[2] - Fraction(c[0])), float(h[1] / h[2] - Fraction(c[1]))
            exact += max(math.hypot(dx, dy) - r, 0.0) ** 2
        assert rep.gamma >= math.sqrt(exact / (2 * N)) * (1 - 1e-15)


def test_n_lmivar_formula_grouped_by_degree_is_the_sum():
    rng = np.random.default_rng(0)

    def naive(nvars, delta, eq, ineq, q):
        n = 1 + tau(nvars, delta) + sum(sigma(nvars, delta - d) for d in eq)
        for d in ineq:
            s = sigma(nvars, (delta - d) // 2)
            n += s * (s + 1) // 2
        if q is not None:
            s = sigma(nvars, q // 2)
            n += s * (s + 1) // 2 - 1
        return n

    for _ in range(500):
        nv, de = int(rng.integers(1, 12)), int(rng.choice([2, 4, 6]))
        eq = [int(d) for d in rng.integers(0, de + 1, rng.integers(0, 7))]
        ineq = [int(d) for d in rng.integers(0, de + 1, rng.integers(0, 7))]
        q = [None, 2, 4][int(rng.integers(3))]
        assert n_lmivar_formula(nv, de, eq, ineq, q) == naive(nv, de, eq, ineq, q)
    assert n_lmivar_formula(800, 2, [2] * 79800) == naive(800, 2, [2] * 79800, [], None)
