"""Point-region problems as stacked arrays: the vectorised paths and ``triangulate_points``.

For M problems with point regions, grouped by their number of views N (cameras (M, N, 3, 4),
observed points (M, N, 2)), :class:`PointStack` runs the batch stages of
:data:`tritools.solve.stages.BATCH_STAGES` (:mod:`tritools.solve.stages.batch`) over each group, each stage
on the rows still open:

1. ``plan``: which batched steps the options allow (:func:`tritools.solve.plan.batch_steps`);
2. ``verify``, with ``path="auto"``: certification by verification (:func:`tritools.solve.fastpath.verify_points`);
3. ``sdp``, with ``path="sdp"`` (or for what verification did not certify, when the plan's first step is
   Corollary 1 at delta = 2): the batched degree-2 SDP (:func:`tritools.solve.sdp_batch.solve_corollary1_points`);
4. ``per_point``: everything else (later degrees of the plan, problems a batch handed back, other options)
   is solved one by one by :func:`tritools.triangulate` through the executor of :mod:`tritools.solve.batch`;
5. ``report``: gamma_UB, residuals, depths and cheirality of the rows the batch stages solved.

Results of the vectorised steps stay in arrays (``X``, ``gamma_lb``, ``gamma_ub``, ``status``,
``in_front`` ...) and go into the batch record :class:`~tritools.records.TriangulationResults` column by column
(:meth:`PointStack.record`); :class:`~tritools.result.TriangulationResult` rows are built only on access, so a
million points cost arrays, not objects.  ``triangulate_points(cameras, points2d, visible)`` is the arrays
API (``cv2.triangulatePoints``-like: one camera per view, a visibility mask).
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ..model.opencv import PointsLayout, points_array
from ..model.regions import real_array
from ..records import TriangulationResults
from .options import TriangulationOptions, options_from
from .stages import BATCH_STAGES, FAST_ALL, BatchContext
from .stages.batch import FAST_CHUNK, FAST_CHUNK_BYTES, chunk_for, verify_chunk_for  # noqa: F401 - re-exported

__all__ = ["PointStack", "PointsResult", "triangulate_points", "FAST_CHUNK"]


class PointStack(BatchContext):
    """M point problems of N views (see the module docstring): a :class:`~tritools.solve.stages.batch.BatchContext`
    running :data:`~tritools.solve.stages.BATCH_STAGES` (or ``stages``); after :meth:`run`, ``done`` marks the
    rows the batch stages closed and ``todo`` / ``prefix`` say how the open ones continue on the per-point path."""

    def __init__(self, cameras: np.ndarray, points2d: np.ndarray, opts: TriangulationOptions, *,
                 stages=BATCH_STAGES, fast=FAST_ALL, per_point=None):
        super().__init__(cameras, points2d, opts, stages=stages, fast=fast, per_point=per_point)


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
        Which views see which point (default: the finite entries of ``points2d``); a point seen in fewer than 2
        gets status ``invalid_input`` (the others are solved).
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
    if robust is not None:
        from .robust import robust_thresholds
        robust_thresholds(robust, C.shape[0])       # the argument is checked whether or not any point is solved
    few = vis.sum(axis=1) < 2
    if np.any(few):
        return _with_unseen(C, x, vis, few, robust, opts, executor, progress)
    views = [np.nonzero(row)[0] for row in vis]
    if robust is not None:
        return _robust_points(C, x, vis, views, robust, opts, executor, progress)
    outcome = solve_point_problems([(C[v], x[m, v]) for m, v in enumerate(views)], opts, executor=executor,
                                   progress=progress)
    return outcome.record().with_views(vis)


def _with_unseen(C, x, vis, few, robust, opts, executor, progress) -> TriangulationResults:
    """The points seen in fewer than two views (``few``) get status ``invalid_input`` naming them; the others their
    results, in input order (a batch never loses a point)."""
    from ..result import Status, TriangulationResult

    method = "tls" if robust is not None else opts.method.value
    idx_bad = np.nonzero(few)[0]
    bad = TriangulationResults.from_rows(
        [TriangulationResult(method, Status.INVALID_INPUT, message=f"ValueError: points2d[{m}] is visible in "
                                                                   "fewer than 2 views") for m in idx_bad.tolist()]
    ).with_views(vis[few])                          # width V, as the solved rows
    if few.all():
        return bad
    good = triangulate_points(C, x[~few], vis[~few], layout=PointsLayout.POINTS_VIEWS, options=opts,
                              executor=executor, progress=progress, robust=robust)
    order = np.argsort(np.concatenate([np.nonzero(~few)[0], idx_bad]), kind="stable")
    return TriangulationResults.concat([good, bad]).take(order)


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
