"""Case III of SPEC §2: the convex polygon ``{y : ||B y + c||_inf <= 1}`` and its vertices.

The polygon is the intersection of the ``2m`` half-planes ``+-(B_k y + c_k) <= 1``.  Its
vertices come from the classical half-plane intersection by angular sweep (sort the unit
normals by angle, keep the tightest of parallel ones, then one pass with a deque: O(m log m)
time, O(m) memory), see :func:`polytope_vertices`.  Distances and containment are vectorised
over points and edges in blocks of :data:`POLYTOPE_CHUNK` numbers, so memory stays
O(m + points) whatever the number of edges.
"""
from __future__ import annotations

import functools
from collections import deque
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from ...errors import FieldError
from .polygon_distance import affine, closest_on_boundary, closest_on_boundary_one, unit_edges
from .base import (Region, RegionPolynomials, as_matrix, as_points, as_vector, check_xy, real_array, similarity_args,
                   square)
from .forms import ConeKind, ConicForm, RegionExtent

__all__ = ["Polytope", "polytope_vertices", "POLYTOPE_RANK_RTOL", "POLYTOPE_VERTEX_RTOL", "POLYTOPE_ROUNDOFF",
           "POLYTOPE_CHUNK"]

#: ``rank(B) < 2`` (an unbounded polytope) if ``sigma_2 <= POLYTOPE_RANK_RTOL * sigma_1`` for ``B``'s
#: nonzero rows scaled to unit norm (the normals' directions; the slab widths do not matter).
POLYTOPE_RANK_RTOL = 1e-12
#: Relative to the diameter of a set found without interior (touching slabs): vertices closer
#: than this are merged, and a set thinner than this is reported as the segment (or point) it
#: degenerates to.  A polygon with interior is only merged within its floating-point slack.
POLYTOPE_VERTEX_RTOL = 1e-9
#: Floating-point slack of a boundary line ``B_k y + c_k = +-1``, relative to the magnitudes
#: ``(1 + |c_k|) / ||B_k||`` and ``||y0||`` that place it: a set that is empty only by this
#: much (touching slabs, a polygon shrunk to a segment or a point) is not empty.
POLYTOPE_ROUNDOFF = 64 * float(np.finfo(float).eps)
#: Block size (number of float entries) of the point x edge and point x row computations.
POLYTOPE_CHUNK = 1 << 18
#: Two unit normals whose cross product is at most this are parallel.
_PARALLEL_ATOL = 1e-13


# ----------------------------------------------------------------------------- vertices
def polytope_vertices(B, c) -> np.ndarray:
    """Vertices of ``{y : ||B y + c||_inf <= 1}``, ``B`` of shape (m, 2), ``c`` of shape (m,).

    Algorithm (O(m log m) time, O(m) memory):

    1. A zero row ``B_k`` is always satisfied if ``|c_k| <= 1`` (dropped) and makes the set
       empty otherwise.  ``rank(B) < 2`` (singular values of the nonzero rows scaled to unit
       norm, see :data:`POLYTOPE_RANK_RTOL`) means unbounded.
    2. In coordinates ``z = y - y0`` (``y0`` the least-squares solution of ``B y = -c``, to keep
       the numbers small), the set is ``{z : n_j . z <= b_j}`` for the ``2m`` unit normals
       ``n_j = +-B_k / ||B_k||``.  They are sorted by angle and, among parallel ones with the
       same direction (duplicate rows, the same slab given twice), only the smallest ``b_j``
       is kept.
    3. Angular sweep with a deque: each half-plane in turn removes from the back, then from the
       front, the lines whose last vertex lies outside it; a turn of pi or more between
       consecutive lines means the intersection is empty.  The remaining cycle of lines, in
       counter-clockwise order, bounds the polygon; its vertices are the intersections of
       consecutive lines.  The result is checked in O(m log m): no inverted edge, and every
       half-plane holds at its support vertex (found by binary search on the angles).
    4. If the sweep finds the set empty, or the check fails, the sweep is repeated with every
       ``b_j`` enlarged by its floating-point slack (:data:`POLYTOPE_ROUNDOFF`): if that is
       empty too the polytope is empty; otherwise the set has no interior (touching slabs: a
       segment or a point), and its vertices are the intersections of the enlarged cycle's
       consecutive lines at their original offsets.
    5. Vertices closer than the lines' floating-point slack are merged (for a set without
       interior, found in step 4: closer than ``POLYTOPE_VERTEX_RTOL * diameter``), a polygon
       thinner than that is reduced to its two extreme points (a segment) or one point, and the
       vertices are returned ordered counter-clockwise by angle around their mean.  A polygon
       with interior keeps its width whatever its aspect ratio.

    Returns
    -------
    ndarray, shape (k, 2)
        ``k >= 3`` for a polygon with interior, 2 for a segment, 1 for a point.

    Raises
    ------
    ValueError
        Bad ``B`` or ``c`` (not real, not finite, wrong shapes), ``rank(B) < 2`` (unbounded),
        an empty set, or vertices beyond the floating-point range.
    """
    B, c = _check_bc(B, c)
    return _vertices(B, c)


