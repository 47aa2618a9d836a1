"""Point-region problems as stacked arrays: the vectorised paths and ``triangulate_points``.

For M problems with point regions, grouped by their number of views N (cameras (M, N, 3, 4),
observed points (M, N, 2)), :class:`PointStack` runs, with numpy over each group:

1. with ``path="auto"``: certification by verification (:func:`tritools.solve.fastpath.verify_points`);
2. with ``path="sdp"`` (or for what verification did not certify, when the plan's first step is
   Corollary 1 at delta = 2): the batched degree-2 SDP (:func:`tritools.solve.sdp_batch.solve_corollary1_points`);
3. everything else (later degrees of the plan, problems a batch handed back, other options) is solved
   one by one by :func:`tritools.triangulate` through the executor of :mod:`tritools.solve.batch`.

Results of the vectorised steps stay in arrays (``X``, ``gamma_lb``, ``gamma_ub``, ``status``,
``in_front`` ...) and go into the batch record :class:`~tritools.records.TriangulationResults` column by column
(:meth:`PointStack.record`); :class:`~tritools.result.TriangulationResult` rows are built only on access, so a
million points cost arrays, not objects.  ``triangulate_points(cameras, points2d, visible)`` is the arrays
API (``cv2.triangulatePoints``-like: one camera per view, a visibility mask).
"""
from __future__ import annotations

import time

import numpy as np
from numpy.typing import ArrayLike

from sospoly import n_lmivar_formula

from ..model.constraints import Method
from ..model.opencv import PointsLayout, points_array
from ..model.regions import Point, real_array
from ..records import TriangulationResults
from ..result import Attempt, Status
from .decide import cheirality
from .fastpath import BAND_MIN_VIEWS, BAND_WIDTHS, verify_points
from .options import TriangulationOptions, options_from
from .plan import batch_steps, last_delta as _last_delta  # noqa: F401 - the plan lives in plan.py
from .report import points_report_stack
from .sdp_batch import solve_corollary1_points
from .settings import stack_deadline
from .trivial import TRIVIAL_BOUND

__all__ = ["PointStack", "PointsResult", "triangulate_points", "FAST_CHUNK"]

#: the vectorised paths handle at most this many problems per numpy call ...
FAST_CHUNK = 4096
#: ... and use at most about this many bytes per call (the verification's arrays grow like N^3 per problem).
FAST_CHUNK_BYTES = 256 * 2 ** 20


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


