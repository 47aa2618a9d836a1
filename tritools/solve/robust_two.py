"""Two point views in the enumeration of every inlier set (:class:`tritools.solve.robust_enum_run._Group`, N = 2).

With two views the inlier sets are both views, one view, or none, so

    f*_TLS = min(L2*(V), c_1^2, c_2^2)

(an X on view i's back-projected ray has d_i = 0 and pays min(d_j^2, c_j^2) <= c_j^2; :mod:`tritools.solve.
robust_rays`).  The enumeration's row of both views gives L2LB(V) and its candidate; :func:`two_view_rays` adds,
for every problem of the stack at once, (1) the candidate of both views refined to convergence on both views (its
inlier set may hold one view only, which the local optimisation does not refine), and (2) each view's ray sampled
at the search's depths (:func:`~tritools.solve.robust_rays.ray_samples_stack`), the best sample of each ray offered
unless it equals UB under the decision rule -- it would change no decision, and a ray sample may sit next to another
camera's principal plane, where a georeferenced world's rounding makes the report refuse it (review of wave 19, F2:
gamma_UB inf and no inlier for a view with c = inf, where the refined candidate of both views certifies).  The
candidates are only a ranking: the search keeps one by its exact f_TLS (:meth:`tritools.solve.robust.TlsSearch.
offer`).
"""
from __future__ import annotations

import numpy as np

from .robust_costs import point_distances2_stack
from .robust_rays import best_ray_samples, ray_samples_stack

__all__ = ["two_view_rays", "ray_offers"]


def two_view_rays(group, live: np.ndarray) -> np.ndarray:
    """The steps of the module docstring for the problems ``live`` (P,) of a two-view ``group`` (a
    :class:`~tritools.solve.robust_enum_run._Group`); the problems that may go on (time left)."""
    P = np.nonzero(live)[0]
    if not P.size:
        return live
    _refine_both_views(group, P)
    offers = ray_offers(group.C[P], group.x[P], group.c2[P], group._ub()[P], group._floors()[P], group.tol)
    group._offer_each([(int(P[r]), X) for r, X in offers])
    return live & ~group._expired()


def ray_offers(C: np.ndarray, x: np.ndarray, c2: np.ndarray, ub: np.ndarray, floors: np.ndarray, tol) -> list:
    """Step (2) of the module docstring for R problems of two point views (cameras C (R, 2, 3, 4), points x (R, 2, 2),
    squared thresholds c2 (R, 2), their best values ``ub`` (R,) and decision-scale floors (R,)): the (problem row,
    world point) to offer -- each view's best ray sample unless it equals UB under the decision rule at the floor
    scale (the tightest).  A stack's two-view problems (:func:`two_view_rays`) and a single call
    (:mod:`tritools.solve.robust_three`) both call it."""
    X, tie = ray_samples_stack(C, x)
    R, N, K = X.shape[:3]
    d2 = point_distances2_stack(C, x, X.reshape(R, N * K, 3)).reshape(R, N, K, N)
    f = np.sum(np.minimum(d2, c2[:, None, None, :]), axis=3)
    f = np.where(np.isfinite(X).all(axis=3), f, np.inf)
    k = best_ray_samples(f, tie)
    best = np.take_along_axis(X, k[:, :, None, None], axis=2)[:, :, 0]
    fk = np.take_along_axis(f, k[:, :, None], axis=2)[:, :, 0]
    same = np.asarray(tol.certified(fk, ub[:, None], floors[:, None]), bool)
    return [(r, best[r, i]) for r in range(R) for i in range(N) if not same[r, i]]


def _refine_both_views(group, P: np.ndarray) -> None:
    """The candidate of both views of the problems ``P`` refined to convergence on both views
    (:func:`~tritools.solve.robust_enum.refine_rows`), put in its row and offered (once per problem)."""
    row, full = len(group.W) - 1, frozenset(range(group.N))
    P = np.array([p for p in P[group.has[P, row]] if full not in group.refined[p]], int)
    if not P.size:
        return
    Xr, ok = group._refine_rows(group.Cn[P], group.Xn[P, row], np.broadcast_to(group.W[row], (len(P), group.N)))
    P, Xr = P[ok], Xr[ok]
    for p in P:
        group.refined[p].add(full)
    if P.size:
        group._put(P, np.full(len(P), row), Xr)
        group._offer_each([(int(p), group.frames[p].world_point(X)) for p, X in zip(P, Xr)])
