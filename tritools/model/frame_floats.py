"""The pieces of the normalisation's frame of one problem on Python floats: the scalar twins of
:func:`tritools.model.stacked.pixel_scales`, :func:`~tritools.model.stacked.project_one` and
:func:`~tritools.model.stacked.null_vectors` for the few views of a single call (issue #22: each numpy call on a
(N, 3, 4) array of two views costs more than its arithmetic), used by
:func:`tritools.model.normalize._frame_one` up to :data:`tritools.model.lm_one.FLOAT_MAX_VIEWS` views.

Each float function has its numpy twin here (``*_array``).  The same formulas with the sums written out in index
order: equal to the numpy code up to round-off
(tests/test_wave48.py checks them against it, bit for bit where numpy sums in the same order).  The frame they
choose is an exact change of coordinates whatever its last bits (:mod:`tritools.model.normalize`), so round-off
here changes no rigour.  Cameras are 3 lists of 4 floats, points pairs of floats.
"""
from __future__ import annotations

import math

import numpy as np

from sospoly import pow2_above

from .geometry import COMMON_CENTRE_RTOL, POINT_AT_INFINITY_RTOL, PROJECTION_DENOM_RTOL
from .stacked import norms, null_vectors, project_one

__all__ = ["pixel_scale_one", "project_floats", "null_vector_one", "max_abs", "residual_squares", "centre_distances",
           "residual_squares_array", "centre_distances_array"]


def pixel_scale_one(P: list, x) -> float:
    """:func:`tritools.model.stacked.pixel_scales` of one view: sigma_max(P[:2, :3] - x P[2, :3]) / ||P[2, :3]||
    (the largest singular value of the 2 x 3 matrix in closed form, divided first by the power of two above its
    largest entry: :func:`tritools.model.stacked.sigma_max_2x3`), NaN where ||P[2, :3]|| = 0."""
    (a, b, c, _), (d, e, f, _), (g, h, i, _) = P
    u, v = x
    B = (a - u * g, b - u * h, c - u * i, d - v * g, e - v * h, f - v * i)
    n = math.sqrt((g * g + h * h) + i * i)
    if not n > 0:
        return math.nan
    m = max_abs(B)
    k = pow2_above(m)
    b00, b01, b02, b10, b11, b12 = (t / k for t in B)
    p = (b00 * b00 + b01 * b01) + b02 * b02
    r = (b10 * b10 + b11 * b11) + b12 * b12
    q = (b00 * b10 + b01 * b11) + b02 * b12
    hh = (p - r) / 2
    w = hh * hh + q * q
    s = (p + r) / 2 + (math.sqrt(w) if w == w else math.nan)
    return k * (math.sqrt(s) if s == s else math.nan) / n


def max_abs(values) -> float:
    """``numpy.maximum.reduce`` of the absolute values: NaN if any is NaN."""
    out = 0.0
    for t in values:
        t = abs(t)
        if t != t:
            return math.nan
        if t > out:
            out = t
    return out


def project_floats(P: list, X) -> list | None:
    """:func:`tritools.model.stacked.project_one` of one point X (3 floats) in the cameras P (N lists of 3 rows of
    4 floats): the projections (N pairs), or None where a view's denominator is at round-off, |P_3 . X~| <=
    PROJECTION_DENOM_RTOL |P_3| . |X~|, or a projection is not finite."""
    X0, X1, X2 = X
    A0, A1, A2 = abs(X0), abs(X1), abs(X2)
    out = []
    for (r0, r1, r2) in P:
        den = ((r2[0] * X0 + r2[1] * X1) + r2[2] * X2) + r2[3]
        scale = ((abs(r2[0]) * A0 + abs(r2[1]) * A1) + abs(r2[2]) * A2) + abs(r2[3])
        if not abs(den) > PROJECTION_DENOM_RTOL * scale:
            return None
        u = (((r0[0] * X0 + r0[1] * X1) + r0[2] * X2) + r0[3]) / den
        v = (((r1[0] * X0 + r1[1] * X1) + r1[2] * X2) + r1[3]) / den
        if not (math.isfinite(u) and math.isfinite(v)):
            return None
        out.append((u, v))
    return out