class PointStack:
    """M point problems of N views (see the module docstring); ``todo`` lists the problems left for the
    per-point path, with the options and the attempts each continues from."""

    def __init__(self, cameras: np.ndarray, points2d: np.ndarray, opts: TriangulationOptions):
        self.C = np.asarray(cameras, float)
        self.x = np.asarray(points2d, float)
        self.opts = opts
        M, N = self.x.shape[:2]
        self.M, self.N = M, N
        self.X = np.full((M, 3), np.nan)
        self.X_raw = np.full((M, 3), np.nan)
        self.gamma_lb = np.full(M, np.nan)
        self.image_points = np.full((M, N, 2), np.nan)
        self.status = np.full(M, None, dtype=object)
        self.optimal = np.zeros(M, bool)
        self.certified_by = np.full(M, None, dtype=object)
        self.delta = np.full(M, -1)
        self.message = np.full(M, "", dtype=object)
        self.seconds = np.zeros(M)              # each problem's share of the vectorised calls it went through
        self.n_lmivar = n_lmivar_formula(2 * N, 2, [2] * (N * (N - 1) // 2))
        self.prefix: list = [() for _ in range(M)]
        self.done = np.zeros(M, bool)
        self.todo: dict[int, TriangulationOptions] = {}

    def run(self) -> PointStack:
        verify, sdp = batch_steps(self.opts)
        left = np.arange(self.M)
        step = verify_chunk_for(self.N) if verify else chunk_for(self.N)
        sdp_step = chunk_for(self.N)
        for start in range(0, self.M, step):
            part = left[start:start + step]
            if verify:
                part = self._timed(part, self._verify)
            if sdp and part.size:
                part = np.concatenate([self._timed(part[k:k + sdp_step], self._sdp)
                                       for k in range(0, part.size, sdp_step)]).astype(int)
            for m in part:
                self.todo.setdefault(int(m), self.opts.replace(path="sdp") if verify else self.opts)
        self._report()
        return self

    def _timed(self, idx: np.ndarray, step, *args):
        t0 = time.perf_counter()
        out = step(idx, *args)
        if idx.size:
            self.seconds[idx] += (time.perf_counter() - t0) / idx.size
        return out

    def _verify(self, idx: np.ndarray) -> np.ndarray:
        try:
            b = verify_points(self.C[idx], self.x[idx], tolerances=self.opts.tolerances,
                              deadline=stack_deadline(self.opts, idx.size))
        except (ValueError, np.linalg.LinAlgError, FloatingPointError):
            b = None
        for k, m in enumerate(idx):
            ok = b is not None and bool(b.certified[k])
            self.prefix[m] += (Attempt("corollary1", 2, "verified" if ok else "verification_failed",
                                       float(b.gamma_lb[k]) if ok else None, None, "verification", "dense"),)
        if b is None:
            return idx
        cert = b.certified
        self._store(idx[cert], b.X[cert], b.X[cert], b.gamma_lb[cert], b.image_points[cert], Status.OPTIMAL.value,
                    True, np.where(b.trivial[cert], TRIVIAL_BOUND, "verification"))
        return idx[~cert]

    def _sdp(self, idx: np.ndarray) -> np.ndarray:
        try:
            b = solve_corollary1_points(self.C[idx], self.x[idx], tolerances=self.opts.tolerances,
                                        refine=self.opts.refine, deadline=stack_deadline(self.opts, idx.size))
        except (ValueError, np.linalg.LinAlgError, FloatingPointError):
            return idx
        final = _last_delta(self.opts) <= 2
        rest = []
        for k, m in enumerate(idx):
            if not b.done[k]:
                rest.append(m)
                continue
            opt = bool(b.optimal[k])
            self.prefix[m] += (Attempt("corollary1", 2, str(b.status[k]), float(b.gamma_lb[k]), None, "sdp-batch",
                                       "dense", ("ipm-batch:converged",)),)
            if opt or final:
                self._store(np.array([m]), b.X[k:k + 1], b.X_raw[k:k + 1], b.gamma_lb[k:k + 1],
                            b.image_points[k:k + 1], str(b.status[k]), opt, b.certified_by[k] if opt else None)
            else:                       # delta = 2 decided, not certified: the per-point path continues at 4
                self.todo[int(m)] = self.opts.replace(delta=4, path="sdp")
        return np.array(rest, dtype=int)

    def _store(self, idx, X, X_raw, gamma_lb, image_points, status, optimal, certified_by) -> None:
        self.X[idx], self.X_raw[idx], self.gamma_lb[idx], self.image_points[idx] = X, X_raw, gamma_lb, image_points
        self.status[idx], self.optimal[idx], self.certified_by[idx] = status, optimal, certified_by
        self.delta[idx] = 2
        self.done[idx] = True

    def _report(self) -> None:
        """gamma_UB, residuals, depths, cheirality of the batch-decided problems (vectorised)."""
        d = np.nonzero(self.done)[0]
        self.gamma_ub = np.full(self.M, np.nan)
        self.gamma_ub_raw = np.full(self.M, np.nan)
        self.residuals = np.full((self.M, self.N), np.nan)
        self.depths = np.full((self.M, self.N), np.nan)
        self.in_front = np.zeros(self.M, bool)
        if not d.size:
            return
        g, res, dep = points_report_stack(self.C[d], self.x[d], self.X[d], self.opts.world_frame)
        self.gamma_ub[d], self.residuals[d], self.depths[d] = g, res, dep
        self.gamma_ub_raw[d] = points_report_stack(self.C[d], self.x[d], self.X_raw[d])[0]
        self.status[d], self.in_front[d] = cheirality(self.status[d], dep, self.opts.require_in_front)
        self.message[d] = np.where(self.in_front[d] | ~self.optimal[d], "", "certified L2 optimum, but behind a camera")
        self.gamma_lb[d] = np.minimum(self.gamma_lb[d], self.gamma_ub[d])

    def record(self, rows) -> TriangulationResults:
        """The :class:`~tritools.records.TriangulationResults` of batch-decided problems ``rows`` (vectorised)."""
        r = np.asarray(rows, int).reshape(-1)
        k = r.size
        return TriangulationResults(
            method=[Method.COROLLARY1.value] * k, status=self.status[r], X=self.X[r], gamma_ub=self.gamma_ub[r],
            gamma_lb=self.gamma_lb[r], optimal=self.optimal[r], delta=np.full(k, 2), n_lmivar=np.full(k, self.n_lmivar),
            image_points=self.image_points[r], X_raw=self.X_raw[r], gamma_ub_raw=self.gamma_ub_raw[r],
            certified_by=self.certified_by[r], message=self.message[r], timings={"batch_share": self.seconds[r]},
            attempts=[self.prefix[m] for m in r], sparsity=["dense"] * k, in_front=self.in_front[r],
            n_views=np.full(k, self.N), depths=self.depths[r], residuals=self.residuals[r])

    def item(self, m: int):
        """(cameras, regions) of problem m for the per-point path."""
        return self.C[m], [Point(p) for p in self.x[m]]


#: the arrays of :func:`triangulate_points`: the one batch record (``X``, ``gamma_lb``, ``gamma_ub``, ``status``,
#: ``optimal``, ``in_front``, ``n_views``, ``delta``, ``certified_by``, ``message``, ``inliers`` ... as columns;
#: ``results()`` / ``[m]`` give :class:`TriangulationResult` rows).
PointsResult = TriangulationResults


def triangulate_points(cameras: ArrayLike, points2d: ArrayLike, visible: ArrayLike | None = None, *,
                       layout: PointsLayout | str = PointsLayout.AUTO, options: TriangulationOptions | None = None,
                       executor: object | None = None, progress: bool | str | None = None,
                       robust: ArrayLike | None = None,
                       **overrides) -> TriangulationResults:
    """Certified triangulation of M points observed in V views, as arrays (like ``cv2.triangulatePoints``).

    Parameters
    ----------
    cameras : array (V, 3, 4)
        One projection matrix per view, shared by all points (:func:`tritools.cameras_from_krt` builds
        them from OpenCV's K, R / rvec, t).
    points2d : array (M, V, 2), or OpenCV's (V, 2, M) / (V, M, 2) / (V, M, 1, 2), or a list of V per-view arrays
        Observed image points (any real dtype, float32 included); entries of views that do not see a point
        are ignored (NaN marks them by default).
    visible : bool array (M, V), optional
        Which views see which point (default: the finite entries of ``points2d``); each point needs >= 2.
    layout : "auto" (default), "points_views", "views_xy_points" or "views_points"
        Axis order of ``points2d`` (:mod:`tritools.model.opencv`); "auto" refuses a shape that fits several
        layouts (two views and two points: (2, 2, 2)) with a ValueError asking for ``layout=``.
    options, overrides : :class:`~tritools.solve.options.TriangulationOptions` and its fields
    executor, progress : as :func:`tritools.triangulate_many`
    robust : None, or TLS thresholds in pixels (a scalar or one per view V): certified truncated least squares
        (:mod:`tritools.solve.robust_batch`); the result then has ``inliers`` (M, V) (False where not visible)
    """
    from .batch import solve_point_problems

    opts = options_from(options, **overrides)
    C = real_array(cameras, "cameras")          # complex, object, string and boolean arrays refused by name
    if C.ndim != 3 or C.shape[1:] != (3, 4):
        raise ValueError(f"cameras must have shape (V, 3, 4), got {C.shape}")
    x = points_array(points2d, C.shape[0], layout, "points2d")
    vis = np.all(np.isfinite(x), axis=2) if visible is None else _visible_mask(visible, x)
    if np.any(vis.sum(axis=1) < 2):
        bad = int(np.argmax(vis.sum(axis=1) < 2))
        raise ValueError(f"points2d[{bad}] is visible in fewer than 2 views")
    views = [np.nonzero(row)[0] for row in vis]
    if robust is not None:
        return _robust_points(C, x, vis, views, robust, opts, executor, progress)
    outcome = solve_point_problems([(C[v], x[m, v]) for m, v in enumerate(views)], opts, executor=executor,
                                   progress=progress)
    return outcome.record().with_views(vis)


def _visible_mask(visible, x: np.ndarray) -> np.ndarray:
    """``visible`` as a bool (M, V) mask: booleans or 0/1 numbers, and every visible entry of ``x`` finite
    (ValueError naming ``visible`` / ``points2d[m, v]``)."""
    raw = np.asarray(visible)
    if raw.shape != x.shape[:2]:
        raise ValueError(f"visible must have shape {x.shape[:2]}, got {raw.shape}")
    if raw.dtype.kind not in "biu" and not (raw.dtype.kind == "f" and np.all((raw == 0) | (raw == 1))):
        raise ValueError(f"visible must be booleans (or 0/1), got dtype {raw.dtype}")
    vis = raw.astype(bool)
    bad = vis & ~np.all(np.isfinite(x), axis=2)
    if np.any(bad):
        m, v = (int(i) for i in np.argwhere(bad)[0])
        raise ValueError(f"points2d[{m}, {v}] is not finite but visible[{m}, {v}] is True")
    return vis


def _robust_points(C, x, vis, views, robust, opts, executor, progress) -> TriangulationResults:
    """``triangulate_points(..., robust=c)``: per-point TLS results (:func:`tritools.solve.robust_batch.robust_many`),
    thresholds taken per view of the shared cameras; ``inliers`` (M, V) False where not visible."""
    from .robust import robust_thresholds
    from .robust_batch import robust_many

    c = robust_thresholds(robust, C.shape[0])
    problems = [(C[v], x[m, v]) for m, v in enumerate(views)]
    results = robust_many(problems, [c[v] for v in views], opts, executor=executor, progress=progress)
    return TriangulationResults.from_rows(results).with_views(vis)
