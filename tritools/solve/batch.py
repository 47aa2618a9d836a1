"""Batches of triangulation problems: one result per input, in input order, always.

:func:`triangulate_many` (issue #5):

1. every input is checked for being a ``(cameras, regions)`` pair; Corollary 1 problems
   with point regions at delta = 2 and ``path="auto"`` are grouped by their number of
   views N and certified by verification with one vectorised computation per group
   (:func:`tritools.solve.fastpath.fast_results`: local L2 optimum, KKT multipliers,
   Lagrangian bound -- the degree-2 certificate without an SDP);
2. the rest -- the fast path's failures (sent with ``path="sdp"``; their ``attempts``
   start with ``(2, "verification_failed", None, None)`` exactly as
   :func:`~tritools.triangulate` records it) and every problem the fast path does not
   apply to -- are solved one by one with :func:`safe_triangulate` plus ``retries``, in
   chunks of ``chunk_size`` submitted to an executor;
3. results are put back in input order.

A failing item (bad input, solver error, anything raised, a crashed worker) becomes a
:class:`~tritools.result.TriangulationResult` with a status and a message
(``INVALID_INPUT`` for bad input, ``SOLVER_FAILED`` otherwise); it never stops or
shrinks the batch.  ``certified_by`` says which path certified each result
(``"verification"``, ``"sdp"`` or ``None``).

Executors: any :class:`concurrent.futures.Executor` (``submit``), or a
``dask.distributed.Client`` (its ``get_executor()`` is used).  With ``executor=None``
the per-item work runs in a local :class:`~concurrent.futures.ProcessPoolExecutor`
with the *spawn* start method (fork deadlocks Clarabel's thread pool) when there are
at least ``LOCAL_PROCESS_MIN_ITEMS`` items for it and more than one CPU -- starting
spawned workers costs about a second each, which ~100 SDP solves pay for -- else in
this process.  Scripts using the local pool need the usual
``if __name__ == "__main__":`` guard of the spawn start method; if the pool breaks,
the remaining chunks run in this process.
"""
from __future__ import annotations

import concurrent.futures as cf
import dataclasses
import os
import time
from typing import Iterable, Sequence

import numpy as np

from sospoly import DEFAULT_TOLERANCES

from ..model.constraints import Method
from .fastpath import fast_results
from ..model.regions import Point
from ..result import Status, TriangulationResult
from .sdp_batch import sdp_results
from .triangulate import SolvePath, triangulate

__all__ = ["triangulate_many", "safe_triangulate", "RetryStep", "LOCAL_PROCESS_MIN_ITEMS", "FAST_CHUNK",
           "DEFAULT_CHUNK_SIZE"]

#: a retry step: (method, delta) tried when the previous steps did not certify.
RetryStep = tuple
#: with executor=None, a local process pool is used from this many per-item (SDP) problems on.
LOCAL_PROCESS_MIN_ITEMS = 200
#: the vectorised fast path handles at most this many problems per numpy call (bounds memory).
FAST_CHUNK = 4096
#: per-item problems per executor task.
DEFAULT_CHUNK_SIZE = 8
_VERIFICATION_FAILED = (2, "verification_failed", None, None)


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


def _failed(method, status: Status, message: str) -> TriangulationResult:
    return TriangulationResult(method=str(getattr(method, "value", method)), status=status, message=message)


def _solve_item(cams, regions, method, delta, max_delta, path, prefix, retries, kw) -> TriangulationResult:
    """One problem through :func:`safe_triangulate`, then the ``retries`` steps while not certified."""
    res = safe_triangulate(cams, regions, method, delta, max_delta, path=path, **kw)
    if res.status == Status.INVALID_INPUT:
        prefix = ()          # the fast path did not fail: it could not read the data
    tried = list(prefix) + (list(res.attempts) or [(res.delta, res.status.value, res.gamma_lb, res.gamma_ub)])
    if res.status != Status.OPTIMAL:
        for m, d in retries:
            r2 = safe_triangulate(cams, regions, m, d, d, path=path, **kw)
            tried.append((f"{getattr(m, 'value', m)}:{r2.delta}", r2.status.value, r2.gamma_lb, r2.gamma_ub))
            if r2.status == Status.OPTIMAL:
                res = r2
                break
    return dataclasses.replace(res, attempts=tuple(tried))


