"""COLMAP binary models and the array representation: bit-exact round trips (bin, txt -> bin -> txt),
pycolmap as an oracle for the byte layout, format detection, and truncated / corrupt files refused
with their location (record and byte offset, or file:line)."""
from __future__ import annotations

import filecmp
import struct

import numpy as np
import pytest

from tests.test_colmap import synthetic_model
from tritools.io.colmap import (Image, Model, ModelArrays, ModelFormatError, detect_format, read_binary_model,
                                read_model, read_model_arrays, read_text_model, write_binary_model, write_model,
                                write_model_arrays, write_text_model)
from tritools.io.colmap.formats import BINARY_FILES, TEXT_FILES, open_model
from tritools.sfm.synthetic import synthetic_arrays


def _no_space_names(model):
    """COLMAP's own text reader stops a NAME at the first space: keep names space-free for pycolmap."""
    return Model(model.cameras, {i: Image(im.id, im.qvec, im.tvec, im.camera_id, im.name.replace(" ", "_"),
                                          im.points2D) for i, im in model.images.items()}, model.points3D)


@pytest.fixture(scope="module")
def model():
    return synthetic_model(n_points=25, noise_px=0.7, seed=11)[0]


def test_binary_round_trip_is_bit_exact(model, tmp_path):
    write_binary_model(model, tmp_path / "a")
    assert detect_format(tmp_path / "a") == "bin"
    back = read_binary_model(tmp_path / "a")
    assert back == model                                         # every float bit for bit
    write_binary_model(back, tmp_path / "b")
    for name in BINARY_FILES:
        assert filecmp.cmp(tmp_path / "a" / name, tmp_path / "b" / name, shallow=False)


def test_text_to_binary_to_text_is_byte_identical(model, tmp_path):
    write_text_model(model, tmp_path / "t1")
    arrays = read_model_arrays(tmp_path / "t1")
    assert arrays.equals(ModelArrays.from_model(model)) and arrays.to_model() == model
    write_model_arrays(arrays, tmp_path / "b", "bin")
    write_model_arrays(read_model_arrays(tmp_path / "b"), tmp_path / "t2", "txt")
    for name in TEXT_FILES:                                      # the arrays writer = the Model writer
        assert (tmp_path / "t1" / name).read_bytes() == (tmp_path / "t2" / name).read_bytes()
    assert read_model(tmp_path / "t2") == model == read_model(tmp_path / "b")


def test_arrays_stream_in_chunks_and_synthetic_models_round_trip(tmp_path):
    a, _ = synthetic_arrays(n_points=500, n_images=12, camera="OPENCV", seed=3)
    write_model_arrays(a, tmp_path / "b", "bin")
    write_model_arrays(a, tmp_path / "t", "txt")
    for fmt in ("b", "t"):
        for chunk in (1, 7, 500, 10_000):
            assert read_model_arrays(tmp_path / fmt, chunk_points=chunk).equals(a)
    src = open_model(tmp_path / "b")
    sizes = [len(c) for c in src.chunks(128)]
    assert sizes == [128, 128, 128, 116] and src.n_points == 500 and open_model(tmp_path / "t").count_points() == 500


def test_pycolmap_writes_the_same_bytes_and_reads_ours(model, tmp_path):
    pycolmap = pytest.importorskip("pycolmap", reason="pycolmap not installed (extra 'colmap')")
    m = _no_space_names(model)
    write_text_model(m, tmp_path / "txt")
    write_binary_model(m, tmp_path / "ours")
    rec = pycolmap.Reconstruction(str(tmp_path / "txt"))
    (tmp_path / "theirs").mkdir()
    rec.write_binary(str(tmp_path / "theirs"))
    for name in BINARY_FILES:                                    # COLMAP's own writer: same bytes
        assert filecmp.cmp(tmp_path / "ours" / name, tmp_path / "theirs" / name, shallow=False), name
    assert read_binary_model(tmp_path / "theirs") == m
    rec2 = pycolmap.Reconstruction(str(tmp_path / "ours"))       # and COLMAP reads ours
    assert (len(rec2.cameras), len(rec2.images), len(rec2.points3D)) == (5, 6, 25)
    for pid, p in m.points3D.items():
        assert np.array_equal(rec2.points3D[pid].xyz, p.xyz) and rec2.points3D[pid].error == p.error
    for iid, im in m.images.items():
        assert rec2.images[iid].name == im.name
        assert [q.point3D_id for q in rec2.images[iid].points2D if q.has_point3D()] == \
            [k for _, _, k in im.points2D if k != -1]


def test_detect_format_and_missing_files(model, tmp_path):
    write_text_model(model, tmp_path / "m")
    assert detect_format(tmp_path / "m") == "txt"
    write_binary_model(model, tmp_path / "m")                    # both complete: binary, as COLMAP
    assert detect_format(tmp_path / "m") == "bin"
    (tmp_path / "m" / "images.bin").unlink()
    assert detect_format(tmp_path / "m") == "txt"
    for name in TEXT_FILES:
        (tmp_path / "m" / name).unlink()
    with pytest.raises(FileNotFoundError, match="images.bin: missing \\(a COLMAP binary model has cameras.bin, "
                                                "images.bin, points3D.bin\\)"):
        detect_format(tmp_path / "m")
    with pytest.raises(FileNotFoundError, match="no such directory"):
        read_model(tmp_path / "nowhere")


