"""Projective geometry for multiple-view triangulation (SPEC §1, §3, §6, §7).

Conventions
-----------
* A camera is a 3x4 projection matrix ``P`` with rows ``p1, p2, p3``; a scene point
  ``X in R^3`` projects to ``Phi(X, P) = (p1.X~ / p3.X~, p2.X~ / p3.X~)``,
  ``X~ = [X; 1]`` (paper eq. (4)).
* ``cameras`` is an array of shape (N, 3, 4); ``points2d`` has shape (N, 2), one
  image point per view.  A stack of M problems has cameras (M, N, 3, 4).
* ``fundamental_matrix(P_i, P_j)`` returns ``F_ij`` with
  ``x~_i' F_ij x~_j = 0`` for exact projections ``x_i`` (view i) and ``x_j`` (view j)
  of one scene point (SPEC §7, paper eq. (61)): the *first* index is the view on
  the *left* of the bilinear form.

Camera validation lives in :mod:`tritools.model.cameras` (re-exported here).
"""
from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from .cameras import (CAMERA_RANK_RTOL, POINT_AT_INFINITY_RTOL, SAME_CAMERA_RTOL, CameraIssue, CameraProblems,
                      camera_center, camera_problems, camera_rank_ratio, cameras_all_equal, check_camera, depths,
                      depths_stack, points3d_array, power2_scale, unit_rows, validate_cameras, WorldFrame,
                      world_frame_of)
from .exact import CANCELLATION_RATIO, COMPENSATED_DENOM_RTOL, accurate_homogeneous
from .refine import (EvaluationGuard, RefinementStopped, disc_shapes, evaluations_after, evaluations_floor, gamma_discs,
                     residual_function, residual_jacobian)
from .regions.base import real_array
from .regions.stack import RegionStack

__all__ = [
    "PointAtInfinityError", "validate_cameras", "validate_points2d", "project", "image_points",
    "camera_center", "depths", "gamma", "dlt", "fundamental_matrix", "fundamental_matrices",
    "M0", "m0_validated", "m0_stack", "point_from_image_points", "point_from_validated", "points_from_validated",
    "CAMERA_RANK_RTOL", "SAME_CAMERA_RTOL", "PROJECTION_DENOM_RTOL", "POINT_AT_INFINITY_RTOL", "COMMON_CENTRE_RTOL",
    "SAME_CENTER_RTOL",
    "camera_problems", "CameraProblems", "CameraIssue", "camera_rank_ratio", "cameras_all_equal", "depths_stack",
    "WorldFrame", "world_frame_of",
]

# ----------------------------------------------------------------------------- tolerances
#: ``Phi(X, P)`` is undefined (at infinity, or X at the camera centre) if
#: ``|p3.X~| <= PROJECTION_DENOM_RTOL * sum_k |p3_k| |X~_k|``: that sum bounds the round-off of the dot
#: product (times eps), so beyond this the projection would carry fewer than ~6 correct digits (a point at
#: a shared camera centre, depth ~1e-13, used to get a round-off gamma reported as an upper bound).  The
#: componentwise sum, not ||p3|| ||X~||: georeferenced scenes (|X| ~ 5e6, depth 10) are well defined.  The rule
#: of the plain dot products (:func:`tritools.model.stacked.project_stack`, the searches); the projections of this
#: module recompute a view that cancels by the compensated dot product and so use
#: :data:`tritools.model.exact.COMPENSATED_DENOM_RTOL` (a view that does not cancel is never that small).
PROJECTION_DENOM_RTOL = 1e-10
#: every view shares one centre C (:func:`common_centre`) if ``|P_i C~| <= COMMON_CENTRE_RTOL sum |P_i| |C~|``
#: for every camera: round-off only (the pairwise homography test has the same tolerance).
COMMON_CENTRE_RTOL = 1e-12
#: Two camera centres coincide (F undefined) if ``||F||_F <= SAME_CENTER_RTOL * ||P_i|| ||P_j||``
#: (cameras divided by their largest entry first) in :func:`fundamental_matrix`; the vectorised
#: :func:`tritools.model.stacked.fundamental_stack` uses the same constant on sin(angle) of the two
#: null vectors (:func:`tritools.model.stacked.distinct_centres`: invariant to the cameras' scales).
SAME_CENTER_RTOL = 1e-10


