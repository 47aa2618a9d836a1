"""Admissible image regions R_i and their polynomial descriptions (SPEC §2).

Each region declares the number ``n_aux`` (``n_i``) of auxiliary variables
``y_i`` and, given polynomial image coordinates ``x_i`` and auxiliaries ``y_i``,
the quadratic ``f_i`` with ``f_i = d(x_i, R_i)^2`` at the minimising ``y_i``
(paper eq. (14)), the equalities ``g_i = 0`` and inequalities ``h_i >= 0``
(paper eq. (13)), Section 4.2 cases I-V:

=================  ====  ========================  ==============================
region             n_i   f_i                       g_i / h_i
=================  ====  ========================  ==============================
Point {x^}         0     ||x - x^||^2              --
Segment            1     ||x - x^ - y d^||^2       h = 1 - y^2
Polytope           2     ||x - y||^2               h_k = 1 - (B y + c)_k^2
EllipseBorder      2     ||x - y||^2               g = 1 - (y-x^)' D^-1 (y-x^)
Ellipse (filled)   2     ||x - y||^2               h = 1 - (y-x^)' D^-1 (y-x^)
=================  ====  ========================  ==============================

Besides the polynomials, every region computes the exact Euclidean distance
``d(p, R)`` (paper eq. (7)) and closest point, used to evaluate ``gamma(X)``.
A new region type only needs to subclass :class:`Region` (as a frozen dataclass
with ``eq=False``) and implement ``n_aux``, ``polynomials``, ``closest_point``,
``center`` and ``similarity`` (docs/regions.md has a worked example); a class
attribute ``kind`` registers it for :meth:`Region.from_dict`.
"""
from __future__ import annotations

import abc
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any, ClassVar, Sequence

import numpy as np

__all__ = [
    "Region", "RegionPolynomials", "Point", "Segment", "Polytope", "EllipseBorder", "Ellipse",
    "as_region", "as_regions",
]

#: Relative tolerance on the singular values of B below which a polytope is unbounded.
POLYTOPE_RANK_RTOL = 1e-12
#: Relative feasibility slack used when keeping intersections of boundary lines as vertices.
POLYTOPE_VERTEX_RTOL = 1e-9
#: Relative tolerance for ``D == D.T``.
SYMMETRY_RTOL = 1e-10
#: ``D`` is positive definite iff ``min eig > PD_RTOL * max eig`` (and ``max eig > 0``).
PD_RTOL = 1e-12
#: Maximum bisection steps of the point-to-ellipse root finder (converges in < 80 in practice).
ELLIPSE_MAX_ITER = 200
#: Up to this many points the point-to-ellipse solver runs a scalar loop (faster than numpy).
ELLIPSE_SCALAR_MAX = 8

_REGISTRY: dict[str, type["Region"]] = {}


# ----------------------------------------------------------------------------- helpers
def _vector(value, name: str, size: int = 2) -> np.ndarray:
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric vector of length {size}, got {value!r}") from exc
    if arr.shape != (size,):
        raise ValueError(f"{name} must have shape ({size},), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {arr.tolist()}")
    arr.setflags(write=False)
    return arr


def _matrix(value, name: str, shape: tuple) -> np.ndarray:
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric matrix, got {value!r}") from exc
    if arr.ndim != 2 or any(s is not None and a != s for a, s in zip(arr.shape, shape)):
        want = "x".join("m" if s is None else str(s) for s in shape)
        raise ValueError(f"{name} must be a {want} matrix, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite (no NaN/inf)")
    arr.setflags(write=False)
    return arr


def _points(points, name: str = "points") -> tuple[np.ndarray, bool]:
    """Return ``(P, single)`` with ``P`` of shape (m, 2)."""
    try:
        arr = np.asarray(points, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric array of shape (2,) or (m, 2)") from exc
    if arr.shape == (2,) or (arr.ndim == 2 and arr.shape[1] == 2):
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} must be finite (no NaN/inf)")
        return (arr[None, :], True) if arr.ndim == 1 else (arr, False)
    raise ValueError(f"{name} must have shape (2,) or (m, 2), got {arr.shape}")


