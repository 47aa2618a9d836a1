"""Build a COLMAP model (PINHOLE cameras) from 3x4 projection matrices and tracks.

Each ``P`` is decomposed as ``P ~ K [R | t]`` by RQ
(:func:`tritools.baselines.decompose_camera`: K upper triangular, positive diagonal,
K[2, 2] = 1, det R = +1).  COLMAP's K has no skew, so a camera whose skew K[0, 1] would
move some pixel of its image by more than :data:`MAX_SKEW_PX` when dropped is refused
(the shift of dropping skew ``s`` is ``s * y_n`` with ``y_n = (y - cy) / fy``, at most
``|s| max(|cy|, |height - cy|) / fy`` over the image).  Of the Oxford sequences, the
college ones (library, merton1-3, wadham) have relative skew ~1e-15 and convert; corridor,
house and dinosaur (skews up to 4% of the focal length) are refused.

The pixel coordinates are kept as given (no half-pixel shift): the model reproduces the
input projections exactly, in the input's pixel convention.

COLMAP's world frame is right-handed (det R = +1).  Projections in a *reflected* frame (the scene
in front of the cameras only when read with h = -1, :class:`tritools.model.cameras.WorldFrame`;
e.g. the Oxford corridor and house sequences) would become a model whose every point lies behind
its cameras, so they are refused with a ValueError saying how to mirror them first.
"""
from __future__ import annotations

import math

import numpy as np

from ...baselines import decompose_camera
from ...model.cameras import WorldFrame, world_frame_of
from ...model.geometry import PointAtInfinityError, dlt, validate_cameras
from .model import Camera, Image, Model, Point3D, qvec_from_rotation
from .projection import reprojection_error

__all__ = ["MAX_SKEW_PX", "SkewError", "model_from_projections", "model_from_oxford"]

#: largest pixel shift allowed from dropping a camera's skew (well below the ~1e-3 px
#: printed precision of real data, far above the ~1e-12 px of zero-skew cameras).
MAX_SKEW_PX = 1e-6


class SkewError(ValueError):
    """A projection matrix whose K has a skew COLMAP cannot represent."""


