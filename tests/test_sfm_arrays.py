"""The vectorised model path against a per-point reference built from the object API, exact data,
Hartley-Sturm, per-camera skipping, cheirality, chunking, options and the certificate sidecar."""
from __future__ import annotations

import numpy as np
import pytest

from tests.reference.hartley_sturm import hartley_sturm
from tests.test_colmap import CAMERAS, synthetic_model
from tritools import Point, Status, triangulate_many
from tritools.io.colmap import (Camera, Image, Model, ModelArrays, Point3D, pixels_from_camera, projection_matrix,
                                qvec_from_rotation, reprojection_error, undistorted_pixels)
from tritools.io.colmap.camera_models import camera_problem
from tritools.sfm import (CERTIFICATES_FILE, OptionError, RetriangulationOptions, certify_stack, read_certificates,
                          retriangulate, retriangulate_arrays, write_certificates)
from tritools.sfm.certify import CertifyOptions, STATUS_LEGEND
from tritools.sfm.synthetic import synthetic_arrays


def mixed_model(seed=3):
    """The five OPENCV-family camera models, plus image 2 on an EQUIRECTANGULAR camera and image 4 on a
    PINHOLE camera with focal length 0: their observations must be left out."""
    model, truth = synthetic_model(n_points=40, noise_px=0.5, seed=seed)
    cams = dict(CAMERAS)
    cams[6] = Camera(6, "EQUIRECTANGULAR", 640, 480, (640, 480))
    cams[7] = Camera(7, "PINHOLE", 640, 480, (0.0, 800.0, 320.0, 240.0))
    images = dict(model.images)
    for iid, cid in ((2, 6), (4, 7)):
        im = images[iid]
        images[iid] = Image(im.id, im.qvec, im.tvec, cid, im.name, im.points2D)
    return Model(cams, images, model.points3D), truth


def reference(model, min_len=2):
    """Per point, with the object API only: usable observations, undistorted keypoint by keypoint,
    projection_matrix per image, then triangulate_many (Corollary 1, delta 2, path auto)."""
    ids, problems, skipped = [], [], {}
    for pid in sorted(model.points3D):
        cams, regions = [], []
        for iid, idx in model.points3D[pid].track:
            cam = model.cameras[model.images[iid].camera_id]
            if camera_problem(cam.model, cam.params) is not None:
                continue
            xy, ok = undistorted_pixels(cam.model, cam.params, np.array(model.images[iid].points2D[idx][:2]))
            assert ok.all()
            cams.append(projection_matrix(model, iid))
            regions.append(Point(xy[0]))
        if len(cams) < min_len:
            skipped[pid] = len(cams)
            continue
        ids.append(pid)
        problems.append((np.array(cams), regions))
    results = triangulate_many(problems, "corollary1", 2, 2, path="auto", progress=False)
    return dict(zip(ids, results)), skipped


def test_arrays_path_agrees_with_the_object_reference_on_mixed_cameras():
    model, _ = mixed_model()
    new, report = retriangulate(model)
    ref, skipped = reference(model)
    assert report.n_points == 40 and [c[0] for c in report.skipped_cameras] == [6, 7]
    assert "focal length fx = 0.0 must be > 0" in report.skipped_cameras[1][2]
    assert report.n_skipped_observations == sum(
        model.cameras[model.images[i].camera_id].id in (6, 7) for p in model.points3D.values() for i, _ in p.track)
    for r in report.records:
        if r.point3D_id in skipped:
            assert r.status == Status.INVALID_INPUT and "min_track_length 2" in r.message and not r.updated
            assert new.points3D[r.point3D_id] == model.points3D[r.point3D_id]
            continue
        res = ref[r.point3D_id]
        assert r.status == res.status and r.optimal == bool(res.optimal) and r.certified_by == res.certified_by
        assert r.n_views == len(res.image_points)
        assert np.allclose(new.points3D[r.point3D_id].xyz, res.X, rtol=0, atol=1e-9)
        assert abs(r.gamma_ub - res.gamma_ub) < 1e-9 and abs(r.gamma_lb - res.gamma_lb) < 1e-9
        p = model.points3D[r.point3D_id]
        usable = tuple(e for e in p.track if model.images[e[0]].camera_id not in (6, 7))
        # COLMAP's error over the usable observations, by the object formula
        assert new.points3D[r.point3D_id].error == pytest.approx(
            reprojection_error(model, new.points3D[r.point3D_id].xyz, usable), rel=1e-12)
    assert report.n_certified == sum(r.optimal for r in ref.values())


