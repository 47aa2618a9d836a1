"""What a result reports about an estimate X, in the caller's units: gamma(X) on the original data, the
per-view residuals d(Phi(X, P_i), R_i) and depths -- scalar (:func:`point_report`, any regions) and
vectorised for point regions (:func:`points_report_stack`), tested equal -- and the radius of a ball that
holds a minimiser of the normalised program (:func:`solve_radius`, for rigorous lower bounds)."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..model.cameras import depths_stack_arrays, depths_validated
from ..model.exact import HOMOGENEOUS_RTOL
from ..model.frame import project_world, project_world_one, project_world_views
from ..model.geometry import WorldFrame, project_point_views
from ..model.refine import disc_shapes
from ..model.regions import RegionStack, extent_of
from ..model.stacked import norms

__all__ = ["PointReport", "point_report", "points_report_stack", "solve_radius", "solve_ball", "region_extent",
           "gamma_upper", "rounding_spread", "projections_and_spread", "projections_and_spread_one",
           "projections_and_spread_views", "projections_and_spread_stack"]

_U = 2.0 ** -53                   # the unit round-off of float64
#: |u~_i - u_i| <= _PROJ_ABS |u_i|: the quotient of two homogeneous coordinates with relative error HOMOGENEOUS_RTOL
#: each, then rounded, then the difference with x_i (its own rounding is in the (1 + 4u) factor)
_PROJ_ABS = 2 * HOMOGENEOUS_RTOL + 4 * _U


def gamma_upper(res, u_norm, cap=None):
    """gamma_UB: gamma of the exact distances at the float estimate X, rounded up -- the distances ``res`` (..., N)
    computed from projections u_i of norm ``u_norm`` (..., N) whose homogeneous images err by at most
    ``HOMOGENEOUS_RTOL`` relative (:func:`tritools.model.exact.homogeneous_images`, used by
    :func:`tritools.model.frame.project_world` and :func:`tritools.model.geometry.project_homogeneous`).  The
    quotient u_i = h_i / h_i3 and the difference u_i - x_i then err by at most ``_PROJ_ABS`` |u_i| + u d_i
    (_PROJ_ABS = 2 HOMOGENEOUS_RTOL + 4u, ~6e-14), a distance to a region is 1-Lipschitz in u_i, and the norm adds
    2u relative: d_i <= d~_i (1 + 4u) + _PROJ_ABS |u_i|; the sum of N squares and the square root are rounded up by
    (1 + (N + 4) u) and (1 + 4u).  So gamma(X) <= gamma_UB for the exact distances of the float data (point regions;
    for other regions up to their own distance round-off): ~6e-11 px above the float value at 1000 px coordinates.
    A distance computed as 0 gets the margin too (a float projection on its observed point may be that far from
    the exact one), so gamma_UB > 0 even at zero noise.  inf where a distance is not finite.
    ``cap`` (N,): truncated distances min(d_i, c_i) (the TLS cost of issue #19; inf: not truncated)."""
    res = np.asarray(res, float)
    n = res.shape[-1]
    with np.errstate(invalid="ignore", over="ignore"):
        d = enlarged_distances(res, u_norm)
        if cap is not None:
            d = np.minimum(d, cap)
        f = np.sum(d * d, axis=-1) * (1.0 + (n + 4) * _U)
        g = np.where(np.isfinite(f), np.sqrt(f / (2.0 * n)) * (1.0 + 4 * _U), np.inf)
    return g.item() if g.ndim == 0 else g


def enlarged_distances(res, u_norm) -> np.ndarray:
    """Upper bounds of the exact distances: the float distances ``res`` (..., N) enlarged by their round-off bound,
    ``res (1 + 4u) + _PROJ_ABS |u_i|`` (:func:`gamma_upper`'s rule; ``u_norm`` the projections' norms)."""
    return np.asarray(res, float) * (1.0 + 4 * _U) + _PROJ_ABS * np.asarray(u_norm, float)


def rounding_spread(C: np.ndarray, X: np.ndarray) -> float:
    """How far the projections move when the float estimate X moves by one unit in the last place of each
    coordinate, as an RMS error: sqrt(sum_i max_k |u_i(X + ulp(X_k) e_k) - u_i(X)|^2 / (2N)) (pixels; compensated
    projections, :func:`tritools.model.frame.project_world`).  No float estimate locates the optimum better than
    this, so a certificate whose bounds are finer than it says nothing about the caller's problem (a point near
    the cameras' principal planes seen 1e8 px off-axis: ~0.5 px)."""
    return projections_and_spread(C, X)[2]


def projections_and_spread(C: np.ndarray, X: np.ndarray) -> tuple:
    """(u (N, 2) the compensated projections of X, defined (N,) per view, :func:`rounding_spread`): up to
    :data:`SCALAR_MAX_VIEWS` views by the scalar twin :func:`projections_and_spread_one`, else from one stacked
    projection (:func:`projections_and_spread_views`); the same numbers (:func:`projections_and_spread_stack`: M
    problems).  A view is undefined where its denominator is at round-off or its projection is not finite
    (:func:`tritools.model.frame.project_world_views`; u is then its undivided pair): the spread is taken over the
    views defined at X (a TLS cost counts an undefined view c_i^2, constant near X), and is inf where one of them is
    undefined at X + ulp(X_k) e_k."""
    if len(C) <= SCALAR_MAX_VIEWS:
        return projections_and_spread_one(C, X)
    return projections_and_spread_views(C, X)


def projections_and_spread_views(C: np.ndarray, X: np.ndarray) -> tuple:
    """:func:`projections_and_spread` of one problem from one stacked projection of X and X + ulp(|X_k|) e_k."""
    X = np.asarray(X, float)
    u, defined, spread = projections_and_spread_stack(np.asarray(C, float)[None], X[None])
    return u[0], defined[0], float(spread[0])


def projections_and_spread_stack(C: np.ndarray, X: np.ndarray) -> tuple:
    """The twin of :func:`projections_and_spread` for M problems of N views (tested equal, bit for bit): C (M, N, 3,
    4), X (M, 3) -> (u (M, N, 2), defined (M, N), spread (M,)), one stacked projection of the 4 M points X and
    X + ulp(X_k) e_k (spread inf where a view defined at X is not at X + ulp(X_k) e_k)."""
    X = np.asarray(X, float)
    M, N = C.shape[:2]
    eye = np.eye(3, dtype=bool)[None]
    Xs = np.concatenate([X[:, None], X[:, None] + np.where(eye, np.spacing(np.abs(X))[:, None, :], 0.0)], axis=1)
    Cs = np.broadcast_to(np.asarray(C, float)[:, None], (M, 4) + C.shape[1:]).reshape((4 * M,) + C.shape[1:])
    u, _, defined = project_world_views(Cs, Xs.reshape(4 * M, 3))
    u, defined = u.reshape(M, 4, N, 2), defined.reshape(M, 4, N)
    at_x = defined[:, 0]
    with np.errstate(invalid="ignore", over="ignore"):
        d2 = np.max(np.sum((u[:, 1:] - u[:, :1]) ** 2, axis=3), axis=1)
        spread = np.sqrt(np.sum(np.where(at_x, d2, 0.0), axis=1) / (2 * N))
    kept = np.all(defined[:, 1:] | ~at_x[:, None], axis=(1, 2))
    return u[:, 0], at_x, np.where(kept, spread, np.inf)


def projections_and_spread_one(C: np.ndarray, X) -> tuple:
    """The scalar twin of :func:`projections_and_spread_views` for a few views (N <= :data:`SCALAR_MAX_VIEWS`): the four
    points X and X + ulp(|X_k|) e_k projected by :func:`tritools.model.frame.project_world_one`, the spread summed
    view by view (numpy's order below 8 terms, 0 for a view undefined at X): the same numbers bit for bit
    (tests/test_single_call_twins.py)."""
    X = [float(v) for v in np.asarray(X, float)]
    Cl = C.tolist()
    absC = [[[abs(v) for v in row] for row in P] for P in Cl]
    pts = [X] + [[X[j] + (math.ulp(abs(X[j])) if j == k else 0.0) for j in range(3)] for k in range(3)]
    proj = [project_world_one(Cl, p, absC) for p in pts]
    u0, at_x = proj[0]
    total, kept = None, True
    for i, (a, b) in enumerate(u0):
        if not at_x[i]:
            d2 = 0.0
        else:
            kept = kept and all(d[i] for _, d in proj[1:])
            d2 = max((u[i][0] - a) * (u[i][0] - a) + (u[i][1] - b) * (u[i][1] - b) for u, _ in proj[1:])
        total = d2 if total is None else total + d2
    return np.array(u0), np.array(at_x, bool), math.sqrt(total / (2 * len(Cl))) if kept else math.inf


#: :func:`projections_and_spread_one` replaces the stacked projection up to this many views.
SCALAR_MAX_VIEWS = 7


@dataclass(frozen=True)
class PointReport:
    gamma: float | None          # RMS reprojection error per coordinate (inf: a projection at infinity)
    residuals: np.ndarray | None  # (N,) distances to the regions
    depths: np.ndarray | None     # (N,)


def point_report(X, cameras, regions, world_frame=WorldFrame.RIGHT_HANDED) -> PointReport:
    """gamma(X) (SPEC §1), per-view residuals and depths of ``X`` (in ``world_frame``) for validated cameras
    and regions."""
    if X is None or not np.all(np.isfinite(X)):
        return PointReport(None, None, None)
    Xh = np.append(np.asarray(X, float), 1.0)[None]
    C = np.asarray(cameras, float)
    u = project_point_views(Xh, C)                      # inf where undefined (the one rule of geometry)
    fin = np.isfinite(u).all(axis=1)
    shapes = disc_shapes(regions)
    if shapes is not None:
        res = np.where(fin, disc_distances(u, *shapes), np.inf)
    else:
        res = np.where(fin, RegionStack.of(regions).distances(np.where(fin[:, None], u, 0.0)), np.inf)
    un = np.hypot(u[:, 0], u[:, 1])
    gamma = float(gamma_upper(res, un)) if np.isfinite(res).all() else math.inf
    return PointReport(gamma, res, depths_validated(X, C, world_frame))


def disc_distances(u: np.ndarray, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Distances (..., N) of image points u (..., N, 2) to point / disc regions (centres (..., N, 2), radii (..., N):
    0 for a point): q = ||u_i - c_i|| for a point (its :meth:`~tritools.model.regions.Region.distance`, the same
    numbers; its round-off is relative to q, within :func:`gamma_upper`'s margin), and for a disc the closed form
    max(0, q - rho + 4u (q + rho)): the differences u - c and the norm err by at most 3u q, rho = sqrt(D_00) and the
    subtraction by u rho and u |q - rho|, so this bounds the exact distance of the float data from above even where
    q >> |u| (a large disc whose border passes near the projection; review 10).  NaN / inf where u is not finite."""
    q = np.hypot(u[..., 0] - centres[..., 0], u[..., 1] - centres[..., 1])
    with np.errstate(invalid="ignore"):
        disc = np.maximum(q - radii + 4 * _U * (q + radii), 0.0)
    return np.where(radii > 0, disc, q)


def points_report_stack(C: np.ndarray, x: np.ndarray, X: np.ndarray, world_frame=WorldFrame.RIGHT_HANDED):
    """The twin of :func:`point_report` for M point problems: (gamma (M,), residuals (M, N), depths (M, N));
    gamma is inf where a projection is at infinity."""
    u, _, fin = project_world(C, X)
    res = np.where(fin[:, None], norms(u - x, axis=2), np.inf)
    gamma = np.where(fin, gamma_upper(np.where(fin[:, None], res, 0.0), norms(u, axis=2)), np.inf)
    return gamma, res, depths_stack_arrays(np.asarray(C, float), np.asarray(X, float), world_frame)


def solve_ball(regions_n, c_upper: float) -> float | None:
    """A bound of ||v|| for a minimiser v* of the normalised program, valid with :func:`solve_radius`'s box:
    sum_i ||x_i - y_i||^2 <= c_upper and ||y_i|| <= rho_i give ||x|| <= ||rho|| + sqrt(c_upper) (triangle
    inequality), and the auxiliary variables add sum a_i^2 (one per auxiliary variable).  Much smaller than
    the box's diagonal with many views.  None when c_upper is not finite; a region type without
    ``extent()`` raises the TypeError of :func:`region_extent`."""
    if not np.isfinite(c_upper):
        return None
    rho2, aux2 = 0.0, 0.0
    for r in regions_n:                 # products, not ** (a Python float's ** raises OverflowError; * gives inf)
        rho, a = region_extent(r)
        rho2 += rho * rho
        aux2 += r.n_aux * (a * a)
    reach = math.sqrt(rho2) + math.sqrt(max(c_upper, 0.0))
    return math.sqrt(reach * reach + aux2)


def region_extent(region) -> tuple[float, float]:
    """(rho, a): every point of the region has norm <= rho, every feasible auxiliary variable |y_ik| <= a -- the
    region's own :meth:`~tritools.model.regions.Region.extent` (a :class:`~tritools.model.regions.RegionExtent`).

    Raises
    ------
    TypeError
        The region type declares no ``extent()`` (or it returns something else than a RegionExtent): without
        it no rigorous margin can be computed, and the region is refused rather than certified without one.
    """
    ext = extent_of(region)
    return ext.radius, ext.aux


def solve_radius(regions_n, c_upper: float) -> np.ndarray | None:
    """Bounds r_i >= |v_i| for a minimiser v* of the normalised program, one per variable in the order of
    :func:`tritools.model.problem.build_problem` (x_11, x_12, ..., then every view's auxiliary variables):
    f(v*) <= f(v^) = c_upper gives ||x_i - y_i|| <= sqrt(c_upper) (y_i the closest region point), so
    |x_ik| <= rho_i + sqrt(c_upper), and the auxiliary variables are bounded by the regions
    (:func:`region_extent`).  None when c_upper is not finite; a region type without ``extent()`` raises
    the TypeError of :func:`region_extent`."""
    if not np.isfinite(c_upper):
        return None
    xs, aux = [], []
    for r in regions_n:
        rho, a = region_extent(r)
        xs += [rho + math.sqrt(max(c_upper, 0.0))] * 2
        aux += [a] * r.n_aux
    return np.array(xs + aux)
