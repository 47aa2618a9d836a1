"""Point quality in the SfM path (tritools.sfm.quality, `tritools colmap --keypoint-radius/--min-angle/...`):
certified radii cover the true points under bounded keypoint noise, filters keep only points whose true
error is within the stated bound, angles against a closed form, the CLI's sidecar, exports, exit codes."""
import json

import numpy as np
import pytest

from tests.cli_util import run
from tritools.io.colmap import read_model_arrays, write_model_arrays
from tritools.io.export import read_npz, read_ply
from tritools.sfm.pipeline import OptionError, prepare_geometry
from tritools.sfm.quality import QUALITY_FILE, QualityOptions, drop_points, point_quality
from tritools.sfm.synthetic import synthetic_arrays
from tritools.uncertain import triangulation_angle


def bounded_noise_model(R, seed=0, n_points=400, n_images=12):
    """A PINHOLE model with exact keypoints moved uniformly within discs of radius R, and the true points."""
    a, X = synthetic_arrays(n_points, n_images=n_images, noise_px=0.0, seed=seed, xyz_noise=0.0)
    rng = np.random.default_rng(seed + 100)
    obs = a.kp_point3D != -1
    u = rng.normal(size=(int(obs.sum()), 2))
    u *= (R * np.sqrt(rng.uniform(size=len(u))) / np.linalg.norm(u, axis=1))[:, None]
    kp = a.kp_xy.copy()
    kp[obs] += u * 0.999
    f = {k: getattr(a, k) for k in a.__dataclass_fields__}
    f["kp_xy"] = kp
    f["point_xyz"] = X + rng.normal(size=X.shape) * 0.002          # an estimate near the truth
    return type(a)(**f), X


def test_certified_radius_covers_true_points_and_filter_bounds_error():
    R = 1.0
    a, X = bounded_noise_model(R)
    q = point_quality(a, prepare_geometry(a), QualityOptions(keypoint_radius=R, max_uncertainty=0.05))
    err = np.linalg.norm(a.point_xyz - X, axis=1)
    bounded = q.status == "bounded"
    assert bounded.sum() > 0.9 * len(X)
    assert np.all(err[bounded] <= q.radius[bounded])                  # coverage: no exception
    assert np.all(q.status != "empty")                                # the truth is consistent with every disc
    assert np.all(err[q.kept] <= 0.05)                                # the filter's promise
    assert 0 < q.kept.sum() < len(X)
    depth_first = []                                   # every view is usable here: the first track entry
    for p in range(a.n_points):
        v = a.track_image[a.track_offsets[p]]
        depth_first.append((rotation(a, v) @ X[p] + a.image_tvec[v])[2])
    depth_first = np.array(depth_first)
    ok = bounded & (q.n_views >= 2)
    assert np.all(q.depth_lo[ok] <= depth_first[ok]) and np.all(depth_first[ok] <= q.depth_hi[ok])


def rotation(a, v):
    from tritools.sfm.pipeline import rotations
    return rotations(a.image_qvec[v:v + 1])[0]


def test_angles_closed_form():
    K = np.diag([800.0, 800.0, 1.0])
    P1 = K @ np.hstack([np.eye(3), np.zeros((3, 1))])
    P2 = K @ np.hstack([np.eye(3), np.array([[-1.0], [0.0], [0.0]])])       # centre (1, 0, 0)
    X = np.array([0.5, 0.0, 10.0])
    expect = np.degrees(2 * np.arctan(0.5 / 10.0))
    assert triangulation_angle(np.array([P1, P2]), X) == pytest.approx(expect, rel=1e-12)
    tiny = np.array([0.5, 0.0, 1e7])
    assert triangulation_angle(np.array([P1, P2]), tiny) == pytest.approx(np.degrees(2 * np.arctan(0.5e-7)), rel=1e-9)


def test_min_angle_and_max_error_filters():
    a, X = bounded_noise_model(0.5, seed=3, n_points=200)
    q = point_quality(a, prepare_geometry(a), QualityOptions(min_angle=20.0, max_error=0.4))
    assert np.all(q.angle_deg[q.kept] >= 20.0) and np.all(q.error[q.kept] <= 0.4)
    assert np.all(q.status == "")                     # no radius: no uncertainty computed
    assert np.all(np.isnan(q.radius))
    small = drop_points(a, q.kept)
    small.to_model()                                   # cross references still hold (Model checks them)
    assert small.n_points == q.kept.sum()
    assert np.all(np.isin(small.kp_point3D[small.kp_point3D != -1], small.point_ids))


