"""The camera-only work of a single call, done once for the cameras of consecutive calls (issue #22).

A program that triangulates point after point with the same cameras -- a stereo rig, the views of one image
pair, the images of one track set -- makes every :func:`tritools.triangulate` repeat the work that depends on
the cameras alone:

* their check (:func:`tritools.model.cameras.validate_cameras`: finite, rank 3 by the conditioned rule, not all
  equal);
* the world frame (:func:`tritools.model.frame.world_frame`) and the cameras re-centred in it
  (:meth:`tritools.model.frame.WorldFrame.cameras`);
* the depth rows sign(det M) p3 / ||m3|| (:func:`tritools.model.cameras.depth_rows`).

Each is a deterministic function of the cameras' numbers, so the result for the last cameras seen is remembered,
keyed by their exact bytes and shape (after the conversion to float64 that the check itself does), and given back
for the same bytes: the same numbers as computing it again (tests/test_fastpath_cameras.py), and nothing skipped for
other data -- a miss computes and checks everything, and a camera array that fails the check raises its
ValueError as before and is never remembered.  One entry per function (memory: one camera set), replaced and
never mutated, so a concurrent reader sees the old or the new pair; remembered arrays are read-only and the
arrays handed out are copies where a caller may write (the validated and the re-centred cameras).
"""
from __future__ import annotations

import numpy as np

from ..model.cameras import WorldFrame as Handedness
from ..model.cameras import SCALAR_MAX_VIEWS, as_world_frame, depth_rows, validate_cameras
from ..model.frame import WorldFrame, world_frame
from ..model.regions.base import real_array

__all__ = ["validated_cameras", "validated_problem", "framed_cameras", "depths_one"]

#: the last entry of each function: (key, value) or None.
_LAST_VALID: list = [None]
_LAST_FRAME: list = [None]
_LAST_ROWS: list = [None]


def _key(C: np.ndarray) -> tuple:
    return C.dtype.str, C.shape, C.tobytes()


def _read_only(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a


def validated_cameras(cameras) -> np.ndarray:
    """:func:`tritools.model.cameras.validate_cameras` (N >= 2 views, not all equal) of ``cameras``: a new float64
    array (N, 3, 4); the checks are skipped only for the bytes of the last cameras that passed them."""
    C = real_array(cameras, "cameras")
    key = _key(C)
    last = _LAST_VALID[0]
    if last is not None and last == key:
        return C
    C = validate_cameras(C)
    _LAST_VALID[0] = key
    return C


def validated_problem(cameras, regions) -> tuple[np.ndarray, list]:
    """The input checks of every path of one problem, in one place: (:func:`validated_cameras` of ``cameras``, the
    regions as :func:`tritools.model.regions.as_regions` of ``regions`` for that many views, each with an extent,
    :func:`~tritools.model.regions.require_extent`).  Raises their ValueError / TypeError."""
    from ..model.regions import as_regions, require_extent

    cams = validated_cameras(cameras)
    regs = as_regions(regions, cams.shape[0])
    require_extent(regs)                  # every path needs it (docs/regions.md): refused alike everywhere
    return cams, regs


def framed_cameras(cams: np.ndarray) -> tuple[WorldFrame, np.ndarray]:
    """(:func:`tritools.model.frame.world_frame` of validated cameras (N, 3, 4), the cameras in that frame -- a new
    array)."""
    key = _key(cams)
    last = _LAST_FRAME[0]
    if last is None or last[0] != key:
        frame = world_frame(cams)
        _read_only(frame.origin)
        last = (key, (frame, _read_only(frame.cameras(cams))))
        _LAST_FRAME[0] = last
    frame, cams_f = last[1]
    return frame, cams_f.copy()


def depths_one(C: np.ndarray, X: np.ndarray, world_frame: Handedness | str = Handedness.RIGHT_HANDED) -> np.ndarray:
    """The depths (N,) of one point X (3,) in the cameras C (N, 3, 4): the formula of
    :func:`tritools.model.cameras.depths_stack_arrays` on a stack of one, with the cameras' depth rows
    remembered."""
    key = _key(C)
    last = _LAST_ROWS[0]
    few = len(C) <= SCALAR_MAX_VIEWS                    # the sums on floats: the same bits
    if last is None or last[0] != key or isinstance(last[1], list) != few:
        rows = depth_rows(C)
        last = (key, rows.tolist() if few else _read_only(rows[None]))
        _LAST_ROWS[0] = last
    h = as_world_frame(world_frame).sign
    if few:                                             # einsum's order of the four products, (p0 + p2) + (p1 + p3)
        x0, x1, x2 = X.tolist()
        return np.array([h * ((r[0] * x0 + r[2] * x2) + (r[1] * x1 + r[3])) for r in last[1]])
    Xh = np.concatenate([X[None], np.ones((1, 1))], axis=1)
    with np.errstate(over="ignore", invalid="ignore"):
        return (h * np.einsum("mj,mnj->mn", Xh, last[1]))[0]
