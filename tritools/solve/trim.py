"""Long segments trimmed to the part that can hold the optimum's closest point: an exact reduction.

A segment S = {c + tau d : |tau| <= 1} far longer than the residuals is, near the optimum, a line: its view has no
weight along it, the degree-2 certificate is not tight, and the degree-4 program is scaled by the segment
(docs/triangulation.md, "A known limit: long segments").  Only a short part of S can hold the closest point of the
optimum's projection, and where that part is found rigorously the problem with S replaced by it has the same
optimum.

With f_UB >= f* (the sum of the squared distances at any point, rounded up) every global minimiser X* -- or every
point of a minimising sequence with f <= f_UB, where the infimum is not attained -- has d_i(X*)^2 <= f* <= f_UB in
every view, so with r = sqrt(f_UB):

* y = Phi(X*, P_j) lies within r of R_j, in the box B_j = m_j +- (rho_j + r) (m_j the region's centre, rho_j >=
  max_{y in R_j} |y - m_j|: :func:`tritools.solve.stages.subproblem.centre_radius`), for every view j;
* p = Phi(X*, P_s) = c0 + t u + delta n with |delta| <= r (u = d / |d|, n its normal, c0 = c + t0 u on the line of S
  at the foot of the local estimate's projection): the distance to the line is at most the distance to S;
* p~^T F y~ = 0 with the fundamental matrix F of the views (s, j) (Hartley & Zisserman (17.3): F_ki =
  (-1)^(i+k) det [P_j without row i; P_s without row k], here computed exactly in rational arithmetic from the
  cameras as given and rounded once), which holds for every point with finite projections.  So
  A(y) + t D(y) + delta B(y) = 0 with A = c0~^T F y~, D = (u, 0)^T F y~, B = (n, 0)^T F y~, affine in y.

Where D does not vanish on B_j, t = -(A + delta B) / D lies in the interval of interval arithmetic over B_j and
|delta| <= r (each affine range widened by 64 units of round-off of its terms' absolute sum: F's rounding and the
evaluation); the intervals of all such views j are intersected.  The closest point of S to p is
c + clip(tau, -1, 1) d, tau = (t0 + t) / |d|, so it lies in S' = {c + tau d : tau in [clip(tau_lo), clip(tau_hi)]}
(widened by 1e-9 of the magnitudes for the rounding of c0, u and n) and

    min f_{S'} <= f_{S'}(X*) <= f_S(X*) = min f_S,

so every lower bound of the problem with S' is one of the whole problem (S' need not lie inside S for this; where it
does, up to its widening, the two optima are equal and the trimmed problem's certificate carries over).  The
trimmed problem is short-segmented and well scaled: its own plan (degree 4 where needed) certifies it.
"""
from __future__ import annotations

import itertools
import math
from fractions import Fraction

import numpy as np

from ..model.regions import ConeKind, Ellipse, Polytope, Segment, conic_form_of, polytope_vertices
from ..model.regions.clipped import ClippedEllipse
from ..model.regions.shapes import shape_fields

__all__ = ["exact_fundamental", "segment_interval", "trimmed_regions", "segment_of", "polytope_axis", "ellipse_axis",
           "TRIM_SHARE", "TRIM_MIN_RATIO", "TRIM_ANCHORS"]

#: a segment is trimmed only where its part that can hold the closest point is at most this share of it
TRIM_SHARE = 0.25
#: ... and only where it is longer than this multiple of r = sqrt(f_UB) (a segment of a few residuals certifies)
TRIM_MIN_RATIO = 8.0
#: the views bounding a segment's part (:func:`segment_interval`): this many with the smallest regions (each costs
#: an exact fundamental matrix, ~3 ms of rational arithmetic)
TRIM_ANCHORS = 4
_U = 2.0 ** -53