def _check_bc(B, c) -> tuple[np.ndarray, np.ndarray]:
    """Validated ``(B, c)``: real, finite, shapes (m, 2) and (m,), m >= 2, rank(B) = 2."""
    B = as_matrix(B, "B", (None, 2))
    m = B.shape[0]
    if m < 2:
        raise FieldError("B", f"must have at least 2 rows for a bounded polytope, got shape {B.shape}")
    c_arr = real_array(c, "c")
    if c_arr.shape != (m,):
        raise FieldError("c", f"must have shape ({m},) to match B {B.shape}, got {c_arr.shape}")
    c = as_vector(c_arr, "c", m)
    nrm = np.hypot(B[:, 0], B[:, 1])
    U = B[nrm > 0] / nrm[nrm > 0, None]
    sv = np.linalg.svd(U, compute_uv=False) if len(U) else np.zeros(2)
    if len(sv) < 2 or sv[0] == 0 or sv[-1] <= POLYTOPE_RANK_RTOL * sv[0]:
        raise FieldError("B", f"has rank < 2 (singular values of its rows scaled to unit norm: {sv.tolist()}): "
                              f"the polytope is unbounded")
    return B, c


def _nxt(a: np.ndarray) -> np.ndarray:
    """``np.roll(a, -1, axis=0)`` (the next element, cyclically) without np.roll's overhead on small arrays."""
    return np.concatenate((a[1:], a[:1]))


def _prv(a: np.ndarray) -> np.ndarray:
    """``np.roll(a, 1, axis=0)`` (the previous element, cyclically)."""
    return np.concatenate((a[-1:], a[:-1]))


def _halfplanes(B: np.ndarray, c: np.ndarray):
    """(normals (n, 2), offsets (n,), slack (n,), y0 (2,)) of the half-planes, sorted by angle,
    parallel duplicates merged; raises for an empty set found on the way."""
    nrm = np.hypot(B[:, 0], B[:, 1])
    zero = nrm == 0.0
    bad = np.flatnonzero(zero & (np.abs(c) > 1.0))
    if bad.size:
        k = int(bad[0])
        raise ValueError(f"polytope is empty: row {k} of B is zero and |c[{k}]| = {abs(c[k])} > 1")
    B, c, nrm = B[~zero], c[~zero], nrm[~zero]
    U = B / nrm[:, None]
    s = float(np.max(np.abs(B)))
    y0 = np.linalg.lstsq(B / s, -c / s, rcond=None)[0]
    if not np.isfinite(y0).all():
        y0 = np.zeros(2)
    with np.errstate(over="ignore", invalid="ignore"):
        Uy0 = U @ y0
        hi = (1.0 - c) / nrm - Uy0           # U z <= hi
        lo = (1.0 + c) / nrm + Uy0           # -U z <= lo
        mag = (1.0 + np.abs(c)) / nrm + float(np.max(np.abs(y0)))
    N = np.vstack([U, -U])
    b = np.concatenate([hi, lo])
    slack = POLYTOPE_ROUNDOFF * np.concatenate([mag, mag])
    if np.any(np.isnan(b)) or np.any(b == -np.inf):
        raise ValueError("polytope is empty (a boundary line lies beyond the floating-point range)")
    keep = b < np.inf                         # a line at +infinity constrains nothing
    N, b, slack = N[keep], b[keep], slack[keep]
    order = np.argsort(np.arctan2(N[:, 1], N[:, 0]), kind="stable")
    N, b, slack = N[order], b[order], slack[order]
    # merge runs of parallel normals with the same direction (cyclically), keeping the smallest b
    nxt = _nxt(N)
    same_next = (np.abs(N[:, 0] * nxt[:, 1] - N[:, 1] * nxt[:, 0]) <= _PARALLEL_ATOL) & (np.sum(N * nxt, axis=1) > 0)
    gid = np.concatenate([[0], np.cumsum(~same_next[:-1])])
    if len(N) > 1 and same_next[-1]:
        gid[gid == gid[-1]] = 0
    pick = np.lexsort((b, gid))
    first = np.concatenate([[True], gid[pick][1:] != gid[pick][:-1]])
    sel = pick[first]
    sel = sel[np.argsort(np.arctan2(N[sel, 1], N[sel, 0]), kind="stable")]
    return N[sel], b[sel], slack[sel], y0


