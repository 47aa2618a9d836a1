"""Batches of triangulation problems: one result per input, in input order, always.

:func:`triangulate_many` (and :func:`tritools.triangulate_points`):

1. every input is read as a ``(cameras, regions)`` pair; point-region problems (regions that are
   :class:`~tritools.model.regions.Point` objects or an (N, 2) array) are grouped by their number of
   views and go through the batch stages of :class:`tritools.solve.points.PointStack`
   (:data:`tritools.solve.stages.BATCH_STAGES`: the vectorised verification and delta = 2 SDP);
2. everything else -- other regions, problems a vectorised path handed back, later degrees of the
   plan -- is solved one by one by :func:`tritools.triangulate` (plus the ``retries`` steps), in
   chunks of ``chunk_size`` submitted to an executor;
3. results are put back in input order.

A failing item (bad input, solver error, anything raised, a crashed worker) becomes a result with a
status and a message (``INVALID_INPUT`` for bad input, ``ILL_POSED`` for valid data that define no problem -- every
camera the same, :class:`tritools.result.IllPosedError` --, ``SOLVER_FAILED`` otherwise); it never stops or
shrinks the batch.  Each result's ``attempts`` lists every step, batched ones included.

Executors: any :class:`concurrent.futures.Executor` (``submit``), or a ``dask.distributed.Client``
(its ``get_executor()`` is used).  With ``executor=None`` the per-item work runs in a local
:class:`~concurrent.futures.ProcessPoolExecutor` with the *spawn* start method (fork deadlocks
Clarabel's thread pool) when there are at least ``LOCAL_PROCESS_MIN_ITEMS`` items and more than one
CPU, else in this process.  Scripts using the local pool need the usual ``if __name__ ==
"__main__":`` guard of the spawn start method.  When a pool breaks (a worker killed), the chunks it
did not finish are retried in this process before anything is reported as failed.
"""
from __future__ import annotations

import concurrent.futures as cf
import dataclasses
import logging
import os
import sys
import time
from collections.abc import Iterable, Sequence

import numpy as np

from ..model.cameras import numeric_cameras
from ..model.regions import Region, declares_extent
from ..model.constraints import Method
from ..records import TriangulationResults
from ..result import Attempt, Status, TriangulationResult, input_failure, refused
from .call_limit import (call_limit, expired, expired_points, expired_regions, mark_cut, reserve_for, reserved_end,
                         reserving, within)
from .options import TriangulationOptions, options_from
from .discs import as_disc_problem, solve_disc_group
from .plan import batch_steps
from .points import PointStack
from .stages import BATCH_STAGES
from .triangulate import triangulate

__all__ = ["triangulate_many", "safe_triangulate", "solve_point_problems", "solve_point_stack", "BatchOutcome",
           "RetryStep", "LOCAL_PROCESS_MIN_ITEMS", "per_point_runner",
           "DEFAULT_CHUNK_SIZE", "PROGRESS_MIN_ITEMS"]

log = logging.getLogger(__name__)

#: a retry step: (method, delta) tried when the previous steps did not certify.
RetryStep = tuple
#: with executor=None, a local process pool is used from this many per-item (SDP) problems on.
LOCAL_PROCESS_MIN_ITEMS = 200
#: per-item problems per executor task.
DEFAULT_CHUNK_SIZE = 8
#: with progress="auto" a bar is shown from this many problems on (only on a terminal, and when tqdm is installed).
PROGRESS_MIN_ITEMS = 1000


def safe_triangulate(cameras, regions, options: TriangulationOptions) -> TriangulationResult:
    """:func:`triangulate` that returns a failed result instead of raising."""
    t0 = time.perf_counter()
    try:
        return triangulate(cameras, regions, options=options)
    except (ValueError, TypeError) as exc:
        status, msg = input_failure(exc)
    except Exception as exc:  # noqa: BLE001 - a batch records every failure
        log.debug("triangulate failed", exc_info=True)
        status, msg = Status.SOLVER_FAILED, f"{type(exc).__name__}: {exc}"
    return TriangulationResult(method=options.method.value, status=status, message=msg,
                               timings={"total": time.perf_counter() - t0},
                               attempts=(Attempt(options.method.value, options.delta, status.value, step="call"),))