def positive_number(value, name: str) -> float:
    """``value`` as a float, or a ValueError naming ``name`` unless it is finite and > 0."""
    try:
        v = float(value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a positive real number, got {value!r}") from exc
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return v


def _similarity_args(scale, shift) -> tuple[float, np.ndarray]:
    return positive_number(scale, "scale"), _vector(shift, "shift")


def _sq(p):
    return p * p


def _check_xy(x, y, n_aux: int) -> tuple[tuple, tuple]:
    x = tuple(x)
    y = tuple(y)
    if len(x) != 2:
        raise ValueError(f"x must be a tuple of 2 polynomials (x_i1, x_i2), got {len(x)}")
    if len(y) != n_aux:
        raise ValueError(f"y must be a tuple of {n_aux} polynomials for this region, got {len(y)}")
    return x, y


def _segment_closest(P: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Closest points of the segment [a, b] to the rows of P."""
    d = b - a
    dd = float(d @ d)
    if dd == 0.0:
        return np.broadcast_to(a, P.shape).copy()
    t = np.clip((P - a) @ d / dd, 0.0, 1.0)
    return a + t[:, None] * d


# ----------------------------------------------------------------------------- base classes
@dataclass(frozen=True)
class RegionPolynomials:
    """Polynomial description of ``x_i in R_i`` (paper eqs. (13)-(14)).

    Attributes
    ----------
    f : Polynomial
        Quadratic with ``min_{y feasible} f = d(x_i, R_i)^2``.
    eq : tuple of Polynomial
        ``g_i(v) = 0``.
    ineq : tuple of Polynomial
        ``h_i(v) >= 0``.
    """

    f: Any
    eq: tuple = ()
    ineq: tuple = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "eq", tuple(self.eq))
        object.__setattr__(self, "ineq", tuple(self.ineq))


@dataclass(frozen=True, eq=False)
class Region(abc.ABC):
    """Abstract admissible region ``R_i`` of the image plane (SPEC §2).

    A region declares ``n_aux`` (``n_i``), ``polynomials(x, y)`` (``f_i``, ``g_i``,
    ``h_i`` of paper eqs. (13)-(14)), the exact ``closest_point`` (hence ``distance``,
    paper eq. (7)), a representative ``center`` and ``similarity`` (the region in
    normalised coordinates).  Subclasses are frozen dataclasses declared with
    ``eq=False``; equality and hashing use :meth:`to_dict`.
    """

    kind: ClassVar[str] = ""

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if cls.__dict__.get("kind"):
            _REGISTRY[cls.kind] = cls

    # -- the interface -------------------------------------------------------
    @property
    @abc.abstractmethod
    def n_aux(self) -> int:
        """Number ``n_i`` of auxiliary variables ``y_i`` (paper eq. (11))."""

    @abc.abstractmethod
    def polynomials(self, x: Sequence, y: Sequence) -> RegionPolynomials:
        """``(f_i, g_i, h_i)`` in terms of ``x = (x_i1, x_i2)`` and ``y`` (``n_aux`` entries)."""

    @abc.abstractmethod
    def closest_point(self, points) -> np.ndarray:
        """Closest point(s) of the region; shape (2,) -> (2,), (m, 2) -> (m, 2)."""

    @property
    @abc.abstractmethod
    def center(self) -> np.ndarray:
        """A representative point (2,) used for initialisation (DLT) and normalisation."""

    @abc.abstractmethod
    def similarity(self, scale: float, shift) -> "Region":
        """The same region in the coordinates ``x' = scale * (x - shift)``."""

    def _fields(self) -> dict[str, Any]:
        """Data fields for :meth:`to_dict`: by default the dataclass fields given to
        ``__init__``, arrays as lists (override when the constructor differs)."""
        values = {f.name: getattr(self, f.name) for f in fields(self) if f.init}
        return {k: v.tolist() if isinstance(v, np.ndarray) else v for k, v in values.items()}

    # -- generic methods -----------------------------------------------------
    def distance(self, points) -> float | np.ndarray:
        """Euclidean distance ``d(p, R) = inf_{x in R} ||p - x||_2`` (paper eq. (7)).

        Parameters
        ----------
        points : array_like, shape (2,) or (m, 2)

        Returns
        -------
        float or ndarray of shape (m,)
        """
        P, single = _points(points)
        C = np.atleast_2d(self.closest_point(P))
        d = np.hypot(P[:, 0] - C[:, 0], P[:, 1] - C[:, 1])
        return float(d[0]) if single else d

    def to_dict(self) -> dict[str, Any]:
        """JSON schema ``{"type": kind, **fields}``."""
        return {"type": self.kind, **self._fields()}

    @staticmethod
    def from_dict(d: Mapping) -> "Region":
        """Build a region from its :meth:`to_dict` form; extra keys are ignored.

        Raises
        ------
        ValueError
            If ``d`` is not a mapping, its ``"type"`` is missing or unknown, or a
            required field is missing (the message names the field).
        """
        if not isinstance(d, Mapping):
            raise ValueError(f"region description must be a mapping, got {type(d).__name__}")
        if "type" not in d:
            raise ValueError("region description is missing the field 'type'")
        kind = d["type"]
        cls = _REGISTRY.get(kind)
        if cls is None:
            raise ValueError(f"unknown region field 'type' = {kind!r}; known types: {sorted(_REGISTRY)}")
        return cls._from_fields(d)

    @classmethod
    def _required(cls) -> tuple[str, ...]:
        return tuple(f.name for f in fields(cls) if f.init)

    @classmethod
    def _from_fields(cls, d: Mapping) -> "Region":
        kwargs = {}
        for name in cls._required():
            if name not in d:
                raise ValueError(f"region of type {cls.kind!r} is missing the field {name!r}")
            kwargs[name] = d[name]
        return cls(**kwargs)

    def __eq__(self, other) -> bool:
        if not isinstance(other, Region):
            return NotImplemented
        return self.to_dict() == other.to_dict()

    def __hash__(self) -> int:
        return hash(json.dumps(self.to_dict(), sort_keys=True))


# ----------------------------------------------------------------------------- I: point
@dataclass(frozen=True, eq=False)
class Point(Region):
    """Case I: ``R = {x^}``; ``n = 0``, ``f = ||x - x^||^2`` (paper Section 4.2)."""

    x: np.ndarray
    kind: ClassVar[str] = "point"

    def __post_init__(self) -> None:
        object.__setattr__(self, "x", _vector(self.x, "x"))

    @property
    def n_aux(self) -> int:
        return 0

    def polynomials(self, x, y=()) -> RegionPolynomials:
        x, y = _check_xy(x, y, 0)
        f = _sq(x[0] - float(self.x[0])) + _sq(x[1] - float(self.x[1]))
        return RegionPolynomials(f)

    def closest_point(self, points) -> np.ndarray:
        P, single = _points(points)
        C = np.broadcast_to(self.x, P.shape).copy()
        return C[0] if single else C

    @property
    def center(self) -> np.ndarray:
        return self.x.copy()

    def similarity(self, scale, shift) -> "Point":
        s, t = _similarity_args(scale, shift)
        return Point(s * (self.x - t))


# ----------------------------------------------------------------------------- II: segment
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
        object.__setattr__(self, "center_", _vector(center, "center"))
        object.__setattr__(self, "direction", _vector(direction, "direction"))

    @classmethod
    def from_endpoints(cls, a, b) -> "Segment":
        """The segment ``[a, b]``."""
        a = _vector(a, "a")
        b = _vector(b, "b")
        return cls((a + b) / 2.0, (b - a) / 2.0)

    @property
    def endpoints(self) -> tuple[np.ndarray, np.ndarray]:
        return self.center_ - self.direction, self.center_ + self.direction

    @property
    def n_aux(self) -> int:
        return 1

    def polynomials(self, x, y) -> RegionPolynomials:
        x, y = _check_xy(x, y, 1)
        (c1, c2), (d1, d2) = (float(v) for v in self.center_), (float(v) for v in self.direction)
        f = _sq(x[0] - c1 - y[0] * d1) + _sq(x[1] - c2 - y[0] * d2)
        return RegionPolynomials(f, (), (1.0 - _sq(y[0]),))

    def parameter(self, points) -> float | np.ndarray:
        """Minimising ``t* in [-1, 1]`` of ``||p - x^ - t d^||`` (0 for a zero direction)."""
        P, single = _points(points)
        dd = float(self.direction @ self.direction)
        t = np.zeros(len(P)) if dd == 0 else np.clip((P - self.center_) @ self.direction / dd, -1.0, 1.0)
        return float(t[0]) if single else t

    def closest_point(self, points) -> np.ndarray:
        P, single = _points(points)
        t = np.atleast_1d(self.parameter(P))
        C = self.center_ + t[:, None] * self.direction
        return C[0] if single else C

    @property
    def center(self) -> np.ndarray:
        return self.center_.copy()

    def similarity(self, scale, shift) -> "Segment":
        s, t = _similarity_args(scale, shift)
        return Segment(s * (self.center_ - t), s * self.direction)

    def _fields(self):
        return {"center": self.center_.tolist(), "direction": self.direction.tolist()}

    @classmethod
    def _required(cls):
        return ("center", "direction")

    def __repr__(self) -> str:
        return f"Segment(center={self.center_.tolist()}, direction={self.direction.tolist()})"


# ----------------------------------------------------------------------------- III: polytope
@dataclass(frozen=True, eq=False)
class Polytope(Region):
    """Case III: ``R = {y : ||B y + c||_inf <= 1}``, ``B`` of shape (m, 2); ``n = 2``,
    ``f = ||x - y||^2``, ``h_k = 1 - (B y + c)_k^2``, k = 1..m (paper Section 4.2).

    The polygon's vertices are computed exactly at construction by intersecting the
    ``2m`` boundary lines ``(B y + c)_k = +-1`` and keeping the feasible
    intersections, ordered by angle around their mean.

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
        B = _matrix(self.B, "B", (None, 2))
        if B.shape[0] < 2:
            raise ValueError(f"B must have at least 2 rows for a bounded polytope, got shape {B.shape}")
        try:
            c = np.array(self.c, dtype=float)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"c must be a numeric vector, got {self.c!r}") from exc
        if c.shape != (B.shape[0],):
            raise ValueError(f"c must have shape ({B.shape[0]},) to match B {B.shape}, got {c.shape}")
        if not np.all(np.isfinite(c)):
            raise ValueError("c must be finite (no NaN/inf)")
        c.setflags(write=False)
        sv = np.linalg.svd(B, compute_uv=False)
        if sv[0] == 0 or sv[-1] <= POLYTOPE_RANK_RTOL * sv[0]:
            raise ValueError(f"B has rank < 2 (singular values {sv.tolist()}): the polytope is unbounded")
        object.__setattr__(self, "B", B)
        object.__setattr__(self, "c", c)
        V = self._compute_vertices(B, c)
        V.setflags(write=False)
        object.__setattr__(self, "vertices", V)

    @staticmethod
    def _compute_vertices(B: np.ndarray, c: np.ndarray) -> np.ndarray:
        # boundary lines a . y = b:  B_k y = 1 - c_k  and  B_k y = -1 - c_k
        A = np.vstack([B, B])
        b = np.concatenate([1.0 - c, -1.0 - c])
        norms = np.linalg.norm(A, axis=1)
        for k in range(B.shape[0]):
            if norms[k] == 0.0 and abs(c[k]) > 1.0:
                raise ValueError(f"polytope is empty: row {k} of B is zero and |c[{k}]| = {abs(c[k])} > 1")
        keep = norms > 0
        A, b, norms = A[keep], b[keep], norms[keep]
        pts = []
        n = len(A)
        for i in range(n):
            for j in range(i + 1, n):
                M = A[[i, j]]
                det = M[0, 0] * M[1, 1] - M[0, 1] * M[1, 0]
                if abs(det) <= 1e-14 * norms[i] * norms[j]:
                    continue
                pts.append(np.linalg.solve(M, b[[i, j]]))
        if not pts:
            raise ValueError("polytope is empty (no feasible vertex)")
        P = np.array(pts)
        scale = 1.0 + np.max(np.abs(P), axis=1)
        resid = np.abs(P @ B.T + c) - 1.0  # (k, m)
        tol = POLYTOPE_VERTEX_RTOL * (1.0 + np.linalg.norm(B, axis=1)[None, :] * scale[:, None])
        feasible = np.all(resid <= tol, axis=1)
        P = P[feasible]
        if len(P) == 0:
            raise ValueError("polytope {y : ||B y + c||_inf <= 1} is empty")
        # deduplicate
        uniq: list[np.ndarray] = []
        span = 1.0 + float(np.max(np.abs(P)))
        for p in P:
            if not any(np.linalg.norm(p - q) <= 1e-9 * span for q in uniq):
                uniq.append(p)
        V = np.array(uniq)
        mean = V.mean(axis=0)
        ang = np.arctan2(V[:, 1] - mean[1], V[:, 0] - mean[0])
        return V[np.argsort(ang)]

    @property
    def n_aux(self) -> int:
        return 2

    def polynomials(self, x, y) -> RegionPolynomials:
        x, y = _check_xy(x, y, 2)
        f = _sq(x[0] - y[0]) + _sq(x[1] - y[1])
        h = tuple(1.0 - _sq(float(Bk[0]) * y[0] + float(Bk[1]) * y[1] + float(ck))
                  for Bk, ck in zip(self.B, self.c))
        return RegionPolynomials(f, (), h)

    def contains(self, points) -> bool | np.ndarray:
        """``||B p + c||_inf <= 1`` (exact test, no slack)."""
        P, single = _points(points)
        inside = np.all(np.abs(P @ self.B.T + self.c) <= 1.0, axis=1)
        return bool(inside[0]) if single else inside

    def closest_point(self, points) -> np.ndarray:
        P, single = _points(points)
        V = self.vertices
        C = P.copy()
        inside = np.atleast_1d(self.contains(P))
        out = ~inside
        if np.any(out):
            Q = P[out]
            if len(V) == 1:
                best = np.broadcast_to(V[0], Q.shape).copy()
            else:
                best = None
                bestd = np.full(len(Q), np.inf)
                edges = [(V[k], V[(k + 1) % len(V)]) for k in range(len(V) if len(V) > 2 else 1)]
                for a, b in edges:
                    cand = _segment_closest(Q, a, b)
                    d = np.sum((Q - cand) ** 2, axis=1)
                    if best is None:
                        best = cand
                        bestd = d
                    else:
                        better = d < bestd
                        best[better] = cand[better]
                        bestd[better] = d[better]
            C[out] = best
        return C[0] if single else C

    @property
    def center(self) -> np.ndarray:
        """Area centroid of the polygon (vertex mean if it is degenerate)."""
        V = self.vertices
        if len(V) < 3:
            return V.mean(axis=0)
        x, y = V[:, 0], V[:, 1]
        xn, yn = np.roll(x, -1), np.roll(y, -1)
        cross = x * yn - xn * y
        area = cross.sum() / 2.0
        span = float(np.ptp(V, axis=0).max())
        if abs(area) <= 1e-14 * span * span:
            return V.mean(axis=0)
        return np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (6.0 * area)

    def similarity(self, scale, shift) -> "Polytope":
        s, t = _similarity_args(scale, shift)
        return Polytope(self.B / s, self.c + self.B @ t)

    @classmethod
    def box(cls, center, half_widths) -> "Polytope":
        """The axis-aligned rectangle ``|y_k - center_k| <= half_widths_k``."""
        c0 = _vector(center, "center")
        w = _vector(half_widths, "half_widths")
        if np.any(w <= 0):
            raise ValueError(f"half_widths must be positive, got {w.tolist()}")
        B = np.diag(1.0 / w)
        return cls(B, -B @ c0)


# ----------------------------------------------------------------------------- IV/V: ellipses
def _ellipse_root(r0, z0, z1, g, max_iter=ELLIPSE_MAX_ITER):
    """Vectorised bisection for the root ``u = s + 1 > 0`` of Eberly's function
    ``G(s) = (r0 z0 / (s + r0))^2 + (z1 / (s + 1))^2 - 1`` (``z0, z1 > 0``, ``r0 >= 1``).

    The root lies in ``[z1, 1]`` inside the ellipse (``g < 0``) and in
    ``[z1, ||(r0 z0, z1)||]`` outside; bisecting on ``u`` (not ``s``) keeps full
    relative precision when ``u`` is tiny (points close to the major axis).
    """
    n0 = r0 * z0
    rm1 = r0 - 1.0
    u0 = np.array(z1, dtype=float)
    u1 = np.where(g < 0, 1.0, np.hypot(n0, z1))
    u = 0.5 * (u0 + u1)
    active = np.ones_like(u, dtype=bool)
    eps = 2.0 * np.finfo(float).eps
    for _ in range(max_iter):
        u = np.where(active, 0.5 * (u0 + u1), u)
        G = (n0 / (u + rm1)) ** 2 + (z1 / u) ** 2 - 1.0
        u0 = np.where(active & (G > 0), u, u0)
        u1 = np.where(active & (G < 0), u, u1)
        done = (G == 0) | (u1 - u0 <= eps * u1)
        u = np.where(active & done & (G != 0), 0.5 * (u0 + u1), u)
        active &= ~done
        if not active.any():
            break
    return u


def _ellipse_closest_scalar(e0: float, e1: float, y0: float, y1: float) -> tuple[float, float]:
    """Scalar version of :func:`_ellipse_closest_local` for ``y0, y1 >= 0`` (fast for few points)."""
    if y1 > 0:
        if y0 > 0:
            z0, z1 = y0 / e0, y1 / e1
            g = z0 * z0 + z1 * z1 - 1.0
            if g == 0:
                return y0, y1
            r0 = (e0 / e1) ** 2
            n0, rm1 = r0 * z0, r0 - 1.0
            u0 = z1
            u1 = 1.0 if g < 0 else math.hypot(n0, z1)
            eps = 2.0 * np.finfo(float).eps
            u = 0.5 * (u0 + u1)
            for _ in range(ELLIPSE_MAX_ITER):
                u = 0.5 * (u0 + u1)
                G = (n0 / (u + rm1)) ** 2 + (z1 / u) ** 2 - 1.0
                if G > 0:
                    u0 = u
                elif G < 0:
                    u1 = u
                else:
                    break
                if u1 - u0 <= eps * u1:
                    u = 0.5 * (u0 + u1)
                    break
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
            x0, x1 = _ellipse_closest_scalar(e0, e1, abs(float(a)), abs(float(b)))
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
        object.__setattr__(self, "center_", _vector(center, "center"))
        D = _matrix(D, "D", (2, 2))
        scale = float(np.max(np.abs(D)))
        if np.max(np.abs(D - D.T)) > SYMMETRY_RTOL * max(scale, 1e-300):
            raise ValueError(f"D must be symmetric, got {D.tolist()}")
        D = 0.5 * (D + D.T)
        lam, Q = np.linalg.eigh(D)
        if not (lam[1] > 0 and lam[0] > PD_RTOL * lam[1]):
            raise ValueError(f"D must be positive definite, got eigenvalues {lam.tolist()}")
        D.setflags(write=False)
        object.__setattr__(self, "D", D)
        object.__setattr__(self, "_axes", np.sqrt(lam[::-1]))
        object.__setattr__(self, "_Q", Q[:, ::-1].copy())
        Dinv = np.linalg.inv(D)
        Dinv = 0.5 * (Dinv + Dinv.T)
        if not np.all(np.isfinite(Dinv)):
            raise ValueError(f"D is too close to singular for floating point (its inverse overflows), "
                             f"got eigenvalues {lam.tolist()}")
        object.__setattr__(self, "_Dinv", Dinv)

    @classmethod
    def circle(cls, center, radius) -> "EllipseBorder":
        r = float(radius)
        if not (math.isfinite(r) and r > 0):
            raise ValueError(f"radius must be positive and finite, got {radius!r}")
        return cls(center, r * r * np.eye(2))

    @property
    def semi_axes(self) -> np.ndarray:
        """Semi-axis lengths ``sqrt(eig D)``, largest first."""
        return self._axes.copy()

    @property
    def n_aux(self) -> int:
        return 2

    def _quadratic(self, y):
        c1, c2 = (float(v) for v in self.center_)
        u1 = y[0] - c1
        u2 = y[1] - c2
        a, b, d = float(self._Dinv[0, 0]), float(self._Dinv[0, 1]), float(self._Dinv[1, 1])
        return 1.0 - (a * _sq(u1) + (2.0 * b) * (u1 * u2) + d * _sq(u2))

    def polynomials(self, x, y) -> RegionPolynomials:
        x, y = _check_xy(x, y, 2)
        f = _sq(x[0] - y[0]) + _sq(x[1] - y[1])
        return RegionPolynomials(f, (self._quadratic(y),), ())

    def level(self, points) -> float | np.ndarray:
        """``(p - x^)' D^-1 (p - x^)`` (1 on the border, < 1 inside)."""
        P, single = _points(points)
        U = P - self.center_
        q = np.einsum("ij,jk,ik->i", U, self._Dinv, U)
        return float(q[0]) if single else q

    def _border_closest(self, P: np.ndarray) -> np.ndarray:
        Y = (P - self.center_) @ self._Q
        X = _ellipse_closest_local(float(self._axes[0]), float(self._axes[1]), Y)
        return self.center_ + X @ self._Q.T

    def closest_point(self, points) -> np.ndarray:
        P, single = _points(points)
        C = self._border_closest(P)
        return C[0] if single else C

    @property
    def center(self) -> np.ndarray:
        return self.center_.copy()

    def similarity(self, scale, shift):
        s, t = _similarity_args(scale, shift)
        return type(self)(s * (self.center_ - t), s * s * self.D)

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
        x, y = _check_xy(x, y, 2)
        f = _sq(x[0] - y[0]) + _sq(x[1] - y[1])
        return RegionPolynomials(f, (), (self._quadratic(y),))

    def closest_point(self, points) -> np.ndarray:
        P, single = _points(points)
        inside = np.atleast_1d(self.level(P)) <= 1.0
        C = P.copy()
        if np.any(~inside):
            C[~inside] = self._border_closest(P[~inside])
        return C[0] if single else C


# ----------------------------------------------------------------------------- coercion
def as_region(obj) -> Region:
    """Coerce a :class:`Region`, a ``to_dict`` mapping or a 2-vector (a :class:`Point`)."""
    if isinstance(obj, Region):
        return obj
    if isinstance(obj, Mapping):
        return Region.from_dict(obj)
    try:
        arr = np.asarray(obj, dtype=float)
    except (TypeError, ValueError):
        arr = None
    if arr is not None and arr.shape == (2,):
        return Point(arr)
    raise ValueError(f"cannot interpret {obj!r} as a region (expected a Region, a dict or a 2-vector)")


def as_regions(regions, n_views: int | None = None) -> tuple[Region, ...]:
    """Coerce a sequence of regions; checks ``len == n_views`` when given."""
    if isinstance(regions, (Region, Mapping)):
        raise ValueError("regions must be a sequence with one region per view")
    try:
        out = tuple(as_region(r) for r in regions)
    except TypeError as exc:
        raise ValueError("regions must be a sequence with one region per view") from exc
    if n_views is not None and len(out) != n_views:
        raise ValueError(f"regions must have one region per view: got {len(out)} regions for {n_views} cameras")
    return out