@pytest.mark.parametrize("kw, field", [({"keypoint_radius": -1.0}, "keypoint_radius"),
                                       ({"max_uncertainty": 1.0}, "max_uncertainty"),
                                       ({"keypoint_radius": 1.0, "max_depth_ratio": 0.5}, "max_depth_ratio"),
                                       ({"min_angle": float("nan")}, "min_angle")])
def test_bad_quality_options(kw, field):
    with pytest.raises(OptionError) as e:
        QualityOptions(**kw)
    assert e.value.field == field


def test_cli_quality_sidecar_filters_and_exports(tmp_path, capsys):
    a, X = bounded_noise_model(1.0, seed=5, n_points=120, n_images=8)
    write_model_arrays(a, tmp_path / "in", "bin")
    out = tmp_path / "out"
    rc, stdout, _ = run(["colmap", tmp_path / "in", out, "--max-delta", "2", "--keypoint-radius", "1.0",
                         "--min-angle", "1.5", "--max-uncertainty", "0.05", "--export", tmp_path / "p.ply",
                         "--export", tmp_path / "p.npz", "--json"], capsys)
    assert rc == 0
    summary = json.loads(stdout)
    qs = summary["quality"]
    lines = [ln.split() for ln in (out / QUALITY_FILE).read_text().splitlines() if not ln.startswith("#")]
    assert len(lines) == qs["n_points"] == a.n_points
    kept_ids = {int(ln[0]) for ln in lines if ln[-1] == "1"}
    model = read_model_arrays(out)
    assert set(model.point_ids.tolist()) == kept_ids and len(kept_ids) == qs["n_kept"]
    for ln in lines:
        if ln[-1] == "1":
            assert float(ln[5]) <= 0.05 and float(ln[2]) >= 1.5
    # the written points are within their certified radius of the truth
    truth = {int(i): X[k] for k, i in enumerate(a.point_ids)}
    for i, xyz in zip(model.point_ids, model.point_xyz):
        assert np.linalg.norm(xyz - truth[int(i)]) <= 0.05
    rec = {r["point3D_id"]: r for r in summary["points"]}
    assert all("uncertainty_radius" in r and "angle_deg" in r for r in rec.values())
    ply, _ = read_ply(tmp_path / "p.ply")
    assert set(ply["point3D_id"].tolist()) == kept_ids and "radius" in ply and "angle_deg" in ply
    npz = read_npz(tmp_path / "p.npz")
    assert set(npz["point3D_id"].tolist()) == kept_ids and len(npz["xyz"]) == len(kept_ids)


@pytest.mark.parametrize("flags, expect", [(["--keypoint-radius", "-2"], "--keypoint-radius"),
                                           (["--max-uncertainty", "1"], "--max-uncertainty"),
                                           (["--min-angle", "inf"], "--min-angle")])
def test_cli_bad_quality_flags(tmp_path, capsys, flags, expect):
    a, _ = bounded_noise_model(1.0, seed=6, n_points=20, n_images=6)
    write_model_arrays(a, tmp_path / "in", "bin")
    rc, _, err = run(["colmap", tmp_path / "in", tmp_path / "out"] + flags, capsys)
    assert rc == 2
    assert expect in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