def null_vector_one(P: list) -> tuple:
    """:func:`tritools.model.stacked.null_vectors` of one 3 x 4 matrix: a_k = (-1)^k det P[:, columns != k], each
    determinant expanded along the first row (the same formula)."""
    out = []
    for k, cols in enumerate(((1, 2, 3), (0, 2, 3), (0, 1, 3), (0, 1, 2))):
        (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = ([row[c] for c in cols] for row in P)
        det = (a00 * (a11 * a22 - a12 * a21) - a01 * (a10 * a22 - a12 * a20)) + a02 * (a10 * a21 - a11 * a20)
        out.append(-det if k % 2 else det)
    return tuple(out)


def residual_squares(P: list, X, x) -> float | None:
    """sum_i ||Phi(X, P_i) - x_i||^2 of the projections of :func:`project_floats` (None where it has none);
    :func:`residual_squares_array` is its twin."""
    u = project_floats(P, X)
    if u is None:
        return None
    out = 0.0
    for (a, b), (p, q) in zip(u, x):
        out += (a - p) * (a - p) + (b - q) * (b - q)
    return out


def centre_distances(P: list, X0) -> list | None:
    """The distances (N floats) from X0 (3 floats) to the cameras' centres (the unit null vectors of
    :func:`null_vector_one`), or None off the normalisation's common path: a centre at infinity (|a_4| <=
    POINT_AT_INFINITY_RTOL), every view through the first view's centre (|P_i a| <= COMMON_CENTRE_RTOL
    max_r |P_i,r| . |a| in every row), or a distance not finite.  :func:`centre_distances_array` is its twin."""
    units = []
    for Pi in P:
        a = null_vector_one(Pi)
        n = math.sqrt(((a[0] * a[0] + a[1] * a[1]) + a[2] * a[2]) + a[3] * a[3])
        if not 0.0 < n < math.inf:                    # (rank < 3 or non-finite: numpy's NaN, off the path)
            return None
        a = tuple(t / n for t in a)
        if not abs(a[3]) > POINT_AT_INFINITY_RTOL:
            return None
        units.append(a)
    a0 = units[0]
    b0 = tuple(abs(t) for t in a0)
    shared = True
    for Pi in P:
        dots = [((r[0] * a0[0] + r[1] * a0[1]) + r[2] * a0[2]) + r[3] * a0[3] for r in Pi]
        scale = [((abs(r[0]) * b0[0] + abs(r[1]) * b0[1]) + abs(r[2]) * b0[2]) + abs(r[3]) * b0[3] for r in Pi]
        tol = COMMON_CENTRE_RTOL * max(scale)
        if not all(abs(t) <= tol for t in dots):
            shared = False
            break
    if shared:
        return None
    out = []
    for a in units:
        e = (a[0] / a[3] - X0[0], a[1] / a[3] - X0[1], a[2] / a[3] - X0[2])
        t = math.sqrt((e[0] * e[0] + e[1] * e[1]) + e[2] * e[2])
        if not math.isfinite(t):
            return None
        out.append(t)
    return out


def residual_squares_array(P: np.ndarray, X0: np.ndarray, xi: np.ndarray) -> float | None:
    """:func:`residual_squares` on arrays (P (N, 3, 4), X0 (3,), xi (N, 2); numpy's sums), under the caller's
    ``np.errstate(over="ignore", invalid="ignore")``."""
    u0, _, fin0 = project_one(P, X0)
    return float(np.add.reduce(np.add.reduce((u0 - xi) ** 2, axis=1))) if fin0 else None


def centre_distances_array(P: np.ndarray, X0: np.ndarray) -> list | None:
    """:func:`centre_distances` on arrays (the same rules; numpy's sums)."""
    a = null_vectors(P)
    a = a / norms(a, axis=1, keepdims=True)
    if not (np.abs(a[:, 3]) > POINT_AT_INFINITY_RTOL).all():
        return None
    a0 = a[0]
    if (np.abs(P @ a0) <= COMMON_CENTRE_RTOL * np.maximum.reduce(np.abs(P) @ np.abs(a0), axis=1)[:, None]).all():
        return None                                      # every view has one centre: the stacked code's special case
    dist = norms(a[:, :3] / a[:, 3:] - X0, axis=1).tolist()
    return dist if all(math.isfinite(t) for t in dist) else None
