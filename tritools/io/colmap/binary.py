"""COLMAP's binary model format (``cameras.bin``, ``images.bin``, ``points3D.bin``), read and written
as arrays (:class:`~.arrays.ModelArrays`).

Layout (little-endian, as COLMAP's ``reconstruction_io.cc`` writes it):

* ``cameras.bin``: uint64 num_cameras; per camera uint32 camera_id, int32 model_id, uint64 width,
  uint64 height, double params[n(model)] (model ids in :data:`.camera_models.COLMAP_MODEL_IDS`);
* ``images.bin``: uint64 num_reg_images; per image uint32 image_id, double qvec[4] (w, x, y, z),
  double tvec[3], uint32 camera_id, the name as NUL-terminated bytes, uint64 num_points2D, then
  per keypoint double x, double y, int64 point3D_id (-1: none; COLMAP writes uint64 max);
* ``points3D.bin``: uint64 num_points; per point uint64 point3D_id, double xyz[3], uint8 rgb[3],
  double error, uint64 track_length, then per element uint32 image_id, uint32 point2D_idx.

Reading is vectorised where the layout allows: each image's keypoints are one
``np.frombuffer``; ``points3D.bin`` is read in chunks of records (:class:`BinaryPointsReader`),
only the record boundaries are found by a loop, and every field of a chunk is gathered with one
numpy operation.  A truncated or inconsistent file raises :class:`~.model.ModelFormatError`
naming the file, the record and its byte offset.  Writing produces the same bytes as COLMAP.
"""
from __future__ import annotations

import math
import struct
from pathlib import Path

import numpy as np

from .camera_models import COLMAP_MODEL_IDS, COLMAP_MODEL_N_PARAMS, COLMAP_MODEL_NAMES
from ..atomic import atomic_open, naming_errors
from .model import ModelFormatError

__all__ = ["read_cameras_binary", "read_images_binary", "BinaryPointsReader", "write_cameras_binary",
           "write_images_binary", "BinaryPointsWriter", "KEYPOINT_DTYPE", "POINT_DTYPE", "TRACK_DTYPE"]

KEYPOINT_DTYPE = np.dtype([("x", "<f8"), ("y", "<f8"), ("id", "<i8")])
POINT_DTYPE = np.dtype([("id", "<u8"), ("xyz", "<f8", (3,)), ("rgb", "u1", (3,)), ("error", "<f8"), ("n", "<u8")])
TRACK_DTYPE = np.dtype([("image", "<u4"), ("kp", "<u4")])
_U64 = struct.Struct("<Q")
_CAM = struct.Struct("<IiQQ")
_IMG = struct.Struct("<I4d3dI")
#: bytes read from points3D.bin at a time (a chunk of records may need more).
READ_BLOCK = 1 << 23


def _fail(path: Path, where: str, msg: str):
    raise ModelFormatError(f"{path.name}: {where}: {msg}")


def _count(path: Path, data, what: str) -> int:
    if len(data) < 8:
        _fail(path, "offset 0", f"the file has {len(data)} bytes, too short for the number of {what} (8 bytes)")
    return _U64.unpack_from(data, 0)[0]


#: COLMAP's invalid camera / image id (uint32 max): never a model's (the text reader refuses it too, review 33c)
INVALID_ID32 = 2 ** 32 - 1