def _run_chunk(items, method, delta, max_delta, retries, kw) -> list:
    """Executor task: [(index, result)] for items [(index, cameras, regions, path, prefix)]."""
    return [(i, _solve_item(c, r, method, delta, max_delta, p, pre, retries, kw)) for i, c, r, p, pre in items]


def _progress_bar(total: int, enabled: bool):
    if not enabled:
        return None
    try:
        from tqdm import tqdm
    except ImportError:  # optional extra 'progress': silently no bar
        return None
    return tqdm(total=total, desc="triangulating", leave=False)


def _fast_eligible(method, delta, path, kw) -> bool:
    try:
        m = Method(method)
    except ValueError:
        return False
    return path == SolvePath.AUTO and m == Method.COROLLARY1 and delta in (None, 2) and kw.get("normalize", True)


#: options of triangulate under which the batched delta = 2 SDP (tritools.solve.sdp_batch) gives its answer:
#: these values (ANY: every value is handled by the batch; backend must be left to the default).
_ANY = object()
_SDP_BATCH_DEFAULTS = {"refine": _ANY, "tolerances": _ANY, "normalize": True, "multiplier": "fixed", "form": "image",
                       "backend": None}


def _sdp_batch_eligible(method, delta, path, kw) -> bool:
    try:
        m = Method(method)
    except ValueError:
        return False
    if path != SolvePath.SDP or m != Method.COROLLARY1 or delta not in (None, 2):
        return False
    for k, v in kw.items():
        if k not in _SDP_BATCH_DEFAULTS:
            return False
        want = _SDP_BATCH_DEFAULTS[k]
        if want is _ANY:
            continue
        if want is None or isinstance(want, bool):
            if v is not want:
                return False
        elif not isinstance(v, str) or str(getattr(v, "value", v)) != want:
            return False
    return True


def _as_point_problem(cams, regions):
    """(cameras (N, 3, 4), centres (N, 2)) when the item is a well-shaped point-region problem, else None."""
    if not isinstance(regions, (list, tuple)) or not all(isinstance(r, Point) for r in regions):
        return None
    try:
        C = np.asarray(cams, dtype=float)
    except (TypeError, ValueError):
        return None
    if C.ndim != 3 or C.shape[1:] != (3, 4) or C.shape[0] != len(regions) or len(regions) < 2:
        return None
    return C, np.array([r.x for r in regions])


def _local_executor(n_items: int, n_chunks: int):
    cpus = os.cpu_count() or 1
    if n_items < LOCAL_PROCESS_MIN_ITEMS or cpus < 2:
        return None
    import multiprocessing

    return cf.ProcessPoolExecutor(max_workers=min(cpus, n_chunks), mp_context=multiprocessing.get_context("spawn"),
                                  initializer=_worker_init)


def _worker_init() -> None:
    os.environ["RUST_BACKTRACE"] = "0"   # Clarabel panics are caught and reported; no backtrace noise


