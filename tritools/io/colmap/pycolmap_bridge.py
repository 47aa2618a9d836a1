"""pycolmap in memory: :func:`from_pycolmap` (a ``pycolmap.Reconstruction`` -> :class:`~.model.Model`) and
:func:`to_pycolmap` (the way back), so a pycolmap user never goes through disk.

What is carried: cameras (model name, size, PARAMS[]), the registered images (name, camera, the pose
``cam_from_world`` -- for COLMAP 4 rigs the composed sensor pose, which is what projects -- and every
keypoint with its POINT3D_ID), and the 3D points (xyz, colour, ERROR, track).  Rigs and frames beyond the
trivial ones are not represented in :class:`~.model.Model`: :func:`tritools.sfm.retriangulate` on a
reconstruction therefore copies the input (``pycolmap.Reconstruction(rec)``) and changes only the xyz and
ERROR of the points it updates, keeping everything else exactly.  pycolmap is imported only here and only
when called (ImportError naming the ``colmap`` extra otherwise).
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .model import NO_POINT3D, Camera, Image, Model, Point3D

if TYPE_CHECKING:                     # an optional dependency: never imported at run time here
    import pycolmap

__all__ = ["from_pycolmap", "to_pycolmap", "is_pycolmap_reconstruction", "import_pycolmap"]


def import_pycolmap():
    """``import pycolmap``, or an ImportError saying how to install it."""
    try:
        import pycolmap
    except ImportError as exc:
        raise ImportError("this needs pycolmap, an optional dependency: pip install 'sospoly-tritools[colmap]'") \
            from exc
    return pycolmap


def is_pycolmap_reconstruction(obj: object) -> bool:
    """Whether ``obj`` is a ``pycolmap.Reconstruction`` (checked without importing pycolmap)."""
    t = type(obj)
    return t.__name__ == "Reconstruction" and t.__module__.split(".")[0] == "pycolmap"


def _pose(image):
    """(qvec (w, x, y, z), tvec) of ``cam_from_world`` (pycolmap's quaternion is Eigen's (x, y, z, w))."""
    cfw = image.cam_from_world
    cfw = cfw() if callable(cfw) else cfw
    x, y, z, w = (float(v) for v in cfw.rotation.quat)
    return (w, x, y, z), tuple(float(v) for v in cfw.translation)


def from_pycolmap(rec: pycolmap.Reconstruction) -> Model:
    """A :class:`~.model.Model` of a ``pycolmap.Reconstruction`` (registered images only).

    Raises
    ------
    TypeError
        ``rec`` is not a ``pycolmap.Reconstruction``.
    ValueError
        A point whose track names an image without a pose (not registered).
    """
    if not is_pycolmap_reconstruction(rec):
        raise TypeError(f"rec must be a pycolmap.Reconstruction, got {type(rec).__name__}")
    cams = {int(cid): Camera(int(cid), c.model.name, int(c.width), int(c.height), tuple(map(float, c.params)))
            for cid, c in rec.cameras.items()}
    images = {}
    for iid, im in rec.images.items():
        if not im.has_pose:
            continue
        q, t = _pose(im)
        kps = tuple((float(p.xy[0]), float(p.xy[1]), int(p.point3D_id) if p.has_point3D() else NO_POINT3D)
                    for p in im.points2D)
        images[int(iid)] = Image(int(iid), q, t, int(im.camera_id),
                                 str(im.name), kps)
    points = {}
    for pid, p in rec.points3D.items():
        track = tuple((int(e.image_id), int(e.point2D_idx)) for e in p.track.elements)
        missing = sorted({i for i, _ in track if i not in images})
        if missing:
            raise ValueError(f"point3D {pid}: its track names image(s) {missing} without a pose")
        points[int(pid)] = Point3D(int(pid), tuple(map(float, p.xyz)), tuple(int(v) for v in p.color),
                                   float(p.error), track)
    return Model(cams, images, points)


def to_pycolmap(model: Model) -> pycolmap.Reconstruction:
    """A ``pycolmap.Reconstruction`` of a :class:`~.model.Model` (a trivial rig per camera, a trivial frame
    per image; ids, names, poses, keypoints, colours, errors and tracks as in ``model``)."""
    if not isinstance(model, Model):
        raise TypeError(f"model must be a tritools.io.colmap.Model, got {type(model).__name__}")
    pycolmap = import_pycolmap()
    rec = pycolmap.Reconstruction()
    for c in sorted(model.cameras.values(), key=lambda c: c.id):
        rec.add_camera_with_trivial_rig(pycolmap.Camera(camera_id=c.id, model=c.model, width=c.width,
                                                        height=c.height, params=list(c.params)))
    for im in sorted(model.images.values(), key=lambda i: i.id):
        pts = [pycolmap.Point2D(np.array(kp[:2], float)) for kp in im.points2D]
        image = pycolmap.Image(name=im.name, points2D=pycolmap.Point2DList(pts), camera_id=im.camera_id,
                               image_id=im.id)
        w, x, y, z = (float(v) for v in im.qvec)
        pose = pycolmap.Rigid3d(pycolmap.Rotation3d(np.array([x, y, z, w])), np.asarray(im.tvec, float))
        rec.add_image_with_trivial_frame(image, pose)
    for p in sorted(model.points3D.values(), key=lambda p: p.id):
        track = pycolmap.Track()
        for iid, idx in p.track:
            track.add_element(iid, idx)
        point = pycolmap.Point3D()
        point.xyz, point.color, point.error, point.track = (np.asarray(p.xyz, float), np.asarray(p.rgb, np.uint8),
                                                            float(p.error), track)
        rec.add_point3D_with_id(p.id, point)
    return rec
