"""`tritools colmap` through the real entry point: formats in and out, exit codes (2 and one line for
every bad flag, file or output path), atomic outputs (a failure mid-write leaves OUT as it was),
exports, the summary and JSON."""
from __future__ import annotations

import json
import os

import numpy as np
import pytest

from tests.test_colmap import synthetic_model
from tests.test_sfm_arrays import behind_model
from tritools.cli.app import main
from tritools.io.colmap import (Camera, Model, detect_format, read_model, read_model_arrays, write_binary_model,
                                write_model_arrays, write_text_model)
from tritools.io.export import read_npz, read_ply
from tritools.sfm import CERTIFICATES_FILE, read_certificates
from tritools.sfm.synthetic import synthetic_arrays


@pytest.fixture()
def binary_in(tmp_path):
    a, _ = synthetic_arrays(n_points=150, n_images=8, camera="OPENCV", seed=2)
    write_model_arrays(a, tmp_path / "in", "bin")
    (tmp_path / "in" / "rigs.bin").write_bytes(b"rig bytes")
    return tmp_path / "in"


def _one_line_error(capsys) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("tritools: error: "), err
    return err


def test_binary_in_binary_out_with_exports(binary_in, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["colmap", str(binary_in), str(out), "--export", str(tmp_path / "e" / "pts.ply"),
                 "--export", str(tmp_path / "pts.npz")]) == 0
    text = capsys.readouterr().out
    assert "150 points, 150 certified globally optimal" in text and "model (bin) written to" in text
    assert detect_format(out) == "bin" and (out / "rigs.bin").read_bytes() == b"rig bytes"
    new = read_model_arrays(out)
    certs = read_certificates(out)
    assert len(certs) == 150 and all(c.certified for c in certs.values())
    cols, comments = read_ply(tmp_path / "e" / "pts.ply")
    assert np.array_equal(np.column_stack([cols["x"], cols["y"], cols["z"]]), new.point_xyz)
    assert np.array_equal(cols["point3D_id"], new.point_ids) and cols["certified"].all()
    assert any("status codes: 0 optimal" in c for c in comments)
    z = read_npz(tmp_path / "pts.npz")
    assert np.array_equal(z["xyz"], new.point_xyz) and list(z["status_legend"][z["status"][:1]]) == ["optimal"]
    assert np.array_equal(z["gamma_ub"], [certs[int(i)].gamma_ub for i in z["point3D_id"]])
    assert main(["colmap", str(binary_in), str(tmp_path / "t"), "--output-type", "txt"]) == 0
    assert detect_format(tmp_path / "t") == "txt" and "rigs.bin not copied" in capsys.readouterr().out
    assert read_model(tmp_path / "t") == read_model(out)          # same model, both formats


def test_existing_output_is_replaced_only_when_complete(binary_in, tmp_path, monkeypatch, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "cameras.txt").write_text("precious\n")
    from tritools.sfm import folder

    calls = []

    def fail_on_second_chunk(self, chunk, xyz=None, error=None):
        calls.append(len(chunk))
        if len(calls) == 2:
            raise OSError(28, "No space left on device", str(out / "points3D.bin"))
        return original(self, chunk, xyz, error)
    original = folder.ModelWriter.write_points
    monkeypatch.setattr(folder.ModelWriter, "write_points", fail_on_second_chunk)
    assert main(["colmap", str(binary_in), str(out), "--chunk-points", "50"]) == 2
    assert "No space left on device" in _one_line_error(capsys)
    assert sorted(os.listdir(out)) == ["cameras.txt"] and (out / "cameras.txt").read_text() == "precious\n"
    assert sorted(os.listdir(tmp_path)) == ["in", "out"]         # no temporary directory left behind
    monkeypatch.undo()
    assert main(["colmap", str(binary_in), str(out)]) == 0      # now the model's files are written, nothing deleted
    assert sorted(os.listdir(out)) == sorted(["cameras.bin", "images.bin", "points3D.bin", CERTIFICATES_FILE,
                                              "rigs.bin", "cameras.txt"])
    assert (out / "cameras.txt").read_text() == "precious\n" and "kept as they were" in capsys.readouterr().out


