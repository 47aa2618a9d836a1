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
* ``budget``: :data:`sospoly.budget.DEFAULT_TIME_LIMIT` (60 s) and 2 GiB **per point** (``time_limit`` means
  per point everywhere: each problem of a batch gets its own); programs that do not fit are skipped with
  status ``budget_exceeded``, a point that runs out of time gets ``time_limit`` (the keyword shorthands
  ``time_limit=`` and ``max_bytes=`` of every entry point change one field of it);
* ``total_time_limit=None``: no limit on a whole batch call (``triangulate_many``, ``triangulate_points``,
  the COLMAP workflow); with a number of seconds, the points not finished when it expires get status
  ``time_limit`` -- every point still gets its row, with the estimate found so far.

Every check raises :class:`OptionError` (a ValueError; :class:`OptionTypeError` where the type is wrong,
also a TypeError) whose ``field`` names the option, so the command line and the problem-file reader place
the message at the flag or field without parsing it.
"""
from __future__ import annotations

import dataclasses
import enum
import math
import numbers
from dataclasses import dataclass

from sospoly import Budget, GramForm, Multiplier, Polynomial, Sparsity, Tolerances
from sospoly.budget import DEFAULT_TIME_LIMIT, as_budget
from sospoly.tolerances import as_tolerances
from sospoly.solvers import get_backend

from ..errors import FieldError
from ..model.cameras import WorldFrame, as_world_frame
from ..model.constraints import Method

__all__ = ["TriangulationOptions", "SolvePath", "Sparsity", "MethodChoice", "DEFAULT_OPTIONS", "TRIANGULATION_BUDGET",
           "options_from", "OptionError", "OptionTypeError", "SPARSITY_CHOICES", "SPARSITY_SPELLINGS",
           "DEFAULT_TIME_LIMIT"]


class OptionError(FieldError):
    """An invalid option: ``field`` names it, ``reason`` says what is wrong (``"must be ..."``).

    ``str()`` is ``"<field> <reason>"`` unless a whole ``message`` is given (a sentence that reads better
    than the two parts, e.g. ``"max_delta (2) must be >= delta (4)"``).  The command line turns ``field``
    into its flag (``max_delta`` -> ``--max-delta``) and the problem-file reader into the field's location:
    nothing parses the text (:class:`tritools.errors.FieldError`).  ``detail`` is ``reason`` (its older name)."""

    @property
    def detail(self) -> str:
        return self.reason


class OptionTypeError(OptionError, TypeError):
    """An option of the wrong type (an :class:`OptionError` that is also a TypeError)."""


class SolvePath(str, enum.Enum):
    """How a point is certified: ``auto`` (certification by verification first where it applies) or ``sdp``."""
    SDP = "sdp"
    AUTO = "auto"


#: the ``sparsity`` choices of a triangulation (:class:`sospoly.Sparsity`): auto, dense (spelt ``"none"`` too) and
#: the view cliques (the caller-given cliques of sospoly, spelt ``"views"``: chain of view triples + dense degree 2).
SPARSITY_CHOICES = (Sparsity.AUTO, Sparsity.DENSE, Sparsity.CLIQUES)
#: tritools' own spelling of a sparsity choice, accepted on input.
SPARSITY_SPELLINGS = {"views": Sparsity.CLIQUES}


class MethodChoice(str, enum.Enum):
    """``method`` of the options: Theorem 1, Corollary 1, or ``auto`` (the degree plan decides)."""
    AUTO = "auto"
    THEOREM1 = "theorem1"
    COROLLARY1 = "corollary1"


#: the default budget of one point (all its degrees together): :data:`sospoly.budget.DEFAULT_TIME_LIMIT` (60 s),
#: 2 GiB.
TRIANGULATION_BUDGET = Budget(time_limit=DEFAULT_TIME_LIMIT, max_bytes=2 * 2 ** 30)
#: keyword shorthands of :meth:`TriangulationOptions.replace` (and so of ``triangulate(..., time_limit=5)``) for
#: the fields of the budget.
BUDGET_SHORTHANDS = ("time_limit", "max_bytes")


def _enum(cls, value, name):
    try:
        return cls(getattr(value, "value", value))
    except ValueError:
        allowed = ", ".join(repr(e.value) for e in cls)
        raise OptionError(name, f"must be one of {allowed}, got {value!r}") from None


def _sparsity(value) -> Sparsity:
    try:
        return Sparsity.parse(value, "sparsity", SPARSITY_CHOICES, SPARSITY_SPELLINGS)
    except ValueError:
        raise OptionError("sparsity", "must be one of 'auto', 'none' (or 'dense'), 'views' (or 'cliques'), "
                                      f"got {value!r}") from None


def _degree(value, name: str, minimum: int = 2):
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        else:
            raise OptionError(name, f"must be an even integer >= {minimum}, got {value!r}")
    value = int(value)
    if value < minimum or value % 2:
        raise OptionError(name, f"must be an even integer >= {minimum}, got {value}")
    if value > 1000:
        raise OptionError(name, f"must be at most 1000, got {value}",
                          f"{name} = {value} is far beyond any solvable relaxation (at most 1000)")
    return value


def _seconds(value, name: str):
    """None, or a positive number of seconds (inf: no limit)."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or math.isnan(value) or not value > 0:
        raise OptionError(name, f"must be a positive number of seconds or None, got {value!r}")
    return float(value)


