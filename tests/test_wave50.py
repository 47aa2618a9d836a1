"""Wave 50: review 49a F4 (the triangulation angle at a camera centre is undefined, not a round-off angle), ...
"""
from __future__ import annotations

import numpy as np
import pytest

import tritools
from tritools.model.cameras import camera_center
from tritools.uncertain.angle import triangulation_angles


def _look_at(c: np.ndarray) -> np.ndarray:
    """A camera at centre c looking at the origin."""
    z = -c / np.linalg.norm(c)
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    R = np.array([x, np.cross(z, x), z])
    return np.hstack([R, (-R @ c)[:, None]])


@pytest.mark.parametrize("scale", [1.0, 1e-6, 1e6])
def test_angle_at_a_camera_centre_is_nan(scale):
    cams = np.array([_look_at(np.array(c) * scale) for c in ([-1.0, 0.0, -5.0], [1.0, 0.2, -5.0], [0.0, 1.0, -5.0])])
    for k in range(3):
        C = camera_center(cams[k])
        assert np.isnan(tritools.triangulation_angle(cams, C))
        assert np.isnan(tritools.triangulation_angle(cams, C * (1 + 1e-14)))
    # a point near, not at, a centre keeps its angle: its rays are defined
    a = tritools.triangulation_angle(cams, camera_center(cams[0]) + np.array([0.0, 0.0, 1e-6]) * scale)
    assert np.isfinite(a) and 0 < a <= 180
    # the origin, seen by all three: a small, defined angle, the same at every scale
    a0 = tritools.triangulation_angle(cams, [0.0, 0.0, 0.0])
    assert np.isclose(a0, np.degrees(np.arctan2(np.linalg.norm(np.cross([-1, 0, -5], [1, 0.2, -5])),
                                                np.dot([-1, 0, -5], [1, 0.2, -5]))), rtol=0.5)


def test_angle_stack_marks_only_the_point_at_a_centre():
    cams = np.array([_look_at(np.array(c)) for c in ([-1.0, 0.0, -5.0], [1.0, 0.2, -5.0])])
    centres = np.array([camera_center(P) for P in cams])
    X = np.array([[0.0, 0.0, 0.0], centres[1], [0.1, 0.2, 0.3]])
    stack = np.broadcast_to(centres, (3, 2, 3)).copy()
    stack[2, 1] = np.nan                                  # padding: one ray only -> 0
    a = triangulation_angles(stack, X)
    assert np.isfinite(a[0]) and a[0] > 1 and np.isnan(a[1]) and a[2] == 0.0


def test_quality_median_angle_skips_undefined_angles():
    from tritools.sfm.quality import _nan_median
    assert _nan_median(np.array([np.nan, 3.0, 1.0, 2.0])) == 2.0
    assert _nan_median(np.array([np.nan])) is None and _nan_median(np.array([])) is None