def test_exports_are_not_left_half_written(binary_in, tmp_path, monkeypatch, capsys):
    from tritools.io import export

    (tmp_path / "pts.ply").write_bytes(b"old")
    monkeypatch.setattr(export, "_write_ply_file", lambda *a: (_ for _ in ()).throw(OSError(13, "Permission denied")))
    assert main(["colmap", str(binary_in), str(tmp_path / "out"), "--export", str(tmp_path / "pts.ply")]) == 2
    _one_line_error(capsys)
    assert (tmp_path / "pts.ply").read_bytes() == b"old" and not (tmp_path / "out").exists()
    assert sorted(os.listdir(tmp_path)) == ["in", "pts.ply"]


@pytest.mark.parametrize("flags, expect", [
    (["--delta", "3"], "--delta: delta must be an even integer >= 2, got 3"),            # the messages of `solve`
    (["--delta", "4", "--max-delta", "2"], "--max-delta: max_delta (2) must be >= delta (4)"),
    (["--max-delta", "5"], "--max-delta: max_delta must be an even integer >= 2, got 5"),
    (["--method", "nms"], "argument --method: invalid choice: 'nms'"),
    (["--time-limit", "0"], "--time-limit: must be a positive number of seconds, got 0"),
    (["--min-track-length", "1"], "--min-track-length: must be an integer >= 2, got 1"),
    (["--max-track-length", "1"], "--max-track-length: must be an integer >= 2, got 1"),
    (["--chunk-points", "0"], "--chunk-points: must be an integer >= 1, got 0"),
    (["--export", "pts.csv"], "--export: pts.csv: the file name must end with .ply or .npz"),
    (["--delta", "x"], "argument --delta: invalid int value: 'x'"),
    (["--behind", "drop"], "argument --behind: invalid choice: 'drop'"),
    (["--output-type", "json"], "argument --output-type: invalid choice"),
])
def test_bad_flags_exit_2_naming_the_flag(binary_in, tmp_path, capsys, flags, expect):
    assert main(["colmap", str(binary_in), str(tmp_path / "out")] + flags) == 2
    assert expect in _one_line_error(capsys)
    assert not (tmp_path / "out").exists()


def test_bad_paths_exit_2(binary_in, tmp_path, capsys):
    (tmp_path / "file").write_text("x")
    cases = [([str(binary_in), str(tmp_path / "file")], "exists and is not a directory"),
             ([str(binary_in), str(binary_in)], "OUT_DIR must differ from IN_DIR"),
             ([str(binary_in), str(tmp_path)], "contains IN_DIR"),
             ([str(tmp_path / "nowhere"), str(tmp_path / "o")], "nowhere: no such directory"),
             ([str(binary_in), str(tmp_path / "o"), "--input-type", "txt"], "cameras.txt: missing"),
             ([str(binary_in), str(tmp_path / "o"), "--export", str(tmp_path / "d.ply")], "d.ply: is a directory"),
             ([str(binary_in), str(tmp_path / "o"), "--export", str(tmp_path / "file" / "x.ply")],
              f"--export: {tmp_path / 'file' / 'x.ply'}: {tmp_path / 'file'} is not a directory"),
             ([str(binary_in), str(tmp_path / "file" / "sub" / "o")],
              f"OUT_DIR {tmp_path / 'file' / 'sub' / 'o'}: {tmp_path / 'file'} is not a directory")]
    (tmp_path / "d.ply").mkdir()
    for argv, expect in cases:
        assert main(["colmap"] + argv) == 2, argv
        assert expect in _one_line_error(capsys)
    assert (tmp_path / "file").read_text() == "x"


def test_bad_files_exit_2_with_location(binary_in, tmp_path, capsys):
    data = (binary_in / "points3D.bin").read_bytes()
    (binary_in / "points3D.bin").write_bytes(data[:-5])
    assert main(["colmap", str(binary_in), str(tmp_path / "o")]) == 2
    assert "points3D.bin: record 149 (offset " in _one_line_error(capsys)
    model, _ = synthetic_model(n_points=6, seed=1)
    write_text_model(model, tmp_path / "t")
    lines = (tmp_path / "t" / "points3D.txt").read_text().splitlines()
    (tmp_path / "t" / "points3D.txt").write_text("\n".join(lines[:-1] + [" ".join(lines[-1].split()[:-2])]))
    assert main(["colmap", str(tmp_path / "t"), str(tmp_path / "o")]) == 2
    assert f"points3D.txt:{len(lines)}: " in _one_line_error(capsys)
    assert not (tmp_path / "o").exists()