def _failed(opts: TriangulationOptions, status: Status, message: str) -> TriangulationResult:
    return TriangulationResult(method=opts.method.value, status=status, message=message)


def _solve_item(cams, regions, opts: TriangulationOptions, prefix: tuple, retries, end=None) -> TriangulationResult:
    """One problem through :func:`safe_triangulate`, then the ``retries`` steps while not certified; ``end``: the
    whole call's end (:mod:`.call_limit`), which cuts the per-point time limit."""
    run, cut = within(opts, end)
    res = safe_triangulate(cams, regions, run)
    tried = list(prefix) + list(res.attempts)
    if refused(res):
        tried = list(res.attempts)          # the batch did not fail on it: it could not read (or pose) the data
    if not res.status.certified:
        for m, d in retries:
            if expired(end):
                break
            run, cut_retry = within(opts.replace(method=m, delta=d, max_delta=d), end)
            cut = cut or cut_retry
            r2 = safe_triangulate(cams, regions, run)
            tried.append(Attempt(r2.method, r2.delta, r2.status.value, r2.gamma_lb, r2.gamma_ub, "retry", r2.sparsity))
            if r2.status.certified:
                res = r2
                break
    res = dataclasses.replace(res, attempts=tuple(tried))
    return mark_cut(res) if cut else res


def _run_chunk(items, retries, end=None, after: float = 0.0) -> list:
    """Executor task: [(index, result)] for items [(index, cameras, regions, options, prefix)]; the items whose
    turn comes after the whole call's ``end`` get their ``time_limit`` results at once (:func:`_expired_items`).
    Each item ends early enough for the rows of the items after it and ``after`` seconds more (the reserve of the
    chunks queued after this one, :func:`_after_seconds`)."""
    out = []
    later = reserve_for(_item_views(items)) + after
    for k, (i, c, r, o, pre) in enumerate(items):
        later -= reserve_for(_item_views(items[k:k + 1]))
        end_k = reserved_end(end, later)              # the rows of the items after it fit before the end
        if expired(end_k):
            return out + _expired_items(items[k:], retries, end)
        out.append((i, _solve_item(c, r, o, pre, retries, end_k)))
    return out


def _after_seconds(chunks, workers) -> list:
    """Per chunk, the reserve (:func:`~tritools.solve.call_limit.reserve_for`) of the rows of the chunks after it,
    shared by ``workers`` processes: the last item of a chunk must not run up to the end while later chunks wait."""
    secs = [reserve_for(_item_views(c)) for c in chunks]
    tail = np.cumsum(secs[::-1])[::-1].tolist() + [0.0]
    w = max(1, int(workers or 1))
    return [tail[k + 1] / w for k in range(len(chunks))]


def _item_views(items) -> list:
    """The view counts of per-item problems (index, cameras, regions, options, prefix) for
    :func:`~tritools.solve.call_limit.reserve_for` (2 where the regions have no length)."""
    return [len(it[2]) if hasattr(it[2], "__len__") else 2 for it in items]


def _expired_items(items, retries, end) -> list:
    """``time_limit`` results of items not started before ``end``: point problems of equal size through
    :func:`tritools.solve.call_limit.expired_points` (vectorised), the others one by one
    (:func:`~tritools.solve.call_limit.expired_regions`: the DLT point of their region centres)."""
    out, points = [], {}
    for i, c, r, o, pre in items:
        pp = as_point_problem(c, r)
        if pp is None:
            res = expired_regions(c, r, o)          # None: the input does not validate (the per-point path names it)
            out.append((i, res if res is not None else _solve_item(c, r, o, pre, retries, end)))
        else:
            points.setdefault((len(pp[1]), o), []).append((i, *pp))
    for (_, o), group in points.items():
        res = expired_points(np.array([g[1] for g in group]), np.array([g[2] for g in group]), o)
        out.extend(zip([g[0] for g in group], res))
    return out


def _progress_bar(total: int, progress):
    """A tqdm bar, or None: ``progress`` None / False (a library call shows no bar unless asked), ``"auto"``
    with fewer than PROGRESS_MIN_ITEMS problems or a standard error that is not a terminal (a redirected stream
    gets no bar: review 33a L10), or tqdm missing (a warning when ``progress`` is True)."""
    if progress is None or progress is False or (progress == "auto" and (total < PROGRESS_MIN_ITEMS
                                                                          or not stderr_is_terminal())):
        return None
    try:
        from tqdm import tqdm
    except ImportError:  # optional extra 'progress'
        if progress is True:
            log.warning("progress=True needs tqdm (pip install 'sospoly-tritools[progress]'): no progress bar")
        return None
    return tqdm(total=total, desc="triangulating", leave=False)