class PointAtInfinityError(ValueError):
    """The homogeneous solution has ``w4 ~ 0``: the problem is ill-posed (SPEC §6)."""


# ----------------------------------------------------------------------------- validation
def validate_points2d(points2d, n_views: int, name: str = "points2d") -> np.ndarray:
    """Check image points: shape (n_views, 2), finite."""
    x = real_array(points2d, name)
    if x.shape != (n_views, 2):
        raise ValueError(f"{name} must have shape ({n_views}, 2), one point per view, got {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError(f"{name} contains NaN or inf")
    return x


# ----------------------------------------------------------------------------- projection
def project_homogeneous(Xh: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Projections of homogeneous points Xh (m, 4) by P (3, 4); inf where at infinity, NaN for
    non-finite points.  ``P`` and each ``Xh`` row are first divided by a power of two near their
    largest entry (``Phi`` does not depend on either scale; the result is the same to the last
    bit unless a product would have overflowed)."""
    return _project_scaled(*_scaled_points(Xh), P)


def project_views(Xh: np.ndarray, cameras) -> list:
    """``[project_homogeneous(Xh, P) for P in cameras]`` with the points scaled once (the same operations per
    camera, so the same numbers)."""
    Xs, finite = _scaled_points(Xh)
    return [_project_scaled(Xs, finite, P) for P in cameras]


def project_point_views(Xh: np.ndarray, cameras: np.ndarray) -> np.ndarray:
    """``np.vstack(project_views(Xh, cameras))`` for one homogeneous point Xh (1, 4) and cameras (N, 3, 4): row 0
    of :func:`project_points_views`, so a report of N views costs a few numpy calls instead of N."""
    return project_points_views(Xh, cameras)[0]


def project_points_views(Xh: np.ndarray, cameras: np.ndarray) -> np.ndarray:
    """``np.stack(project_views(Xh, cameras), axis=1)``, (m, N, 2), for homogeneous points Xh (m, 4) and cameras
    (N, 3, 4), stacked over the cameras: the operations of :func:`_project_scaled` per camera in one numpy
    expression each (a matrix product broadcast over the cameras makes the same BLAS call per camera as the loop;
    the compensated sums are elementwise), so the same numbers, tested equal."""
    Xs, finite = _scaled_points(Xh)
    C = np.asarray(cameras, float)
    Ps = C / power2_scale(C, (1, 2))
    h = Xs @ np.swapaxes(Ps, 1, 2)                                        # (N, m, 3): Xs @ Ps.T per camera
    mag = np.abs(Xs) @ np.swapaxes(np.abs(Ps), 1, 2)
    view, point = np.nonzero(~np.all(mag <= CANCELLATION_RATIO * np.abs(h), axis=2))
    if view.size:                     # cancellation (a georeferenced world): compensated, per camera and point
        h[view, point] = accurate_homogeneous(Ps[view], Xs[point][:, None, :])
    den = h[..., 2]
    tiny = np.abs(den) <= COMPENSATED_DENOM_RTOL * (np.abs(Xs) @ np.abs(Ps[:, 2, :]).T).T
    safe = np.where(tiny, 1.0, den)
    with np.errstate(over="ignore"):
        out = h[..., :2] / safe[..., None]
    out[tiny] = np.inf
    out[:, ~finite] = np.nan
    return np.swapaxes(out, 0, 1)


def _scaled_points(Xh: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(Xh's finite rows divided by a power of two near their largest entry, 0 elsewhere; the finite mask)."""
    finite = np.isfinite(Xh).all(axis=1)
    Xs = np.where(finite[:, None], Xh, 0.0)
    return Xs / power2_scale(Xs, (1,)), finite


def _project_scaled(Xs: np.ndarray, finite: np.ndarray, P: np.ndarray) -> np.ndarray:
    """:func:`project_homogeneous` of the scaled points of :func:`_scaled_points`."""
    Ps = P / power2_scale(P, (0, 1))
    h = Xs @ Ps.T
    rows = np.nonzero(~np.all(np.abs(Xs) @ np.abs(Ps).T <= CANCELLATION_RATIO * np.abs(h), axis=1))[0]
    if rows.size:                     # cancellation (a georeferenced world): compensated, per point
        h[rows] = accurate_homogeneous(np.broadcast_to(Ps, (rows.size, 3, 4)), Xs[rows][:, None, :])
    den = h[:, 2]
    tiny = np.abs(den) <= COMPENSATED_DENOM_RTOL * (np.abs(Xs) @ np.abs(Ps[2]))
    safe = np.where(tiny, 1.0, den)
    with np.errstate(over="ignore"):
        out = h[:, :2] / safe[:, None]
    out[tiny] = np.inf
    out[~finite] = np.nan
    return out


def project(X: ArrayLike, P: ArrayLike) -> np.ndarray:
    """``Phi(X, P)`` (paper eq. (4)).

    Parameters
    ----------
    X : array_like, shape (3,) or (m, 3)
    P : array_like, shape (3, 4)

    Returns
    -------
    ndarray, shape (2,) or (m, 2)
        ``inf`` entries where ``p3.X~`` vanishes (projection at infinity).
    """
    A, single = points3d_array(X)
    P = real_array(P, "P")
    if P.shape != (3, 4):
        raise ValueError(f"P must be a 3x4 matrix, got shape {P.shape}")
    Xh = np.hstack([A, np.ones((len(A), 1))])
    out = project_homogeneous(Xh, P)
    return out[0] if single else out


def image_points(X, cameras) -> np.ndarray:
    """Projections of ``X`` in every view: (3,) -> (N, 2); (m, 3) -> (m, N, 2) (:func:`project_points_views`:
    the per-camera :func:`project_homogeneous` stacked, the same numbers)."""
    A, single = points3d_array(X)
    C = validate_cameras(cameras, min_views=1, require_distinct=False)
    out = project_points_views(np.hstack([A, np.ones((len(A), 1))]), C)
    return out[0] if single else out


# ----------------------------------------------------------------------------- cost
def gamma_validated(Xs: np.ndarray, cameras: np.ndarray, regions: Sequence, *, shapes=...) -> np.ndarray:
    """gamma for validated inputs; Xs (m, 3) -> (m,). inf where a projection is at infinity.  Point and disc
    regions: one stacked expression (:func:`tritools.model.refine.gamma_discs`), else a loop over the views.
    ``shapes``: :func:`tritools.model.refine.disc_shapes` of ``regions`` when the caller has it (a loop over many
    points of one problem); found here by default."""
    shapes = disc_shapes(regions) if shapes is ... else shapes
    if shapes is not None and len(Xs):
        return gamma_discs(Xs, np.asarray(cameras, float), *shapes)
    m = len(Xs)
    Xh = np.hstack([Xs, np.ones((m, 1))])
    if m == 1:
        return _gamma_one(Xh, cameras, regions)
    total = np.zeros(m)
    bad = ~np.all(np.isfinite(Xs), axis=1)
    for P, R in zip(cameras, regions):
        x = project_homogeneous(Xh, P)
        finite = np.all(np.isfinite(x), axis=1)
        bad |= ~finite
        if np.any(finite):
            d = np.asarray(R.distance(x[finite]), dtype=float)
            total[finite] += d * d
    out = np.sqrt(total / (2 * len(cameras)))
    out[bad] = np.inf
    return out


def _gamma_one(Xh: np.ndarray, cameras: np.ndarray, regions: Sequence) -> np.ndarray:
    """:func:`gamma_validated` of one point (Xh (1, 4)): the same projections, the regions' closest points stacked
    by kind (:class:`~tritools.model.regions.RegionStack`, each the region's own single-point value) and the squares
    summed in view order, so the same numbers as a loop over ``Region.distance``."""
    x = np.array([project_homogeneous(Xh, P)[0] for P in cameras])
    if not np.all(np.isfinite(Xh)) or not np.all(np.isfinite(x)):
        return np.array([np.inf])
    stack = RegionStack.of(regions)
    total = 0.0
    for d in stack.distances(x).tolist():
        total += d * d
    return np.array([np.sqrt(total / (2 * len(cameras)))])


def gamma(X: ArrayLike, cameras: ArrayLike, regions: Sequence | ArrayLike) -> float | np.ndarray:
    """RMS reprojection error (SPEC §1, paper eq. (6)):
    ``gamma(X) = sqrt( sum_i d(Phi(X, P_i), R_i)^2 / (2N) )`` with exact distances.

    Parameters
    ----------
    X : array_like, shape (3,) or (m, 3)
    cameras : array_like, shape (N, 3, 4)
    regions : N regions, as :func:`~tritools.model.regions.as_regions` takes them
        (:class:`~tritools.model.regions.Region` objects, dicts, 2-vectors, or an (N, 2) array of points)

    Returns
    -------
    float or ndarray (m,)
        ``inf`` where a projection is at infinity.
    """
    from .regions import as_regions

    A, single = points3d_array(X)
    if not np.all(np.isfinite(A)):
        raise ValueError("X contains NaN or inf")
    C = validate_cameras(cameras, require_distinct=False)
    R = as_regions(regions, len(C))
    out = gamma_validated(A, C, R)
    return float(out[0]) if single else out


# ----------------------------------------------------------------------------- linear triangulation
def M0(points2d, cameras) -> np.ndarray:
    """Numeric ``M0(v)`` of SPEC §3 (paper eq. (24)):
    rows ``[I2, -x_i] P_i``, i.e. ``p1_i - x_i1 p3_i`` and ``p2_i - x_i2 p3_i``.

    Returns
    -------
    ndarray, shape (2N, 4)
        ``M0 X~ = 0`` iff the ``x_i`` are exact projections of ``X`` (for finite ``X``).
    """
    C = validate_cameras(cameras, min_views=1, require_distinct=False)
    return m0_validated(points2d, C)


def m0_validated(points2d, cameras: np.ndarray) -> np.ndarray:
    """:func:`M0` for validated cameras (N, 3, 4) (the image points are still checked: shape, finite)."""
    x = validate_points2d(points2d, len(cameras))
    rows = cameras[:, :2, :] - x[:, :, None] * cameras[:, 2:3, :]
    return rows.reshape(2 * len(cameras), 4)


def m0_stack(points2d: np.ndarray, cameras: np.ndarray) -> np.ndarray:
    """The vectorised twin of :func:`m0_validated`: M0 of many image-point sets (m, N, 2) of one camera set,
    (m, 2N, 4) (the same operations per set, so the same numbers; finite points expected)."""
    x = np.asarray(points2d, float)
    rows = cameras[None, :, :2, :] - x[..., None] * cameras[None, :, 2:3, :]
    return rows.reshape(len(x), 2 * len(cameras), 4)


def _null_vector(A: np.ndarray) -> np.ndarray:
    """Unit right singular vector of the smallest singular value."""
    return np.linalg.svd(A)[2][-1]


def point_from_image_points(points2d, cameras, *, centre=...) -> np.ndarray | None:
    """Scene point from image points via the SVD of ``M0`` (SPEC §6, paper eq. (53)):
    ``w`` = last right singular vector of ``M0(v*)``, ``X^ = w[:3] / w[3]``.

    Returns
    -------
    ndarray (3,) or None
        ``None`` if ``|w4| <= POINT_AT_INFINITY_RTOL * ||w||`` (ill-posed; never divides by 0).

    When every camera has one centre (views related by homographies only), that centre is in the null space
    of ``M0`` for any image points and carries no information; the point is then taken on the ray of the
    image points instead (:func:`_point_on_common_ray`), at a distance max(1, ||C||) from the centre C.
    ``centre``: :func:`common_centre` of ``cameras`` when the caller already has it (None: there is none),
    for loops over many image points of one problem; found here by default.
    """
    cameras = validate_cameras(cameras, min_views=1, require_distinct=False)
    return point_from_validated(points2d, cameras, centre=centre)


def point_from_validated(points2d, cameras: np.ndarray, *, centre=...) -> np.ndarray | None:
    """:func:`point_from_image_points` for validated cameras (N, 3, 4) (a loop over many image points of one
    problem: the cameras are not checked again)."""
    w = _null_vector(m0_validated(points2d, cameras))
    return _point_from_null(w, points2d, cameras, centre)


def points_from_validated(points2d: np.ndarray, cameras: np.ndarray, *, centre=...) -> np.ndarray:
    """The vectorised twin of :func:`point_from_validated`: points (m, 3) of image-point sets (m, N, 2), a row of
    NaN where it gives None or the set is not finite (one stacked SVD; the rows are the scalar path's numbers)."""
    x = np.asarray(points2d, float)
    out = np.full((len(x), 3), np.nan)
    fin = np.nonzero(np.isfinite(x).all(axis=(1, 2)))[0]
    with np.errstate(over="ignore", invalid="ignore"):
        M = m0_stack(x[fin], cameras)
    keep = np.isfinite(M).all(axis=(1, 2))           # (an overflowing M0: the scalar SVD raises, no point)
    fin, M = fin[keep], M[keep]
    if not fin.size:
        return out
    W = np.linalg.svd(M)[2][:, -1]
    C = common_centre(cameras) if centre is ... else centre
    for k, w in zip(fin, W):
        X = _point_from_null(w, x[k], cameras, C)
        if X is not None:
            out[k] = X
    return out


def _point_from_null(w: np.ndarray, points2d, cameras: np.ndarray, centre) -> np.ndarray | None:
    """The point of :func:`point_from_image_points` from the null vector ``w`` of M0 (its docstring)."""
    if abs(w[3]) <= POINT_AT_INFINITY_RTOL * np.linalg.norm(w):
        return None
    C = common_centre(cameras) if centre is ... else centre
    if C is None:
        return w[:3] / w[3]
    X = w[:3] / w[3]
    if _is_common_centre(w, cameras) or not np.linalg.norm(X - C) > 0:
        return _point_on_common_ray(C, np.asarray(points2d, float).reshape(-1, 2), cameras)
    return on_common_ray(X, C, cameras)


def on_common_ray(X: np.ndarray, C: np.ndarray, cameras: np.ndarray | None = None) -> np.ndarray:
    """The point of the line through the common centre C and X at distance max(1, ||C||) from C: every point
    of the line has the same projections (C + t d and C - t d too), and near C they are round-off (1e-6 px
    at 6e-8 from it).  With ``cameras``, the side in front of most of them (the first camera breaks ties)."""
    d = (X - C) / np.linalg.norm(X - C)
    Y = C + max(1.0, float(np.linalg.norm(C))) * d
    if cameras is not None:
        s = np.sign(depths(Y, cameras))
        if np.sum(s) < 0 or (np.sum(s) == 0 and s[0] < 0):
            Y = C - max(1.0, float(np.linalg.norm(C))) * d
    return Y


def _is_common_centre(w: np.ndarray, cameras: np.ndarray) -> bool:
    """Whether P_i w = 0 to round-off (``COMMON_CENTRE_RTOL``, componentwise) for every camera."""
    scale = np.abs(cameras) @ np.abs(w)                       # (N, 3): bounds of each row's round-off / eps
    return bool(np.all(np.abs(cameras @ w) <= COMMON_CENTRE_RTOL * np.max(scale, axis=1, keepdims=True)))


def _point_on_common_ray(C: np.ndarray, x: np.ndarray, cameras: np.ndarray) -> np.ndarray | None:
    # (used when the SVD's point is the centre itself)
    """C + t d with d the direction minimising sum_i ||x~_i x (M_i d)||^2 (|d| = 1, M_i = P_i[:, :3]), oriented in
    front of the first camera, and t = max(1, ||C||): every point of that ray has the same projections."""
    rows = []
    for xi, P in zip(x, cameras):
        xt = np.array([xi[0], xi[1], 1.0])
        skew = np.array([[0.0, -xt[2], xt[1]], [xt[2], 0.0, -xt[0]], [-xt[1], xt[0], 0.0]])
        M = P[:, :3]
        rows.append(skew @ (M / np.linalg.norm(M)))
    d = np.linalg.svd(np.vstack(rows))[2][-1]
    M0_ = cameras[0][:, :3]
    if (M0_ @ d)[2] * np.linalg.det(M0_) < 0:
        d = -d
    X = C + max(1.0, float(np.linalg.norm(C))) * d
    return X if np.all(np.isfinite(X)) else None


def _hartley_normalisation(x: np.ndarray) -> np.ndarray:
    """Similarity T (3x3) moving the centroid of x (N, 2) to 0 and the mean distance to sqrt(2)."""
    c = x.mean(axis=0)
    dist = np.hypot(x[:, 0] - c[0], x[:, 1] - c[1]).mean()
    if dist <= 1e-12 * (1.0 + np.abs(c).max()):
        s = 1.0 / (1.0 + np.abs(c).max())
    else:
        s = np.sqrt(2.0) / dist
    return np.array([[s, 0.0, -s * c[0]], [0.0, s, -s * c[1]], [0.0, 0.0, 1.0]])


def dlt(cameras: ArrayLike, points2d: ArrayLike) -> np.ndarray:
    """Linear (algebraic-error) triangulation, Hartley & Zisserman §12.2.

    Image points are normalised by one similarity ``T`` (centroid 0, mean distance
    sqrt(2)) applied to all views (``x' = T x~``, ``P' = T P``), each row of
    ``M0`` is scaled to unit norm, and ``X~`` is the last right singular vector.

    Returns
    -------
    ndarray, shape (3,)

    Raises
    ------
    PointAtInfinityError
        If ``|w4| <= POINT_AT_INFINITY_RTOL`` (the solution is a point at infinity).
    ValueError
        Bad shapes or values.
    """
    C = validate_cameras(cameras, require_distinct=False)
    x = validate_points2d(points2d, len(C))
    T = _hartley_normalisation(x)
    xn = x @ T[:2, :2].T + T[:2, 2]
    Cn = np.einsum("ab,nbc->nac", T, C / power2_scale(C, (1, 2)))      # per-camera scale: no effect after row scaling
    A = (Cn[:, :2, :] - xn[:, :, None] * Cn[:, 2:3, :]).reshape(-1, 4)
    A = unit_rows(A)[0]
    w = _null_vector(A)
    if abs(w[3]) <= POINT_AT_INFINITY_RTOL:
        raise PointAtInfinityError(
            f"linear triangulation gives a point at infinity (|w4| = {abs(w[3]):.3g}): ill-posed problem")
    return w[:3] / w[3]


# ----------------------------------------------------------------------------- epipolar geometry
def _skew(e: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -e[2], e[1]], [e[2], 0.0, -e[0]], [-e[1], e[0], 0.0]])


