"""Every COLMAP camera model, as a user with pycolmap meets it: forward maps equal to pycolmap's
``img_from_cam`` (the independent reference), undistortion equal to pycolmap's ``cam_from_img``, and whole
models (keypoints made by pycolmap) re-triangulated through the API and ``tritools colmap`` in a subprocess;
EQUIRECTANGULAR gives a non-zero exit with the counts, never a silent exit 0."""
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

from tritools.io.colmap import Camera, Image, Model, Point3D, qvec_from_rotation, write_text_model
from tritools.io.colmap.camera_models import (COLMAP_MODEL_N_PARAMS, UnsupportedCameraModelError, camera_problem,
                                              intrinsics, pixels_from_camera, undistorted_pixels, usable_models)
from tritools.io.colmap.lens import OWN_MODELS, PYCOLMAP_MODELS
from tritools.sfm import retriangulate

pycolmap = pytest.importorskip("pycolmap")
ROOT = pathlib.Path(__file__).resolve().parents[1]

#: realistic parameters per model (f ~ 500 px, 640 x 480 images, mild to strong distortion).
PARAMS = {
    "SIMPLE_PINHOLE": (500, 320, 240), "PINHOLE": (500, 510, 320, 240), "SIMPLE_RADIAL": (500, 320, 240, -0.1),
    "RADIAL": (500, 320, 240, -0.1, 0.02), "OPENCV": (500, 505, 320, 240, -0.12, 0.03, 0.001, -0.0015),
    "FULL_OPENCV": (500, 505, 320, 240, -0.12, 0.03, 0.001, -0.0015, 0.002, 0.01, -0.003, 0.001),
    "OPENCV_FISHEYE": (400, 405, 320, 240, 0.05, -0.01, 0.003, -0.001),
    "SIMPLE_RADIAL_FISHEYE": (400, 320, 240, 0.04), "RADIAL_FISHEYE": (400, 320, 240, 0.04, -0.01),
    "THIN_PRISM_FISHEYE": (400, 405, 320, 240, 0.04, -0.01, 0.001, -0.001, 0.002, -0.001, 0.0005, -0.0004),
    "FOV": (450, 455, 320, 240, 0.8), "SIMPLE_FISHEYE": (400, 320, 240), "FISHEYE": (400, 405, 320, 240),
    "RAD_TAN_THIN_PRISM_FISHEYE": (400, 405, 320, 240, 0.03, -0.01, 0.002, -0.001, 0.0005, 0.0001, 0.001,
                                   -0.001, 0.0005, -0.0002, 0.0003, 0.0001),
    "SIMPLE_DIVISION": (500, 320, 240, -0.1), "DIVISION": (500, 505, 320, 240, -0.1),
    "EUCM": (450, 455, 320, 240, 0.5, 1.1),
}
PERSPECTIVE = sorted(PARAMS)


def _ref(model):
    return pycolmap.Camera(model=model, width=640, height=480, params=list(map(float, PARAMS[model])))


def test_every_colmap_model_is_known_and_every_perspective_one_usable():
    names = {n for n, _ in pycolmap.CameraModelId.__members__.items() if n != "INVALID"}
    assert names == set(COLMAP_MODEL_N_PARAMS)
    for n in names:
        assert COLMAP_MODEL_N_PARAMS[n] == len(pycolmap.Camera.create_from_model_name(1, n, 500.0, 640, 480).params)
    assert set(PERSPECTIVE) == names - {"EQUIRECTANGULAR"} == set(usable_models())
    for m in PERSPECTIVE:
        assert camera_problem(m, PARAMS[m]) is None, m
    assert "spherical" in camera_problem("EQUIRECTANGULAR", (640, 480))


@pytest.mark.parametrize("model", PERSPECTIVE)
def test_forward_map_and_undistortion_equal_pycolmap(model):
    rng = np.random.default_rng(len(model))
    cam = _ref(model)
    X = np.column_stack([rng.uniform(-0.5, 0.5, (200, 2)), np.ones(200)]) * rng.uniform(1, 20, (200, 1))
    ref = cam.img_from_cam(X)
    np.testing.assert_allclose(pixels_from_camera(model, PARAMS[model], X), ref, rtol=0, atol=1e-9)
    K = intrinsics(model, PARAMS[model])
    np.testing.assert_allclose(K, cam.calibration_matrix(), rtol=1e-15)
    xy_u, ok = undistorted_pixels(model, PARAMS[model], ref)            # the pinhole image of the same rays
    assert ok.all()
    uv = X[:, :2] / X[:, 2:]
    np.testing.assert_allclose(xy_u, uv @ K[:2, :2].T + K[:2, 2], rtol=0, atol=1e-6)
    np.testing.assert_allclose(xy_u, cam.cam_from_img(ref) @ K[:2, :2].T + K[:2, 2], rtol=0, atol=1e-6)


def test_pycolmap_models_without_pycolmap_are_refused_by_name(monkeypatch):
    from tritools.io.colmap import camera_models

    monkeypatch.setattr(camera_models, "_pycolmap_available", lambda: False)
    for m in PYCOLMAP_MODELS:
        with pytest.raises(UnsupportedCameraModelError, match=f"'{m}'.*pycolmap.*not installed"):
            intrinsics(m, PARAMS[m])
    assert camera_problem("FULL_OPENCV", PARAMS["FULL_OPENCV"]) is None        # own code: no pycolmap needed
    assert set(OWN_MODELS) <= set(camera_models.usable_models())


def _look_at(C):
    z = -C / np.linalg.norm(C)
    x = np.cross([0.0, 1.0, 0.3], z)
    x /= np.linalg.norm(x)
    R = np.vstack([x, np.cross(z, x), z])
    return R, -R @ C


