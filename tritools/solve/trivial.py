"""The trivial lower bound gamma* >= 0, and the local estimate every result falls back on.

gamma(X) is an RMS of distances, so 0 is a lower bound of gamma* for every problem.  When an estimate X^
has gamma(X^) within the certificate tolerance of 0 -- :func:`tritools.solve.decide.decide` applied to
(c_LB, c_UB) = (0, 2N gamma'(X^)^2) in the normalised units, then confirmed on the numbers reported by
:func:`tritools.solve.decide.decide_reported` (the rule of every path, at the problem's own scale) --
X^ is a certified global minimiser (``certified_by = "trivial_bound"``) whatever the SDP did: problems
whose regions contain the projections of one point (gamma* = 0) certify even where every solver attempt
stopped short (Clarabel's "almost solved" at gamma* = 0 is common: the optimal face is degenerate).

:func:`local_estimate` is the estimate of last resort: the linear (DLT) point of the region centres in the
normalised frame (its origin, :mod:`tritools.model.normalize`) refined by Levenberg-Marquardt on the exact
distances to the regions (:func:`tritools.model.geometry.refine_l2`).  Every result other than
``invalid_input`` carries it when nothing better was found.
"""
from __future__ import annotations

import numpy as np

from ..model.geometry import gamma_validated
from ..model.geometry import common_centre, refine_l2
from ..model.lm_one import refine_point_one
from ..model.stacked import dlt_stack
from .decide import decide, decide_reported

__all__ = ["TRIVIAL_BOUND", "trivially_certified", "trivially_certified_reported", "local_estimate",
           "point_views_start", "small_views", "SMALL_SHARE"]

#: ``certified_by`` of a certificate through the trivial lower bound 0.
TRIVIAL_BOUND = "trivial_bound"


def trivially_certified(c_upper, tolerances, n_views, resolution):
    """Does c_UB (normalised units, scalar or array) meet the trivial lower bound 0 under the rule of
    :func:`tritools.solve.decide.decide`?  False where c_UB is not finite."""
    up = np.asarray(c_upper, float)
    _, optimal, _ = decide(np.zeros_like(up), up, tolerances, n_views, resolution)
    out = np.asarray(optimal, bool) & np.isfinite(up)
    return bool(out) if out.ndim == 0 else out


def trivially_certified_reported(gamma_ub, tolerances, n_views, scale, resolution):
    """:func:`trivially_certified` on the numbers the user sees: gamma_UB in pixels against gamma_LB = 0
    (:func:`tritools.solve.decide.decide_reported`)."""
    up = np.asarray(gamma_ub, float)
    return decide_reported(np.zeros_like(up), up, tolerances, n_views, scale, resolution)


#: point regions of at most this many views take the scalar Levenberg-Marquardt (:func:`_points_lm`).
LOCAL_POINTS_MAX_VIEWS = 10


def local_estimate(cameras_n, regions_n) -> tuple[float, np.ndarray] | None:
    """(gamma'(X), X) in the normalised frame: Levenberg-Marquardt from the frame's origin (the DLT point of
    the region centres) and, with two point views (or regions far smaller than another, :func:`small_views`) beside
    a region view, also from their DLT (:func:`point_views_start`), the lower gamma kept; None when the refinements
    fail or gamma is not finite.
    Point regions of few views take the scalar LM of the single calls (:func:`_points_lm`), the others scipy's
    (:func:`refine_l2`)."""
    X = _points_lm(cameras_n, regions_n)
    if X is None:
        X = refine_l2(np.zeros(3), cameras_n, regions_n)
    best = _scored(X, cameras_n, regions_n)
    extent = np.array([[0.0 if r.is_point else float(r.extent().radius) for r in regions_n]])
    X2, second = point_views_start(np.asarray(cameras_n, float)[None], small_views(extent))
    if second[0]:                                       # two small views beside a large region: also from their DLT
        other = _scored(refine_l2(X2[0], cameras_n, regions_n), cameras_n, regions_n)
        if other is not None and (best is None or other[0] < best[0]):
            best = other
    return best


def _scored(X, cameras_n, regions_n) -> tuple[float, np.ndarray] | None:
    """(gamma'(X), X), or None for no X or a gamma that is not finite."""
    if X is None:
        return None
    g = float(gamma_validated(np.asarray(X, float)[None], np.asarray(cameras_n, float), regions_n)[0])   # (checked)
    return (g, X) if np.isfinite(g) else None


def _points_lm(cameras_n, regions_n) -> np.ndarray | None:
    """The local L2 optimum from the origin by :func:`tritools.model.lm_one.refine_point_one` (the same
    minimisation as :func:`refine_l2` for point regions, on Python floats: ~0.2 ms at three views where scipy's
    least squares took ~2.5 ms of a 3-view Theorem 1 sub-problem of a robust search), for point regions of at most
    :data:`LOCAL_POINTS_MAX_VIEWS` views whose cameras do not share one centre (:func:`refine_l2` keeps X on that
    ray); None otherwise or where it did not converge (the caller then runs :func:`refine_l2`)."""
    C = np.asarray(cameras_n, float)
    if len(regions_n) > LOCAL_POINTS_MAX_VIEWS or not all(r.is_point for r in regions_n) or \
            common_centre(C) is not None:
        return None
    xhat = [[float(v) for v in np.asarray(r.center, float).reshape(2)] for r in regions_n]
    X, ok, converged = refine_point_one(C.tolist(), xhat, [0.0, 0.0, 0.0])
    return np.array(X, float) if ok and converged else None


#: a view's region is "small" for :func:`small_views` when its extent is at most this share of the largest one's
SMALL_SHARE = 1e-2


def small_views(extent: np.ndarray) -> np.ndarray:
    """(M, N) bool: the views whose region's extent (M, N; 0 for a point) is at most ``SMALL_SHARE`` of the problem's
    largest -- the views :func:`point_views_start` triangulates (points, and keypoint-sized regions beside a region
    far larger than them)."""
    e = np.asarray(extent, float)
    return e <= SMALL_SHARE * np.max(e, axis=1, keepdims=True)


def point_views_start(Cn: np.ndarray, pt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(X (M, 3), ok (M,)): a second start for the local optimum of M problems with region views in the normalised
    frame (every region's centre at the origin): :func:`tritools.model.stacked.dlt_stack` of the views ``pt`` (M, N)
    alone (the other views' cameras zeroed: rows of zeros), ok where a problem has at least two such views and
    another view and the point is finite.  A region far larger than the residuals whose centre is far from the
    optimum's projection can draw the start from all centres to another local minimum (review 40a: 262 px, the
    optimum 0.18 px)."""
    use = np.asarray(pt, bool)
    X, ok = dlt_stack(np.where(use[..., None, None], Cn, 0.0), np.zeros(use.shape + (2,)))
    return X, ok & (np.sum(use, axis=1) >= 2) & ~use.all(axis=1)
