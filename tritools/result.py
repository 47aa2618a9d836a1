"""Result records shared by the certified triangulation and the baseline methods.

A :class:`TriangulationResult` reports, for one triangulation problem (SPEC §1, paper eq. (5)),
the estimate ``X`` of the scene point, the upper bound ``gamma_ub = gamma(X)`` (exact distances
to the regions, paper eq. (6)), and for the certified method (Theorem 1 / Corollary 1) the lower
bound ``gamma_lb`` with ``gamma_lb <= gamma* <= gamma_ub``.  Local and baseline methods leave
``gamma_lb`` and ``optimal`` at ``None`` (no certificate; "NA" in the paper's tables).

Every certified result is self-consistent: ``gamma_lb <= gamma_ub`` always (a lower bound above
the upper bound beyond the tolerance is a ``numerical_failure``, never a certificate; within the
tolerance it is reported equal to the upper bound).  Each step tried is an :class:`Attempt`.
:meth:`TriangulationResult.to_dict` / :meth:`TriangulationResult.from_dict` are the one JSON form
(NaN and infinity become ``null``).
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

__all__ = ["Status", "Attempt", "TriangulationResult", "jsonable", "IllPosedError", "input_failure", "refused"]


def __getattr__(name: str):
    """``TriangulationResults`` (the batch record whose rows are :class:`TriangulationResult`) lives in
    :mod:`tritools.records`; imported on first use (PEP 562: no import cycle)."""
    if name == "TriangulationResults":
        from .records import TriangulationResults

        return TriangulationResults
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


class Status(str, enum.Enum):
    """Outcome of a triangulation method.

    OPTIMAL
        ``gamma_lb == gamma_ub`` to the stated tolerance: ``X`` is a certified global minimiser
        (Theorem 1), in front of every camera.
    BEHIND_CAMERA
        With ``require_in_front``: certified as OPTIMAL, but the minimiser lies behind at least one
        camera (``in_front`` is False, ``depths`` say which).  The L2 problem ignores cheirality, so
        such data are not consistent with a physical point in front of the cameras; by default the
        status stays OPTIMAL and ``in_front`` says it.
    NOT_CERTIFIED
        The LMI method returned bounds that do not meet.
    NO_CERTIFICATE
        A local or baseline method: an estimate without any bound.
    ILL_POSED
        The problem has no finite estimate (e.g. the extracted homogeneous point has ``w4 = 0``, all
        cameras share one centre).
    SOLVER_FAILED
        The SDP solver or the local optimiser reported a failure (``X`` and ``gamma_ub`` are still the
        best estimate found, e.g. the local L2 refinement of the linear estimate).
    NUMERICAL_FAILURE
        Results are not trustworthy (NaN, inconsistent bounds, ...).
    TIME_LIMIT
        The time limit of the budget was reached first (the best bounds found so far are reported).
    BUDGET_EXCEEDED
        The next program of the plan exceeds the memory budget, so it was not built (the programs before it were
        built and solved: their best bounds are reported; review 47a F2).
    INVALID_INPUT
        The method is not applicable to the given input (e.g. Newton with a non-point region).
    """

    OPTIMAL = "optimal"
    BEHIND_CAMERA = "behind_camera"
    NOT_CERTIFIED = "not_certified"
    NO_CERTIFICATE = "no_certificate"
    ILL_POSED = "ill_posed"
    SOLVER_FAILED = "solver_failed"
    NUMERICAL_FAILURE = "numerical_failure"
    TIME_LIMIT = "time_limit"
    BUDGET_EXCEEDED = "budget_exceeded"
    INVALID_INPUT = "invalid_input"

    def __str__(self) -> str:  # "optimal" rather than "Status.OPTIMAL"
        return self.value

    @property
    def certified(self) -> bool:
        """A certificate of global optimality was found (OPTIMAL or BEHIND_CAMERA)."""
        return self in (Status.OPTIMAL, Status.BEHIND_CAMERA)


def jsonable(v):
    """Arrays -> lists, enums -> values, non-finite floats -> None (JSON has no NaN), records -> dicts."""
    if isinstance(v, np.ndarray):
        return [jsonable(x) for x in v.tolist()]
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, enum.Enum):
        return v.value
    if isinstance(v, float):
        return v if math.isfinite(v) else None
    if isinstance(v, Attempt):
        return {f.name: jsonable(getattr(v, f.name)) for f in fields(v)}
    if isinstance(v, dict):
        return {str(k): jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [jsonable(x) for x in v]
    return v


class IllPosedError(ValueError):
    """Valid data that define no triangulation (SPEC section 6): e.g. every camera the same up to scale, so no point
    has a depth.  A ValueError for the single call's caller; a batch records it as ``Status.ILL_POSED``
    (:func:`input_failure`), not as bad input."""


def input_failure(exc: Exception) -> tuple[Status, str]:
    """(status, message) of a batch item whose problem could not be set up: ``ILL_POSED`` with the error's own words
    for an :class:`IllPosedError`, ``INVALID_INPUT`` with the error's class for other ValueError / TypeError."""
    if isinstance(exc, IllPosedError):
        return Status.ILL_POSED, str(exc)
    return Status.INVALID_INPUT, f"{type(exc).__name__}: {exc}"