# ----------------------------------------------------------------------------- corrupt binary files
def _binary(model, tmp_path):
    write_binary_model(model, tmp_path)
    return {n: (tmp_path / n).read_bytes() for n in BINARY_FILES}


def _corrupt(files, name, data, tmp_path):
    for n, d in files.items():
        (tmp_path / n).write_bytes(data if n == name else d)
    with pytest.raises(ModelFormatError) as exc:
        read_model_arrays(tmp_path, chunk_points=4)
    return str(exc.value)


def _points_offsets(data):
    """Byte offset of every points3D.bin record."""
    n, pos, out = struct.unpack_from("<Q", data)[0], 8, []
    for _ in range(n):
        out.append(pos)
        pos += 51 + 8 * struct.unpack_from("<Q", data, pos + 43)[0]
    return out


def test_corrupt_cameras_and_images_bin_are_refused_with_record_and_offset(model, tmp_path):
    f = _binary(model, tmp_path)
    cams = f["cameras.bin"]
    msg = _corrupt(f, "cameras.bin", cams[:-3], tmp_path)
    assert msg.startswith("cameras.bin: record 4 (offset ") and "truncated (camera 5 needs 8 params)" in msg
    bad = bytearray(cams)
    bad[12:16] = struct.pack("<i", 99)                           # model id of the first camera
    assert _corrupt(f, "cameras.bin", bytes(bad), tmp_path) == \
        "cameras.bin: record 0 (offset 8): camera 1: unknown camera model id 99 (known: 0..17)"
    assert "1 unexpected bytes after the last of 5 cameras" in _corrupt(f, "cameras.bin", cams + b"\0", tmp_path)
    assert "too short for the number of cameras" in _corrupt(f, "cameras.bin", b"\1\0", tmp_path)
    ims = f["images.bin"]
    msg = _corrupt(f, "images.bin", ims[:-30], tmp_path)
    assert msg.startswith("images.bin: record 5 (offset ") and "truncated" in msg
    bad = bytearray(ims)
    bad[8 + 60:8 + 64] = struct.pack("<I", 42)                    # camera id of the first image
    assert _corrupt(f, "images.bin", bytes(bad), tmp_path) == \
        "images.bin: record 0 (offset 8): image 1 refers to camera 42, which does not exist"
    bad = bytearray(ims)
    bad[0:8] = struct.pack("<Q", 7)                              # one image more than there is
    assert "record 6 (offset " in _corrupt(f, "images.bin", bytes(bad), tmp_path)
    # COLMAP's invalid id (uint32 max) as a camera's or an image's id (review 33c: the text reader refused it)
    bad = bytearray(cams)
    bad[8:12] = struct.pack("<I", 2 ** 32 - 1)
    assert "camera_id 4294967295 is COLMAP's invalid id" in _corrupt(f, "cameras.bin", bytes(bad), tmp_path)
    bad = bytearray(ims)
    bad[8:12] = struct.pack("<I", 2 ** 32 - 1)
    assert "image_id 4294967295 is COLMAP's invalid id" in _corrupt(f, "images.bin", bytes(bad), tmp_path)


def test_corrupt_points3d_bin_is_refused_with_record_and_offset(model, tmp_path):
    f = _binary(model, tmp_path)
    pts = f["points3D.bin"]
    offs = _points_offsets(pts)
    msg = _corrupt(f, "points3D.bin", pts[:-3], tmp_path)         # last record cut
    assert msg.startswith(f"points3D.bin: record 24 (offset {offs[24]}): point3D 25: track_length") and \
        "truncated or corrupt" in msg
    bad = bytearray(pts)
    bad[0:8] = struct.pack("<Q", 26)
    assert _corrupt(f, "points3D.bin", bytes(bad), tmp_path) == \
        f"points3D.bin: record 25 (offset {len(pts)}): file ends at byte {len(pts)}: truncated (header says 26 points)"
    bad = bytearray(pts)                                         # the last point dropped, count fixed
    bad = bad[:offs[24]]
    bad[0:8] = struct.pack("<Q", 24)
    msg = _corrupt(f, "points3D.bin", bytes(bad), tmp_path)
    assert msg.startswith("images.bin: record ") and "refers to point3D 25, which does not exist" in msg
    bad = bytearray(pts)                                         # first track element -> another keypoint
    struct.pack_into("<I", bad, offs[0] + 51 + 4, 0 if struct.unpack_from("<I", pts, offs[0] + 55)[0] else 1)
    msg = _corrupt(f, "points3D.bin", bytes(bad), tmp_path)
    assert msg.startswith("points3D.bin: record 0 (offset 8): point3D 1 track refers to keypoint ")
    bad = bytearray(pts)
    struct.pack_into("<I", bad, offs[3] + 51, 77)                # image id
    assert _corrupt(f, "points3D.bin", bytes(bad), tmp_path) == \
        f"points3D.bin: record 3 (offset {offs[3]}): point3D 4 track refers to image 77, which does not exist"
    assert "unexpected bytes after the last of 25 points" in _corrupt(f, "points3D.bin", pts + b"xx", tmp_path)


