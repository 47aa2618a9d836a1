"""Arrays as OpenCV users have them: point layouts for :func:`tritools.triangulate_points` and camera
matrices from ``K, R, t`` (or a Rodrigues ``rvec``).

Point layouts (:class:`PointsLayout`), for M points seen in V views:

========================= ================= ==============================================================
layout                    shape             where it comes from
========================= ================= ==============================================================
``"points_views"``        (M, V, 2)         one row per point (tritools' own layout)
``"views_xy_points"``     (V, 2, M)         ``cv2.triangulatePoints(P1, P2, pts1, pts2)``: each view 2 x M
``"views_points"``        (V, M, 2) or      each view an (M, 2) array, or OpenCV's (M, 1, 2) (``cv2.
                          (V, M, 1, 2)      undistortPoints``, ``cv2.goodFeaturesToTrack``), stacked
========================= ================= ==============================================================

A list of V per-view arrays is stacked first.  With ``layout="auto"`` (the default) the shape must fit
exactly one layout; a shape that fits several -- e.g. two views and two points, (2, 2, 2), or V = M in
(V, V, 2) -- is refused with a ValueError asking for ``layout=``: a transposed array is never guessed.

Cameras: :func:`cameras_from_krt` gives ``P = K [R | t]`` (world -> pixel, as ``cv2.projectPoints``) for
one view or V views; ``R`` is a rotation matrix (det +1, orthonormal to 1e-6) or a Rodrigues vector
(``cv2.Rodrigues``: axis times angle; a (3, 3) array is always read as one rotation matrix, so pass three
vectors as (3, 3, 1), the shape of a stack of ``cv2.solvePnP`` results), ``t`` the translation (``tvec``).
"""
from __future__ import annotations

import enum

import numpy as np
from numpy.typing import ArrayLike

from .regions.base import real_array

__all__ = ["PointsLayout", "points_array", "cameras_from_krt", "rotation_from_rodrigues", "ROTATION_ATOL"]

#: ``R`` must satisfy ``|R^T R - I| <= ROTATION_ATOL`` (entrywise) and det R > 0.
ROTATION_ATOL = 1e-6


class PointsLayout(str, enum.Enum):
    """Axis order of an image-point array (module table)."""

    AUTO = "auto"
    POINTS_VIEWS = "points_views"          # (M, V, 2)
    VIEWS_XY_POINTS = "views_xy_points"    # (V, 2, M), cv2.triangulatePoints
    VIEWS_POINTS = "views_points"          # (V, M, 2) or (V, M, 1, 2)


def _fits(shape: tuple, V: int) -> list[PointsLayout]:
    out = []
    if len(shape) == 3 and shape[1:] == (V, 2):
        out.append(PointsLayout.POINTS_VIEWS)
    if len(shape) == 3 and shape[:2] == (V, 2):
        out.append(PointsLayout.VIEWS_XY_POINTS)
    if (len(shape) == 3 and shape[0] == V and shape[2] == 2) or (len(shape) == 4 and shape[0] == V
                                                                 and shape[2:] == (1, 2)):
        out.append(PointsLayout.VIEWS_POINTS)
    return out


def points_array(points2d: ArrayLike, n_views: int, layout: PointsLayout | str = PointsLayout.AUTO,
                 name: str = "points2d") -> np.ndarray:
    """``points2d`` in tritools' (M, V, 2) layout (float64), from any layout of the module table.

    Raises
    ------
    ValueError
        An unknown ``layout``; a shape that fits no layout (or not the one given); with ``"auto"``, a shape
        that fits several layouts (the message names them: pass ``layout=``).
    """
    try:
        lay = PointsLayout(getattr(layout, "value", layout))
    except ValueError:
        raise ValueError(f"layout must be one of {', '.join(repr(v.value) for v in PointsLayout)}, "
                         f"got {layout!r}") from None
    if isinstance(points2d, (list, tuple)) and points2d and all(np.ndim(p) >= 2 for p in points2d):
        per_view = [real_array(p, f"{name}[{k}]") for k, p in enumerate(points2d)]
        if len({p.shape for p in per_view}) > 1:
            raise ValueError(f"{name} as a list of per-view arrays must have arrays of one shape, got "
                             f"{[p.shape for p in per_view]}")
        points2d = np.stack(per_view)
    x = real_array(points2d, name)
    fits = _fits(x.shape, n_views)
    if lay == PointsLayout.AUTO:
        if len(fits) > 1:
            raise ValueError(f"{name} of shape {x.shape} with {n_views} views is ambiguous (it fits layouts "
                             f"{', '.join(repr(f.value) for f in fits)}): pass layout=... explicitly")
        if not fits:
            raise ValueError(f"{name} must have shape (M, {n_views}, 2), ({n_views}, 2, M), ({n_views}, M, 2) or "
                             f"({n_views}, M, 1, 2) for {n_views} views, got {x.shape}")
        lay = fits[0]
    elif lay not in fits:
        want = {PointsLayout.POINTS_VIEWS: f"(M, {n_views}, 2)", PointsLayout.VIEWS_XY_POINTS: f"({n_views}, 2, M)",
                PointsLayout.VIEWS_POINTS: f"({n_views}, M, 2) or ({n_views}, M, 1, 2)"}[lay]
        raise ValueError(f"{name} with layout {lay.value!r} must have shape {want}, got {x.shape}")
    if lay == PointsLayout.VIEWS_XY_POINTS:
        return np.ascontiguousarray(x.transpose(2, 0, 1))
    if lay == PointsLayout.VIEWS_POINTS:
        return np.ascontiguousarray(x.reshape(n_views, -1, 2).transpose(1, 0, 2))
    return x


