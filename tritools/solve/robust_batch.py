"""Batches of robust (TLS) problems: :func:`triangulate_many` and :func:`triangulate_points` with ``robust=``.

1. Every problem first goes through the batched L2 path (:func:`tritools.solve.batch.solve_point_problems`:
   vectorised verification for point regions, one call per number of views).
2. A problem whose L2 result is certified with every residual below its threshold and
   2N gamma_UB^2 <= min_i c_i^2 is certified for TLS by that certificate alone: any inlier set other than all
   views pays at least min_i c_i^2 >= f_TLS(X), so f_TLS* = L2* (:mod:`tritools.solve.robust`, the root bound).
   Its L2 result is returned as it is, with every view an inlier (clean tracks cost the L2 batch only).
3. Every other problem gets the branch and bound of :mod:`tritools.solve.robust`, in chunks of
   :data:`ROBUST_CHUNK` searched together by :func:`tritools.solve.robust.drive` (their sub-bounds batched per
   subset size across problems); a failing item becomes a result with a status (INVALID_INPUT / SOLVER_FAILED),
   never stopping the batch.  ``timings["batch_share"]``: a problem's even share of its chunk's time.
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..model.geometry import validate_cameras
from ..model.regions import as_regions
from ..result import Status, TriangulationResult
from .robust import robust_thresholds, triangulate_robust

__all__ = ["robust_many", "thresholds_for"]

def thresholds_for(robust, problems) -> list:
    """The thresholds of each problem from ``robust=`` (a scalar, one array for problems of equal size, or a
    sequence with one entry per problem); ValueError naming ``robust``."""
    sizes = [_n_views(p) for p in problems]
    per_problem = (isinstance(robust, np.ndarray) and robust.ndim == 2) or (
        isinstance(robust, (list, tuple)) and len(robust) > 0
        and all(isinstance(e, (list, tuple, np.ndarray)) for e in robust))
    if not per_problem:
        return [robust_thresholds(robust, n) if n is not None else None for n in sizes]
    if len(robust) != len(problems):
        raise ValueError(f"robust must be a scalar, one threshold per view, or one entry per problem "
                         f"({len(problems)}), got {len(robust)} entries")
    return [robust_thresholds(c, n) if n is not None else None for c, n in zip(robust, sizes)]


def _n_views(problem) -> int | None:
    """The view count of a (cameras, regions) problem, or None when it has none (a malformed problem: the
    batch gives it status ``invalid_input`` and its threshold is never used)."""
    try:
        _, regions = problem
        n = int(np.shape(regions)[0]) if hasattr(regions, "shape") else len(regions)
    except (TypeError, ValueError, IndexError):
        return None
    return n


def _l2_suffices(res: TriangulationResult, c: np.ndarray) -> bool:
    if not res.optimal or res.residuals is None or res.gamma_ub is None:
        return False
    n = len(res.residuals)
    return bool(np.all(res.residuals < c) and 2 * n * res.gamma_ub ** 2 <= np.min(c * c))


#: problems searched together by :func:`tritools.solve.robust.drive` (their sub-bounds batched per subset size);
#: each keeps its own time budget, counted from the start of its chunk.
ROBUST_CHUNK = 64


def _search_or_failure(cameras, regions, c, opts):
    """A :class:`tritools.solve.robust._Search` for one problem, or a failed result (bad input)."""
    from .robust import _Search

    t0 = time.perf_counter()
    try:
        cams = validate_cameras(cameras)
        return _Search(cams, as_regions(regions, cams.shape[0]), c, opts, t0)
    except (ValueError, TypeError) as exc:
        return TriangulationResult("tls", Status.INVALID_INPUT, message=f"{type(exc).__name__}: {exc}",
                                   timings={"total": time.perf_counter() - t0})


def robust_many(problems: list, robust, opts, *, executor=None, progress=None) -> list[TriangulationResult]:
    """One TLS result per problem, in input order (module docstring)."""
    from .batch import solve_point_problems
    from .robust import drive

    thresholds = thresholds_for(robust, problems)
    first = solve_point_problems(problems, opts, executor=executor, progress=progress).results()
    out: list = [None] * len(problems)
    searches = []
    for i, ((cams, regions), c, res) in enumerate(zip(problems, thresholds, first)):
        if res.status == Status.INVALID_INPUT or _l2_suffices(res, c):
            out[i] = dataclasses.replace(res, inliers=None if res.residuals is None
                                         else np.ones(len(res.residuals), bool))
        elif not np.any(np.isfinite(c)):
            out[i] = triangulate_robust(validate_cameras(cams), as_regions(regions, len(c)), c, opts)
        else:
            s = _search_or_failure(cams, regions, c, opts)
            if isinstance(s, TriangulationResult):
                out[i] = s
            else:
                searches.append((i, s))
    for k in range(0, len(searches), ROBUST_CHUNK):
        part = searches[k:k + ROBUST_CHUNK]
        t0 = time.perf_counter()
        results = drive([s for _, s in part])
        share = (time.perf_counter() - t0) / len(part)
        for (i, _), r in zip(part, results):
            out[i] = dataclasses.replace(r, timings={**r.timings, "batch_share": share})
    return out