def model_of(model_name, n_points=30, n_images=5, seed=0):
    """One camera of ``model_name`` for every image; keypoints are pycolmap's projections (exact)."""
    rng = np.random.default_rng(seed)
    cam = _ref(model_name)
    poses = {}
    for i in range(1, n_images + 1):
        c = rng.normal(size=3) * np.array([1, 0.3, 1])
        poses[i] = _look_at(6.0 * c / np.linalg.norm(c))
    kps = {i: [] for i in poses}
    points, truth = {}, {}
    for pid in range(1, n_points + 1):
        X = rng.uniform(-1, 1, 3)
        track = []
        for i, (R, t) in poses.items():
            x = cam.img_from_cam((R @ X + t)[None])[0]
            track.append((i, len(kps[i])))
            kps[i].append((float(x[0]), float(x[1]), pid))
        points[pid] = Point3D(pid, tuple(X + 0.05 * rng.normal(size=3)), (128, 128, 128), 1.0, tuple(track))
        truth[pid] = X
    images = {i: Image(i, tuple(qvec_from_rotation(R)), tuple(t), 1, f"im{i}.jpg", tuple(kps[i]))
              for i, (R, t) in poses.items()}
    cams = {1: Camera(1, model_name, 640, 480, tuple(map(float, PARAMS[model_name])))}
    return Model(cams, images, points), truth


@pytest.mark.parametrize("model", ["FULL_OPENCV", "SIMPLE_RADIAL_FISHEYE", "OPENCV_FISHEYE", "THIN_PRISM_FISHEYE",
                                   "FOV", "RADIAL_FISHEYE", "DIVISION", "EUCM"])
def test_models_of_every_lens_certify_every_point(model):
    m, truth = model_of(model)
    new, report = retriangulate(m, max_delta=2)
    assert report.skipped_cameras == () and report.n_certified == report.n_points == len(truth)
    for pid, X in truth.items():
        np.testing.assert_allclose(new.points3D[pid].xyz, X, atol=1e-6)
        assert new.points3D[pid].error < 1e-6                 # COLMAP's ERROR with the full lens model


def _run(*args):
    return subprocess.run([sys.executable, "-m", "tritools", *map(str, args)], capture_output=True, text=True,
                          cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=300)


@pytest.mark.slow
def test_cli_full_opencv_and_fisheye_models_certify_and_equirectangular_exits_3(tmp_path):
    for name in ("FULL_OPENCV", "SIMPLE_RADIAL_FISHEYE"):
        m, _ = model_of(name, n_points=20)
        write_text_model(m, tmp_path / name)
        run = _run("colmap", tmp_path / name, tmp_path / f"{name}_out", "--max-delta", "2")
        assert run.returncode == 0, run.stderr
        assert run.stdout.startswith("20 points, 20 certified globally optimal")
        back = pycolmap.Reconstruction(str(tmp_path / f"{name}_out"))
        assert back.num_points3D() == 20
    m, _ = model_of("PINHOLE", n_points=10)
    cams = {1: m.cameras[1], 2: Camera(2, "EQUIRECTANGULAR", 640, 480, (640.0, 480.0))}
    images = dict(m.images)
    for i in (1, 2, 3, 4):                                     # 4 of 5 images on the spherical camera
        im = images[i]
        images[i] = Image(i, im.qvec, im.tvec, 2, im.name, im.points2D)
    write_text_model(Model(cams, images, m.points3D), tmp_path / "eq")
    run = _run("colmap", tmp_path / "eq", tmp_path / "eq_out")
    assert run.returncode == 3
    assert "tritools: warning: 1 camera(s) could not be used (EQUIRECTANGULAR): 40 observation(s) left out, " \
           "0 of 10 point(s) certified" in run.stderr
    run = _run("colmap", tmp_path / "eq", tmp_path / "eq_out2", "--strict")
    assert run.returncode == 2 and run.stderr.count("tritools: error:") == 1 and "EQUIRECTANGULAR" in run.stderr


def test_every_model_round_trips_through_pycolmap_binary(tmp_path):
    """Binary cameras.bin of every model (EQUIRECTANGULAR included, id 17) read by pycolmap and back."""
    from tritools.io.colmap import read_binary_model, write_binary_model

    m, _ = model_of("PINHOLE", n_points=3)
    params = dict(PARAMS, EQUIRECTANGULAR=(640.0, 480.0))
    cams = {k + 1: Camera(k + 1, name, 640, 480, tuple(map(float, params[name]))) for k, name in enumerate(params)}
    model = Model(cams, m.images, m.points3D)
    write_binary_model(model, tmp_path / "a")
    rec = pycolmap.Reconstruction(str(tmp_path / "a"))
    assert {c.model.name for c in rec.cameras.values()} == set(params)
    (tmp_path / "b").mkdir()
    rec.write_binary(str(tmp_path / "b"))
    assert read_binary_model(tmp_path / "b").cameras == model.cameras


@pytest.mark.parametrize("omega", [1e-9, 0.005, 0.5, 2.0])
def test_fov_model_follows_colmap_branches(omega):
    """COLMAP switches to series for small omega or small radius: ERROR must use the same map."""
    p = (450.0, 455.0, 320.0, 240.0, omega)
    cam = pycolmap.Camera(model="FOV", width=640, height=480, params=list(p))
    X = np.vstack([np.column_stack([np.random.default_rng(1).uniform(-0.6, 0.6, (40, 2)), np.ones(40)]),
                   [[1e-3, 2e-3, 1.0], [0.0, 0.0, 1.0]]])
    np.testing.assert_allclose(pixels_from_camera("FOV", p, X), cam.img_from_cam(X), rtol=0, atol=1e-9)
    assert undistorted_pixels("FOV", p, cam.img_from_cam(X))[1].all()
