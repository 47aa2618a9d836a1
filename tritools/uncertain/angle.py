"""Triangulation angle: the largest angle between two viewing rays of a point.

For camera centres ``C_i`` and a point ``X`` the rays are ``X - C_i``; the triangulation angle is
``max_{i<j} angle(X - C_i, X - C_j)`` (COLMAP filters on it: ``min_tri_angle`` 1.5 degrees by
default).  Computed with ``atan2(||u x v||, u . v)`` (accurate for tiny angles, unlike ``acos``).

A ray is undefined where ``X`` sits at a camera centre: ``||X - C_i|| <= RAY_RTOL max(||X||, ||C_i||)`` (the
centre itself is known to a few ulps of that size); the angle of such a point is NaN, not the angle of a
round-off direction (review 49a F4).
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ..model.cameras import camera_center, validate_cameras

__all__ = ["triangulation_angle", "triangulation_angles", "ray_angles", "RAY_RTOL"]

#: A viewing ray shorter than this times the larger of ||X|| and ||C_i|| is undefined (X at the camera centre).
RAY_RTOL = 1e-10


def ray_angles(U: np.ndarray, V: np.ndarray) -> np.ndarray:
    """Angles (radians) between rays U, V (..., 3), in [0, pi]."""
    return np.arctan2(np.linalg.norm(np.cross(U, V), axis=-1), np.einsum("...k,...k->...", U, V))


def triangulation_angles(centres: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Largest pairwise ray angle in degrees for stacks: centres (M, N, 3) (NaN rows are ignored:
    padding), X (M, 3) -> (M,); 0 for fewer than two rays, NaN where a ray is undefined (``RAY_RTOL``)."""
    rays = X[:, None, :] - centres
    with np.errstate(invalid="ignore"):
        size = np.fmax(np.linalg.norm(centres, axis=-1), np.linalg.norm(X, axis=-1)[:, None])
        undefined = np.any(np.linalg.norm(rays, axis=-1) <= RAY_RTOL * size, axis=1)
    n = rays.shape[1]
    best = np.zeros(len(X))
    for i in range(n):
        for j in range(i + 1, n):
            a = ray_angles(rays[:, i], rays[:, j])
            best = np.fmax(best, np.where(np.isnan(a), 0.0, a))
    return np.where(undefined, np.nan, np.degrees(best))


def triangulation_angle(cameras: ArrayLike, X: ArrayLike) -> float:
    """Largest angle (degrees) between the viewing rays of ``X`` (3,) from the cameras' centres; NaN when ``X`` is
    at a camera centre (that view's ray is undefined)."""
    C = validate_cameras(cameras, min_views=1, require_distinct=False)
    X = np.asarray(X, float)
    if X.shape != (3,) or not np.all(np.isfinite(X)):
        raise ValueError(f"X must be a finite 3-vector, got {X!r}")
    centres = np.array([camera_center(P) for P in C])
    return float(triangulation_angles(centres[None], X[None])[0])
