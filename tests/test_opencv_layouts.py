"""Arrays as OpenCV users have them: cameras_from_krt (K, R or rvec, t) and triangulate_points with
OpenCV's point layouts ((V, 2, M) as cv2.triangulatePoints, (V, M, 1, 2), per-view lists, float32, NaN for
unseen views); an ambiguous shape is refused instead of guessed."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import tritools
from tritools import cameras_from_krt, triangulate_points

K = np.array([[700.0, 0.0, 320.0], [0.0, 710.0, 240.0], [0.0, 0.0, 1.0]])


def rig(V=3, seed=0):
    rng = np.random.default_rng(seed)
    rvecs = rng.normal(scale=0.15, size=(V, 3))
    tvecs = np.column_stack([rng.uniform(-1, 1, V), rng.uniform(-0.3, 0.3, V), np.full(V, 6.0)])
    return rvecs, tvecs


def observe(rvecs, tvecs, X):
    """(V, 2, M) pixels computed independently with scipy's rotations."""
    out = []
    for r, t in zip(rvecs, tvecs):
        Xc = Rotation.from_rotvec(r).apply(X) + t
        uv = (K @ Xc.T)
        out.append(uv[:2] / uv[2])
    return np.array(out)


def test_cameras_from_krt_matches_an_independent_projection():
    rvecs, tvecs = rig()
    P = cameras_from_krt(K, rvecs[:, :, None], tvecs)                   # rvecs (3, 1) each, as cv2.solvePnP
    with pytest.raises(ValueError, match="Rodrigues vectors\\? pass them as shape \\(3, 3, 1\\)"):
        cameras_from_krt(K, rvecs, tvecs)                              # (3, 3): read as one matrix, refused
    X = np.array([[0.1, -0.2, 0.3], [0.5, 0.4, -0.2]])
    ref = observe(rvecs, tvecs, X)
    Xh = np.c_[X, np.ones(2)]
    proj = np.einsum("vij,mj->vim", P, Xh)
    np.testing.assert_allclose(proj[:, :2] / proj[:, 2:], ref, rtol=1e-12)
    Rm = Rotation.from_rotvec(rvecs).as_matrix()
    np.testing.assert_allclose(cameras_from_krt(K, Rm, tvecs[:, :, None]), P, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(cameras_from_krt(K, Rm[0], tvecs[0]), P[0], rtol=1e-12, atol=1e-9)
    assert cameras_from_krt(K, rvecs[0][:, None], tvecs[0][:, None]).shape == (3, 4)
    with pytest.raises(ValueError, match="R must be a rotation"):
        cameras_from_krt(K, 2 * Rm, tvecs)
    with pytest.raises(ValueError, match="R must be a rotation"):
        cameras_from_krt(K, -Rm[0], tvecs[0])                          # det -1: a reflection
    with pytest.raises(ValueError, match="different numbers of views"):
        cameras_from_krt(K, Rm, tvecs[:2])


def test_opencv_layouts_give_the_same_certified_points():
    rvecs, tvecs = rig(3)
    P = cameras_from_krt(K, rvecs[:, :, None], tvecs)
    X = np.random.default_rng(1).uniform(-0.5, 0.5, (6, 3))
    pts = observe(rvecs, tvecs, X)                                      # (V, 2, M)
    ours = triangulate_points(P, pts.transpose(2, 0, 1))                 # tritools' (M, V, 2)
    assert np.all(ours.optimal)
    np.testing.assert_allclose(ours.X, X, atol=1e-6)
    layouts = [pts.astype(np.float32),                                   # cv2.triangulatePoints' 2 x M per view
               list(pts),                                                # [pts1, pts2, pts3]
               pts.transpose(0, 2, 1)[:, :, None, :].astype(np.float32),  # (V, M, 1, 2) as cv2 point vectors
               [p.T for p in pts]]                                       # per-view (M, 2)
    for a in layouts:
        r = triangulate_points(P, a)
        assert np.all(r.optimal)
        np.testing.assert_allclose(r.X, X, atol=2e-3)                    # float32 pixels: ~1e-4 px
    r = triangulate_points(P, pts, layout="views_xy_points")
    np.testing.assert_allclose(r.X, ours.X, atol=1e-9)
    seen = pts.copy()
    seen[2, :, 0] = np.nan                                               # view 2 does not see point 0
    r = triangulate_points(P, seen)
    assert list(r.n_views) == [2, 3, 3, 3, 3, 3] and np.all(r.optimal)
    np.testing.assert_allclose(r.X[0], X[0], atol=1e-6)


def test_two_views_two_points_must_name_the_layout():
    """A (2, 2, 2) array with 2 views fits both (M, V, 2) and (V, 2, M): never guessed."""
    rvecs, tvecs = rig(2, seed=3)
    P = cameras_from_krt(K, rvecs, tvecs)
    X = np.array([[0.2, 0.1, 0.0], [-0.3, 0.2, 0.4]])
    pts = observe(rvecs, tvecs, X)                                      # (V=2, 2, M=2): cv2's layout
    with pytest.raises(ValueError, match="ambiguous.*layout="):
        triangulate_points(P, pts)
    r = triangulate_points(P, pts, layout="views_xy_points")
    np.testing.assert_allclose(r.X, X, atol=1e-6)
    assert np.all(r.optimal) and np.all(r.gamma_ub < 1e-6)
    r = triangulate_points(P, pts.transpose(2, 0, 1), layout=tritools.PointsLayout.POINTS_VIEWS)
    np.testing.assert_allclose(r.X, X, atol=1e-6)
    with pytest.raises(ValueError, match="ambiguous"):
        triangulate_points(np.concatenate([P, P[:1] + 1.0]), np.zeros((3, 3, 2)))   # V = M = 3 in (V, V, 2)


def test_bad_layouts_are_named():
    rvecs, tvecs = rig(4)
    P = cameras_from_krt(K, rvecs, tvecs)[:3]                           # (4, 3) rvecs: unambiguous
    with pytest.raises(ValueError, match="layout must be one of"):
        triangulate_points(P, np.zeros((4, 3, 2)), layout="cv2")
    with pytest.raises(ValueError, match="layout 'views_xy_points' must have shape \\(3, 2, M\\)"):
        triangulate_points(P, np.zeros((4, 3, 2)), layout="views_xy_points")
    with pytest.raises(ValueError, match="points2d must have shape"):
        triangulate_points(P, np.zeros((4, 5, 2)))
