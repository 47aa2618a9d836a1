"""Batches of triangulation problems: one result per input, in input order, always.

A failing item (bad input, solver error, anything raised) becomes a
:class:`~tritools.result.TriangulationResult` with a status and a message; it never
stops or shrinks the batch.
"""
from __future__ import annotations

import dataclasses
import time
from typing import Iterable, Sequence

from .result import Status, TriangulationResult
from .triangulate import triangulate

__all__ = ["triangulate_many", "safe_triangulate", "RetryStep"]

#: a retry step: (method, delta) tried when the previous steps did not certify.
RetryStep = tuple


def safe_triangulate(cameras, regions, method="corollary1", delta=None, max_delta=None, **kw) -> TriangulationResult:
    """:func:`triangulate` that returns a failed result instead of raising."""
    t0 = time.perf_counter()
    try:
        return triangulate(cameras, regions, method, delta, max_delta, **kw)
    except (ValueError, TypeError) as exc:
        status, msg = Status.INVALID_INPUT, f"{type(exc).__name__}: {exc}"
    except Exception as exc:  # noqa: BLE001 - a batch records every failure
        status, msg = Status.SOLVER_FAILED, f"{type(exc).__name__}: {exc}"
    return TriangulationResult(method=str(getattr(method, "value", method)), status=status, message=msg,
                               timings={"total": time.perf_counter() - t0})


def _progress(iterable, total, enabled, desc):
    if not enabled:
        return iterable
    try:
        from tqdm import tqdm
    except ImportError:  # optional extra
        return iterable
    return tqdm(iterable, total=total, desc=desc, leave=False)


def triangulate_many(problems: Iterable[Sequence], method="corollary1", delta=None, max_delta=None, *,
                     retries: Sequence[RetryStep] = (), progress: bool = False, **kw) -> list[TriangulationResult]:
    """Triangulate every (cameras, regions) pair; results in input order, one per input.

    ``retries``: (method, delta) steps tried in order on items the first call did not
    certify (e.g. ``[("corollary1", 4), ("theorem1", None)]``); the first certified
    result is kept, else the first call's.  Each result's ``attempts`` lists them all.
    """
    problems = list(problems)
    out = []
    for cams, regions in _progress(problems, len(problems), progress, "triangulating"):
        res = safe_triangulate(cams, regions, method, delta, max_delta, **kw)
        tried = list(res.attempts) or [(res.delta, res.status.value, res.gamma_lb, res.gamma_ub)]
        if res.status != Status.OPTIMAL:
            for m, d in retries:
                r2 = safe_triangulate(cams, regions, m, d, d, **kw)
                tried.append((f"{getattr(m, 'value', m)}:{r2.delta}", r2.status.value, r2.gamma_lb, r2.gamma_ub))
                if r2.status == Status.OPTIMAL:
                    res = r2
                    break
        out.append(dataclasses.replace(res, attempts=tuple(tried)))
    return out
