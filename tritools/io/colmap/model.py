"""COLMAP sparse models in COLMAP's documented text format (cameras.txt, images.txt, points3D.txt).

* ``cameras.txt``: ``CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]``, one line per camera;
* ``images.txt``: two lines per image, ``IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME``
  then ``POINTS2D[]`` as ``X Y POINT3D_ID`` triples (``-1``: no 3D point; the line is
  empty for an image without keypoints).  ``(QW, QX, QY, QZ)`` is the Hamilton unit
  quaternion (w first) and ``(TX, TY, TZ)`` the translation of ``cam_from_world``:
  ``X_cam = R(q) X_world + t``;
* ``points3D.txt``: ``POINT3D_ID X Y Z R G B ERROR TRACK[]`` with the track as
  ``IMAGE_ID POINT2D_IDX`` pairs (0-based index into that image's POINTS2D).

Comment lines start with ``#``.  A file cut short is refused: a points3D.txt line with fewer
than 8 fields, an odd number of TRACK[] fields or an empty track, an image without its POINTS2D
line, or a keypoint naming a point whose track does not list it.  :func:`write_text_model` writes COLMAP's header
comments and floats with ``repr`` (the shortest string that reads back to the same
double), so write -> read is exact.  Malformed input raises :class:`ModelFormatError`
naming the file and line.  Newer COLMAP versions also write ``rigs.txt`` and
``frames.txt``; they are not read here (COLMAP rebuilds trivial rigs without them).
"""
from __future__ import annotations

import math
import operator
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from collections.abc import Mapping

import numpy as np

from .camera_models import COLMAP_MODEL_N_PARAMS

__all__ = ["Camera", "Image", "Point3D", "Model", "ModelFormatError", "read_text_model", "write_text_model",
           "rotation_from_qvec", "qvec_from_rotation", "NO_POINT3D", "MODEL_FILES"]

#: POINT3D_ID of a keypoint without a 3D point.
NO_POINT3D = -1
MODEL_FILES = ("cameras.txt", "images.txt", "points3D.txt")


class ModelFormatError(ValueError):
    """Malformed COLMAP text model; the message names the file and line."""


def _finite_tuple(values, n: int | None, name: str) -> tuple:
    try:
        out = tuple(float(v) for v in values)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be numbers, got {values!r}") from None
    if n is not None and len(out) != n:
        raise ValueError(f"{name} must have {n} entries, got {len(out)}")
    if not all(math.isfinite(v) for v in out):
        raise ValueError(f"{name} contains NaN or inf: {out}")
    return out


def _whole(value, name: str) -> int:
    """``value`` as an int: Python and numpy integers, and floats without a fractional part (``640.0``);
    refused with a ValueError naming ``name``: fractions (a width of 10.5), booleans, strings, NaN."""
    if type(value) is int:
        return value
    if not isinstance(value, (bool, np.bool_)):
        try:
            return operator.index(value)
        except TypeError:
            if isinstance(value, (float, np.floating)) and math.isfinite(value) and float(value).is_integer():
                return int(value)
    raise ValueError(f"{name} must be an integer, got {value!r}")


def _set_whole(record, names: tuple, what: str) -> None:
    """The integer fields ``names`` of a record (``id`` first: the others' messages name it, ``camera 3: width``)."""
    object.__setattr__(record, "id", _whole(record.id, f"{what} id"))
    for name in names:
        if name != "id":
            object.__setattr__(record, name, _whole(getattr(record, name), f"{what} {record.id}: {name}"))


@dataclass(frozen=True)
class Camera:
    """Intrinsics shared by images: ``model`` is a COLMAP model name (see camera_models)."""
    id: int
    model: str
    width: int
    height: int
    params: tuple

    def __post_init__(self):
        _set_whole(self, ("id", "width", "height"), "camera")
        object.__setattr__(self, "params", _finite_tuple(self.params, None, f"camera {self.id} params"))
        if self.model not in COLMAP_MODEL_N_PARAMS:
            raise ValueError(f"camera {self.id}: unknown COLMAP camera model {self.model!r}")
        if len(self.params) != COLMAP_MODEL_N_PARAMS[self.model]:
            raise ValueError(f"camera {self.id}: model {self.model} needs {COLMAP_MODEL_N_PARAMS[self.model]} "
                             f"params, got {len(self.params)}")
        if self.width <= 0 or self.height <= 0:
            raise ValueError(f"camera {self.id}: width and height must be positive, got {self.width}x{self.height}")


