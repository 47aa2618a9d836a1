"""The scalar twins of the camera rules that validate_cameras runs on a single call's few cameras
(rank_ratio_scalar, _all_equal_scalar) equal the vectorised rules (camera_rank_ratio, cameras_all_equal)."""
import numpy as np
import pytest

from tritools.model.cameras import (CAMERA_RANK_RTOL, _all_equal, _all_equal_scalar, checked_rank_ratio,
                                    rank_ratio_scalar, validate_cameras)
from tritools.scene import random_scene


def _cases():
    rng = np.random.default_rng(0)
    yield np.array(random_scene(5, 1, seed=1).cameras, float)
    yield rng.normal(size=(8, 3, 4))
    K = np.array([[1000.0, 0, 1e6], [0, 1000.0, 1e6], [0, 0, 1]])         # principal point at 1e6 px
    yield np.array([K @ np.hstack([np.eye(3), rng.normal(size=(3, 1))]) for _ in range(3)])
    yield np.array([K @ np.hstack([np.eye(3), -4e7 + rng.normal(size=(3, 1))]) for _ in range(3)])   # georeferenced
    for e in (-150, -20, 20, 150):                                          # any camera scale
        yield np.array(random_scene(4, 1, seed=2).cameras, float) * 10.0 ** e
    A = rng.normal(size=(3, 3, 4))
    A[1, 2] = A[1, 0] * 0.5 + A[1, 1] * 1e-17                              # rank 2 up to round-off
    A[2, 1] = 0.0                                                           # a zero row
    yield A
    B = rng.normal(size=(3, 3, 4))
    B[0, 1] = B[0, 0] + CAMERA_RANK_RTOL * 10 * rng.normal(size=4)           # near the rank threshold
    yield B


@pytest.mark.parametrize("C", list(_cases()))
def test_rank_ratio_scalar_equals_the_vectorised_rule(C):
    a, b = np.array(rank_ratio_scalar(C)), checked_rank_ratio(C)
    assert np.allclose(a, b, rtol=1e-12, atol=1e-15)
    assert np.array_equal(a > CAMERA_RANK_RTOL, b > CAMERA_RANK_RTOL)
    d = np.array(rank_ratio_scalar(C, decide_only=True))       # validate_cameras' form: the same decisions
    assert np.array_equal(d > CAMERA_RANK_RTOL, b > CAMERA_RANK_RTOL) and np.all(d <= a)
    assert np.array_equal(d[a <= CAMERA_RANK_RTOL], a[a <= CAMERA_RANK_RTOL])     # a failing camera's value: the rule's


def test_all_equal_scalar_equals_the_vectorised_rule():
    P = np.array(random_scene(3, 1, seed=4).cameras, float)
    for C in (P, np.array([P[0], -3.0 * P[0], 1e-200 * P[0]]), np.array([P[0], P[0] * (1 + 1e-15), P[1]]),
              np.array([P[0], P[0] * (1 + 1e-15)])):
        assert _all_equal_scalar(C) == bool(_all_equal(C))
    with pytest.raises(ValueError, match="all equal"):
        validate_cameras(np.array([P[0], -2.0 * P[0]]))
    R = np.array(_cases().__next__())
    R[1, 2] = R[1, 0]
    with pytest.raises(ValueError, match=r"cameras\[1\] has rank < 3"):
        validate_cameras(R)
