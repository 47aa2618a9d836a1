"""Regression tests for the defects listed in issues #14 (bounded resources, clean failures) and #15 (SfM
workflows) that no other test file reproduces with the original input.  Each test names the defect it
reproduces; the inputs are the ones of the issue, with a short time limit where the original ran for minutes.

Timing: no assertion on speed beyond "returned within a generous multiple of its time limit" (a hang or a
run of minutes is what these tests catch); the whole file runs in well under a minute.
"""
from __future__ import annotations

import numpy as np
import pytest

import tritools
from tritools import Status

#: three cameras and the exact projections of X_TRUE (gamma* = 0, certified by verification in milliseconds).
CAMS = np.array([[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 1]],
                 [[1, 0, 0, 1], [0, 1, 0, 0], [0, 0, 1, 1]],
                 [[1, 0, 0, 0], [0, 1, 0, 1], [0, 0, 1, 1]]], dtype=float)
X_TRUE = np.array([0.2, -0.1, 1.0])
_H = CAMS @ np.append(X_TRUE, 1.0)
PTS = _H[:, :2] / _H[:, 2:]
#: wall time allowed beyond a time limit before calling it a hang: one solver iteration of the largest program
#: the default memory budget admits can take ~10 s on a busy 2-core machine (the limit is checked between
#: iterations).
SLACK = 40.0
MISLEADING = ("equal up to scale", "rank < 3", "coincide")


# ----------------------------------------------------------------------------- #14: misleading diagnoses
@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_cameras_times_1e300_are_the_same_cameras():
    """#14: cameras x 1e300 were diagnosed "cameras are all equal up to scale" (later: "all camera centres
    coincide"); a camera's scale is irrelevant, so the answer is that of the unscaled cameras."""
    ref = tritools.triangulate(CAMS, PTS)
    for k in (1e300, -1e300, 1e-300):
        res = tritools.triangulate(k * CAMS, PTS)
        assert res.status == ref.status == Status.OPTIMAL, (k, res.status, res.message)
        np.testing.assert_allclose(res.X, X_TRUE, atol=1e-9)
    (many,) = tritools.triangulate_many([(1e300 * CAMS, PTS)], progress=False)
    assert many.status == Status.OPTIMAL and np.allclose(many.X, X_TRUE, atol=1e-9)


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
@pytest.mark.parametrize("k", [1e20, 1e100, 1e300])
def test_points_at_1e300_are_not_blamed_on_the_cameras(k):
    """#14: image points at 1e300 were diagnosed "rank < 3" (later: "all camera centres coincide"), and points at
    1e20 raised numpy's LinAlgError out of triangulate.  Now: a result whose status and message name the data."""
    for res in (tritools.triangulate(CAMS, k * PTS), tritools.triangulate_many([(CAMS, k * PTS)], progress=False)[0]):
        assert isinstance(res, tritools.TriangulationResult)
        assert res.status == Status.NUMERICAL_FAILURE and not res.optimal, (res.status, res.message)
        assert "too large" in res.message and not any(m in res.message for m in MISLEADING[:2])
        assert "centres coincide" not in res.message