@dataclass(frozen=True)
class Image:
    """A registered image: pose ``cam_from_world`` = (qvec (w, x, y, z), tvec), its camera,
    and its keypoints ``points2D`` = ((x, y, point3D_id), ...) in pixels."""
    id: int
    qvec: tuple
    tvec: tuple
    camera_id: int
    name: str
    points2D: tuple = ()

    def __post_init__(self):
        _set_whole(self, ("id", "camera_id"), "image")
        object.__setattr__(self, "qvec", _finite_tuple(self.qvec, 4, f"image {self.id} qvec"))
        object.__setattr__(self, "tvec", _finite_tuple(self.tvec, 3, f"image {self.id} tvec"))
        if np.linalg.norm(self.qvec) == 0:
            raise ValueError(f"image {self.id}: qvec is zero")
        if not self.name or any(c in self.name for c in "\r\n") or self.name != self.name.strip():
            raise ValueError(f"image {self.id}: name must be a non-empty single-line string without leading or "
                             f"trailing whitespace (COLMAP's text format), got {self.name!r}")
        pts = []
        for k, p in enumerate(self.points2D):
            if len(p) != 3:
                raise ValueError(f"image {self.id} points2D[{k}] must be (x, y, point3D_id), got {p!r}")
            x, y = _finite_tuple(p[:2], 2, f"image {self.id} points2D[{k}]")
            pts.append((x, y, _whole(p[2], f"image {self.id} points2D[{k}] point3D_id")))
        object.__setattr__(self, "points2D", tuple(pts))

    @property
    def rotation(self) -> np.ndarray:
        """R of ``cam_from_world`` (from the normalised quaternion)."""
        return rotation_from_qvec(self.qvec)

    @property
    def cam_from_world(self) -> np.ndarray:
        """[R | t], shape (3, 4)."""
        return np.hstack([self.rotation, np.array(self.tvec)[:, None]])

    @property
    def xy(self) -> np.ndarray:
        """Keypoint coordinates, shape (K, 2)."""
        return np.array([p[:2] for p in self.points2D], float).reshape(-1, 2)


@dataclass(frozen=True)
class Point3D:
    """A 3D point: ``xyz`` (world), colour, mean reprojection ``error`` (pixels) and
    ``track`` = ((image_id, point2D_idx), ...)."""
    id: int
    xyz: tuple
    rgb: tuple = (128, 128, 128)
    error: float = 0.0
    track: tuple = ()

    def __post_init__(self):
        _set_whole(self, ("id",), "point3D")
        object.__setattr__(self, "xyz", _finite_tuple(self.xyz, 3, f"point3D {self.id} xyz"))
        rgb = tuple(_whole(c, f"point3D {self.id} rgb") for c in self.rgb)
        if len(rgb) != 3 or not all(0 <= c <= 255 for c in rgb):
            raise ValueError(f"point3D {self.id}: rgb must be 3 integers in 0..255, got {self.rgb!r}")
        object.__setattr__(self, "rgb", rgb)
        object.__setattr__(self, "error", float(self.error))
        object.__setattr__(self, "track", tuple((_whole(i, f"point3D {self.id} track image_id"),
                                                 _whole(k, f"point3D {self.id} track point2D_idx"))
                                                for i, k in self.track))