def _det4(rows: list) -> Fraction:
    """The determinant of a 4 x 4 matrix of Fractions (Leibniz: exact)."""
    total = Fraction(0)
    for perm in itertools.permutations(range(4)):
        inv = sum(1 for a in range(4) for b in range(a + 1, 4) if perm[a] > perm[b])
        term = rows[0][perm[0]] * rows[1][perm[1]] * rows[2][perm[2]] * rows[3][perm[3]]
        total += -term if inv % 2 else term
    return total


def exact_fundamental(Ps: np.ndarray, Pj: np.ndarray) -> np.ndarray | None:
    """F (3, 3) with p~_s^T F y~_j = 0 for the projections of every point (module docstring), computed exactly from
    the float cameras and divided by its largest entry before one rounding to floats (entries in [-1, 1], each within
    a unit of round-off, or 2^-1074, of the exact quotient); None where F vanishes.  (One camera given twice gives a
    skew F, for which the relation holds trivially: no bound comes of it.)"""
    a = [[Fraction(float(v)) for v in row] for row in np.asarray(Pj, float).tolist()]
    b = [[Fraction(float(v)) for v in row] for row in np.asarray(Ps, float).tolist()]
    F = [[_det4([a[r] for r in range(3) if r != i] + [b[r] for r in range(3) if r != k]) * (-1) ** (i + k)
          for i in range(3)] for k in range(3)]
    big = max(abs(v) for row in F for v in row)
    if big == 0:
        return None
    return np.array([[float(v / big) for v in row] for row in F])


def _affine_range(v: np.ndarray, F: np.ndarray, m: np.ndarray, half: float) -> tuple[float, float]:
    """[lo, hi] of v~^T F (y, 1) over the box |y - m|_inf <= half, widened for the rounding (module docstring)."""
    k = v @ F
    mid = float(k[0] * m[0] + k[1] * m[1] + k[2])
    w = float((abs(k[0]) + abs(k[1])) * half)
    err = 64 * _U * float(np.abs(v) @ np.abs(F) @ np.array([abs(m[0]) + half, abs(m[1]) + half, 1.0])) + 1e-300
    return mid - w - err, mid + w + err


def _divide(num: tuple, den: tuple) -> tuple[float, float] | None:
    """The range of -num / den for intervals num, den with 0 outside den (None where den holds 0)."""
    if not (den[0] > 0 or den[1] < 0):
        return None
    q = [-n / d for n in num for d in den]
    return min(q), max(q)


def segment_interval(cams: np.ndarray, regions, s: int, u_s: np.ndarray, r: float, radii, *, line=None,
                     reach: float = 0.0) -> tuple | None:
    """(tau_lo, tau_hi): the parameters of segment ``regions[s]`` that can hold the closest point of the optimum's
    projection (module docstring), from the local estimate's projection ``u_s`` in view s, r = sqrt(f_UB) and the
    regions' centre radii ``radii``; None where no view bounds it.  ``line`` = (c, d, w): the axis c + tau d of a
    region within w of it (:func:`polytope_axis`) instead of a segment; ``reach``: the interval grown by that many
    pixels (r for a polytope: its closest point lies within r of the projection)."""
    if line is None:
        c, d = segment_of(regions[s])
        w = 0.0
    else:
        c, d, w = line
    L = float(np.hypot(d[0], d[1]))
    if not (L > 0 and math.isfinite(L) and np.all(np.isfinite(u_s))):
        return None
    u = d / L
    n = np.array([-u[1], u[0]])
    t0 = float(u @ (u_s - c))
    c0 = c + t0 * u
    rd = (r + w) * (1 + 1e-12) + 1e-12 * (float(np.max(np.abs(c))) + L + abs(t0))
    lo, hi = -math.inf, math.inf
    anchors = sorted((radii[j], j) for j in range(len(regions)) if j != s and math.isfinite(radii[j]))
    for _, j in anchors[:TRIM_ANCHORS]:
        Pj, rj = cams[j], regions[j]
        F = exact_fundamental(cams[s], Pj)
        if F is None:
            continue
        m, half = np.asarray(rj.center, float), radii[j] + r
        A = _affine_range(np.append(c0, 1.0), F, m, half)
        B = _affine_range(np.append(n, 0.0), F, m, half)
        D = _affine_range(np.append(u, 0.0), F, m, half)
        bb = rd * max(abs(B[0]), abs(B[1]))
        t = _divide((A[0] - bb, A[1] + bb), D)
        if t is not None and all(math.isfinite(v) for v in t):
            lo, hi = max(lo, t[0]), min(hi, t[1])
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return None
    pad = 1e-9 * (abs(t0) + max(abs(lo), abs(hi)) + float(np.max(np.abs(c))) + r) + reach
    if lo > hi:               # (no point with f <= f_UB: f_UB is not an upper bound after all; nothing trimmed)
        return None
    lo, hi = (t0 + lo - pad) / L, (t0 + hi + pad) / L
    if line is not None:            # (a polytope's axis ends at its computed vertices: not clipped, the cut is R's)
        return lo, hi
    return min(1.0, max(-1.0, lo)), min(1.0, max(-1.0, hi))


