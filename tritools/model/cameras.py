"""Camera checks and camera-side geometry: the rank rule (computed in :mod:`tritools.model.camera_rank`), centres,
depths (scalar and vectorised twins).

Camera check
------------
:func:`validate_cameras` (one problem, errors with messages) and :func:`camera_problems`
(a stack of problems, a mask and reason codes) apply the same rule, computed by the same
vectorised functions (:func:`camera_rank_ratio`, :func:`cameras_all_equal`):

1. every entry is finite;
2. every camera has rank 3, tested on a conditioned copy (:func:`camera_rank_ratio`) and on its conditioned
   left 3 x 3 block (rank 3 there is sufficient; it is what a georeferenced camera, whose fourth column
   dominates every row, passes):
   the camera is divided by its largest absolute entry (no overflow, whatever its scale),
   rows 1 and 2 are replaced by their components orthogonal to row 3 (left multiplication
   by an image translation ``[[1, 0, -a], [0, 1, -b], [0, 0, 1]]``), and each row is scaled
   to unit norm (an image scaling).  These are invertible left factors: they change neither
   the rank, nor the centre, nor the geometry of the camera (the image is only translated
   and scaled).  They remove what makes a perfectly good pixel camera look nearly singular:
   ``K = [[1e3, 0, 1e6], [0, 1e3, 1e6], [0, 0, 1]]`` gives rows 1 and 2 that are ~1e3 times
   row 3 plus a small part, and sigma_3 / sigma_1 ~ 5e-11 before conditioning, ~1 after.
   The rank is 3 iff ``sigma_3 / sigma_1 > CAMERA_RANK_RTOL`` of the conditioned matrix or of its block;
   a row whose component orthogonal to row 3 is at most ``CAMERA_RANK_RTOL`` of its norm
   counts as zero (it is a multiple of row 3 to that precision);
3. (optional) the cameras are not all equal up to a (possibly negative) scale factor, the
   one ill-posed configuration of the problem; each camera is divided by its largest
   entry before its Frobenius norm is taken, so no norm overflows.  Views sharing a centre
   (a repeated view, a camera rotated about its centre) are valid input.

Depth and the world frame
-------------------------
:func:`depths` (and its vectorised twin :func:`depths_stack`, the same rows from
:func:`depth_rows`) is Hartley & Zisserman's eq. (6.15),
``depth(X; P) = h sign(det M) w / (||m3|| T)`` for ``P X = w (x, y, 1)``, ``X = (X, Y, Z, T)``:
invariant under ``P -> k P`` for every k != 0 (``P`` and ``-P`` are the same camera) and
positive in front of the camera.  ``h`` is the handedness of the world frame,
:class:`WorldFrame`: +1 for a right-handed frame (``P = K [R | t]``, det R = +1, every SfM
package), -1 for a *reflected* one (det R = -1), in which every depth of eq. (6.15) changes
sign.  The handedness is a property of the whole reconstruction, not of one camera: a
reflected frame puts a real scene behind every camera by eq. (6.15) (the Oxford corridor and
house sequences: every camera has det M < 0 and w > 0).  :func:`world_frame_of` reads it
off a reconstruction's own points.  Every cheirality judgement (``in_front``, status
``behind_camera``, the re-triangulation's keep-the-input rule) goes through these functions.
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike


from sospoly import pow2_above

from .camera_rank import (CAMERA_RANK_RTOL, EXACT_RANK_BELOW, SHARED_MIN_CAMERAS,  # noqa: F401 (re-exported)
                          camera_rank_ratio, checked_rank_ratio, exactly_rank_deficient, power2_scale,
                          rank_ratio_scalar, shared_rank_ratio, unit_rows)
from ..result import IllPosedError
from .regions.base import real_array

__all__ = ["depth_rows", "depth_row_one", "numeric_cameras",
           "CAMERA_RANK_RTOL",
           "SAME_CAMERA_RTOL", "POINT_AT_INFINITY_RTOL", "CameraIssue", "CameraProblems",
           "camera_rank_ratio", "cameras_all_equal", "check_camera", "validate_cameras", "camera_refusal",
           "camera_problems",
           "camera_center", "depths", "depths_stack", "power2_scale", "points3d_array", "unit_rows", "WorldFrame",
           "as_world_frame", "world_frame_of"]


class WorldFrame(str, enum.Enum):
    """Handedness of the world frame, the factor ``h`` of the depth ``h sign(det M) w / (||m3|| T)``."""

    RIGHT_HANDED = "right_handed"      # h = +1: P = K [R | t] with det R = +1 (COLMAP, OpenCV, H&Z)
    REFLECTED = "reflected"            # h = -1: a mirrored world (det R = -1), e.g. Oxford corridor / house

    @property
    def sign(self) -> float:
        return -1.0 if self is WorldFrame.REFLECTED else 1.0


def as_world_frame(value, name: str = "world_frame") -> WorldFrame:
    """A :class:`WorldFrame` from itself or its value (``"right_handed"``, ``"reflected"``); ValueError naming
    ``name`` otherwise."""
    try:
        return WorldFrame(getattr(value, "value", value))
    except ValueError:
        raise ValueError(f"{name} must be one of {', '.join(repr(w.value) for w in WorldFrame)}, "
                         f"got {value!r}") from None


#: Two cameras are "equal up to scale" if ``min_{s=+-1} ||P_i/||P_i|| - s P_j/||P_j||||_F`` is below this.
SAME_CAMERA_RTOL = 1e-10


#: A homogeneous solution ``w`` (unit norm) is a point at infinity if ``|w4| <= POINT_AT_INFINITY_RTOL``.
#: With unit-scale data this rejects estimates farther than ~1e10 from the origin.
POINT_AT_INFINITY_RTOL = 1e-10


class CameraIssue(enum.IntEnum):
    """Why :func:`camera_problems` refuses a problem (the first check that fails)."""

    OK = 0
    NOT_FINITE = 1
    RANK = 2
    ALL_EQUAL = 3


@dataclass(frozen=True)
class CameraProblems:
    """Result of :func:`camera_problems` for M problems.

    Attributes
    ----------
    valid : ndarray of bool, shape (M,)
        The problem's cameras pass :func:`validate_cameras`.
    reason : ndarray of int8, shape (M,)
        :class:`CameraIssue` code of the first failing check (0 = OK).
    view : ndarray of int, shape (M,)
        The first offending view for NOT_FINITE and RANK, -1 otherwise.
    """

    valid: np.ndarray
    reason: np.ndarray
    view: np.ndarray


def cameras_all_equal(cameras) -> np.ndarray:
    """Whether all cameras of each problem are equal up to a (possibly negative) scale factor.

    Each camera is divided by its largest absolute entry, then by its Frobenius norm (so no
    norm overflows or underflows); the cameras are all equal if
    ``min_{s = +-1} ||U_i - s U_0||_F <= SAME_CAMERA_RTOL`` for every view i.

    Parameters
    ----------
    cameras : array_like, shape (..., N, 3, 4), finite

    Returns
    -------
    ndarray of bool, shape (...)
        True for N = 1.
    """
    C = real_array(cameras, "cameras")
    if C.ndim < 3 or C.shape[-2:] != (3, 4):
        raise ValueError(f"cameras must have shape (..., N, 3, 4), got {C.shape}")
    return _all_equal(C)


def _all_equal(C: np.ndarray) -> np.ndarray:
    """:func:`cameras_all_equal` of a finite float array (..., N, 3, 4) already checked."""
    U = C / power2_scale(C, (-2, -1))
    n = np.sqrt(np.sum(U * U, axis=(-2, -1), keepdims=True))
    U = U / np.where(n > 0, n, 1.0)
    U0 = U[..., :1, :, :]
    minus = np.sqrt(np.sum((U - U0) ** 2, axis=(-2, -1)))
    plus = np.sqrt(np.sum((U + U0) ** 2, axis=(-2, -1)))
    return np.all(np.minimum(minus, plus) <= SAME_CAMERA_RTOL, axis=-1)


def _rank_message(name: str, ratio: float) -> str:
    return (f"{name} has rank < 3: sigma3/sigma1 = {ratio:.3g} <= CAMERA_RANK_RTOL = {CAMERA_RANK_RTOL:g} "
            f"after conditioning (rows 1, 2 made orthogonal to row 3, every row scaled to unit norm)")


def check_camera(P: np.ndarray, name: str) -> None:
    """One camera: shape (3, 4), finite, rank 3 by the conditioned rule (ValueError naming ``name``)."""
    if P.shape != (3, 4):
        raise ValueError(f"{name} must be a 3x4 matrix, got shape {P.shape}")
    if not np.all(np.isfinite(P)):
        raise ValueError(f"{name} contains NaN or inf")
    ratio = float(camera_rank_ratio(P))
    if not ratio > CAMERA_RANK_RTOL:
        raise ValueError(_rank_message(name, ratio))


def validate_cameras(cameras: ArrayLike, *, min_views: int = 2, require_distinct: bool = True) -> np.ndarray:
    """Check and convert projection matrices (the rule is in the module docstring).

    Parameters
    ----------
    cameras : array_like, shape (N, 3, 4)
        Projection matrices ``P_i`` (paper eq. (2)), real numbers of any finite scale.
    min_views : int
        Minimum number of views (2 for triangulation).
    require_distinct : bool
        If true, reject the ill-posed input where all cameras are equal up to a
        (possibly negative) scale factor (:func:`cameras_all_equal`).

    Returns
    -------
    ndarray, shape (N, 3, 4)
        A float copy.

    Raises
    ------
    ValueError
        Not real numbers (``"cameras must be real numbers, got complex128"``), wrong shape,
        NaN/inf, rank < 3 after conditioning (:func:`camera_rank_ratio`), fewer than
        ``min_views`` views, all cameras equal.  :func:`camera_problems` is the vectorised
        twin for stacks of problems.
    """
    C = real_array(cameras, "cameras")
    if C.ndim != 3 or C.shape[1:] != (3, 4):
        raise ValueError(f"cameras must have shape (N, 3, 4), got {C.shape}")
    if C.shape[0] < min_views:
        raise ValueError(f"cameras: at least {min_views} views are needed, got {C.shape[0]}")
    finite = np.isfinite(C).all(axis=(1, 2))
    if not finite.all():
        raise ValueError(f"cameras[{int(np.argmin(finite))}] contains NaN or inf")
    few = C.shape[0] <= SCALAR_MAX_VIEWS          # a single call's few cameras: the scalar twins (plain floats)
    ratio = rank_ratio_scalar(C, decide_only=True) if few else checked_rank_ratio(C)
    for i, r in enumerate(ratio):
        if not r > CAMERA_RANK_RTOL:
            raise ValueError(_rank_message(f"cameras[{i}]", float(r)))
    if require_distinct and C.shape[0] >= 2 and (_all_equal_scalar(C) if few else _all_equal(C)):
        raise IllPosedError(f"cameras are all equal up to scale (unit-norm cameras within {SAME_CAMERA_RTOL:g} of "
                            "each other): the triangulation is ill-posed")
    return C


def camera_refusal(cameras) -> str | None:
    """:func:`validate_cameras`' message for ``cameras`` (no minimum number of views, equal cameras allowed), None
    when it accepts them."""
    try:
        validate_cameras(cameras, min_views=1, require_distinct=False)
    except ValueError as exc:
        return str(exc)
    return None


#: :func:`validate_cameras` checks up to this many cameras with the scalar twins of the rank and equality rules.
SCALAR_MAX_VIEWS = 8


def _all_equal_scalar(C: np.ndarray) -> bool:
    """The scalar twin of :func:`_all_equal` for one problem's finite cameras (N, 3, 4), stopping at the first
    camera that differs from the first."""
    units = []
    for P in C.tolist():
        flat = [v for row in P for v in row]
        k = pow2_above(max(abs(v) for v in flat))
        flat = [v / k for v in flat]
        n = math.sqrt(sum(v * v for v in flat))
        U = [v / n for v in flat] if n > 0 else flat
        if units:
            U0 = units[0]
            minus = math.sqrt(sum((a - b) ** 2 for a, b in zip(U, U0)))
            plus = math.sqrt(sum((a + b) ** 2 for a, b in zip(U, U0)))
            if not min(minus, plus) <= SAME_CAMERA_RTOL:
                return False
        units.append(U)
    return True


def camera_problems(cameras, *, require_distinct: bool = True) -> CameraProblems:
    """:func:`validate_cameras` for a stack of M problems, without exceptions, in numpy over the stack.

    Parameters
    ----------
    cameras : array_like, shape (M, N, 3, 4)
    require_distinct : bool
        As in :func:`validate_cameras` (only for N >= 2).

    Returns
    -------
    CameraProblems
        ``valid[m]`` is true iff ``validate_cameras(cameras[m], min_views=1,
        require_distinct=require_distinct)`` accepts problem m; ``reason`` and ``view`` say
        which check failed first (the order of :func:`validate_cameras`).

    Raises
    ------
    ValueError
        Not real numbers or not of shape (M, N, 3, 4).
    """
    C = real_array(cameras, "cameras")
    if C.ndim != 4 or C.shape[2:] != (3, 4):
        raise ValueError(f"cameras must have shape (M, N, 3, 4), got {C.shape}")
    M, N = C.shape[:2]
    bad_finite = ~np.all(np.isfinite(C), axis=(2, 3))                          # (M, N)
    bad_rank = ~(shared_rank_ratio(C) > CAMERA_RANK_RTOL) & ~bad_finite       # NaN ratio -> not finite
    any_finite, any_rank = bad_finite.any(axis=1), bad_rank.any(axis=1)
    equal = np.zeros(M, dtype=bool)
    if require_distinct and N >= 2:
        equal = cameras_all_equal(np.where(bad_finite[..., None, None], 0.0, C)) & ~any_finite & ~any_rank
    reason = np.full(M, CameraIssue.OK, dtype=np.int8)
    reason[equal] = CameraIssue.ALL_EQUAL
    reason[any_rank] = CameraIssue.RANK
    reason[any_finite] = CameraIssue.NOT_FINITE
    view = np.where(any_finite, np.argmax(bad_finite, axis=1), np.where(any_rank, np.argmax(bad_rank, axis=1), -1))
    return CameraProblems(valid=reason == CameraIssue.OK, reason=reason, view=view)


def numeric_cameras(cams) -> np.ndarray | None:
    """``cams`` as a float array when it holds real numbers (no complex, object or string data), else None:
    the batch paths' test of whether an item can join a vectorised stack (anything else goes through the
    per-point path and its named errors)."""
    try:
        C = np.asarray(cams)
        if not np.issubdtype(C.dtype, np.number) or np.iscomplexobj(C):
            return None
        return C.astype(float)
    except (TypeError, ValueError):
        return None


def points3d_array(X, name: str = "X") -> tuple[np.ndarray, bool]:
    A = real_array(X, name)
    if A.shape == (3,):
        return A[None, :], True
    if A.ndim == 2 and A.shape[1] == 3:
        return A, False
    raise ValueError(f"{name} must have shape (3,) or (m, 3), got {A.shape}")


def camera_center(P, homogeneous: bool = False) -> np.ndarray:
    """Centre of projection: the null vector ``a`` of ``P`` (``P a = 0``).

    Parameters
    ----------
    P : array_like, shape (3, 4)
    homogeneous : bool
        Return the unit 4-vector ``a`` instead of ``a[:3] / a[3]``.

    Raises
    ------
    ValueError
        Bad ``P``, or a centre at infinity (affine camera) when ``homogeneous`` is false.
    """
    P = real_array(P, "P")
    check_camera(P, "P")
    a = np.linalg.svd(P / power2_scale(P, (0, 1)))[2][-1]
    if homogeneous:
        return a
    if abs(a[3]) <= POINT_AT_INFINITY_RTOL:
        raise ValueError("P has its centre at infinity (affine camera); use homogeneous=True")
    return a[:3] / a[3]


def depth_rows(C: np.ndarray) -> np.ndarray:
    """``sign(det M) p3 / ||m3||`` for cameras (..., 3, 4) -> (..., 4), so that depth = row . X~.

    Each camera is divided by a power of two near its largest entry first (the depth does not
    change under ``P -> k P``, k > 0), and ``||m3||`` is taken without overflow or underflow.
    NaN rows for cameras with ``m3 = 0`` (depth undefined) or non-finite entries.  A few finite cameras (N, 3, 4),
    at most ``SCALAR_MAX_VIEWS``: :func:`depth_row_one` each, the same bits without the array calls.
    """
    if C.ndim == 3 and len(C) <= SCALAR_MAX_VIEWS and np.isfinite(C).all():
        return np.array([depth_row_one(P) for P in C.tolist()]).reshape(C.shape[0], 4)
    Cs = C / power2_scale(C, (-2, -1))
    m3 = Cs[..., 2, :3]
    k = power2_scale(m3, (-1,))[..., 0]
    n = k * np.sqrt(np.sum((m3 / k[..., None]) ** 2, axis=-1))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):   # (LAPACK's warnings on extreme rows)
        sign = np.sign(np.linalg.det(Cs[..., :3]))
    sign = np.where(sign == 0, 1.0, sign)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        f = np.where(n > 0, sign / np.where(n > 0, n, 1.0), np.nan)
    return Cs[..., 2, :] * f[..., None]


def depth_row_one(P: list) -> list:
    """The scalar twin of :func:`depth_rows` for one finite camera (3 lists of 4 floats): the same operations on
    floats, equal bit for bit (tests/test_wave48.py); the sign of det M from its cofactor expansion where that
    is far from round-off (relative 1e-8 of |m1| |m2| |m3|), from ``numpy.linalg.det`` (the stacked code's) else."""
    k0 = pow2_above(max(abs(v) for row in P for v in row))
    Cs = [[v / k0 for v in row] for row in P]
    m3 = Cs[2][:3]
    k = pow2_above(max(abs(v) for v in m3))
    t = [v / k for v in m3]
    n = k * math.sqrt((t[0] * t[0] + t[1] * t[1]) + t[2] * t[2])
    (a, b, c, _), (d, e, f, _), (g, h, i, _) = Cs
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    scale = math.sqrt((a * a + b * b) + c * c) * math.sqrt((d * d + e * e) + f * f) * n
    if not (abs(det) > 1e-8 * scale and math.isfinite(det)):
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            det = float(np.linalg.det(np.array([row[:3] for row in Cs])))
    sign = 1.0 if det > 0 or det == 0 else (-1.0 if det < 0 else math.nan)
    if not n > 0:
        return [math.nan] * 4
    f_ = sign / n
    return [v * f_ for v in Cs[2]]


def depths(X: ArrayLike, cameras: ArrayLike, world_frame: WorldFrame | str = WorldFrame.RIGHT_HANDED) -> np.ndarray:
    """Depth of ``X`` in each camera (Hartley & Zisserman eq. (6.15)):
    ``depth = h sign(det M) (p3.X~) / ||m3||``, ``M`` the left 3x3 block of ``P``,
    ``m3`` its third row, ``h = world_frame.sign`` (see the module docstring); invariant to
    ``P -> k P`` for every k != 0; positive in front of the camera.
    For ``P = K [R | t]`` with ``det K > 0`` and ``det R = +1`` it is the third coordinate of ``R X + t``.

    Returns
    -------
    ndarray, shape (N,) for ``X`` of shape (3,), (m, N) for (m, 3).
        NaN for a camera with ``m3 = 0`` (an affine camera: no depth).

    Raises
    ------
    ValueError
        Bad ``X`` or cameras (:func:`validate_cameras` with ``min_views=1``, distinctness not required).
    """
    h = as_world_frame(world_frame).sign
    A, single = points3d_array(X)
    C = validate_cameras(cameras, min_views=1, require_distinct=False)
    Xh = np.hstack([A, np.ones((len(A), 1))])
    with np.errstate(over="ignore", invalid="ignore"):
        out = h * np.einsum("mj,nj->mn", Xh, depth_rows(C))
    return out[0] if single else out


def depths_validated(X: np.ndarray, cameras: np.ndarray, world_frame: WorldFrame | str = WorldFrame.RIGHT_HANDED
                     ) -> np.ndarray:
    """:func:`depths` of one point X (3,) for cameras (N, 3, 4) already validated (:func:`validate_cameras`) and
    converted to float: the same numbers without checking the cameras again."""
    h = as_world_frame(world_frame).sign
    Xh = np.hstack([np.asarray(X, float)[None], np.ones((1, 1))])
    with np.errstate(over="ignore", invalid="ignore"):
        return (h * np.einsum("mj,nj->mn", Xh, depth_rows(cameras)))[0]


def depths_stack(cameras: ArrayLike, X: ArrayLike,
                 world_frame: WorldFrame | str = WorldFrame.RIGHT_HANDED) -> np.ndarray:
    """:func:`depths` for M problems at once: cameras (M, N, 3, 4), X (M, 3) -> (M, N), the depth
    of ``X[m]`` in camera ``cameras[m, i]`` (same formula, numpy over the stack).

    The cameras are not validated (use :func:`camera_problems`): non-finite data give NaN.

    Raises
    ------
    ValueError
        Not real numbers, or shapes other than (M, N, 3, 4) and (M, 3).
    """
    C = real_array(cameras, "cameras")
    A = real_array(X, "X")
    if C.ndim != 4 or C.shape[2:] != (3, 4):
        raise ValueError(f"cameras must have shape (M, N, 3, 4), got {C.shape}")
    if A.shape != (C.shape[0], 3):
        raise ValueError(f"X must have shape ({C.shape[0]}, 3), one point per problem, got {A.shape}")
    return depths_stack_arrays(C, A, world_frame)


def depths_stack_arrays(C: np.ndarray, X: np.ndarray, world_frame: WorldFrame | str = WorldFrame.RIGHT_HANDED
                        ) -> np.ndarray:
    """:func:`depths_stack` of float arrays C (M, N, 3, 4) and X (M, 3) whose shapes are known to be right (the
    vectorised report): the formula without the checks."""
    h = as_world_frame(world_frame).sign
    Xh = np.concatenate([X, np.ones((len(X), 1))], axis=1)
    with np.errstate(over="ignore", invalid="ignore"):
        return h * np.einsum("mj,mnj->mn", Xh, depth_rows(C))


def world_frame_of(cameras: ArrayLike, X: ArrayLike) -> WorldFrame:
    """The handedness of a reconstruction's world frame, read off its own points: REFLECTED when most
    finite right-handed depths (eq. (6.15)) of the pairs (``X[m]``, ``cameras[m, i]``) are negative (a real
    scene lies in front of the cameras that see it; only a mirrored frame puts it behind them).

    ``cameras`` (M, N, 3, 4) and ``X`` (M, 3) as for :func:`depths_stack` (e.g. each track's cameras and
    its DLT point); ValueError when no depth is finite and non-zero (nothing to decide from).
    """
    d = depths_stack(cameras, X)
    d = d[np.isfinite(d) & (d != 0)]
    if not d.size:
        raise ValueError("world_frame_of: no finite non-zero depth to read the frame's handedness from")
    return WorldFrame.REFLECTED if np.count_nonzero(d < 0) > d.size / 2 else WorldFrame.RIGHT_HANDED