def triangulate_many(problems: Iterable[Sequence], method="corollary1", delta=None, max_delta=None, *,
                     path: SolvePath | str = SolvePath.AUTO, executor=None, progress: bool = True,
                     retries: Sequence[RetryStep] = (), chunk_size: int = DEFAULT_CHUNK_SIZE,
                     **kw) -> list[TriangulationResult]:
    """Triangulate every (cameras, regions) pair; results in input order, one per input.

    Parameters
    ----------
    problems : iterable of (cameras (N, 3, 4), regions) pairs
    method, delta, max_delta, kw : as for :func:`tritools.triangulate`
    path : "auto" (certification by verification first, vectorised over problems with the
        same structure; SDP fallback) or "sdp" (always the SDP)
    executor : None, a :class:`concurrent.futures.Executor`, or a ``dask.distributed.Client``
        (see the module docstring for the default)
    progress : a tqdm bar (optional extra ``progress``; silently none without tqdm)
    retries : (method, delta) steps tried in order on items the first call did not certify
        (e.g. ``[("corollary1", 4), ("theorem1", None)]``); the first certified result is
        kept, else the first call's.  Each result's ``attempts`` lists them all.
    chunk_size : per-item problems per executor task
    """
    try:
        path = SolvePath(path)
    except ValueError:
        raise ValueError(f"path must be 'sdp' or 'auto', got {path!r}") from None
    if int(chunk_size) != chunk_size or chunk_size < 1:
        raise ValueError(f"chunk_size must be a positive integer, got {chunk_size!r}")
    problems = list(problems)
    results: list[TriangulationResult | None] = [None] * len(problems)
    bar = _progress_bar(len(problems), progress)
    fast = _fast_eligible(method, delta, path, kw)
    sdp_batch = _sdp_batch_eligible(method, delta, path, kw)
    groups: dict[int, list] = {}
    items = []                                          # (index, cameras, regions, path, prefix)
    for i, prob in enumerate(problems):
        try:
            cams, regions = prob
        except (TypeError, ValueError):
            results[i] = _failed(method, Status.INVALID_INPUT,
                                 f"problems[{i}] must be a (cameras, regions) pair, got {type(prob).__name__}")
            continue
        pp = _as_point_problem(cams, regions) if fast or sdp_batch else None
        if pp is None:
            items.append((i, cams, regions, path.value, ()))
        else:
            groups.setdefault(len(regions), []).append((i, *pp, cams, regions))
    n_done = len(problems) - len(items) - sum(map(len, groups.values()))
    if bar is not None:
        bar.update(n_done)

    tol = kw.get("tolerances", DEFAULT_TOLERANCES)
    # delta = 2 is the last degree when given as such (triangulate's rule) and no retries follow
    final = not retries and (max_delta == 2 or (delta == 2 and max_delta is None))
    for group in groups.values():
        for start in range(0, len(group), FAST_CHUNK):
            part = group[start:start + FAST_CHUNK]
            C, x = np.array([g[1] for g in part]), np.array([g[2] for g in part])
            try:
                if sdp_batch:   # the delta = 2 SDP for the whole group; what it hands back goes per point
                    prefix = ()
                    fres = sdp_results(C, x, tolerances=tol, refine=kw.get("refine", True), final=final,
                                       method=Method.COROLLARY1.value)
                else:
                    prefix = (_VERIFICATION_FAILED,)
                    fres = fast_results(C, x, tolerances=tol, method=Method.COROLLARY1.value)
            except Exception:  # noqa: BLE001 - e.g. LinAlgError on extreme data: every item goes per point
                fres = [None] * len(part)
            for (i, _, _, cams, regions), r in zip(part, fres):
                if r is None:
                    items.append((i, cams, regions, SolvePath.SDP.value, prefix))
                else:
                    results[i] = r
            if bar is not None:
                bar.update(sum(r is not None for r in fres))

    items.sort(key=lambda it: it[0])
    chunks = [items[k:k + chunk_size] for k in range(0, len(items), chunk_size)]
    args = (method, delta, max_delta, tuple(retries), kw)

    def store(pairs):
        for i, r in pairs:
            results[i] = r
        if bar is not None:
            bar.update(len(pairs))

    own = None
    ex = executor
    if ex is not None and hasattr(ex, "get_executor"):       # dask.distributed.Client
        ex = ex.get_executor()
    elif ex is None and chunks:
        ex = own = _local_executor(len(items), len(chunks))
    try:
        pending = list(range(len(chunks)))
        if ex is not None:
            futures = {ex.submit(_run_chunk, chunks[k], *args): k for k in pending}
            for fut in cf.as_completed(futures):
                k = futures[fut]
                try:
                    store(fut.result())
                    pending.remove(k)
                except cf.BrokenExecutor:
                    if own is None:
                        raise
                    break                                        # our own pool broke: finish in-process
                except Exception as exc:  # noqa: BLE001 - a failed task fails its items, not the batch
                    store([(it[0], _failed(method, Status.SOLVER_FAILED, f"executor task failed: "
                                                                         f"{type(exc).__name__}: {exc}"))
                           for it in chunks[k]])
                    pending.remove(k)
        for k in list(pending) if ex is None or own is not None else []:
            if all(results[it[0]] is None for it in chunks[k]):
                store(_run_chunk(chunks[k], *args))
    except cf.BrokenExecutor as exc:
        for k in pending:
            store([(it[0], _failed(method, Status.SOLVER_FAILED, f"executor broke: {exc}")) for it in chunks[k]
                   if results[it[0]] is None])
    finally:
        if own is not None:
            own.shutdown(wait=True, cancel_futures=True)
        if bar is not None:
            bar.close()
    return results
