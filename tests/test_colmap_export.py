"""PLY and NPZ exports: round trips through the readers, the byte layout of the PLY header, atomic
replacement, refused inputs, pycolmap reading our PLY, and export_points' certificate fields."""
from __future__ import annotations

import numpy as np
import pytest

from tritools.io.export import (CERTIFIED_BY_LEGEND, STATUS_LEGEND, export_points, read_npz, read_ply, write_npz,
                                write_ply)
from tritools.sfm import retriangulate_arrays
from tritools.sfm.synthetic import synthetic_arrays


def _data(n=6, seed=0):
    rng = np.random.default_rng(seed)
    return rng.normal(size=(n, 3)), rng.integers(0, 256, (n, 3)).astype(np.uint8)


def test_ply_round_trip_and_header(tmp_path):
    xyz, rgb = _data()
    fields = {"gamma_lb": np.linspace(0, 1, 6), "gamma_ub": np.linspace(0, 1, 6).astype(np.float32),
              "certified": np.array([1, 0, 1, 1, 0, 1], bool), "status": np.arange(6, dtype=np.uint8),
              "n_views": np.arange(6, dtype=np.int32), "delta": np.full(6, -1, np.int16)}
    path = write_ply(tmp_path / "p.ply", xyz, rgb, comments=["hello  world"], **fields)
    data = path.read_bytes()
    header = data[:data.index(b"end_header\n") + 11].decode()
    assert header.splitlines()[:4] == ["ply", "format binary_little_endian 1.0", "comment hello world",
                                       "element vertex 6"]
    assert "property double x" in header and "property uchar red" in header and "property float gamma_ub" in header
    assert "property short delta" in header and "property int n_views" in header
    # x y z (3 doubles) + rgb (3 uchar) + lb (double) + ub (float) + 2 uchar + int + short per vertex
    assert len(data) - len(header) == 6 * (24 + 3 + 8 + 4 + 2 + 4 + 2)
    cols, comments = read_ply(path)
    assert comments == ["hello world"]
    assert np.array_equal(np.column_stack([cols["x"], cols["y"], cols["z"]]), xyz)
    assert np.array_equal(np.column_stack([cols["red"], cols["green"], cols["blue"]]), rgb)
    for k, v in fields.items():
        assert np.array_equal(cols[k], v.astype(np.uint8) if v.dtype == bool else v) and cols[k].dtype.itemsize == \
            (1 if v.dtype == bool else v.dtype.itemsize)


def test_ply_is_read_by_pycolmap(tmp_path):
    pycolmap = pytest.importorskip("pycolmap", reason="pycolmap not installed (extra 'colmap')")
    xyz, rgb = _data(20, seed=1)
    write_ply(tmp_path / "p.ply", xyz, rgb, gamma_ub=np.ones(20), certified=np.ones(20, bool))
    rec = pycolmap.Reconstruction()
    rec.import_PLY(str(tmp_path / "p.ply"))
    got = sorted((tuple(p.xyz), tuple(int(c) for c in p.color)) for p in rec.points3D.values())
    want = sorted((tuple(x), tuple(int(c) for c in col)) for x, col in zip(xyz, rgb))
    assert [g[1] for g in got] == [w[1] for w in want]
    # COLMAP keeps PLY coordinates as float32: equal after rounding to single precision
    assert np.array_equal(np.array([g[0] for g in got], np.float32), np.array([w[0] for w in want], np.float32))


def test_npz_round_trip_without_pickle(tmp_path):
    xyz, rgb = _data()
    path = write_npz(tmp_path / "p.npz", xyz, rgb, gamma_ub=np.arange(6.0), legend=np.array(["a", "bc"]))
    z = read_npz(path)
    assert sorted(z) == ["gamma_ub", "legend", "rgb", "xyz"] and np.array_equal(z["xyz"], xyz)
    assert list(z["legend"]) == ["a", "bc"] and z["rgb"].dtype == np.uint8
    with pytest.raises(ValueError, match="object arrays cannot be stored"):
        write_npz(tmp_path / "q.npz", xyz, msg=np.array(["a", None] * 3, object))


def test_writers_refuse_bad_input_and_keep_the_old_file(tmp_path):
    xyz, rgb = _data()
    (tmp_path / "p.ply").write_bytes(b"old")
    with pytest.raises(ValueError, match="field 'n' must have shape \\(6,\\)"):
        write_ply(tmp_path / "p.ply", xyz, rgb, n=np.zeros(5))
    with pytest.raises(ValueError, match="dtype int64 has no PLY type"):
        write_ply(tmp_path / "p.ply", xyz, rgb, n=np.zeros(6, np.int64))
    with pytest.raises(ValueError, match="rgb must be"):
        write_ply(tmp_path / "p.ply", xyz, rgb[:3])
    assert (tmp_path / "p.ply").read_bytes() == b"old" and sorted(p.name for p in tmp_path.iterdir()) == ["p.ply"]
    (tmp_path / "bad.ply").write_bytes(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n1\n")
    with pytest.raises(ValueError, match="expected format binary_little_endian"):
        read_ply(tmp_path / "bad.ply")


def test_export_points_carries_the_certificate_fields(tmp_path):
    a, _ = synthetic_arrays(n_points=80, n_images=6, seed=4)
    new, report = retriangulate_arrays(a)
    export_points(tmp_path / "c.ply", new.point_xyz, new.point_rgb, report)
    export_points(tmp_path / "c.npz", new.point_xyz, new.point_rgb, report)
    cols, comments = read_ply(tmp_path / "c.ply")
    z = read_npz(tmp_path / "c.npz")
    for d in (cols, z):
        assert np.array_equal(d["point3D_id"], report.point_ids) and np.array_equal(d["gamma_lb"], report.gamma_lb)
        assert np.array_equal(d["certified"].astype(bool), report.certified)
        assert np.array_equal(d["in_front"].astype(bool), report.in_front)
        assert [STATUS_LEGEND[k] for k in d["status"]] == [r.status.value for r in report.records]
    assert tuple(z["status_legend"]) == STATUS_LEGEND and tuple(z["certified_by_legend"]) == CERTIFIED_BY_LEGEND
    assert [CERTIFIED_BY_LEGEND[k] for k in z["certified_by"]] == [r.certified_by or "" for r in report.records]
    assert np.array_equal(z["n_views"], report.n_views) and comments[1].startswith("status codes: 0 optimal, 1 ")
    with pytest.raises(ValueError, match="export format must be ply or npz"):
        export_points(tmp_path / "c.csv", new.point_xyz, new.point_rgb, report)