def refused(result) -> bool:
    """Whether a result is an :func:`input_failure` row (its problem was never set up: ``INVALID_INPUT``, or
    ``ILL_POSED`` without an estimate), which later stages pass on as it is rather than solve again."""
    return result.status == Status.INVALID_INPUT or (result.status == Status.ILL_POSED and result.X is None)


@dataclass(frozen=True)
class Attempt:
    """One step of a triangulation strategy.

    ``step`` names it (``"sdp"``, ``"verification"``, ``"sdp-batch"``, ``"tight"`` for a re-solve
    with tighter solver tolerances, ``"retry"`` for a batch retry step); ``solver`` lists the
    back-end attempts (``label:status``) of an SDP.
    """

    method: str
    delta: int | None
    status: str
    gamma_lb: float | None = None
    gamma_ub: float | None = None
    step: str = "sdp"
    sparsity: str | None = None
    solver: tuple = ()
    seconds: float = 0.0

    @classmethod
    def from_dict(cls, d) -> Attempt:
        kw = {f.name: d.get(f.name) for f in fields(cls) if f.name in d}
        kw["solver"] = tuple(kw.get("solver") or ())
        kw["seconds"] = float(kw.get("seconds") or 0.0)
        return cls(**kw)


def _opt_array(value, shape_tail: tuple, name: str) -> np.ndarray | None:
    if value is None:
        return None
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric array, got {type(value).__name__}") from exc
    if shape_tail == (3,):
        if arr.shape != (3,):
            raise ValueError(f"{name} must have shape (3,), got {arr.shape}")
    elif shape_tail == (None,):
        if arr.ndim != 1:
            raise ValueError(f"{name} must have shape (N,), got {arr.shape}")
    elif arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(f"{name} must have shape (N, 2), got {arr.shape}")
    arr.setflags(write=False)
    return arr


def _opt_bools(value, name: str) -> np.ndarray | None:
    if value is None:
        return None
    arr = np.asarray(value)
    boolean = arr.dtype == bool or (np.issubdtype(arr.dtype, np.integer) and bool(np.all((arr == 0) | (arr == 1))))
    if arr.ndim != 1 or not boolean:
        raise ValueError(f"{name} must be a boolean array of shape (N,), got {arr.dtype} {arr.shape}")
    arr = arr.astype(bool)
    arr.setflags(write=False)
    return arr