def read_cameras_binary(path) -> dict:
    """Camera table of ``cameras.bin``: dict of ``ids, models, width, height, params, sources``."""
    path = Path(path)
    data = path.read_bytes()
    n = _count(path, data, "cameras")
    pos, out = 8, {"ids": [], "models": [], "width": [], "height": [], "params": [], "sources": []}
    seen = set()
    for k in range(n):
        where = f"record {k} (offset {pos})"
        if pos + _CAM.size > len(data):
            _fail(path, where, f"file ends at byte {len(data)}: truncated (header says {n} cameras)")
        cid, mid, w, h = _CAM.unpack_from(data, pos)
        name = COLMAP_MODEL_NAMES.get(mid)
        if name is None:
            _fail(path, where, f"camera {cid}: unknown camera model id {mid} (known: 0..{max(COLMAP_MODEL_NAMES)})")
        m = COLMAP_MODEL_N_PARAMS[name]
        if pos + _CAM.size + 8 * m > len(data):
            _fail(path, where, f"file ends at byte {len(data)}: truncated (camera {cid} needs {m} params)")
        params = np.frombuffer(data, "<f8", m, pos + _CAM.size).astype(float)
        if not np.all(np.isfinite(params)):
            _fail(path, where, f"camera {cid}: PARAMS[{int(np.argmin(np.isfinite(params)))}] is not finite")
        if w == 0 or h == 0 or w > 2 ** 62 or h > 2 ** 62:
            _fail(path, where, f"camera {cid}: WIDTH and HEIGHT must be positive, got {w}x{h}")
        if cid == INVALID_ID32:
            _fail(path, where, f"camera_id {cid} is COLMAP's invalid id")
        if cid in seen:
            _fail(path, where, f"duplicate camera_id {cid}")
        seen.add(cid)
        for key, v in zip(("ids", "models", "width", "height", "params"), (cid, name, w, h, params)):
            out[key].append(v)
        out["sources"].append(f"{path.name}: {where}")
        pos += _CAM.size + 8 * m
    if pos != len(data):
        _fail(path, f"offset {pos}", f"{len(data) - pos} unexpected bytes after the last of {n} cameras")
    return out


def read_images_binary(path, camera_ids: np.ndarray) -> dict:
    """Images of ``images.bin``: dict of ``ids, qvec, tvec, camera (index into camera_ids), names,
    kp_offsets, kp_xy, kp_point3D`` (keypoints concatenated)."""
    path = Path(path)
    data = path.read_bytes()
    n = _count(path, data, "images")
    cam_index = {int(c): k for k, c in enumerate(camera_ids)}
    ids, qv, tv, cams, names, kps, seen, sources = [], [], [], [], [], [], set(), []
    pos = 8
    for k in range(n):
        where = f"record {k} (offset {pos})"
        if pos + _IMG.size > len(data):
            _fail(path, where, f"file ends at byte {len(data)}: truncated (header says {n} images)")
        iid, *vals, cid = _IMG.unpack_from(data, pos)
        end = data.find(b"\0", pos + _IMG.size)
        if end < 0:
            _fail(path, where, f"image {iid}: the name has no terminating NUL byte: truncated")
        name = data[pos + _IMG.size:end].decode("utf-8", "surrogateescape")
        if end + 9 > len(data):
            _fail(path, where, f"image {iid}: file ends at byte {len(data)}: truncated before num_points2D")
        m = _U64.unpack_from(data, end + 1)[0]
        start = end + 9
        if m > (len(data) - start) // KEYPOINT_DTYPE.itemsize:
            _fail(path, where, f"image {iid}: {m} keypoints need {m * KEYPOINT_DTYPE.itemsize} bytes, the file ends "
                               f"at byte {len(data)}: truncated")
        q, t = vals[:4], vals[4:]
        if not all(math.isfinite(v) for v in vals) or not any(q):
            _fail(path, where, f"image {iid}: qvec/tvec must be finite with a non-zero qvec, got {q} {t}")
        if cid not in cam_index:
            _fail(path, where, f"image {iid} refers to camera {cid}, which does not exist")
        if not name or name != name.strip() or "\n" in name or "\r" in name:
            _fail(path, where, f"image {iid}: name must be non-empty, one line, without leading or trailing "
                               f"whitespace, got {name!r}")
        if iid == INVALID_ID32:
            _fail(path, where, f"image_id {iid} is COLMAP's invalid id")
        if iid in seen:
            _fail(path, where, f"duplicate image_id {iid}")
        kp = np.frombuffer(data, KEYPOINT_DTYPE, m, start)
        if m and not (np.all(np.isfinite(kp["x"])) and np.all(np.isfinite(kp["y"]))):
            j = int(np.argmin(np.isfinite(kp["x"]) & np.isfinite(kp["y"])))
            _fail(path, where, f"image {iid}: keypoint {j} is not finite")
        if m and kp["id"].min() < -1:
            _fail(path, where, f"image {iid}: keypoint {int(np.argmin(kp['id']))} has point3D_id "
                               f"{int(kp['id'].min())} (must be >= 0, or -1 for none)")
        seen.add(iid)
        ids.append(iid)
        qv.append(q)
        tv.append(t)
        cams.append(cam_index[cid])
        names.append(name)
        kps.append(kp)
        sources.append(f"{path.name}: {where}")
        pos = start + m * KEYPOINT_DTYPE.itemsize
    if pos != len(data):
        _fail(path, f"offset {pos}", f"{len(data) - pos} unexpected bytes after the last of {n} images")
    kp = np.concatenate(kps) if kps else np.zeros(0, KEYPOINT_DTYPE)
    counts = np.array([len(a) for a in kps], np.int64)
    return {"ids": np.array(ids, np.int64), "qvec": np.array(qv, float).reshape(-1, 4),
            "tvec": np.array(tv, float).reshape(-1, 3), "camera": np.array(cams, np.int64), "names": tuple(names),
            "kp_offsets": np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
            "kp_xy": np.column_stack([kp["x"], kp["y"]]).astype(float).reshape(-1, 2),
            "kp_point3D": kp["id"].astype(np.int64), "sources": tuple(sources)}


