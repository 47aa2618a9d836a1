"""A COLMAP model as flat numpy arrays (:class:`ModelArrays`), the representation of the fast path.

The record classes of :mod:`.model` (one frozen dataclass per camera, image, keypoint and
point) are convenient for small models; a reconstruction with 10^6 points and 10^7 keypoints
needs arrays.  :class:`ModelArrays` holds the same data:

* cameras: ``camera_ids (C,)``, ``camera_models (C,)`` (COLMAP model names), ``camera_width``,
  ``camera_height (C,)``, ``camera_params`` (a tuple of C float arrays, one per camera);
* images: ``image_ids (V,)``, ``image_qvec (V, 4)``, ``image_tvec (V, 3)``, ``image_camera (V,)``
  (index into the camera table), ``image_names`` (tuple of V str);
* keypoints of all images concatenated: ``kp_offsets (V + 1,)`` (image v owns rows
  ``kp_offsets[v]:kp_offsets[v + 1]``), ``kp_xy (K, 2)``, ``kp_point3D (K,)`` (-1: none);
* points: ``point_ids (P,)``, ``point_xyz (P, 3)``, ``point_rgb (P, 3) uint8``, ``point_error (P,)``
  and the tracks in CSR form: ``track_offsets (P + 1,)``, ``track_image (T,)`` (image *index*)
  and ``track_kp (T,)`` (POINT2D_IDX within that image).

Optional ``sources`` say where each camera came from (``"cameras.txt:4"``,
``"cameras.bin: record 2 (offset 8)"``) for error messages.  :meth:`ModelArrays.from_model`
and :meth:`ModelArrays.to_model` convert from and to :class:`~.model.Model` exactly (records
sorted by id); :func:`check_references` is the vectorised version of the model's cross-reference
checks (COLMAP's invariant: a keypoint names point p iff p's track lists the keypoint).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .model import Camera, Image, Model, Point3D

__all__ = ["ModelArrays", "PointChunk", "check_references", "unlisted_keypoint", "global_keypoints"]


@dataclass(frozen=True)
class PointChunk:
    """Consecutive 3D points with their tracks (the unit the streaming path works on).

    ``track_image`` holds image *indices* of the owning :class:`ModelArrays`; ``start`` is
    the index of the chunk's first point in the whole file (for messages)."""
    ids: np.ndarray
    xyz: np.ndarray
    rgb: np.ndarray
    error: np.ndarray
    track_offsets: np.ndarray
    track_image: np.ndarray
    track_kp: np.ndarray
    start: int = 0
    locations: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.ids)

    @property
    def track_lengths(self) -> np.ndarray:
        """Number of observations of each point."""
        return np.diff(self.track_offsets)


