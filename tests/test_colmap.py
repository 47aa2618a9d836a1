"""COLMAP text models: exact round trip, camera models and undistortion, certified re-triangulation
against independent references (Hartley-Sturm, multi-start least squares), the certificate
sidecar, conversion from projection matrices and Oxford data, and the CLI subcommands."""
from __future__ import annotations

import argparse
import json
import re

import numpy as np
import pytest

from tests.reference.hartley_sturm import hartley_sturm
from tests.reference.multistart import best_local_gamma
from tritools import Status
from tritools.io.colmap import (Camera, Image, Model, ModelFormatError, Point3D, SkewError, UnsupportedCameraModelError,
                                distort, intrinsics, model_from_oxford, model_from_projections, pixels_from_camera,
                                projection_matrix, qvec_from_rotation, read_text_model, reprojection_error,
                                rotation_from_qvec, undistort, undistorted_pixels, write_text_model)
from tritools.sfm import CERTIFICATES_FILE, CameraError, read_certificates, retriangulate, write_certificates
from tritools.io.colmap.camera_models import UNDISTORT_RTOL
from tritools.cli.colmap import register
from tritools.io.oxford import load_sequence

#: one camera per supported model (f ~ 800 px, 640 x 480 images, realistic distortion).
CAMERAS = {
    1: Camera(1, "SIMPLE_PINHOLE", 640, 480, (800.0, 320.0, 240.0)),
    2: Camera(2, "PINHOLE", 640, 480, (810.5, 790.25, 318.0, 242.5)),
    3: Camera(3, "SIMPLE_RADIAL", 640, 480, (805.0, 321.0, 239.0, -0.08)),
    4: Camera(4, "RADIAL", 640, 480, (795.0, 319.5, 240.5, -0.1, 0.02)),
    5: Camera(5, "OPENCV", 640, 480, (800.0, 804.0, 322.0, 238.0, -0.12, 0.03, 0.001, -0.0015)),
}


#: (fx, fy, cx, cy) of CAMERAS, read off COLMAP's parameter orders by hand (independent of intrinsics()).
FX_FY_CX_CY = {1: (800.0, 800.0, 320.0, 240.0), 2: (810.5, 790.25, 318.0, 242.5), 3: (805.0, 805.0, 321.0, 239.0),
               4: (795.0, 795.0, 319.5, 240.5), 5: (800.0, 804.0, 322.0, 238.0)}


def _look_at(C):
    z = -C / np.linalg.norm(C)
    x = np.cross([0.0, 1.0, 0.3], z)
    x /= np.linalg.norm(x)
    R = np.vstack([x, np.cross(z, x), z])
    return R, -R @ C


def synthetic_model(n_points=12, noise_px=0.0, seed=0, track_lengths=(2, 3, 4, 5), camera_ids=(1, 2, 3, 4, 5)):
    """Seeded scene: 5 images on a sphere of radius 10 looking at the origin, points in the unit
    ball, observations = COLMAP's forward projection (with distortion) + Gaussian noise.
    Returns (model, true points {id: xyz})."""
    rng = np.random.default_rng(seed)
    images, keypoints, poses = {}, {i: [] for i in range(1, 6)}, {}
    for i, cid in zip(range(1, 6), camera_ids):
        c = rng.normal(size=3)
        poses[i] = (cid, *_look_at(10.0 * c / np.linalg.norm(c)))
    points, truth = {}, {}
    for pid in range(1, n_points + 1):
        X = rng.uniform(-1, 1, 3) * 0.7
        views = sorted(rng.choice(5, size=track_lengths[pid % len(track_lengths)], replace=False) + 1)
        track = []
        for i in views:
            cid, R, t = poses[i]
            cam = CAMERAS[cid]
            x = pixels_from_camera(cam.model, cam.params, R @ X + t)[0] + noise_px * rng.normal(size=2)
            track.append((int(i), len(keypoints[i])))
            keypoints[i].append((float(x[0]), float(x[1]), pid))
        points[pid] = Point3D(pid, X + rng.normal(size=3) * 0.05, tuple(rng.integers(0, 256, 3)), 1.5, tuple(track))
        truth[pid] = X
    for i, (cid, R, t) in poses.items():
        kp = keypoints[i] + [(12.25, 400.5, -1)]               # a keypoint without a 3D point
        images[i] = Image(i, tuple(qvec_from_rotation(R)), tuple(t), cid, f"img {i:02d}.jpg", tuple(kp))
    images[6] = Image(6, (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 12.0), 1, "empty.jpg", ())   # no keypoints
    return Model(CAMERAS, images, points), truth


