"""Tests of tritools.scene: synthetic scenes, the Example 5 protocol (paper §5.5) and the
paper's example data."""
import json

import numpy as np
import pytest

from tritools.model.geometry import camera_center, depths, gamma, image_points
from tritools.model.regions import EllipseBorder, Point, Segment
from tritools.scene import (EXAMPLE5_MIN_DEPTH, SyntheticScene, example5_cameras, example5_cases, paper_data,
                            paper_example, paper_table, random_cameras, random_scene, turntable_cameras)


# ---------------------------------------------------------------- random scenes
def test_random_cameras_look_at_origin():
    rng = np.random.default_rng(0)
    C = random_cameras(5, rng, radius=10.0, focal=800.0, image_size=(640, 480))
    assert C.shape == (5, 3, 4)
    x = image_points(np.zeros(3), C)
    assert np.allclose(x, [320.0, 240.0], atol=1e-9)       # origin projects to the principal point
    assert np.allclose(depths(np.zeros(3), C), 10.0)
    with pytest.raises(ValueError, match="n_views"):
        random_cameras(0, rng)
    with pytest.raises(ValueError, match="focal"):
        random_cameras(2, rng, focal=-1.0)


def test_random_scene_reproducible_and_valid():
    a = random_scene(4, 30, noise_px=1.0, seed=11)
    b = random_scene(4, 30, noise_px=1.0, seed=11)
    c = random_scene(4, 30, noise_px=1.0, seed=12)
    assert np.array_equal(a.points2d, b.points2d) and np.array_equal(a.cameras, b.cameras)
    assert not np.array_equal(a.points3d, c.points3d)
    assert a.points2d.shape == (30, 4, 2) and a.points3d.shape == (30, 3)
    assert np.all(depths(a.points3d, a.cameras) > 0)
    assert np.allclose(a.points2d_true, image_points(a.points3d, a.cameras), atol=1e-9)
    noise = (a.points2d - a.points2d_true).ravel()
    assert 0.8 < noise.std() < 1.2 and abs(noise.mean()) < 0.2
    for j in range(3):
        assert gamma(a.points3d[j], a.cameras, a.regions(j, noisy=False)) < 1e-9
    assert len(a.regions(0)) == 4 and isinstance(a.regions(0)[0], Point)
    with pytest.raises(ValueError):
        a.points2d[0, 0, 0] = 1.0                         # read-only


def test_scene_validators():
    s = random_scene(2, 3, noise_px=0.0, seed=1)
    behind = s.points3d.copy()
    c0 = camera_center(s.cameras[0])
    behind[0] = 2 * c0 - s.points3d[0]          # mirrored through camera 0's centre: negative depth
    assert depths(behind[0], s.cameras)[0] < 0
    with pytest.raises(ValueError, match="front of every camera"):
        SyntheticScene(s.cameras, behind, s.points2d_true, s.points2d)
    with pytest.raises(ValueError, match="outside"):
        SyntheticScene(s.cameras, s.points3d, s.points2d_true + 1e4, s.points2d)
    with pytest.raises(ValueError, match=r"points2d must have shape \(3, 2, 2\)"):
        SyntheticScene(s.cameras, s.points3d, s.points2d_true, s.points2d[:, :1])
    with pytest.raises(ValueError, match="noise_px"):
        random_scene(2, 3, noise_px=-1.0)
    with pytest.raises(ValueError, match="point_radius"):
        random_scene(2, 3, point_radius=20.0)