def _sweep(N: np.ndarray, b: np.ndarray) -> list[int] | None:
    """Indices of the half-planes ``N_k . z <= b_k`` (sorted by angle, no two with the same
    direction) that bound their intersection, counter-clockwise; None if it is empty."""
    n0, n1, bb = N[:, 0].tolist(), N[:, 1].tolist(), b.tolist()

    def outside(k: int, i: int, j: int) -> bool:
        # is the vertex of lines i, j (consecutive, so det > 0) strictly outside half-plane k?
        det = n0[i] * n1[j] - n1[i] * n0[j]
        x = (bb[i] * n1[j] - n1[i] * bb[j]) / det
        y = (n0[i] * bb[j] - bb[i] * n0[j]) / det
        return n0[k] * x + n1[k] * y > bb[k]

    def turns(i: int, j: int) -> bool:
        # line j follows line i counter-clockwise by less than pi
        return n0[i] * n1[j] - n1[i] * n0[j] > _PARALLEL_ATOL

    dq: deque[int] = deque()
    for k in range(len(bb)):
        while len(dq) >= 2 and outside(k, dq[-2], dq[-1]):
            dq.pop()
        while len(dq) >= 2 and outside(k, dq[0], dq[1]):
            dq.popleft()
        if dq and not turns(dq[-1], k):
            return None
        dq.append(k)
    while len(dq) >= 3 and outside(dq[0], dq[-2], dq[-1]):
        dq.pop()
    while len(dq) >= 3 and outside(dq[-1], dq[0], dq[1]):
        dq.popleft()
    if len(dq) < 3 or not turns(dq[-1], dq[0]):
        return None
    return list(dq)


def _corners(N: np.ndarray, b: np.ndarray, cycle: list[int]) -> np.ndarray:
    """Intersections of consecutive lines of ``cycle`` (k, 2)."""
    i = np.asarray(cycle)
    j = _nxt(i)
    det = N[i, 0] * N[j, 1] - N[i, 1] * N[j, 0]
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        x = (b[i] * N[j, 1] - N[i, 1] * b[j]) / det
        y = (N[i, 0] * b[j] - b[i] * N[j, 0]) / det
    return np.column_stack([x, y])


def _consistent(V: np.ndarray, N: np.ndarray, b: np.ndarray, slack: np.ndarray, cycle: list[int]) -> bool:
    """Check a sweep result in O(n log k): vertices finite; every edge runs counter-clockwise along
    its line (no inverted edge); every half-plane holds at its support vertex, the vertex between
    the two cycle normals that bracket its angle (where ``n_j . z`` is largest on a convex polygon).
    Allowed errors: the line's slack plus the rounding of the vertex, ``POLYTOPE_ROUNDOFF *
    (|v| + (|b_k| + |b_k+1|) / det)`` (Cramer's rule for two lines at a small angle)."""
    if not np.isfinite(V).all():
        return False
    i = np.asarray(cycle)
    j = _nxt(i)
    det = N[i, 0] * N[j, 1] - N[i, 1] * N[j, 0]
    err = POLYTOPE_ROUNDOFF * (np.max(np.abs(V), axis=1) + (np.abs(b[i]) + np.abs(b[j])) / det)
    prev = _prv(V)
    along = (V[:, 1] - prev[:, 1]) * N[i, 0] - (V[:, 0] - prev[:, 0]) * N[i, 1]    # (V_k - V_k-1) . (-n_y, n_x)
    if np.any(along < -(err + _prv(err))):
        return False
    ang = np.arctan2(N[:, 1], N[:, 0])
    k = (np.searchsorted(ang[i], ang, side="right") - 1) % len(i)
    return bool(np.all(np.sum(N * V[k], axis=1) - b <= slack + err[k]))