@dataclass(frozen=True, eq=False)
class ModelArrays:
    """A COLMAP model as arrays (layout in the module docstring)."""
    camera_ids: np.ndarray
    camera_models: tuple
    camera_width: np.ndarray
    camera_height: np.ndarray
    camera_params: tuple
    image_ids: np.ndarray
    image_qvec: np.ndarray
    image_tvec: np.ndarray
    image_camera: np.ndarray
    image_names: tuple
    kp_offsets: np.ndarray
    kp_xy: np.ndarray
    kp_point3D: np.ndarray
    point_ids: np.ndarray
    point_xyz: np.ndarray
    point_rgb: np.ndarray
    point_error: np.ndarray
    track_offsets: np.ndarray
    track_image: np.ndarray
    track_kp: np.ndarray
    sources: dict = field(default_factory=dict)

    # ------------------------------------------------------------------ sizes and views
    @property
    def n_cameras(self) -> int:
        """Number of cameras."""
        return len(self.camera_ids)

    @property
    def n_images(self) -> int:
        """Number of images."""
        return len(self.image_ids)

    @property
    def n_points(self) -> int:
        """Number of 3D points."""
        return len(self.point_ids)

    @property
    def n_observations(self) -> int:
        """Number of track elements."""
        return len(self.track_image)

    def camera_source(self, k: int) -> str:
        """Where camera k (table index) was read, or ``"camera ID"`` for in-memory models."""
        src = self.sources.get("cameras")
        return src[k] if src is not None else f"camera {int(self.camera_ids[k])}"

    def points(self, start: int = 0, stop: int | None = None) -> PointChunk:
        """Points ``start:stop`` as a :class:`PointChunk` (views into the arrays, tracks re-based)."""
        stop = self.n_points if stop is None else min(stop, self.n_points)
        a, b = self.track_offsets[start], self.track_offsets[stop]
        return PointChunk(self.point_ids[start:stop], self.point_xyz[start:stop], self.point_rgb[start:stop],
                          self.point_error[start:stop], self.track_offsets[start:stop + 1] - a,
                          self.track_image[a:b], self.track_kp[a:b], start)

    def with_points(self, xyz: np.ndarray, error: np.ndarray) -> ModelArrays:
        """The same model with new point coordinates and errors (tracks, colours, ids unchanged)."""
        xyz = np.asarray(xyz, float).reshape(self.point_xyz.shape)
        error = np.asarray(error, float).reshape(self.point_error.shape)
        fields = {k: getattr(self, k) for k in self.__dataclass_fields__}
        fields.update(point_xyz=xyz, point_error=error)
        return ModelArrays(**fields)

    def equals(self, other: ModelArrays) -> bool:
        """Exact equality of every field but ``sources`` (floats bit for bit, NaN never occurs)."""
        for k in self.__dataclass_fields__:
            if k == "sources":
                continue
            a, b = getattr(self, k), getattr(other, k)
            if k == "camera_params":
                if len(a) != len(b) or not all(np.array_equal(x, y) for x, y in zip(a, b)):
                    return False
            elif isinstance(a, tuple):
                if a != b:
                    return False
            elif a.shape != b.shape or not np.array_equal(a, b):
                return False
        return True

    # ------------------------------------------------------------------ conversion
    @classmethod
    def from_model(cls, model: Model) -> ModelArrays:
        """Arrays of a :class:`Model`; cameras, images and points sorted by id."""
        cams = sorted(model.cameras.values(), key=lambda c: c.id)
        cam_index = {c.id: k for k, c in enumerate(cams)}
        ims = sorted(model.images.values(), key=lambda i: i.id)
        im_index = {im.id: k for k, im in enumerate(ims)}
        counts = np.array([len(im.points2D) for im in ims], np.int64)
        kp = [p for im in ims for p in im.points2D]
        pts = sorted(model.points3D.values(), key=lambda p: p.id)
        lengths = np.array([len(p.track) for p in pts], np.int64)
        tr = [e for p in pts for e in p.track]
        return cls(
            camera_ids=np.array([c.id for c in cams], np.int64), camera_models=tuple(c.model for c in cams),
            camera_width=np.array([c.width for c in cams], np.int64),
            camera_height=np.array([c.height for c in cams], np.int64),
            camera_params=tuple(np.array(c.params, float) for c in cams),
            image_ids=np.array([im.id for im in ims], np.int64),
            image_qvec=np.array([im.qvec for im in ims], float).reshape(-1, 4),
            image_tvec=np.array([im.tvec for im in ims], float).reshape(-1, 3),
            image_camera=np.array([cam_index[im.camera_id] for im in ims], np.int64),
            image_names=tuple(im.name for im in ims),
            kp_offsets=np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
            kp_xy=np.array([p[:2] for p in kp], float).reshape(-1, 2),
            kp_point3D=np.array([p[2] for p in kp], np.int64),
            point_ids=np.array([p.id for p in pts], np.int64),
            point_xyz=np.array([p.xyz for p in pts], float).reshape(-1, 3),
            point_rgb=np.array([p.rgb for p in pts], np.uint8).reshape(-1, 3),
            point_error=np.array([p.error for p in pts], float),
            track_offsets=np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64),
            track_image=np.array([im_index[i] for i, _ in tr], np.int64),
            track_kp=np.array([k for _, k in tr], np.int64))

    def to_model(self) -> Model:
        """The :class:`Model` of these arrays (checks its cross references)."""
        cams = {int(i): Camera(int(i), m, int(w), int(h), tuple(p.tolist()))
                for i, m, w, h, p in zip(self.camera_ids, self.camera_models, self.camera_width, self.camera_height,
                                         self.camera_params)}
        xy, pid = self.kp_xy.tolist(), self.kp_point3D.tolist()
        images = {}
        for v, iid in enumerate(self.image_ids.tolist()):
            a, b = int(self.kp_offsets[v]), int(self.kp_offsets[v + 1])
            pts = tuple((x, y, k) for (x, y), k in zip(xy[a:b], pid[a:b]))
            images[iid] = Image(iid, tuple(self.image_qvec[v].tolist()), tuple(self.image_tvec[v].tolist()),
                                int(self.camera_ids[self.image_camera[v]]), self.image_names[v], pts)
        img_ids, tim, tkp = self.image_ids.tolist(), self.track_image.tolist(), self.track_kp.tolist()
        off = self.track_offsets.tolist()
        points = {}
        for p, (pid_, xyz, rgb, err) in enumerate(zip(self.point_ids.tolist(), self.point_xyz.tolist(),
                                                      self.point_rgb.tolist(), self.point_error.tolist())):
            track = tuple((img_ids[tim[t]], tkp[t]) for t in range(off[p], off[p + 1]))
            points[pid_] = Point3D(pid_, tuple(xyz), tuple(rgb), err, track)
        return Model(cams, images, points)


