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


@pytest.mark.parametrize("scale", [1.0, 1e-200, 1e200])
def test_fundamental_stack_both_decides_centres_on_raw_cameras_at_any_scale(scale):
    """One helper for 'F of the normalised cameras, one centre or not decided on the raw ones' (the fast path, the
    robust enumeration and the batched SDP): its raw ``defined`` is invariant to the cameras' scales and flags a pair
    whose raw centres coincide although the normalised cameras (here perturbed) would not say so."""
    from tritools.model.stacked import fundamental_stack, fundamental_stack_both
    from tritools.solve.robust_enum import fundamentals
    rng = np.random.default_rng(50)
    C = rng.normal(size=(2, 4, 3, 4))
    C[1, 2] = rng.normal(size=(3, 3)) @ C[1, 0]                  # views 0 and 2 of problem 1: one centre
    Cn = C + 1e-3 * rng.normal(size=C.shape)                      # stands in for the normalised frame
    F, d, raw, E = fundamental_stack_both(Cn, C * scale)
    F0, d0, E0 = fundamental_stack(Cn, errors=True)
    assert np.array_equal(d, d0) and np.allclose(F, F0) and np.allclose(E, E0)
    assert raw[0].all() and not raw[1, 1] and raw[1].sum() == 5   # pair (0, 2) is the second of view_pairs(4)
    Ff, df, Ef = fundamentals(C * scale, Cn)
    assert np.array_equal(df, d & raw) and np.isinf(Ef[~d]).all()
