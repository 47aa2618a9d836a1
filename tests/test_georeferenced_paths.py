"""A georeferenced track (cameras ~3.6e6 from the world origin, 50 apart): the single call and the batch call
give the same outcome (the review found `triangulate` -> numerical_failure "image data too large" where
`triangulate_points` certified), and the certified value is the minimum of an independent local search."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

import tritools

CENTRE = np.array([1.2e6, -3.4e6, 2.5e5])


def _cameras(n, rng, radius=50.0, f=800.0):
    K = np.array([[f, 0, 320], [0, f, 240], [0, 0, 1.0]])
    cams = []
    for i in range(n):
        a = np.pi * i / n
        C = CENTRE + radius * np.array([np.sin(a), 0.3 * rng.standard_normal() + 0.2 * np.cos(3 * a), -np.cos(a)])
        z = (CENTRE - C) / np.linalg.norm(CENTRE - C)
        x = np.cross([0, 1, 0], z)
        x /= np.linalg.norm(x)
        R = np.vstack([x, np.cross(z, x), z])
        cams.append(K @ np.hstack([R, (-R @ C)[:, None]]))
    return np.array(cams)


def _project(P, X):
    p = P @ np.append(X, 1.0)
    return p[:2] / p[2]


@pytest.mark.parametrize("n_views", [4, 12])
def test_single_and_batch_calls_agree_on_a_georeferenced_track(n_views):
    rng = np.random.default_rng(7)
    cams = _cameras(n_views, rng)
    X_true = CENTRE + 5 * rng.standard_normal(3)
    obs = np.array([_project(P, X_true) for P in cams]) + rng.standard_normal((n_views, 2))
    single = tritools.triangulate(cams, obs)
    batch = tritools.triangulate_points(cams, obs[None])
    assert single.optimal and bool(batch.optimal[0]), (single.status, single.message, batch.status)

    # independent reference: local least squares in coordinates relative to the true point's neighbourhood
    def res(d):
        return np.concatenate([_project(P, X_true + d) - x for P, x in zip(cams, obs)])

    ref = least_squares(res, np.zeros(3), x_scale=1.0, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    gamma_ref = np.sqrt(np.sum(ref.fun ** 2) / (2 * n_views))
    for lb, ub in [(single.gamma_lb, single.gamma_ub), (batch.gamma_lb[0], batch.gamma_ub[0])]:
        assert lb <= gamma_ref * (1 + 1e-6) + 1e-9
        assert ub <= gamma_ref * (1 + 1e-9) + 1e-12             # no worse than the local reference


def test_the_reviewed_georeferenced_track_certifies_in_a_single_call():
    """The review's 12-view track (tests/data/georeferenced_12_views.npz: cameras ~3.6e6 from the origin): the
    single call reported numerical_failure ("image data too large") where the batch certified."""
    from pathlib import Path

    d = np.load(Path(__file__).parent / "data" / "georeferenced_12_views.npz")
    single = tritools.triangulate(d["cams"], d["obs"])
    batch = tritools.triangulate_points(d["cams"], d["obs"][None])
    assert single.optimal and bool(batch.optimal[0]), (single.status, single.message)
    assert abs(single.gamma_ub - batch.gamma_ub[0]) <= 1e-6 * batch.gamma_ub[0]
