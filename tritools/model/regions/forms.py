"""What the solvers need of a region, as plain records: :class:`RegionExtent` (the bound behind the
rigorous lower bound of the SDP), :class:`ConeKind` and :class:`ConicForm` (the region as convex cones,
for the certified uncertainty).  Every region type declares them through
:meth:`~tritools.model.regions.Region.extent` and :meth:`~tritools.model.regions.Region.conic_form`
(docs/regions.md, 'A new region type').
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np

__all__ = ["RegionExtent", "ConeKind", "ConicForm", "EXTENT_ROUND_UP", "conic_form_of", "extent_of"]


#: Outward rounding of the built-in extents: a norm computed in floating point is within a few ulps of the
#: exact one, so the reported radius is the computed one times this factor (an upper bound).
EXTENT_ROUND_UP = 1.0 + 8.0 * float(np.finfo(float).eps)


def _real_scalar(owner: str, name: str, value) -> float:
    """``value`` as a float, refusing booleans, strings and arrays (TypeError) and NaN (ValueError)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{owner}.{name} must be a real number, got {type(value).__name__}")
    v = float(value)
    if math.isnan(v):
        raise ValueError(f"{owner}.{name} must not be NaN")
    return v


@dataclass(frozen=True)
class RegionExtent:
    """What bounds a region and its auxiliary variables, for the rigorous lower bound.

    ``radius``: every point p of the region has ``||p||_2 <= radius``; ``aux``: every feasible
    auxiliary vector ``y_i`` (``g_i = 0``, ``h_i >= 0`` of paper eq. (13)) has ``|y_ik| <= aux`` for each
    of its ``n_i`` entries.  Both finite and >= 0.  At a minimiser ``v*`` of the program (44),
    ``f(v*) <= c_UB`` gives ``|x_ik| <= radius + sqrt(c_UB)`` (``||x_i - y_i||^2 <= c_UB`` with ``y_i``
    the closest region point), the box on which the PSD defect and identity residual of an approximate
    certificate are charged: ``c_LB = c* - (sum_j eps_j max ||b_j(v)||^2 + max |e(v)|) / min q(v)``
    (docs/certificates.md, :func:`tritools.solve.report.solve_radius`).  An unbounded region has no
    extent, and no certified lower bound.
    """

    radius: float
    aux: float

    def __post_init__(self) -> None:
        for name in ("radius", "aux"):
            v = _real_scalar("RegionExtent", name, getattr(self, name))
            if not (math.isfinite(v) and v >= 0.0):
                raise ValueError(f"RegionExtent.{name} must be finite and >= 0, got {v!r}")
            object.__setattr__(self, name, v)

    @classmethod
    def outward(cls, radius: float, aux: float) -> RegionExtent:
        """The extent of computed (rounded) bounds, each raised by :data:`EXTENT_ROUND_UP`."""
        return cls(float(radius) * EXTENT_ROUND_UP, float(aux) * EXTENT_ROUND_UP)


class ConeKind(str, enum.Enum):
    """How a region is written as convex cones on ``X~ = (X, 1)`` (:mod:`tritools.uncertain.sets`).

    With the signed camera rows ``r_i``, ``a = (r_i1 . X~, r_i2 . X~)``, ``s = r_i3 . X~`` (so that
    ``Phi = a / s``, ``s >= 0`` in front), every constraint is homogeneous of degree one in ``X~``.
    """

    POINT = "point"          #: ``a - x^ s = 0`` (2 equalities), ``s >= 0``
    SEGMENT = "segment"      #: ``n'(a - x^ s) = 0``, ``|d'(a - x^ s)| <= d'd s`` (1 equality, 2 linear)
    POLYTOPE = "polytope"    #: ``(1 -+ c_k) s -+ B_k a >= 0`` (2m linear)
    ELLIPSE = "ellipse"      #: ``||L'(a - x^ s)|| <= s`` with ``D^-1 = L L'`` (one second-order cone)


