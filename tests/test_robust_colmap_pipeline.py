"""The COLMAP pipeline with ``robust`` (review 6): cheirality is judged on the observations the robust estimate
keeps, and an estimate that keeps fewer than two observations does not move the point."""
import numpy as np

from tritools.io.colmap import model_from_projections
from tritools.sfm import retriangulate


def _look_at(C, target, f=800.0):
    z = (target - C) / np.linalg.norm(target - C)
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    R = np.array([x, np.cross(z, x), z])
    K = np.array([[f, 0, 320.0], [0, f, 240.0], [0, 0, 1]])
    return K @ np.hstack([R, -R @ C[:, None]])


def _ring(n, away=False):
    cams = [_look_at(np.array([10 * np.cos(a), 0.5, 10 * np.sin(a)]), np.zeros(3)) for a in np.linspace(0, 1.2, n)]
    if away:
        cams.append(_look_at(np.array([0.0, 0.0, -4.0]), np.array([0.0, 0.0, -20.0])))   # faces away from the scene
    return np.array(cams)


def test_wrong_match_in_a_camera_facing_away_is_removed_and_the_point_written():
    rng = np.random.default_rng(0)
    cams = _ring(5, away=True)
    pts = rng.uniform(-0.5, 0.5, size=(6, 3))
    tracks = []
    for X in pts:
        h = cams @ np.append(X, 1.0)
        obs = h[:, :2] / h[:, 2:] + rng.normal(size=(6, 2)) * 0.5
        obs[5] = rng.uniform([0, 0], [640, 480])               # a wrong match, "behind" its camera
        tracks.append({j: tuple(obs[j]) for j in range(6)})
    m = model_from_projections(cams, (640, 480), tracks)
    new, rep = retriangulate(m, robust=5.0)
    assert rep.updated.all()
    away_image = max(m.images)                                  # the last image holds the camera facing away
    for pid, X in zip(sorted(m.points3D), pts):
        assert all(img != away_image for img, _ in new.points3D[pid].track)
        assert len(new.points3D[pid].track) == 5
        assert np.linalg.norm(np.asarray(new.points3D[pid].xyz) - X) < 0.05


def test_two_view_track_keeping_one_observation_is_not_moved():
    rng = np.random.default_rng(1)
    cams = _ring(2)
    X = np.array([0.1, -0.2, 0.05])
    h = cams @ np.append(X, 1.0)
    obs = h[:, :2] / h[:, 2:]
    obs[1] += [120.0, -90.0]                                    # 150 px: L2 of both views >> c^2
    m = model_from_projections(cams, (640, 480), [{0: tuple(obs[0]), 1: tuple(obs[1])}])
    pid = next(iter(m.points3D))
    new, rep = retriangulate(m, robust=5.0)
    assert not rep.updated[0]
    assert new.points3D[pid].xyz == m.points3D[pid].xyz and new.points3D[pid].track == m.points3D[pid].track
    assert "not determined" in rep.records[0].message
    assert rng is not None
