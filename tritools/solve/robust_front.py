"""A certified TLS estimate on a line of minimisers, moved to a well-placed point of it (review 36a F2).

With point regions the L2 optimum of an inlier set is generically unique, and so is the TLS optimum; a certified
estimate behind a camera is then the answer (:func:`tritools.solve.decide.cheirality` says so).  Not when the
inlier views S share one camera centre C (a camera listed twice, one view left as the only inlier): every point

    X(t) = C + t (X - C),    t != 0,

projects to the same image points in the views of S, so f_TLS restricted to S is constant on that line and the
optimum may be a whole ray (the other views stay outliers on much of it).  The search returns one point of it,
possibly behind the cameras while points of equal cost lie in front, or within round-off of C itself, where no
projection is defined in the caller's frame (a georeferenced world: the estimate's report then refuses the
certificate it met).

:func:`front_tie` acts on a certified estimate of such an S that lies behind a camera of S, or within
:data:`CLOSE_RTOL` of the scene's scale from C (cheap screens on its depths first; the centres only then). It tries
(1) where S is one camera given |S| times with point regions (:func:`tritools.model.exact.one_exact_camera`), the
ray of the observations' mean x_bar at depths B * :data:`STEPS` (B the camera baseline) -- S's own L2 optimum
(:func:`tritools.solve.robust_subsolve._one_camera`); (2) the line through X, at the same distances from C on either
side. It keeps the first point in front of every camera (else the first in front of every camera of S) whose exact
f_TLS (:meth:`tritools.solve.robust.TlsSearch.cost`) is not above the certified value beyond :data:`TIE_RTOL` (the
tie rule of :meth:`~tritools.solve.robust.TlsSearch.offer`) or, for an estimate at C (within :data:`NEAR_RTOL`: its
own value is round-off there), whose value the lower bound certifies. The lower bound is unchanged; the upper bound
becomes f at the new point and the certificate is decided on it by the one rule as before, so the rigour is the
search's. Certified estimates behind a camera whose inlier views do not share a centre are left alone: their
minimiser is the answer.
"""
from __future__ import annotations

import numpy as np

from ..model.cameras import camera_center
from ..model.exact import one_exact_camera
from .robust_rays import camera_baseline, view_ray

__all__ = ["front_tie", "STEPS", "TIE_RTOL", "CENTRE_RTOL", "NEAR_RTOL", "CLOSE_RTOL"]

#: distances from C tried along a line, in units of the camera baseline B, nearest B first
STEPS = (1.0, 0.5, 2.0, 0.1, 10.0, 1e-2, 1e2, 1e-3, 1e3)
#: a point of the line replaces the estimate when its f_TLS is at most (1 + TIE_RTOL) times the certified value
TIE_RTOL = 1e-12
#: the inlier views share a centre when their centres differ by at most this much of |C| + |X - C| + B
CENTRE_RTOL = 1e-9
#: an estimate whose depth in a view of S is at most this much of the scene's scale sits at that view's centre
NEAR_RTOL = 1e-6
#: ... and at most this much, next to it: moved only to a point of equal cost (review 37b M1: a certified estimate
#: at depth 1.5e-5 of a scene of scale 2, where a batch row of the same problem gave a point at depth 1.98)
CLOSE_RTOL = 1e-2


def front_tie(search, lb: float, depths: np.ndarray) -> bool:
    """Move a certified TLS estimate of ``search`` (a :class:`~tritools.solve.robust.TlsSearch`, lower bound ``lb``
    in pixels^2; ``depths``: the estimate's depths in every view, from its report) behind a camera of its inlier
    set, or next to its centre, to a well-placed point of equal cost on the line of minimisers through the inlier
    views' shared centre (module docstring); True when it moved.  A few array operations where it does not act."""
    X, S = search.best_X, sorted(search.best_S)
    if X is None or not S or depths is None:
        return False
    lo = depths[S].min()
    if lo > CLOSE_RTOL * max(np.abs(X).max(), np.abs(depths).max()):   # the common case (False for NaN)
        return False
    dep = np.where(np.isfinite(depths), depths, -np.inf)
    near = float(np.min(np.abs(dep[S]))) <= NEAR_RTOL * max(float(np.max(np.abs(X))),
                                                             float(np.max(np.abs(dep[np.isfinite(dep)]), initial=0.0)))
    if not search.tol.certified_one(lb, search.best_f, search.scale):
        return False
    centres = _centres(search.C)
    if centres is None:
        return False
    C, B = centres[S[0]], camera_baseline(centres)      # B: the median distance between distinct centres
    if np.any(np.linalg.norm(centres[S] - C, axis=1) > CENTRE_RTOL * (np.linalg.norm(C) + np.linalg.norm(X - C) + B)):
        return False
    fallback = None
    for Y in _line_points(search, S, C, X, B, near):
        dep = _depths(search, Y)
        if not np.all(dep[S] > 0):
            continue
        d, f = search.cost(Y)
        if not (f <= search.best_f * (1 + TIE_RTOL) or (near and search.tol.certified_one(lb, f, search.scale))):
            continue
        if np.all(dep > 0):
            return _take(search, Y, d, f)
        fallback = fallback or (Y, d, f)
    return fallback is not None and _take(search, *fallback)


def _line_points(search, S: list, C: np.ndarray, X: np.ndarray, B: float, near: bool):
    """The points tried, in order (module docstring): the mean observation's ray of one exact camera, then the line
    through X (not where X sits at C: its direction is round-off there)."""
    ray = view_ray(search.C[S[0]], np.mean(search.x[S], axis=0)) \
        if search.points and (len(S) == 1 or one_exact_camera(search.C[S])) else None
    if ray is not None:
        for s in STEPS:
            yield C + s * B * ray[1]
    v = X - C
    if not near and np.linalg.norm(v) > 0:
        v = B * v / np.linalg.norm(v)
        for s in STEPS:
            yield C - s * v                   # the other side of C first (an estimate behind it), then this side
            yield C + s * v


def _depths(search, X) -> np.ndarray:
    """The depths of the search-frame point X in every view (the caller's cameras; -inf where undefined)."""
    dep = search.report(search.frame.user_point(X) if search.frame.moved else X).depths
    return np.where(np.isfinite(dep), dep, -np.inf)


def _centres(cams: np.ndarray):
    """The camera centres (N, 3) in the search frame, or None (a centre at infinity)."""
    try:
        centres = np.array([camera_center(P) for P in cams])
    except ValueError:
        return None
    return centres if np.all(np.isfinite(centres)) else None


def _take(search, Y, d, f) -> bool:
    search.best_X, search.best_f = np.asarray(Y, float), float(f)
    search.best_S = frozenset(int(i) for i in np.nonzero(d < search.c)[0])
    return True