def segment_of(region) -> tuple:
    """(centre, half-direction) of a region whose conic form is exactly a segment (asked of the region: a user
    type with that form counts), or (None, None)."""
    try:
        form = conic_form_of(region)
    except (TypeError, ValueError, AttributeError, NotImplementedError):
        return None, None
    if form.kind != ConeKind.SEGMENT or form.convexified or form.direction is None:
        return None, None
    return np.asarray(form.center, float), np.asarray(form.direction, float)


def polytope_axis(region) -> tuple | None:
    """(c, d, w, B, cb) of a region whose conic form is exactly a polytope ||B y + cb||_inf <= 1: its vertices lie
    within w of the axis c + tau d, |tau| <= 1, along the direction of its two farthest vertices (w padded for the
    vertices' rounding); None otherwise."""
    try:
        form = conic_form_of(region)
        V = np.asarray(polytope_vertices(form.B, form.c), float) if form.kind == ConeKind.POLYTOPE and \
            not form.convexified else None
    except (TypeError, ValueError, AttributeError, NotImplementedError):
        return None
    if V is None or len(V) < 2 or not np.all(np.isfinite(V)):
        return None
    diff = V[:, None] - V[None]
    i, j = np.unravel_index(np.argmax(np.einsum("ijk,ijk->ij", diff, diff)), diff.shape[:2])
    u = (V[i] - V[j]) / np.linalg.norm(V[i] - V[j])
    n = np.array([-u[1], u[0]])
    a, b = (V - V[j]) @ u, (V - V[j]) @ n
    c = V[j] + (a.max() + a.min()) / 2 * u + (b.max() + b.min()) / 2 * n
    L = (a.max() - a.min()) / 2
    w = (b.max() - b.min()) / 2 + 1e-6 * L + 1e-9 * float(np.max(np.abs(V)))
    return c, L * u, w, np.asarray(form.B, float), np.asarray(form.c, float)


def ellipse_axis(region) -> tuple | None:
    """(c, d, w, D) of a region whose conic form is exactly a filled ellipse (y - c)' D^-1 (y - c) <= 1: it lies within
    w (its minor semi-axis) of its major axis c + tau d, |tau| <= 1; None otherwise."""
    try:
        form = conic_form_of(region)
    except (TypeError, ValueError, AttributeError, NotImplementedError):
        return None
    if form.kind != ConeKind.ELLIPSE or form.convexified:
        return None
    D = np.asarray(form.D, float)
    _, axes, Q, _, lam = shape_fields(D[None])            # exact to round-off for thin ellipses (not eigh's)
    if not (lam[0, 0] > 0 and np.all(np.isfinite(lam)) and np.all(np.isfinite(Q))):
        return None
    c = np.asarray(form.center, float)
    return c, float(axes[0, 0]) * Q[0, :, 0], float(axes[0, 1]) * (1 + 1e-12), D


