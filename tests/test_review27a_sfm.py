"""Review 27a (the SfM path): stale files of another model in OUT, spherical cameras in the depth test, non-finite
or invalid point3D records, subnormal focal lengths, integers spelled as floats, SIGTERM."""
import io
import os
import signal
import struct
from contextlib import redirect_stderr, redirect_stdout

import numpy as np
import pytest

from tests.cli_util import colmap_signalled
from tritools.cli.app import main
from tritools.io.colmap.formats import write_model_arrays
from tritools.sfm.synthetic import synthetic_arrays


def _run(*argv):
    err = io.StringIO()
    with redirect_stderr(err), redirect_stdout(io.StringIO()):
        rc = main([str(a) for a in argv])
    return rc, err.getvalue().strip()


def _model(tmp_path, name="in", n=30, seed=2, **kw):
    arr, _ = synthetic_arrays(n, 6, "OPENCV", noise_px=0.5, seed=seed, max_track=4, **kw)
    write_model_arrays(arr, tmp_path / name, "bin")
    return arr, tmp_path / name


def test_stale_rigs_or_quality_files_in_out_are_refused_before_any_work(tmp_path):
    """F1: rigs.bin / frames.bin of an earlier model (IN has none) stayed beside the new model, which COLMAP then
    refused; a quality file of an earlier run listed points removed that the new model holds."""
    _, src = _model(tmp_path)
    out = tmp_path / "out"
    assert _run("colmap", src, out, "--max-delta", "2")[0] == 0
    (out / "rigs.bin").write_bytes(b"from another model")
    before = sorted(os.listdir(out))
    rc, err = _run("colmap", src, out, "--max-delta", "2")
    assert rc == 2 and "rigs.bin" in err and "remove it" in err and len(err.splitlines()) == 1
    assert sorted(os.listdir(out)) == before and (out / "rigs.bin").read_bytes() == b"from another model"
    os.remove(out / "rigs.bin")
    assert _run("colmap", src, out, "--max-delta", "2", "--min-angle", "1")[0] == 0
    assert (out / "points3D_uncertainty.txt").is_file()
    rc, err = _run("colmap", src, out, "--max-delta", "2")              # no quality filter this time
    assert rc == 2 and "points3D_uncertainty.txt" in err
    assert _run("colmap", src, out, "--max-delta", "2", "--min-angle", "1")[0] == 0     # replaced: accepted


def test_a_spherical_camera_does_not_take_part_in_the_depth_test():
    """F2: a 360-degree view of a point behind its z axis made a certified point 'behind camera'."""
    from tritools.io.colmap import Camera, Image, Model, Point3D, pixels_from_camera, qvec_from_rotation
    from tritools.sfm import retriangulate

    pin = Camera(1, "PINHOLE", 640, 480, (500.0, 500.0, 320.0, 240.0))
    eq = Camera(2, "EQUIRECTANGULAR", 2000, 1000, (2000.0, 1000.0))
    X = np.array([0.1, -0.2, 0.3])
    imgs, track = {}, []
    for v in range(1, 5):
        a = 0.2 * (v - 2)
        R = np.array([[np.cos(a), 0, -np.sin(a)], [0, 1, 0], [np.sin(a), 0, np.cos(a)]]) if v < 4 else np.eye(3)
        t = np.array([0, 0, 5.0]) if v < 4 else np.array([0, 0, -3.0])       # view 4: X at depth -2.7
        xy = pixels_from_camera("PINHOLE", pin.params, (R @ X + t)[None])[0] if v < 4 else np.array([1988.2, 476.5])
        imgs[v] = Image(v, tuple(qvec_from_rotation(R)), tuple(t), 1 if v < 4 else 2, f"im{v}.jpg",
                        ((float(xy[0]), float(xy[1]), 1),))
        track.append((v, 0))
    model = Model({1: pin, 2: eq}, imgs, {1: Point3D(1, tuple(X + 0.01), (1, 2, 3), 0.0, tuple(track))})
    _, rep = retriangulate(model)
    r = rep.records[0]
    assert r.certified and r.updated and r.in_front, r.message
    assert "behind" not in r.message


def _first_point_offset(path) -> int:
    return 8                                                     # after the uint64 count


def test_non_finite_xyz_in_points3d_bin_is_refused_with_its_record(tmp_path):
    """F3: a NaN X was accepted and written back into a model no reader accepts."""
    _, src = _model(tmp_path)
    b = bytearray((src / "points3D.bin").read_bytes())
    struct.pack_into("<d", b, _first_point_offset(src) + 8, float("nan"))
    (src / "points3D.bin").write_bytes(bytes(b))
    rc, err = _run("colmap", src, tmp_path / "out", "--output-type", "txt")
    assert rc == 2 and "points3D.bin: record 0 (offset 8)" in err and "X is not finite" in err
    assert not (tmp_path / "out").exists()