def stderr_is_terminal() -> bool:
    """Is standard error a terminal?  The condition of every ``"auto"`` progress bar."""
    try:
        return bool(sys.stderr is not None and sys.stderr.isatty())
    except (AttributeError, ValueError):            # a closed or replaced stream
        return False


def _local_executor(n_items: int, n_chunks: int):
    cpus = os.cpu_count() or 1
    if n_items < LOCAL_PROCESS_MIN_ITEMS or cpus < 2:
        return None
    import multiprocessing

    return cf.ProcessPoolExecutor(max_workers=min(cpus, n_chunks), mp_context=multiprocessing.get_context("spawn"),
                                  initializer=worker_init, initargs=(os.getpid(),))


def worker_init(parent: int | None = None) -> None:
    """The set-up of a local worker process: no Rust backtraces (Clarabel panics are caught and reported), and a
    watch that ends the worker once the process that created its pool, ``parent`` (its pid, passed by the pool: a
    worker still starting when that process died is already re-parented), is gone (:func:`_watch_parent`)."""
    os.environ["RUST_BACKTRACE"] = "0"
    if os.name == "posix":             # (Windows: a parent's death is not seen through its pid; no watch)
        _watch_parent(os.getppid() if parent is None else parent)


#: seconds between a local worker's checks that the process that started it still runs
PARENT_POLL_SECONDS = 1.0


def _watch_parent(parent: int) -> None:
    """A daemon thread that exits this worker within :data:`PARENT_POLL_SECONDS` of the end of ``parent``, the
    process that created its pool: one killed without clean-up (SIGKILL from a timeout wrapper, a job scheduler or
    the OOM killer) left its workers solving, orphaned, for minutes (review 33a M3).  Gone means: this worker was
    re-parented (its parent id changed), or ``parent`` no longer exists -- a worker of a ``forkserver`` pool is the
    server's child, and one still starting when ``parent`` died was re-parented before it could look."""
    import threading

    first = os.getppid()

    def gone() -> bool:
        if os.getppid() != first:
            return True
        try:
            os.kill(parent, 0)
        except ProcessLookupError:
            return True
        except OSError:                 # (e.g. another user's process now: it exists)
            pass
        return False

    def watch():
        while True:
            time.sleep(PARENT_POLL_SECONDS)
            if gone():
                os._exit(1)

    threading.Thread(target=watch, name="tritools-parent-watch", daemon=True).start()


def stop_pool(ex) -> None:
    """Stop a local process pool at once -- the tasks not started cancelled, the workers terminated -- for an
    interrupt (Ctrl-C, SIGTERM) or an error in the caller.  ``shutdown(wait=True)`` waited for every running task,
    and a worker inside a Clarabel solve sees its own SIGINT only when the solve returns: ``tritools colmap
    --workers 2`` ran on for over a minute after Ctrl-C (review 29b F4).  Any other executor is shut down without
    waiting (only local pools are passed: a dask Client is left to its owner)."""
    procs = list((getattr(ex, "_processes", None) or {}).values())
    ex.shutdown(wait=False, cancel_futures=True)
    for p in procs:
        if p.is_alive():
            p.terminate()
    for p in procs:
        p.join(STOP_JOIN_SECONDS)


#: seconds :func:`stop_pool` waits for each terminated worker to exit.
STOP_JOIN_SECONDS = 5.0


def as_point_problem(cams, regions):
    """(cameras (N, 3, 4), points (N, 2)) when the item is a well-shaped point-region problem, else None
    (the item then goes through :func:`triangulate`, whose validation reports any problem)."""
    if isinstance(regions, np.ndarray):
        x = regions
        if x.ndim != 2 or x.shape[1] != 2 or not np.issubdtype(x.dtype, np.number) or np.iscomplexobj(x):
            return None
        x = x.astype(float)
    elif isinstance(regions, (list, tuple)) and regions and \
            all(isinstance(r, Region) and r.is_point and declares_extent(r) for r in regions):
        x = np.array([r.center for r in regions])
    else:
        return None
    C = numeric_cameras(cams)
    if C is None:
        return None
    if C.ndim != 3 or C.shape[1:] != (3, 4) or C.shape[0] != len(x) or len(x) < 2 or not np.all(np.isfinite(x)):
        return None
    return C, x


