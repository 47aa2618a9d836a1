"""Batches of robust (TLS) problems: :func:`triangulate_many` and :func:`triangulate_points` with ``robust=``.

1. Point-region problems (with a finite threshold) of 2 to :data:`BATCH_ENUM_MAX_VIEWS` views first go through the
   enumeration of every inlier set, stacked across problems (:func:`tritools.solve.robust_enum_run.enumerate_many`,
   the single call's path).  The others, and those it does not decide, go to the branch and bound of
   :mod:`tritools.solve.robust` -- exactly the search :func:`tritools.triangulate` runs for one of them -- in
   chunks of :data:`ROBUST_CHUNK` searched together by :func:`tritools.solve.robust_drive.drive`: every sub-bound
   request of every search of a chunk (the full view set first, then the view pairs, the local optimisation's
   inlier sets, the node sub-problems) is computed in one vectorised call per subset size across the chunk
   (:func:`tritools.solve.robust_bounds.compute_many`: verification, then the batched delta = 2 SDP).  A clean
   track is certified at the root by the L2 bound of all its views (f_TLS* >= min(L2LB(all), min_i c_i^2)), so
   it costs one row of the first vectorised call; no per-point SDP runs before the search.  A track with one to
   three wrong matches is usually certified by the suspect stage (:mod:`tritools.solve.robust_suspects`) from about
   N + 3 rows, before the view pairs and the branch and bound; the searches left are the rare hard ones.  Their cameras
   are checked in one :func:`tritools.model.cameras.camera_problems` call per view count (a problem that fails
   it takes the per-problem path below, whose :func:`tritools.model.cameras.validate_cameras` names the error).
2. Other problems (and point problems whose thresholds are all infinite) first go through the batched L2 path
   (:func:`tritools.solve.batch.solve_point_problems`; the default plan to degree 2 only,
   :func:`tritools.solve.robust_settle.first_pass`).
   A result certified with every residual below its threshold and 2N gamma_UB^2 <= min_i c_i^2 is certified for
   TLS by that certificate alone: any inlier set other than all views pays at least min_i c_i^2 >= f_TLS(X), so
   f_TLS* = L2*.  It is returned as it is, every
   view an inlier; every other problem gets the branch and bound, in chunks as in 1.
3. A failing item becomes a result with a status (INVALID_INPUT / SOLVER_FAILED), never stopping the batch.
   ``timings["batch_share"]``: a problem's even share of its chunk's time.
"""
from __future__ import annotations

import dataclasses
import logging
import time

import numpy as np

from ..result import Attempt, Status, TriangulationResult, input_failure, refused
from .call_limit import (call_limit, current_end, expired, expired_points, mark_cut, reserve_for, reserving,
                         within)
from .fastpath_cameras import validated_problem
from .identical_views import identical_views, may_repeat_views
from .robust import robust_thresholds, triangulate_robust
from .robust_report import tls_reported_stack
from .robust_settle import first_pass, l2_suffices, settled_by_l2

__all__ = ["robust_many", "thresholds_for"]

log = logging.getLogger(__name__)

def thresholds_for(robust, problems) -> list:
    """The thresholds of each problem from ``robust=``: a scalar; one array of per-view thresholds for problems of
    equal size; or a sequence with one entry per problem, each a scalar or a per-view array (a 2-D array; a list
    holding an array; or a list of M scalars for M problems that cannot be per-view thresholds because some problem
    has another view count -- M scalars for M problems of M views each read as per-view thresholds).  ValueError
    naming ``robust`` (and the problem, ``robust[k]``); a problem that a valid shared per-view array does not fit gets
    a ValueError instance in its place (:func:`_shared`: status ``invalid_input``, the batch goes on) -- unless the
    array fits no valid problem of two or more views (the argument is wrong: raised)."""
    sizes = [_n_views(p) for p in problems]
    if not _per_problem(robust, sizes):
        out = [_shared(robust, n, k) if n is not None else None for k, n in enumerate(sizes)]
        solvable = [k for k, n in enumerate(sizes) if n is not None and n >= 2]    # a 1-view problem is no fit
        fits = [k for k in solvable if not isinstance(out[k], ValueError)]
        if solvable and len(fits) < len(solvable) and not any(_valid(problems[k]) for k in fits):
            robust_thresholds(robust, sizes[solvable[0]])     # fits no valid problem: the argument is wrong
        return out
    if len(robust) != len(problems):
        raise ValueError(f"robust must be a scalar, one threshold per view, or one entry per problem "
                         f"({len(problems)}), got {len(robust)} entries")
    out = []
    for k, (c, n) in enumerate(zip(robust, sizes)):
        try:
            out.append(robust_thresholds(c, n) if n is not None else None)
        except ValueError as exc:
            raise ValueError(f"robust[{k}] (problem {k}): {exc}") from None
    return out


