"""Reading and writing whole COLMAP models, binary or text, as arrays or as :class:`~.model.Model`.

* :func:`detect_format` tells a binary model (``cameras.bin``, ``images.bin``, ``points3D.bin``) from
  a text one (the ``.txt`` files); binary wins when both are complete, as in COLMAP.
* :func:`open_model` reads the cameras and images (with every keypoint) and returns a
  :class:`ModelSource`, whose :meth:`ModelSource.chunks` streams the 3D points in chunks of
  :class:`~.arrays.PointChunk`, checking every cross reference on the way (and, at the end, that
  no keypoint names a point whose track does not list it).  Memory: the keypoints plus one chunk.
* :func:`read_model_arrays` / :func:`write_model_arrays`: a whole :class:`~.arrays.ModelArrays`;
  :class:`ModelWriter` writes cameras and images at once and points chunk by chunk.
* :func:`read_model`, :func:`write_model`, :func:`read_binary_model`, :func:`write_binary_model`:
  the same for :class:`~.model.Model` objects.

Errors in the files raise :class:`~.model.ModelFormatError` naming the file and line (text) or
record and byte offset (binary).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .arrays import ModelArrays, PointChunk, check_references, unlisted_keypoint
from .binary import (BinaryPointsReader, BinaryPointsWriter, read_cameras_binary, read_images_binary,
                     write_cameras_binary, write_images_binary)
from .model import MODEL_FILES, Model, ModelFormatError
from .text_arrays import (TextPointsReader, TextPointsWriter, read_cameras_text, read_images_text,
                          write_cameras_text, write_images_text)

__all__ = ["BINARY_FILES", "TEXT_FILES", "FORMATS", "detect_format", "ModelSource", "open_model",
           "read_model_arrays", "write_model_arrays", "ModelWriter", "read_model", "write_model",
           "read_binary_model", "write_binary_model", "DEFAULT_CHUNK_POINTS"]

BINARY_FILES = ("cameras.bin", "images.bin", "points3D.bin")
TEXT_FILES = MODEL_FILES
FORMATS = ("bin", "txt")
#: points per chunk when streaming points3D.
DEFAULT_CHUNK_POINTS = 100_000


def model_files(fmt: str) -> tuple:
    return BINARY_FILES if fmt == "bin" else TEXT_FILES


def detect_format(folder) -> str:
    """``"bin"`` or ``"txt"``: the complete COLMAP model in ``folder`` (binary first, as COLMAP).

    Raises FileNotFoundError naming the missing file of a partial model, or the folder."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"{folder}: no such directory")
    for fmt in FORMATS:
        if all((folder / f).is_file() for f in model_files(fmt)):
            return fmt
    for fmt in FORMATS:
        have = [f for f in model_files(fmt) if (folder / f).is_file()]
        if have:
            missing = next(f for f in model_files(fmt) if f not in have)
            kind = "binary" if fmt == "bin" else "text"
            raise FileNotFoundError(f"{folder / missing}: missing (a COLMAP {kind} model has "
                                    f"{', '.join(model_files(fmt))})")
    raise FileNotFoundError(f"{folder}: no COLMAP model ({', '.join(BINARY_FILES)} or {', '.join(TEXT_FILES)})")


