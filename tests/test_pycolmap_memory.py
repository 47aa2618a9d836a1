"""pycolmap in memory: from_pycolmap / to_pycolmap, and tritools.sfm.retriangulate(rec) returning a new
pycolmap.Reconstruction (checked by reading it with pycolmap itself, and against the points' truth)."""
import numpy as np
import pytest

from tritools.io.colmap import from_pycolmap, read_model, to_pycolmap, write_text_model
from tritools.sfm import RetriangulationReport, retriangulate

from .test_camera_models import model_of

pycolmap = pytest.importorskip("pycolmap")


def test_round_trip_through_pycolmap_is_exact(tmp_path):
    model, _ = model_of("OPENCV", n_points=15)
    rec = to_pycolmap(model)
    assert isinstance(rec, pycolmap.Reconstruction)
    assert (rec.num_cameras(), rec.num_images(), rec.num_points3D()) == (1, 5, 15)
    assert rec.images[2].points2D[3].point3D_id == 4                      # keypoint -> point links kept
    assert from_pycolmap(rec) == model
    write_text_model(model, tmp_path / "m")                              # pycolmap's own reader agrees
    assert from_pycolmap(pycolmap.Reconstruction(str(tmp_path / "m"))) == model
    rec.write_text(str(tmp_path))                                        # and our reader of pycolmap's writer
    assert read_model(tmp_path) == model
    with pytest.raises(TypeError, match="pycolmap.Reconstruction"):
        from_pycolmap(model)


def test_retriangulate_a_reconstruction_in_memory(tmp_path):
    model, truth = model_of("FULL_OPENCV", n_points=25, seed=4)
    write_text_model(model, tmp_path)
    rec = pycolmap.Reconstruction(str(tmp_path))                         # as a pycolmap user has it
    before = {pid: np.array(p.xyz) for pid, p in rec.points3D.items()}
    new, report = retriangulate(rec, max_delta=2)
    assert isinstance(new, pycolmap.Reconstruction) and isinstance(report, RetriangulationReport)
    assert new is not rec and report.n_certified == report.n_points == 25 and report.n_updated == 25
    for pid, X in truth.items():
        np.testing.assert_allclose(new.points3D[pid].xyz, X, atol=1e-6)
        np.testing.assert_array_equal(rec.points3D[pid].xyz, before[pid])   # the input is not modified
    new.update_point_3d_errors()                                          # pycolmap's own ERROR: ~0 now
    assert max(p.error for p in new.points3D.values()) < 1e-6
    assert new.num_frames() == rec.num_frames() and new.num_rigs() == rec.num_rigs()
    out = tmp_path / "out"
    out.mkdir()
    new.write_binary(str(out))
    back = pycolmap.Reconstruction(str(out))
    np.testing.assert_allclose(back.points3D[3].xyz, truth[3], atol=1e-6)
    default_new, _ = retriangulate(rec)                                    # the public defaults work too
    assert isinstance(default_new, pycolmap.Reconstruction)
