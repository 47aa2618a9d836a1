"""One closest point per view for the regions of a problem, stacked by kind.

A local refinement evaluates ``x_i - Pi_{R_i}(x_i)`` for every view i (paper eq. (7): d(x_i, R_i) = ||x_i -
Pi_{R_i}(x_i)||) dozens of times; one region method call per view costs ~30-70 us of Python and numpy overhead, so
30 mixed views took ~2 ms per evaluation and the local estimate ~45 ms.  :class:`RegionStack` groups the views once
by region kind and evaluates each kind with the rule of its class on stacked parameters:

* :class:`~.point.Point`: the centre;
* :class:`~.point.Segment`: x^ + t* d^ with t* from :func:`~.point.segment_parameters`;
* :class:`~.ellipse.EllipseBorder` and :class:`~.ellipse.Ellipse`: the level (:func:`~.ellipse.ellipse_levels`, the
  filled ellipse keeps a point with level <= 1), the rotation into the axes (:func:`~.ellipse.rotate`) and
  Eberly's scalar bisection per view (the single point's path);
* any other region (polytopes, user classes): its own ``closest_point``, one view at a time.

The stacked rules are the classes' own functions on the same operands, so every closest point is the one the
region's ``closest_point`` gives for that single point, bit for bit (tests/test_region_stack.py).

:meth:`RegionStack.residual_derivatives` gives the derivative of each residual x_i - Pi(x_i), so the refinement's
Levenberg-Marquardt has an analytic Jacobian instead of forward differences (three more evaluations per iteration);
the last closest points are remembered, since the Jacobian is asked for at the point just evaluated.  With both, the
local estimate of 30 mixed views fell from ~45 ms to ~12 ms.
"""
from __future__ import annotations

import numpy as np

from .ellipse import Ellipse, EllipseBorder, ellipse_closest_scalar, ellipse_levels, rotate
from .point import Point, Segment, segment_parameters, segment_scaling
from .polytope import Polytope

__all__ = ["RegionStack", "MIN_CURVATURE_FACTOR"]

#: the least denominator 1 - kappa n of the border projection's derivative inside an ellipse (near its evolute the
#: projection is not differentiable; the Jacobian only steers the refinement)
MIN_CURVATURE_FACTOR = 0.1


class _Ellipses:
    """The ellipses (border or filled) of a stack: their view indices and stacked shape fields."""

    def __init__(self, idx: np.ndarray, regions: tuple) -> None:
        self.idx = idx
        self.axes, self.Q, self.Dinv = EllipseBorder.stacked_shapes([regions[i] for i in idx])
        self.axes_list = self.axes.tolist()           # Python floats for the scalar bisection