def test_exact_observations_give_the_true_points():
    a, truth = synthetic_arrays(n_points=300, n_images=10, camera="OPENCV", noise_px=0.0, seed=5)
    new, report = retriangulate_arrays(a)
    assert report.n_certified == 300
    # exact data: gamma* = 0 at the true point; 1e-6 of the scene's size (10) bounds the
    # undistortion (1e-10 px) and the local solver's accuracy
    assert np.max(np.linalg.norm(new.point_xyz - truth, axis=1)) < 1e-5
    assert np.max(report.gamma_ub) < 1e-6 and np.max(new.point_error) < 1e-6
    assert np.all(report.gamma_lb <= report.gamma_ub + 1e-9)


def test_two_view_points_match_hartley_sturm():
    a, _ = synthetic_arrays(n_points=200, n_images=8, camera="PINHOLE", noise_px=1.0, seed=6)
    model = a.to_model()
    _, report = retriangulate_arrays(a)
    two = np.nonzero(report.n_views == 2)[0]
    assert two.size > 40
    for i in two:
        p = model.points3D[int(a.point_ids[i])]
        P = [projection_matrix(model, iid) for iid, _ in p.track]
        x = [np.array(model.images[iid].points2D[k][:2]) for iid, k in p.track]
        _, cost = hartley_sturm(P[0], P[1], x[0], x[1])
        assert report.certified[i] and abs(report.gamma_ub[i] - np.sqrt(cost / 4)) < 1e-7


def test_chunks_do_not_change_the_answer():
    a, _ = synthetic_arrays(n_points=400, n_images=12, camera="OPENCV", seed=8)
    whole, r1 = retriangulate_arrays(a)
    parts, r2 = retriangulate_arrays(a, RetriangulationOptions(chunk_points=37))
    assert np.allclose(whole.point_xyz, parts.point_xyz, rtol=0, atol=1e-9)
    assert np.array_equal(r1.status, r2.status) and np.array_equal(r1.updated, r2.updated)


# ----------------------------------------------------------------------------- cheirality
def behind_model():
    """Two PINHOLE cameras at x = -1 and x = +1 looking along +z.  Point 1's keypoints are the exact
    projections of (0.3, 0.2, -50): the L2 optimum (gamma* = 0) lies *behind* both cameras.  Point 2
    is an ordinary point in front."""
    cam = Camera(1, "PINHOLE", 640, 480, (800.0, 800.0, 320.0, 240.0))
    q = tuple(qvec_from_rotation(np.eye(3)))
    kps = {1: [], 2: []}
    for X, pid in ((np.array([0.3, 0.2, -50.0]), 1), (np.array([0.1, -0.2, 8.0]), 2)):
        for iid, c in ((1, -1.0), (2, 1.0)):
            x = pixels_from_camera("PINHOLE", cam.params, X - np.array([c, 0, 0]))[0]
            kps[iid].append((float(x[0]), float(x[1]), pid))
    images = {i: Image(i, q, (-c, 0.0, 0.0), 1, f"im{i}.png", tuple(kps[i])) for i, c in ((1, -1.0), (2, 1.0))}
    points = {1: Point3D(1, (0.3, 0.2, 50.0), track=((1, 0), (2, 0))),
              2: Point3D(2, (0.1, -0.2, 8.1), track=((1, 1), (2, 1)))}
    return Model({1: cam}, images, points)


def test_point_behind_the_cameras_is_flagged_and_not_written_by_default(tmp_path):
    model = behind_model()
    new, report = retriangulate(model)
    r1, r2 = report.records
    assert r1.status == Status.OPTIMAL and r1.optimal and r1.gamma_ub < 1e-9     # the solver certifies it ...
    assert not r1.in_front and not r1.certified and not r1.updated              # ... but it is behind
    assert "behind camera" in r1.message and "input point kept" in r1.message
    assert new.points3D[1] == model.points3D[1]                                 # z = +50 kept, not -50
    assert r2.certified and r2.in_front and np.allclose(new.points3D[2].xyz, (0.1, -0.2, 8.0), atol=1e-9)
    assert report.n_behind == 1 and report.n_certified == 1
    write_certificates(report, tmp_path)
    line = [ln for ln in (tmp_path / CERTIFICATES_FILE).read_text().splitlines() if ln.startswith("1 ")][0]
    t = line.split(None, 11)
    assert t[4] == "0" and t[5] == "optimal" and t[10] == "0" and t[11].startswith("behind camera")
    back = read_certificates(tmp_path)[1]
    assert (back.status, back.optimal, back.in_front, back.certified) == (Status.OPTIMAL, True, False, False)
    new_w, report_w = retriangulate(model, behind="write")
    r1w = report_w.records[0]
    assert r1w.updated and not r1w.certified and not r1w.in_front and "written anyway" in r1w.message
    assert np.allclose(new_w.points3D[1].xyz, (0.3, 0.2, -50.0), atol=1e-6)