def _bench():
    import importlib.util
    import pathlib

    path = pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "uncertainty.py"
    spec = importlib.util.spec_from_file_location("bench_uncertainty", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_benchmark_script_small(capsys):
    total = _bench().main(["--points", "150", "--oxford-tracks", "0", "--colmap-points", "300", "--level-trials", "0"])
    out = capsys.readouterr().out
    assert total["misses"] == 0 and total["points"] == 150
    assert "coverage 100.0000% (0 misses)" in out and "SfM path" in out


@pytest.mark.slow
def test_bounded_noise_coverage_many_points():
    """6000 bounded-noise points over 2-4 views with angles from 0.01 to 40 degrees: no true point
    outside its certified box or radius (the benchmark runs 10,000)."""
    total = _bench().main(["--points", "6000", "--oxford-tracks", "0", "--colmap-points", "0", "--seed", "7",
                           "--level-trials", "0"])
    assert total["points"] == 6000 and total["misses"] == 0


def _radii_file(a, path, r):
    lines = ["# IMAGE_ID POINT2D_IDX RADIUS"]
    for v, iid in enumerate(a.image_ids.tolist()):
        for k in range(int(a.kp_offsets[v + 1] - a.kp_offsets[v])):
            if a.kp_point3D[a.kp_offsets[v] + k] != -1:
                lines.append(f"{iid} {k} {r}")
    path.write_text("\n".join(lines) + "\n")
    return path


def test_per_observation_radii_file_matches_uniform_radius(tmp_path):
    a, X = bounded_noise_model(1.0, seed=8, n_points=80, n_images=8)
    geom = prepare_geometry(a)
    f = _radii_file(a, tmp_path / "radii.txt", 1.0)
    q_file = point_quality(a, geom, QualityOptions(keypoint_radii=f))
    q_one = point_quality(a, geom, QualityOptions(keypoint_radius=1.0))
    assert np.array_equal(q_file.status, q_one.status)
    fin = np.isfinite(q_one.radius)
    assert np.allclose(q_file.radius[fin], q_one.radius[fin], rtol=1e-9)
    err = np.linalg.norm(a.point_xyz - X, axis=1)
    assert np.all(err[fin] <= q_file.radius[fin])
    # a smaller radius for one image shrinks (never grows) the sets of its points
    lines = f.read_text().splitlines()
    first = int(a.image_ids[0])
    f.write_text("\n".join(ln if not ln.startswith(f"{first} ") else ln.rsplit(" ", 1)[0] + " 2.0"
                           for ln in lines) + "\n")
    q_big = point_quality(a, geom, QualityOptions(keypoint_radii=f))
    assert np.all(q_big.radius[fin] >= q_one.radius[fin] * (1 - 1e-9))


def test_radii_file_errors(tmp_path, capsys):
    a, _ = bounded_noise_model(1.0, seed=9, n_points=20, n_images=6)
    write_model_arrays(a, tmp_path / "in", "bin")
    bad = tmp_path / "bad.txt"
    bad.write_text("# header\n1 0 0.5\n1 x 2\n")
    rc, _, err = run(["colmap", tmp_path / "in", tmp_path / "out", "--keypoint-radii", bad], capsys)
    assert rc == 2 and f"{bad}:3" in err and "--keypoint-radii" in err and not (tmp_path / "out").exists()
    bad.write_text("1 0 -1\n")
    rc, _, err = run(["colmap", tmp_path / "in", tmp_path / "out", "--keypoint-radii", bad], capsys)
    assert rc == 2 and f"{bad}:1" in err
    bad.write_text("99999 0 1.0\n")
    with pytest.raises(ValueError, match="unknown IMAGE_ID"):
        point_quality(a, prepare_geometry(a), QualityOptions(keypoint_radii=bad, keypoint_radius=1.0))
    partial = tmp_path / "partial.txt"
    partial.write_text(f"{int(a.image_ids[0])} 0 1.0\n")
    with pytest.raises(ValueError, match="no radius"):
        point_quality(a, prepare_geometry(a), QualityOptions(keypoint_radii=partial))


def test_cli_text_model_depth_ratio_and_error_filters(tmp_path, capsys):
    a, _ = bounded_noise_model(1.0, seed=12, n_points=60, n_images=8)
    write_model_arrays(a, tmp_path / "in", "txt")
    out = tmp_path / "out"
    rc, stdout, _ = run(["colmap", tmp_path / "in", out, "--max-delta", "2", "--keypoint-radius", "1.0",
                         "--max-depth-ratio", "1.004", "--max-error", "0.9"], capsys)
    assert rc == 0 and "quality:" in stdout
    assert (out / "points3D.txt").is_file() and (out / QUALITY_FILE).is_file()
    rows = [ln.split() for ln in (out / QUALITY_FILE).read_text().splitlines() if not ln.startswith("#")]
    for r in rows:
        kept = r[-1] == "1"
        assert kept == (float(r[8]) <= 1.004 and float(r[3]) <= 0.9)
    model = read_model_arrays(out)
    assert model.n_points == sum(r[-1] == "1" for r in rows) < len(rows)