class RegionStack:
    """The regions of N views grouped by kind (module docstring); :meth:`closest` and :meth:`distances` take one
    finite image point per view."""

    def __init__(self, regions) -> None:
        self.regions = tuple(regions)
        kinds = [type(r) for r in self.regions]
        self.point = np.array([i for i, k in enumerate(kinds) if k is Point], int)
        self.segment = np.array([i for i, k in enumerate(kinds) if k is Segment], int)
        self.border = np.array([i for i, k in enumerate(kinds) if k is EllipseBorder], int)
        self.filled = np.array([i for i, k in enumerate(kinds) if k is Ellipse], int)
        self.other = [i for i, k in enumerate(kinds) if k not in (Point, Segment, EllipseBorder, Ellipse)]
        self._memo = None
        self._centres = np.array([r.x if k is Point else r.center_ if k in (Segment, EllipseBorder, Ellipse)
                                  else np.zeros(2) for r, k in zip(self.regions, kinds)], float).reshape(-1, 2)
        if self.segment.size:
            self._dirs = np.array([self.regions[i].direction for i in self.segment], float)
            self._seg = segment_scaling(self._dirs)
        self._ellipses = {"border": _Ellipses(self.border, self.regions),
                          "filled": _Ellipses(self.filled, self.regions)}
        self._Dinv = self._ellipses["filled"].Dinv

    @classmethod
    def of(cls, regions) -> RegionStack:
        """``regions`` itself when it is a stack already, else the stack of the sequence."""
        return regions if isinstance(regions, cls) else cls(regions)

    def __len__(self) -> int:
        return len(self.regions)

    def __iter__(self):
        return iter(self.regions)

    def __getitem__(self, i):
        return self.regions[i]

    def closest(self, U: np.ndarray) -> np.ndarray:
        """Pi_{R_i}(u_i) for U (N, 2), one finite point per view (ValueError otherwise, like ``closest_point``)."""
        U = np.asarray(U, float)
        if U.shape != (len(self.regions), 2):
            raise ValueError(f"points must have shape ({len(self.regions)}, 2), got {U.shape}")
        if not np.all(np.isfinite(U)):
            raise ValueError("points must be finite")
        if self._memo is not None and np.array_equal(U, self._memo[0]):
            return self._memo[1].copy()          # the refinement asks for its residuals' Jacobian at the same point
        C = self._centres
        out = np.empty_like(U)
        if self.point.size:
            out[self.point] = C[self.point]
        if self.segment.size:
            i = self.segment
            s, u, uu = self._seg
            t = segment_parameters(U[i] - C[i], s, u, uu)
            out[i] = C[i] + t[:, None] * self._dirs
        if self.border.size:
            out[self.border] = self._on_border(U, "border")
        if self.filled.size:
            i = self.filled
            inside = ellipse_levels(U[i] - C[i], self._Dinv) <= 1.0
            out[i] = U[i]
            if not np.all(inside):
                out[i[~inside]] = self._on_border(U, "filled", ~inside)
        for i in self.other:
            out[i] = np.asarray(self.regions[i].closest_point(U[i]), float).reshape(2)
        self._memo = (U.copy(), out.copy())
        return out

    def _on_border(self, U: np.ndarray, group: str, keep: np.ndarray | None = None) -> np.ndarray:
        """The closest border points of the ellipses of ``group`` (the rows ``keep`` of them): EllipseBorder's rule,
        the rotations stacked and the scalar bisection per view (a vectorised bisection makes ~50 passes of a dozen
        numpy operations: slower than the scalar loop for the few ellipses of one problem)."""
        g = self._ellipses[group]
        idx, Q, axes = g.idx, g.Q, g.axes_list
        rows = np.arange(len(idx)) if keep is None else np.flatnonzero(keep)
        C = self._centres[idx[rows]]
        Y = rotate(U[idx[rows]] - C, Q[rows])
        X = np.empty_like(Y)
        for k, (r, (a, b)) in enumerate(zip(rows.tolist(), Y.tolist())):
            x0, x1 = ellipse_closest_scalar(axes[r][0], axes[r][1], abs(a), abs(b))
            X[k] = (-x0 if a < 0 else x0, -x1 if b < 0 else x1)
        return C + rotate(X, Q[rows], back=True)

    def residual_derivatives(self, U: np.ndarray) -> np.ndarray:
        """D_i = d(u_i - Pi_{R_i}(u_i)) / d u_i (N, 2, 2) where the projection is differentiable, for the local
        refinement's analytic Jacobian (any value is safe there: it only steers Levenberg-Marquardt).  I - JPi with
        JPi = 0 at a point (and at a segment's end), d d'/||d||^2 inside a segment, I inside a filled ellipse
        (D = 0), and for a point at distance n from an ellipse's border with foot point p: JPi = t t' / (1 +- kappa
        n), t the unit tangent and kappa = a b / (a^2 y^2 / b^2 + b^2 x^2 / a^2)^(3/2) the curvature at p (in its
        axes), + outside the ellipse, - inside (the denominator kept >= :data:`MIN_CURVATURE_FACTOR`).  Polygons:
        I inside, t t' on an edge (t along it), 0 at a vertex.  Other regions: central differences of their
        ``closest_point`` with steps of 1e-6 of the point's size (at least 1e-6)."""
        U = np.asarray(U, float)
        P = self.closest(U)
        N = len(self.regions)
        J = np.zeros((N, 2, 2))                       # JPi
        if self.segment.size:
            i = self.segment
            s, u, uu = self._seg
            t = segment_parameters(U[i] - self._centres[i], s, u, uu)
            inner = (np.abs(t) < 1.0) & (s > 0)
            with np.errstate(divide="ignore", invalid="ignore"):
                J[i] = np.where(inner[:, None, None], u[:, :, None] * u[:, None, :] / uu[:, None, None], 0.0)
        for g in self._ellipses.values():
            if g.idx.size:
                J[g.idx] = self._border_jacobian(U[g.idx], P[g.idx], g)
        if self.filled.size:
            i = self.filled
            inside = ellipse_levels(U[i] - self._centres[i], self._Dinv) <= 1.0
            J[i[inside]] = np.eye(2)
        for i in self.other:
            r = self.regions[i]
            if type(r) is Polytope:
                J[i] = _polygon_jacobian(U[i], P[i], r.vertices)
                continue
            h = 1e-6 * max(1.0, float(np.max(np.abs(U[i]))))
            for k in range(2):
                e = np.zeros(2)
                e[k] = h
                J[i, :, k] = (np.asarray(r.closest_point(U[i] + e), float) - r.closest_point(U[i] - e)) / (2 * h)
        return np.eye(2) - J

    def _border_jacobian(self, U: np.ndarray, P: np.ndarray, g: _Ellipses) -> np.ndarray:
        """JPi of the projection onto the ellipses' borders (:meth:`residual_derivatives`) at the foot points P."""
        Q, ax = g.Q, g.axes
        c = self._centres[g.idx]
        x, y = rotate(P - c, Q).T
        a, b = ax[:, 0], ax[:, 1]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            kappa = a * b / (a * a * y * y / (b * b) + b * b * x * x / (a * a)) ** 1.5
            tl = np.column_stack([-a * y / b, b * x / a])
            tl = tl / np.hypot(tl[:, 0], tl[:, 1])[:, None]
            t = rotate(tl, Q, back=True)
            n = np.hypot(*(U - P).T)
            outside = ellipse_levels(U - c, g.Dinv) > 1.0
            den = np.maximum(np.where(outside, 1.0 + kappa * n, 1.0 - kappa * n), MIN_CURVATURE_FACTOR)
            J = t[:, :, None] * t[:, None, :] / den[:, None, None]
        return np.where(np.isfinite(J), J, 0.0)

    def distances(self, U: np.ndarray) -> np.ndarray:
        """d(u_i, R_i) (N,): ``Region.distance``'s norm of u_i - Pi_{R_i}(u_i)."""
        U = np.asarray(U, float)
        P = self.closest(U)
        return np.hypot(U[:, 0] - P[:, 0], U[:, 1] - P[:, 1])


def _polygon_jacobian(u: np.ndarray, p: np.ndarray, V: np.ndarray) -> np.ndarray:
    """JPi of a polygon's projection at u with closest point p: I inside (p = u), 0 at a vertex (p within 1e-12 of
    the polygon's size of one), else t t' for the edge through p (t perpendicular to u - p)."""
    e = u - p
    n = float(np.hypot(e[0], e[1]))
    if n == 0.0:
        return np.eye(2)
    size = max(1e-300, float(np.max(np.abs(V - V.mean(axis=0)))))
    if np.min(np.hypot(V[:, 0] - p[0], V[:, 1] - p[1])) <= 1e-12 * size:
        return np.zeros((2, 2))
    t = np.array([-e[1], e[0]]) / n
    return np.outer(t, t)

