"""The ray candidates of the TLS search (tritools.solve.robust_rays), against independent constructions."""
import numpy as np
import pytest

import tritools
from tritools.scene import random_cameras
from tritools.solve import robust_rays as rr


def _random_cameras(rng, n, scale=1.0):
    return rng.normal(size=(n, 3, 4)) * scale


@pytest.mark.parametrize("scale", [1e-3, 1.0, 1e3])
def test_rays_match_null_vector_and_back_projection(scale):
    """Centre = the camera's null vector (SVD), direction = M^-1 (x, 1) with positive depth in its view."""
    rng = np.random.default_rng(1)
    C = _random_cameras(rng, 6, scale)
    pts = rng.normal(size=(6, 2)) * 300
    centres, dirs, ok = rr._rays(C, pts)
    assert ok.all()
    for i in range(6):
        null = np.linalg.svd(C[i])[2][-1]
        np.testing.assert_allclose(centres[i], null[:3] / null[3], rtol=1e-8, atol=1e-10)
        np.testing.assert_allclose(np.linalg.norm(dirs[i]), 1.0, rtol=1e-12)
        X = centres[i] + 2.5 * dirs[i]                  # a point on the ray projects onto pts[i] ...
        h = C[i] @ np.append(X, 1.0)
        np.testing.assert_allclose(h[:2] / h[2], pts[i], rtol=1e-7, atol=1e-7)
        M = C[i][:, :3]                                 # ... in front of the camera (Hartley-Zisserman depth sign)
        assert np.sign(np.linalg.det(M)) * h[2] > 0


def test_rays_singular_camera_gives_no_ray():
    """A camera whose left 3x3 block is singular has no finite centre: no ray, the others unchanged."""
    rng = np.random.default_rng(2)
    C = _random_cameras(rng, 4)
    pts = rng.normal(size=(4, 2))
    full = rr._rays(C, pts)
    C[2, :, :3] = 0.0
    centres, dirs, ok = rr._rays(C, pts)
    np.testing.assert_array_equal(ok, [True, True, False, True])
    for k in (0, 1, 3):
        np.testing.assert_allclose(centres[k], full[0][k])
        np.testing.assert_allclose(dirs[k], full[1][k])


def test_closest_depths_match_least_squares():
    """t_ij minimises |C_i + t u_i - C_j - s u_j| over (t, s): the 2-unknown least-squares solution."""
    rng = np.random.default_rng(3)
    centres = rng.normal(size=(5, 3)) * 4
    dirs = rng.normal(size=(5, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    dirs[4] = dirs[0]                                   # parallel rays: no closest depth between them
    got = rr._closest_depths_all(centres, dirs)
    for i in range(5):
        ref = []
        for j in range(5):
            if j == i or abs(abs(dirs[i] @ dirs[j]) - 1) < 1e-9:
                continue
            A = np.stack([dirs[i], -dirs[j]], axis=1)
            t, _ = np.linalg.lstsq(A, centres[j] - centres[i], rcond=None)[0]
            if t > 0:
                ref.append(t)
        np.testing.assert_allclose(np.sort(got[i]), np.sort(ref), rtol=1e-9)


def test_two_views_tls_optimum_is_min_of_l2_and_thresholds():
    """With N = 2 the TLS optimum is min(L2*, c_1^2, c_2^2) (a single inlier is reached on its ray): a wrong match
    far beyond both thresholds gives f* = min c^2, certified, and gamma_ub = sqrt(min c^2 / 4)."""
    K = np.array([[800.0, 0, 400], [0, 800, 300], [0, 0, 1]])
    P1 = K @ np.hstack([np.eye(3), [[0.0], [0], [5]]])
    P2 = K @ np.hstack([np.eye(3), [[-1.0], [0], [5]]])
    X = np.array([0.1, 0.2, 0.3])
    x1 = (P1 @ np.append(X, 1))[:2] / (P1 @ np.append(X, 1))[2]
    x2 = (P2 @ np.append(X, 1))[:2] / (P2 @ np.append(X, 1))[2] + [0.0, 250.0]     # off the epipolar line
    c = np.array([10.0, 6.0])
    res = tritools.triangulate(np.array([P1, P2]), [tritools.Point(x1), tritools.Point(x2)], robust=c)
    assert res.optimal
    np.testing.assert_allclose(res.gamma_ub, np.sqrt(36.0 / 4), rtol=1e-6)
    assert res.gamma_lb <= res.gamma_ub
    assert int(np.sum(res.inliers)) == 1


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_a_free_ray_optimum_in_a_georeferenced_world_is_placed_in_the_scene(seed):
    """Review 8 F3: c below the noise, so the optimum is any point of one view's ray (value 2 c^2); a world shifted by
    ~1e7 certified nothing when the ray candidate sat next to another camera's centre (its rounding moves that view's
    projection beyond the coordinates' resolution).  Among equal values the depth nearest the scene is taken: the
    shifted problem certifies the origin problem's value."""
    rng = np.random.default_rng(seed)
    Ps = random_cameras(3, rng)
    X = rng.normal(size=3)
    h = np.einsum("nij,j->ni", Ps, np.append(X, 1.0))
    xs = h[:, :2] / h[:, 2:] + rng.normal(size=(3, 2))
    xs[0] += [150, -80]
    T = rng.uniform(-1, 1, 3) * 1e7
    M = np.eye(4)
    M[:3, 3] = -T
    ref = tritools.triangulate(Ps, xs, robust=0.5)
    r = tritools.triangulate(Ps @ M, xs, robust=0.5)
    assert ref.optimal and r.optimal, (r.status, r.message)
    assert r.gamma_ub == pytest.approx(ref.gamma_ub, rel=1e-6)
    assert r.gamma_lb <= np.sqrt(2 * 0.25 / 6) * (1 + 1e-9)          # the ray value 2 c^2, an attained optimum
