"""Coincident camera centres in the vectorised fundamental matrices (issue #22): the rule of
:func:`tritools.model.stacked.distinct_centres` against the centres the cameras were built from (an independent
reference: sin of the angle between (c_i, 1) and (c_j, 1)), at pixel coordinates ~1e6, under arbitrary rescaling
of each camera, in georeferenced worlds, and for exactly duplicated views."""
from __future__ import annotations

import numpy as np
import pytest

import tritools
from tritools.model.stacked import fundamental_stack


def _rotation(rng) -> np.ndarray:
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


def _camera(f: float, pp: float, R: np.ndarray, centre: np.ndarray) -> np.ndarray:
    K = np.array([[f, 0.0, pp], [0.0, 1.1 * f, 0.7 * pp], [0.0, 0.0, 1.0]])
    return K @ R @ np.hstack([np.eye(3), -centre[:, None]])


def _true_sin(c1: np.ndarray, c2: np.ndarray) -> float:
    a, b = np.append(c1, 1.0), np.append(c2, 1.0)
    W = np.outer(a, b)
    return float(np.linalg.norm(W - W.T) / np.sqrt(2) / (np.linalg.norm(a) * np.linalg.norm(b)))


def _pairs(rng, pp, f, offset, baseline, n=60):
    """(cameras (n, 2, 3, 4), true sin of the centres' angle (n,)): distinct or coincident (baseline 0) centres,
    each pair with its own rotations and focal lengths."""
    C, sins = [], []
    for _ in range(n):
        c1 = rng.normal(size=3) * 5 + offset
        c2 = c1 + rng.normal(size=3) * baseline
        C.append([_camera(f, pp, _rotation(rng), c1), _camera(f * rng.uniform(0.5, 2), pp, _rotation(rng), c2)])
        sins.append(_true_sin(c1, c2))
    return np.array(C), np.array(sins)


def _defined(C: np.ndarray) -> np.ndarray:
    return fundamental_stack(C)[1][:, 0]


@pytest.mark.parametrize("pp", [0.0, 1e3, 1e6])
@pytest.mark.parametrize("offset", [0.0, 1e6])
def test_distinct_centres_kept_at_any_camera_scale(pp, offset):
    """Centres apart by >= 1e-9 of their magnitude are distinct, whatever each camera's scale (1e-8..1e8, not
    powers of two); the old rule ||F|| > rtol |P_i| |P_j| dropped some at 1e6 px and depended on the scales."""
    rng = np.random.default_rng(int(pp + offset) % 1000)
    C, sins = _pairs(rng, pp, 1e3, offset, 1e-2)
    assert (sins > 1e-9).all()
    assert _defined(C).all()
    for _ in range(3):
        k = 10.0 ** rng.uniform(-8, 8, size=(len(C), 2))
        assert _defined(C * k[..., None, None]).all()


@pytest.mark.parametrize("pp", [0.0, 1e3, 1e6])
def test_coincident_centres_dropped_at_any_camera_scale(pp):
    """Views sharing one centre (different rotations and focal lengths) are coincident, also rescaled."""
    rng = np.random.default_rng(7)
    C, sins = _pairs(rng, pp, 1e3, 0.0, 0.0)
    assert (sins == 0).all()
    assert not _defined(C).any()
    k = 10.0 ** rng.uniform(-8, 8, size=(len(C), 2))
    assert not _defined(C * k[..., None, None]).any()


@pytest.mark.parametrize("pp, f, offset", [(0.0, 1e3, 0.0), (1e6, 1e3, 0.0), (1e6, 1.0, 0.0), (1e6, 1e3, 1e6),
                                           (1e8, 1e-3, 1e6)])
def test_duplicated_views_always_coincident(pp, f, offset):
    """An exactly duplicated view is never a constraint (its null vector is the same bits), even for cameras
    too ill-conditioned for their centres to be known (a 1e6 px principal point with f = 1)."""
    rng = np.random.default_rng(3)
    C, _ = _pairs(rng, pp, f, offset, 1.0, n=20)
    C[:, 1] = C[:, 0]
    assert not _defined(C).any()
    assert not _defined(C * 1e-7).any()


def test_georeferenced_small_baseline_is_relative():
    """Centres 1e6 from the origin and 1e-7 apart (sin ~ 1e-13 < SAME_CENTER_RTOL) are one centre in floating
    point; 1e-2 apart (sin ~ 1e-8) they are two."""
    rng = np.random.default_rng(11)
    C_far, s_far = _pairs(rng, 1e3, 1e3, 1e6, 1e-7)
    assert (s_far < 1e-11).all() and not _defined(C_far).any()
    C_near, s_near = _pairs(rng, 1e3, 1e3, 1e6, 1e-2)
    assert (s_near > 1e-9).all() and _defined(C_near).all()


def test_triangulate_at_1e6_px_rescaled_cameras_and_duplicated_view():
    """End to end: a 3-view track at 1e6 px certifies with the same gamma whatever the cameras' scales, and a
    duplicated view (its constraint dropped) leaves gamma* of the track with that view counted twice
    consistent: gamma_lb <= gamma_ub, certified."""
    rng = np.random.default_rng(5)
    X = np.array([0.3, -0.2, 0.1])
    cams = [_camera(1e3, 1e6, _rotation(rng), rng.normal(size=3) * 0.5 + np.array([0, 0, -6.0]))
            for _ in range(3)]
    cams = [P if (P[2] @ np.append(X, 1)) > 0 else -P for P in cams]
    x = np.array([(P @ np.append(X, 1))[:2] / (P @ np.append(X, 1))[2] for P in cams]) + rng.normal(size=(3, 2))
    C = np.array(cams)
    ref = tritools.triangulate(C, x)
    assert ref.optimal
    k = np.array([1e-7, 3.3e5, 2.0 ** 0.5])[:, None, None]
    res = tritools.triangulate(C * k, x)
    assert res.optimal and res.status == ref.status
    assert abs(res.gamma_ub - ref.gamma_ub) <= 1e-6 * ref.gamma_ub
    dup = tritools.triangulate(np.concatenate([C, C[:1]]), np.concatenate([x, x[:1]]))
    assert dup.optimal and dup.gamma_lb <= dup.gamma_ub
    # an independent local solve of the duplicated problem (view 0 counted twice) from the certified point
    from scipy.optimize import least_squares

    Cd, xd = np.concatenate([C, C[:1]]), np.concatenate([x, x[:1]])

    def residuals(Xw):
        h = Cd @ np.append(Xw, 1.0)
        return (h[:, :2] / h[:, 2:] - xd).ravel()

    sol = least_squares(residuals, ref.X, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    gamma_local = np.linalg.norm(sol.fun) / np.sqrt(2 * len(Cd))          # the RMS error of SPEC §1
    assert dup.gamma_lb <= gamma_local * (1 + 1e-9)
    assert abs(dup.gamma_ub - gamma_local) <= 1e-6 * gamma_local
    # the certified point is at least as good as the local solve (scipy's LM may stop ~1e-6 short along the flat
    # depth direction, depending on its version), and close to it
    assert np.sum(residuals(dup.X) ** 2) <= np.sum(sol.fun ** 2) * (1 + 1e-9)
    np.testing.assert_allclose(dup.X, sol.x, rtol=1e-4, atol=1e-6)

