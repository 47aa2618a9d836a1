"""Result record shared by the certified triangulation and the baseline methods.

A :class:`TriangulationResult` reports, for one triangulation problem (SPEC §1,
paper eq. (5)), the estimate ``X`` of the scene point, the upper bound
``gamma_ub = gamma(X)`` (exact distances to the regions, paper eq. (6)), and for the
certified method (Theorem 1 / Corollary 1) the lower bound ``gamma_lb`` with
``gamma_lb <= gamma* <= gamma_ub``.  Local and baseline methods leave ``gamma_lb``
and ``optimal`` at ``None`` (no certificate; "NA" in the paper's tables).
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["Status", "TriangulationResult"]


class Status(str, enum.Enum):
    """Outcome of a triangulation method.

    OPTIMAL
        ``gamma_lb == gamma_ub`` to the stated tolerance: ``X`` is a certified
        global minimiser (Theorem 1).
    NOT_CERTIFIED
        The LMI method returned bounds that do not meet.
    NO_CERTIFICATE
        A local or baseline method: an estimate without any bound.
    ILL_POSED
        The problem has no finite estimate (e.g. the extracted homogeneous point has
        ``w4 = 0``, all cameras share one centre).
    SOLVER_FAILED
        The SDP solver or the local optimiser reported a failure.
    NUMERICAL_FAILURE
        Results are not trustworthy (NaN, inconsistent bounds, ...).
    INVALID_INPUT
        The method is not applicable to the given input (e.g. Newton with a
        non-point region).
    """

    OPTIMAL = "optimal"
    NOT_CERTIFIED = "not_certified"
    NO_CERTIFICATE = "no_certificate"
    ILL_POSED = "ill_posed"
    SOLVER_FAILED = "solver_failed"
    NUMERICAL_FAILURE = "numerical_failure"
    INVALID_INPUT = "invalid_input"

    def __str__(self) -> str:  # "optimal" rather than "Status.OPTIMAL"
        return self.value


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
    elif arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(f"{name} must have shape (N, 2), got {arr.shape}")
    arr.setflags(write=False)
    return arr


def _opt_float(value, name: str) -> float | None:
    if value is None:
        return None
    try:
        return float(value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a real number or None, got {value!r}") from exc


@dataclass(frozen=True)
class TriangulationResult:
    """Estimate of a scene point with optional optimality certificate.

    Parameters
    ----------
    method : str
        Method name (``"theorem1"``, ``"corollary1"``, ``"nms"``, ...).
    status : Status
        Outcome (a :class:`Status` or its string value).
    X : ndarray, shape (3,), optional
        Final estimate of the scene point.
    gamma_ub : float, optional
        ``gamma(X)`` with exact distances (SPEC §1, paper eq. (6)); an upper bound
        on ``gamma*``.
    gamma_lb : float, optional
        ``sqrt(c*/(2N))``, a lower bound on ``gamma*`` (paper eq. (44), Theorem 1).
    optimal : bool, optional
        Whether ``gamma_lb`` certifies ``X`` (``None`` when no certificate exists).
    delta : int, optional
        Relaxation degree used.
    n_lmivar : int, optional
        Number of independent scalar LMI variables (SPEC §8).
    image_points : ndarray, shape (N, 2), optional
        The image points ``x_i*`` (from ``v*`` or the projections of ``X``).
    X_raw, gamma_ub_raw : optional
        Extracted estimate before local refinement and its ``gamma``.
    certified_by : str, optional
        Which path produced the certificate: ``"sdp"`` (the LMI of Theorem 1 /
        Corollary 1) or ``"verification"`` (``path="auto"``: KKT multipliers and
        the Lagrangian bound of :mod:`sospoly.analysis.verify`); ``None`` when not certified.
    message : str
        Human readable details.
    timings : dict
        Wall-clock times in seconds, at least ``"total"``.
    attempts : tuple
        Per-degree records of an escalation strategy.
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

    def __post_init__(self) -> None:
        try:
            status = Status(self.status)
        except ValueError as exc:
            raise ValueError(f"status must be one of {[s.value for s in Status]}, got {self.status!r}") from exc
        object.__setattr__(self, "status", status)
        object.__setattr__(self, "method", str(self.method))
        object.__setattr__(self, "X", _opt_array(self.X, (3,), "X"))
        object.__setattr__(self, "X_raw", _opt_array(self.X_raw, (3,), "X_raw"))
        object.__setattr__(self, "image_points", _opt_array(self.image_points, (None, 2), "image_points"))
        for name in ("gamma_ub", "gamma_lb", "gamma_ub_raw"):
            object.__setattr__(self, name, _opt_float(getattr(self, name), name))
        if self.optimal is not None:
            object.__setattr__(self, "optimal", bool(self.optimal))
        for name in ("delta", "n_lmivar"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, int(value))
        object.__setattr__(self, "timings", dict(self.timings))
        object.__setattr__(self, "attempts", tuple(self.attempts))

    @property
    def gap(self) -> float | None:
        """``gamma_ub - gamma_lb`` (``None`` unless both bounds are known)."""
        if self.gamma_ub is None or self.gamma_lb is None:
            return None
        return self.gamma_ub - self.gamma_lb

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly dictionary (arrays become lists, status its string value)."""

        def conv(v):
            if isinstance(v, np.ndarray):
                return v.tolist()
            if isinstance(v, Status):
                return v.value
            if isinstance(v, float) and not math.isfinite(v):
                return str(v)
            return v

        return {
            "method": self.method,
            "status": self.status.value,
            "X": conv(self.X),
            "gamma_ub": conv(self.gamma_ub),
            "gamma_lb": conv(self.gamma_lb),
            "optimal": self.optimal,
            "delta": self.delta,
            "n_lmivar": self.n_lmivar,
            "image_points": conv(self.image_points),
            "X_raw": conv(self.X_raw),
            "gamma_ub_raw": conv(self.gamma_ub_raw),
            "certified_by": self.certified_by,
            "message": self.message,
            "timings": {k: conv(v) for k, v in self.timings.items()},
        }

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