def fundamental_matrix(P_i: ArrayLike, P_j: ArrayLike, normalize: bool = True) -> np.ndarray:
    """Fundamental matrix ``F_ij = [e]_x P_i P_j^+`` with ``e = P_i a_j``, ``P_j a_j = 0``,
    ``||a_j|| = 1`` (SPEC §7; Hartley & Zisserman eq. (9.1)).

    It satisfies ``x~_i' F_ij x~_j = 0`` for exact projections ``x_i = Phi(X, P_i)``,
    ``x_j = Phi(X, P_j)`` (paper eq. (61)).  ``F_ji`` is proportional to ``F_ij'``.

    Parameters
    ----------
    normalize : bool
        Scale to unit Frobenius norm (the sign is arbitrary).

    The cameras are divided by powers of two ``k_i, k_j`` near their largest entries first
    (``F(k_i P_i, k_j P_j) = k_i^2 / k_j F(P_i, P_j)`` exactly), so no product overflows.

    Raises
    ------
    ValueError
        Bad cameras (:func:`validate_cameras`' rule), or coincident camera centres
        (``||F||_F <= SAME_CENTER_RTOL ||P_i|| ||P_j||`` for the scaled cameras: ``F`` vanishes).
    """
    Pi = real_array(P_i, "P_i")
    Pj = real_array(P_j, "P_j")
    check_camera(Pi, "P_i")
    check_camera(Pj, "P_j")
    ki, kj = power2_scale(Pi, (0, 1)).item(), power2_scale(Pj, (0, 1)).item()
    Pi, Pj = Pi / ki, Pj / kj
    a = _null_vector(Pj)
    e = Pi @ a
    F = _skew(e) @ Pi @ np.linalg.pinv(Pj)
    nrm = np.linalg.norm(F)
    if nrm <= SAME_CENTER_RTOL * np.linalg.norm(Pi) * np.linalg.norm(Pj):
        raise ValueError("P_i and P_j share the same camera centre: the fundamental matrix is undefined")
    return F / nrm if normalize else F * (ki * ki / kj)