# ----------------------------------------------------------------------------- truncated text files
@pytest.mark.parametrize("cut, expect", [
    (lambda line: " ".join(line.split()[:-1]), "TRACK[] must be (IMAGE_ID, POINT2D_IDX) pairs"),   # mid pair
    (lambda line: " ".join(line.split()[:-2]), "does not list"),                             # at a pair boundary
    (lambda line: " ".join(line.split()[:8]), "has an empty TRACK[]"),                        # before the track
    (lambda line: " ".join(line.split()[:5]), "expected POINT3D_ID X Y Z R G B ERROR TRACK[] (8 fields)"),
    (lambda line: line[:-1], ""),                                                            # last digit cut
])
def test_truncated_points3d_txt_is_refused_by_both_readers(model, tmp_path, cut, expect):
    write_text_model(model, tmp_path)
    path = tmp_path / "points3D.txt"
    lines = path.read_text().splitlines()
    lines[-1] = cut(lines[-1])
    path.write_text("\n".join(lines))                            # no final newline, as a cut file
    n = len(lines)
    for reader in (read_text_model, read_model_arrays):
        with pytest.raises(ModelFormatError) as exc:
            reader(tmp_path)
        assert str(exc.value).startswith(f"points3D.txt:{n}: ") and expect in str(exc.value), str(exc.value)


def test_truncated_images_txt_is_refused(model, tmp_path):
    write_text_model(model, tmp_path)
    path = tmp_path / "images.txt"
    lines = path.read_text().splitlines()
    path.write_text("\n".join(lines[:-3]))                       # the last image without its POINTS2D line
    for reader in (read_text_model, read_model_arrays):
        with pytest.raises(ModelFormatError, match=f"images.txt:{len(lines) - 3}: image 5 has no POINTS2D line"):
            reader(tmp_path)
    lines[-3] = " ".join(lines[-3].split()[:-6])                 # image 5's last two keypoints cut
    path.write_text("\n".join(lines) + "\n")
    for reader in (read_text_model, read_model_arrays):
        with pytest.raises(ModelFormatError, match="points3D.txt:[0-9]+: point3D [0-9]+ track refers to keypoint "
                                                   "[0-9]+ of image 5, which has"):
            reader(tmp_path)


def test_bad_tokens_in_text_are_located_by_the_array_reader(model, tmp_path):
    write_text_model(model, tmp_path)
    path = tmp_path / "points3D.txt"
    lines = path.read_text().splitlines()
    t = lines[5].split()
    lines[5] = " ".join(t[:1] + ["x"] + t[2:])
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ModelFormatError, match="points3D.txt:6: X must be a number, got 'x'"):
        read_model_arrays(tmp_path)
    write_text_model(model, tmp_path)
    path = tmp_path / "images.txt"
    lines = path.read_text().splitlines()
    lines[5] = lines[5] + " 1.0 2.0 -7"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ModelFormatError, match="images.txt:6: POINT3D_ID of keypoint [0-9]+ must be >= -1, got -7"):
        read_model_arrays(tmp_path)


def test_write_model_refuses_ids_binary_cannot_hold(model, tmp_path):
    m = Model(model.cameras, model.images, model.points3D)
    write_model(m, tmp_path / "ok", "bin")
    a = ModelArrays.from_model(m)
    bad = ModelArrays(**{**{k: getattr(a, k) for k in a.__dataclass_fields__}, "image_ids": a.image_ids - 10})
    with pytest.raises(ValueError, match="image_id -9 cannot be written in COLMAP's binary format"):
        write_model_arrays(bad, tmp_path / "bad", "bin")


def test_unusual_but_valid_text_takes_the_exact_parser(model, tmp_path):
    """Tabs, doubled spaces and a POINT3D_ID beyond 2^53 (not exact through float64): the array reader
    falls back to the per-line parser and reads the same model as read_text_model."""
    big = 2 ** 60 + 1
    p = model.points3D[3]
    images = dict(model.images)
    for iid, k in p.track:
        im = images[iid]
        pts = list(im.points2D)
        pts[k] = (pts[k][0], pts[k][1], big)
        images[iid] = Image(im.id, im.qvec, im.tvec, im.camera_id, im.name, tuple(pts))
    points = {k: v for k, v in model.points3D.items() if k != 3}
    points[big] = type(p)(big, p.xyz, p.rgb, p.error, p.track)
    m = Model(model.cameras, images, points)
    write_text_model(m, tmp_path)
    path = tmp_path / "points3D.txt"
    path.write_text(path.read_text().replace(" ", "\t", 3).replace(" 1 ", "  1 "))
    assert read_model_arrays(tmp_path, chunk_points=5).to_model() == read_text_model(tmp_path) == m
