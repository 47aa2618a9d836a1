"""`retriangulate(model, robust=c)` in memory (a tritools Model or a pycolmap.Reconstruction) removes the outlier
observations from the tracks and unlinks their keypoints, as `tritools colmap --robust` does on disk (a reviewer's
finding: the in-memory paths kept every track unchanged and wrote an ERROR over the inliers only)."""
import dataclasses

import numpy as np
import pytest

from tritools.io.colmap import read_model, write_model_arrays
from tritools.io.colmap.model import NO_POINT3D
from tritools.sfm import retriangulate
from tritools.sfm.synthetic import synthetic_arrays


def _model_with_wrong_matches(tmp_path, seed=0):
    """A synthetic model and a set of (point id, image id, keypoint) moved by 150 px (own bookkeeping)."""
    a, truth = synthetic_arrays(n_points=40, n_images=8, camera="PINHOLE", seed=seed)
    write_model_arrays(a, tmp_path / "clean", "txt")
    m = read_model(tmp_path / "clean")
    rng = np.random.default_rng(seed)
    images, bad = dict(m.images), set()
    for pid, pt in m.points3D.items():
        if len(pt.track) < 4 or rng.uniform() > 0.5:
            continue
        img, kp = pt.track[int(rng.integers(len(pt.track)))]
        pts = list(images[img].points2D)
        u, v, p3 = pts[kp]
        pts[kp] = (u + 120.0, v - 90.0, p3)
        images[img] = dataclasses.replace(images[img], points2D=tuple(pts))
        bad.add((pid, img, kp))
    assert bad
    return dataclasses.replace(m, images=images), bad


def _own_error(model, pt):
    """Mean reprojection error (px) of pt over its track, computed here from the cameras (PINHOLE)."""
    from tritools.io.colmap.model import rotation_from_qvec

    errs = []
    for img, kp in pt.track:
        im = model.images[img]
        fx, fy, cx, cy = model.cameras[im.camera_id].params
        x = rotation_from_qvec(im.qvec) @ np.asarray(pt.xyz) + np.asarray(im.tvec)
        errs.append(np.hypot(fx * x[0] / x[2] + cx - im.points2D[kp][0], fy * x[1] / x[2] + cy - im.points2D[kp][1]))
    return float(np.mean(errs))


def test_model_in_memory_drops_outliers(tmp_path):
    m, bad = _model_with_wrong_matches(tmp_path)
    new, rep = retriangulate(m, robust=5.0)
    updated = {int(p) for p, u in zip(rep.point_ids, rep.updated) if u}
    assert {p for p, _, _ in bad} <= updated
    for pid, img, kp in bad:
        pt = new.points3D[pid]
        assert (img, kp) not in pt.track
        assert new.images[img].points2D[kp][2] == NO_POINT3D
        assert len(pt.track) == len(m.points3D[pid].track) - 1
        assert _own_error(new, pt) < 3.0 and abs(pt.error - _own_error(new, pt)) < 1e-6
    others = set(m.points3D) - {p for p, _, _ in bad}
    assert all(new.points3D[p].track == m.points3D[p].track for p in others)
    # without robust nothing leaves a track
    plain, _ = retriangulate(m)
    assert all(plain.points3D[p].track == m.points3D[p].track for p in m.points3D)


def test_pycolmap_reconstruction_drops_outliers(tmp_path):
    pycolmap = pytest.importorskip("pycolmap")
    from tritools.io.colmap import write_text_model

    m, bad = _model_with_wrong_matches(tmp_path, seed=1)
    write_text_model(m, tmp_path / "in")
    rec = pycolmap.Reconstruction(str(tmp_path / "in"))
    out, rep = retriangulate(rec, robust=5.0)
    for pid, img, kp in bad:
        track = {(e.image_id, e.point2D_idx) for e in out.points3D[pid].track.elements}
        assert (img, kp) not in track and len(track) == len(m.points3D[pid].track) - 1
        assert not out.images[img].points2D[kp].has_point3D()
    assert len(rec.points3D[next(iter(bad))[0]].track.elements) == len(m.points3D[next(iter(bad))[0]].track)
