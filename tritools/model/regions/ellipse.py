"""Cases IV and V of SPEC §2: the border ``{y : (y - x^)' D^-1 (y - x^) = 1}`` of an ellipse
(:class:`EllipseBorder`) and the filled ellipse (:class:`Ellipse`), with the exact
point-to-ellipse distance (Eberly's 1-D root of the Lagrange condition, by a safeguarded Newton: ~10x faster than
his bisection, the same root to an ulp)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from ...errors import FieldError
from .base import (Region, RegionPolynomials, as_matrix, as_points, as_vector, check_xy, positive_number,
                   similarity_args, square)
from .forms import ConeKind, ConicForm, RegionExtent
from .shapes import shape_fields

__all__ = ["EllipseBorder", "Ellipse", "SYMMETRY_RTOL", "PD_RTOL", "ELLIPSE_MAX_ITER", "ELLIPSE_SCALAR_MAX",
           "EXACT_SCALE_RATIO"]

#: Relative tolerance for ``D == D.T``.
SYMMETRY_RTOL = 1e-10
#: ``D`` is positive definite iff ``min eig > PD_RTOL * max eig`` (and ``max eig > 0``).
PD_RTOL = 1e-12
#: Maximum steps of the point-to-ellipse root finder (safeguarded Newton: at most ~35 measured, bisection ~52).
ELLIPSE_MAX_ITER = 200
#: semi-axis ratio above which a normalisation scales the ellipse by a power of two (``exact_scale``): s^2 D's
#: rounding moves the minor semi-axis by ~eps (a / b)^2 / 2 of itself, 5e-13 at this ratio
EXACT_SCALE_RATIO = 100.0
#: Up to this many points the point-to-ellipse solver runs a scalar loop (faster than numpy).
ELLIPSE_SCALAR_MAX = 8


def _ellipse_root(r0, z0, z1, g, max_iter=ELLIPSE_MAX_ITER):
    """Vectorised safeguarded Newton for the root ``u = s + 1 > 0`` of Eberly's function
    ``G(u) = (r0 z0 / (u + r0 - 1))^2 + (z1 / u)^2 - 1`` (``z0, z1 > 0``, ``r0 >= 1``): the scalar twin
    :func:`ellipse_closest_scalar`'s steps on every element (the same operations, so the same numbers).

    G is decreasing and convex on u > 0; the root lies in ``[z1, 1]`` inside the ellipse (``g < 0``) and in
    ``[z1, ||(r0 z0, z1)||]`` outside.  From u = z1 (where G >= 0) each step keeps the bracket [lo, hi] (G > 0 at
    lo, G < 0 at hi) and takes Newton's step u - G / G' when it falls inside it, else the bracket's midpoint, until
    the bracket is 2 eps of hi wide or G = 0 (bisection alone: ~52 steps; this: a handful, at most ~35 measured).
    Working on ``u`` (not ``s``) keeps full relative precision when ``u`` is tiny (points close to the major axis).
    """
    n0 = r0 * z0
    rm1 = r0 - 1.0
    lo = np.array(z1, dtype=float)
    hi = np.where(g < 0, 1.0, np.hypot(n0, z1))
    u = lo.copy()
    active = np.ones_like(u, dtype=bool)
    with np.errstate(divide="ignore", invalid="ignore"):
        for _ in range(max_iter):
            a, b = n0 / (u + rm1), z1 / u
            G = a * a + b * b - 1.0
            lo = np.where(active & (G > 0), u, lo)
            hi = np.where(active & (G < 0), u, hi)
            zero = G == 0
            narrow = ~zero & (hi - lo <= _ROOT_EPS * hi)
            u = np.where(active & narrow, 0.5 * (lo + hi), u)
            active &= ~(zero | narrow)
            if not active.any():
                break
            d = -2.0 * (a * a / (u + rm1) + b * b / u)
            v = u - G / d
            v = np.where((lo < v) & (v < hi), v, 0.5 * (lo + hi))
            u = np.where(active, v, u)
    return u


#: the relative width at which the root's bracket is closed (:func:`_ellipse_root`, :func:`ellipse_closest_scalar`)
_ROOT_EPS = 2.0 * float(np.finfo(float).eps)


def ellipse_closest_scalar(e0: float, e1: float, y0: float, y1: float) -> tuple[float, float]:
    """Scalar version of :func:`_ellipse_closest_local` for ``y0, y1 >= 0`` (fast for few points)."""
    if y1 > 0:
        if y0 > 0:
            z0, z1 = y0 / e0, y1 / e1
            g = z0 * z0 + z1 * z1 - 1.0
            if g == 0:
                return y0, y1
            r0 = (e0 / e1) ** 2
            n0, rm1 = r0 * z0, r0 - 1.0
            lo = z1
            hi = 1.0 if g < 0 else float(np.hypot(n0, z1))
            u = lo
            for _ in range(ELLIPSE_MAX_ITER):          # the safeguarded Newton of _ellipse_root, one element
                a, b = n0 / (u + rm1), z1 / u
                G = a * a + b * b - 1.0
                if G > 0:
                    lo = u
                elif G < 0:
                    hi = u
                else:
                    break
                if hi - lo <= _ROOT_EPS * hi:
                    u = 0.5 * (lo + hi)
                    break
                v = u - G / (-2.0 * (a * a / (u + rm1) + b * b / u))
                u = v if lo < v < hi else 0.5 * (lo + hi)
            return r0 * y0 / (u + rm1), y1 / u
        return 0.0, e1
    numer0, denom0 = e0 * y0, e0 * e0 - e1 * e1
    if numer0 < denom0:
        xde0 = numer0 / denom0
        return e0 * xde0, e1 * math.sqrt(max(0.0, 1.0 - xde0 * xde0))
    return e0, 0.0


def _ellipse_closest_local(e0: float, e1: float, Y: np.ndarray) -> np.ndarray:
    """Closest points on ``x0^2/e0^2 + x1^2/e1^2 = 1`` (``e0 >= e1 > 0``) to points Y (m, 2)
    in the ellipse's own axes.  Works in the first quadrant and restores signs.
    """
    if len(Y) <= ELLIPSE_SCALAR_MAX:
        out = np.empty_like(Y)
        for k, (a, b) in enumerate(Y):
            x0, x1 = ellipse_closest_scalar(e0, e1, abs(float(a)), abs(float(b)))
            out[k] = (-x0 if a < 0 else x0, -x1 if b < 0 else x1)
        return out
    sgn = np.where(Y < 0, -1.0, 1.0)
    y0 = np.abs(Y[:, 0])
    y1 = np.abs(Y[:, 1])
    x0 = np.empty_like(y0)
    x1 = np.empty_like(y1)

    # y1 > 0 and y0 > 0: root finding
    m = (y1 > 0) & (y0 > 0)
    if np.any(m):
        z0 = y0[m] / e0
        z1 = y1[m] / e1
        g = z0 * z0 + z1 * z1 - 1.0
        r0 = (e0 / e1) ** 2
        u = _ellipse_root(r0, z0, z1, g)
        on = g == 0
        x0[m] = np.where(on, y0[m], r0 * y0[m] / (u + (r0 - 1.0)))
        x1[m] = np.where(on, y1[m], y1[m] / u)
    # y0 == 0, y1 > 0: closest is the minor-axis end
    m = (y1 > 0) & (y0 == 0)
    x0[m] = 0.0
    x1[m] = e1
    # y1 == 0
    m = y1 == 0
    if np.any(m):
        numer0 = e0 * y0[m]
        denom0 = e0 * e0 - e1 * e1
        inner = numer0 < denom0
        xde0 = np.where(inner, numer0 / np.where(denom0 > 0, denom0, 1.0), 1.0)
        x0[m] = np.where(inner, e0 * xde0, e0)
        x1[m] = np.where(inner, e1 * np.sqrt(np.maximum(0.0, 1.0 - xde0 * xde0)), 0.0)
    return np.column_stack([x0, x1]) * sgn


def ellipse_levels(U: np.ndarray, Dinv: np.ndarray) -> np.ndarray:
    """u' D^-1 u for offsets U (m, 2) from the centres, D^-1 (1, 2, 2) broadcast or (m, 2, 2) one per row: the rule
    of :meth:`EllipseBorder.level` and of the stacked regions (:mod:`.stack`), the same operations."""
    u0, u1 = U[:, 0], U[:, 1]
    return u0 * (Dinv[:, 0, 0] * u0 + Dinv[:, 0, 1] * u1) + u1 * (Dinv[:, 1, 0] * u0 + Dinv[:, 1, 1] * u1)


def rotate(U: np.ndarray, Q: np.ndarray, back: bool = False) -> np.ndarray:
    """U Q (into the axes Q's columns) or, with ``back``, U Q' (out of them), for U (m, 2) and Q (1, 2, 2) broadcast
    or (m, 2, 2) one per row; the rule of the ellipse distances, single and stacked."""
    u0, u1 = U[:, 0:1], U[:, 1:2]
    if back:
        return u0 * Q[:, :, 0] + u1 * Q[:, :, 1]
    return u0 * Q[:, 0, :] + u1 * Q[:, 1, :]


def disc_matrix(radius) -> np.ndarray:
    """``D = radius^2 I`` of a disc, refused by the name ``radius`` (a FieldError) where ``radius`` is not a
    finite positive number or where radius^2 or its inverse leaves the floats (below ~1e-154, above ~1e154;
    review 31b F6: the error named ``D``, with a numpy overflow warning)."""
    r = positive_number(radius, "radius")
    with np.errstate(over="ignore", under="ignore", divide="ignore"):
        r2 = r * r
        ok = r2 >= np.finfo(float).tiny and math.isfinite(r2) and math.isfinite(1.0 / r2)
    if not ok:
        raise FieldError("radius", f"must have radius^2 and its inverse finite and non-zero in floating point "
                                   f"(about 1e-154 .. 1e154), got {r!r}")
    return r2 * np.eye(2)


@dataclass(frozen=True, eq=False)
class EllipseBorder(Region):
    """Case IV: ``R = {y : (y - x^)' D^-1 (y - x^) = 1}``, ``D`` symmetric positive
    definite; ``n = 2``, ``f = ||x - y||^2``, ``g = 1 - (y - x^)' D^-1 (y - x^)``
    (paper Section 4.2).  A circle of radius rho is ``D = rho^2 I``.

    The distance is computed in ``D``'s eigenbasis (semi-axes ``sqrt(eig D)``) by
    Eberly's bisection on the 1-D root of the Lagrange condition, with closed forms
    for points on the axes and at the centre.
    """

    center_: np.ndarray
    D: np.ndarray
    _axes: np.ndarray = field(init=False, repr=False)   # semi-axes, descending
    _Q: np.ndarray = field(init=False, repr=False)      # columns: matching axis directions
    _Dinv: np.ndarray = field(init=False, repr=False)
    kind: ClassVar[str] = "ellipse_border"

    def __init__(self, center, D):
        object.__setattr__(self, "center_", as_vector(center, "center"))
        D = as_matrix(D, "D", (2, 2))
        scale = float(np.max(np.abs(D)))
        if np.max(np.abs(D - D.T)) > SYMMETRY_RTOL * max(scale, 1e-300):
            raise FieldError("D", f"must be symmetric, got {D.tolist()}")
        D, axes, Q, Dinv, lam = shape_fields(D[None])
        if not (lam[0, 1] > 0 and lam[0, 0] > 0):
            raise FieldError("D", f"must be positive definite, got eigenvalues {lam[0].tolist()}")
        if not lam[0, 0] > PD_RTOL * lam[0, 1]:
            raise FieldError("D", f"must be positive definite and not thinner than an eigenvalue ratio of PD_RTOL = "
                                  f"{PD_RTOL:g} (semi-axis ratio {math.sqrt(PD_RTOL):g}), got eigenvalues "
                                  f"{lam[0].tolist()} (for a thinner region use a Segment)")
        if not np.all(np.isfinite(Dinv)):
            raise FieldError("D", f"is too close to singular for floating point (its inverse overflows), "
                             f"got eigenvalues {lam[0].tolist()}")
        self._set_fields(self.center_, D[0], axes[0].copy(), Q[0].copy(), Dinv[0])

    def _set_fields(self, center, D, axes, Q, Dinv) -> None:
        D.setflags(write=False)
        for name, value in (("center_", center), ("D", D), ("_axes", axes), ("_Q", Q), ("_Dinv", Dinv)):
            object.__setattr__(self, name, value)

    @classmethod
    def similarity_many(cls, regions, scale, shifts) -> list:
        """``[r.similarity(scale, shifts[i]) for i, r in enumerate(regions)]`` for regions of this very class, with
        the shape fields of all of them computed in one stacked call of the constructor's rule
        (:func:`~.shapes.shape_fields`: the same closed forms per matrix, so the same numbers, tested equal); any region
        the stacked rule does not accept (non-finite, not positive definite after scaling) is built one by one,
        which raises the constructor's error.  The normalisation of N views' regions in a few numpy calls."""
        s = positive_number(scale, "scale")
        T = np.asarray(shifts, float).reshape(len(regions), 2)
        if not np.all(np.isfinite(T)) or any(type(r) is not cls for r in regions):
            return [r.similarity(s, T[i]) for i, r in enumerate(regions)]
        centres = s * (np.array([r.center_ for r in regions]) - T)
        D, axes, Q, Dinv, lam = shape_fields(s * s * np.array([r.D for r in regions]))
        good = np.isfinite(centres).all(axis=1) & np.isfinite(D).all(axis=(1, 2)) & (lam[:, 1] > 0) \
            & (lam[:, 0] > PD_RTOL * lam[:, 1]) & np.isfinite(Dinv).all(axis=(1, 2))
        out = []
        for i, r in enumerate(regions):
            if not good[i]:
                out.append(r.similarity(s, T[i]))
                continue
            new = object.__new__(cls)
            centre = centres[i].copy()
            centre.setflags(write=False)
            new._set_fields(centre, D[i].copy(), axes[i].copy(), Q[i].copy(), Dinv[i].copy())
            out.append(new)
        return out

    @classmethod
    def circle(cls, center, radius) -> EllipseBorder:
        """The circle of radius ``radius`` (``D = radius^2 I``)."""
        return cls(center, disc_matrix(radius))

    @property
    def semi_axes(self) -> np.ndarray:
        """Semi-axis lengths ``sqrt(eig D)``, largest first."""
        return self._axes.copy()

    @property
    def exact_scale(self) -> bool:
        """Whether a normalisation must scale this region by a power of two (:func:`tritools.model.normalize.
        power_of_two_below`): an axis ratio above ``EXACT_SCALE_RATIO``, where rounding s^2 D moves the border."""
        return bool(self._axes[0] > EXACT_SCALE_RATIO * self._axes[1])

    @property
    def n_aux(self) -> int:
        return 2

    def _quadratic(self, y):
        c1, c2 = (float(v) for v in self.center_)
        u1 = y[0] - c1
        u2 = y[1] - c2
        a, b, d = float(self._Dinv[0, 0]), float(self._Dinv[0, 1]), float(self._Dinv[1, 1])
        return 1.0 - (a * square(u1) + (2.0 * b) * (u1 * u2) + d * square(u2))

    def polynomials(self, x, y) -> RegionPolynomials:
        x, y = check_xy(x, y, 2)
        f = square(x[0] - y[0]) + square(x[1] - y[1])
        return RegionPolynomials(f, (self._quadratic(y),), ())

    def level(self, points) -> float | np.ndarray:
        """``(p - x^)' D^-1 (p - x^)`` (1 on the border, < 1 inside)."""
        P, single = as_points(points)
        q = ellipse_levels(P - self.center_, self._Dinv[None])
        return float(q[0]) if single else q

    @staticmethod
    def stacked_shapes(regions) -> tuple:
        """(semi-axes (k, 2) descending, axis directions (k, 2, 2), D^-1 (k, 2, 2)) of ellipse regions, stacked: the
        fields the distances use (:class:`~.stack.RegionStack`)."""
        return (np.array([r._axes for r in regions], float).reshape(-1, 2),
                np.array([r._Q for r in regions], float).reshape(-1, 2, 2),
                np.array([r._Dinv for r in regions], float).reshape(-1, 2, 2))

    def _border_closest(self, P: np.ndarray) -> np.ndarray:
        Y = rotate(P - self.center_, self._Q[None])
        X = _ellipse_closest_local(float(self._axes[0]), float(self._axes[1]), Y)
        return self.center_ + rotate(X, self._Q[None], back=True)

    def closest_point(self, points) -> np.ndarray:
        P, single = as_points(points)
        C = self._border_closest(P)
        return C[0] if single else C

    @property
    def center(self) -> np.ndarray:
        return self.center_.copy()

    @property
    def center_offset(self) -> float:
        """The smallest semi-axis: the distance from the centre to the border."""
        return float(self._axes[1])

    def similarity(self, scale, shift):
        """The region mapped by y -> s (y - t).  The constructor's rule decides the copy's shape fields; where it
        refuses s^2 D although D was accepted (an axis ratio near ``sqrt(PD_RTOL)``: the small eigenvalue of the
        scaled matrix is only known to ~eps lam_max / lam_min relative, review 28a F2), the fields are carried over
        instead (:meth:`_scaled`): the same ellipse, scaled."""
        s, t = similarity_args(scale, shift)
        try:
            return type(self)(s * (self.center_ - t), s * s * self.D)
        except FieldError:
            new = self._scaled(s, t)
            if new is None:
                raise
            return new

    def _scaled(self, s: float, t: np.ndarray):
        """The copy mapped by y -> s (y - t) with its shape fields carried over (D s^2, semi-axes s, the same axis
        directions, D^-1 / s^2); None where a field is not finite or a semi-axis vanishes in floating point."""
        s2 = s * s
        centre, D, axes, Dinv = s * (self.center_ - t), s2 * self.D, s * self._axes, self._Dinv / s2
        if not (np.isfinite(centre).all() and np.isfinite(D).all() and np.isfinite(Dinv).all() and axes[1] > 0
                and np.isfinite(axes[0])):
            return None
        new = object.__new__(type(self))
        centre.setflags(write=False)
        new._set_fields(centre, D, axes, self._Q.copy(), Dinv)
        return new

    def extent(self) -> RegionExtent:
        """``(rho, rho)`` with rho = ``||x^||`` + the largest semi-axis: the auxiliary ``y`` is a point of the
        ellipse (its border, or the filled ellipse)."""
        rho = math.hypot(*self.center_) + float(self._axes[0])
        return RegionExtent.outward(rho, rho)

    def conic_form(self) -> ConicForm:
        """The filled ellipse ``||L'(a - x^ s)|| <= s`` (``D^-1 = L L'``): the convex hull of the border,
        flagged ``convexified``."""
        return ConicForm(ConeKind.ELLIPSE, self.center_, D=self.D, Dinv=self._Dinv, convexified=True)

    def _fields(self):
        return {"center": self.center_.tolist(), "D": self.D.tolist()}

    @classmethod
    def _required(cls):
        return ("center", "D")

    def __repr__(self) -> str:
        return f"{type(self).__name__}(center={self.center_.tolist()}, D={self.D.tolist()})"


@dataclass(frozen=True, eq=False, init=False, repr=False)
class Ellipse(EllipseBorder):
    """Case V: filled ellipse ``{y : (y - x^)' D^-1 (y - x^) <= 1}``; ``n = 2``,
    ``f = ||x - y||^2``, ``h = 1 - (y - x^)' D^-1 (y - x^)`` (paper Section 4.2).
    Distance 0 inside, else the border distance.
    """

    kind: ClassVar[str] = "ellipse"

    def polynomials(self, x, y) -> RegionPolynomials:
        x, y = check_xy(x, y, 2)
        f = square(x[0] - y[0]) + square(x[1] - y[1])
        return RegionPolynomials(f, (), (self._quadratic(y),))

    @property
    def center_offset(self) -> float:
        """0: the centre is a point of the filled ellipse."""
        return 0.0

    def conic_form(self) -> ConicForm:
        """``||L'(a - x^ s)|| <= s`` with ``D^-1 = L L'``: the region itself."""
        return ConicForm(ConeKind.ELLIPSE, self.center_, D=self.D, Dinv=self._Dinv)

    @property
    def disc_radius(self) -> float | None:
        """rho when ``D = rho^2 I`` exactly (a disc), else None."""
        D = self.D
        if D[0, 1] != 0 or D[1, 0] != 0 or D[0, 0] != D[1, 1]:
            return None
        return float(np.sqrt(D[0, 0]))

    def closest_point(self, points) -> np.ndarray:
        P, single = as_points(points)
        inside = np.atleast_1d(self.level(P)) <= 1.0
        C = P.copy()
        if np.any(~inside):
            C[~inside] = self._border_closest(P[~inside])
        return C[0] if single else C


