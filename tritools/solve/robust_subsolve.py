"""One L2 sub-problem of the robust search through :func:`tritools.triangulate` (:meth:`tritools.solve.
robust_bounds.SubsetBounds._solve_one`): its options, the stop at the level the search needs, and the order of the
degree plan for three views.

* ``light``: the degree-2 steps only (``max_delta = 2``: a sub-problem with outliers needs a large bound, not a
  tight one);
* ``from_delta``: the plan starts at that degree (the verification and delta = 2 steps skipped: a weak subset's
  delta = 2 bound is known already);
* ``need`` (pixels^2, finite): the search's node needs L2*(S) >= need; the plan stops once its rigorous bound
  reaches it (the options' ``lower_bound_stop`` at :func:`stop_level`, like a MIP solver's best-bound stop).  Such
  a result is not certified and the plan did not run out: the subset stays weak (a later, larger need solves it
  again) and is never exhausted (:attr:`SubSolve.stopped`).  A caller's own ``lower_bound_stop`` (a level of the
  whole problem) is not passed on;
* one camera given |S| times with point regions (exact multiples, :func:`~tritools.model.exact.one_exact_camera`):
  L2*(S) is the observations' spread about their mean (:func:`_one_camera`), with no solve (``triangulate``
  refuses such cameras);
* three views from ``from_delta``, point regions, ``method="auto"``, no ``max_delta`` below 4: Theorem 1 at delta = 4
  first (:data:`THEOREM1_FIRST`).  Three camera centres are always coplanar, so Corollary 1's epipolar constraints
  admit image points on the centres' plane lines and its delta = 4 bound often stops below L2* (the plan then ends
  with the exact-variety step, Theorem 1 at delta = 4, anyway: :mod:`tritools.solve.stages.exact`).  Measured on the
  full-plan sub-problems of 300 robust calls (N = 3-5, 20-40% wrong matches, 5 px): Theorem 1 at delta = 4 alone
  certified all 16 with the same bounds at 0.61x the CPU time of Corollary 1 delta = 4 -> Theorem 1 delta = 4. Where
  it neither certifies nor reaches ``need`` nor runs out of time, the ordinary plan from ``from_delta`` runs too,
  within what is left of the limit, and the larger bound is kept (its status decides exhaustion, as before).
"""
from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass

import numpy as np

from ..model.exact import one_exact_camera
from ..result import Status
from .options import MethodChoice
from .robust_rays import view_ray

__all__ = ["SubSolve", "solve_subproblem", "subsolve_of", "stop_level", "THEOREM1_FIRST", "BOUND_STOP", "ROUND_DOWN",
           "TRUSTED_LOWER_BOUND", "EXHAUSTED"]

#: f = 2 |S| gamma^2 is computed with a few roundings (and gamma came through a square root): multiplying by
#: this factor keeps the product a lower bound by a wide margin (relative error ~1e-15 at most).
ROUND_DOWN = 1.0 - 1e-12
#: statuses whose gamma_lb is a valid lower bound (a numerical failure's is not trusted; failures have none)
TRUSTED_LOWER_BOUND = frozenset({Status.OPTIMAL, Status.BEHIND_CAMERA, Status.NOT_CERTIFIED, Status.TIME_LIMIT,
                                 Status.BUDGET_EXCEEDED})
#: statuses of a full-plan sub-problem whose bound no later solve raises (``SubsetBounds.exhausted``): the plan ran
#: out of degrees or its solver failed at the top one, not a time or memory limit
EXHAUSTED = frozenset({Status.NOT_CERTIFIED, Status.SOLVER_FAILED, Status.NUMERICAL_FAILURE})
#: a full-plan solve stops at the level its caller needs (module docstring; False: the whole plan, as the tests
#: compare)
BOUND_STOP = True
#: three-view sub-problems solved from a degree > 2 start with Theorem 1 at delta = 4 (module docstring; False:
#: the ordinary plan, as the tests compare)
THEOREM1_FIRST = True


@dataclass(frozen=True)
class SubSolve:
    """The outcome of one sub-problem: ``lb`` the rigorous bound of L2*(S) (pixels^2, rounded down; 0 without
    one), ``X`` the estimate (or None), ``certified``, ``stopped`` (at ``need``, not certified), ``exhausted`` (the
    full plan ran out: no later solve raises the bound), ``budget_exceeded``, ``light`` (only the degree-2 steps
    ran: the caller's options may refuse them, review 10b), ``timed_out`` (stopped by its time limit)."""
    lb: float
    X: np.ndarray | None
    certified: bool
    stopped: bool = False
    exhausted: bool = False
    budget_exceeded: bool = False
    light: bool = False
    timed_out: bool = False


def stop_level(need: float, n_views: int) -> float | None:
    """The ``lower_bound_stop`` (gamma, pixels) of a sub-problem of ``n_views`` views whose L2 bound must reach
    ``need`` (pixels^2): gamma_lb >= sqrt(need / (2 |S| ROUND_DOWN)) gives the stored bound 2 |S| gamma_lb^2
    ROUND_DOWN >= need (the level raised by 1e-12 relative for the square root's rounding); None for no finite
    positive need."""
    if not (math.isfinite(need) and need > 0):
        return None
    return math.sqrt(need / (2 * n_views * ROUND_DOWN)) * (1.0 + 1e-12)