def test_colmaps_invalid_point3d_id_is_refused_up_front(tmp_path):
    """F4: POINT3D_ID 2^64 - 1 with a track of unlinked keypoints (-1 == -1) passed the reference check."""
    arr, src = _model(tmp_path, extra_keypoints=0.5)
    free = [(v, k) for v in range(arr.n_images) for k in range(arr.kp_offsets[v + 1] - arr.kp_offsets[v])
            if arr.kp_point3D[arr.kp_offsets[v] + k] == -1]
    (v1, k1) = free[0]
    (v2, k2) = next(f for f in free if f[0] != v1)
    p = bytearray((src / "points3D.bin").read_bytes())
    n = struct.unpack_from("<Q", p, 0)[0]
    struct.pack_into("<Q", p, 0, n + 1)
    p += struct.pack("<Q3d3BdQ", 2 ** 64 - 1, 0.0, 0.0, 0.0, 1, 2, 3, 0.0, 2)
    p += struct.pack("<II", int(arr.image_ids[v1]), k1) + struct.pack("<II", int(arr.image_ids[v2]), k2)
    (src / "points3D.bin").write_bytes(bytes(p))
    for fmt in ("bin", "txt"):
        rc, err = _run("colmap", src, tmp_path / f"out_{fmt}", "--output-type", fmt)
        assert rc == 2 and f"points3D.bin: record {n}" in err and "not a valid point3D id" in err, err
        assert not (tmp_path / f"out_{fmt}").exists()


def test_a_subnormal_focal_length_makes_the_camera_unusable():
    """F5: fy = 5e-324 passed the camera check and undistortion returned -inf flagged as converged."""
    from tritools.io.colmap.camera_models import camera_problem, undistort

    assert "too small" in camera_problem("PINHOLE", (800.0, 5e-324, 512.0, 384.0))
    assert camera_problem("PINHOLE", (800.0, 1e-300, 512.0, 384.0)) is None          # tiny but invertible
    uv, ok = undistort(np.array([[0.5, -np.inf], [0.1, 0.2]]), np.zeros(4))
    assert ok.tolist() == [False, True]


@pytest.mark.parametrize("chunk", [1, 100000])
def test_an_integer_field_spelled_as_a_float_is_refused_whatever_the_chunk(tmp_path, chunk):
    """F6: the fast text parser read POINT3D_ID '1.0' (the exact one refused it), so the verdict depended on which
    lines shared a chunk."""
    arr, _ = synthetic_arrays(20, 5, "PINHOLE", noise_px=0.5, seed=3, max_track=4)
    write_model_arrays(arr, tmp_path / "in", "txt")
    path = tmp_path / "in" / "points3D.txt"
    lines = path.read_text().splitlines()
    k = next(i for i, ln in enumerate(lines) if not ln.startswith("#"))
    head, rest = lines[k].split(" ", 1)
    lines[k] = f"{head}.0 {rest}"
    path.write_text("\n".join(lines) + "\n")
    rc, err = _run("colmap", tmp_path / "in", tmp_path / "out", "--chunk-points", chunk)
    assert rc == 2 and f"points3D.txt:{k + 1}" in err and "must be an integer" in err


@pytest.mark.slow
def test_sigterm_unwinds_like_ctrl_c(tmp_path):
    """F7: SIGTERM killed the run and left the staging directory in OUT; now exit 143, OUT as it was."""
    rc, err, out = colmap_signalled(tmp_path, signal.SIGTERM, "--export", tmp_path / "exp" / "p.ply")
    if rc == 0:
        pytest.skip("the run finished before the signal")
    assert rc == 143 and err.strip().endswith("tritools: terminated")
    assert sorted(os.listdir(out)) == ["notes.txt"] and not (tmp_path / "exp").exists()


def test_strict_must_be_a_boolean():
    """'no' is truthy: it turned strict mode on."""
    from tritools.sfm import OptionError, RetriangulationOptions

    with pytest.raises(OptionError, match="strict"):
        RetriangulationOptions(strict="no")
    assert RetriangulationOptions(strict=np.bool_(True)).strict


def test_a_keypoint_listed_twice_in_the_radii_file_is_refused(tmp_path):
    from tritools.sfm.quality import read_keypoint_radii

    arr, _ = _model(tmp_path)
    v = 0
    k = next(int(i) for i in range(int(arr.kp_offsets[1])) if arr.kp_point3D[i] != -1)
    f = tmp_path / "radii.txt"
    iid = int(arr.image_ids[v])
    f.write_text(f"# IMAGE_ID POINT2D_IDX RADIUS\n{iid} {k} 1.0\n{iid} {k} 2.0\n")
    again = rf"radii.txt:3: image {iid} keypoint {k} listed again \(first at .*radii.txt:2\)"
    with pytest.raises(ValueError, match=again):
        read_keypoint_radii(f, arr, 1.0)


def test_non_unit_quaternions_get_a_note(tmp_path):
    """F9: COLMAP uses a stored quaternion as it is, tritools normalises it: say so."""
    import dataclasses

    from tritools.sfm import retriangulate_folder

    arr, _ = synthetic_arrays(20, 6, "PINHOLE", seed=5, max_track=4)
    write_model_arrays(dataclasses.replace(arr, image_qvec=arr.image_qvec * 1.001), tmp_path / "in", "bin")
    res = retriangulate_folder(tmp_path / "in", tmp_path / "out")
    assert any("not unit" in n and "|q| = 1.001" in n for n in res.notes), res.notes
    write_model_arrays(arr, tmp_path / "in2", "bin")
    assert not any("not unit" in n for n in retriangulate_folder(tmp_path / "in2", tmp_path / "out2").notes)