def _level(value, name: str):
    """None, or a finite non-negative number."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value) or value < 0:
        raise OptionError(name, f"must be a finite non-negative number or None, got {value!r}")
    return float(value)


def _multiplier(m):
    if isinstance(m, str) and not isinstance(m, Multiplier):
        return _enum(Multiplier, m, "multiplier")
    if not isinstance(m, (Multiplier, Polynomial)) and not (isinstance(m, numbers.Real) and not isinstance(m, bool)
                                                            and math.isfinite(m) and m > 0):
        raise OptionError("multiplier", f"must be 'fixed', 'putinar', 'free', a positive finite number or an "
                                        f"SOS Polynomial, got {m!r}")
    return m


def _checked(name: str, check, value):
    """``check(value)``, with its ValueError / TypeError as an :class:`OptionError` / :class:`OptionTypeError`
    naming ``name`` (the checks of sospoly and of the camera model, which know no option names)."""
    try:
        return check(value)
    except TypeError as exc:
        raise OptionTypeError(name, f"is invalid: {exc}", str(exc)) from None
    except ValueError as exc:
        raise OptionError(name, f"is invalid: {exc}", str(exc)) from None


def _backend(value):
    if isinstance(value, str):
        if value.partition(":")[0] not in ("clarabel", "ipm", "auto", "cvxpy"):
            raise OptionError("backend", f"must be 'clarabel', 'ipm', 'auto', 'cvxpy' or 'cvxpy:<SOLVER>', "
                                         f"got {value!r}")
        _checked("backend", get_backend, value)     # an unknown or uninstalled solver, named
    elif value is not None:
        _checked("backend", get_backend, value)     # an object: sospoly's back-end protocol (a solve method)
    return value


@dataclass(frozen=True)
class TriangulationOptions:
    """Options of a triangulation (see the module docstring for the defaults).

    Parameters
    ----------
    method : "auto", "theorem1" (4x4 minors + SVD reduction) or "corollary1" (epipolar constraints); an explicit
        method runs that certificate's degree plan only, without the stages "auto" adds (the sub-problem of the views
        whose regions hold the estimate, where long regions are trimmed; the exact-variety step at 5+ views; the
        multi-start estimate of uncertified point problems; docs/certificates.md), so it may leave ``not_certified``
        a problem "auto" certifies (review 47a F6)
    delta : first relaxation degree (even, >= delta_min; default delta_min)
    max_delta : last degree tried (default: 4 for ``method="auto"``; ``delta`` when given, else
        delta_min + 2, for an explicit method)
    path : "auto" (certification by verification first where it applies) or "sdp"
    sparsity : :class:`sospoly.Sparsity` ``AUTO``, ``DENSE`` or ``CLIQUES`` (the view cliques), spelt
        "auto", "none" (or "dense") and "views"
    multiplier : "fixed" (the paper's q = (1 + ||v||^2)^(delta/2 - 1); q = 1 for sparse formulations),
        "putinar" (q = 1), "free" (GEVP by bisection) or a positive number / SOS Polynomial
    refine : local L2 refinement of the extracted estimate (it can only lower gamma_UB)
    normalize : normalise the data (the L2 problem is unchanged, see :mod:`tritools.model.normalize`)
    backend, form : sospoly back-end (None: automatic) and Gram form
    tolerances : :class:`sospoly.Tolerances` (the certificate rule)
    budget : :class:`sospoly.Budget` per point: ``time_limit`` for each point, on every path (see
        :mod:`tritools.solve.settings`), ``max_bytes`` for each program
    total_time_limit : seconds for a whole batch call (None, the default: no limit); the points not finished
        when it expires get status ``time_limit`` with the estimate found so far (a single ``triangulate``
        call is bounded by ``budget.time_limit`` alone)
    require_in_front : a certified minimiser behind a camera gets status ``behind_camera`` instead of
        ``optimal`` (by default it stays ``optimal`` with ``in_front=False`` and a message)
    world_frame : handedness of the cameras' world frame, the sign rule of the depths that judge
        ``in_front`` (:class:`tritools.model.cameras.WorldFrame`: ``"right_handed"``, the default, or
        ``"reflected"`` for a mirrored reconstruction such as the Oxford corridor and house sequences)
    lower_bound_stop : a level of gamma (pixels, the caller's units; None, the default: no stop).  The degree
        plan (and the exact-variety step) stops as soon as the best rigorous ``gamma_lb`` so far reaches it
        without a certificate -- like a MIP solver's best-bound stop: a caller that only needs
        ``gamma* >= level`` (the robust search's subset bounds) skips the steps that would tighten the bound
        further.  Such a result is never optimal: status ``not_certified``, its ``gamma_lb`` the rigorous bound
        reached, and a message saying the plan stopped there (:data:`tritools.solve.stages.sdp.BOUND_STOP`).
        Robust calls do not pass it to their sub-problems (:mod:`tritools.solve.robust_subsolve` sets their own)

    Every invalid field raises :class:`OptionError` naming it.
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
    total_time_limit: float | None = None
    lower_bound_stop: float | None = None

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "method", _enum(MethodChoice, self.method, "method"))
        set_(self, "path", _enum(SolvePath, self.path, "path"))
        set_(self, "sparsity", _sparsity(self.sparsity))
        set_(self, "form", _enum(GramForm, self.form, "form"))
        set_(self, "world_frame", _checked("world_frame", as_world_frame, self.world_frame))
        set_(self, "delta", _degree(self.delta, "delta"))
        set_(self, "max_delta", _degree(self.max_delta, "max_delta"))
        if self.delta is not None and self.max_delta is not None and self.max_delta < self.delta:
            raise OptionError("max_delta", f"must be >= delta ({self.delta}), got {self.max_delta}",
                              f"max_delta ({self.max_delta}) must be >= delta ({self.delta})")
        set_(self, "multiplier", _multiplier(self.multiplier))
        if self.multiplier == Multiplier.FREE and self.sparsity == Sparsity.CLIQUES:
            raise OptionError("multiplier", "'free' needs a dense certificate: sparsity 'auto' or 'none', got "
                                            "sparsity 'views'")
        for name in ("refine", "normalize", "require_in_front"):
            if not isinstance(getattr(self, name), (bool, int)) or isinstance(getattr(self, name), float):
                raise OptionTypeError(name, f"must be True or False, got {getattr(self, name)!r}")
            set_(self, name, bool(getattr(self, name)))
        set_(self, "tolerances", _checked("tolerances", as_tolerances, self.tolerances))
        set_(self, "budget", TRIANGULATION_BUDGET if self.budget is None else _checked("budget", as_budget,
                                                                                        self.budget))
        set_(self, "total_time_limit", _seconds(self.total_time_limit, "total_time_limit"))
        set_(self, "lower_bound_stop", _level(self.lower_bound_stop, "lower_bound_stop"))
        _backend(self.backend)

    def replace(self, **changes) -> TriangulationOptions:
        """A copy with some fields changed (validated again); None values are ignored.

        ``time_limit`` (seconds per point) and ``max_bytes`` are accepted as shorthands for the fields of the
        budget: ``replace(time_limit=5)`` keeps the budget's memory limit (``budget=Budget(time_limit=5)``
        would take sospoly's default memory limit instead)."""
        changes = {k: v for k, v in changes.items() if v is not None}
        limits = {k: changes.pop(k) for k in BUDGET_SHORTHANDS if k in changes}
        if limits:
            base = _checked("budget", as_budget, changes["budget"]) if "budget" in changes else self.budget
            for name, value in limits.items():         # validated by sospoly.Budget, named here
                _checked(name, lambda v, n=name: Budget(**{n: v}), value)
            changes["budget"] = dataclasses.replace(base, **limits)
        unknown = set(changes) - {f.name for f in dataclasses.fields(self)}
        if unknown:
            raise OptionTypeError(sorted(unknown)[0], "is not a triangulation option",
                                  f"unknown triangulation option(s): {', '.join(sorted(unknown))}")
        return dataclasses.replace(self, **changes) if changes else self

    @property
    def explicit_method(self) -> Method | None:
        return None if self.method == MethodChoice.AUTO else Method(self.method.value)


DEFAULT_OPTIONS = TriangulationOptions()


def options_from(options: TriangulationOptions | None = None, **overrides) -> TriangulationOptions:
    """The options of a call: ``options`` (default :data:`DEFAULT_OPTIONS`) with the keyword overrides that
    are not None (the one place where the keyword arguments of the public functions are merged)."""
    if options is not None and not isinstance(options, TriangulationOptions):
        raise OptionTypeError("options", f"must be a TriangulationOptions, got {type(options).__name__}")
    return (options or DEFAULT_OPTIONS).replace(**overrides)