class BatchOutcome:
    """Results of a batch: vectorised ones kept in their :class:`PointStack` arrays, per-item ones as objects;
    :meth:`record` puts them together, in input order."""

    def __init__(self, n: int):
        self.objects: dict[int, TriangulationResult] = {}
        self.stacked: dict[int, tuple] = {}         # index -> (stack, row)
        self.n = n

    def record(self) -> TriangulationResults:
        """The batch record: the stacks' rows copied column by column, the per-item objects as rows."""
        by_stack: dict[int, tuple] = {}
        for i, (stack, m) in self.stacked.items():
            entry = by_stack.setdefault(id(stack), (stack, [], []))
            entry[1].append(i)
            entry[2].append(m)
        idx = [np.array(ids, int) for _, ids, _ in by_stack.values()]
        parts = [stack.record(rows) for stack, _, rows in by_stack.values()]
        if self.objects:
            keys = sorted(self.objects)
            idx.append(np.array(keys, int))
            parts.append(TriangulationResults.from_rows([self.objects[i] for i in keys]))
        order = np.concatenate(idx) if idx else np.zeros(0, int)
        if not np.array_equal(np.sort(order), np.arange(self.n)):
            raise RuntimeError("a batch lost or duplicated a problem")       # an internal error, never expected
        return TriangulationResults.concat(parts).take(np.argsort(order, kind="stable"))


def executor_problem(executor) -> str | None:
    """Why ``executor`` cannot run per-point work (None: it can -- None itself, or an object with ``submit()``)."""
    if executor is None or (not isinstance(executor, type) and callable(getattr(executor, "submit", None))):
        return None       # (a class has a submit function too: an instance is needed)
    return (f"must be a concurrent.futures.Executor or a dask.distributed.Client (an object with submit()), got "
            f"{type(executor).__name__}")


def per_point_runner(executor=None, chunk_size: int = DEFAULT_CHUNK_SIZE, end: float | None = None):
    """The runner of the batch stage ``per_point`` (:mod:`tritools.solve.stages.batch`): items (row, cameras,
    regions, options, attempts) solved by :func:`tritools.triangulate` in chunks through ``executor`` (the
    module docstring's default: in this process below LOCAL_PROCESS_MIN_ITEMS items), within the whole call's
    ``end``; gives [(row, result)]."""
    def run(items) -> list:
        pairs: list = []
        _run_items(items, (), executor, chunk_size, pairs.extend, end)
        return pairs
    return run


def _collect(stack: PointStack, idx, out: BatchOutcome) -> list:
    """Rows of ``stack`` into ``out`` under the batch indices ``idx`` (closed by a batch stage: kept in the
    stack; solved by its per_point stage: objects); the per-item items (index, cameras, regions, options,
    attempts) of the rows still open."""
    items, done = [], stack.done
    for m, i in enumerate(idx):
        if m in stack.objects:
            out.objects[i] = stack.objects[m]
        elif done[m]:
            out.stacked[i] = (stack, m)
        else:
            items.append((i, *stack.item(m), stack.options_left(m), stack.prefix[m]))
    return items


