"""One camera listed twice in a track with two different keypoints (review 22a F3): the L2 sub-problem of such views
is refused by ``triangulate`` (cameras equal up to scale), so its bound was 0 and the robust search never
certified; now its exact value, sum_i |x_i - x_bar|^2 (:func:`tritools.solve.robust_subsolve._one_camera`), only for
cameras that are exact multiples of each other (:func:`tritools.model.exact.one_exact_camera`).

Reference independent of tritools' solvers: every inlier set S enumerated, L2*(S) by scipy multi-start least
squares (an attained value, so no valid lower bound exceeds the reference)."""
from __future__ import annotations

from itertools import combinations

import numpy as np
import pytest
from scipy.optimize import least_squares

import tritools
from tritools.scene import robust_protocol_scene
from tritools.model.exact import one_exact_camera as one_camera
from tritools.solve.robust_subsolve import _one_camera


def _reference(P, x, c, starts) -> float:
    N = len(P)
    best = float(np.sum(np.sort(c ** 2)[:N]))                       # no inlier at all
    best = min(best, float(np.sum(c ** 2) - np.max(c ** 2)))        # one inlier (on its ray)
    for k in range(2, N + 1):
        for S in combinations(range(N), k):
            S = list(S)

            def r(X):
                h = P[S] @ np.append(X, 1.0)
                return (h[:, :2] / h[:, 2:] - x[S]).ravel()
            rest = float(np.sum(np.delete(c, S) ** 2))
            for X0 in starts:
                sol = least_squares(r, X0, method="lm", xtol=1e-14, ftol=1e-14)
                best = min(best, 2 * sol.cost + rest)
    return best


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_view_listed_twice_with_two_keypoints_is_certified(seed):
    rng = np.random.default_rng(seed)
    for _ in range(4):
        N = int(rng.integers(2, 5))
        P, x, X, _ = robust_protocol_scene(N, int(rng.integers(0, N - 1)), 1.0, rng)
        k = int(rng.integers(N))
        P = np.concatenate([P, P[k:k + 1] * rng.choice([1.0, -2.0, 0.5])])    # exact multiples (powers of two)
        x = np.concatenate([x, x[k:k + 1] + rng.normal(scale=50.0, size=(1, 2))])
        c = float(rng.choice([3.0, 20.0, 200.0]))
        res = tritools.triangulate(P, x, robust=c)
        f_ref = _reference(P, x, np.full(N + 1, c), [X, res.X])
        n2 = 2 * (N + 1)
        assert n2 * res.gamma_lb ** 2 <= f_ref * (1 + 1e-9) + 1e-9
        assert res.optimal, res.message
        assert n2 * res.gamma_ub ** 2 <= f_ref * (1 + 1e-6) + 1e-6
        many = tritools.triangulate_many([(P, x)], robust=c)[0]
        assert many.optimal and many.gamma_ub == pytest.approx(res.gamma_ub, rel=1e-6)


def test_one_camera_is_exact_proportionality():
    P = robust_protocol_scene(2, 0, 1.0, np.random.default_rng(3))[0]
    assert one_camera(np.stack([P[0], P[0], -4.0 * P[0]]))
    assert not one_camera(np.stack([P[0], P[1]]))
    assert not one_camera(np.stack([P[0], P[0] * (1 + 2 ** -52)]))        # one ulp off: maybe a micro-baseline
    Q = P[0].copy()
    Q[0, 0] = 0.0
    assert not one_camera(np.stack([P[0], Q]))
    assert not one_camera(np.stack([P[0], np.full((3, 4), np.nan)]))


def test_one_camera_value_is_the_spread_about_the_mean():
    """The value, and the estimate: a point in front of the camera whose projection is the observations' mean, so
    its cost on the copies is that value (attained)."""
    x = np.array([[1.0, 2.0], [4.0, 6.0], [-2.0, 0.5]])
    P = robust_protocol_scene(2, 0, 1.0, np.random.default_rng(3))[0][0]
    cams = np.stack([P, -2.0 * P, 0.5 * P])
    out = _one_camera(cams, tritools.as_regions(x))
    exact = float(np.sum((x - x.mean(axis=0)) ** 2))
    assert out.certified and out.lb <= exact and out.lb == pytest.approx(exact, rel=1e-11)
    h = P @ np.append(out.X, 1.0)
    assert h[2] * np.sign(np.linalg.det(P[:, :3])) > 0                     # in front
    np.testing.assert_allclose(h[:2] / h[2], x.mean(axis=0), rtol=0, atol=1e-9)
    huge = _one_camera(cams[:2], tritools.as_regions(np.array([[1e300, 0.0], [-1e300, 0.0]])))
    assert huge.lb == 0.0 and not huge.certified