def global_keypoints(arrays: ModelArrays, track_image: np.ndarray, track_kp: np.ndarray) -> np.ndarray:
    """Row of each track element in the concatenated keypoint arrays."""
    return arrays.kp_offsets[track_image] + track_kp


def check_references(arrays: ModelArrays, chunk: PointChunk, seen: np.ndarray | None = None):
    """The first broken reference of a chunk of points as ``(point index in the chunk, message)``, or None.

    Checks: each track element names a keypoint of its image, whose POINT3D_ID is this point;
    no keypoint is listed twice (``seen``, a (K,) bool array shared across chunks, is
    updated).  The remaining direction (every keypoint with a POINT3D_ID is listed by that
    point's track) is :func:`unlisted_keypoint` once all chunks were seen.
    """
    head = _bad_record(chunk)
    if head is not None:
        return head
    counts = np.diff(arrays.kp_offsets)[chunk.track_image]
    bad = (chunk.track_kp < 0) | (chunk.track_kp >= counts)
    owner = np.repeat(np.arange(len(chunk)), chunk.track_lengths)
    if bad.any():
        t = int(np.argmax(bad))
        p = int(owner[t])
        return p, (f"point3D {int(chunk.ids[p])} track refers to keypoint {int(chunk.track_kp[t])} of image "
                   f"{int(arrays.image_ids[chunk.track_image[t]])}, which has {int(counts[t])} keypoints")
    g = global_keypoints(arrays, chunk.track_image, chunk.track_kp)
    names = arrays.kp_point3D[g]
    wrong = names != chunk.ids[owner]
    if wrong.any():
        t = int(np.argmax(wrong))
        return int(owner[t]), (f"point3D {int(chunk.ids[owner[t]])} track refers to keypoint "
                               f"{int(chunk.track_kp[t])} of image {int(arrays.image_ids[chunk.track_image[t]])}, "
                               f"whose POINT3D_ID is {int(names[t])}")
    if seen is not None:
        order = np.argsort(g, kind="stable")
        gs = g[order]
        dup = np.nonzero(gs[1:] == gs[:-1])[0]
        again = seen[g]
        if dup.size or again.any():
            t = int(order[dup[0] + 1]) if dup.size else int(np.argmax(again))
            return int(owner[t]), (f"point3D {int(chunk.ids[owner[t]])} track lists keypoint {int(chunk.track_kp[t])} "
                                   f"of image {int(arrays.image_ids[chunk.track_image[t]])} a second time")
        seen[g] = True
    return None


def _bad_record(chunk: PointChunk):
    """The first point of a chunk whose own fields are unusable, as ``(index, message)``, or None: an id that is
    COLMAP's invalid id (2^64 - 1 in points3D.bin, -1 in points3D.txt; its unlinked keypoints carry the same
    value, so the track check would pass) or does not fit an int64, or a non-finite X / Y / Z (written back
    unchanged, it made a model that no reader, tritools' included, accepts)."""
    neg = chunk.ids < 0
    if neg.any():
        p = int(np.argmax(neg))
        v = int(chunk.ids[p])
        label = "-1 (2^64 - 1)" if v == -1 else str(v % 2 ** 64)
        return p, (f"POINT3D_ID {label} is not a valid point3D id (COLMAP's invalid id is 2^64 - 1 in points3D.bin, "
                   f"-1 in points3D.txt; ids must fit an int64)")
    fin = np.isfinite(chunk.xyz)
    if not fin.all():
        p, k = (int(v) for v in np.argwhere(~fin)[0])
        return p, f"point3D {int(chunk.ids[p])}: {'XYZ'[k]} is not finite ({chunk.xyz[p, k]})"
    return None


def unlisted_keypoint(arrays: ModelArrays, seen: np.ndarray):
    """After every chunk went through :func:`check_references`: ``(image index, keypoint index,
    point3D id)`` of the first keypoint naming a 3D point whose track does not list it (a missing
    point, or a points3D file cut short), or None."""
    missing = (arrays.kp_point3D != -1) & ~seen
    if not missing.any():
        return None
    k = int(np.argmax(missing))
    v = int(np.searchsorted(arrays.kp_offsets, k, side="right") - 1)
    return v, k - int(arrays.kp_offsets[v]), int(arrays.kp_point3D[k])
