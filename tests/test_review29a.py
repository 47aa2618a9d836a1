"""Review 29a (independent: long tracks and large batches) -- the fixes, each against an independent reference.

F3: rows of a batch cut by ``total_time_limit`` (:func:`tritools.solve.call_limit.expired_points`) reported a gamma_UB
below the exact gamma at their own float X in georeferenced worlds: each camera was divided by its largest entry,
which rounds every entry, and the world's offset amplifies that past gamma_UB's margin.  The reference here is
exact rational arithmetic on the caller's float data."""
from fractions import Fraction

import numpy as np
import pytest

import tritools
from tritools.solve.call_limit import expired_points
from tritools.solve.options import TriangulationOptions


def _camera(centre, target, f=800.0):
    z = target - centre
    z = z / np.linalg.norm(z)
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    R = np.vstack([x, np.cross(z, x), z])
    K = np.array([[f, 0, 320.0], [0, f, 240.0], [0, 0, 1]])
    return K @ np.hstack([R, (-R @ centre)[:, None]])


def _geo_track(N: int, seed: int, offset: float):
    """N cameras around the origin looking at it, moved into a world offset by ``offset`` metres."""
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(N, 3))
    C = 6 * v / np.linalg.norm(v, axis=1)[:, None]
    X = rng.normal(scale=0.3, size=3)
    cams = np.array([_camera(c, np.zeros(3)) for c in C])
    x = np.array([P[:2] @ np.append(X, 1) / (P[2] @ np.append(X, 1)) for P in cams]) + rng.normal(size=(N, 2))
    shift = np.eye(4)
    shift[:3, 3] = -offset
    return cams @ shift, x


def exact_f(cams, x, X) -> Fraction:
    """sum_i |pi(P_i (X, 1)) - x_i|^2 in exact rational arithmetic on the float data."""
    Xh = [Fraction(float(v)) for v in X] + [Fraction(1)]
    total = Fraction(0)
    for P, xi in zip(cams, x):
        h = [sum(Fraction(float(P[r, k])) * Xh[k] for k in range(4)) for r in range(3)]
        total += sum((h[r] / h[2] - Fraction(float(xi[r]))) ** 2 for r in range(2))
    return total


def _assert_upper(cams, x, r):
    assert r.X is not None and r.gamma_ub is not None, r.message
    N = len(cams)
    assert Fraction(r.gamma_ub) ** 2 * (2 * N) >= exact_f(cams, x, r.X), (r.gamma_ub, N)


@pytest.mark.parametrize("offset", [5e8, 6e8, 1e9])
def test_expired_rows_bound_the_exact_gamma_in_georeferenced_worlds(offset):
    problems = [_geo_track(N, seed, offset) for seed, N in enumerate((3, 4, 5, 6, 15) * 2)]
    opts = TriangulationOptions()
    for cams, x in problems:           # one stack per view count, as the batch forms them
        r = expired_points(cams[None], x[None], opts)[0]
        assert r.status == "time_limit"
        _assert_upper(cams, x, r)


def test_a_batch_cut_by_its_whole_call_limit_keeps_valid_upper_bounds():
    problems = [_geo_track(N, 100 + seed, 6e8) for seed, N in enumerate((3, 4, 5, 6, 15, 30) * 3)]
    res = tritools.triangulate_many(problems, total_time_limit=1e-6, progress=False)
    assert len(res) == len(problems)
    for (cams, x), r in zip(problems, res):
        assert r.status == "time_limit" and not r.optimal
        _assert_upper(cams, x, r)