def test_cameras_are_skipped_or_refused_with_strict(tmp_path, capsys):
    model, _ = synthetic_model(n_points=10, noise_px=0.5, seed=3)
    cams = dict(model.cameras)
    cams[3] = Camera(3, "PINHOLE", 640, 480, (0.0, 800.0, 320.0, 240.0))      # focal 0: used by image 3
    write_binary_model(Model(cams, model.images, model.points3D), tmp_path / "in")
    assert main(["colmap", str(tmp_path / "in"), str(tmp_path / "o"), "--json"]) == 3   # written, with a warning
    captured = capsys.readouterr()
    out = json.loads(captured.out)
    assert "tritools: warning: 1 camera(s) could not be used (PINHOLE): 4 observation(s)" in captured.err
    (skip,) = out["skipped_cameras"]
    assert skip["camera_id"] == 3 and "focal length fx = 0.0 must be > 0" in skip["reason"]
    assert skip["reason"].startswith("cameras.bin: record 2 (offset ") and out["n_skipped_observations"] > 0
    assert out["n_points"] == 10 and len(out["points"]) == 10 and out["delta"] is None and out["max_delta"] is None
    assert out["method"] == "auto" and out["time_limit"] == 60                    # the defaults of `tritools solve`
    assert main(["colmap", str(tmp_path / "in"), str(tmp_path / "o2"), "--strict"]) == 2
    assert "cameras.bin: record 2 (offset " in _one_line_error(capsys) and not (tmp_path / "o2").exists()


def test_behind_points_in_the_summary_and_sidecar(tmp_path, capsys):
    write_text_model(behind_model(), tmp_path / "in")
    assert main(["colmap", str(tmp_path / "in"), str(tmp_path / "o")]) == 0
    text = capsys.readouterr().out
    assert "1 certified globally optimal, 1 updated, 1 behind a camera" in text
    assert "point3D 1 (2 views): optimal, behind a camera -- behind camera" in text
    assert read_model(tmp_path / "o").points3D[1].xyz == (0.3, 0.2, 50.0)
    assert main(["colmap", str(tmp_path / "in"), str(tmp_path / "w"), "--behind", "write"]) == 0
    capsys.readouterr()
    assert read_model(tmp_path / "w").points3D[1].xyz[2] == pytest.approx(-50.0)
    assert not read_certificates(tmp_path / "w")[1].certified


def test_help_describes_every_argument(capsys):
    assert main(["colmap", "--help"]) == 0
    text = capsys.readouterr().out
    for flag in ("--input-type", "--output-type", "--method", "--path", "--delta", "--max-delta",
                 "--min-track-length", "--max-track-length", "--behind", "--strict", "--export", "--chunk-points",
                 "--json", "--progress", "IN_DIR", "OUT_DIR"):
        assert flag in text
    assert "nothing else in OUT_DIR is touched" in " ".join(text.split())
    import argparse
    from tritools.cli.colmap import register
    ap = argparse.ArgumentParser()
    register(ap.add_subparsers())
    for sub in ap._subparsers._group_actions[0].choices.values():
        for action in sub._actions:
            assert action.help, (sub.prog, action.dest)


def test_corrupt_point_count_gives_one_error_line_and_no_progress_bar(tmp_path):
    """Review 21b F3: a points3D.bin whose header claims 32518 points but ends after a few records exits 2 with
    exactly one stderr line (no progress bar sized from the untrusted count, even past the bar's threshold)."""
    import struct
    import subprocess
    import sys

    from tests.test_colmap import synthetic_model
    from tritools.io.colmap import write_binary_model

    src = tmp_path / "in"
    write_binary_model(synthetic_model(n_points=6, seed=3)[0], src)
    b = bytearray((src / "points3D.bin").read_bytes())
    struct.pack_into("<Q", b, 0, 32518)
    (src / "points3D.bin").write_bytes(bytes(b))
    p = subprocess.run([sys.executable, "-m", "tritools", "colmap", str(src), str(tmp_path / "out")],
                       capture_output=True, text=True, timeout=300)
    lines = [ln for ln in p.stderr.replace("\r", "\n").splitlines() if ln.strip()]
    assert p.returncode == 2 and len(lines) == 1 and "points3D.bin" in lines[0], p.stderr
