"""Independent references of the robust (TLS) tests: multi-start scipy least squares over the 3D point, the TLS
value by inlier-set enumeration, seeded tracks with wrong matches, and a driver of one search's subset requests."""
import itertools
from fractions import Fraction

import numpy as np
from scipy.optimize import least_squares

from tritools.scene import random_scene
from tritools.solve.robust import tls_cost
from tritools.solve.robust_bounds import compute_many


def outlier_track(N, n_out, seed, noise=1.0, *, seed_offset=11, shift=(40.0, 400.0)):
    """(cameras, points, true X, outlier views): a random_scene track with ``n_out`` observations moved by
    ``shift`` px in random directions (the wrong matches; rng seeded ``seed + seed_offset``)."""
    sc = random_scene(N, 1, noise_px=noise, seed=seed)
    rng = np.random.default_rng(seed + seed_offset)
    x = sc.points2d[0].copy()
    out = rng.choice(N, n_out, replace=False)
    ang = rng.uniform(0, 2 * np.pi, n_out)
    x[out] += rng.uniform(*shift, n_out)[:, None] * np.stack([np.cos(ang), np.sin(ang)], 1)
    return sc.cameras, x, sc.points3d[0], out


def _residuals(cams, x):
    def res(X):
        u = np.einsum("nij,j->ni", cams, np.append(X, 1.0))
        return (u[:, :2] / u[:, 2:] - x).ravel()
    return res


def l2_min(cams, x, starts, tol=1e-14) -> float:
    """Smallest sum of squared reprojection errors over multi-start scipy least squares (an attained value >= L2*)."""
    res = _residuals(cams, x)
    return min(float(np.sum(least_squares(res, X0, xtol=tol, ftol=tol, gtol=tol).fun ** 2)) for X0 in starts)


def hp_l2_min(cams, x, X0, digits=60, iters=80):
    """The L2 local minimum of the float data next to ``X0`` in ``digits``-digit arithmetic (mpmath Gauss-Newton on
    the exact float inputs), as a Fraction accurate to ~1e-45 relative: the value a float reference computation loses
    ~1e-7 of in a georeferenced world."""
    import mpmath as mp

    with mp.workdps(digits):
        P = [[[mp.mpf(float(v)) for v in row] for row in Pi] for Pi in cams]
        xs = [[mp.mpf(float(v)) for v in xi] for xi in x]
        X = [mp.mpf(float(v)) for v in X0]

        def res_jac(X):
            R, J = [], []
            for Pi, xi in zip(P, xs):
                h = [Pi[r][0] * X[0] + Pi[r][1] * X[1] + Pi[r][2] * X[2] + Pi[r][3] for r in range(3)]
                for a in range(2):
                    R.append(h[a] / h[2] - xi[a])
                    J.append([(Pi[a][k] * h[2] - h[a] * Pi[2][k]) / h[2] ** 2 for k in range(3)])
            return mp.matrix(R), mp.matrix(J)

        for _ in range(iters):
            R, J = res_jac(X)
            d = mp.lu_solve(J.T * J, -(J.T * R))
            X = [X[k] + d[k] for k in range(3)]
            if mp.norm(d) < mp.mpf(10) ** (15 - digits) * (1 + mp.norm(mp.matrix(X))):
                break
        R, _ = res_jac(X)
        m, e = mp.mpf(sum(r * r for r in R)).man_exp
        return Fraction(int(m)) * Fraction(2) ** int(e)       # as a Fraction: compared exactly with floats


def tls_by_subsets(cams, x, c, starts, tol=1e-12, with_ray=True) -> float:
    """min over inlier sets S (|S| >= 2) of f_TLS at S's local L2 minimisers from ``starts`` (and, ``with_ray``,
    the value sum of all but the largest c^2 of a point on one view's ray): an attained value, >= the TLS optimum.
    Sets whose c^2(V - S) alone reaches the best value so far are skipped (f_TLS = min over S of L2(S) + c^2(V - S);
    a point that does better has another inlier set, enumerated too)."""
    N = len(x)
    c2 = np.asarray(c, float) ** 2 * np.ones(N)
    best = float(np.sum(np.sort(c2)[:-1])) if with_ray else np.inf
    for k in range(N, 1, -1):                    # large sets first: UB falls fast and prunes the small ones
        for S in map(list, itertools.combinations(range(N), k)):
            if float(np.sum(np.delete(c2, S))) >= best:
                continue                         # every X is worth >= c^2(V - S) with S its inliers: no better
            for X0 in starts:
                X = least_squares(_residuals(cams[S], x[S]), X0, xtol=tol, ftol=tol).x
                u = np.einsum("nij,j->ni", cams, np.append(X, 1.0))
                best = min(best, tls_cost(np.linalg.norm(u[:, :2] / u[:, 2:] - x, axis=1), c))
    return best


def drive_one(gen, bounds):
    """Drive one generator of subset requests to its return value (what robust_drive.drive does for many)."""
    try:
        req = next(gen)
        while True:
            compute_many([(bounds, req)])
            req = gen.send(None)
    except StopIteration as stop:
        return stop.value


def primed_search(cams, x, c, X):
    """A ``TlsSearch`` over (cams, x, c) offered the candidate X, its full view set W verified first: (search, W),
    the state every sub-bound test starts from."""
    import tritools
    from tritools.solve.robust import TlsSearch

    s = TlsSearch(cams, None, c, tritools.TriangulationOptions(), 0.0, points=x)
    s.offer(X)
    W = frozenset(range(len(x)))
    drive_one(s.verify_first(W), s.bounds)
    return s, W


def assert_same_tls(a, b, rel=1e-6):
    """Two TLS results of one problem agree: status, inlier set and gamma_UB (to ``rel``)."""
    assert a.status == b.status, (a.status, b.status)
    np.testing.assert_array_equal(a.inliers, b.inliers)
    assert abs(a.gamma_ub - b.gamma_ub) <= rel * max(abs(a.gamma_ub), abs(b.gamma_ub)) + 1e-12, (a.gamma_ub, b.gamma_ub)


def assert_lb_below(results, N, f_ref):
    """Every result's TLS lower bound (gamma units: f = 2 N gamma^2) is at most the attained reference value f_ref."""
    for r in results:
        assert 2 * N * r.gamma_lb ** 2 <= f_ref * (1 + 1e-9) + 1e-9, (r.gamma_lb, f_ref)