@dataclass(frozen=True)
class ConicForm:
    """A region (or its convex hull) as one of the :class:`ConeKind` descriptions.

    ``center`` (2,) always (the point of a POINT, the centre of a SEGMENT or ELLIPSE, a representative
    point of a POLYTOPE); ``direction`` (2,) for a SEGMENT (``{center + t direction : |t| <= 1}``,
    nonzero); ``B`` (m, 2), ``c`` (m,) for a POLYTOPE (``||B y + c||_inf <= 1``); ``D`` (2, 2) positive
    definite and ``Dinv`` its inverse for an ELLIPSE (``(y - center)' D^-1 (y - center) <= 1``).
    ``convexified`` is True when the form is the region's convex hull rather than the region (an
    ellipse border is described by its filled ellipse): the sets built on it are outer bounds.
    Shapes are checked; the numbers are trusted (they come from validated regions).
    """

    kind: ConeKind
    center: np.ndarray
    direction: np.ndarray | None = None
    B: np.ndarray | None = None
    c: np.ndarray | None = None
    D: np.ndarray | None = None
    Dinv: np.ndarray | None = None
    convexified: bool = False

    def __post_init__(self) -> None:
        if type(self.kind) is not ConeKind:
            try:
                object.__setattr__(self, "kind", ConeKind(self.kind))
            except ValueError:
                raise ValueError(f"ConicForm.kind must be one of {[k.value for k in ConeKind]}, "
                                 f"got {self.kind!r}") from None
        for name in ("center",) + _NEEDS[self.kind]:
            arr = getattr(self, name)
            if type(arr) is not np.ndarray or arr.dtype != np.float64:
                arr = None if arr is None else np.asarray(arr, dtype=float)
                object.__setattr__(self, name, arr)
            shape = _SHAPES[name]              # -1 (any length) only ever first
            if arr is None or (arr.shape != shape and (shape[0] != -1 or arr.shape[1:] != shape[1:]
                                                        or arr.ndim != len(shape))):
                raise ValueError(f"ConicForm.{name} of a {self.kind.value} must have shape {shape}, "
                                 f"got {None if arr is None else arr.shape}")
        if self.kind == ConeKind.POLYTOPE and self.B.shape[0] != self.c.shape[0]:
            raise ValueError(f"ConicForm.c must have one entry per row of B ({self.B.shape[0]}), got {self.c.shape}")
        if not isinstance(self.convexified, (bool, np.bool_)):
            raise TypeError(f"ConicForm.convexified must be True or False, got {self.convexified!r}")


#: the fields each kind needs besides ``center``, and the shapes of all (-1: any length).
_NEEDS = {ConeKind.POINT: (), ConeKind.SEGMENT: ("direction",), ConeKind.POLYTOPE: ("B", "c"),
          ConeKind.ELLIPSE: ("D", "Dinv")}
_SHAPES = {"center": (2,), "direction": (2,), "B": (-1, 2), "c": (-1,), "D": (2, 2), "Dinv": (2, 2)}


def _declared(region, method: str, kind: type):
    """``region.<method>()``, checked to be a ``kind`` (TypeError naming the method otherwise)."""
    value = getattr(region, method)()
    if not isinstance(value, kind):
        raise TypeError(f"{type(region).__name__}.{method}() must return a {kind.__name__}, got {type(value).__name__}")
    return value


def extent_of(region) -> RegionExtent:
    """``region.extent()``, checked to be a :class:`RegionExtent`.

    Raises
    ------
    TypeError
        The region type declares no ``extent()`` (the message names it), or it returns something else.
    """
    return _declared(region, "extent", RegionExtent)


def conic_form_of(region) -> ConicForm:
    """``region.conic_form()``, checked to be a :class:`ConicForm`.

    Raises
    ------
    TypeError
        The region type declares no ``conic_form()`` (the message names it), or it returns something else.
    """
    return _declared(region, "conic_form", ConicForm)
