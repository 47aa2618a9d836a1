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

A single call (:class:`tritools.solve.robust_three._TwoViews`) starts instead from the closed-form optimum of both
views (:func:`two_view_optimum`, Hartley and Sturm's degree-6 polynomial in the normalised frame, where both
observations sit at the origin): the refinement then converges in a step or two (a wrong match took ~30
Levenberg-Marquardt steps from the DLT), and the Lagrangian bound taken there is L2* itself (one quadratic
constraint: the S-lemma).  Its rays wait until a decision fails where UB is already at most min c_j^2 (a ray sample
then costs at least min(L2*, c_j^2) = L2*).
"""
from __future__ import annotations

import math

import numpy as np

from ..model.stacked import dlt_stack
from .robust_costs import point_distances2_stack
from .robust_rays import best_ray_samples, ray_samples_stack

__all__ = ["two_view_rays", "ray_offers", "two_view_optimum", "optimum_candidate"]


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


def two_view_optimum(F: np.ndarray):
    """The L2 optimum of two views with both observations at the origin (the normalised frame of
    :func:`~tritools.solve.robust_enum.enum_frame`) in closed form (Hartley and Sturm, "Triangulation", 1997): the
    corrected points (y_0, y_1) (two 2-vectors) with y_0^T F y_1 = 0 (homogeneous) closest to the origins, and their
    cost ||y_0||^2 + ||y_1||^2; None where the form does not apply (an epipole at an origin, a line at infinity,
    non-finite numbers).

    With e_1 (F e_1 = 0) and e_0 (F^T e_0 = 0) scaled to unit first two coordinates, the rotations R_k taking e_k to
    (1, 0, f_k) bring F to R_0 F R_1^T = [[f_0 f_1 d, -f_0 c, -f_0 d], [-f_1 b, a, b], [-f_1 d, c, d]].  The pencil of
    epipolar lines through e_1, l_1(t) = (t f_1, 1, -t), and its partner l_0(t) = (-f_0 (c t + d), a t + b, c t + d)
    give the cost s(t) = t^2 / (1 + f_1^2 t^2) + (c t + d)^2 / ((a t + b)^2 + f_0^2 (c t + d)^2), stationary at the
    real roots of the degree-6 polynomial t ((a t + b)^2 + f_0^2 (c t + d)^2)^2 - (a d - b c) (1 + f_1^2 t^2)^2
    (a t + b)(c t + d); the least of s at those roots and at t = inf is the optimum, attained at the points of l_0
    and l_1 closest to the origins.  A candidate only: the caller refines it and bounds the set at it, so round-off
    in the roots changes no rigour."""
    with np.errstate(all="ignore"):
        if not np.isfinite(F).all():
            return None
        e1, e0 = np.array(_null(F.tolist())), np.array(_null(F.T.tolist()))
        n1, n0 = np.hypot(e1[0], e1[1]), np.hypot(e0[0], e0[1])
        if not (n1 > 1e-12 * abs(e1[2]) and n0 > 1e-12 * abs(e0[2])):
            return None                                     # an epipole at an origin: an observation on a baseline
        e1, e0 = e1 / n1, e0 / n0
        R1 = np.array([[e1[0], e1[1], 0.0], [-e1[1], e1[0], 0.0], [0.0, 0.0, 1.0]])
        R0 = np.array([[e0[0], e0[1], 0.0], [-e0[1], e0[0], 0.0], [0.0, 0.0, 1.0]])
        G = R0 @ F @ R1.T
        f1, f0 = float(e1[2]), float(e0[2])
        a, b, c, d = float(G[1, 1]), float(G[1, 2]), float(G[2, 1]), float(G[2, 2])
        t = _stationary(a, b, c, d, f0, f1)
        if t is None:
            return None
        l1 = np.array([t * f1, 1.0, -t]) if np.isfinite(t) else np.array([f1, 0.0, -1.0])
        l0 = np.array([-f0 * (c * t + d), a * t + b, c * t + d]) if np.isfinite(t) else np.array([-f0 * c, a, c])
        y1, y0 = R1.T @ _foot(l1), R0.T @ _foot(l0)
        if not (abs(y1[2]) > 0 and abs(y0[2]) > 0):
            return None
        y0, y1 = y0[:2] / y0[2], y1[:2] / y1[2]
        cost = float(y0 @ y0 + y1 @ y1)
    return (y0, y1, cost) if np.isfinite(cost) and np.isfinite(y0).all() and np.isfinite(y1).all() else None


#: :func:`_stationary` drops leading coefficients of its polynomial below this share of the largest one.
LEADING_RTOL = 1e-13


def _stationary(a: float, b: float, c: float, d: float, f0: float, f1: float):
    """The t of :func:`two_view_optimum` (a real root of its polynomial or inf) where s(t) is least, or None."""
    e = f0 * f0
    p2, p1, p0 = a * a + e * c * c, 2.0 * (a * b + e * c * d), b * b + e * d * d     # (at + b)^2 + f0^2 (ct + d)^2
    q2, q1, q0 = a * c, a * d + b * c, b * d                                        # (at + b)(ct + d)
    k, h2, h4 = a * d - b * c, f1 * f1, f1 ** 4                                     # (1 + f1^2 t^2)^2 = h4 t^4 + ...
    g = [-k * h4 * q2, p2 * p2 - k * h4 * q1, 2 * p2 * p1 - k * (h4 * q0 + 2 * h2 * q2),
         p1 * p1 + 2 * p2 * p0 - 2 * k * h2 * q1, 2 * p1 * p0 - k * (2 * h2 * q0 + q2), p0 * p0 - k * q1, -k * q0]
    if not all(math.isfinite(v) for v in g) or not any(g):
        return None
    # leading coefficients at round-off of the largest (an epipole at infinity up to round-off, f_1 ~ 1e-17: the
    # f_1^4 terms ~1e-68) left out: their roots sit at |t| ~ 1e13 and beyond, where s(t) ~ min(t^2, 1 / f_1^2) is
    # nowhere near the least (t = inf is tried on its own), and np.roots lost the others' digits to them
    top = max(abs(v) for v in g)
    while abs(g[0]) <= LEADING_RTOL * top:
        g = g[1:]
    ts = np.roots(g).real.tolist()

    def cost(t: float) -> float:
        u, v = a * t + b, c * t + d
        return t * t / (1.0 + f1 * f1 * t * t) + v * v / (u * u + f0 * f0 * v * v)

    best_t = math.inf
    best = (1.0 / (f1 * f1) if f1 != 0 else math.inf) + (c * c / p2 if p2 > 0 else math.inf)
    for t in ts:
        v = cost(t)
        if v < best:
            best, best_t = v, t
    return best_t if math.isfinite(best) else None


def _null(rows: list) -> list:
    """A null vector of a rank-2 3x3 matrix given by its rows: the longest cross product of two rows."""
    best, out = -1.0, None
    for i, j in ((0, 1), (0, 2), (1, 2)):
        u, v = rows[i], rows[j]
        w = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]
        n = w[0] * w[0] + w[1] * w[1] + w[2] * w[2]
        if n > best:
            best, out = n, w
    return out


def _foot(line: np.ndarray) -> np.ndarray:
    """The point (homogeneous) of the line (l, m, n) closest to the origin: (-l n, -m n, l^2 + m^2)."""
    return np.array([-line[0] * line[2], -line[1] * line[2], line[0] ** 2 + line[1] ** 2])


def optimum_candidate(Cn: np.ndarray, F: np.ndarray):
    """The normalised candidate Xn (3,) of two normalised point views Cn (2, 3, 4) (observations at the origin) with
    x_0^T F x_1 = 0 (:func:`~tritools.model.stacked.fundamental_stack`'s F of the pair): the DLT of the corrected
    points of :func:`two_view_optimum` (exactly consistent, so the DLT is their intersection), or None."""
    opt = two_view_optimum(F)
    if opt is None:
        return None
    y0, y1, _ = opt
    X, ok = dlt_stack(Cn[None], np.array([[y0, y1]]))
    return X[0] if ok[0] and np.isfinite(X[0]).all() else None