def fundamental_matrices(cameras, normalize: bool = True, *,
                         skip_coincident: bool = False) -> dict[tuple[int, int], np.ndarray]:
    """``{(i, j): F_ij for i < j}`` (0-based view indices), see :func:`fundamental_matrix`.

    Parameters
    ----------
    skip_coincident : bool
        Leave out the pairs whose camera centres coincide (a repeated view: valid input,
        but its epipolar constraint is undefined) instead of raising.

    Raises
    ------
    ValueError
        Bad cameras; coincident centres of views i and j (``"cameras i and j: ..."``) unless
        ``skip_coincident``.
    """
    C = validate_cameras(cameras, require_distinct=False)
    out = {}
    for i, j in itertools.combinations(range(len(C)), 2):
        try:
            out[(i, j)] = fundamental_matrix(C[i], C[j], normalize=normalize)
        except ValueError as exc:
            if skip_coincident:
                continue
            raise ValueError(f"cameras {i} and {j}: {exc}") from None
    return out


def refine_l2(X0, cameras, regions, *, xtol: float = 1e-15, ftol: float = 1e-15, gtol: float = 1e-15,
              max_nfev: int = 400) -> np.ndarray | None:
    """Local minimisation of gamma (SPEC §1) from X0 by Levenberg-Marquardt on the residuals
    x_i - closest point of R_i (scipy's least_squares with these stopping tolerances; the residuals vectorised
    and their Jacobian analytic for point and disc regions, :mod:`tritools.model.refine`); None when the solver
    fails or leaves the finite numbers.  Past the active deadline it makes at most
    :func:`tritools.model.refine.evaluations_after` more evaluations, then returns its best iterate (any X is a
    valid estimate)."""
    from scipy.optimize import least_squares

    if disc_shapes(regions) is None:
        regions = RegionStack.of(regions)        # one stack for the residuals and the Jacobian (its closest points)
    fun, vectorised = residual_function(cameras, regions)
    guard = EvaluationGuard(fun, evaluations_after(len(regions), vectorised), evaluations_floor(vectorised),
                            early=not vectorised)
    try:
        X = least_squares(guard, np.asarray(X0, float), jac=residual_jacobian(cameras, regions), method="lm",
                          xtol=xtol, ftol=ftol, gtol=gtol, max_nfev=max_nfev).x
    except RefinementStopped:
        X = guard.best_X
    except (ValueError, np.linalg.LinAlgError):
        return None
    if X is None or not np.all(np.isfinite(X)):
        return None
    C = common_centre(np.asarray(cameras, float))
    if C is not None and np.linalg.norm(X - C) > 0:
        X = on_common_ray(X, C, np.asarray(cameras, float))    # LM may slide along the ray towards the centre
    return X


def common_centre(cameras: np.ndarray) -> np.ndarray | None:
    """The camera centre shared by every view (views related by homographies only), or None: P_i C~ = 0 to
    round-off (``COMMON_CENTRE_RTOL``) for every camera, with C~ the null vector of the first camera."""
    cameras = np.asarray(cameras, float)
    if cameras.ndim != 3 or len(cameras) < 2:
        return None
    w = _null_vector(cameras[0])
    if abs(w[3]) <= POINT_AT_INFINITY_RTOL * np.linalg.norm(w) or not _is_common_centre(w, cameras):
        return None
    return w[:3] / w[3]