def _cut(cams, regions, s, h, r, radii, axis) -> tuple | None:
    """(u, mid, half) of the slab across the axis (c, d, w) of view s's region that holds the closest point (module
    docstring): |u . y - u . mid| <= half; None where the region is not long and thin or the slab is not at most
    :data:`TRIM_SHARE` of it."""
    c, d, w = axis
    L = float(np.hypot(d[0], d[1]))
    if not (L > TRIM_MIN_RATIO * (r + w) and w < TRIM_SHARE * L):
        return None
    iv = segment_interval(cams, regions, s, h[:2] / h[2], r, radii, line=(c, d, w), reach=r)
    if iv is None or (iv[1] - iv[0]) / 2 > TRIM_SHARE:
        return None
    mid, half = c + (iv[0] + iv[1]) / 2 * d, (iv[1] - iv[0]) / 2 * L
    return (d / L, mid, half) if half > 0 else None


def _trimmed_by(cams, regions, s, h, r, radii, axis_of, build):
    """View s's region cut by the slab across the axis that ``axis_of`` gives it (:func:`polytope_axis`,
    :func:`ellipse_axis`) where the closest point can be (:func:`_cut`), built by ``build(axis, u, mid, half)``; None
    where it is not cut."""
    ax = axis_of(regions[s])
    cut = None if ax is None else _cut(cams, regions, s, h, r, radii, ax[:3])
    if cut is None:
        return None
    try:
        return build(ax, *cut)
    except (ValueError, ArithmeticError):        # (an empty cut in floats: left as it is)
        return None


def _polytope_cut(ax, u, mid, half) -> Polytope:
    """The polytope with one more slab row, |u . y - u . mid| <= half."""
    return Polytope(np.vstack([ax[3], u / half]), np.append(ax[4], -float(u @ mid) / half))


def _ellipse_cut(ax, u, mid, half) -> ClippedEllipse:
    """The filled ellipse cut by the slab (:class:`~tritools.model.regions.clipped.ClippedEllipse`)."""
    return ClippedEllipse(Ellipse(ax[0], ax[3]), u, float(u @ mid), half)


#: the region kinds cut across their axis, tried in this order: (the axis, the cut region)
_CUTS = ((polytope_axis, _polytope_cut), (ellipse_axis, _ellipse_cut))


def trimmed_regions(cams: np.ndarray, regions, X: np.ndarray, f_ub: float, radii) -> tuple | None:
    """The regions with every long segment (a region whose conic form is a segment, :func:`segment_of`; at least
    :data:`TRIM_MIN_RATIO` r long) replaced by its part that can hold the closest point (:func:`segment_interval`,
    kept where at most :data:`TRIM_SHARE` of it), for the local estimate X (world frame) and f_UB >= f*; None where
    no segment is trimmed."""
    r = math.sqrt(f_ub * (1 + 1e-9)) if f_ub >= 0 and math.isfinite(f_ub) else math.inf
    if not math.isfinite(r):
        return None
    out, changed = list(regions), False
    with np.errstate(all="ignore"):
        Xh = np.append(np.asarray(X, float), 1.0)
        for s, reg in enumerate(regions):
            c, d = segment_of(reg)
            h = cams[s] @ Xh
            if c is None:
                cut = next((x for x in (_trimmed_by(cams, regions, s, h, r, radii, *kind) for kind in _CUTS)
                            if x is not None), None)
                if cut is not None:
                    out[s], changed = cut, True
                continue
            if not float(np.hypot(d[0], d[1])) > TRIM_MIN_RATIO * r:
                continue
            iv = segment_interval(cams, regions, s, h[:2] / h[2], r, radii)
            if iv is None or (iv[1] - iv[0]) / 2 > TRIM_SHARE:
                continue
            out[s] = Segment(c + (iv[0] + iv[1]) / 2 * d, (iv[1] - iv[0]) / 2 * d)
            changed = True
    return tuple(out) if changed else None