def solve_subproblem(cameras, regions, opts, *, light: bool, from_delta: int | None, limit: float, need: float,
                     points: bool) -> SubSolve | None:
    """The sub-problem (cameras and regions of S) under the caller's options (module docstring); ``limit``
    seconds (inf: the options' budget); None when the input is refused (e.g. coincident cameras: 0 is a valid
    bound then)."""
    if points and len(cameras) >= 2 and one_exact_camera(cameras):
        return _one_camera(cameras, regions)
    opts = opts.replace(time_limit=max(1e-3, limit)) if math.isfinite(limit) else opts
    if light:
        try:
            opts = opts.replace(max_delta=2)
        except ValueError:
            light = False
    elif from_delta is not None:
        try:
            opts = opts.replace(delta=max(from_delta, opts.delta or 0))     # never below the caller's
        except ValueError:
            pass
    stop = None if light or not BOUND_STOP else stop_level(need, len(cameras))
    if stop is not None or opts.lower_bound_stop is not None:      # the sub-problem's own level, or none
        opts = dataclasses.replace(opts, lower_bound_stop=stop)
    first, t0 = None, time.monotonic()
    if THEOREM1_FIRST and not light and from_delta is not None and len(cameras) == 3 and points \
            and opts.method == MethodChoice.AUTO and (opts.max_delta is None or opts.max_delta >= 4):
        first = _run(cameras, regions, _theorem1(opts), light, stop, need)
        if first is not None and (first.certified or first.lb >= need or first.timed_out):
            return first                        # certified, at the level, or out of time: no second solve
        if math.isfinite(limit):                # the ordinary plan gets what is left of the limit
            opts = opts.replace(time_limit=max(1e-3, limit - (time.monotonic() - t0)))
    plan = _run(cameras, regions, opts, light, stop, need)
    return _larger(first, plan)


def _one_camera(cameras, regions) -> SubSolve:
    """The sub-problem of one camera given |S| times with point regions x_i
    (:func:`~tritools.model.exact.one_exact_camera`): every view
    projects X to the same point u, so sum_i |u - x_i|^2 >= sum_i |x_bar - x_i|^2 = sum_{i<j} |x_i - x_j|^2 / |S|,
    attained on the ray of x_bar: L2*(S) exactly, from the differences' squares (each within a few roundings of its
    exact value) summed exactly (``math.fsum``), divided and rounded down by ``ROUND_DOWN``; certified.  Not 0 where
    the observations differ, so a track that lists one image twice with two keypoints is certified (review 22a F3: the
    sub-problem was refused, its bound 0).  The estimate is a point of that ray in front of the camera
    (:func:`_ray_point`; S does not determine its depth, the search's exact f_TLS ranks it among the others)."""
    x = np.array([r.center for r in regions], float)
    n = len(x)
    with np.errstate(over="ignore", invalid="ignore"):
        terms = [(x[i + 1:] - x[i]) ** 2 for i in range(n - 1)]
    lb = math.fsum(float(v) for t in terms for v in t.ravel()) / n * ROUND_DOWN    # (a few roundings of 1e-16)
    return SubSolve(lb if math.isfinite(lb) else 0.0, _ray_point(np.asarray(cameras[0], float), x.mean(axis=0)),
                    math.isfinite(lb))


def _ray_point(P: np.ndarray, u: np.ndarray):
    """The point C + |C| d of the ray of image point u (:func:`~tritools.solve.robust_rays.view_ray`: C the centre, d
    the unit direction toward positive depth; |C| its distance from the frame's origin, which the search puts among
    the cameras in a moved world, else 1), or None where the camera gives no ray."""
    ray = view_ray(P, u)
    if ray is None:
        return None
    r = float(np.linalg.norm(ray[0]))
    return ray[0] + (r if 0 < r < math.inf else 1.0) * ray[1]


def _theorem1(opts):
    """Theorem 1 at delta = 4 alone (the caller's higher degree kept); the options unchanged where refused."""
    try:
        d = max(4, opts.delta or 0)
        return opts.replace(method=MethodChoice.THEOREM1.value, delta=d, max_delta=max(d, opts.max_delta or 0))
    except ValueError:
        return opts


def _run(cameras, regions, opts, light: bool, stop, need: float) -> SubSolve | None:
    from .triangulate import triangulate

    try:
        res = triangulate(cameras, regions, options=opts)
    except (ValueError, TypeError, ArithmeticError, np.linalg.LinAlgError):
        return None
    return subsolve_of(res, len(cameras), light, stop, need)


def subsolve_of(res, n_views: int, light: bool, stop=None, need: float = math.inf) -> SubSolve:
    """The :class:`SubSolve` of an L2 result ``res`` of ``n_views`` views solved ``light`` (or the full plan) with
    the level ``stop`` for ``need`` (None, inf: none)."""
    lb = 0.0
    if res.status in TRUSTED_LOWER_BOUND and res.gamma_lb is not None and math.isfinite(res.gamma_lb):
        lb = 2 * n_views * max(res.gamma_lb, 0.0) ** 2 * ROUND_DOWN
    certified = bool(res.status.certified)
    stopped = stop is not None and not certified and lb >= need
    X = np.asarray(res.X, float) if res.X is not None and np.all(np.isfinite(res.X)) else None
    return SubSolve(lb, X, certified, stopped, not light and not stopped and res.status in EXHAUSTED,
                    res.status == Status.BUDGET_EXCEEDED, light, res.status == Status.TIME_LIMIT)


def _larger(first: SubSolve | None, plan: SubSolve | None) -> SubSolve | None:
    """The ordinary plan's outcome with the larger of the two bounds (its estimate, else the first's)."""
    if first is None or plan is None:
        return plan if first is None else first
    return SubSolve(max(first.lb, plan.lb), plan.X if plan.X is not None else first.X, plan.certified,
                    plan.stopped, plan.exhausted, first.budget_exceeded or plan.budget_exceeded, plan.light,
                    plan.timed_out)
