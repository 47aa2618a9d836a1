"""A filled ellipse cut by a slab across its axis: the part of a long thin ellipse that can hold the closest point.

``R = E ∩ S``, ``E = {y : (y - x^)' D^-1 (y - x^) <= 1}``, ``S = {y : |u . y - m| <= l}`` (``u`` a unit vector, ``l >
0``).  ``n = 2``, ``f = ||x - y||^2``, ``h = (1 - (y - x^)' D^-1 (y - x^), 1 - ((u . y - m) / l)^2)`` (paper Section
4.2: the constraints of a filled ellipse and of one polytope slab, as one region).

It is what :mod:`tritools.solve.trim` replaces a long thin filled ellipse by (a problem of the same optimum, scaled by
the cut part, not by the ellipse): built there, solved by the sub-problem stage's plan.  Its closest point: the
projection onto E where that lies in S; otherwise the projection lies on a line bounding S (an inactive slab would
make it the projection onto E), so it is the nearer of the projections onto the two chords ``E ∩ {u . y = m +- l}``.
It declares no conic form (the certified uncertainty and the verification paths do not take it: the SDP does).
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from .base import Region, RegionPolynomials, as_points, check_xy, similarity_args, square
from .ellipse import Ellipse
from .forms import RegionExtent

__all__ = ["ClippedEllipse"]

#: the extent's relative padding against the rounding of the rectangle holding the region
_PAD = 1e-9


@dataclass(frozen=True, eq=False)
class ClippedEllipse(Region):
    """``E ∩ {y : |u . y - m| <= half}`` (module docstring); ``axis`` is normalised to unit length.

    Raises
    ------
    ValueError
        If ``axis`` is zero or not finite, ``half`` is not positive and finite, or the cut is empty.
    """

    ellipse: Ellipse
    axis: np.ndarray
    m: float
    half: float
    _center: np.ndarray = field(init=False, repr=False)
    kind: ClassVar[str] = ""

    def __post_init__(self) -> None:
        if not isinstance(self.ellipse, Ellipse):
            raise TypeError(f"ClippedEllipse.ellipse must be an Ellipse, got {type(self.ellipse).__name__}")
        u = np.asarray(self.axis, float).reshape(2)
        n = float(np.hypot(u[0], u[1]))
        if not (n > 0 and math.isfinite(n)):
            raise ValueError(f"ClippedEllipse.axis must be a finite nonzero vector, got {u.tolist()}")
        m, half = float(self.m), float(self.half)
        if not (half > 0 and math.isfinite(half) and math.isfinite(m)):
            raise ValueError(f"ClippedEllipse needs a finite m and a positive finite half, got m={m}, half={half}")
        u = u / n
        u.setflags(write=False)
        object.__setattr__(self, "axis", u)
        object.__setattr__(self, "m", m)
        object.__setattr__(self, "half", half)
        mid = self.ellipse.center_ + (m - float(u @ self.ellipse.center_)) * u        # on the slab's middle line
        c = self.closest_point(mid)
        if not np.all(np.isfinite(c)) or abs(float(u @ c) - m) > half * (1 + 1e-9):
            raise ValueError("ClippedEllipse: the slab does not meet the ellipse")
        c.setflags(write=False)
        object.__setattr__(self, "_center", c)

    @property
    def exact_scale(self) -> bool:
        """The ellipse's (:attr:`EllipseBorder.exact_scale`): the cut keeps its shape."""
        return self.ellipse.exact_scale

    @property
    def n_aux(self) -> int:
        return 2

    def polynomials(self, x, y) -> RegionPolynomials:
        x, y = check_xy(x, y, 2)
        f = square(x[0] - y[0]) + square(x[1] - y[1])
        a0, a1, b = (float(self.axis[0] / self.half), float(self.axis[1] / self.half), float(-self.m / self.half))
        return RegionPolynomials(f, (), (self.ellipse._quadratic(y), 1.0 - square(a0 * y[0] + a1 * y[1] + b)))

    @functools.cached_property
    def _chords(self) -> list:
        """The chords ``E ∩ {u . y = m +- half}`` as (start, end) pairs (points), those that exist; computed once."""
        u = self.axis
        v = np.array([-u[1], u[0]])
        c, Dinv = self.ellipse.center_, self.ellipse._Dinv
        out = []
        uc = float(u @ c)
        for t in (self.m - self.half, self.m + self.half):
            w0 = (t - uc) * u               # the line's foot of the ellipse's centre, relative to it (review 43c:
            qa, qb, qc = float(v @ Dinv @ v), float(v @ Dinv @ w0), float(w0 @ Dinv @ w0) - 1.0   # not the origin's)
            disc = qb * qb - qa * qc
            if disc >= 0 and qa > 0:
                root = math.sqrt(disc)
                out.append((c + w0 + ((-qb - root) / qa) * v, c + w0 + ((-qb + root) / qa) * v))
        return out

    def closest_point(self, points) -> np.ndarray:
        P, single = as_points(points)
        C = np.atleast_2d(self.ellipse.closest_point(P))
        off = np.abs(C @ self.axis - self.m) > self.half
        if np.any(off):
            Q = P[off]
            best, dist = np.full_like(Q, np.nan), np.full(len(Q), np.inf)
            for a, b in self._chords:
                d = b - a
                dd = float(d @ d)
                t = np.clip((Q - a) @ d / dd, 0.0, 1.0) if dd > 0 else np.zeros(len(Q))
                Y = a + t[:, None] * d
                e = np.hypot(*(Q - Y).T)
                take = e < dist
                best[take], dist[take] = Y[take], e[take]
            C[off] = best
        return C[0] if single else C

    @property
    def center(self) -> np.ndarray:
        return self._center.copy()

    @property
    def center_offset(self) -> float:
        return 0.0

    def similarity(self, scale, shift) -> ClippedEllipse:
        """``y' = s (y - t)``: the ellipse's own similarity, the slab ``|u . y' - s (m - u . t)| <= s half``."""
        s, t = similarity_args(scale, shift)
        return ClippedEllipse(self.ellipse.similarity(s, t), self.axis, s * (self.m - float(self.axis @ t)),
                              s * self.half)

    def extent(self) -> RegionExtent:
        """``(rho, rho)``: the region lies in the rectangle ``|u . y - m| <= half``, ``|v . (y - x^)| <= sqrt(v' D v)``
        (v the normal of u: the ellipse's support across the axis), so ``||y|| <= ||m u + (v . x^) v|| +
        hypot(half, sqrt(v' D v))``, padded for the rounding."""
        u = self.axis
        v = np.array([-u[1], u[0]])
        width = math.sqrt(float(v @ self.ellipse.D @ v))
        mid = self.m * u + float(v @ self.ellipse.center_) * v
        rho = (math.hypot(*mid) + math.hypot(self.half, width)) * (1 + _PAD) + _PAD * math.hypot(*self.ellipse.center_)
        rho = min(rho, self.ellipse.extent().radius)
        return RegionExtent.outward(rho, rho)

    def _fields(self):
        return {"center": self.ellipse.center_.tolist(), "D": self.ellipse.D.tolist(), "axis": self.axis.tolist(),
                "m": self.m, "half": self.half}

    def __repr__(self) -> str:
        return (f"ClippedEllipse(ellipse={self.ellipse!r}, axis={self.axis.tolist()}, m={self.m!r}, "
                f"half={self.half!r})")