def model_from_projections(projections, image_sizes, tracks, names=None, *, rgb=(128, 128, 128)) -> Model:
    """A COLMAP model from cameras and tracks.

    Parameters
    ----------
    projections : (V, 3, 4) camera matrices, world -> pixel
    image_sizes : (V, 2) integer (width, height) per view (or one pair for all views)
    tracks : list of {view index: (x, y)} (pixels), one per 3D point, >= 2 views each
    names : V image names (default ``view_000.png``, ...)

    Camera and image j get id j + 1 (one PINHOLE camera per view), point k gets id k + 1;
    keypoints are numbered per image in track order.  Each point's xyz is the normalised
    DLT of its observations (:func:`tritools.model.geometry.dlt`); run
    :func:`~tritools.sfm.retriangulate.retriangulate` to get the certified L2 points.
    """
    Ps = validate_cameras(projections, min_views=1, require_distinct=False)
    V = len(Ps)
    sizes = np.asarray(image_sizes, dtype=float)
    sizes = np.broadcast_to(sizes, (V, 2)) if sizes.shape == (2,) else sizes
    if sizes.shape != (V, 2) or not np.all(np.isfinite(sizes)) or np.any(sizes <= 0) or np.any(sizes % 1):
        raise ValueError(f"image_sizes must be positive integer (width, height) pairs for {V} views, "
                         f"got shape {np.shape(image_sizes)}")
    names = [f"view_{j:03d}.png" for j in range(V)] if names is None else [str(n) for n in names]
    if len(names) != V or len(set(names)) != V:
        raise ValueError(f"names must be {V} distinct image names, got {len(names)} ({len(set(names))} distinct)")
    cameras, poses = {}, []
    for j, P in enumerate(Ps):
        K, Rt = decompose_camera(P)
        w, h = (int(v) for v in sizes[j])
        shift = abs(K[0, 1]) * max(abs(K[1, 2]), abs(h - K[1, 2])) / K[1, 1]
        if shift > MAX_SKEW_PX:
            raise SkewError(f"view {j} ({names[j]}): K has skew {K[0, 1]:.6g} (fx = {K[0, 0]:.6g}); dropping it "
                            f"moves pixels by up to {shift:.3g} px > MAX_SKEW_PX = {MAX_SKEW_PX:g}: COLMAP cameras "
                            f"have no skew, so this camera cannot be represented")
        cameras[j + 1] = Camera(j + 1, "PINHOLE", w, h, (K[0, 0], K[1, 1], K[0, 2], K[1, 2]))
        poses.append((qvec_from_rotation(Rt[:, :3]), Rt[:, 3]))
    keypoints = [[] for _ in range(V)]
    points = []
    for k, track in enumerate(tracks):
        views = sorted(int(v) for v in track)
        if len(views) < 2 or views[0] < 0 or views[-1] >= V:
            raise ValueError(f"tracks[{k}] must map >= 2 distinct view indices in 0..{V - 1} to points, "
                             f"got views {views}")
        xy = np.array([np.asarray(track[v], float) for v in views])
        if xy.shape != (len(views), 2) or not np.all(np.isfinite(xy)):
            raise ValueError(f"tracks[{k}]: image points must be finite (x, y) pairs")
        try:
            X = dlt(Ps[views], xy)
        except PointAtInfinityError as exc:
            raise ValueError(f"tracks[{k}]: {exc}") from None
        entries = []
        for v, p in zip(views, xy):
            entries.append((v + 1, len(keypoints[v])))
            keypoints[v].append((float(p[0]), float(p[1]), k + 1))
        points.append((k + 1, X, tuple(entries)))
    _check_right_handed(Ps, points)
    images = {j + 1: Image(j + 1, tuple(q), tuple(t), j + 1, names[j], tuple(keypoints[j]))
              for j, (q, t) in enumerate(poses)}
    base = Model(cameras, images, {pid: Point3D(pid, X, rgb, 0.0, tr) for pid, X, tr in points})
    return base.replace_points([Point3D(pid, X, rgb, reprojection_error(base, X, tr), tr) for pid, X, tr in points])


def _check_right_handed(Ps: np.ndarray, points) -> None:
    """ValueError when the DLT points say the projections' world frame is reflected (module docstring)."""
    if not points:
        return
    cams = np.concatenate([Ps[[v - 1 for v, _ in tr]] for _, _, tr in points])[:, None]
    X = np.concatenate([np.broadcast_to(X, (len(tr), 3)) for _, X, tr in points])
    if world_frame_of(cams, X) is WorldFrame.REFLECTED:
        raise ValueError("the projections are in a reflected (mirrored) world frame: their points lie in front of "
                         "the cameras only with world_frame='reflected', and COLMAP's frames are right-handed; "
                         "mirror the world first (P @ diag(1, 1, -1, 1), points (x, y, -z))")


def model_from_oxford(name: str, data_dir=None, max_tracks: int | None = None, min_views: int = 2) -> Model:
    """Convert an Oxford VGG sequence (:func:`tritools.io.oxford.load_sequence`) to a COLMAP model.

    The data carry no image sizes: each view's size is the smallest integer (width, height)
    containing all of its corners (``ceil(max x) + 1``, ``ceil(max y) + 1``).  Image names
    are ``<name>_<view>.png``.  ``max_tracks`` keeps the first tracks only.
    """
    from ..oxford import load_sequence

    seq = load_sequence(name, data_dir, min_views=min_views)
    tracks = seq.tracks if max_tracks is None else seq.tracks[:int(max_tracks)]
    V = len(seq.cameras)
    extent = np.zeros((V, 2))
    for t in seq.tracks:
        for v, p in zip(t.views, t.points2d):
            extent[v] = np.maximum(extent[v], p)
    sizes = [(math.ceil(x) + 1, math.ceil(y) + 1) for x, y in extent]
    return model_from_projections(seq.cameras, sizes, [dict(zip(t.views, t.points2d)) for t in tracks],
                                  [f"{name}_{v:03d}.png" for v in range(V)])