@dataclass(frozen=True)
class Model:
    """A COLMAP sparse model (read-only mappings id -> record).

    Construction checks the cross references COLMAP relies on: every image's camera
    exists; every track entry (image_id, point2D_idx) names an existing keypoint whose
    POINT3D_ID is this point, and no keypoint is listed twice; every keypoint's POINT3D_ID
    (other than -1) is a point whose track lists that keypoint.
    """
    cameras: Mapping = field(default_factory=dict)
    images: Mapping = field(default_factory=dict)
    points3D: Mapping = field(default_factory=dict)

    def __post_init__(self):
        for name in ("cameras", "images", "points3D"):
            d = getattr(self, name)
            if not isinstance(d, Mapping):
                d = {r.id: r for r in d}
            for k, r in d.items():
                if k != r.id:
                    raise ValueError(f"{name}: key {k} differs from the record's id {r.id}")
            object.__setattr__(self, name, MappingProxyType(dict(d)))
        err = _reference_error(self.cameras, self.images, self.points3D)
        if err:
            raise ValueError(err[1])

    def replace_points(self, points) -> Model:
        """The model with some Point3D records replaced (same ids)."""
        new = dict(self.points3D)
        for p in points:
            if p.id not in new:
                raise ValueError(f"point3D {p.id} is not in the model")
            new[p.id] = p
        return Model(self.cameras, self.images, new)


def _reference_error(cameras, images, points3D):
    """(kind, message) of the first broken cross reference, or None."""
    for im in images.values():
        if im.camera_id not in cameras:
            return ("image", im.id), f"image {im.id} refers to camera {im.camera_id}, which does not exist"
        for k, (_, _, pid) in enumerate(im.points2D):
            if pid != NO_POINT3D and pid not in points3D:
                return ("image", im.id), f"image {im.id} keypoint {k} refers to point3D {pid}, which does not exist"
    for p in points3D.values():
        for image_id, idx in p.track:
            im = images.get(image_id)
            if im is None:
                return ("point", p.id), f"point3D {p.id} track refers to image {image_id}, which does not exist"
            if not 0 <= idx < len(im.points2D):
                return ("point", p.id), (f"point3D {p.id} track refers to keypoint {idx} of image {image_id}, "
                                         f"which has {len(im.points2D)} keypoints")
            if im.points2D[idx][2] != p.id:
                return ("point", p.id), (f"point3D {p.id} track refers to keypoint {idx} of image {image_id}, "
                                         f"whose POINT3D_ID is {im.points2D[idx][2]}")
    listed = {}
    for p in points3D.values():
        for e in p.track:
            if e in listed:
                return ("point", p.id), (f"point3D {p.id} track lists keypoint {e[1]} of image {e[0]} twice"
                                         if listed[e] == p.id else
                                         f"keypoint {e[1]} of image {e[0]} is listed by the tracks of point3D "
                                         f"{listed[e]} and {p.id}")
            listed[e] = p.id
    for im in images.values():
        for k, (_, _, pid) in enumerate(im.points2D):
            if pid != NO_POINT3D and (im.id, k) not in listed:
                return ("point", pid), (f"image {im.id} keypoint {k} has POINT3D_ID {pid}, but the track of point3D "
                                        f"{pid} does not list it (track cut short?)")
    return None


