"""The region interface: :class:`Region`, :class:`RegionPolynomials`, the ``kind`` registry
used by :meth:`Region.from_dict`, and the validation helpers shared by the region modules.

A region ``R_i`` of view i declares the number ``n_aux`` (``n_i``) of auxiliary variables
``y_i`` and, given polynomial image coordinates ``x_i`` and auxiliaries ``y_i``, the quadratic
``f_i`` with ``min_{y_i feasible} f_i = d(x_i, R_i)^2`` (paper eq. (14)), the equalities
``g_i = 0`` and the inequalities ``h_i >= 0`` (paper eq. (13)); SPEC §2.  It also computes the
exact closest point (hence the Euclidean distance ``d(p, R)`` of paper eq. (7)) used to
evaluate ``gamma(X)``.

The helpers (:func:`real_array`, :func:`as_vector`, :func:`as_matrix`, :func:`as_points`, :func:`positive_number`,
:func:`similarity_args`, :func:`check_xy`, :func:`square`) are public so that every region module, and a user's own
region type, validates its numbers the same way: real (not complex, boolean, string or object) and finite, with
errors that name the argument.
"""
from __future__ import annotations

import abc
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Any, ClassVar

import numpy as np

from ...errors import MISSING, FieldError
from .forms import ConicForm, RegionExtent

__all__ = ["Region", "RegionPolynomials", "real_array", "as_vector", "as_matrix", "as_points", "positive_number",
           "similarity_args", "check_xy", "square", "declares_extent", "require_extent"]

#: ``Region`` subclasses by ``kind`` (filled by ``Region.__init_subclass__``).
_REGISTRY: dict[str, type[Region]] = {}

#: dtype kinds accepted as real numbers: signed and unsigned integers, floating point.
_REAL_KINDS = "iuf"
#: readable names of the refused dtype kinds (others print as the dtype's name).
_KIND_NAMES = {"b": "bool", "U": "str", "S": "bytes", "O": "object", "V": "void"}


# ----------------------------------------------------------------------------- validation helpers
def real_array(value, name: str, what: str = "array") -> np.ndarray:
    """``value`` as a new float64 array, refusing anything that is not an array of real numbers.

    Accepted: integer, unsigned and floating-point data (numbers, nested lists and tuples,
    numpy arrays, objects with ``__array__``).  Refused, with a ValueError naming ``name``:
    complex numbers (their imaginary part would otherwise be dropped silently), booleans,
    strings and bytes, dates, and Python objects (``dtype=object``: ``None`` entries, numbers
    too large for int64, ragged nested lists).  Shape and finiteness are left to the caller
    (:func:`as_vector`, :func:`as_matrix`, :func:`as_points` check them).

    Parameters
    ----------
    value : array_like
    name : str
        The argument's name, for the messages.
    what : str
        The expected form, for the message about ragged nested sequences
        (``"{name} must be a numeric {what}, got [[1, 0], [0]]"``).

    Raises
    ------
    ValueError
        ``"{name} must be real numbers, got complex128"`` and the like.
    """
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError, OverflowError) as exc:
        raise FieldError(name, f"must be a numeric {what}, got {_short_repr(value)}") from exc
    kind = arr.dtype.kind
    if kind == "O":
        arr = _big_integers(arr, name)
    elif kind in _REAL_KINDS and isinstance(value, (list, tuple)) and _holds_bool(value):
        kind = "b"                                # [True, 0] is an int array to numpy: refused like a bool array
    if arr.dtype.kind not in _REAL_KINDS or kind == "b":
        raise FieldError(name, f"must be real numbers, got {_KIND_NAMES.get(kind, arr.dtype.name)}")
    if arr.dtype == np.float64:                   # nothing to convert: no error state to set (the common case)
        return np.array(arr)
    with np.errstate(over="ignore"):              # long double beyond float64: inf, refused by the finite checks
        return np.array(arr, dtype=float)


def _holds_bool(value) -> bool:
    """True when a nested list/tuple holds a boolean anywhere."""
    if isinstance(value, (bool, np.bool_)):
        return True
    return isinstance(value, (list, tuple)) and any(_holds_bool(v) for v in value if type(v) not in (float, int))


def _big_integers(arr: np.ndarray, name: str) -> np.ndarray:
    """An object array of Python numbers holding an integer beyond int64 as floats; an integer
    beyond the float range is refused by name.  Other object arrays are returned as they are
    (refused by the caller)."""
    flat = arr.ravel().tolist()
    if not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in flat) or \
            not any(isinstance(x, int) and not -2 ** 63 <= x < 2 ** 64 for x in flat):
        return arr
    try:
        return np.array([float(x) for x in flat]).reshape(arr.shape)
    except OverflowError:
        big = next(x for x in flat if isinstance(x, int) and abs(x) >= 2 ** 1024)
        digits = int(abs(big).bit_length() * 0.30103) + 1        # str() of a huge int is itself limited
        why = f"an integer of about {digits} digits is beyond the floating-point range (|x| < 1.8e308)"
        raise FieldError(name, why, message=f"{name}: {why}") from None