class BinaryPointsReader:
    """``points3D.bin`` in chunks of records: ``n_points`` from the header, :meth:`chunks` yields
    ``(ids, xyz, rgb, error, track_lengths, track_image_ids, track_kp, offsets)`` arrays per chunk
    (``offsets``: byte offset of each record, for messages)."""

    def __init__(self, path):
        self.path = Path(path)
        self.size = self.path.stat().st_size
        with open(self.path, "rb") as fh:
            self.n_points = _count(self.path, fh.read(8), "points")

    def where(self, record: int, offset: int) -> str:
        """Location of a record, for messages."""
        return f"{self.path.name}: record {record} (offset {offset})"

    def chunks(self, size: int):
        """Yield the records in chunks of at most ``size`` points."""
        rec_size = POINT_DTYPE.itemsize
        unpack = _U64.unpack_from
        with open(self.path, "rb") as fh:
            fh.seek(8)
            buf = bytearray()
            base = 8                                   # file offset of buf[0]
            rec = 0
            while rec < self.n_points:
                starts, lens = [], []
                rel = 0
                while rec < self.n_points and len(starts) < size:
                    if rel + rec_size > len(buf):
                        buf += fh.read(max(READ_BLOCK, rel + rec_size - len(buf)))
                        if rel + rec_size > len(buf):
                            _fail(self.path, f"record {rec} (offset {base + rel})",
                                  f"file ends at byte {self.size}: truncated (header says {self.n_points} points)")
                    n = unpack(buf, rel + 43)[0]
                    end = rel + rec_size + 8 * n
                    if base + end > self.size:
                        pid = unpack(buf, rel)[0]
                        _fail(self.path, f"record {rec} (offset {base + rel})",
                              f"point3D {pid}: track_length {n} needs {8 * n} bytes, the file ends at byte "
                              f"{self.size}: truncated or corrupt")
                    if end > len(buf):
                        buf += fh.read(max(READ_BLOCK, end - len(buf)))
                    starts.append(rel)
                    lens.append(n)
                    rel = end
                    rec += 1
                yield self._parse(buf, np.array(starts, np.int64), np.array(lens, np.int64), base)
                del buf[:rel]
                base += rel
            if buf or fh.read(1):
                _fail(self.path, f"offset {base}", f"{self.size - base} unexpected bytes after the last of "
                                                   f"{self.n_points} points")

    @staticmethod
    def _parse(buf, starts, lens, base):
        arr = np.frombuffer(buf, np.uint8)
        try:
            hdr = arr[starts[:, None] + np.arange(POINT_DTYPE.itemsize)].view(POINT_DTYPE)[:, 0]
            T = int(lens.sum())
            first = np.repeat(np.cumsum(lens) - lens, lens)
            pos = np.repeat(starts + POINT_DTYPE.itemsize, lens) + 8 * (np.arange(T) - first)
            tr = arr[pos[:, None] + np.arange(8)].view(TRACK_DTYPE)[:, 0]
        finally:
            del arr                                  # the bytearray can be resized again
        return (hdr["id"], hdr["xyz"].astype(float), hdr["rgb"].copy(), hdr["error"].astype(float), lens,
                tr["image"].astype(np.int64), tr["kp"].astype(np.int64), starts + base)


def _check_id(value: int, bits: int, what: str) -> None:
    if not 0 <= value < 2 ** bits:
        raise ValueError(f"{what} {value} cannot be written in COLMAP's binary format (uint{bits})")