def _valid(problem) -> bool:
    """Does ``problem`` pass the input checks (:func:`~tritools.solve.fastpath_cameras.validated_problem`)?"""
    from .fastpath_cameras import validated_problem

    try:
        validated_problem(*problem)
    except (ValueError, TypeError):
        return False
    return True


def _shared(robust, n: int, k: int):
    """The thresholds of problem ``k`` (``n`` views) from one value or one per-view array; a ValueError *instance*
    naming ``problems[k]`` when a valid per-view array has another length (that problem gets status
    ``invalid_input``, the batch goes on); raised when ``robust`` itself is invalid (every problem's)."""
    try:
        return robust_thresholds(robust, n)
    except ValueError as exc:
        if np.ndim(robust) != 1:
            raise
        robust_thresholds(robust, len(robust))          # raises for invalid values: the call's argument
        return ValueError(f"problems[{k}]: {n} views, {exc}")


def _per_problem(robust, sizes: list) -> bool:
    """Is ``robust`` one entry per problem (:func:`thresholds_for`) rather than one value or one per-view array?"""
    if isinstance(robust, np.ndarray):
        if robust.ndim != 1:
            return robust.ndim == 2
        robust = list(robust)           # a 1-D array of scalars: the list's rule (review 8b F5)
    if not isinstance(robust, (list, tuple)) or len(robust) == 0:
        return False
    if any(isinstance(e, (list, tuple, np.ndarray)) and np.ndim(e) > 0 for e in robust):
        return True
    return len(robust) == len(sizes) and any(n is not None and n != len(robust) for n in sizes)


def _n_views(problem) -> int | None:
    """The view count of a (cameras, regions) problem, or None when it has none (a malformed problem: the
    batch gives it status ``invalid_input`` and its threshold is never used)."""
    try:
        _, regions = problem
        n = int(np.shape(regions)[0]) if hasattr(regions, "shape") else len(regions)
    except (TypeError, ValueError, IndexError):
        return None
    return n


#: problems searched together by :func:`tritools.solve.robust_drive.drive` (their sub-bounds batched per subset size);
#: each keeps its own time budget, from the start of its chunk, charged with its own steps and an even share of
#: the batched calls only.
ROBUST_CHUNK = 512


#: batches enumerate every inlier set of point problems up to this many views (single calls: up to
#: :data:`tritools.solve.robust_enum.ENUM_MAX_VIEWS`), the branch and bound beyond.  In a stack of many problems the
#: enumeration's rows are shared (benchmarks/RESULTS.md, "Wave 9 robust batches at N = 7-10"): at 9-10 views with
#: three or four wrong matches it costs about half the search's time.
BATCH_ENUM_MAX_VIEWS = 10


def _mismatch(problem, exc: ValueError) -> TriangulationResult:
    """The ``invalid_input`` result of a problem whose per-view thresholds do not fit it: the problem's own fault
    when it has one (e.g. one view), else the thresholds'."""
    why = f"ValueError: {exc}"
    try:
        validated_problem(*problem)
    except (ValueError, TypeError) as bad:
        why = f"{type(bad).__name__}: {bad}"
    return TriangulationResult("tls", Status.INVALID_INPUT, message=why)


def _search_or_failure(cameras, regions, c, opts):
    """A :class:`tritools.solve.robust.TlsSearch` for one problem, or a failed result (bad input)."""
    from .robust import TlsSearch
    from .triangulate import solve_validated

    t0 = time.perf_counter()
    try:
        cams, regs = validated_problem(cameras, regions)
        if identical_views(cams, regs, c) is not None:      # views listed twice: the single call's exact reduction
            return solve_validated(cams, regs, c, opts, t0)
        return TlsSearch(cams, regs, c, opts, t0)
    except (ValueError, TypeError) as exc:
        status, msg = input_failure(exc)
    except Exception as exc:  # noqa: BLE001 - a batch never loses a point (review 29b F1: an OverflowError here
        log.debug("robust search set-up failed", exc_info=True)       # raised out of the batch, every row lost)
        status, msg = Status.SOLVER_FAILED, f"{type(exc).__name__}: {exc}"
    # the call's one attempt, as the L2 batch's rows record it (batch.safe_triangulate; review 46c L1)
    return TriangulationResult("tls", status, message=msg, timings={"total": time.perf_counter() - t0},
                               attempts=(Attempt("tls", opts.delta, status.value, step="call"),))