def _vertices(B: np.ndarray, c: np.ndarray) -> np.ndarray:
    N, b, slack, y0 = _halfplanes(B, c)
    cycle = _sweep(N, b)
    V = _corners(N, b, cycle) if cycle is not None else None
    interior = V is not None and _consistent(V, N, b, slack, cycle)
    if not interior:
        cycle = _sweep(N, b + slack)
        if cycle is None:
            raise ValueError("polytope {y : ||B y + c||_inf <= 1} is empty")
        V = _corners(N, b, cycle)
        if not np.isfinite(V).all():
            V = _corners(N, b + slack, cycle)
    if not np.isfinite(V).all():
        raise ValueError("polytope vertices are beyond the floating-point range")
    V = _simplify(V, 16.0 * float(np.max(slack[cycle])), relative=not interior)
    V = V + y0
    if not np.isfinite(V).all():
        raise ValueError("polytope vertices are beyond the floating-point range")
    mean = (V / 2.0).mean(axis=0) * 2.0                    # halved: no overflow near the float limit
    return V[np.argsort(np.arctan2(V[:, 1] - mean[1], V[:, 0] - mean[0]), kind="stable")]


def _simplify(V: np.ndarray, floor: float, relative: bool = True) -> np.ndarray:
    """Merge consecutive vertices (cyclic) closer than ``tol``; reduce a polygon thinner than
    ``tol`` to its extreme points.  ``tol`` is the floating-point slack ``floor`` of the lines; for
    a set found without interior by the sweep (``relative``) at least ``POLYTOPE_VERTEX_RTOL *
    diameter``.  A polygon with interior is never thinned by its aspect ratio: a 2 x 1e10 box keeps
    its width, which decides distances of the order of the width (issue 24)."""
    centred = V - V.mean(axis=0)
    axis = np.linalg.svd(centred, full_matrices=False)[2][0] if len(V) > 1 else np.array([1.0, 0.0])
    proj = centred @ axis
    diam = float(np.ptp(proj)) if len(V) > 1 else 0.0
    tol = max(POLYTOPE_VERTEX_RTOL * diam, floor) if relative else floor
    if diam <= tol:
        return V[[int(np.argmin(np.hypot(*centred.T)))]]
    step = np.hypot(*(V[1:] - V[:-1]).T)                  # runs of coincident consecutive vertices -> one
    keep = list(np.flatnonzero(np.concatenate([[True], step > tol])))
    while len(keep) > 1 and np.hypot(*(V[keep[-1]] - V[keep[0]])) <= tol:
        keep.pop()
    W = V[keep]
    if len(W) >= 3:
        x, y = (W[:, 0] - W[:, 0].mean()) / diam, (W[:, 1] - W[:, 1].mean()) / diam    # no under/overflow
        area = 0.5 * abs(float(np.sum(x * _nxt(y) - _nxt(x) * y)))        # relative to diam^2
        if 2.0 * area * diam > tol:
            return W
    return V[[int(np.argmin(proj)), int(np.argmax(proj))]]


def _centroid(V: np.ndarray) -> np.ndarray:
    """Area centroid of the convex polygon ``V`` (counter-clockwise), the vertex mean if it is degenerate."""
    mean = V / 2.0
    mean = mean.mean(axis=0) * 2.0                          # halved: no overflow near the float limit
    if len(V) < 3:
        return mean
    span = float(np.max(np.abs(V - mean)))
    x, y = (V[:, 0] - mean[0]) / span, (V[:, 1] - mean[1]) / span     # the shape at unit scale
    xn, yn = _nxt(x), _nxt(y)
    cross = x * yn - xn * y
    area = cross.sum() / 2.0
    if abs(area) <= 1e-14:
        return mean
    return mean + span * np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (6.0 * area)


