"""The one place where the model path calls the solver: :func:`certify_stack`.

``certify_stack(cameras (M, N, 3, 4), points2d (M, N, 2), options)`` certifies M point-region
problems with N views each through the library's stacked engine
(:func:`tritools.solve.batch.solve_point_stack`: vectorised certification by verification, the batched
degree-2 SDP, then the per-point path for the rest, with the degrees of ``options``) and returns
the batch record (:class:`StackResult`, columns in the SfM encodings).  Everything else of the
model path (undistortion, grouping, cheirality, writing) is numpy code outside this module.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from ..io.export import STATUS_LEGEND
from ..records import TriangulationResults
from ..result import Status
from ..solve.options import DEFAULT_OPTIONS, OptionError, OptionTypeError, TriangulationOptions

__all__ = ["CertifyOptions", "RecordColumns", "StackResult", "certify_stack", "STATUS_LEGEND", "status_code",
           "solver_options", "robust_threshold", "written_certified"]

_CODE = {s: k for k, s in enumerate(STATUS_LEGEND)}


def status_code(status) -> int:
    """Code of a :class:`tritools.Status` (or its value) in :data:`STATUS_LEGEND`."""
    return _CODE[Status(status).value]


def written_certified(status, optimal, in_front, updated):
    """CERTIFIED of a re-triangulated point (docs/colmap.md): the *written* point is a certified global minimiser in
    front of its cameras -- status ``optimal`` (codes of :data:`STATUS_LEGEND`), certified by the solver, in front,
    and written anew (``updated``).  A certified estimate that is not written -- behind a camera under
    ``behind="keep-input"``, or a robust optimum that keeps fewer than two observations (any point of one ray costs
    the same: the input point and its track are kept) -- leaves an input point that is not that minimiser (review
    24b S1).  Arrays or scalars, elementwise."""
    return (np.asarray(status) == _CODE[Status.OPTIMAL.value]) & np.asarray(optimal, bool) \
        & np.asarray(in_front, bool) & np.asarray(updated, bool)


def solver_options(base, name: str, **shorthands) -> TriangulationOptions:
    """``base`` (a :class:`TriangulationOptions`; None: :data:`DEFAULT_OPTIONS`) with the shorthands that are not
    None (``method``, ``path``, ``delta``, ``max_delta``), validated once by :class:`TriangulationOptions`
    (:class:`OptionError` naming the field); an ``OptionTypeError`` naming ``name`` when ``base`` is something
    else."""
    if base is not None and not isinstance(base, TriangulationOptions):
        raise OptionTypeError(name, f"must be a tritools.TriangulationOptions, got {type(base).__name__}")
    return (DEFAULT_OPTIONS if base is None else base).replace(**shorthands)


def robust_threshold(value) -> float | None:
    """None, or ``value`` as a positive threshold in pixels (:class:`OptionError` naming ``robust``)."""
    if value is None:
        return None
    try:      # a number, not its text (tritools.triangulate's rule; the CLI parses its flag itself)
        ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool) and \
            float(value) > 0
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise OptionError("robust", f"must be a positive threshold in pixels, got {value!r}")
    from ..solve.robust import MIN_THRESHOLD
    if float(value) < MIN_THRESHOLD:
        raise OptionError("robust", f"must be at least {MIN_THRESHOLD:g} pixels (its square underflows), "
                                    f"got {value!r}")
    return float(value)


@dataclass(frozen=True, init=False)
class CertifyOptions:
    """Solver settings of :func:`certify_stack`.

    ``options``: the :class:`~tritools.solve.options.TriangulationOptions` of every problem (None: the
    defaults of ``tritools.triangulate`` -- method auto, path auto, the default per-point budget);
    ``method``, ``path``, ``delta``, ``max_delta``: constructor shorthands for its fields (None: its value;
    read back as properties); ``executor``: for the per-problem SDPs (see
    :func:`tritools.solve.batch.triangulate_many`); ``robust``: None, or the TLS threshold in pixels
    (:mod:`tritools.solve.robust_batch`).  Invalid values raise :class:`OptionError` naming the field.
    """
    options: TriangulationOptions
    executor: object = field(compare=False)
    robust: float | None

    def __init__(self, method: str | None = None, path: str | None = None, delta: int | None = None,
                 max_delta: int | None = None, executor: object = None, options: TriangulationOptions | None = None,
                 robust: float | None = None):
        set_ = object.__setattr__
        set_(self, "options", solver_options(options, "options", method=method, path=path, delta=delta,
                                             max_delta=max_delta))
        set_(self, "executor", executor)
        set_(self, "robust", robust_threshold(robust))

    method = property(lambda self: self.options.method.value, doc="the options' method (a string)")
    path = property(lambda self: self.options.path.value, doc="the options' path (a string)")
    delta = property(lambda self: self.options.delta, doc="the options' first degree (None: delta_min)")
    max_delta = property(lambda self: self.options.max_delta, doc="the options' last degree (None: the plan's)")

    def triangulation_options(self) -> TriangulationOptions:
        """The :class:`~tritools.solve.options.TriangulationOptions` these settings stand for (validated)."""
        return self.options


class RecordColumns:
    """Per-point columns of an SfM result read from its batch record ``results``
    (:class:`~tritools.records.TriangulationResults`) in the SfM encodings: ``status`` int8 codes of
    :data:`STATUS_LEGEND`, ``certified_by`` ``""`` where none, ``delta`` int16 (-1 where none), ``n_views``
    int32; ``X``, ``gamma_lb``, ``gamma_ub`` (NaN when absent), ``optimal``, ``in_front``, ``message`` as
    the record has them."""

    @property
    def X(self) -> np.ndarray:
        """(M, 3) estimates, NaN rows where none."""
        return self.results.X

    @property
    def gamma_lb(self) -> np.ndarray:
        """(M,) lower bounds, NaN when absent."""
        return self.results.gamma_lb

    @property
    def gamma_ub(self) -> np.ndarray:
        """(M,) upper bounds gamma(X), NaN when absent."""
        return self.results.gamma_ub

    @property
    def optimal(self) -> np.ndarray:
        """(M,) certified by the solver."""
        return self.results.optimal

    @property
    def in_front(self) -> np.ndarray:
        """(M,) positive depth in every camera."""
        return self.results.in_front

    @property
    def message(self) -> np.ndarray:
        """(M,) per-point details."""
        return self.results.message

    @cached_property
    def n_views(self) -> np.ndarray:
        """(M,) int32 views of each point."""
        return self.results.n_views.astype(np.int32)

    @cached_property
    def status(self) -> np.ndarray:
        """(M,) int8 codes of STATUS_LEGEND."""
        return np.fromiter((_CODE[s.value] for s in self.results.status), np.int8, count=len(self.results))

    @cached_property
    def certified_by(self) -> np.ndarray:
        """(M,) object: how each point was certified, "" where not."""
        return np.fromiter((c or "" for c in self.results.certified_by), object, count=len(self.results))

    @cached_property
    def delta(self) -> np.ndarray:
        """(M,) int16 relaxation degree, -1 where none."""
        return self.results.delta.astype(np.int16)


@dataclass(frozen=True, eq=False)
class StackResult(RecordColumns):
    """Result of :func:`certify_stack`: the batch record ``results`` of the M problems, read as SfM columns
    (:class:`RecordColumns`: ``X`` (M, 3), ``gamma_lb``/``gamma_ub``, ``status`` codes, ``optimal``,
    ``certified_by``, ``delta``, ``message``); with ``robust``, ``inliers`` (M, N): the views each estimate keeps
    (all of them where the solver gave no inlier set)."""
    results: TriangulationResults
    robust: bool = False

    @property
    def inliers(self) -> np.ndarray | None:
        if not self.robust:
            return None
        r = self.results
        if r.inliers is None:
            return np.ones((len(r), r.width), bool)
        return r.inliers | r.null.get("inliers", np.zeros(len(r), bool))[:, None]


def certify_stack(cameras, points2d, options=None) -> StackResult:
    """Certify M problems of N views with point regions (see the module docstring).

    ``options``: a :class:`CertifyOptions`, a :class:`~tritools.solve.options.TriangulationOptions`, or None
    (the defaults of ``tritools.triangulate``)."""
    from ..model.regions import real_array
    from ..solve.batch import solve_point_stack

    if options is None or isinstance(options, TriangulationOptions):
        options = CertifyOptions(options=options)
    if not isinstance(options, CertifyOptions):
        raise TypeError(f"options must be a CertifyOptions or a TriangulationOptions, got {type(options).__name__}")
    opts = options.triangulation_options()
    C = real_array(cameras, "cameras")
    x = real_array(points2d, "points2d")
    M, N = x.shape[:2]
    if M == 0:
        return StackResult(TriangulationResults(method=[], status=[]), robust=options.robust is not None)
    if options.robust is not None:
        return _robust_stack(C, x, opts, options)
    return StackResult(solve_point_stack(C, x, opts, executor=options.executor).record())


def _robust_stack(C, x, opts, options: CertifyOptions) -> StackResult:
    """``certify_stack`` with ``robust``: TLS results (:func:`tritools.solve.robust_batch.robust_many`)."""
    from ..solve.robust_batch import robust_many

    results = robust_many([(C[m], x[m]) for m in range(len(C))], options.robust, opts, executor=options.executor)
    return StackResult(TriangulationResults.from_rows(results, np.full(len(C), x.shape[1])), robust=True)