def robust_many(problems: list, robust, opts, *, executor=None, progress=None) -> list[TriangulationResult]:
    """One TLS result per problem, in input order (module docstring); ``opts.total_time_limit`` bounds the whole
    call: each chunk's searches get at most the time left (:mod:`.call_limit`)."""
    # cameras scaled by 1e+-200 over- and underflow in intermediate products that every step checks for finiteness
    # (review 8 F7: numpy's RuntimeWarnings leaked, and raised under -W error); the results are unaffected
    with call_limit(opts.total_time_limit), np.errstate(all="ignore"):
        return _robust_many(problems, robust, opts, executor, progress)


def _robust_many(problems: list, robust, opts, executor, progress) -> list[TriangulationResult]:
    from .batch import as_point_problem, solve_point_problems

    thresholds = thresholds_for(robust, problems)
    out: list = [None] * len(problems)
    direct, l2_first, points = [], [], {}
    for i, (prob, c) in enumerate(zip(problems, thresholds)):
        if isinstance(c, ValueError):               # thresholds of another view count (:func:`_shared`)
            out[i] = _mismatch(prob, c)
            continue
        pp = as_point_problem(*prob) if isinstance(prob, (list, tuple)) and len(prob) == 2 else None
        (direct if pp is not None and np.any(np.isfinite(c)) else l2_first).append(i)
        if pp is not None:
            points[i] = pp
    pending, spent = direct, {}
    if l2_first:
        first = solve_point_problems([problems[i] for i in l2_first], first_pass(opts), executor=executor,
                                     progress=progress).record()
        pending = pending + _after_l2(problems, thresholds, opts, l2_first, first, out)
        # the first pass counts against each problem's time limit, as in a single call (robust_settle): its search
        # gets the rest (a 30-view box track ran 1.9-2.1x its limit, review 42a MEDIUM-1)
        spent = {i: float((res.timings or {}).get("total", 0.0)) for i, res in zip(l2_first, first)}
    _drive_chunks(problems, thresholds, opts, sorted(pending), out, points, spent)
    return out


def _less(opts, seconds: float):
    """``opts`` with ``seconds`` less of its per-problem time limit (none: unchanged; at least 1 ms left)."""
    limit = opts.budget.time_limit
    if limit is None or not seconds > 0:
        return opts
    return opts.replace(time_limit=max(1e-3, limit - seconds))


def _after_l2(problems, thresholds, opts, idx, first, out) -> list:
    """Fill ``out`` for the problems settled by their L2 result (module docstring, 2); the rest of ``idx``."""
    rest = []
    for k, (i, res) in enumerate(zip(idx, first)):
        c = thresholds[i]                        # None: a malformed entry, invalid_input from the L2 stage
        if res.status == Status.INVALID_INPUT and res.message:     # the L2 stage saw problems[k]: the caller's i
            res = dataclasses.replace(res, message=res.message.replace(f"problems[{k}]", f"problems[{i}]", 1))
        if refused(res) or c is None:
            out[i] = dataclasses.replace(res, inliers=None if res.residuals is None
                                         else np.ones(len(res.residuals), bool))
        elif l2_suffices(res, c, *problems[i][:2], opts.tolerances):
            out[i] = settled_by_l2(res)
        elif not np.any(np.isfinite(c)):
            out[i] = triangulate_robust(*validated_problem(*problems[i]), c, opts)
        else:
            rest.append(i)
    return rest


