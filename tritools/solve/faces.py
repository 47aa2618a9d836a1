"""Verification of regions whose candidate lies inside a segment or on one face of a polytope (issue #22).

In the degree-2 certificate with constant multipliers of :mod:`tritools.solve.regions_verify`, a view whose closest
region point y^ lies in the relative interior of a segment ``{c + t d : |t| <= 1}`` (|t^| < 1) or on a single
face of a polytope has KKT multiplier 0 on the constraints that are not active, so its weight after the exact
elimination of y is rank one: the squared distance to the face's *line*, W = n n^T.  Along the face the
Lagrangian is then linear in x_i, and as the epipolar constraints are bilinear (x~_i^T F_ik x~_k: no x_i x_i
term) its Hessian has a zero diagonal entry with non-zero couplings unless every multiplier lambda_ik
vanishes: not PSD, no certificate.  This is no defect of the elimination: at delta = 2 the Lagrangian dual
(Shor) of the Corollary 1 program needs a multiplier mu > 0 on the inactive constraint to bound L below, and
pays for it -- the SDP chooses the best such mu, and certifies when the price is within the tolerance.

The price is explicit.  For the segment, h = 1 - t^2 >= 0 and any mu >= 0 give (exact elimination of t,
:func:`tritools.solve.regions_verify._segment`)

    min_t ||x - c - t d||^2 - mu (1 - t^2) = (x - c)^T (I - d d^T / (|d|^2 + mu)) (x - c) - mu,

a weight mu / (|d|^2 + mu) > 0 along d; at the candidate the view's Lagrangian term is at most mu below its
distance (-mu h(y^) >= -mu), so the bound loses at most mu plus what the shifted stationary point costs (the
Lagrangian minimum is computed exactly, so that part is accounted for, not estimated).  For a polytope with one
active slab k, the multiplier mu goes to the inactive slabs j (h_j = 1 - (B_j y + c_j)^2, curvature mu B_j B_j^T
across the face) and costs at most mu (1 - s_j^2) <= mu.  So mu is taken as a fraction of the certificate
tolerance in c units, ``FACE_MU_FRACTIONS`` in turn: a small region (uncertain keypoints: |d| of a pixel or less)
gets a large weight mu / (|d|^2 + mu) for a loss within the tolerance, a long one a weight too small to make
the Hessian PSD (then no claim, as for the SDP at that tolerance).

Every mu >= 0 is a valid multiplier of an inequality, so every bound computed here is a valid lower bound
whatever mu is chosen (weak duality; the rigour of the bound itself -- PSD test, exact minimum with its
floating-point margin -- is :func:`tritools.solve.fastpath.lagrangian_bounds`'), and the largest of them is
kept.  Corners (two active slabs) and segment ends (|t^| = 1) have their KKT multipliers and full-rank weights
already; a degenerate segment (d = 0) is a point.
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

from sospoly import Tolerances

from ..model.regions import ConeKind

__all__ = ["face_bound", "FACE_MU_FRACTIONS", "has_faces"]

#: the face multiplier mu, as fractions of the certificate's gap tolerance at the candidate's value (c units),
#: shared by the views that may lie on a face; tried in turn after the KKT multipliers (mu = 0) until one
#: certifies.  Measured on 64 problems of 3-6 views (2 px noise; boxes of 0.3 and 1 px, segments of 0.2 and
#: 1 px): the KKT multipliers certify 28, (0.25, 0.02) 33, these 38; the mu the PSD test needs is mostly
#: 1-1000x the tolerance (the SDP, choosing the epipolar multipliers too, certifies more).
FACE_MU_FRACTIONS = (0.5, 0.1, 0.9, 0.02)


def has_faces(forms) -> int:
    """The number of views whose region has faces (a segment of non-zero length or a polytope)."""
    return sum(f.kind == ConeKind.POLYTOPE or (f.kind == ConeKind.SEGMENT and bool(np.any(f.direction != 0)))
               for f in forms)


def face_bound(bound_at: Callable[[float], float], forms, c_upper: float, tolerances: Tolerances,
               deadline=None) -> float:
    """The largest lower bound (c units, NaN: none) of ``bound_at(mu)`` (the bound with the face multiplier mu)
    over mu = 0 (the KKT multipliers) and, while that does not certify against ``c_upper``, the multipliers of
    ``FACE_MU_FRACTIONS`` (module docstring): each a valid lower bound, so their maximum is one.  A multiplier is
    not tried once less of the ``deadline`` is left than the last bound took."""
    t0 = time.perf_counter()
    best = bound_at(0.0)
    last = time.perf_counter() - t0
    n_faces = has_faces(forms)
    if n_faces == 0 or not math.isfinite(c_upper):
        return best
    tol = float(tolerances.gap_tolerance(c_upper))
    for fraction in FACE_MU_FRACTIONS:
        if (math.isfinite(best) and bool(tolerances.certified(best, c_upper))) or _no_time_for(deadline, last):
            break
        t0 = time.perf_counter()
        lower = bound_at(fraction * tol / n_faces)
        last = time.perf_counter() - t0
        if math.isfinite(lower) and not (lower <= best):
            best = lower
    return best


def _no_time_for(deadline, seconds: float) -> bool:
    """The deadline has passed, or what is left of it is shorter than ``seconds`` (the last bound's time: each
    costs about the same, ~15 ms at 30 views, and its view quadratics do not look at the deadline)."""
    if deadline is None:
        return False
    left = deadline.remaining()
    return deadline.expired or (left is not None and left < seconds)