# ----------------------------------------------------------------------------- options, stack, sidecar
@pytest.mark.parametrize("kw, field, text", [
    ({"delta": 3}, "delta", "must be an even integer >= 2, got 3"),
    ({"delta": 4, "max_delta": 2}, "max_delta", "must be >= delta (4), got 2"),
    ({"max_delta": 0}, "max_delta", "must be an even integer >= 2"),
    ({"min_track_length": 1}, "min_track_length", "must be an integer >= 2"),
    ({"max_track_length": 2, "min_track_length": 3}, "max_track_length", "must be >= min_track_length (3)"),
    ({"behind": "drop"}, "behind", "must be one of keep-input, write"),
    ({"method": "nms"}, "method", "must be one of"),
    ({"chunk_points": 0}, "chunk_points", "must be an integer >= 1"),
])
def test_options_are_validated_with_their_name(kw, field, text):
    with pytest.raises(OptionError) as exc:
        RetriangulationOptions(**kw)
    assert exc.value.field == field and text in exc.value.detail


def test_default_degrees_are_bounded():
    """The model path has the defaults of tritools.triangulate (method auto, the per-point budget: no point may
    take minutes or gigabytes); max_delta=2 keeps every point at delta = 2."""
    from tritools.solve.options import DEFAULT_OPTIONS, TRIANGULATION_BUDGET

    o = RetriangulationOptions()
    assert o.solver == DEFAULT_OPTIONS and o.certify_options().triangulation_options() == DEFAULT_OPTIONS
    assert (o.method, o.path, o.delta, o.max_delta) == ("auto", "auto", None, None)
    assert o.solver.budget == TRIANGULATION_BUDGET
    assert RetriangulationOptions(max_delta=2).solver.max_delta == 2
    assert RetriangulationOptions(delta=4).solver.delta == 4
    t1 = RetriangulationOptions(method="theorem1", solver=DEFAULT_OPTIONS.replace(time_limit=5))
    assert (t1.solver.method.value, t1.solver.budget.time_limit) == ("theorem1", 5)


def test_certify_stack_returns_arrays_and_reports_what_it_does_not_certify():
    a, _ = synthetic_arrays(n_points=60, n_images=6, camera="PINHOLE", seed=9)
    m = a.to_model()
    two = [p for p in m.points3D.values() if len(p.track) == 2][:5]
    C = np.array([[projection_matrix(m, iid) for iid, _ in p.track] for p in two])
    x = np.array([[m.images[iid].points2D[k][:2] for iid, k in p.track] for p in two])
    C[0, 1] = C[0, 0]                                           # one problem with two identical cameras
    s = certify_stack(C, x, CertifyOptions())
    assert s.X.shape == (5, 3) and s.status.dtype == np.int8
    assert [STATUS_LEGEND[k] for k in s.status[1:]] == ["optimal"] * 4 and list(s.certified_by[1:]) == \
        ["verification"] * 4
    assert STATUS_LEGEND[s.status[0]] != "optimal" and s.message[0]


def test_sidecar_reads_old_ten_column_files(tmp_path):
    (tmp_path / CERTIFICATES_FILE).write_text("# old\n7 3 0.5 0.5 1 optimal 2 verification 0.75 1\n"
                                              "8 2 nan nan 0 invalid_input -1 - nan 0\n")
    c = read_certificates(tmp_path)
    assert c[7].certified and c[7].in_front and c[7].gamma_input == 0.75 and c[8].gamma_lb is None


def test_sidecar_round_trip_with_messages(tmp_path):
    model, _ = mixed_model(seed=4)
    _, report = retriangulate(model, min_track_length=3)
    write_certificates(report, tmp_path)
    back = read_certificates(tmp_path)
    assert sorted(back) == sorted(model.points3D)
    for r in report.records:
        b = back[r.point3D_id]
        assert (b.status, b.certified, b.updated, b.in_front, b.n_views, b.delta) == \
            (r.status, r.certified, r.updated, r.in_front, r.n_views, r.delta)
        assert (b.gamma_lb, b.gamma_ub, b.gamma_input) == (r.gamma_lb, r.gamma_ub, r.gamma_input)   # repr: exact
        assert b.message == " ".join(r.message.split())
    assert any("left out" in b.message for b in back.values())


def test_model_arrays_conversion_is_exact():
    model, _ = mixed_model(seed=5)
    a = ModelArrays.from_model(model)
    assert a.to_model() == model and a.n_points == 40 and a.n_observations == sum(
        len(p.track) for p in model.points3D.values())