def _drive_chunks(problems, thresholds, opts, idx, out, points, spent=None) -> None:
    """The TLS results of the problems ``idx`` (:func:`_enumerated_then_searched`), :data:`ROBUST_CHUNK` together at
    a time (each search's time budget starts with its chunk).  ``points``: index -> (cameras, centres) of the point
    problems (their cameras checked in one vectorised call per view count, :func:`_point_searches`).  Under a
    whole-call limit a chunk takes about :data:`CHUNK_SHARE` of the time left at the last chunk's cost per problem
    (at least :data:`CHUNK_MIN` problems), and the problems whose chunk would start after the end get the rows of
    :func:`expired_tls` (a search past its deadline still costs ~1 ms: 200 problems took a 0.01 s limit to 0.1-0.4 s,
    review 18); a chunk ends early enough for those rows (:func:`~.call_limit.reserving`).  ``spent``: index ->
    seconds of a problem's time limit already used (its L2 first pass)."""
    k, per = 0, CHUNK_PRIOR_SECONDS
    while k < len(idx):
        end = current_end()
        if expired(end):
            expired_tls(problems, thresholds, opts, idx[k:], out, points)
            return
        size = ROBUST_CHUNK if end is None else \
            int(min(ROBUST_CHUNK, max(CHUNK_MIN, CHUNK_SHARE * (end - time.time()) / per)))
        t0 = time.perf_counter()
        chunk = idx[k:k + size]
        k += size
        with reserving(reserve_for(_view_count(problems[i]) for i in idx[k:])):    # their rows past the end
            _drive_chunk(problems, thresholds, opts, chunk, out, points, t0, spent or {})
        per = max((time.perf_counter() - t0) / len(chunk), 1e-6)


def _view_count(problem) -> int:
    """The view count of a batch item for :func:`~.call_limit.reserve_for` (2 for an item it cannot read)."""
    try:
        return max(2, len(problem[0]))
    except (TypeError, IndexError, KeyError, ValueError, AttributeError):
        return 2


#: under a whole-call limit: a chunk's share of the time left, the fewest problems in a chunk, and the cost per
#: problem assumed before the first chunk (seconds; measured 0.5-2 ms on the 2-core machine)
CHUNK_SHARE = 0.25
CHUNK_MIN = 2
CHUNK_PRIOR_SECONDS = 2e-3


def _drive_chunk(problems, thresholds, opts, chunk, out, points, t0, spent) -> None:
    """The results of one chunk of :func:`_drive_chunks`."""
    run, cut = within(opts, current_end())
    searches = _point_searches([i for i in chunk if i in points], points, thresholds, run, t0)
    for i in chunk:
        if i in searches:
            continue
        s = _search_or_failure(*problems[i], thresholds[i], _less(run, spent.get(i, 0.0)))
        if isinstance(s, TriangulationResult):
            out[i] = s
        else:
            searches[i] = s
    searches = sorted(searches.items())
    results = _enumerated_then_searched([s for _, s in searches])
    share = (time.perf_counter() - t0) / max(1, len(searches))
    for (i, _), r in zip(searches, results):
        r.timings["batch_share"] = share    # the result's own dict (TriangulationResult copies it): no replace
        out[i] = mark_cut(r) if cut else r


def expired_tls(problems, thresholds, opts, idx, out, points) -> None:
    """``time_limit`` rows of the problems ``idx`` not started before the whole call's end: for point problems, per
    view count, the DLT point of all views (:func:`~.call_limit.expired_points`, vectorised) with its TLS
    numbers (:func:`~.robust_report.tls_reported_stack` at the trivial lower bound 0, not certified: gamma_UB =
    gamma_TLS(X), a valid upper bound, inliers d_i(X) < c_i); a problem those checks refuse keeps their
    ``invalid_input`` row; other problems through their search with a spent budget (its last-resort estimate)."""
    groups: dict = {}
    for i in idx:
        if i in points:
            groups.setdefault(len(points[i][1]), []).append(i)
        elif not _expired_region_tls(problems[i], thresholds[i], opts, out, i):
            _drive_chunk(problems, thresholds, opts, [i], out, points, time.perf_counter())
    for group in groups.values():
        C = np.stack([points[i][0] for i in group])
        x = np.stack([points[i][1] for i in group])
        l2 = expired_points(C, x, opts, refine=False, c=np.stack([thresholds[i] for i in group]))
        have = [k for k, r in enumerate(l2) if r.X is not None]
        told = tls_reported_stack(C[have], x[have], np.array([l2[k].X for k in have]).reshape(-1, 3),
                                  np.stack([thresholds[group[k]] for k in have]).reshape(len(have), -1),
                                  np.zeros(len(have)), opts.tolerances, np.zeros(len(have), bool),
                                  np.full(len(have), np.nan)) if have else []       # (checked)
        told = dict(zip(have, told))
        for k, (i, r) in enumerate(zip(group, l2)):
            out[i] = _expired_row(r, told.get(k))


