"""The one options object of every triangulation path: :class:`TriangulationOptions`.

``triangulate``, ``triangulate_many``, ``triangulate_points``, the CLI and the COLMAP workflow all
build one :class:`TriangulationOptions` (its constructor validates every field, so a flag on the
command line is checked exactly like a field of a problem file) and pass it down; no function takes
the options as a long positional list.

Defaults (the same everywhere):

* ``method="auto"``, ``delta=None``, ``max_delta=None``: the degree plan of
  :func:`tritools.solve.plan.degree_plan` -- Corollary 1 at delta = 2 (the paper's economical
  certificate; certification by verification first when ``path="auto"``), then delta = 4, dense when
  the program is small and in the sparse view-clique formulation otherwise;
* ``path="auto"``: certification by verification before any SDP where it applies;
* ``sparsity="auto"``: dense where small, view cliques (chain of view triples plus the dense
  degree-2 certificate) where not;
* ``budget``: 60 s and 2 GiB per point; programs that do not fit are skipped with status
  ``budget_exceeded``, a point that runs out of time gets ``time_limit`` (the keyword shorthands
  ``time_limit=`` and ``max_bytes=`` of every entry point change one field of it).
"""
from __future__ import annotations

import dataclasses
import enum
import numbers
from dataclasses import dataclass

from sospoly import Budget, GramForm, Multiplier, Polynomial, Tolerances
from sospoly.budget import as_budget
from sospoly.tolerances import as_tolerances
from sospoly.solvers import get_backend

from ..model.cameras import WorldFrame, as_world_frame
from ..model.constraints import Method

__all__ = ["TriangulationOptions", "SolvePath", "Sparsity", "MethodChoice", "DEFAULT_OPTIONS", "TRIANGULATION_BUDGET",
           "options_from"]


class SolvePath(str, enum.Enum):
    """How a point is certified: ``auto`` (certification by verification first where it applies) or ``sdp``."""
    SDP = "sdp"
    AUTO = "auto"


class Sparsity(str, enum.Enum):
    """The formulation of certificates above degree 2 (see :mod:`tritools.solve.plan`)."""
    AUTO = "auto"          #: dense where the program is small, view cliques where not
    NONE = "none"          #: the dense certificate (the paper's)
    VIEWS = "views"        #: view cliques (band of view pairs; Theorem 1: chain of triples) + the dense degree 2


class MethodChoice(str, enum.Enum):
    """``method`` of the options: Theorem 1, Corollary 1, or ``auto`` (the degree plan decides)."""
    AUTO = "auto"
    THEOREM1 = "theorem1"
    COROLLARY1 = "corollary1"


#: the default budget of one triangulation (all its degrees together): 60 s, 2 GiB.
TRIANGULATION_BUDGET = Budget(time_limit=60.0, max_bytes=2 * 2 ** 30)
#: keyword shorthands of :meth:`TriangulationOptions.replace` (and so of ``triangulate(..., time_limit=5)``) for
#: the fields of the budget.
BUDGET_SHORTHANDS = ("time_limit", "max_bytes")


def _enum(cls, value, name):
    try:
        return cls(getattr(value, "value", value))
    except ValueError:
        allowed = ", ".join(repr(e.value) for e in cls)
        raise ValueError(f"{name} must be one of {allowed}, got {value!r}") from None


def _degree(value, name: str, minimum: int = 2):
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        else:
            raise ValueError(f"{name} must be an even integer >= {minimum}, got {value!r}")
    value = int(value)
    if value < minimum or value % 2:
        raise ValueError(f"{name} must be an even integer >= {minimum}, got {value}")
    if value > 1000:
        raise ValueError(f"{name} = {value} is far beyond any solvable relaxation (at most 1000)")
    return value


