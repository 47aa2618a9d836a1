"""Batches of robust (TLS) problems: :func:`triangulate_many` and :func:`triangulate_points` with ``robust=``.

1. Every problem first goes through the batched L2 path (:func:`tritools.solve.batch.solve_point_problems`:
   vectorised verification for point regions, one call per number of views).
2. A problem whose L2 result is certified with every residual below its threshold and
   2N gamma_UB^2 <= min_i c_i^2 is certified for TLS by that certificate alone: any inlier set other than all
   views pays at least min_i c_i^2 >= f_TLS(X), so f_TLS* = L2* (:mod:`tritools.solve.robust`, the root bound).
   Its L2 result is returned as it is, with every view an inlier (clean tracks cost the L2 batch only).
3. Every other problem is solved by :func:`tritools.solve.robust.triangulate_robust` (branch and bound), one by
   one in this process; a failing item becomes a result with a status (INVALID_INPUT / SOLVER_FAILED), never
   stopping the batch.
"""
from __future__ import annotations

import dataclasses
import logging
import time

import numpy as np

from ..model.geometry import validate_cameras
from ..model.regions import as_regions
from ..result import Status, TriangulationResult
from .robust import robust_thresholds, triangulate_robust

__all__ = ["robust_many", "thresholds_for"]

log = logging.getLogger(__name__)


def thresholds_for(robust, problems) -> list:
    """The thresholds of each problem from ``robust=`` (a scalar, one array for problems of equal size, or a
    sequence with one entry per problem); ValueError naming ``robust``."""
    sizes = [len(p[1]) if not hasattr(p[1], "shape") else int(np.shape(p[1])[0]) for p in problems]
    per_problem = (isinstance(robust, np.ndarray) and robust.ndim == 2) or (
        isinstance(robust, (list, tuple)) and len(robust) > 0
        and all(isinstance(e, (list, tuple, np.ndarray)) for e in robust))
    if not per_problem:
        return [robust_thresholds(robust, n) for n in sizes]
    if len(robust) != len(problems):
        raise ValueError(f"robust must be a scalar, one threshold per view, or one entry per problem "
                         f"({len(problems)}), got {len(robust)} entries")
    return [robust_thresholds(c, n) for c, n in zip(robust, sizes)]


def _l2_suffices(res: TriangulationResult, c: np.ndarray) -> bool:
    if not res.optimal or res.residuals is None or res.gamma_ub is None:
        return False
    n = len(res.residuals)
    return bool(np.all(res.residuals < c) and 2 * n * res.gamma_ub ** 2 <= np.min(c * c))


def _safe_robust(cameras, regions, c, opts) -> TriangulationResult:
    t0 = time.perf_counter()
    try:
        cams = validate_cameras(cameras)
        return triangulate_robust(cams, as_regions(regions, cams.shape[0]), c, opts, t0)
    except (ValueError, TypeError) as exc:
        status, msg = Status.INVALID_INPUT, f"{type(exc).__name__}: {exc}"
    except Exception as exc:  # noqa: BLE001 - a batch records every failure
        log.debug("robust triangulation failed", exc_info=True)
        status, msg = Status.SOLVER_FAILED, f"{type(exc).__name__}: {exc}"
    return TriangulationResult("tls", status, message=msg, timings={"total": time.perf_counter() - t0})


def robust_many(problems: list, robust, opts, *, executor=None, progress=None) -> list[TriangulationResult]:
    """One TLS result per problem, in input order (module docstring)."""
    from .batch import solve_point_problems

    thresholds = thresholds_for(robust, problems)
    first = solve_point_problems(problems, opts, executor=executor, progress=progress).results()
    out = []
    for (cams, regions), c, res in zip(problems, thresholds, first):
        if _l2_suffices(res, c) or (res.status == Status.INVALID_INPUT):
            out.append(dataclasses.replace(res, inliers=None if res.residuals is None
                                           else np.ones(len(res.residuals), bool)))
        else:
            out.append(_safe_robust(cams, regions, c, opts))
    return out