def _expired_region_tls(problem, c, opts, out, i) -> bool:
    """The ``time_limit`` row of a problem with regions not started before the end (:func:`expired_tls`): the DLT
    point of the region centres (:func:`~.call_limit.expired_regions_validated`) with its TLS numbers at the trivial
    lower bound 0 (:func:`~.robust_report.tls_reported`: d_i(X) the distances to the regions, gamma_UB =
    gamma_TLS(X), inliers d_i(X) < c_i) -- without the search's normalisation and local refinement (~4 ms a
    6-view problem of regions, review 3 of wave 18: 120 problems took a 0.01 s limit to 0.6 s).  False where the
    problem or its thresholds do not validate: the caller's search then reports what is wrong."""
    from .call_limit import expired_regions_validated
    from .fastpath_cameras import validated_problem
    from .robust_report import tls_reported

    if c is None or isinstance(c, ValueError):
        return False
    try:
        cams, regs = validated_problem(*problem)
        centres = np.array([np.asarray(r.center, float).reshape(2) for r in regs])
    except (ValueError, TypeError):
        return False
    c = np.asarray(c, float)
    if c.shape != (len(regs),):
        return False
    r = expired_regions_validated(cams, regs, centres, opts, time.perf_counter(), c)
    told = None
    if r.X is not None:
        told = tls_reported(cams, centres, np.asarray(r.residuals, float), np.asarray(r.X, float), c, 0.0,
                            opts.tolerances, False, regions=regs)
    out[i] = _expired_row(r, told)
    return True


def _expired_row(r: TriangulationResult, told) -> TriangulationResult:
    """The TLS form of an expired L2 row ``r`` (:func:`expired_tls`) with its reported TLS numbers ``told``."""
    if refused(r):
        return dataclasses.replace(r, method="tls")
    if told is None:
        return dataclasses.replace(r, method="tls", attempts=(Attempt("tls", None, Status.TIME_LIMIT.value,
                                                                      step="call"),))
    msg = r.message.replace("gamma_UB from", "gamma_UB (TLS) from")
    return dataclasses.replace(r, method="tls", gamma_ub=told.gamma_ub, gamma_lb=told.gamma_lb,
                               residuals=told.residuals, inliers=told.inliers, image_points=told.image_points,
                               message=f"TLS: {int(told.inliers.sum())}/{len(told.inliers)} inliers; {msg}",
                               attempts=(Attempt("tls", None, Status.TIME_LIMIT.value, None, told.gamma_ub,
                                                 step="call"),))


def _enumerated_then_searched(searches: list) -> list:
    """The results of the searches: point problems of 2 to BATCH_ENUM_MAX_VIEWS views by the enumeration of every inlier
    set, stacked across problems (:func:`tritools.solve.robust_enum_run.enumerate_many`, the staged order), those it
    leaves open by the single call's enumeration of each alone (:func:`~tritools.solve.robust_enum_run.enumerate_tls`:
    the unstaged order, or the scalar paths of two and three views; it decided tiny-baseline tracks in
    georeferenced worlds that the staged order left to the search with a worse estimate, review 22a F1), the
    others and those still open by the branch and bound (:func:`tritools.solve.robust_drive.drive`).  The
    decision scales come from one normalisation stack per view count (:func:`_normalization_scales`), computed only
    for the searches that need them."""
    from .robust_drive import drive
    from .robust_enum_run import eligible, enumerate_many, enumerate_tls

    normalised: set = set()

    def scales(group) -> None:
        _normalization_scales(group)
        normalised.update(map(id, group))

    results = enumerate_many(searches, scales=scales, max_views=BATCH_ENUM_MAX_VIEWS, staged=True)
    left = [k for k, r in enumerate(results) if r is None]
    _normalization_scales([searches[k] for k in left if id(searches[k]) not in normalised])
    for k in left:                      # the single call's enumeration next (review 22a F1), each problem alone
        if eligible(searches[k], BATCH_ENUM_MAX_VIEWS):
            results[k] = enumerate_tls(searches[k])
    left = [k for k in left if results[k] is None]
    again = [k for k, r in enumerate(results) if r is not None and withheld(r)]
    for k, r in zip(left, drive([searches[k] for k in left]) if left else []):
        results[k] = r
    for k, r in zip(again, searched_again([searches[k] for k in again], [results[k] for k in again])):
        results[k] = r
    return results