def _short_repr(value, limit: int = 80) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _check_finite(arr: np.ndarray, name: str) -> None:
    if not np.all(np.isfinite(arr)):
        shown = arr.tolist() if arr.size <= 8 else "an array with NaN or inf entries"
        raise FieldError(name, f"must be finite (no NaN/inf), got {shown}")


def as_vector(value, name: str, size: int = 2) -> np.ndarray:
    """``value`` as a read-only float vector of shape ``(size,)``: real numbers, finite.

    Any finite magnitude is accepted (``1e300`` included).

    Raises
    ------
    ValueError
        Not real numbers, shape other than ``(size,)``, NaN or inf; the message names ``name``.
    """
    arr = real_array(value, name, f"vector of length {size}")
    if arr.shape != (size,):
        raise FieldError(name, f"must have shape ({size},), got {arr.shape}")
    _check_finite(arr, name)
    arr.setflags(write=False)
    return arr


def as_matrix(value, name: str, shape: tuple) -> np.ndarray:
    """``value`` as a read-only float matrix; ``shape`` entries that are ``None`` are free
    (``(None, 2)``: any number of rows, 2 columns).

    Raises
    ------
    ValueError
        Not real numbers, wrong shape, NaN or inf; the message names ``name``.
    """
    arr = real_array(value, name, "matrix")
    if arr.ndim != 2 or any(s is not None and a != s for a, s in zip(arr.shape, shape)):
        want = "x".join("m" if s is None else str(s) for s in shape)
        raise FieldError(name, f"must be a {want} matrix, got shape {arr.shape}")
    _check_finite(arr, name)
    arr.setflags(write=False)
    return arr


def as_points(points, name: str = "points") -> tuple[np.ndarray, bool]:
    """``(P, single)``: ``P`` (a new array) of shape (m, 2) from one point ``(2,)`` (``single`` true) or many
    ``(m, 2)``; real numbers, finite.  A finite float64 ``(2,)`` array (every internal call) skips the conversions.

    Raises ValueError: not real numbers, another shape, NaN or inf; the message names ``name``.
    """
    if type(points) is np.ndarray and points.dtype == np.float64 and points.shape == (2,) \
            and math.isfinite(points[0]) and math.isfinite(points[1]):
        return points.reshape(1, 2).copy(), True
    arr = real_array(points, name, "array of shape (2,) or (m, 2)")
    if arr.shape == (2,) or (arr.ndim == 2 and arr.shape[1] == 2):
        _check_finite(arr, name)
        return (arr[None, :], True) if arr.ndim == 1 else (arr, False)
    raise FieldError(name, f"must have shape (2,) or (m, 2), got {arr.shape}")


def positive_number(value, name: str) -> float:
    """``value`` as a float: a real number (not a bool, a string or a complex), finite and > 0.

    Raises
    ------
    ValueError
        Otherwise; the message names ``name``.
    """
    try:
        arr = real_array(value, name)
    except ValueError as exc:
        raise FieldError(name, f"must be a positive real number, got {_short_repr(value)}") from exc
    if arr.shape != ():
        raise FieldError(name, f"must be a positive real number, got an array of shape {arr.shape}")
    v = float(arr)
    if not (math.isfinite(v) and v > 0):
        raise FieldError(name, f"must be a positive finite number, got {_short_repr(value)}")
    return v


def similarity_args(scale, shift) -> tuple[float, np.ndarray]:
    """The checked arguments of :meth:`Region.similarity`: ``scale`` > 0 finite, ``shift`` a finite 2-vector."""
    return positive_number(scale, "scale"), as_vector(shift, "shift")


def square(p):
    """``p * p`` (for numbers and polynomials alike)."""
    return p * p


def check_xy(x, y, n_aux: int) -> tuple[tuple, tuple]:
    """The arguments of :meth:`Region.polynomials` as tuples: ``x`` of 2 entries, ``y`` of ``n_aux``.

    Raises
    ------
    ValueError
        Wrong lengths.
    """
    x = tuple(x)
    y = tuple(y)
    if len(x) != 2:
        raise ValueError(f"x must be a tuple of 2 polynomials (x_i1, x_i2), got {len(x)}")
    if len(y) != n_aux:
        raise ValueError(f"y must be a tuple of {n_aux} polynomials for this region, got {len(y)}")
    return x, y


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


def _not_declared(region, method: str, why: str) -> TypeError:
    """The TypeError of a region type that does not declare ``method`` (docs/regions.md)."""
    return TypeError(f"region type {type(region).__name__} does not declare {method}, which {why}; "
                     f"define it on the class (docs/regions.md, 'A new region type')")


