"""Stages over a batch of point problems: a column record being filled and the mask of the rows still open.

M point problems of N views -- cameras (M, N, 3, 4), observed points (M, N, 2), the point regions' centres
-- are solved by the stages of :data:`BATCH_STAGES`, module-level functions ``stage(ctx) -> None`` over a
:class:`BatchContext`.  Each stage touches only the rows where ``ctx.open`` is True and closes the rows it
decides (``ctx.store`` for a solved row, ``ctx.close`` for a row decided otherwise):

``plan`` -> ``verify`` -> ``sdp`` -> ``per_point`` -> ``report``

* ``plan`` -- which batched steps the options allow (:func:`tritools.solve.plan.batch_steps`: the plan
  starts with Corollary 1 at delta = 2 with normalisation; the degree plan itself lives in ``plan.py``);
* ``verify`` -- :data:`BATCH_VERIFY_IMPLEMENTATIONS`, the first usable one: ``"verify-points"``,
  certification by verification vectorised over the open rows (:func:`tritools.solve.fastpath.verify_points`,
  the same function the point stage ``verify`` runs on a stack of one), in chunks of ``verify_chunk_for(N)``;
  a certified row is closed; every row gets its attempt, and the rows left continue with ``path="sdp"``;
* ``sdp`` -- :data:`BATCH_SDP_IMPLEMENTATIONS`: ``"sdp-points"``, the batched delta = 2 SDP
  (:func:`tritools.solve.sdp_batch.solve_corollary1_points`, the point stage ``sdp``'s fast twin) in chunks
  of ``chunk_for(N)``: a row certified, or decided at the plan's last degree, is closed; a row decided but
  not certified continues at delta = 4; a row the batch hands back stays open;
* ``per_point`` -- the rows still open through the per-point stages (:data:`~tritools.solve.stages.POINT_STAGES`
  via :func:`tritools.triangulate`), each with its options and the attempts so far, by the ``per_point``
  runner of the context (:mod:`tritools.solve.batch`: the executor).  Without a runner the rows stay open
  and the caller takes them (:meth:`BatchContext.items`): ``triangulate_many`` does, to run the open rows
  of every group and its non-point problems in one executor pass (one local process pool, the whole
  call's limit in input order);
* ``report`` -- gamma_UB, residuals, depths and cheirality of the rows a batch stage solved, vectorised
  (:func:`tritools.solve.report.points_report_stack`; a per-point result carries its own report).

A chunk's wall time is shared among its rows (``timings["batch_share"]``).  The per-point deadline
``time_limit`` holds in the vectorised stages as M times the limit for a chunk of M rows
(:func:`tritools.solve.settings.stack_deadline`).  The stage list is data, like the point stages':
``with_stage(BATCH_STAGES, Stage("mine", fn), after="verify")`` inserts a stage without touching the others
(docs/architecture.md, "Stages").
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from sospoly import n_lmivar_formula

from ...model.constraints import Method
from ...model.frame import moved_cameras, world_origins
from ...model.magnitude import guard_resolutions, view_floors
from ...model.regions import Point
from ...records import TriangulationResults
from ...result import Attempt, Status
from ..decide import cheirality, decide_reported, reported_lower
from ..fastpath import BAND_MIN_VIEWS, BAND_WIDTHS, verify_points
from ..options import TriangulationOptions
from ..plan import batch_steps, last_delta
from ..report import points_report_stack
from ..sdp_batch import solve_corollary1_points
from ..settings import stack_deadline
from ..trivial import TRIVIAL_BOUND
from .outcome import TRANSFER_MESSAGE
from .context import AttemptStep, ImplName, Implementation, bound_stop_reached, fast_names

__all__ = ["BatchContext", "BatchPlan", "BATCH_VERIFY_IMPLEMENTATIONS", "BATCH_SDP_IMPLEMENTATIONS",
           "plan_batch_stage", "verify_batch_stage", "sdp_batch_stage", "per_point_batch_stage",
           "report_batch_stage", "FAST_CHUNK", "FAST_CHUNK_BYTES", "chunk_for", "verify_chunk_for", "BEHIND_MESSAGE"]

#: the vectorised stages handle at most this many problems per numpy call ...
FAST_CHUNK = 4096
#: ... and use at most about this many bytes per call (the verification's arrays grow like N^3 per problem).
FAST_CHUNK_BYTES = 256 * 2 ** 20
#: the message of a row certified but behind a camera.
BEHIND_MESSAGE = "certified L2 optimum, but behind a camera"


def chunk_for(n_views: int, n_pairs: int | None = None) -> int:
    """Problems per vectorised call for N views (memory ~ 8 (4 K n + 8 n^2) bytes each, n = 2N, K the view pairs
    whose constraints are held: all N(N-1)/2 by default)."""
    K, n = n_views * (n_views - 1) // 2 if n_pairs is None else n_pairs, 2 * n_views
    return int(max(1, min(FAST_CHUNK, FAST_CHUNK_BYTES // (8 * (4 * K * n + 8 * n * n + 64)))))


def verify_chunk_for(n_views: int) -> int:
    """Problems per call of the verification: its band paths hold ~max(BAND_WIDTHS) N pairs (the all-pairs
    fallback chunks itself, :func:`tritools.solve.fastpath.verify_checked`)."""
    if n_views < BAND_MIN_VIEWS:
        return chunk_for(n_views)
    return chunk_for(n_views, max(BAND_WIDTHS) * n_views)


@dataclass(frozen=True)
class BatchPlan:
    """The batched steps the options allow: certification by verification, the delta = 2 SDP."""
    verify: bool = False
    sdp: bool = False


class BatchContext:
    """M point problems of N views in progress (module docstring): the input stacks ``C`` / ``x``, the options,
    the columns of the record being filled, the ``open`` mask, and for each open row the options and the
    attempts (``todo`` / ``prefix``) the per-point path continues from.  ``per_point``: the runner of the
    ``per_point`` stage, ``runner(items) -> [(row, TriangulationResult)]`` with items
    ``(row, cameras, regions, options, attempts)``; None leaves the open rows to the caller (:meth:`items`).
    ``stages``: the batch stages :meth:`run` runs (:data:`tritools.solve.stages.BATCH_STAGES`); ``fast``: the
    names of the fast implementations allowed (None: all)."""

    def __init__(self, cameras: np.ndarray, points2d: np.ndarray, opts: TriangulationOptions, *,
                 stages=(), fast=None, per_point: Callable | None = None):
        self.C, self.x, self.opts = np.asarray(cameras, float), np.asarray(points2d, float), opts
        M, N = self.x.shape[:2]
        # georeferenced worlds: the batch stages solve in each problem's re-centred frame, like the point stages
        # (tritools.model.frame); X is stored there and moved back by the report stage
        self.origin = world_origins(self.C) if M else np.zeros((0, 3))
        self.Cw = moved_cameras(self.C, self.origin) if np.any(self.origin) else self.C
        self.scale = np.full(M, np.nan)         # the normalisation's image scale of each row a batch stage solved
        self.M, self.N = M, N
        self.stages, self.per_point = tuple(stages), per_point
        self.fast = frozenset(ImplName) if fast is None else fast_names(fast)
        self.plan, self.rest_opts = BatchPlan(), opts     # rest_opts: what an open row continues with
        self.open, self.solved = np.ones(M, bool), np.zeros(M, bool)
        self.X, self.X_raw = np.full((M, 3), np.nan), np.full((M, 3), np.nan)
        self.gamma_lb = np.full(M, np.nan)
        self.image_points = np.full((M, N, 2), np.nan)
        self.status = np.full(M, None, dtype=object)
        self.method = np.full(M, opts.method.value, dtype=object)
        self.optimal = np.zeros(M, bool)
        self.certified_by = np.full(M, None, dtype=object)
        self.delta = np.full(M, -1)
        self.message = np.full(M, "", dtype=object)
        self.seconds = np.zeros(M)              # each problem's share of the vectorised calls it went through
        self.n_lmivar = n_lmivar_formula(2 * N, 2, [2] * (N * (N - 1) // 2))
        self.prefix: list = [() for _ in range(M)]
        self.todo: dict[int, TriangulationOptions] = {}
        self.objects: dict = {}                 # row -> TriangulationResult of the per-point path
        self._report_columns(np.zeros(0, int))

    # ------------------------------------------------------------------------------------------------ running
    def run(self) -> BatchContext:
        """The stages in order (each skips closed rows)."""
        for stage in self.stages:
            stage.run(self)
        return self

    @property
    def done(self) -> np.ndarray:
        """Rows closed by a batch stage (in :meth:`record`), not by the per-point path."""
        d = ~self.open
        if self.objects:
            d[list(self.objects)] = False
        return d

    def open_rows(self) -> np.ndarray:
        return np.nonzero(self.open)[0]

    def timed(self, idx: np.ndarray, step, *args):
        """``step(idx, *args)``, its wall time shared among the rows ``idx``."""
        t0 = time.perf_counter()
        out = step(idx, *args)
        if idx.size:
            self.seconds[idx] += (time.perf_counter() - t0) / idx.size
        return out

    # ------------------------------------------------------------------------------------------ closing rows
    def store(self, idx, X, X_raw, gamma_lb, image_points, status, optimal, certified_by, scale) -> None:
        """Close rows ``idx`` solved at delta = 2 by a batch stage (``report`` completes them); X, X_raw in the
        rows' re-centred frames, ``scale`` the normalisation's image scale."""
        self.X[idx], self.X_raw[idx], self.gamma_lb[idx], self.image_points[idx] = X, X_raw, gamma_lb, image_points
        self.scale[idx] = scale
        self.status[idx], self.optimal[idx], self.certified_by[idx] = status, optimal, certified_by
        self.method[idx] = Method.COROLLARY1.value
        self.delta[idx] = 2
        self.open[idx], self.solved[idx] = False, True

    def close(self, idx, status: Status, message: str = "") -> None:
        """Close rows ``idx`` without a solution (e.g. a user rule): ``status`` and ``message``, no bounds."""
        idx = np.asarray(idx, int).reshape(-1)
        self.status[idx], self.message[idx] = Status(status).value, message
        self.open[idx] = False

    def close_results(self, pairs) -> None:
        """Close rows with per-point results: [(row, TriangulationResult)]."""
        for m, res in pairs:
            self.objects[int(m)] = res
            self.open[int(m)] = False

    def expire_open(self) -> None:
        """Close the open rows with their rows of last resort past the whole call's end, in one vectorised call
        (:func:`~tritools.solve.call_limit.expired_points`: what each would get as a per-point item)."""
        from ..call_limit import expired_points

        rows = self.open_rows()
        if rows.size:
            self.close_results(zip(rows.tolist(), expired_points(self.C[rows], self.x[rows], self.opts)))

    def items(self, rows=None) -> list:
        """(row, cameras, regions, options, attempts) of the open rows (or ``rows``) for the per-point path."""
        rows = self.open_rows() if rows is None else rows
        return [(int(m), self.C[m], [Point(p) for p in self.x[m]], self.options_left(int(m)), self.prefix[m])
                for m in rows]

    def options_left(self, m: int) -> TriangulationOptions:
        """Row ``m``'s options for the per-point path (``todo``, else ``rest_opts``) with the per-point time limit
        less the row's share of the batch stages' time (``seconds``): the
        per-point path gets what is left of the point's limit, not a fresh one (review 27a: a 50-view track took
        11.2 s under a 5 s limit, 9.7 s of them in the batched SDP).  At least 1 ms (then it reports the time
        limit at its first check)."""
        opts = self.todo.get(m, self.rest_opts)
        limit = opts.budget.time_limit
        if limit is None or not self.seconds[m] > 0:
            return opts
        return opts.replace(time_limit=max(float(limit) - float(self.seconds[m]), 1e-3))

    # -------------------------------------------------------------------------------------------- the record
    def _report_columns(self, d: np.ndarray) -> None:
        M, N = self.M, self.N
        self.gamma_ub, self.gamma_ub_raw = np.full(M, np.nan), np.full(M, np.nan)
        self.residuals, self.depths = np.full((M, N), np.nan), np.full((M, N), np.nan)
        self.in_front = np.zeros(M, bool)
        if not d.size:
            return
        self.X[d] += self.origin[d]             # back to the caller's frame (0 where not moved)
        self.X_raw[d] += self.origin[d]
        g, res, dep = points_report_stack(self.C[d], self.x[d], self.X[d], self.opts.world_frame)
        self.gamma_ub[d], self.residuals[d], self.depths[d] = g, res, dep
        self.gamma_ub_raw[d] = points_report_stack(self.C[d], self.x[d], self.X_raw[d])[0]
        self.status[d], self.in_front[d] = cheirality(self.status[d], dep, self.opts.require_in_front)
        self.message[d] = np.where(self.in_front[d] | ~self.optimal[d], "", BEHIND_MESSAGE)
        self._no_contradiction(d)
        self._confirm_moved(d)

    def _no_contradiction(self, d: np.ndarray) -> None:
        """gamma_LB of rows ``d`` never above their gamma_UB on the caller's cameras; a row whose bound (of a
        re-centred frame, moved back) lies above it beyond the rule has none: ``numerical_failure`` (the point
        stage ``world_frame``'s rule, :func:`tritools.solve.decide.reported_lower`; review 46c L3)."""
        self.gamma_lb[d], contra = reported_lower(self.gamma_lb[d], self.gamma_ub[d], self.opts.tolerances, self.N,
                                                  self.scale[d])
        bad = d[contra]
        self.status[bad], self.optimal[bad], self.certified_by[bad] = Status.NUMERICAL_FAILURE.value, False, None
        self.message[bad] = TRANSFER_MESSAGE + " in the caller's frame"

    def _confirm_moved(self, d: np.ndarray) -> None:
        """The certificates of rows solved in a moved frame, confirmed on the caller's cameras at the moved-back
        estimate (:func:`tritools.solve.decide.decide_reported`: the rule of the point stage ``world_frame``)."""
        m = d[np.any(self.origin[d] != 0, axis=1) & self.optimal[d] & (self.certified_by[d] != TRIVIAL_BOUND)]
        if not m.size:
            return
        res = guard_resolutions(self.scale[m], self.x[m], view_floors(self.C[m], self.x[m]))
        ok = decide_reported(self.gamma_lb[m], self.gamma_ub[m], self.opts.tolerances, self.N, self.scale[m], res)
        lost = m[~ok]
        self.optimal[lost], self.certified_by[lost] = False, None
        self.status[lost] = Status.NOT_CERTIFIED.value
        self.message[lost] = "the bounds met in the re-centred frame, but not at the estimate in the caller's frame"

    def record(self, rows) -> TriangulationResults:
        """The :class:`~tritools.records.TriangulationResults` of rows ``rows`` closed by a batch stage."""
        r = np.asarray(rows, int).reshape(-1)
        k, solved = r.size, self.solved[r]
        return TriangulationResults(
            method=self.method[r], status=self.status[r], X=self.X[r], gamma_ub=self.gamma_ub[r],
            gamma_lb=self.gamma_lb[r], optimal=self.optimal[r], delta=self.delta[r],
            n_lmivar=np.where(solved, self.n_lmivar, -1), image_points=self.image_points[r], X_raw=self.X_raw[r],
            gamma_ub_raw=self.gamma_ub_raw[r], certified_by=self.certified_by[r], message=self.message[r],
            timings={"batch_share": self.seconds[r]}, attempts=[self.prefix[m] for m in r],
            sparsity=np.where(solved, "dense", None), in_front=self.in_front[r], n_views=np.full(k, self.N),
            depths=self.depths[r], residuals=self.residuals[r])

    def item(self, m: int):
        """(cameras, regions) of problem m for the per-point path."""
        return self.C[m], [Point(p) for p in self.x[m]]


# ---------------------------------------------------------------------------------------------------- stages
def plan_batch_stage(ctx: BatchContext) -> None:
    """The batched steps the options allow (:func:`tritools.solve.plan.batch_steps`)."""
    ctx.plan = BatchPlan(*batch_steps(ctx.opts))


def _run_impls(ctx: BatchContext, impls, chunk: int) -> None:
    """The first usable implementation over the open rows, chunk by chunk."""
    impl = next((i for i in impls if i.usable(ctx, None)), None)
    if impl is None:
        return
    rows = ctx.open_rows()
    for start in range(0, rows.size, chunk):
        ctx.timed(rows[start:start + chunk], impl.run, ctx)


def verify_batch_stage(ctx: BatchContext) -> None:
    """Certification by verification of the open rows (module docstring)."""
    _run_impls(ctx, BATCH_VERIFY_IMPLEMENTATIONS, verify_chunk_for(ctx.N))


def sdp_batch_stage(ctx: BatchContext) -> None:
    """The batched delta = 2 SDP of the open rows (module docstring)."""
    _run_impls(ctx, BATCH_SDP_IMPLEMENTATIONS, chunk_for(ctx.N))


def per_point_batch_stage(ctx: BatchContext) -> None:
    """The open rows through the per-point path, by the context's runner (module docstring); past the whole call's
    end (``total_time_limit``) their rows of last resort at once, vectorised (:func:`~tritools.solve.call_limit.
    expired_points`, what each item would get): 19,000 open rows of a COLMAP model under a 2 s limit were turned
    into per-point items and sent through the process pool one by one, 20 s past the end (review 29b F9)."""
    from ..call_limit import current_end, expired

    if ctx.per_point is None or not ctx.open.any():
        return
    if expired(current_end()):
        ctx.expire_open()
        return
    ctx.close_results(ctx.per_point(ctx.items()))


def report_batch_stage(ctx: BatchContext) -> None:
    """gamma_UB, residuals, depths and cheirality of the rows the batch stages solved (vectorised)."""
    ctx._report_columns(np.nonzero(ctx.solved)[0])


# ---------------------------------------------------------------------------------------------- implementations
def _verify_points(idx: np.ndarray, ctx: BatchContext) -> None:
    """``"verify-points"`` on rows ``idx``: certified rows closed, an attempt for each row."""
    ctx.rest_opts = ctx.opts.replace(path="sdp")         # verification was tried: the per-point path skips it
    try:
        b = verify_points(ctx.Cw[idx], ctx.x[idx], tolerances=ctx.opts.tolerances,
                          deadline=stack_deadline(ctx.opts, idx.size))
    except (ValueError, np.linalg.LinAlgError, FloatingPointError):
        b = None
    for k, m in enumerate(idx):
        ok = b is not None and bool(b.certified[k])
        ctx.prefix[m] += (Attempt("corollary1", 2, "verified" if ok else "verification_failed",
                                  float(b.gamma_lb[k]) if ok else None, None, AttemptStep.VERIFICATION.value,
                                  "dense"),)
    if b is None:
        return
    cert = b.certified
    ctx.store(idx[cert], b.X[cert], b.X[cert], b.gamma_lb[cert], b.image_points[cert], Status.OPTIMAL.value,
              True, np.where(b.trivial[cert], TRIVIAL_BOUND, "verification"), b.scale[cert])


def _sdp_points(idx: np.ndarray, ctx: BatchContext) -> None:
    """``"sdp-points"`` on rows ``idx``: decided rows closed (or continued at delta = 4), handed-back ones open."""
    try:
        b = solve_corollary1_points(ctx.Cw[idx], ctx.x[idx], tolerances=ctx.opts.tolerances, refine=ctx.opts.refine,
                                    deadline=stack_deadline(ctx.opts, idx.size))
    except (ValueError, np.linalg.LinAlgError, FloatingPointError):
        return
    final = last_delta(ctx.opts) <= 2
    for k in np.nonzero(b.done)[0]:
        m, opt = idx[k], bool(b.optimal[k])
        ctx.prefix[m] += (Attempt("corollary1", 2, str(b.status[k]), float(b.gamma_lb[k]), None,
                                  AttemptStep.SDP_BATCH.value, "dense", ("ipm-batch:converged",)),)
        if opt or final or bound_stop_reached(ctx.opts.lower_bound_stop, float(b.gamma_lb[k]), opt):
            ctx.store(np.array([m]), b.X[k:k + 1], b.X_raw[k:k + 1], b.gamma_lb[k:k + 1], b.image_points[k:k + 1],
                      str(b.status[k]), opt, b.certified_by[k] if opt else None, b.scale[k])
        else:                       # delta = 2 decided, not certified: the per-point path continues at 4
            ctx.todo[int(m)] = ctx.opts.replace(delta=4, path="sdp")


#: the implementations of the batch ``verify`` stage, the first usable one runs (fast ones need their name in
#: ``ctx.fast``); rows none certifies go on open.
BATCH_VERIFY_IMPLEMENTATIONS: tuple[Implementation, ...] = (
    Implementation(ImplName.VERIFY_POINTS, lambda ctx, _: ctx.plan.verify, _verify_points),
)
#: the implementations of the batch ``sdp`` stage.
BATCH_SDP_IMPLEMENTATIONS: tuple[Implementation, ...] = (
    Implementation(ImplName.SDP_POINTS, lambda ctx, _: ctx.plan.sdp, _sdp_points),
)