def withheld(res) -> bool:
    """Did the report withhold the certificate an enumeration gave on its own scale, at the coordinates' resolution
    (:data:`tritools.solve.robust_report.GAP_GUARD_REASON`: the round-off of a wrong match far off the image)?"""
    from .robust_report import GAP_GUARD_REASON
    return res.status == Status.NOT_CERTIFIED and GAP_GUARD_REASON in (res.message or "")


def searched_again(searches: list, results: list) -> list:
    """Enumerated results that :func:`withheld` flags, searched again by the branch and bound (its suspect cover's
    bound splits by views down to the pair bounds, :func:`tritools.solve.robust_suspects._told`: a 9-view track with
    wrong matches 7e4 and 1e8 px off at zero noise was certified by the search and not by the enumeration, review 50b),
    the search's certificate taken where it gives one, else the enumeration's result.  The search starts from the
    enumeration's best estimate; its bounds are its own (the enumeration frame's terms are not reused)."""
    from .robust_drive import drive

    if not searches:
        return []
    for s in searches:
        s.enum_terms = None
    return [r if r.optimal else old for r, old in zip(drive(searches), results)]


def _normalization_scales(searches) -> None:
    """The decision scales of point-region searches, grouped by view count, from one
    :func:`tritools.model.normalize.normalization_stack` call per group: the same function
    :func:`tritools.model.normalize.normalization_for` applies to a stack of one (scale 1 where it fails)."""
    from ..model.normalize import normalization_stack
    from .robust_verify import frames_of

    groups: dict = {}
    for s in searches:
        if s.points:
            groups.setdefault(s.N, []).append(s)
    for group in groups.values():
        st = normalization_stack(np.stack([s.C for s in group]), np.stack([s.x for s in group]), scalar=False)
        for k, (s, frame) in enumerate(zip(group, frames_of(st))):
            s.set_normalization_scale(float(st.scale[k]) if st.ok[k] else 1.0)
            s.bounds.set_frame(frame)           # the sub-problems are verified in this frame (.robust_verify)


def _point_searches(idx, points, thresholds, opts, t0) -> dict:
    """index -> search for the point problems ``idx`` whose cameras pass
    :func:`tritools.model.cameras.camera_problems` (the vectorised twin of the per-problem
    :func:`tritools.model.cameras.validate_cameras`), one call per view count; the others are left out (the
    caller's per-problem path gives them their named error)."""
    from ..model.cameras import camera_problems, depth_rows
    from ..model.frame import world_origins
    from .robust import TlsSearch

    groups: dict = {}
    for i in idx:
        groups.setdefault(len(points[i][1]), []).append(i)
    out = {}
    for group in groups.values():
        C = np.stack([points[i][0] for i in group])
        try:
            valid = camera_problems(C).valid & ~may_repeat_views(C)    # views listed twice: the per-problem path
            rows = depth_rows(C)                # the depth rows of every search's report, in one call
            origins = world_origins(C)          # each search's world frame (TlsSearch), in one call
        except (ValueError, ArithmeticError, np.linalg.LinAlgError):
            continue                            # the per-problem path takes the group (and names any failure)
        for k, i in enumerate(group):
            if valid[k]:
                out[i] = TlsSearch(C[k].copy(), None, thresholds[i], opts, t0, points=points[i][1],
                                   origin=origins[k])
                out[i].drows = rows[k]
    return out


def searched_again_one(search, res: TriangulationResult) -> TriangulationResult:
    """:func:`searched_again` of one enumerated result where :func:`withheld` flags it (a single call), else ``res``."""
    return searched_again([search], [res])[0] if withheld(res) else res


def enumerated_again(search, res: TriangulationResult) -> TriangulationResult:
    """An uncertified single call of more views than a single call enumerates (:data:`robust_enum.ENUM_MAX_VIEWS`) but
    at most what a batch does (:data:`robust_batch.BATCH_ENUM_MAX_VIEWS`): the batch's staged enumeration, its
    certificate taken where it gives one (review 49b M1: a wrong match 1e7 px off certified by the batch at 9-10 views
    -- its bound split by sets of views, :func:`robust_split._split_lower` -- and not by the search of a single
    call); else ``res``."""
    from .robust_enum import ENUM_MAX_VIEWS
    from .robust_enum_run import eligible, enumerate_many

    if not (ENUM_MAX_VIEWS < search.N and eligible(search, BATCH_ENUM_MAX_VIEWS)):
        return res
    again = enumerate_many([search], max_views=BATCH_ENUM_MAX_VIEWS, staged=True)[0]
    return again if again is not None and again.optimal else res