def _run_items(items, retries, executor, chunk_size: int, store, end=None) -> None:
    """Solve per-item problems in chunks through ``executor`` (see the module docstring)."""
    chunks = [items[k:k + chunk_size] for k in range(0, len(items), chunk_size)]
    if not chunks:
        return
    own = None
    ex = executor
    if ex is not None and hasattr(ex, "get_executor"):       # dask.distributed.Client
        ex = ex.get_executor()
    elif ex is None:
        ex = own = _local_executor(len(items), len(chunks))
    pending = list(range(len(chunks)))
    after = _after_seconds(chunks, getattr(ex, "_max_workers", 1) if ex is not None else 1)
    try:
        if ex is not None:
            futures = {}
            try:
                futures = {ex.submit(_run_chunk, chunks[k], retries, end, after[k]): k for k in pending}
                for fut in cf.as_completed(futures):
                    k = futures[fut]
                    try:
                        store(fut.result())
                        pending.remove(k)
                    except cf.BrokenExecutor:
                        raise
                    except Exception as exc:  # noqa: BLE001 - a failed task fails its items, not the batch
                        log.warning("executor task failed: %s", exc)
                        store([(it[0], _failed(it[3], Status.SOLVER_FAILED,
                                               f"executor task failed: {type(exc).__name__}: {exc}"))
                               for it in chunks[k]])
                        pending.remove(k)
            except cf.BrokenExecutor as exc:       # a worker died: the unfinished chunks are retried here
                log.warning("executor broke (%s); retrying %d chunk(s) in this process", exc, len(pending))
        after = _after_seconds([chunks[k] for k in pending], 1)
        for j, k in enumerate(list(pending)):
            store(_run_chunk(chunks[k], retries, end, after[j]))
            pending.remove(k)
    except BaseException:
        if own is not None:                 # an interrupt: the workers stop now, not after their running chunks
            stop_pool(own)
        raise
    finally:
        if own is not None:
            own.shutdown(wait=True, cancel_futures=True)


def solve_point_stack(cameras: np.ndarray, points2d: np.ndarray, opts: TriangulationOptions, *, executor=None,
                      chunk_size: int = DEFAULT_CHUNK_SIZE, stages=BATCH_STAGES) -> BatchOutcome:
    """M point problems of N views given as stacks (cameras (M, N, 3, 4), points2d (M, N, 2)): the batch
    ``stages`` (:data:`~tritools.solve.stages.BATCH_STAGES`) of :class:`PointStack`, whose ``per_point`` stage
    runs the rows left open through ``executor`` (no per-item parsing); rows a stage list without
    ``per_point`` leaves open are solved the same way after it."""
    # (cameras scaled by 1e+-300 over- and underflow in intermediate products that every step checks for
    # finiteness: numpy's warnings are noise, and raised under -W error, as in robust_batch.robust_many)
    with call_limit(opts.total_time_limit) as end, np.errstate(all="ignore"):
        M = len(points2d)
        out = BatchOutcome(M)
        runner = per_point_runner(executor, chunk_size, end)
        items = stack_in_slices(cameras, points2d, np.arange(M), opts, stages, end, 0.0, out, runner)
        _run_items(items, (), executor, chunk_size, lambda pairs: out.objects.update(pairs), end)
    return out


#: under a whole-call limit a stack of point problems is solved in slices predicted to take at most this share of
#: the time left when it began (the vectorised steps of one slice are not interrupted): review 33a, 40,000 tracks of
#: 20 views as one stack ran a 3 s ``--total-time-limit`` to 18-21 s
SLICE_SHARE = 0.05
#: the pace of the first slice, before one is measured: this many times a row of last resort's (``reserve_for``)
SLICE_PRIOR = 4.0


def stack_in_slices(C, x, idx, opts, stages, end, later: float, out: BatchOutcome, runner=None) -> list:
    """The point problems C (M, N, 3, 4), x (M, N, 2) under the batch indices ``idx`` through :class:`PointStack`
    into ``out``; the per-item items of the rows left open.  Without a whole-call ``end``, one stack.  With one,
    the rows of last resort (:func:`expired_points`) of the last :func:`_sample_rows` rows first, which measures
    their cost (the reserve model :func:`~tritools.solve.call_limit.reserve_for` is a bound 3x above it: review 33c
    M1, 20,000 six-view rows under a 3 s limit reserved 3.2 s and solved none, where one stack certified all in
    2.5 s); then slices sized by the pace measured on the last (:data:`SLICE_SHARE`, :data:`SLICE_PRIOR`), each begun
    only where it is predicted to end before ``end`` less the reserve for the rows after it (``later`` seconds of
    other problems', capped as :func:`~tritools.solve.call_limit.reserved_end` caps it, and its own rows' at the
    measured cost); the rows not begun, and the open rows of a slice that ended past ``end``, keep or get their rows
    of last resort."""
    M, N = x.shape[:2]
    if end is None:
        return _collect(PointStack(C, x, opts, stages=stages, per_point=runner).run(), idx.tolist(), out)
    if M == 0:                          # (no rows: no sample either)
        return []
    target = SLICE_SHARE * max(0.0, end - time.time())
    k, t0 = _sample_rows(M, N), time.time()
    tail = expired_points(C[M - k:], x[M - k:], opts)           # (kept for these rows if they are not solved)
    model = reserve_for((N,))
    row_reserve = min(model, RESERVE_MARGIN * (time.time() - t0) / k)
    pace, a, items = SLICE_PRIOR * model, 0, []
    while a < M:
        left = reserved_end(end, later) - time.time() - row_reserve * max(0, M - k - a)
        rows = int(min(M - a, min(target, left) / pace))         # (a limit of 1e308 s: the ratio overflows)
        if rows < 1:
            break
        b, t0 = a + rows, time.time()
        with reserving(later + row_reserve * max(0, M - k - b)):       # the rows after it fit before the end
            stack = PointStack(C[a:b], x[a:b], opts, stages=stages, per_point=runner).run()
        if expired(end):                                       # past the end: the open rows' estimates at once
            stack.expire_open()
        pace = max((time.time() - t0) / rows, 1e-7)
        items.extend(_collect(stack, idx[a:b].tolist(), out))
        a = b
    if a < M - k:                                              # past the whole call's end: estimates only
        out.objects.update(zip(idx[a:M - k].tolist(), expired_points(C[a:M - k], x[a:M - k], opts)))
    out.objects.update((int(i), r) for i, r in zip(idx[max(a, M - k):], tail[max(a, M - k) - (M - k):]))
    return items