# ----------------------------------------------------------------------------- rotations
def rotation_from_qvec(qvec) -> np.ndarray:
    """Rotation matrix of the Hamilton quaternion (w, x, y, z) (normalised first, after an exact power-of-two scaling
    of its largest entry to [0.5, 1): a quaternion of norm 1e-200 is the same rotation; review 50a F5)."""
    q = np.asarray(qvec, float)
    q = q / 2.0 ** np.frexp(np.max(np.abs(q)))[1]
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def qvec_from_rotation(R) -> np.ndarray:
    """Unit quaternion (w, x, y, z), w >= 0, of a rotation matrix (largest-pivot formula)."""
    R = np.asarray(R, float)
    tr = np.trace(R)
    cands = [tr, R[0, 0], R[1, 1], R[2, 2]]
    k = int(np.argmax(cands))
    if k == 0:
        s = 2 * np.sqrt(1 + tr)
        q = [s / 4, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s]
    elif k == 1:
        s = 2 * np.sqrt(1 + R[0, 0] - R[1, 1] - R[2, 2])
        q = [(R[2, 1] - R[1, 2]) / s, s / 4, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s]
    elif k == 2:
        s = 2 * np.sqrt(1 + R[1, 1] - R[0, 0] - R[2, 2])
        q = [(R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, s / 4, (R[1, 2] + R[2, 1]) / s]
    else:
        s = 2 * np.sqrt(1 + R[2, 2] - R[0, 0] - R[1, 1])
        q = [(R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, s / 4]
    q = np.array(q)
    q /= np.linalg.norm(q)
    return -q if q[0] < 0 else q


# ----------------------------------------------------------------------------- reading
def _data_lines(path: Path, strict: bool = False):
    """(line number, stripped text) of the non-comment lines; blank lines kept (images.txt
    uses an empty POINTS2D line for an image without keypoints).  Bytes that are not UTF-8 are
    kept as surrogates (an image NAME round-trips); ``strict``: refused, naming file:line."""
    with open(path, encoding="utf-8-sig", errors="surrogateescape") as fh:   # a BOM (review 29b F10) skipped
        for lineno, line in enumerate(fh, 1):
            if strict and not line.isascii():
                _check_utf8(path, lineno, line)
            s = line.strip()
            if not s.startswith("#"):
                yield lineno, s


def _check_utf8(path: Path, lineno: int, line: str) -> None:
    try:
        line.encode("utf-8")
    except UnicodeEncodeError as exc:
        byte = ord(line[exc.start]) - 0xDC00
        raise ModelFormatError(f"{path.name}:{lineno}: not UTF-8 text (byte 0x{byte:02x} at column "
                               f"{exc.start + 1})") from None


def _cut(token: str, limit: int = 24) -> str:
    """``token`` shortened for a one-line message (a 5,000-digit field is not printed whole)."""
    return token if len(token) <= limit else token[:limit] + "..."


def _plain(token: str) -> str:
    """``token`` unless it holds Python's digit separator ``_`` or a NUL byte (ValueError: "1_0" is 10 to int() and
    float(), not to COLMAP; review 39b B3)."""
    if "_" in token or "\x00" in token:
        raise ValueError(token)
    return token


class LineFields:
    """The whitespace-separated fields of one line of a text model, with errors naming file:line."""

    def __init__(self, path: Path, lineno: int, text: str):
        self.where = f"{path.name}:{lineno}"
        self.tokens = text.split()

    def fail(self, msg: str):
        """Raise ModelFormatError at this file:line."""
        raise ModelFormatError(f"{self.where}: {msg}")

    def need(self, n: int, what: str):
        """Fail unless the line has at least n fields."""
        if len(self.tokens) < n:
            self.fail(f"expected {what} ({n} fields), got {len(self.tokens)} fields")

    def int(self, k: int, name: str) -> int:
        """Field k as an integer in the 64-bit range (COLMAP's widest integer type)."""
        try:
            v = int(_plain(self.tokens[k]))
        except ValueError:
            self.fail(f"{name} must be an integer, got {_cut(self.tokens[k])!r}")
        if not -2 ** 63 <= v < 2 ** 63:
            self.fail(f"{name} {_cut(self.tokens[k])} is beyond the 64-bit integer range")
        return v

    def id32(self, k: int, name: str) -> int:
        """Field k as a COLMAP camera or image id: uint32 below 2^32 - 1, COLMAP's invalid id (review 33a M2: -1 and
        2^32 - 1 were read, and the models written with them were refused by COLMAP and pycolmap)."""
        v = self.int(k, name)
        if not 0 <= v < 2 ** 32 - 1:
            self.fail(f"{name} {v} is outside COLMAP's range 0..4294967294 (uint32; 4294967295 is its invalid id)")
        return v

    def float(self, k: int, name: str) -> float:
        """Field k as a finite float."""
        try:
            v = float(_plain(self.tokens[k]))
        except ValueError:
            self.fail(f"{name} must be a number, got {_cut(self.tokens[k])!r}")
        if not math.isfinite(v):
            self.fail(f"{name} is {_cut(self.tokens[k])}")
        return v


def read_camera_records(path: Path) -> tuple[dict, dict]:
    """Cameras of a ``cameras.txt`` and the file:line of each (ModelFormatError naming the line)."""
    cams, where = {}, {}
    for lineno, text in _data_lines(path, strict=True):
        if not text:
            continue
        f = LineFields(path, lineno, text)
        f.need(4, "CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]")
        cid, model = f.id32(0, "CAMERA_ID"), f.tokens[1]
        if model not in COLMAP_MODEL_N_PARAMS:
            f.fail(f"unknown camera MODEL {model!r} (COLMAP models: {', '.join(COLMAP_MODEL_N_PARAMS)})")
        n = COLMAP_MODEL_N_PARAMS[model]
        if len(f.tokens) != 4 + n:
            f.fail(f"camera model {model} needs {n} PARAMS, got {len(f.tokens) - 4}")
        width, height = f.int(2, "WIDTH"), f.int(3, "HEIGHT")
        if width <= 0 or height <= 0:
            f.fail(f"WIDTH and HEIGHT must be positive, got {width}x{height}")
        if cid in cams:
            f.fail(f"duplicate CAMERA_ID {cid}")
        cams[cid] = Camera(cid, model, width, height, tuple(f.float(4 + k, f"PARAMS[{k}]") for k in range(n)))
        where[cid] = f.where
    return cams, where


def parse_image_header(path: Path, lineno: int, text: str) -> tuple:
    """``(image_id, qvec, tvec, camera_id, name)`` of an images.txt header line (ModelFormatError
    naming file:line when malformed)."""
    f = LineFields(path, lineno, text)
    f.need(10, "IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME")
    iid = f.id32(0, "IMAGE_ID")
    q = tuple(f.float(k, n) for k, n in zip(range(1, 5), ("QW", "QX", "QY", "QZ")))
    t = tuple(f.float(k, n) for k, n in zip(range(5, 8), ("TX", "TY", "TZ")))
    cid = f.id32(8, "CAMERA_ID")
    name = text.split(None, 9)[9]
    if np.linalg.norm(q) == 0:
        f.fail("quaternion (QW, QX, QY, QZ) is zero")
    return iid, q, t, cid, name


def parse_points2d(path: Path, lineno: int, text: str, image_id: int) -> tuple:
    """The ``(x, y, point3D_id)`` triples of an images.txt POINTS2D line."""
    g = LineFields(path, lineno, text)
    if len(g.tokens) % 3:
        g.fail(f"POINTS2D of image {image_id} must be (X, Y, POINT3D_ID) triples, got {len(g.tokens)} fields")
    pts = tuple((g.float(k, f"X of keypoint {k // 3}"), g.float(k + 1, f"Y of keypoint {k // 3}"),
                 g.int(k + 2, f"POINT3D_ID of keypoint {k // 3}")) for k in range(0, len(g.tokens), 3))
    for k, p in enumerate(pts):
        if p[2] < NO_POINT3D:
            g.fail(f"POINT3D_ID of keypoint {k} must be >= -1, got {p[2]}")
    return pts


def parse_point(path: Path, lineno: int, text: str) -> Point3D:
    """The :class:`Point3D` of a points3D.txt line."""
    f = LineFields(path, lineno, text)
    f.need(8, "POINT3D_ID X Y Z R G B ERROR TRACK[]")
    if (len(f.tokens) - 8) % 2:
        f.fail("TRACK[] must be (IMAGE_ID, POINT2D_IDX) pairs, got an odd number of fields (line cut short?)")
    pid = f.int(0, "POINT3D_ID")
    xyz = tuple(f.float(k, n) for k, n in zip(range(1, 4), "XYZ"))
    rgb = tuple(f.int(k, n) for k, n in zip(range(4, 7), "RGB"))
    if not all(0 <= c <= 255 for c in rgb):
        f.fail(f"R G B must be in 0..255, got {rgb}")
    try:
        err = float(f.tokens[7])
    except ValueError:
        f.fail(f"ERROR must be a number, got {f.tokens[7]!r}")
    if len(f.tokens) == 8:
        f.fail(f"point3D {pid} has an empty TRACK[] (line cut short?)")
    track = tuple((f.int(k, "IMAGE_ID"), f.int(k + 1, "POINT2D_IDX")) for k in range(8, len(f.tokens), 2))
    for i, k in track:
        if k < 0:
            f.fail(f"POINT2D_IDX must be >= 0, got {k} (image {i})")
    return Point3D(pid, xyz, rgb, err, track)


def _read_images(path: Path) -> tuple[dict, dict]:
    images, where = {}, {}
    lines = iter(_data_lines(path))
    for lineno, text in lines:
        if not text:
            continue
        iid, q, t, cid, name = parse_image_header(path, lineno, text)
        if iid in images:
            LineFields(path, lineno, text).fail(f"duplicate IMAGE_ID {iid}")
        try:
            plineno, ptext = next(lines)
        except StopIteration:
            LineFields(path, lineno, text).fail(f"image {iid} has no POINTS2D line (two lines per image)")
        images[iid] = Image(iid, q, t, cid, name, parse_points2d(path, plineno, ptext, iid))
        where[iid] = f"{path.name}:{lineno}"
    return images, where


def _read_points(path: Path) -> tuple[dict, dict]:
    points, where = {}, {}
    for lineno, text in _data_lines(path):
        if not text:
            continue
        p = parse_point(path, lineno, text)
        if p.id in points:
            LineFields(path, lineno, text).fail(f"duplicate POINT3D_ID {p.id}")
        points[p.id] = p
        where[p.id] = f"{path.name}:{lineno}"
    return points, where


def read_text_model(path) -> Model:
    """Read ``cameras.txt``, ``images.txt`` and ``points3D.txt`` from the folder ``path``."""
    folder = Path(path)
    for name in MODEL_FILES:
        if not (folder / name).is_file():
            raise FileNotFoundError(f"{folder / name}: missing (a COLMAP text model has {', '.join(MODEL_FILES)})")
    cameras, _ = read_camera_records(folder / "cameras.txt")
    images, img_where = _read_images(folder / "images.txt")
    points, pt_where = _read_points(folder / "points3D.txt")
    err = _reference_error(cameras, images, points)
    if err:
        (kind, rid), msg = err
        raise ModelFormatError(f"{(img_where if kind == 'image' else pt_where)[rid]}: {msg}")
    return Model(cameras, images, points)


# ----------------------------------------------------------------------------- writing
def _num(v: float) -> str:
    return repr(float(v))


def write_text_model(model: Model, path) -> Path:
    """Write the model as COLMAP text files into the folder ``path`` (created if needed).
    Records are written sorted by id, each file atomically (:mod:`tritools.io.atomic`).  Returns the folder."""
    from ..atomic import atomic_open

    folder = Path(path)
    folder.mkdir(parents=True, exist_ok=True)

    def write_text(name, text):
        with atomic_open(folder / name, "w", encoding="utf-8", errors="surrogateescape") as fh:
            fh.write(text)
    lines = ["# Camera list with one line of data per camera:",
             "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]",
             f"# Number of cameras: {len(model.cameras)}"]
    for c in sorted(model.cameras.values(), key=lambda c: c.id):
        lines.append(" ".join([str(c.id), c.model, str(c.width), str(c.height)] + [_num(p) for p in c.params]))
    write_text("cameras.txt", "\n".join(lines) + "\n")

    n_obs = sum(p[2] != NO_POINT3D for im in model.images.values() for p in im.points2D)
    mean_obs = n_obs / len(model.images) if model.images else 0.0
    lines = ["# Image list with two lines of data per image:",
             "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME",
             "#   POINTS2D[] as (X, Y, POINT3D_ID)",
             f"# Number of images: {len(model.images)}, mean observations per image: {mean_obs:.6g}"]
    for im in sorted(model.images.values(), key=lambda i: i.id):
        lines.append(" ".join([str(im.id)] + [_num(v) for v in im.qvec + im.tvec] + [str(im.camera_id), im.name]))
        lines.append(" ".join(f"{_num(x)} {_num(y)} {pid}" for x, y, pid in im.points2D))
    write_text("images.txt", "\n".join(lines) + "\n")

    mean_track = (sum(len(p.track) for p in model.points3D.values()) / len(model.points3D)
                  if model.points3D else 0.0)
    lines = ["# 3D point list with one line of data per point:",
             "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)",
             f"# Number of points: {len(model.points3D)}, mean track length: {mean_track:.6g}"]
    for p in sorted(model.points3D.values(), key=lambda p: p.id):
        lines.append(" ".join([str(p.id)] + [_num(v) for v in p.xyz] + [str(c) for c in p.rgb] + [_num(p.error)]
                              + [f"{i} {k}" for i, k in p.track]))
    write_text("points3D.txt", "\n".join(lines) + "\n")
    return folder