@dataclass
class ModelSource:
    """Cameras and images of a model on disk (``arrays``, without points) and its points, streamed.

    ``n_points`` is known up front for binary models, None for text ones (see
    :meth:`count_points`)."""
    folder: Path
    format: str
    arrays: ModelArrays
    reader: object

    @property
    def n_points(self) -> int | None:
        """Number of points if the file says (binary), else None."""
        return self.reader.n_points

    def count_points(self) -> int:
        """Number of points (for text: one quick pass over points3D.txt)."""
        return self.reader.n_points if self.reader.n_points is not None else self.reader.count()

    def _image_index(self):
        ids = self.arrays.image_ids
        order = np.argsort(ids, kind="stable")
        return ids[order], order

    def chunks(self, size: int = DEFAULT_CHUNK_POINTS):
        """Yield :class:`~.arrays.PointChunk` of at most ``size`` points, every reference checked.

        The final checks (unique ids; every keypoint naming a point is listed by its track) run
        after the last chunk, so a consumer must exhaust the generator before trusting its output."""
        if int(size) != size or size < 1:
            raise ValueError(f"chunk size must be a positive integer, got {size!r}")
        a = self.arrays
        sorted_ids, order = self._image_index()
        seen = np.zeros(len(a.kp_point3D), bool)
        all_ids, all_loc, start = [], [], 0
        for ids, xyz, rgb, err, lens, timg, tkp, loc in self.reader.chunks(int(size)):
            pos = np.minimum(np.searchsorted(sorted_ids, timg), max(len(sorted_ids) - 1, 0))
            ok = sorted_ids[pos] == timg if len(sorted_ids) else np.zeros(len(timg), bool)
            owner = np.repeat(np.arange(len(ids)), lens)
            if not ok.all():
                t = int(np.argmin(ok))
                p = int(owner[t])
                raise ModelFormatError(f"{self.reader.where(start + p, loc[p])}: point3D {int(ids[p])} track refers "
                                       f"to image {int(timg[t])}, which does not exist")
            offsets = np.concatenate([[0], np.cumsum(lens)]).astype(np.int64)
            chunk = PointChunk(ids.astype(np.int64), xyz, rgb, err, offsets, order[pos], tkp, start, loc)
            bad = check_references(a, chunk, seen)
            if bad is not None:
                p, msg = bad
                raise ModelFormatError(f"{self.reader.where(start + p, loc[p])}: {msg}")
            all_ids.append(chunk.ids)
            all_loc.append(loc)
            start += len(ids)
            yield chunk
        ids = np.concatenate(all_ids) if all_ids else np.zeros(0, np.int64)
        loc = np.concatenate(all_loc) if all_loc else np.zeros(0, np.int64)
        order_p = np.argsort(ids, kind="stable")
        dup = np.nonzero(ids[order_p][1:] == ids[order_p][:-1])[0]
        if dup.size:
            p = int(order_p[dup[0] + 1])
            raise ModelFormatError(f"{self.reader.where(p, loc[p])}: duplicate POINT3D_ID {int(ids[p])}")
        miss = unlisted_keypoint(a, seen)
        if miss is not None:
            v, k, pid = miss
            j = np.searchsorted(ids[order_p], pid)
            if j < len(ids) and ids[order_p][j] == pid:
                p = int(order_p[j])
                raise ModelFormatError(f"{self.reader.where(p, loc[p])}: the track of point3D {pid} does not list "
                                       f"keypoint {k} of image {int(a.image_ids[v])}, whose POINT3D_ID is {pid} "
                                       f"(track cut short?)")
            raise ModelFormatError(f"{a.sources['images'][v]}: image {int(a.image_ids[v])} keypoint {k} refers to "
                                   f"point3D {pid}, which does not exist (points3D file cut short?)")


def open_model(folder, fmt: str | None = None) -> ModelSource:
    """Read the cameras and images of the model in ``folder`` (format detected when ``fmt`` is None)."""
    folder = Path(folder)
    if fmt is None:
        fmt = detect_format(folder)
    elif fmt not in FORMATS:
        raise ValueError(f"model format must be one of {FORMATS}, got {fmt!r}")
    else:
        for f in model_files(fmt):
            if not (folder / f).is_file():
                raise FileNotFoundError(f"{folder / f}: missing")
    names = model_files(fmt)
    if fmt == "bin":
        cams = read_cameras_binary(folder / names[0])
        ims = read_images_binary(folder / names[1], np.array(cams["ids"], np.int64))
        reader = BinaryPointsReader(folder / names[2])
    else:
        cams = read_cameras_text(folder / names[0])
        ims = read_images_text(folder / names[1], np.array(cams["ids"], np.int64))
        reader = TextPointsReader(folder / names[2])
    arrays = ModelArrays(
        camera_ids=np.array(cams["ids"], np.int64), camera_models=tuple(cams["models"]),
        camera_width=np.array(cams["width"], np.int64), camera_height=np.array(cams["height"], np.int64),
        camera_params=tuple(cams["params"]), image_ids=ims["ids"], image_qvec=ims["qvec"], image_tvec=ims["tvec"],
        image_camera=ims["camera"], image_names=ims["names"], kp_offsets=ims["kp_offsets"], kp_xy=ims["kp_xy"],
        kp_point3D=ims["kp_point3D"], point_ids=np.zeros(0, np.int64), point_xyz=np.zeros((0, 3)),
        point_rgb=np.zeros((0, 3), np.uint8), point_error=np.zeros(0), track_offsets=np.zeros(1, np.int64),
        track_image=np.zeros(0, np.int64), track_kp=np.zeros(0, np.int64),
        sources={"cameras": tuple(cams["sources"]), "images": ims["sources"],
                 "format": fmt})
    return ModelSource(folder, fmt, arrays, reader)