def test_turntable_cameras_coplanar_centres_looking_at_origin():
    C = turntable_cameras(7, 3, radius=2.0)
    centres = np.array([camera_center(P) for P in C])
    assert np.allclose(centres[:, 2], 0.0, atol=1e-12)                        # one horizontal plane
    assert np.allclose(np.linalg.norm(centres[:, :2], axis=1), 2.0)
    assert np.all(depths(np.zeros(3), C) > 0)
    assert np.allclose(image_points(np.zeros(3), C), [1054.0, 581.0])       # the origin at the principal point
    assert np.array_equal(C, turntable_cameras(7, 3))                        # seeded
    lifted = np.array([camera_center(P) for P in turntable_cameras(7, 3, height=0.5, jitter=0.01)])
    assert 0.4 < lifted[:, 2].mean() < 0.6 and lifted[:, 2].std() > 0
    for bad in (dict(N=1), dict(N=2.5), dict(N=4, jitter=-1.0), dict(N=4, radius=0.0),
                dict(N=4, height=np.nan)):
        with pytest.raises(ValueError, match=next(iter(k for k in bad if k != "N"), "N")):
            turntable_cameras(rng=0, **bad)


# ---------------------------------------------------------------- paper data
def test_paper_examples_load():
    for k, types in ((2, (EllipseBorder, Point, Point)), (3, (Segment, Segment, Point)), (4, (Point,) * 4)):
        C, R = paper_example(k)
        assert C.shape == (len(types), 3, 4)
        assert tuple(type(r) for r in R) == types
    C, R = paper_example(2)
    assert np.allclose(R[0].D, np.eye(2) / 9)              # radius 1/3, see the data notes
    assert paper_table(4)[0]["gamma"] == pytest.approx(0.76)
    with pytest.raises(ValueError, match="k must be 2, 3 or 4"):
        paper_example(5)
    # the packaged copy equals the shared data
    with open("/work/shared/data/paper_examples.json") as f:
        shared = json.load(f)
    assert paper_data()["example4"] == shared["example4"]


# ---------------------------------------------------------------- Example 5
@pytest.fixture(scope="module")
def cases():
    return example5_cases(seed=0)


def test_example5_protocol_shape(cases):
    assert len(cases) == 1000
    assert [c.theta for c in cases[:40:10]] == [0.05, 0.1, 0.15, 0.2]
    assert [(c.point_index, c.trial) for c in cases[:3]] == [(0, 0), (0, 1), (0, 2)]
    assert len({c.point_index for c in cases}) == 25
    for theta in (0.05, 0.1, 0.15, 0.2):
        assert sum(c.theta == theta for c in cases) == 250


def test_example5_cameras_normalised():
    C = example5_cameras()
    C4, _ = paper_example(4)
    assert np.allclose(np.linalg.norm(C, ord=2, axis=(1, 2)), 1.0)
    for P, Q in zip(C, C4):
        assert np.allclose(P * np.linalg.norm(Q, 2), Q)


def test_example5_noise_bounds_and_visibility(cases):
    for c in cases:
        assert np.all(np.abs(c.X_obj) <= 1.0)
        assert np.all(depths(c.X_obj, c.cameras_true) > EXAMPLE5_MIN_DEPTH)
        assert np.allclose(c.image_points_true, image_points(c.X_obj, c.cameras_true))
        A = np.max(np.linalg.norm(c.image_points_true, axis=1))
        assert np.all(np.abs(c.image_points - c.image_points_true) <= c.theta * A)
        assert np.all(np.abs(c.cameras - c.cameras_true) <= c.theta)
        assert all(isinstance(r, Point) for r in c.regions)
    # the noise actually uses its range (uniform, not degenerate)
    big = [c for c in cases if c.theta == 0.2]
    rel = np.concatenate([np.abs(c.cameras - c.cameras_true).ravel() for c in big]) / 0.2
    assert rel.max() > 0.99 and 0.45 < rel.mean() < 0.55


def test_example5_reproducible():
    a = example5_cases(seed=3, n_points=2, trials=2)
    b = example5_cases(seed=3, n_points=2, trials=2)
    c = example5_cases(seed=4, n_points=2, trials=2)
    assert len(a) == 16
    assert all(np.array_equal(x.cameras, y.cameras) and np.array_equal(x.image_points, y.image_points)
               for x, y in zip(a, b))
    assert not np.array_equal(a[0].X_obj, c[0].X_obj)
    with pytest.raises(ValueError, match="n_points"):
        example5_cases(n_points=0)
    with pytest.raises(ValueError, match="thetas"):
        example5_cases(thetas=(-0.1,))