def rotation_from_rodrigues(rvec: ArrayLike) -> np.ndarray:
    """R = exp([r]_x) of Rodrigues vectors (..., 3) (``cv2.Rodrigues``): Rodrigues' formula
    ``I + sin(a) [k]_x + (1 - cos(a)) [k]_x^2`` with ``a = |r|``, ``k = r / a`` (I at a = 0)."""
    r = np.asarray(rvec, float)
    a = np.linalg.norm(r, axis=-1)
    k = r / np.where(a > 0, a, 1.0)[..., None]
    Kx = np.zeros(r.shape[:-1] + (3, 3))
    Kx[..., 0, 1], Kx[..., 0, 2], Kx[..., 1, 2] = -k[..., 2], k[..., 1], -k[..., 0]
    Kx = Kx - np.swapaxes(Kx, -1, -2)
    s, c = np.sin(a)[..., None, None], np.cos(a)[..., None, None]
    return np.eye(3) + s * Kx + (1 - c) * (Kx @ Kx)


def cameras_from_krt(K: ArrayLike, R: ArrayLike, t: ArrayLike) -> np.ndarray:
    """``P = K [R | t]``: (3, 4) for one view, (V, 3, 4) for V views (K may be shared).

    Parameters
    ----------
    K : (3, 3) or (V, 3, 3) intrinsics
    R : (3, 3) / (V, 3, 3) rotations (cam_from_world), or (3,), (3, 1), (V, 3, 1) Rodrigues vectors (as
        ``cv2.solvePnP`` returns them), or (V, 3) for V != 3 (a (3, 3) array is always one rotation matrix)
    t : (3,), (3, 1), (V, 3) or (V, 3, 1) translations (cam_from_world)

    Raises
    ------
    ValueError
        Non-finite values, shapes that do not match, or an ``R`` that is not a rotation (naming the field).
    """
    Ka, Ra, ta = real_array(K, "K"), real_array(R, "R"), real_array(t, "t")
    for nm, a in (("K", Ka), ("R", Ra), ("t", ta)):
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{nm} must be finite")
    if Ra.shape[-2:] != (3, 3):                               # Rodrigues vectors
        if Ra.shape[-1:] == (1,) and Ra.shape[-2:-1] == (3,):
            Ra = Ra[..., 0]
        if Ra.shape[-1:] != (3,) or Ra.ndim > 2:
            raise ValueError(f"R must be (3, 3) / (V, 3, 3) rotations or (3,) / (V, 3) Rodrigues vectors, "
                             f"got shape {Ra.shape}")
        Ra = rotation_from_rodrigues(Ra)
    if ta.shape[-1:] == (1,) and ta.shape[-2:-1] == (3,):
        ta = ta[..., 0]
    if Ka.shape[-2:] != (3, 3) or Ka.ndim > 3 or Ra.ndim > 3 or ta.shape[-1:] != (3,) or ta.ndim > 2:
        raise ValueError(f"K, R, t must have shapes (3, 3) / (V, 3, 3), (3, 3) / (V, 3, 3), (3,) / (V, 3); got "
                         f"{Ka.shape}, {Ra.shape}, {ta.shape}")
    eye = np.swapaxes(Ra, -1, -2) @ Ra
    if np.any(np.abs(eye - np.eye(3)) > ROTATION_ATOL) or np.any(np.linalg.det(Ra) <= 0):
        hint = " (three Rodrigues vectors? pass them as shape (3, 3, 1))" if Ra.shape == (3, 3) else ""
        raise ValueError(f"R must be a rotation (orthonormal to {ROTATION_ATOL:g}, det +1){hint}")
    if np.any(Ka[..., 2, 2] == 0):
        raise ValueError("K[2, 2] must be non-zero")
    single = Ka.ndim == 2 and Ra.ndim == 2 and ta.ndim == 1
    try:
        lead = np.broadcast_shapes(Ka.shape[:-2], Ra.shape[:-2], ta.shape[:-1])
    except ValueError:
        raise ValueError(f"K, R, t have different numbers of views: {Ka.shape}, {Ra.shape}, {ta.shape}") from None
    Rt = np.concatenate([np.broadcast_to(Ra, lead + (3, 3)), np.broadcast_to(ta[..., :, None], lead + (3, 1))],
                        axis=-1)
    P = Ka @ Rt
    return P.reshape(3, 4) if single else P
