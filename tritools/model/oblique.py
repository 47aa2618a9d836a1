"""The obliquity of a view's ray (review 24a): sec theta, theta the angle between the ray through an image point and
the camera's principal axis.  On a ray with sec theta = 1e8 a relative perturbation of the camera moves the depth of
a point, and its projection, ~1e8 times more, so bounds computed in a rounded frame are lowered by it
(:func:`tritools.model.magnitude.magnitudes`, :func:`tritools.solve.decide.gamma_lower`).
"""
from __future__ import annotations

import math

import numpy as np

from .cameras import power2_scale

__all__ = ["obliquities", "obliquity_one"]


def obliquities(C: np.ndarray, x: np.ndarray) -> np.ndarray:
    """sec theta_i (..., N) of cameras C (..., N, 3, 4) at points x (..., N, 2): theta the angle between the ray of
    x_i and the principal axis, sec theta = |m3| |M^-1 x~| (M = P[:, :3], m3 its third row; m3 . M^-1 x~ = 1), from
    M^-1 = [m2 x m3, m3 x m1, m1 x m2] / det M.  A relative perturbation of the camera moves the depth of a point on
    that ray by ~ sec theta times its own size, so the projection there by ~ |x_i| sec theta times it
    (:func:`tritools.model.magnitude.magnitudes`).  Invariant to the camera's scale, to image similarities (the point
    moving with the image) and to world similarities (the ray and the axis are the camera's); 1 where it is NaN (an
    affine camera, m3 = 0: no depth), inf where the ray is parallel to the image plane or the numbers overflow."""
    C = np.asarray(C, float)
    M = np.moveaxis(C[..., :3] / power2_scale(C, (-2, -1)), (-2, -1), (0, 1))     # M[r, k] (...,): entries
    (a, b, c), (d, e, f), (g, h, i) = M
    u, v = x[..., 0], x[..., 1]
    with np.errstate(all="ignore"):
        c0 = (e * i - f * h, f * g - d * i, d * h - e * g)           # m2 x m3, m3 x m1, m1 x m2: the columns of adj M
        c1 = (h * c - i * b, i * a - g * c, g * b - h * a)
        c2 = (b * f - c * e, c * d - a * f, a * e - b * d)
        det = a * c0[0] + b * c0[1] + c * c0[2]
        r0, r1, r2 = (c0[k] * u + c1[k] * v + c2[k] for k in range(3))
        sec = np.sqrt((g * g + h * h + i * i) * (r0 * r0 + r1 * r1 + r2 * r2)) / np.abs(det)
    return np.where(np.isnan(sec), 1.0, np.maximum(sec, 1.0))


def obliquity_one(P: list, x: list) -> float:
    """The scalar twin of :func:`obliquities` for one view: camera P (3 lists of 4 floats) divided by the power of
    two of :func:`tritools.model.cameras.power2_scale` (the caller's), x (2 floats); the same operations, equal bit
    for bit (tests/test_oblique_frame.py)."""
    (a, b, c, _), (d, e, f, _), (g, h, i, _) = P
    u, v = x
    c0 = (e * i - f * h, f * g - d * i, d * h - e * g)
    c1 = (h * c - i * b, i * a - g * c, g * b - h * a)
    c2 = (b * f - c * e, c * d - a * f, a * e - b * d)
    det = a * c0[0] + b * c0[1] + c * c0[2]
    r0, r1, r2 = (c0[k] * u + c1[k] * v + c2[k] for k in range(3))
    num = math.sqrt((g * g + h * h + i * i) * (r0 * r0 + r1 * r1 + r2 * r2))
    if det == 0:                                                    # (numpy's num / 0: inf, or NaN for 0 / 0)
        return math.inf if num > 0 else 1.0
    sec = num / abs(det)
    return 1.0 if math.isnan(sec) else max(sec, 1.0)
