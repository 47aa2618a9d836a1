"""The one place where the model path calls the solver: :func:`certify_stack`.

``certify_stack(cameras (M, N, 3, 4), points2d (M, N, 2), options)`` certifies M point-region
problems with N views each through the library's stacked engine
(:func:`tritools.solve.batch.solve_point_stack`: vectorised certification by verification, the batched
degree-2 SDP, then the per-point path for the rest, with the degrees of ``options``) and returns
arrays (:class:`StackResult`).  Everything else of the model path (undistortion, grouping, cheirality,
writing) is numpy code outside this module.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..io.export import STATUS_LEGEND
from ..result import Status
from ..solve.options import DEFAULT_OPTIONS, OptionError, OptionTypeError, TriangulationOptions

__all__ = ["CertifyOptions", "StackResult", "certify_stack", "STATUS_LEGEND", "status_code", "solver_options",
           "robust_threshold"]

_CODE = {s: k for k, s in enumerate(STATUS_LEGEND)}


def status_code(status) -> int:
    """Code of a :class:`tritools.Status` (or its value) in :data:`STATUS_LEGEND`."""
    return _CODE[Status(status).value]


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
    try:
        ok = not isinstance(value, bool) and float(value) > 0
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise OptionError("robust", f"must be a positive threshold in pixels, got {value!r}")
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


@dataclass(frozen=True)
class StackResult:
    """Per-problem arrays of :func:`certify_stack` (first axis = problem).

    ``X`` (M, 3) NaN where no estimate; ``gamma_lb``/``gamma_ub`` NaN when absent; ``status``
    codes of :data:`STATUS_LEGEND`; ``optimal`` bool; ``certified_by`` object array of
    ``"verification"``/``"sdp"``/``""``; ``delta`` (-1 when none); ``message`` object array."""
    X: np.ndarray
    gamma_lb: np.ndarray
    gamma_ub: np.ndarray
    status: np.ndarray
    optimal: np.ndarray
    certified_by: np.ndarray
    delta: np.ndarray
    message: np.ndarray
    inliers: np.ndarray | None = None       # (M, N) with ``robust``: the views each estimate keeps


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
    out = StackResult(np.full((M, 3), np.nan), np.full(M, np.nan), np.full(M, np.nan),
                      np.full(M, _CODE[Status.SOLVER_FAILED.value], np.int8), np.zeros(M, bool),
                      np.full(M, "", object), np.full(M, -1, np.int16), np.full(M, "", object))
    if M == 0:
        return out
    if options.robust is not None:
        return _robust_stack(C, x, opts, options, out)
    arrays = solve_point_stack(C, x, opts, executor=options.executor).arrays()
    out.X[:] = arrays["X"]
    out.gamma_lb[:] = arrays["gamma_lb"]
    out.gamma_ub[:] = arrays["gamma_ub"]
    out.status[:] = [_CODE[Status(s).value] for s in arrays["status"]]
    out.optimal[:] = arrays["optimal"]
    out.certified_by[:] = [c or "" for c in arrays["certified_by"]]
    out.delta[:] = arrays["delta"]
    out.message[:] = [m or "" for m in arrays["message"]]
    return out


def _robust_stack(C, x, opts, options: CertifyOptions, out: StackResult) -> StackResult:
    """``certify_stack`` with ``robust``: TLS results (:func:`tritools.solve.robust_batch.robust_many`)."""
    import dataclasses

    from ..solve.robust_batch import robust_many

    results = robust_many([(C[m], x[m]) for m in range(len(C))], options.robust, opts, executor=options.executor)
    inliers = np.zeros(x.shape[:2], bool)
    for m, r in enumerate(results):
        if r.X is not None:
            out.X[m] = r.X
        out.gamma_lb[m] = np.nan if r.gamma_lb is None else r.gamma_lb
        out.gamma_ub[m] = np.nan if r.gamma_ub is None else r.gamma_ub
        out.status[m] = _CODE[r.status.value]
        out.optimal[m] = bool(r.optimal)
        out.certified_by[m] = r.certified_by or ""
        out.delta[m] = -1 if r.delta is None else r.delta
        out.message[m] = r.message or ""
        inliers[m] = True if r.inliers is None else r.inliers
    return dataclasses.replace(out, inliers=inliers)
