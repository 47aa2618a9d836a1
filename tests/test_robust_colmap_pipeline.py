"""The COLMAP pipeline with ``robust`` (review 6): cheirality is judged on the observations the robust estimate
keeps, and an estimate that keeps fewer than two observations does not move the point."""
import numpy as np

import tritools

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
    # the TLS optimum is certified, but the written point is the input one: not CERTIFIED anywhere (review 24b S1)
    assert rep.records[0].status.value == "optimal" and rep.records[0].optimal
    assert not rep.records[0].certified and not rep.certified[0] and rep.n_certified == 0
    from tritools.sfm.certificates import write_certificates
    import tempfile
    with tempfile.TemporaryDirectory() as d:
        row = write_certificates(rep, d).read_text().splitlines()[-1].split()
        assert row[4] == "0" and row[5] == "optimal" and row[9] == "0"        # CERTIFIED, STATUS, UPDATED
    assert rng is not None


def _tls_gamma(model, xyz, track, c):
    """TLS gamma of xyz over a track (PINHOLE cameras, own projection)."""
    from tritools.io.colmap.model import rotation_from_qvec

    d2 = []
    for img, kp in track:
        im = model.images[img]
        fx, fy, cx, cy = model.cameras[im.camera_id].params
        x = rotation_from_qvec(im.qvec) @ np.asarray(xyz) + np.asarray(im.tvec)
        u = (fx * x[0] / x[2] + cx, fy * x[1] / x[2] + cy)
        d2.append(min((u[0] - im.points2D[kp][0]) ** 2 + (u[1] - im.points2D[kp][1]) ** 2, c * c))
    return float(np.sqrt(np.sum(d2) / (2 * len(track))))


def test_uncertified_robust_estimates_are_written_only_where_no_worse_in_tls(tmp_path):
    """GAMMA_INPUT is the input point's TLS gamma with the same threshold, so an uncertified robust estimate
    replaces the input only where its TLS gamma is no larger (review 6 F4: it was compared with the input's L2
    gamma, wrong matches included, and all-outlier estimates replaced inputs)."""
    from tests.test_robust_inmemory import _model_with_wrong_matches

    m, _ = _model_with_wrong_matches(tmp_path, seed=2)
    new, rep = retriangulate(m, robust=5.0, solver=tritools.TriangulationOptions().replace(time_limit=1e-4))
    c = 5.0
    checked = 0
    for pid, upd, rec in zip(rep.point_ids, rep.updated, rep.records):
        old = m.points3D[int(pid)]
        g_in = _tls_gamma(m, old.xyz, old.track, c)
        assert abs(rec.gamma_input - g_in) <= 1e-6 * max(1.0, g_in)
        if upd and not rec.certified:
            checked += 1
            assert _tls_gamma(m, new.points3D[int(pid)].xyz, old.track, c) <= g_in * (1 + 1e-9)
    assert checked > 0


def test_robust_option_refuses_text():
    import pytest

    from tritools.sfm import OptionError, RetriangulationOptions

    for bad in ("5", b"5", [5.0]):
        with pytest.raises(OptionError, match="robust"):
            RetriangulationOptions(robust=bad)
    assert RetriangulationOptions(robust=np.float32(2.5)).robust == 2.5


def _away_model():
    """Six tracks of five views plus a wrong match in a sixth camera facing away (the first test's scene)."""
    rng = np.random.default_rng(0)
    cams = _ring(5, away=True)
    tracks = []
    for X in rng.uniform(-0.5, 0.5, size=(6, 3)):
        h = cams @ np.append(X, 1.0)
        obs = h[:, :2] / h[:, 2:] + rng.normal(size=(6, 2)) * 0.5
        obs[5] = rng.uniform([0, 0], [640, 480])
        tracks.append({j: tuple(obs[j]) for j in range(6)})
    return model_from_projections(cams, (640, 480), tracks)


def test_the_inlier_set_is_reported_as_data(tmp_path, capsys):
    """Review 24b M2: the inlier count and the removed (image id, keypoint index) pairs per point, in the records
    and the JSON of ``tritools colmap --robust`` (before: free text in MESSAGE only)."""
    import json

    from tests.cli_util import run
    from tritools.io.colmap.formats import write_model

    m = _away_model()
    new, rep = retriangulate(m, robust=5.0)
    away = max(m.images)
    for pid, r in zip(sorted(m.points3D), rep.records):
        gone = {e for e in m.points3D[pid].track} - set(new.points3D[pid].track)
        assert r.n_inliers == 5 and set(r.removed_observations) == gone and len(gone) == 1
        assert all(img == away for img, _ in r.removed_observations)
        assert all(new.images[img].points2D[kp][2] == -1 for img, kp in r.removed_observations)
    plain = retriangulate(m)[1]
    assert plain.n_inliers is None and plain.records[0].n_inliers is None
    assert plain.records[0].removed_observations == ()
    write_model(m, tmp_path / "in", "bin")
    rc, out, _ = run(["colmap", tmp_path / "in", tmp_path / "out", "--robust", "5", "--json"], capsys)
    assert rc == 0
    points = json.loads(out)["points"]
    assert [p["n_inliers"] for p in points] == [5] * 6
    assert [sorted(map(tuple, p["removed_observations"])) for p in points] == \
        [sorted(r.removed_observations) for r in rep.records]
