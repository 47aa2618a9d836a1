"""Cases I and II of SPEC §2: a point ``{x^}`` and a segment ``{x^ + t d^ : t in [-1, 1]}``."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from .base import Region, RegionPolynomials, as_points, as_vector, check_xy, similarity_args, square
from .forms import ConeKind, ConicForm, RegionExtent

__all__ = ["Point", "Segment"]


# ----------------------------------------------------------------------------- I: point
@dataclass(frozen=True, eq=False)
class Point(Region):
    """Case I: ``R = {x^}``; ``n = 0``, ``f = ||x - x^||^2`` (paper Section 4.2)."""

    x: np.ndarray
    kind: ClassVar[str] = "point"

    def __post_init__(self) -> None:
        object.__setattr__(self, "x", as_vector(self.x, "x"))

    @classmethod
    def from_checked_rows(cls, X: np.ndarray) -> tuple:
        """One Point per row of a float64 array (N, 2) whose entries the caller has checked finite (the coercion
        of an array of points, :func:`tritools.model.regions.as_regions`): each ``x`` a read-only copy of its row,
        as :func:`as_vector` makes it, without repeating its checks row by row."""
        out = []
        for row in X:
            p = object.__new__(cls)
            x = row.copy()
            x.setflags(write=False)
            object.__setattr__(p, "x", x)
            out.append(p)
        return tuple(out)

    @property
    def n_aux(self) -> int:
        return 0

    def polynomials(self, x, y=()) -> RegionPolynomials:
        x, y = check_xy(x, y, 0)
        f = square(x[0] - float(self.x[0])) + square(x[1] - float(self.x[1]))
        return RegionPolynomials(f)

    def closest_point(self, points) -> np.ndarray:
        P, single = as_points(points)
        C = np.broadcast_to(self.x, P.shape).copy()
        return C[0] if single else C

    @property
    def center(self) -> np.ndarray:
        return self.x.copy()

    @property
    def center_offset(self) -> float:
        """0: the centre is a point of the region."""
        return 0.0

    def similarity(self, scale, shift) -> Point:
        s, t = similarity_args(scale, shift)
        return Point(s * (self.x - t))

    def extent(self) -> RegionExtent:
        """``(||x^||, 0)``: no auxiliary variable."""
        return RegionExtent.outward(math.hypot(*self.x), 0.0)

    def conic_form(self) -> ConicForm:
        """``a - x^ s = 0``, ``s >= 0``."""
        return ConicForm(ConeKind.POINT, self.x)

    @property
    def is_point(self) -> bool:
        """True: the region is the point ``x^`` (= :attr:`center`)."""
        return True


# ----------------------------------------------------------------------------- II: segment
def segment_scaling(D: np.ndarray) -> tuple:
    """(s, u, uu) of directions D (k, 2): s the largest entry's magnitude, u = D / s (0 where s = 0) and
    uu = u.u, for :func:`segment_parameters` (a direction of any finite size neither overflows nor underflows)."""
    s = np.max(np.abs(D), axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.where(s[:, None] > 0, D / np.where(s > 0, s, 1.0)[:, None], 0.0)
    return s, u, u[:, 0] * u[:, 0] + u[:, 1] * u[:, 1]


def segment_parameters(R: np.ndarray, s: np.ndarray, u: np.ndarray, uu: np.ndarray) -> np.ndarray:
    """t* = clip(r.d^ / ||d^||^2, -1, 1) for offsets R = p - x^ (m, 2) from segments of :func:`segment_scaling` (one
    segment broadcast, or one per row): (r.u) / (s u.u), +-inf clipped to +-1, 0 for NaN and for a zero direction.
    The rule of :meth:`Segment.parameter` and of the stacked regions (:mod:`.stack`), the same operations."""
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        t = np.clip((R[:, 0] * u[:, 0] + R[:, 1] * u[:, 1]) / (s * uu), -1.0, 1.0)
    return np.where(np.isnan(t) | (s == 0.0), 0.0, t)


@dataclass(frozen=True, eq=False)
class Segment(Region):
    """Case II: ``R = {x^ + t d^ : t in [-1, 1]}``; ``n = 1``,
    ``f = ||x - x^ - y d^||^2``, ``h = 1 - y^2`` (paper Section 4.2).

    A zero ``direction`` is allowed (the segment is then the point ``center``).
    """

    center_: np.ndarray
    direction: np.ndarray
    kind: ClassVar[str] = "segment"

    def __init__(self, center, direction):
        object.__setattr__(self, "center_", as_vector(center, "center"))
        object.__setattr__(self, "direction", as_vector(direction, "direction"))

    @classmethod
    def from_endpoints(cls, a, b) -> Segment:
        """The segment ``[a, b]``: centre ``a/2 + b/2``, direction ``b/2 - a/2`` (halved first,
        so endpoints near the floating-point limit do not overflow)."""
        a = as_vector(a, "a")
        b = as_vector(b, "b")
        return cls(a / 2.0 + b / 2.0, b / 2.0 - a / 2.0)

    @property
    def endpoints(self) -> tuple[np.ndarray, np.ndarray]:
        return self.center_ - self.direction, self.center_ + self.direction

    @property
    def n_aux(self) -> int:
        return 1

    def polynomials(self, x, y) -> RegionPolynomials:
        x, y = check_xy(x, y, 1)
        (c1, c2), (d1, d2) = (float(v) for v in self.center_), (float(v) for v in self.direction)
        f = square(x[0] - c1 - y[0] * d1) + square(x[1] - c2 - y[0] * d2)
        return RegionPolynomials(f, (), (1.0 - square(y[0]),))

    def parameter(self, points) -> float | np.ndarray:
        """Minimising ``t* = clip((p - x^).d^ / ||d^||^2, -1, 1)`` of ``||p - x^ - t d^||``
        (0 for a zero direction); computed with ``d^`` scaled by its largest entry, so
        directions of any finite size neither overflow nor underflow."""
        P, single = as_points(points)
        s, u, uu = segment_scaling(self.direction[None])
        t = segment_parameters(P - self.center_, s, u, uu)
        return float(t[0]) if single else t

    def closest_point(self, points) -> np.ndarray:
        P, single = as_points(points)
        t = np.atleast_1d(self.parameter(P))
        C = self.center_ + t[:, None] * self.direction
        return C[0] if single else C

    @property
    def center(self) -> np.ndarray:
        return self.center_.copy()

    @property
    def center_offset(self) -> float:
        """0: the centre is a point of the region."""
        return 0.0

    def similarity(self, scale, shift) -> Segment:
        s, t = similarity_args(scale, shift)
        return Segment(s * (self.center_ - t), s * self.direction)

    def extent(self) -> RegionExtent:
        """``(||x^|| + ||d^||, 1)``: the auxiliary ``y`` is the parameter ``t``, ``|t| <= 1``."""
        return RegionExtent.outward(math.hypot(*self.center_) + math.hypot(*self.direction), 1.0)

    def conic_form(self) -> ConicForm:
        """A SEGMENT (``n'(a - x^ s) = 0``, ``|d^'(a - x^ s)| <= d^'d^ s``); a POINT for a zero direction."""
        if not np.any(self.direction):
            return ConicForm(ConeKind.POINT, self.center_)
        return ConicForm(ConeKind.SEGMENT, self.center_, direction=self.direction)

    def _fields(self):
        return {"center": self.center_.tolist(), "direction": self.direction.tolist()}

    @classmethod
    def _required(cls):
        return ("center", "direction")

    def __repr__(self) -> str:
        return f"Segment(center={self.center_.tolist()}, direction={self.direction.tolist()})"