@dataclass(frozen=True, eq=False)
class Region(abc.ABC):
    """Abstract admissible region ``R_i`` of the image plane (SPEC §2).

    A region declares ``n_aux`` (``n_i``), ``polynomials(x, y)`` (``f_i``, ``g_i``,
    ``h_i`` of paper eqs. (13)-(14)), the exact ``closest_point`` (hence ``distance``,
    paper eq. (7)), a representative ``center`` and ``similarity`` (the region in
    normalised coordinates).  Subclasses are frozen dataclasses declared with
    ``eq=False``; equality and hashing use :meth:`to_dict`.  A class attribute ``kind``
    registers the subclass for :meth:`from_dict`.

    What the solvers need of a region is asked of the region, never inferred from its class:
    :meth:`extent` (required by ``triangulate``: the box of the rigorous margin), :meth:`conic_form`
    (required by ``uncertainty``), :attr:`is_point` and :attr:`disc_radius` (the fast paths; their
    defaults are correct).  A missing ``extent`` or ``conic_form`` raises a TypeError naming it.
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
    def similarity(self, scale: float, shift) -> Region:
        """The same region in the coordinates ``x' = scale * (x - shift)``."""

    # -- what the solvers need (docs/regions.md) -----------------------------
    def extent(self) -> RegionExtent:
        """Bounds of the region's points and of its feasible auxiliary variables (:class:`RegionExtent`).

        Required to triangulate with the SDP: the rigorous lower bound charges the certificate's PSD
        defect on the box they give.  No generic default exists (a region may be unbounded).

        Raises
        ------
        TypeError
            The region type does not declare it.
        """
        raise _not_declared(self, "extent()", "the rigorous lower bound (the SDP's PSD-defect margin) needs")

    def conic_form(self) -> ConicForm:
        """The region (or its convex hull, flagged ``convexified``) as convex cones (:class:`ConicForm`),
        for the certified 3D uncertainty (:mod:`tritools.uncertain`).

        Raises
        ------
        TypeError
            The region type does not declare it.
        """
        raise _not_declared(self, "conic_form()", "the certified uncertainty (tritools.uncertainty) needs")

    @property
    def is_point(self) -> bool:
        """True when the region is exactly the single point :attr:`center` (the point-region fast paths then
        apply).  Default False: always correct, only slower."""
        return False

    @property
    def disc_radius(self) -> float | None:
        """rho when the region is exactly the filled disc of radius rho around :attr:`center` (the disc
        fast path, :mod:`tritools.solve.discs`, then applies), else None.  Default None: always correct."""
        return None

    @property
    def center_offset(self) -> float:
        """d(:attr:`center`, R), 0 for a centre in R: it bounds the image scale (:func:`~tritools.model.
        normalize.normalization_for`).  Default: :meth:`distance`."""
        return float(self.distance(self.center))

    def _fields(self) -> dict[str, Any]:
        """Fields for :meth:`to_dict`: the dataclass init fields, arrays as lists (override if the init differs)."""
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
        P, single = as_points(points)
        C = np.atleast_2d(self.closest_point(P[0] if single else P))       # one point: a region's scalar twin
        d = np.hypot(P[:, 0] - C[:, 0], P[:, 1] - C[:, 1])
        return float(d[0]) if single else d

    def to_dict(self) -> dict[str, Any]:
        """JSON schema ``{"type": kind, **fields}``."""
        return {"type": self.kind, **self._fields()}

    @staticmethod
    def from_dict(d: Mapping) -> Region:
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
        cls = _REGISTRY.get(kind) if isinstance(kind, str) else None
        if cls is None:
            raise ValueError(f"unknown region field 'type' = {kind!r}; known types: {sorted(_REGISTRY)}")
        return cls._from_fields(d)

    @classmethod
    def _required(cls) -> tuple[str, ...]:
        return tuple(f.name for f in fields(cls) if f.init)

    @classmethod
    def _from_fields(cls, d: Mapping) -> Region:
        kwargs = {}
        for name in cls._required():
            if name not in d:
                raise FieldError(name, MISSING, message=f"region of type {cls.kind!r} is missing the field {name!r}")
            kwargs[name] = d[name]
        return cls(**kwargs)

    def __eq__(self, other) -> bool:
        if not isinstance(other, Region):
            return NotImplemented
        return self.to_dict() == other.to_dict()

    def __hash__(self) -> int:
        return hash(json.dumps(self.to_dict(), sort_keys=True))


def declares_extent(region) -> bool:
    """Does the region's type declare :meth:`Region.extent` (a class-level test: nothing is computed)."""
    return type(region).extent is not Region.extent


def require_extent(regions) -> None:
    """The TypeError naming ``extent()`` for the first region whose type does not declare it.

    Triangulation requires ``extent()`` of every region on every path -- single calls, batches, robust, the
    point fast paths alike -- so a region type is refused the same way wherever it enters (docs/regions.md),
    even where a particular path would not need the margin."""
    for r in regions:
        if not declares_extent(r):
            raise _not_declared(r, "extent()", "the rigorous lower bound (the SDP's PSD-defect margin) needs")
