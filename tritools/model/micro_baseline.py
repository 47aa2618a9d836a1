"""Views whose camera centres agree to round-off but not exactly: when a homography may tie them.

A rotation rig built as K_i R_i [I | -C] in floats, or a duplicated view rescaled by 3, gives cameras whose centres
the float tests call one (:func:`tritools.model.constraints.centre_groups`) while the caller's float data, read
exactly, have a micro-baseline e (|e| ~ 1e-16 |C|).  Far from the centres that baseline is invisible and the pair
is related by the homography H = M_j M_i^-1; next to them (within ~|e| / parallax) it is a real baseline, and the
exact L2 problem (SPEC §1 ignores cheirality) has values below anything the homography admits (review 8b: a rig
certified at f_LB = 4.353 while a float point 3e-9 from its centres has exact cost 4.007).

So a pair of one group whose centres are not exactly equal (:func:`tritools.model.exact.same_exact_centre`) gets
the homography constraint only when the ball B(C, rho) around the group's centre is *excluded*: every point of it
costs more, in the views outside the group alone, than an upper bound f_UB of the optimum (:func:`ball_lower_cost`).
The optimum then lies outside the ball, where the exact projections satisfy x_j ~ H x_i up to an angle |e| / rho =
1 / ``BALL_RATIO`` = 1e-12 rad (~1e-9 px at f = 1000: far below the coordinates' resolution of the decision rule,
though above the round-off of the constraints' own coefficients; review 9 measured one certified bound 3.3e-6 of f
above an exact value, at gamma ~ 1e-4 px, within that resolution).  A group with no
view outside it (a pure-rotation rig in floats) is never excluded: its pairs keep no constraint (a valid, weaker
bound; the point is ``ill_posed``), and a rig with one exact centre (t = 0) is certified as before.
"""
from __future__ import annotations

import math
from fractions import Fraction

import numpy as np

from .exact import accurate_homogeneous, exact_centre

__all__ = ["BALL_RATIO", "group_ball", "ball_lower_cost", "admitted_pairs"]

#: the excluded ball's radius over the group's exact micro-baseline: outside it the homography errs by at most
#: 1 / BALL_RATIO rad.
BALL_RATIO = 1e12
#: relative safety margin on the ball's lower bound (round-off of the projections, distances and the upper bound).
MARGIN_RTOL = 1e-8


def _exact_point(P) -> tuple | None:
    c = exact_centre(P)
    if c[3] == 0:
        return None
    return tuple(Fraction(c[k], c[3]) for k in range(3))


def group_ball(raw: np.ndarray, views, floor: float = 0.0) -> float | None:
    """The radius rho = BALL_RATIO max(|e|, floor) of the ball to exclude for ``views`` of one group, |e| the
    largest exact distance between their centres (None: a centre at infinity)."""
    pts = [_exact_point(raw[v]) for v in views]
    if any(p is None for p in pts):
        return None
    sep = max(math.sqrt(_float_or_inf(sum((a - b) ** 2 for a, b in zip(p, pts[0])))) for p in pts)
    return BALL_RATIO * max(sep, floor)


def _float_or_inf(q: Fraction) -> float:
    """A non-negative Fraction as a float, inf beyond the largest double (``float()`` raises OverflowError there:
    a camera entry of 1e200 put its exact centre that far, review 29b F1)."""
    try:
        return float(q)
    except OverflowError:
        return math.inf


def ball_lower_cost(cams: np.ndarray, regions, outside, centre: np.ndarray, rho: float) -> float:
    """A lower bound of sum_{k in outside} d_k(X)^2 over the ball |X - centre| <= rho (cameras ``cams`` in the
    frame of ``centre``, regions in pixels).

    For P_k = [M | p] and h = P_k (C, 1): u(C + delta) - u(C) = (M_12 - u(C) m_3) delta / (h_3 + m_3 delta), so
    the projection of the ball lies within dev = rho ||M_12 - u m_3||_2 / (|h_3| - rho ||m_3||) of u(C) (no bound
    when the ball reaches the camera's principal plane), and d_k >= d_k(u(C)) - dev."""
    total = 0.0
    Ch = np.append(np.asarray(centre, float), 1.0)
    for k in outside:
        P = np.asarray(cams[k], float)
        h = accurate_homogeneous(P, Ch)
        m3 = np.linalg.norm(P[2, :3])
        if not np.all(np.isfinite(h)) or abs(h[2]) <= rho * m3 * (1 + MARGIN_RTOL):
            continue
        u = h[:2] / h[2]
        A = P[:2, :3] - np.outer(u, P[2, :3])
        dev = rho * np.linalg.norm(A, 2) / (abs(h[2]) - rho * m3)
        d = float(regions[k].distance(u))
        lb = d - dev * (1 + MARGIN_RTOL) - MARGIN_RTOL * (d + float(np.max(np.abs(u))) + 1.0)
        if np.isfinite(lb) and lb > 0:
            total += lb * lb
    return total * (1 - MARGIN_RTOL)


def admitted_pairs(raw: np.ndarray, cams: np.ndarray, regions, groups, f_upper: float | None,
                   floor: float = 0.0, pairs=()) -> frozenset:
    """The ``pairs`` of one centre group whose centres agree to round-off only
    (:attr:`tritools.model.constraints.CentreRelations.untied`) whose group's ball is excluded by ``f_upper`` (an
    upper bound of the optimum's sum of squared distances): every point of the ball costs more in the other views.
    ``raw`` the caller's cameras (exactness), ``cams`` the same in the solver's world frame (the ball's centre;
    ``floor`` the frame move's round-off), ``regions`` in pixels."""
    if not pairs or f_upper is None or not np.isfinite(f_upper):
        return frozenset()
    groups = np.asarray(groups)
    admitted = set()
    for g in sorted({int(groups[i]) for i, _ in pairs}):
        views = [int(v) for v in np.flatnonzero(groups == g)]
        outside = [int(v) for v in np.flatnonzero(groups != g)]
        rho = group_ball(raw, views, floor)
        if rho is None or not outside:
            continue
        centre = _frame_centre(cams[views[0]])
        if centre is None or not np.isfinite(rho):
            continue
        if ball_lower_cost(cams, regions, outside, centre, rho) > f_upper * (1 + MARGIN_RTOL):
            admitted |= {(i, j) for i, j in pairs if groups[i] == g}
    return frozenset(admitted)


def _frame_centre(P) -> np.ndarray | None:
    c = _exact_point(P)
    return None if c is None else np.array([float(v) for v in c])