# ----------------------------------------------------------------------------- text format
def test_round_trip_is_exact_and_follows_colmap_layout(tmp_path):
    model, _ = synthetic_model(noise_px=0.7)
    write_text_model(model, tmp_path / "a")
    back = read_text_model(tmp_path / "a")
    assert back == model                        # ints/strings exact, floats bit-exact (repr)
    write_text_model(back, tmp_path / "b")
    for name in ("cameras.txt", "images.txt", "points3D.txt"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
    cams = (tmp_path / "a" / "cameras.txt").read_text().splitlines()
    assert cams[:3] == ["# Camera list with one line of data per camera:",
                        "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]", "# Number of cameras: 5"]
    assert cams[3] == "1 SIMPLE_PINHOLE 640 480 800.0 320.0 240.0"
    imgs = (tmp_path / "a" / "images.txt").read_text().splitlines()
    assert imgs[1] == "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME"
    assert imgs[2] == "#   POINTS2D[] as (X, Y, POINT3D_ID)"
    assert imgs[3].startswith("# Number of images: 6, mean observations per image: ")
    assert imgs[4].endswith(" 1 img 01.jpg") and imgs[5].endswith(" 12.25 400.5 -1")
    assert imgs[-2].endswith(" 1 empty.jpg") and imgs[-1] == ""          # empty POINTS2D line
    pts = (tmp_path / "a" / "points3D.txt").read_text().splitlines()
    assert pts[2].startswith("# Number of points: 12, mean track length: ")
    assert back.images[1].name == "img 01.jpg"


def test_reader_accepts_colmap_documentation_example(tmp_path):
    """The three files as printed in COLMAP's format documentation (6 significant digits)."""
    (tmp_path / "cameras.txt").write_text(
        "# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
        "# Number of cameras: 3\n1 SIMPLE_PINHOLE 3072 2304 2559.81 1536 1152\n"
        "2 PINHOLE 3072 2304 2560.56 2560.56 1536 1152\n3 SIMPLE_RADIAL 3072 2304 2559.69 1536 1152 -0.0218531\n")
    (tmp_path / "images.txt").write_text(
        "# Image list with two lines of data per image:\n"
        "1 0.851773 0.0165051 0.503764 -0.142941 -0.737434 1.02973 3.74354 1 P1180141.JPG\n"
        "2362.39 248.498 2 1784.7 268.254 -1\n"
        "2 0.851773 0.0165051 0.503764 -0.142941 -0.737434 1.02973 3.74354 3 P1180142.JPG\n"
        "1190.83 663.957 2\n")
    (tmp_path / "points3D.txt").write_text("2 1.67241 0.292931 0.609726 115 121 122 1.33927 1 0 2 0\n")
    m = read_text_model(tmp_path)
    assert m.cameras[3].params == (2559.69, 1536.0, 1152.0, -0.0218531)
    assert m.images[1].points2D == ((2362.39, 248.498, 2), (1784.7, 268.254, -1))
    assert m.points3D[2].track == ((1, 0), (2, 0)) and m.points3D[2].rgb == (115, 121, 122)


@pytest.mark.parametrize("fname, text, expect", [
    ("cameras.txt", "1 PINHOLE 640 480 800 800 320\n", "cameras.txt:1: camera model PINHOLE needs 4 PARAMS, got 3"),
    ("cameras.txt", "# c\n1 FISH 640 480 1\n", "cameras.txt:2: unknown camera MODEL 'FISH'"),
    ("cameras.txt", "1 PINHOLE 640 -4 800 800 320 240\n", "cameras.txt:1: WIDTH and HEIGHT must be positive"),
    ("cameras.txt", "1 PINHOLE 640 480 800 nan 320 240\n", "cameras.txt:1: PARAMS[1] is nan"),
    ("images.txt", "1 1 0 0 0 0 0 0 1 a.png\n1.0 2.0\n",
     "images.txt:2: POINTS2D of image 1 must be (X, Y, POINT3D_ID)"),
    ("images.txt", "1 1 0 0 0 0 0 x 1 a.png\n\n", "images.txt:1: TZ must be a number, got 'x'"),
    ("images.txt", "1 1 0 0 0 0 0 0 1 a.png\n", "images.txt:1: image 1 has no POINTS2D line"),
    ("images.txt", "1 1 0 0 0 0 0 0 9 a.png\n\n", "images.txt:1: image 1 refers to camera 9"),
    ("points3D.txt", "1 0 0 0 1 2 3 0.5 1\n", "points3D.txt:1: TRACK[] must be (IMAGE_ID, POINT2D_IDX) pairs"),
    ("points3D.txt", "1 0 0 0 1 2 300 0.5\n", "points3D.txt:1: R G B must be in 0..255"),
    # review 33a M2: ids COLMAP cannot hold (uint32; 2^32 - 1 is its invalid id) were read and written
    ("cameras.txt", "-1 PINHOLE 640 480 800 800 320 240\n", "cameras.txt:1: CAMERA_ID -1 is outside COLMAP's range"),
    ("images.txt", "4294967295 1 0 0 0 0 0 0 1 a.png\n\n", "images.txt:1: IMAGE_ID 4294967295 is outside"),
    ("images.txt", "4294967296 1 0 0 0 0 0 0 1 a.png\n\n", "images.txt:1: IMAGE_ID 4294967296 is outside"),
    ("images.txt", "1 1 0 0 0 0 0 0 -1 a.png\n\n", "images.txt:1: CAMERA_ID -1 is outside COLMAP's range"),
    ("points3D.txt", "7 0 0 0 1 2 3 0.5 1 0\n", "points3D.txt:1: point3D 7 track refers to keypoint 0 of image 1, "
                                                 "which has 0 keypoints"),
])
def test_malformed_files_name_file_and_line(tmp_path, fname, text, expect):
    files = {"cameras.txt": "1 PINHOLE 640 480 800 800 320 240\n", "images.txt": "1 1 0 0 0 0 0 0 1 a.png\n\n",
             "points3D.txt": ""}
    files[fname] = text
    for k, v in files.items():
        (tmp_path / k).write_text(v)
    with pytest.raises(ModelFormatError) as exc:
        read_text_model(tmp_path)
    assert expect in str(exc.value)


def test_missing_file_is_named(tmp_path):
    (tmp_path / "cameras.txt").write_text("")
    with pytest.raises(FileNotFoundError, match="images.txt: missing"):
        read_text_model(tmp_path)


def test_model_checks_cross_references():
    cam = {1: CAMERAS[1]}
    im = {1: Image(1, (1, 0, 0, 0), (0, 0, 5), 1, "a", ((1.0, 2.0, 3),))}
    with pytest.raises(ValueError, match="image 1 keypoint 0 refers to point3D 3, which does not exist"):
        Model(cam, im, {})
    with pytest.raises(ValueError, match="whose POINT3D_ID is 3"):
        Model(cam, im, {3: Point3D(3, (0, 0, 0), track=((1, 0),)), 4: Point3D(4, (0, 0, 0), track=((1, 0),))})


def test_quaternions_hamilton_w_first():
    a = 0.3      # rotation about z by a: Hamilton (cos a/2, 0, 0, sin a/2) -> [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    R = rotation_from_qvec((np.cos(a / 2), 0, 0, np.sin(a / 2)))
    assert np.allclose(R, [[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]], atol=1e-15)
    rng = np.random.default_rng(3)
    for _ in range(50):        # all four branches of the largest-pivot formula; 1e-14 = a few ulps
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        q2 = qvec_from_rotation(rotation_from_qvec(q))
        assert np.allclose(q2, q * np.sign(q[0]), atol=1e-14)


# ----------------------------------------------------------------------------- camera models
@pytest.mark.parametrize("cid", sorted(CAMERAS))
def test_undistortion_inverts_the_forward_model(cid):
    cam = CAMERAS[cid]
    rng = np.random.default_rng(cid)
    X_cam = np.column_stack([rng.uniform(-0.38, 0.38, 200), rng.uniform(-0.28, 0.28, 200), np.ones(200)])
    observed = pixels_from_camera(cam.model, cam.params, X_cam)     # whole image, corners included
    xy_u, ok = undistorted_pixels(cam.model, cam.params, observed)
    assert ok.all()
    fx, fy, cx, cy = FX_FY_CX_CY[cid]
    pinhole = np.column_stack([fx * X_cam[:, 0] + cx, fy * X_cam[:, 1] + cy])
    # the Newton stop is UNDISTORT_RTOL (16 ulps) on the normalised forward residual; |dD^-1| < 2 on this domain, so
    # the recovered pinhole pixel is within ~32 ulps of f; 1e-11 px at f ~ 500 leaves room for rounding
    assert np.max(np.abs(xy_u - pinhole)) < 1e-11
    uv = np.column_stack([(xy_u[:, 0] - cx) / fx, (xy_u[:, 1] - cy) / fy, np.ones(200)])
    assert np.max(np.abs(pixels_from_camera(cam.model, cam.params, uv) - observed)) <= 4 * UNDISTORT_RTOL * max(fx, fy)


def test_undistort_reports_non_convergence():
    # k1 = -1 folds the image at r^2 = 1/3 (maximum r_d = 0.385): r_d = 0.5 has no preimage
    uv, ok = undistort(np.array([[0.5, 0.0], [0.1, 0.0]]), np.array([-1.0, 0, 0, 0]))
    assert not ok[0] and ok[1]
    assert np.allclose(distort(uv[1:], np.array([-1.0, 0, 0, 0])), [[0.1, 0.0]], atol=1e-14)


def test_unsupported_model_is_skipped_or_refused_when_strict():
    cams = dict(CAMERAS)
    cams[1] = Camera(1, "EQUIRECTANGULAR", 640, 480, (640, 480))
    model, _ = synthetic_model(n_points=12)
    model = Model(cams, model.images, model.points3D)
    with pytest.raises(CameraError, match="camera 1 \\(EQUIRECTANGULAR\\) cannot be used: camera model "
                                          "'EQUIRECTANGULAR' is not supported.*spherical.*FULL_OPENCV"):
        retriangulate(model, strict=True)
    with pytest.raises(UnsupportedCameraModelError, match="'EQUIRECTANGULAR' is not supported"):
        intrinsics("EQUIRECTANGULAR", (640, 480))
    _, report = retriangulate(model)          # image 1 uses camera 1: its observations are left out
    (cid, name, reason, n_obs), = report.skipped_cameras
    assert (cid, name) == (1, "EQUIRECTANGULAR") and "not supported" in reason and n_obs > 0
    assert report.n_skipped_observations == n_obs
    for r in report.records:
        track = model.points3D[r.point3D_id].track
        in_cam1 = sum(model.images[i].camera_id == 1 for i, _ in track)
        assert r.n_views == len(track) - in_cam1
        if in_cam1:
            assert "unusable camera(s) 1 left out" in r.message


# ----------------------------------------------------------------------------- re-triangulation
def test_noise_free_points_are_recovered_and_certified():
    model, truth = synthetic_model(n_points=12, noise_px=0.0, seed=1)
    new, report = retriangulate(model, "corollary1", "auto")
    assert report.n_certified == 12 and report.n_updated == 12
    for pid, X in truth.items():
        # exact observations: the L2 minimiser is the true point up to the undistortion (1e-10 px)
        # and solver accuracy; 1e-6 relative to the scene radius 10 is the brief's target
        assert np.linalg.norm(np.array(new.points3D[pid].xyz) - X) < 1e-6 * 10
        assert new.points3D[pid].error < 1e-6
        r = report.records[pid - 1]
        assert r.gamma_ub < 1e-6 and r.gamma_lb <= r.gamma_ub + 1e-9
    assert all(new.images[i] == model.images[i] for i in model.images)
    assert new.points3D[1].rgb == model.points3D[1].rgb and new.points3D[1].track == model.points3D[1].track


def _undistorted_problem(model, point):
    cams, xs = [], []
    for iid, idx in point.track:
        im, cam = model.images[iid], model.cameras[model.images[iid].camera_id]
        xs.append(undistorted_pixels(cam.model, cam.params, np.array(im.points2D[idx][:2]))[0][0])
        cams.append(projection_matrix(model, iid))
    return np.array(cams), np.array(xs)


def test_noisy_certified_gamma_matches_independent_references():
    model, _ = synthetic_model(n_points=12, noise_px=1.0, seed=2)
    new, report = retriangulate(model)
    rng = np.random.default_rng(0)
    assert report.n_certified == 12
    for r in report.records:
        p = model.points3D[r.point3D_id]
        cams, xs = _undistorted_problem(model, p)
        if len(cams) == 2:
            _, cost = hartley_sturm(cams[0], cams[1], xs[0], xs[1])
            ref = np.sqrt(cost / 4)
        else:
            # 30 LM starts uniform in the ball of radius 2 (the scene is in the unit ball, cameras
            # at distance 10): a dense search independent of the SOS machinery
            ref = best_local_gamma(cams, xs, rng.uniform(-2, 2, (30, 3)))
        # both are global minima of the same function (gamma ~ 0.5 px): agreement to 1e-7 px is
        # the accuracy of the LM / polynomial-root references, far below any pixel effect
        assert abs(r.gamma_ub - ref) < 1e-7, (r, ref)
        assert r.gamma_lb <= r.gamma_ub + 1e-9 and r.updated
        assert r.gamma_ub <= r.gamma_input
        # the same formula, vectorised: equal to rounding
        assert new.points3D[r.point3D_id].error == pytest.approx(
            reprojection_error(model, new.points3D[r.point3D_id].xyz, p.track), rel=1e-12)


def test_min_track_length_skips_short_tracks():
    model, _ = synthetic_model(n_points=8, noise_px=0.5, seed=4)
    new, report = retriangulate(model, min_track_length=3)
    for r in report.records:
        if r.n_views < 3:
            assert r.status == Status.INVALID_INPUT and "min_track_length 3" in r.message and not r.updated
            assert new.points3D[r.point3D_id] == model.points3D[r.point3D_id]
        else:
            assert r.certified
    with pytest.raises(ValueError, match="min_track_length must be an integer >= 2"):
        retriangulate(model, min_track_length=1)


def test_sidecar_and_output_model_reread(tmp_path):
    model, _ = synthetic_model(n_points=10, noise_px=1.0, seed=5)
    new, report = retriangulate(model, min_track_length=3)
    write_text_model(new, tmp_path)
    write_certificates(report, tmp_path)
    back = read_text_model(tmp_path)
    assert back == new
    certs = read_certificates(tmp_path)
    assert sorted(certs) == sorted(new.points3D)
    for r in report.records:
        c = certs[r.point3D_id]
        assert (c.certified, c.status, c.n_views, c.updated) == (r.certified, r.status, r.n_views, r.updated)
        assert (c.gamma_ub, c.gamma_lb) == (r.gamma_ub, r.gamma_lb)       # repr: exact
    lines = (tmp_path / CERTIFICATES_FILE).read_text().splitlines()
    assert lines[1].startswith("#   POINT3D_ID, N_VIEWS, GAMMA_LB, GAMMA_UB, CERTIFIED, STATUS")
    skipped = [ln for ln in lines if ln.split()[5] == "invalid_input"] if len(lines) > 4 else []
    assert skipped and all(ln.split()[2:5] == ["nan", "nan", "0"] for ln in skipped)


# ----------------------------------------------------------------------------- conversion
def test_model_from_projections_reproduces_the_cameras():
    model0, truth = synthetic_model(n_points=6, seed=6, camera_ids=(2, 2, 2, 2, 2))
    Ps = [3.7 * projection_matrix(model0, i) for i in range(1, 6)]       # any scale
    tracks = []
    for pid, _X in truth.items():
        tracks.append({iid - 1: model0.images[iid].points2D[idx][:2] for iid, idx in model0.points3D[pid].track})
    m = model_from_projections(Ps, (640, 480), tracks)
    for j, P in enumerate(Ps):
        P2 = projection_matrix(m, j + 1)
        assert np.allclose(P2 / np.linalg.norm(P2), P / np.linalg.norm(P), atol=1e-12)
    for pid, X in truth.items():       # exact observations: the DLT point is the true one
        assert np.allclose(m.points3D[pid].xyz, X, atol=1e-8) and m.points3D[pid].error < 1e-6
    skew = np.array([[800.0, 2.0, 320.0], [0, 800, 240], [0, 0, 1]]) @ model0.images[1].cam_from_world
    with pytest.raises(SkewError, match="view 0 .* skew 2 .*MAX_SKEW_PX"):
        model_from_projections([skew, Ps[1]], (640, 480), tracks[:1])
    with pytest.raises(ValueError, match="tracks\\[0\\] must map >= 2 distinct view indices"):
        model_from_projections(Ps, (640, 480), [{0: (1.0, 2.0)}])


@pytest.mark.usefixtures("oxford_data")
def test_oxford_library_converted_and_certified(tmp_path):
    """First 30 library tracks: the converted model re-reads exactly, every point is certified,
    and every 2-view gamma equals Hartley-Sturm on the *original* Oxford P (so the K[R|t]
    conversion lost nothing)."""
    model = model_from_oxford("library", max_tracks=30)
    write_text_model(model, tmp_path)
    assert read_text_model(tmp_path) == model
    new, report = retriangulate(model)
    assert report.n_certified == 30
    seq = load_sequence("library")
    for r, t in zip(report.records, seq.tracks[:30]):
        assert r.n_views == t.n_views and r.gamma_ub <= r.gamma_input + 1e-12
        if t.n_views == 2:
            cams, x = seq.problem(t)
            _, cost = hartley_sturm(cams[0], cams[1], x[0], x[1])
            assert abs(r.gamma_ub - np.sqrt(cost / 4)) < 1e-6       # pixel units, gamma ~ 0.1-1 px
    with pytest.raises(SkewError, match="view 0 .*skew"):
        model_from_oxford("house", max_tracks=5)


# ----------------------------------------------------------------------------- CLI
def _cli(argv):
    ap = argparse.ArgumentParser(prog="tritools")
    register(ap.add_subparsers(dest="command", required=True))
    args = ap.parse_args(argv)
    return args.func(args)


def test_cli_colmap_writes_model_and_certificates(tmp_path, capsys):
    model, _ = synthetic_model(n_points=6, noise_px=1.0, seed=7)
    write_text_model(model, tmp_path / "in")
    (tmp_path / "in" / "rigs.txt").write_text("# rigs\n")
    assert _cli(["colmap", str(tmp_path / "in"), str(tmp_path / "out"), "--json", "--min-track-length", "2"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["n_points"] == 6 and out["n_certified"] == 6 and len(out["points"]) == 6
    assert read_text_model(tmp_path / "out").points3D.keys() == model.points3D.keys()
    assert (tmp_path / "out" / CERTIFICATES_FILE).is_file() and (tmp_path / "out" / "rigs.txt").is_file()
    assert _cli(["colmap", str(tmp_path / "in"), str(tmp_path / "out2")]) == 0
    assert "6 certified globally optimal" in capsys.readouterr().out


def test_cli_bad_input_exits_2(tmp_path, capsys):
    (tmp_path / "in").mkdir()
    for k, v in {"cameras.txt": "1 PINHOLE 640 480 800 800 320 240\n", "images.txt": "1 1 0 0 0 0 0 0 1 a\n\n",
                 "points3D.txt": "5 0 0 0 1 2 3 x\n"}.items():
        (tmp_path / "in" / k).write_text(v)
    assert _cli(["colmap", str(tmp_path / "in"), str(tmp_path / "out")]) == 2
    assert "points3D.txt:1: ERROR must be a number, got 'x'" in capsys.readouterr().err
    assert _cli(["colmap", str(tmp_path / "nowhere"), str(tmp_path / "out")]) == 2
    assert "nowhere: no such directory" in capsys.readouterr().err
    (tmp_path / "in" / "images.txt").unlink()
    assert _cli(["colmap", str(tmp_path / "in"), str(tmp_path / "out")]) == 2
    assert "images.txt: missing (a COLMAP text model has cameras.txt, images.txt, points3D.txt)" in \
        capsys.readouterr().err
    assert _cli(["colmap-from-oxford", "no_such_sequence", str(tmp_path / "o")]) == 2
    assert "error:" in capsys.readouterr().err
    (tmp_path / "in" / "images.txt").write_text("1 1 0 0 0 0 0 0 1 a\n\n")
    (tmp_path / "in" / "cameras.txt").write_text("1 EQUIRECTANGULAR 640 480 640 480\n")
    (tmp_path / "in" / "points3D.txt").write_text("")
    assert _cli(["colmap", str(tmp_path / "in"), str(tmp_path / "out"), "--strict"]) == 2
    assert "cameras.txt:1: camera 1 (EQUIRECTANGULAR) cannot be used: camera model 'EQUIRECTANGULAR' is not " \
           "supported" in capsys.readouterr().err
    assert _cli(["colmap", str(tmp_path / "in"), str(tmp_path / "out")]) == 0          # skipped, reported
    assert "skipped camera 1 (EQUIRECTANGULAR)" in capsys.readouterr().out


@pytest.mark.usefixtures("oxford_data")
def test_cli_colmap_from_oxford(tmp_path, capsys):
    assert _cli(["colmap-from-oxford", "merton3", str(tmp_path), "--max-tracks", "20"]) == 0
    m = read_text_model(tmp_path)
    assert len(m.images) == 3 and len(m.points3D) == 20 and {c.model for c in m.cameras.values()} == {"PINHOLE"}
    assert _cli(["colmap-from-oxford", "corridor", str(tmp_path / "c")]) == 2
    assert "skew" in capsys.readouterr().err


def test_pycolmap_reads_the_output_and_agrees_on_projection_undistortion_and_error(tmp_path):
    """COLMAP itself (pycolmap, optional extra 'colmap') as the reference for the file format,
    the quaternion convention, the distortion models, the undistortion and Point3D.error."""
    pycolmap = pytest.importorskip("pycolmap", reason="pycolmap not installed (extra 'colmap')")
    model, _ = synthetic_model(n_points=12, noise_px=1.0, seed=8)
    new, _ = retriangulate(model)
    write_text_model(new, tmp_path)
    rec = pycolmap.Reconstruction(str(tmp_path))
    assert (len(rec.cameras), len(rec.images), len(rec.points3D)) == (5, 6, 12)
    for p in new.points3D.values():
        for iid, idx in p.track:
            im, cam = new.images[iid], new.cameras[new.images[iid].camera_id]
            ours = pixels_from_camera(cam.model, cam.params, im.cam_from_world @ np.append(p.xyz, 1.0))[0]
            # same double-precision formula evaluated twice: 1e-9 px is rounding level at 1000 px
            assert np.allclose(rec.images[iid].project_point(np.array(p.xyz)), ours, atol=1e-9)
            xy = np.array([im.points2D[idx][:2]])
            u = undistorted_pixels(cam.model, cam.params, xy)[0]
            fx, fy, cx, cy = FX_FY_CX_CY[cam.id]
            normalized = np.column_stack([(u[:, 0] - cx) / fx, (u[:, 1] - cy) / fy])
            # COLMAP stops its own iterative undistortion earlier than we do (1e-10 px here):
            # 1e-9 in normalised units is ~1e-6 px
            assert np.allclose(rec.cameras[cam.id].cam_from_img(xy), normalized, atol=1e-9)
    errors = {pid: rec.points3D[pid].error for pid in new.points3D}
    rec.update_point_3d_errors()
    for pid, p in new.points3D.items():
        assert errors[pid] == p.error                                     # read back exactly
        assert rec.points3D[pid].error == pytest.approx(p.error, rel=1e-9, abs=1e-12)


@pytest.mark.parametrize("record, kwargs, field", [
    ("camera", {"width": 10.5}, "camera 1: width"), ("camera", {"height": True}, "camera 1: height"),
    ("camera", {"id": "1"}, "camera id"), ("image", {"camera_id": 1.25}, "image 1: camera_id"),
    ("image", {"points2D": ((1.0, 2.0, 2.7),)}, "points2D[0] point3D_id"),
    ("point", {"rgb": (1.5, 2, 3)}, "rgb"), ("point", {"track": ((1, 0.5),)}, "track point2D_idx"),
])
def test_records_refuse_fractional_and_non_integer_ids(record, kwargs, field):
    from tritools.io.colmap.model import Camera, Image, Point3D

    base = {"camera": (Camera, dict(id=1, model="PINHOLE", width=640, height=480, params=(1, 1, 1, 1))),
            "image": (Image, dict(id=1, qvec=(1, 0, 0, 0), tvec=(0, 0, 0), camera_id=1, name="a.jpg")),
            "point": (Point3D, dict(id=1, xyz=(0, 0, 0)))}[record]
    with pytest.raises(ValueError, match=re.escape(field)):
        base[0](**{**base[1], **kwargs})
    r = base[0](**{**base[1], "id": np.int64(7)})          # numpy integers and integral floats are integers
    assert type(r.id) is int and r.id == 7
    if record == "camera":
        assert Camera(**{**base[1], "width": 640.0}).width == 640


@pytest.mark.parametrize("token", ["9" * 5000, "x" * 5000, "1e" + "9" * 400, "-" + "7" * 30])
def test_long_fields_are_cut_in_messages(tmp_path, token):
    (tmp_path / "cameras.txt").write_text(f"1 PINHOLE {token} 480 500 500 320 240\n")
    (tmp_path / "images.txt").write_text("")
    (tmp_path / "points3D.txt").write_text("")
    with pytest.raises(ModelFormatError) as err:
        read_text_model(tmp_path)
    assert "cameras.txt:1" in str(err.value) and "WIDTH" in str(err.value)
    assert len(str(err.value)) < 120, str(err.value)
    if np.isfinite(float(token) if token[-1].isdigit() and len(token) < 400 else np.inf):
        return                                     # a float PARAM it is
    (tmp_path / "cameras.txt").write_text(f"1 PINHOLE 640 480 {token} 1 1 1\n")
    with pytest.raises(ModelFormatError) as err:
        read_text_model(tmp_path)
    assert "cameras.txt:1" in str(err.value) and len(str(err.value)) < 120, str(err.value)