#: the rows of last resort of a stack's last rows are computed first to measure their cost
#: (:func:`stack_in_slices`): at most this many rows, and about this many views in all
SAMPLE_ROWS, SAMPLE_VIEWS = 256, 4096
#: the reserve per row is this many times the measured cost of the sample (its fixed costs already count in it)
RESERVE_MARGIN = 1.25


def _sample_rows(M: int, N: int) -> int:
    """Rows of a stack of M problems of N views whose rows of last resort measure their cost (at least one)."""
    return max(1, min(M, SAMPLE_ROWS, max(16, SAMPLE_VIEWS // max(N, 1))))


def solve_point_problems(problems, opts: TriangulationOptions, *, executor=None, progress=None, retries=(),
                         chunk_size: int = DEFAULT_CHUNK_SIZE, stages=BATCH_STAGES) -> BatchOutcome:
    """The engine of :func:`triangulate_many` (module docstring); ``problems`` a sequence of (cameras, regions);
    ``stages``: the batch stages run on each group of point problems (their open rows, with every other
    problem, then go through ``executor`` in one pass)."""
    with call_limit(opts.total_time_limit) as end, np.errstate(all="ignore"):
        return _solve_problems(problems, opts, executor, progress, retries, chunk_size, end, stages)


def _solve_problems(problems, opts: TriangulationOptions, executor, progress, retries, chunk_size: int, end,
                    stages=BATCH_STAGES) -> BatchOutcome:
    """:func:`solve_point_problems` within the whole call's ``end`` (:mod:`.call_limit`)."""
    n = len(problems)
    out = BatchOutcome(n)
    bar = _progress_bar(n, progress)
    groups: dict[int, list] = {}
    disc_groups: dict[int, list] = {}                # uncertain keypoints: all regions discs
    verify_discs_first = batch_steps(opts)[0]
    items = []                                       # (index, cameras, regions, options, prefix)
    for i, prob in enumerate(problems):
        try:
            cams, regions = prob
        except (TypeError, ValueError):
            out.objects[i] = _failed(opts, Status.INVALID_INPUT,
                                     f"problems[{i}] must be a (cameras, regions) pair, got {type(prob).__name__}")
            continue
        pp = as_point_problem(cams, regions)
        dp = as_disc_problem(cams, regions) if pp is None and verify_discs_first else None
        if dp is not None:
            disc_groups.setdefault(len(regions), []).append((i, cams, dp[1], dp[2], regions))
        elif pp is None:
            items.append((i, cams, regions, opts, ()))
        else:
            groups.setdefault(len(pp[1]), []).append((i, *pp))
    for group in disc_groups.values():
        if expired(end):                              # past the whole call's end: the per-point path's result
            items.extend((g[0], g[1], g[4], opts, ()) for g in group)
            continue
        done, rest = solve_disc_group(group, opts)
        out.objects.update(done)
        items.extend(rest)
    if bar is not None:
        bar.update(len(out.objects))
    order = list(groups.items())
    for k, (_, group) in enumerate(order):
        idx = [g[0] for g in group]
        C, x = np.array([g[1] for g in group]), np.array([g[2] for g in group])
        later = sum(reserve_for((n,)) * len(g) for n, g in order[k + 1:]) + reserve_for(_item_views(items))
        opened = len(items)                           # (no runner: the open rows join ``items``)
        items.extend(stack_in_slices(C, x, np.asarray(idx), opts, stages, end, later, out))
        if bar is not None:
            bar.update(len(idx) - (len(items) - opened))

    def store(pairs):
        for i, r in pairs:
            out.objects[i] = r
        if bar is not None:
            bar.update(len(pairs))

    items.sort(key=lambda it: it[0])
    try:
        _run_items(items, tuple(retries), executor, chunk_size, store, end)
    finally:
        if bar is not None:
            bar.close()
    return out


def triangulate_many(problems: Iterable[Sequence], method: str | Method | None = None, delta: int | None = None,
                     max_delta: int | None = None, *, options: TriangulationOptions | None = None,
                     executor: cf.Executor | object | None = None, progress: bool | str | None = None,
                     retries: Sequence[RetryStep] = (), chunk_size: int = DEFAULT_CHUNK_SIZE,
                     robust: float | Sequence | np.ndarray | None = None,
                     **overrides) -> TriangulationResults:
    """Triangulate every (cameras, regions) pair; results in input order, one per input, as the batch record
    :class:`~tritools.records.TriangulationResults` (a sequence of :class:`TriangulationResult` rows with
    vectorised columns: ``results[i]``, ``results.gamma_ub``).

    Parameters
    ----------
    problems : iterable of (cameras (N, 3, 4), regions) pairs; regions as for :func:`tritools.triangulate`
    method, delta, max_delta, options, overrides : as for :func:`tritools.triangulate` (one
        :class:`~tritools.solve.options.TriangulationOptions` for the whole batch; the default path "auto"
        certifies by verification first, vectorised over problems with the same structure); the budget's
        ``time_limit`` is per problem, ``total_time_limit`` bounds the whole call (:mod:`.call_limit`: the
        problems left when it expires get status ``time_limit`` with their estimate)
    executor : None, a :class:`concurrent.futures.Executor`, or a ``dask.distributed.Client``
        (see the module docstring for the default)
    progress : a tqdm bar: True, False / None (the default: no bar), or "auto" (only for batches of
        PROGRESS_MIN_ITEMS or more on a terminal's stderr; what the command line does unless --progress)
    retries : (method, delta) steps tried in order on items the first call did not certify
        (e.g. ``[("corollary1", 4), ("theorem1", None)]``); the first certified result is kept, else the
        first call's.  Each result's ``attempts`` lists them all.
    chunk_size : per-item problems per executor task
    robust : None, or TLS thresholds in pixels (a scalar, one per view, or one entry per problem): certified
        truncated least squares (:mod:`tritools.solve.robust_batch`; ``retries`` do not apply)
    """
    opts = options_from(options, method=method, delta=delta, max_delta=max_delta, **overrides)
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, (int, float, np.integer, np.floating)) or \
            not (np.isfinite(chunk_size) and chunk_size == int(chunk_size) and chunk_size >= 1):
        raise ValueError(f"chunk_size must be a positive integer, got {chunk_size!r}")
    if isinstance(problems, (str, bytes)) or not hasattr(problems, "__iter__"):
        raise TypeError(f"problems must be an iterable of (cameras, regions) pairs, got {type(problems).__name__}")
    why = executor_problem(executor)
    if why:
        raise TypeError(f"executor {why}")
    for step in retries:
        if not (isinstance(step, (tuple, list)) and len(step) == 2):
            raise ValueError(f"retries must be (method, delta) pairs, got {step!r}")
        opts.replace(method=step[0], delta=step[1])           # validated like every option
    if robust is not None:
        from .robust_batch import robust_many

        return TriangulationResults.from_rows(robust_many(list(problems), robust, opts, executor=executor,
                                                          progress=progress))
    return solve_point_problems(list(problems), opts, executor=executor, progress=progress, retries=retries,
                                chunk_size=int(chunk_size)).record()