def read_model_arrays(folder, fmt: str | None = None, chunk_points: int = DEFAULT_CHUNK_POINTS) -> ModelArrays:
    """The whole model in ``folder`` as :class:`~.arrays.ModelArrays` (points in file order)."""
    src = open_model(folder, fmt)
    chunks = list(src.chunks(chunk_points))
    a = src.arrays
    if not chunks:
        return a
    lens = np.concatenate([c.track_lengths for c in chunks])
    fields = {k: getattr(a, k) for k in a.__dataclass_fields__}
    fields.update(point_ids=np.concatenate([c.ids for c in chunks]),
                  point_xyz=np.concatenate([c.xyz for c in chunks]),
                  point_rgb=np.concatenate([c.rgb for c in chunks]),
                  point_error=np.concatenate([c.error for c in chunks]),
                  track_offsets=np.concatenate([[0], np.cumsum(lens)]).astype(np.int64),
                  track_image=np.concatenate([c.track_image for c in chunks]),
                  track_kp=np.concatenate([c.track_kp for c in chunks]))
    return ModelArrays(**fields)


class ModelWriter:
    """Write a model into ``folder``: cameras and images of ``arrays`` at once, points by
    :meth:`write_points`; :meth:`close` completes points3D (its count / header)."""

    def __init__(self, arrays: ModelArrays, folder, fmt: str = "bin"):
        if fmt not in FORMATS:
            raise ValueError(f"output format must be one of {FORMATS}, got {fmt!r}")
        self.arrays = arrays
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        names = model_files(fmt)
        (write_cameras_binary if fmt == "bin" else write_cameras_text)(arrays, self.folder / names[0])
        (write_images_binary if fmt == "bin" else write_images_text)(arrays, self.folder / names[1])
        self.points = (BinaryPointsWriter if fmt == "bin" else TextPointsWriter)(self.folder / names[2])

    def write_points(self, chunk: PointChunk, xyz=None, error=None) -> None:
        """Append the chunk's points (with new ``xyz``/``error`` when given)."""
        self.points.write(chunk.ids, chunk.xyz if xyz is None else xyz, chunk.rgb,
                          chunk.error if error is None else error, chunk.track_lengths,
                          self.arrays.image_ids[chunk.track_image], chunk.track_kp)

    def close(self) -> None:
        """Complete the points file."""
        self.points.close()

    def abort(self) -> None:
        """Close without completing."""
        self.points.abort()


def write_model_arrays(arrays: ModelArrays, folder, fmt: str = "bin") -> Path:
    """Write a whole :class:`~.arrays.ModelArrays` (points in array order); returns the folder.
    The three files replace their namesakes atomically; nothing else in ``folder`` is touched
    (:func:`tritools.io.atomic.staged_directory`)."""
    from ..atomic import staged_directory

    with staged_directory(folder) as stage:
        w = ModelWriter(arrays, stage, fmt)
        try:
            w.write_points(arrays.points())
        except BaseException:
            w.abort()
            raise
        w.close()
    return Path(folder)


def read_model(folder, fmt: str | None = None) -> Model:
    """The :class:`~.model.Model` in ``folder``, binary or text (detected when ``fmt`` is None)."""
    return read_model_arrays(folder, fmt).to_model()


def write_model(model: Model, folder, fmt: str = "txt") -> Path:
    """Write a :class:`~.model.Model` as a binary (``"bin"``) or text (``"txt"``) model."""
    return write_model_arrays(ModelArrays.from_model(model), folder, fmt)


def read_binary_model(folder) -> Model:
    """:func:`read_model` of a binary model."""
    return read_model(folder, "bin")


def write_binary_model(model: Model, folder) -> Path:
    """:func:`write_model` in COLMAP's binary format."""
    return write_model(model, folder, "bin")