@dataclass(frozen=True)
class TriangulationOptions:
    """Options of a triangulation (see the module docstring for the defaults).

    Parameters
    ----------
    method : "auto", "theorem1" (4x4 minors + SVD reduction) or "corollary1" (epipolar constraints)
    delta : first relaxation degree (even, >= delta_min; default delta_min)
    max_delta : last degree tried (default: 4 for ``method="auto"``; ``delta`` when given, else
        delta_min + 2, for an explicit method)
    path : "auto" (certification by verification first where it applies) or "sdp"
    sparsity : "auto", "none" (dense) or "views" (view-clique formulation)
    multiplier : "fixed" (the paper's q = (1 + ||v||^2)^(delta/2 - 1); q = 1 for sparse formulations),
        "putinar" (q = 1), "free" (GEVP by bisection) or a positive number / SOS Polynomial
    refine : local L2 refinement of the extracted estimate (it can only lower gamma_UB)
    normalize : normalise the data (the L2 problem is unchanged, see :mod:`tritools.model.normalize`)
    backend, form : sospoly back-end (None: automatic) and Gram form
    tolerances : :class:`sospoly.Tolerances` (the certificate rule)
    budget : :class:`sospoly.Budget` per point: ``time_limit`` for each point, on every path (see
        :mod:`tritools.solve.settings`), ``max_bytes`` for each program
    require_in_front : a certified minimiser behind a camera gets status ``behind_camera`` instead of
        ``optimal`` (by default it stays ``optimal`` with ``in_front=False`` and a message)
    world_frame : handedness of the cameras' world frame, the sign rule of the depths that judge
        ``in_front`` (:class:`tritools.model.cameras.WorldFrame`: ``"right_handed"``, the default, or
        ``"reflected"`` for a mirrored reconstruction such as the Oxford corridor and house sequences)
    """

    method: MethodChoice | str = MethodChoice.AUTO
    delta: int | None = None
    max_delta: int | None = None
    path: SolvePath | str = SolvePath.AUTO
    sparsity: Sparsity | str = Sparsity.AUTO
    multiplier: object = Multiplier.FIXED
    refine: bool = True
    normalize: bool = True
    backend: object = None
    form: GramForm | str = GramForm.IMAGE
    tolerances: Tolerances | None = None
    budget: Budget | None = None
    require_in_front: bool = False
    world_frame: WorldFrame | str = WorldFrame.RIGHT_HANDED

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "method", _enum(MethodChoice, self.method, "method"))
        set_(self, "path", _enum(SolvePath, self.path, "path"))
        set_(self, "sparsity", _enum(Sparsity, self.sparsity, "sparsity"))
        set_(self, "form", _enum(GramForm, self.form, "form"))
        set_(self, "world_frame", as_world_frame(self.world_frame))
        set_(self, "delta", _degree(self.delta, "delta"))
        set_(self, "max_delta", _degree(self.max_delta, "max_delta"))
        if self.delta is not None and self.max_delta is not None and self.max_delta < self.delta:
            raise ValueError(f"max_delta ({self.max_delta}) must be >= delta ({self.delta})")
        m = self.multiplier
        if isinstance(m, str) and not isinstance(m, Multiplier):
            set_(self, "multiplier", _enum(Multiplier, m, "multiplier"))
        elif not isinstance(m, (Multiplier, Polynomial)) and not (isinstance(m, numbers.Real)
                                                                 and not isinstance(m, bool) and m > 0):
            raise ValueError(f"multiplier must be 'fixed', 'putinar', 'free', a positive number or an SOS "
                             f"Polynomial, got {m!r}")
        for name in ("refine", "normalize", "require_in_front"):
            if not isinstance(getattr(self, name), (bool, int)) or isinstance(getattr(self, name), float):
                raise TypeError(f"{name} must be True or False, got {getattr(self, name)!r}")
            set_(self, name, bool(getattr(self, name)))
        set_(self, "tolerances", as_tolerances(self.tolerances))
        set_(self, "budget", TRIANGULATION_BUDGET if self.budget is None else as_budget(self.budget))
        if isinstance(self.backend, str) and self.backend.partition(":")[0] not in ("clarabel", "ipm", "auto",
                                                                                    "cvxpy"):
            raise ValueError(f"backend must be 'clarabel', 'ipm', 'auto', 'cvxpy' or 'cvxpy:<SOLVER>', "
                             f"got {self.backend!r}")
        if isinstance(self.backend, str):
            get_backend(self.backend)    # ValueError / ImportError naming an unknown or uninstalled solver

    def replace(self, **changes) -> TriangulationOptions:
        """A copy with some fields changed (validated again); None values are ignored.

        ``time_limit`` (seconds) and ``max_bytes`` are accepted as shorthands for the fields of the
        budget: ``replace(time_limit=5)`` keeps the budget's memory limit (``budget=Budget(time_limit=5)``
        would take sospoly's default memory limit instead)."""
        changes = {k: v for k, v in changes.items() if v is not None}
        limits = {k: changes.pop(k) for k in BUDGET_SHORTHANDS if k in changes}
        if limits:
            base = as_budget(changes["budget"]) if "budget" in changes else self.budget
            changes["budget"] = dataclasses.replace(base, **limits)      # validated by Budget
        unknown = set(changes) - {f.name for f in dataclasses.fields(self)}
        if unknown:
            raise TypeError(f"unknown triangulation option(s): {', '.join(sorted(unknown))}")
        return dataclasses.replace(self, **changes) if changes else self

    @property
    def explicit_method(self) -> Method | None:
        return None if self.method == MethodChoice.AUTO else Method(self.method.value)


DEFAULT_OPTIONS = TriangulationOptions()


def options_from(options: TriangulationOptions | None = None, **overrides) -> TriangulationOptions:
    """The options of a call: ``options`` (default :data:`DEFAULT_OPTIONS`) with the keyword overrides that
    are not None (the one place where the keyword arguments of the public functions are merged)."""
    if options is not None and not isinstance(options, TriangulationOptions):
        raise TypeError(f"options must be a TriangulationOptions, got {type(options).__name__}")
    return (options or DEFAULT_OPTIONS).replace(**overrides)