# ----------------------------------------------------------------------------- the region
@dataclass(frozen=True, eq=False)
class Polytope(Region):
    """Case III: ``R = {y : ||B y + c||_inf <= 1}``, ``B`` of shape (m, 2); ``n = 2``,
    ``f = ||x - y||^2``, ``h_k = 1 - (B y + c)_k^2``, k = 1..m (paper Section 4.2).

    The polygon's vertices are computed at construction by :func:`polytope_vertices`
    (angular sweep over the ``2m`` half-planes, O(m log m)), ordered counter-clockwise by
    angle around their mean; a polytope without interior (touching slabs) keeps the 2
    endpoints of its segment or its single point.

    Raises
    ------
    ValueError
        If ``rank(B) < 2`` (unbounded set) or the set is empty.
    """

    B: np.ndarray
    c: np.ndarray
    vertices: np.ndarray = field(init=False, repr=False)
    kind: ClassVar[str] = "polytope"

    def __post_init__(self) -> None:
        B, c = _check_bc(self.B, self.c)
        object.__setattr__(self, "B", B)
        object.__setattr__(self, "c", c)
        V = _vertices(B, c)
        V.setflags(write=False)
        object.__setattr__(self, "vertices", V)

    @property
    def n_aux(self) -> int:
        return 2

    def polynomials(self, x, y) -> RegionPolynomials:
        x, y = check_xy(x, y, 2)
        f = square(x[0] - y[0]) + square(x[1] - y[1])
        h = tuple(1.0 - square(float(Bk[0]) * y[0] + float(Bk[1]) * y[1] + float(ck))
                  for Bk, ck in zip(self.B, self.c))
        return RegionPolynomials(f, (), h)

    def contains(self, points) -> bool | np.ndarray:
        """``||B p + c||_inf <= 1`` (exact test, no slack), in blocks of points."""
        P, single = as_points(points)
        inside = np.empty(len(P), dtype=bool)
        step = max(1, POLYTOPE_CHUNK // len(self.c))
        for s in range(0, len(P), step):
            with np.errstate(over="ignore", invalid="ignore"):       # overflow: far outside
                inside[s:s + step] = np.all(np.abs(affine(P[s:s + step], self.B, self.c)) <= 1.0, axis=1)
        return bool(inside[0]) if single else inside

    def closest_point(self, points) -> np.ndarray:
        P, single = as_points(points)
        if single:                                   # one point: the scalar twin of the boundary search
            with np.errstate(over="ignore", invalid="ignore"):
                inside = bool(np.all(np.abs(affine(P, self.B, self.c)) <= 1.0))     # contains' operation
            return P[0].copy() if inside else np.array(closest_on_boundary_one(P[0], self._unit_edges))
        C = P.copy()
        out = ~np.atleast_1d(self.contains(P))
        if np.any(out):
            C[out] = closest_on_boundary(P[out], self.vertices, POLYTOPE_CHUNK)
        return C

    @functools.cached_property
    def _unit_edges(self) -> tuple:
        """The boundary at unit scale for :func:`~.polygon_distance.closest_on_boundary_one`, once."""
        return unit_edges(self.vertices)

    @functools.cached_property
    def center(self) -> np.ndarray:
        """Area centroid of the polygon (vertex mean if it is degenerate); computed once, read-only."""
        out = _centroid(self.vertices)
        out.setflags(write=False)
        return out

    @property
    def center_offset(self) -> float:
        """0: the centroid (or vertex mean) of a convex polygon is one of its points."""
        return 0.0

    def similarity(self, scale, shift) -> Polytope:
        s, t = similarity_args(scale, shift)
        return Polytope(self.B / s, self.c + self.B @ t)

    def extent(self) -> RegionExtent:
        """``(rho, rho)``: the auxiliary ``y`` is a point of the polygon, and rho bounds its norm -- the largest
        vertex norm, padded by what the computed vertices may lose (vertices merged or a thin set reduced
        within ``POLYTOPE_VERTEX_RTOL`` of its size, lines placed within ``POLYTOPE_ROUNDOFF`` of their
        magnitudes ``(1 + |c_k|) / ||B_k||``, see :func:`polytope_vertices`)."""
        rho = float(np.max(np.hypot(self.vertices[:, 0], self.vertices[:, 1])))
        nrm = np.hypot(self.B[:, 0], self.B[:, 1])
        with np.errstate(over="ignore"):
            place = float(np.max((1.0 + np.abs(self.c[nrm > 0])) / nrm[nrm > 0]))
        rho += 4.0 * POLYTOPE_VERTEX_RTOL * rho + 64.0 * POLYTOPE_ROUNDOFF * place
        return RegionExtent.outward(rho, rho)

    def conic_form(self) -> ConicForm:
        """``(1 -+ c_k) s -+ B_k a >= 0``, k = 1..m."""
        return ConicForm(ConeKind.POLYTOPE, self.center, B=self.B, c=self.c)

    @classmethod
    def box(cls, center, half_widths) -> Polytope:
        """The axis-aligned rectangle ``|y_k - center_k| <= half_widths_k``."""
        c0 = as_vector(center, "center")
        w = as_vector(half_widths, "half_widths")
        if np.any(w <= 0):
            raise FieldError("half_widths", f"must be positive, got {w.tolist()}")
        B = np.diag(1.0 / w)
        return cls(B, -B @ c0)
