"""A better estimate where no certificate was found: Levenberg-Marquardt from the DLT points of a few view pairs.

An uncertified point keeps the best estimate the plan found, usually the local L2 refinement of the DLT point of all
views.  With wrong matches in a long track that start can lie in a poor basin of the L2 cost: review 29a F2 saw
gamma_UB = 1754 px (100 views, 20% wrong matches, ``budget_exceeded``) and 134.6 px (300 views) where a multi-start
least-squares reaches 74.0 / 79.7 px.  :func:`multistart_point` refines the DLT points of :data:`MULTISTART_PAIRS`
view pairs (a fixed sample, the same for every call of N views) over all views in one vectorised call, and the
settle stage (:func:`tritools.solve.stages.outcome.settle_stage`, ``method="auto"``) keeps the lowest cost when it
beats the estimate -- a lower upper bound; the lower bound and the status are unchanged.  Point regions only; not
started past the deadline (it costs 5-56 ms at 12-300 views; its iterations are not interrupted).
"""
from __future__ import annotations

import numpy as np

from ..model.stacked import dlt_stack, project_quiet, refine_points_stack

__all__ = ["multistart_point", "pair_sample", "MULTISTART_PAIRS"]

#: view pairs whose DLT points start a refinement (8 reached the multi-start reference in each of review 29a F2's
#: three tracks, 5-56 ms at 12-300 views on the loaded 2-core machine)
MULTISTART_PAIRS = 8


def pair_sample(n_views: int, k: int = MULTISTART_PAIRS) -> np.ndarray:
    """(K, 2) distinct view pairs i < j, K = min(k, N (N - 1) / 2): every pair when that is at most k, else a fixed
    pseudo-random sample without repeats (seeded by N: the same pairs for every call of N views)."""
    i, j = np.triu_indices(n_views, 1)
    if i.size > k:
        pick = np.sort(np.random.default_rng(n_views).choice(i.size, k, replace=False))
        i, j = i[pick], j[pick]
    return np.stack([i, j], axis=1)


def multistart_point(C: np.ndarray, x: np.ndarray, k: int = MULTISTART_PAIRS) -> tuple | None:
    """(X (3,), f) with the lowest sum of squared reprojection errors f over the Levenberg-Marquardt refinements
    (all views) of the DLT points of :func:`pair_sample`'s pairs, for cameras C (N, 3, 4) and observed points x
    (N, 2); None with fewer than three views or no finite refinement."""
    N = len(C)
    if N < 3:
        return None
    pairs = pair_sample(N, k)
    K = len(pairs)
    CC, xx = np.broadcast_to(C, (K,) + C.shape), np.broadcast_to(x, (K,) + x.shape)
    try:
        X0, ok = dlt_stack(C[pairs], x[pairs])
        X, ok = refine_points_stack(CC, xx, X0, ok, scalar=False)
        with np.errstate(over="ignore", invalid="ignore"):
            u, _, fin = project_quiet(CC, X)
            f = np.where(ok & fin, np.add.reduce((u - xx) ** 2, axis=(1, 2)), np.inf)
    except (np.linalg.LinAlgError, ValueError, FloatingPointError):      # extreme data: no better estimate
        return None
    m = int(np.argmin(f))
    return (X[m], float(f[m])) if np.isfinite(f[m]) else None
