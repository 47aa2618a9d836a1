"""The one place where the model path calls the solver: :func:`certify_stack`.

``certify_stack(cameras (M, N, 3, 4), points2d (M, N, 2), options)`` certifies M point-region
problems with N views each and returns arrays (:class:`StackResult`).  Today it

1. runs the vectorised certification by verification of :mod:`tritools.solve.fastpath`
   (:func:`~tritools.solve.fastpath.verify_points`, the array form of ``fast_results``: Corollary 1
   at delta = 2, local L2 optimum, KKT multipliers, Lagrangian bound -- no SDP) over the whole
   stack, in sub-stacks sized to a memory budget (its arrays grow as N^4);
2. sends only the problems it did not certify to :func:`tritools.solve.batch.triangulate_many`
   (``tritools.Point`` regions, the SDP at the degrees of ``options``).

Everything else of the model path (undistortion, grouping, cheirality, writing) is numpy code
outside this module, so a new solver API only has to replace this function's body.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..io.export import STATUS_LEGEND
from ..result import Status

__all__ = ["CertifyOptions", "StackResult", "certify_stack", "STATUS_LEGEND", "status_code", "FAST_MEMORY_BUDGET",
           "FAST_MAX_STACK", "resolved_degrees"]

_CODE = {s: k for k, s in enumerate(STATUS_LEGEND)}
#: bytes the fast path may use per numpy call (its Hessian stack is M * K * (2N)^2 doubles, K = N(N-1)/2).
FAST_MEMORY_BUDGET = 256 << 20
#: ... and at most this many problems per call.
FAST_MAX_STACK = 8192


def status_code(status) -> int:
    """Code of a :class:`tritools.Status` (or its value) in :data:`STATUS_LEGEND`."""
    return _CODE[Status(status).value]


@dataclass(frozen=True)
class CertifyOptions:
    """Solver settings of :func:`certify_stack`.

    ``delta``/``max_delta``: first and last relaxation degree (None: the method's delta_min,
    and no escalation beyond the first degree); ``path``: "auto" (verification first) or
    "sdp"; ``executor``: for the per-problem SDPs (see :func:`tritools.solve.batch.triangulate_many`).
    """
    method: str = "corollary1"
    path: str = "auto"
    delta: int | None = 2
    max_delta: int | None = 2
    executor: object = field(default=None, compare=False)
    memory_budget: int = FAST_MEMORY_BUDGET


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


def resolved_degrees(options: CertifyOptions, n_views: int) -> tuple[int | None, int]:
    """(first, last) relaxation degree for problems with ``n_views`` views: the last degree defaults
    to the first, and the first to the method's delta_min (Corollary 1: 2; Theorem 1 with point
    regions: 2 for two views, 4 from three views on, the degree of the 4x4 minors rounded up)."""
    delta_min = 2 if options.method == "corollary1" or n_views == 2 else 4
    first = options.delta
    last = options.max_delta if options.max_delta is not None else (first if first is not None else delta_min)
    return first, last


def _fast_chunk(n_views: int, budget: int) -> int:
    K, n = n_views * (n_views - 1) // 2, 2 * n_views
    per_problem = 8 * (3 * K * n * n + 6 * K * n + 40 * n_views * 4)
    return int(max(1, min(FAST_MAX_STACK, budget // per_problem)))


def _gamma_ub(C: np.ndarray, x: np.ndarray, X: np.ndarray) -> np.ndarray:
    """gamma(X) (SPEC §1) of each problem, NaN where a projection is at infinity."""
    h = np.einsum("mnij,mj->mni", C, np.concatenate([X, np.ones((len(X), 1))], axis=1))
    with np.errstate(all="ignore"):
        g = np.sqrt(np.sum((h[..., :2] / h[..., 2:3] - x) ** 2, axis=(1, 2)) / (2 * x.shape[1]))
    return np.where(np.isfinite(g), g, np.nan)


def certify_stack(cameras, points2d, options: CertifyOptions = CertifyOptions()) -> StackResult:
    """Certify M problems of N views with point regions (see the module docstring)."""
    from ..model.regions import Point
    from ..solve.batch import triangulate_many
    from ..solve.fastpath import verify_points

    C = np.asarray(cameras, float)
    x = np.asarray(points2d, float)
    M, N = x.shape[:2]
    out = StackResult(np.full((M, 3), np.nan), np.full(M, np.nan), np.full(M, np.nan),
                      np.full(M, _CODE[Status.SOLVER_FAILED.value], np.int8), np.zeros(M, bool),
                      np.full(M, "", object), np.full(M, -1, np.int16), np.full(M, "", object))
    if M == 0:
        return out
    first, last = resolved_degrees(options, N)
    todo = np.ones(M, bool)
    fast = options.path == "auto" and options.method == "corollary1" and first in (None, 2)
    if fast:
        step = _fast_chunk(N, options.memory_budget)
        for a in range(0, M, step):
            b = min(a + step, M)
            try:
                batch = verify_points(C[a:b], x[a:b])
            except Exception:  # noqa: BLE001 - e.g. LinAlgError on extreme data: those go to the SDP
                continue
            ub = _gamma_ub(C[a:b], x[a:b], batch.X)
            ok = np.asarray(batch.certified, bool) & np.isfinite(ub) & np.all(np.isfinite(batch.X), axis=1)
            rows = a + np.nonzero(ok)[0]
            out.X[rows] = batch.X[ok]
            out.gamma_lb[rows] = batch.gamma_lb[ok]
            out.gamma_ub[rows] = ub[ok]
            out.status[rows] = _CODE[Status.OPTIMAL.value]
            out.optimal[rows] = True
            out.certified_by[rows] = "verification"
            out.delta[rows] = 2
            todo[rows] = False
    rest = np.nonzero(todo)[0]
    if rest.size:
        problems = [(C[m], [Point(p) for p in x[m]]) for m in rest]
        results = triangulate_many(problems, options.method, first, last, path="sdp" if fast else options.path,
                                   executor=options.executor, progress=False)
        for m, r in zip(rest, results):
            _store(out, m, r)
    return out


def _store(out: StackResult, m: int, r) -> None:
    """Copy one :class:`tritools.TriangulationResult` into row m."""
    if r.X is not None:
        out.X[m] = r.X
    out.gamma_lb[m] = np.nan if r.gamma_lb is None else r.gamma_lb
    out.gamma_ub[m] = np.nan if r.gamma_ub is None else r.gamma_ub
    out.status[m] = _CODE[Status(r.status).value]
    out.optimal[m] = bool(r.optimal)
    out.certified_by[m] = r.certified_by or ""
    out.delta[m] = -1 if r.delta is None else r.delta
    out.message[m] = r.message or ""
