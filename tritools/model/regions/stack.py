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
"""
from __future__ import annotations

import numpy as np

from .ellipse import Ellipse, EllipseBorder, ellipse_closest_scalar, ellipse_levels, rotate
from .point import Point, Segment, segment_parameters, segment_scaling

__all__ = ["RegionStack"]


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
        self._centres = np.array([r.x if k is Point else r.center_ if k in (Segment, EllipseBorder, Ellipse)
                                  else np.zeros(2) for r, k in zip(self.regions, kinds)], float).reshape(-1, 2)
        if self.segment.size:
            self._dirs = np.array([self.regions[i].direction for i in self.segment], float)
            self._seg = segment_scaling(self._dirs)
        self._Q, self._axes = {}, {}
        for a in (self.border, self.filled):
            axes, self._Q[id(a)], Dinv = EllipseBorder.stacked_shapes([self.regions[i] for i in a])
            self._axes[id(a)] = axes.tolist()
            if a is self.filled:
                self._Dinv = Dinv

    def __len__(self) -> int:
        return len(self.regions)

    def closest(self, U: np.ndarray) -> np.ndarray:
        """Pi_{R_i}(u_i) for U (N, 2), one finite point per view (ValueError otherwise, like ``closest_point``)."""
        U = np.asarray(U, float)
        if U.shape != (len(self.regions), 2):
            raise ValueError(f"points must have shape ({len(self.regions)}, 2), got {U.shape}")
        if not np.all(np.isfinite(U)):
            raise ValueError("points must be finite")
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
            out[self.border] = self._on_border(U, self.border)
        if self.filled.size:
            i = self.filled
            inside = ellipse_levels(U[i] - C[i], self._Dinv) <= 1.0
            out[i] = U[i]
            if not np.all(inside):
                out[i[~inside]] = self._on_border(U, i, ~inside)
        for i in self.other:
            out[i] = np.asarray(self.regions[i].closest_point(U[i]), float).reshape(2)
        return out

    def _on_border(self, U: np.ndarray, idx: np.ndarray, keep: np.ndarray | None = None) -> np.ndarray:
        """The closest border points of the ellipses ``idx`` (the rows ``keep`` of them): EllipseBorder's rule, the
        rotations stacked and the scalar bisection per view (a vectorised bisection makes ~50 passes of a dozen numpy
        operations: slower than the scalar loop for the few ellipses of one problem)."""
        Q, axes = self._Q[id(idx)], self._axes[id(idx)]
        rows = np.arange(len(idx)) if keep is None else np.flatnonzero(keep)
        C = self._centres[idx[rows]]
        Y = rotate(U[idx[rows]] - C, Q[rows])
        X = np.empty_like(Y)
        for k, (r, (a, b)) in enumerate(zip(rows.tolist(), Y.tolist())):
            x0, x1 = ellipse_closest_scalar(axes[r][0], axes[r][1], abs(a), abs(b))
            X[k] = (-x0 if a < 0 else x0, -x1 if b < 0 else x1)
        return C + rotate(X, Q[rows], back=True)

    def distances(self, U: np.ndarray) -> np.ndarray:
        """d(u_i, R_i) (N,): ``Region.distance``'s norm of u_i - Pi_{R_i}(u_i)."""
        U = np.asarray(U, float)
        P = self.closest(U)
        return np.hypot(U[:, 0] - P[:, 0], U[:, 1] - P[:, 1])