def write_cameras_binary(arrays, path) -> None:
    """Write the camera table of a :class:`~.arrays.ModelArrays` as ``cameras.bin``."""
    parts = [_U64.pack(arrays.n_cameras)]
    for cid, model, w, h, params in zip(arrays.camera_ids.tolist(), arrays.camera_models, arrays.camera_width.tolist(),
                                        arrays.camera_height.tolist(), arrays.camera_params):
        _check_id(cid, 32, "camera_id")
        parts.append(_CAM.pack(cid, COLMAP_MODEL_IDS[model], w, h))
        parts.append(np.asarray(params, "<f8").tobytes())
    with atomic_open(path, "wb") as fh:
        fh.write(b"".join(parts))


def write_images_binary(arrays, path) -> None:
    """Write the images and keypoints of a :class:`~.arrays.ModelArrays` as ``images.bin``."""
    kp = np.empty(len(arrays.kp_point3D), KEYPOINT_DTYPE)
    kp["x"], kp["y"], kp["id"] = arrays.kp_xy[:, 0], arrays.kp_xy[:, 1], arrays.kp_point3D
    off = arrays.kp_offsets.tolist()
    with atomic_open(path, "wb") as fh:
        fh.write(_U64.pack(arrays.n_images))
        for v, iid in enumerate(arrays.image_ids.tolist()):
            _check_id(iid, 32, "image_id")
            cid = int(arrays.camera_ids[arrays.image_camera[v]])
            fh.write(_IMG.pack(iid, *arrays.image_qvec[v].tolist(), *arrays.image_tvec[v].tolist(), cid))
            fh.write(arrays.image_names[v].encode("utf-8", "surrogateescape") + b"\0")
            fh.write(_U64.pack(off[v + 1] - off[v]))
            fh.write(kp[off[v]:off[v + 1]].tobytes())


class BinaryPointsWriter:
    """``points3D.bin`` written chunk by chunk (:meth:`write`); :meth:`close` patches the count."""

    def __init__(self, path):
        self.path = Path(path)
        self.fh = open(self.path, "wb")
        self.fh.write(_U64.pack(0))
        self.n_points = 0
        self.n_observations = 0

    def write(self, ids, xyz, rgb, error, track_lengths, track_image_ids, track_kp) -> None:
        """Append points (arrays as in :class:`BinaryPointsReader`; image *ids* in the track)."""
        n = len(ids)
        if n and (np.min(ids) < 0 or np.min(track_image_ids, initial=0) < 0 or np.min(track_kp, initial=0) < 0
                  or np.max(track_image_ids, initial=0) >= 2 ** 32 or np.max(track_kp, initial=0) >= 2 ** 32):
            raise ValueError("point3D ids, image ids and keypoint indices must be non-negative integers that fit "
                             "COLMAP's binary format")
        hdr = np.empty(n, POINT_DTYPE)
        hdr["id"], hdr["xyz"], hdr["rgb"], hdr["error"], hdr["n"] = ids, xyz, rgb, error, track_lengths
        tr = np.empty(len(track_kp), TRACK_DTYPE)
        tr["image"], tr["kp"] = track_image_ids, track_kp
        lens = np.asarray(track_lengths, np.int64)
        sizes = POINT_DTYPE.itemsize + 8 * lens
        starts = np.cumsum(sizes) - sizes
        out = np.empty(int(sizes.sum()), np.uint8)
        out[starts[:, None] + np.arange(POINT_DTYPE.itemsize)] = hdr.view(np.uint8).reshape(n, POINT_DTYPE.itemsize)
        T = len(tr)
        first = np.repeat(np.cumsum(lens) - lens, lens)
        pos = np.repeat(starts + POINT_DTYPE.itemsize, lens) + 8 * (np.arange(T) - first)
        out[pos[:, None] + np.arange(8)] = tr.view(np.uint8).reshape(T, 8)
        with naming_errors(self.path):
            self.fh.write(out.tobytes())
        self.n_points += n
        self.n_observations += T

    def close(self) -> None:
        """Write the number of points into the header and close."""
        with naming_errors(self.path):
            self.fh.seek(0)
            self.fh.write(_U64.pack(self.n_points))
            self.fh.close()

    def abort(self) -> None:
        """Close without completing (the caller discards the file)."""
        self.fh.close()