def _opt_float(value, name: str) -> float | None:
    if value is None:
        return None
    try:
        return float(value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a real number or None, got {value!r}") from exc


#: statuses whose lower bound is not trusted: a result with one of them carries gamma_lb = None
#: (docs/getting-started.md: "no trustworthy bound at all"); gamma_ub, the value at an actual X, stays
UNTRUSTED_LOWER = frozenset({Status.SOLVER_FAILED, Status.NUMERICAL_FAILURE, Status.ILL_POSED})


@dataclass(frozen=True)
class TriangulationResult:
    """Estimate of a scene point with optional optimality certificate: one row of the batch record
    :class:`tritools.records.TriangulationResults` (``results[i]``; its JSON form is the row of the record's).

    Parameters
    ----------
    method : str
        Method name (``"theorem1"``, ``"corollary1"``, ``"nms"``, ...).
    status : Status
        Outcome (a :class:`Status` or its string value).
    X : ndarray, shape (3,), optional
        Final estimate of the scene point.
    gamma_ub : float, optional
        ``gamma(X)`` with exact distances (SPEC §1, paper eq. (6)), rounded up by the float evaluation's round-off
        bound (:func:`tritools.solve.report.gamma_upper`: about 6e-14 of the projections' pixel magnitude per view,
        ~6e-11 px at 1000 px coordinates), so an upper bound on ``gamma(X)`` and on ``gamma*``.
    gamma_lb : float, optional
        A lower bound on ``gamma*`` from ``sqrt(c*/(2N))`` (paper eq. (44), Theorem 1), with the PSD
        defect of the returned certificate subtracted; never above ``gamma_ub``.
    optimal : bool, optional
        Whether ``gamma_lb`` certifies ``X`` (``None`` when no certificate exists).
    delta : int, optional
        Relaxation degree of the certificate; without one, of the step whose lower bound is reported (every
        degree tried is in ``attempts``).
    n_lmivar : int, optional
        Number of independent scalar LMI variables (SPEC §8).
    image_points : ndarray, shape (N, 2), optional
        The image points ``x_i*`` (from ``v*`` or the projections of ``X``).
    X_raw, gamma_ub_raw : optional
        Extracted estimate before local refinement and its ``gamma``.
    certified_by : str, optional
        ``"sdp"`` (the LMI of Theorem 1 / Corollary 1), ``"verification"`` (KKT multipliers and the
        Lagrangian bound of :mod:`sospoly.analysis.verify`) or ``"trivial_bound"`` (gamma(X) within the
        certificate tolerance of the lower bound 0, :mod:`tritools.solve.trivial`), ``"sub_problem"`` (the
        problem without views whose regions hold its minimiser, :mod:`tritools.solve.stages.subproblem`) or
        ``"branch-and-bound"`` (robust TLS, :mod:`tritools.solve.robust`); ``None`` when not certified.
    message : str
        Human readable details.
    timings : dict
        Wall-clock times in seconds: ``"total"`` (and per stage) for a point solved on its own,
        ``"batch_share"`` (its even share of the vectorised calls) for a point decided inside a batch.
    attempts : tuple of :class:`Attempt`
        Every step tried, in order.
    sparsity : str, optional
        The formulation of the certificate: ``"dense"`` or ``"views"`` (view cliques).
    in_front : bool, optional
        Whether ``X`` lies in front of every camera (positive depth).
    depths : ndarray, shape (N,), optional
        Depth of ``X`` in each camera (Hartley & Zisserman eq. (6.15); positive in front).
    residuals : ndarray, shape (N,), optional
        Per-view distance ``d(Phi(X, P_i), R_i)`` (pixels, evaluated in floating point); ``gamma_ub`` is their RMS
        over 2N rounded up by the round-off bound above (at residuals of 1e-5 px with coordinates of 1e5 px the two
        differ by ~1e-3 relative, 5e-9 px absolute).
    inliers : bool ndarray, shape (N,), optional
        With ``robust=`` (truncated least squares, :mod:`tritools.solve.robust`): the views with
        ``d_i(X) < c_i``; then ``gamma_lb`` / ``gamma_ub`` bound gamma_TLS = sqrt(sum_i min(d_i^2, c_i^2) / 2N).
        ``None`` without ``robust=``.
    """

    method: str
    status: Status
    X: np.ndarray | None = None
    gamma_ub: float | None = None
    gamma_lb: float | None = None
    optimal: bool | None = None
    delta: int | None = None
    n_lmivar: int | None = None
    image_points: np.ndarray | None = None
    X_raw: np.ndarray | None = None
    gamma_ub_raw: float | None = None
    certified_by: str | None = None
    message: str = ""
    timings: dict = field(default_factory=dict)
    attempts: tuple = ()
    sparsity: str | None = None
    in_front: bool | None = None
    depths: np.ndarray | None = None
    residuals: np.ndarray | None = None
    inliers: np.ndarray | None = None

    def __post_init__(self) -> None:
        try:
            status = Status(self.status)
        except ValueError as exc:
            raise ValueError(f"status must be one of {[s.value for s in Status]}, got {self.status!r}") from exc
        set_ = object.__setattr__
        set_(self, "status", status)
        set_(self, "method", str(self.method))
        set_(self, "X", _opt_array(self.X, (3,), "X"))
        set_(self, "X_raw", _opt_array(self.X_raw, (3,), "X_raw"))
        set_(self, "image_points", _opt_array(self.image_points, (None, 2), "image_points"))
        set_(self, "depths", _opt_array(self.depths, (None,), "depths"))
        set_(self, "residuals", _opt_array(self.residuals, (None,), "residuals"))
        set_(self, "inliers", _opt_bools(self.inliers, "inliers"))
        for name in ("gamma_ub", "gamma_lb", "gamma_ub_raw"):
            set_(self, name, _opt_float(getattr(self, name), name))
        if status in UNTRUSTED_LOWER and self.gamma_lb is not None:
            set_(self, "gamma_lb", None)    # no trustworthy bound (review 8b F6: 340 px for a 1.3 px optimum)
        for name in ("optimal", "in_front"):
            if getattr(self, name) is not None:
                set_(self, name, bool(getattr(self, name)))
        for name in ("delta", "n_lmivar"):
            value = getattr(self, name)
            if value is not None:
                set_(self, name, int(value))
        set_(self, "timings", dict(self.timings))
        set_(self, "attempts", tuple(a if isinstance(a, Attempt) else Attempt.from_dict(a) if isinstance(a, dict)
                                     else a for a in self.attempts))

    def __eq__(self, other) -> bool:
        """Equal in the one JSON form (:meth:`to_dict`: every field; NaN and ``None`` alike)."""
        if not isinstance(other, TriangulationResult):
            return NotImplemented
        return self.to_dict() == other.to_dict()

    @property
    def gap(self) -> float | None:
        """``gamma_ub - gamma_lb`` (``None`` unless both bounds are known)."""
        if self.gamma_ub is None or self.gamma_lb is None:
            return None
        return self.gamma_ub - self.gamma_lb

    def to_dict(self) -> dict[str, Any]:
        """The one JSON form: every field, arrays as lists, the status its value, attempts as objects, NaN
        and infinity as ``null``."""
        return {f.name: jsonable(getattr(self, f.name)) for f in fields(self)}

    @classmethod
    def from_dict(cls, d) -> TriangulationResult:
        """Inverse of :meth:`to_dict` (unknown keys ignored; ``null`` stays ``None``)."""
        kw = {f.name: d[f.name] for f in fields(cls) if f.name in d}
        kw["status"] = Status(kw["status"])
        kw["attempts"] = tuple(Attempt.from_dict(a) if isinstance(a, dict) else a for a in kw.get("attempts") or ())
        kw["timings"] = kw.get("timings") or {}
        return cls(**kw)

    def __str__(self) -> str:
        def f(v):
            return "NA" if v is None else f"{v:.6g}"

        X = "NA" if self.X is None else "(" + ", ".join(f"{c:.4g}" for c in self.X) + ")"
        parts = [f"{self.method}: {self.status.value}", f"X={X}", f"gamma_ub={f(self.gamma_ub)}",
                 f"gamma_lb={f(self.gamma_lb)}"]
        if self.delta is not None:
            parts.append(f"delta={self.delta}")
        if self.n_lmivar is not None:
            parts.append(f"n_lmivar={self.n_lmivar}")
        if "total" in self.timings:
            parts.append(f"time={self.timings['total']:.3g}s")
        if self.message:
            parts.append(f"[{self.message}]")
        return " ".join(parts)
