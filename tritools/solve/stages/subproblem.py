"""The stage ``sub_problem``: certification through a simpler problem whose optimum bounds the whole one's.

Three kinds, tried in this order at the local estimate:

* **tiny regions collapsed to their centres** (review 39a F1: a square of half-side 1e-20 px was ``solver_failed``
  with no bound): with c_i the centre of R_i and rho_i >= max_{y in R_i} ||y - c_i|| (:func:`centre_radius`),
  d(x, R_i) >= ||x - c_i|| - rho_i, so by the triangle inequality in R^N,
  gamma*_R >= gamma*_C - ||rho|| / sqrt(2N) (:func:`collapsed_lower_bound`), C the problem with points c_i: a point
  problem, certified in milliseconds (where other regions remain, a problem of those regions solved by its own
  degree plan).  Tried where every collapsed rho_i is at most :data:`COLLAPSE_SHARE` of the local estimate's gamma;
* **long segments, thin polytopes and thin filled ellipses trimmed** (:mod:`tritools.solve.trim`): an exact
  reduction -- the problem with each such region cut to the part that can hold the closest point of the optimum's
  projection has the same optimum -- solved by its own degree plan (``Relaxation.plan``); where that plan ran to its
  end the whole problem's is not repeated;
* **views whose regions hold the estimate dropped** (below); then (where they are not the same views) those whose
  regions reach farther than :data:`WIDE_SHARE` times the local estimate's gamma from their centre (a 1e4 px
  segment; a 1e8 px box that a poor local estimate misses): certified where they hold the sub-problem's minimiser,
  else a lower bound.

For a set W of views, f_V(X) = sum_{i in V} d_i(X)^2 >= f_{V-W}(X) for every X (d_w >= 0), so the L2 optimum of the
sub-problem bounds the whole problem's from below: with gamma = sqrt(f / 2N) (the paper's (6)),

    gamma*_V >= gamma*_{V-W} sqrt(|V - W| / N),

a valid lower bound for any W whatever the sub-problem's minimiser X'.  Where X' projects into every region of W
(d_w(X') = 0, computed exactly 0: the region's closest point is the projection itself) the bound is attained,
gamma_V(X') = gamma*_{V-W} sqrt(|V - W| / N), the whole problem's gap is the sub-problem's (certified under its own
rule), and the whole problem is certified at X' -- only then: a gap that merely passes the whole problem's rule
with X' outside a dropped region (0.08 px outside a polygon, coordinates of 6e6 px: review 40a HIGH-1) is not.
This is the case of a region much larger than the residuals (a keypoint with a 1e4 px
uncertainty, a wide polytope): the optimum of the other views projects inside it, the view drops out, and the
sub-problem -- fewer views, no auxiliary variables for that region -- is the easy one.  The degree plan of the
whole problem meanwhile works on a program scaled by the large region and stops uncertified (review 39a F3:
ellipses / polytopes of 1e4-1e10 px, lower bound 0 after 3-4 s).

The stage runs after ``verify`` / ``trivial`` (``method="auto"``, at least three views) when the local estimate
projects into some region other than a point (W: those views, at least two views left).  The sub-problem runs the
point stages at delta = 2 within the time left (``max_delta=2``, ``path="auto"``: the per-point rows of a batch
come with ``path="sdp"`` only because the whole problem's verification was tried): its verification and delta = 2
SDP where the kept views are points, its verification only otherwise (:func:`sub_stages`); never this stage again
(no recursion) nor the degree-4 exact-variety step.

Its gamma_LB -- a bound of the sub-problem's data, already lowered for the round-off of its own normalisation --
scaled as above and rounded down is the whole problem's lower bound at X'.  It is not lowered again for the whole
problem's normalisation, whose resolution the large regions coarsen (a 5e4 px disc cost 1e-4 of the bound).  The
report at X' (:func:`~tritools.solve.stages.outcome.report_point`: gamma_UB on all N views, the decision on the
reported numbers with the whole problem's normalisation, cheirality) decides.  A certificate finishes the point;
otherwise the result joins the plan's steps as a candidate (the larger lower bound is kept, :func:`.outcome.better`).
"""
from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import numpy as np

from ...model.geometry import gamma_validated, project
from ...model.regions import Point
from ...model.regions.forms import extent_of
from ...result import Attempt, Status
from ..options import SolvePath
from ..decide import c_from_gamma, decide
from ..robust_subsolve import ROUND_DOWN, TRUSTED_LOWER_BOUND
from ..trim import ellipse_axis, polytope_axis, segment_of, trimmed_regions
from .context import AttemptStep, PointContext
from .outcome import better, join, replace, report_point, step_of

__all__ = ["sub_problem_stage", "held_views", "sub_lower_bound", "sub_stages", "centre_radius", "collapsed_lower_bound",
           "Relaxation", "relaxations", "SUB_PROBLEM", "COLLAPSE_SHARE", "WIDE_SHARE"]

#: ``certified_by`` of a certificate through the sub-problem
SUB_PROBLEM = "sub_problem"
#: regions whose points all lie within this share of the local estimate's gamma of their centre are collapsed to
#: the centre (:func:`relaxations`): the bound then loses at most that share of gamma over sqrt(2), ~1e-8 of the
#: certificate rule's relative gap in c (a 2e-9 px box at gamma = 0.29 px was not collapsed at 1e-9: review 47a F4)
COLLAPSE_SHARE = 1e-8
#: regions reaching farther than this multiple of the local estimate's gamma from their centre are "wide": where no
#: region holds the estimate, the sub-problem without the wide ones still gives a lower bound (:func:`relaxations`;
#: a 1e4 px segment's plan ended with lower bound 0, review 39a F3)
WIDE_SHARE = 1e3
#: an exact reduction's plan that ended uncertified with gamma_LB at least this share of gamma_UB ends the point (the
#: whole problem's plan is not repeated; :func:`_try`)
PLAN_NEAR = 0.99
#: a sub-problem starts only with this multiple of the whole problem's verification and local-estimate time left,
#: and at least SUB_MIN_SECONDS (:func:`_time_for_it`)
SUB_TIME_FACTOR = 2.0
SUB_MIN_SECONDS = 0.02


def held_views(cams: np.ndarray, regions, X) -> list[int]:
    """The views other than points whose region holds the projection of the world point ``X`` (distance exactly
    0: the region's own closest point is the projection)."""
    out = []
    for i, (P, r) in enumerate(zip(cams, regions)):
        if r.is_point:
            continue
        with np.errstate(all="ignore"):
            p = project(X, P)
        if np.all(np.isfinite(p)) and float(r.distance(p)) == 0.0:
            out.append(i)
    return out


def sub_lower_bound(gamma_lb: float, n_sub: int, n_views: int) -> float:
    """gamma*_V >= gamma*_{V-W} sqrt(|V - W| / N) (module docstring), rounded down."""
    return max(0.0, float(gamma_lb) * math.sqrt(n_sub / n_views) * ROUND_DOWN)


def centre_radius(region) -> float:
    """An upper bound of max_{y in R} ||y - c|| for the region's centre c: the extent of the region shifted to c,
    plus 64 units of round-off of |c| (the shift's rounding; the rule of :data:`~tritools.solve.decide.
    LB_ROUNDOFF_ULPS`)."""
    c = np.asarray(region.center, float)
    rho = float(extent_of(region.similarity(1.0, c)).radius)
    return rho * (1.0 + 1e-12) + 64.0 * 2.0 ** -53 * float(np.max(np.abs(c)))


def collapsed_lower_bound(gamma_lb: float, radii, n_views: int) -> float:
    """gamma*_R >= gamma*_C - ||rho|| / sqrt(2N) (module docstring: regions R_i replaced by their centres c_i,
    rho_i >= max_{y in R_i} ||y - c_i||), rounded down; 0 at least."""
    slack = math.sqrt(math.fsum(r * r for r in radii) / (2 * n_views)) * (1.0 + 1e-12)
    return max(0.0, (float(gamma_lb) - slack) * ROUND_DOWN)


@dataclass(frozen=True)
class Relaxation:
    """A simpler problem whose optimum bounds the whole one's: the views ``keep`` with ``regions``; ``bound`` maps
    its gamma_LB to one of the whole problem; ``what`` names it in the messages."""
    keep: tuple
    regions: tuple
    bound: Callable
    what: str
    dropped: tuple = ()
    #: solved by its own degree plan (:func:`_solve`), not at delta = 2 only
    plan: bool = False
    #: an exact reduction (its optimum is the whole problem's): a plan of it that ends near its estimate ends the
    #: point (:func:`_try`); a relaxation that only bounds the optimum leaves the others to be tried
    exact: bool = False


def relaxations(ctx: PointContext, X) -> list[Relaxation]:
    """The relaxations tried at the local estimate ``X`` (world frame), in order: regions far smaller than the
    residuals collapsed to their centres (a point problem), then the views whose regions hold X's projection
    dropped (module docstring)."""
    out = []
    gamma_px = float(ctx.local()[0]) / ctx.norm.scale
    tiny, wide = [], []
    for i, r in enumerate(ctx.regions):
        if not r.is_point:
            try:
                rho = centre_radius(r)
            except (TypeError, ValueError):         # no extent, or a shift the region refuses
                continue
            if rho <= COLLAPSE_SHARE * gamma_px:
                tiny.append((i, rho))
            elif rho > WIDE_SHARE * gamma_px:
                wide.append(i)
    if tiny:
        idx = dict(tiny)
        regs = tuple(Point(r.center) if i in idx else r for i, r in enumerate(ctx.regions))
        views = ", ".join(map(str, idx))
        # where other regions remain the collapsed problem runs its own degree plan: the whole problem's works on
        # rows scaled by the tiny region and fails numerically (review 47a F4: a 1e-20 px box beside an ellipse and
        # a segment ended solver_failed with no bound, its collapsed problem's verification alone did not certify)
        out.append(Relaxation(tuple(range(ctx.N)), regs,
                              partial(collapsed_lower_bound, radii=tuple(idx.values()), n_views=ctx.N),
                              f"the problem with the region(s) of view(s) {views} collapsed to their centres",
                              plan=not all(r.is_point for r in regs)))
    trimmed = _trimmed(ctx, X)
    if trimmed is not None:
        views = ", ".join(str(i) for i, (a, b) in enumerate(zip(trimmed, ctx.regions)) if a is not b)
        out.append(Relaxation(tuple(range(ctx.N)), trimmed, _same,
                              f"the problem with the long region(s) of view(s) {views} trimmed", plan=True,
                              exact=True))
    held = held_views(ctx.cams, ctx.regions, X)
    # then the wide regions (a poor local estimate -- the whole problem's frame scaled by them -- may sit outside
    # some): a certificate where they hold the sub-problem's minimiser, a lower bound at least (d_w >= 0)
    wide = wide if set(wide) != set(held) else []
    for W, what in ((held, "the sub-problem without view(s) {}"),
                    (wide, "the sub-problem without the wide region(s) of view(s) {}")):
        keep = tuple(i for i in range(ctx.N) if i not in set(W))
        if W and len(keep) >= 2:
            out.append(Relaxation(keep, tuple(ctx.regions[i] for i in keep),
                                  partial(sub_lower_bound, n_sub=len(keep), n_views=ctx.N),
                                  what.format(", ".join(map(str, W))), tuple(W)))
    return out


def _same(gamma_lb: float) -> float:
    """The bound of an exact reduction: its own (:mod:`tritools.solve.trim`)."""
    return float(gamma_lb)


def _trimmed(ctx: PointContext, X) -> tuple | None:
    """The regions with the long segments, thin polytopes and thin ellipses trimmed
    (:func:`tritools.solve.trim.trimmed_regions`) at the local
    estimate X, f_UB = 2N gamma(X)^2 on the whole problem; None where none is."""
    if all(segment_of(r)[0] is None and polytope_axis(r) is None and ellipse_axis(r) is None
           for r in ctx.regions if not r.is_point):
        return None
    with np.errstate(all="ignore"):
        g = float(gamma_validated(np.asarray(X, float)[None], ctx.cams, ctx.regions)[0])
    radii = []
    for r in ctx.regions:
        try:
            radii.append(centre_radius(r))
        except (TypeError, ValueError):
            radii.append(math.inf)
    return trimmed_regions(ctx.cams, ctx.regions, X, 2 * ctx.N * g * g, radii) if math.isfinite(g) else None


def _applies(ctx: PointContext) -> bool:
    opts = ctx.opts
    return ctx.N >= 3 and not (ctx.finished or ctx.expired) and opts.explicit_method is None \
        and not all(r.is_point for r in ctx.regions) and _time_for_it(ctx)


def _time_for_it(ctx: PointContext) -> bool:
    """Whether a sub-problem fits in the time left: its local estimate and verification cost about the whole
    problem's (review 40a LOW-2: started with 0.03 s left, it took 0.08-0.15 s past a 0.05 s limit), so at least
    :data:`SUB_TIME_FACTOR` times theirs and :data:`SUB_MIN_SECONDS` must be left, and not after a verification
    the time limit cut."""
    left = ctx.settings.deadline.remaining()
    if left is None:
        return True
    spent = ctx.timings.get("verify", 0.0) + ctx.timings.get("local", 0.0)
    cut = ctx.verify_cut or any(a.step == AttemptStep.VERIFICATION and a.status == Status.TIME_LIMIT.value
                                for a in ctx.attempts)
    return not cut and left >= SUB_TIME_FACTOR * spent + SUB_MIN_SECONDS


def sub_problem_stage(ctx: PointContext) -> None:
    """Certification through a simpler problem (module docstring): each of :func:`relaxations` in turn until one
    certifies."""
    if not _applies(ctx) or ctx.local() is None:
        return
    try:
        for relax in relaxations(ctx, ctx.norm.world_point(ctx.local()[1])):
            if ctx.finished or ctx.expired:
                return
            _try(ctx, relax)
    except (ValueError, TypeError, ArithmeticError, np.linalg.LinAlgError):    # a shortcut that fails is no answer:
        return                                                                   # the plan decides


def _try(ctx: PointContext, relax: Relaxation) -> None:
    """One relaxation: solved, its bound carried to the whole problem, the report at its minimiser decides."""
    t = time.perf_counter()
    sub = _solve(ctx, relax)
    ctx.tick("sub_problem", t)
    if sub is None or sub.X is None or sub.gamma_lb is None or sub.status not in TRUSTED_LOWER_BOUND:
        why = "failed" if sub is None else sub.status.value if sub.gamma_lb is not None else "no_bound"
        ctx.attempts.append(Attempt("auto", None, why, None, None, AttemptStep.SUB_PROBLEM, None, (),
                                    time.perf_counter() - t))
        return
    with np.errstate(all="ignore"):
        x = np.array([project(sub.X, P) for P in ctx.cams])
    held = len(held_views(ctx.cams[list(relax.dropped)], [ctx.regions[w] for w in relax.dropped], sub.X)) == \
        len(relax.dropped)
    certify = sub.status.certified and held and _decided(ctx, relax.bound(sub.gamma_lb), sub.X)
    # (report_point decides again on the whole problem's reported numbers, with its cheirality)
    res = report_point(ctx, step_of(sub, ctx), Status.OPTIMAL if certify else Status.NOT_CERTIFIED, certify,
                       relax.bound(sub.gamma_lb), X=sub.X, X_raw=sub.X, image_points=x,
                       certified_by=SUB_PROBLEM if certify else None, lowered=True)
    ctx.attempts.append(Attempt(sub.method, sub.delta, res.status.value, res.gamma_lb, res.gamma_ub,
                                AttemptStep.SUB_PROBLEM, sub.sparsity, (), time.perf_counter() - t))
    if res.optimal:
        ctx.best, ctx.finished = replace(res, message=join(f"certified by {relax.what}", res.message)), True
        return
    if res.gamma_lb is not None and (ctx.best is None or better(res, ctx.best)):
        ctx.best = replace(res, message=join(f"lower bound of {relax.what}", res.message))
    # an exact reduction whose whole plan ran to a bound near its estimate: the whole problem's plan would repeat it on
    # data scaled by the long regions (a 4-view problem with 20-70 px residuals: 12 s, then 17 s more for a lower bound
    # 2.6e-3 below its); not after a poor one (lower bound 0 at a local estimate 36 % above another point: review 42c)
    near = res.gamma_lb is not None and res.gamma_ub is not None and res.gamma_lb >= PLAN_NEAR * res.gamma_ub
    ctx.finished = ctx.finished or (relax.exact and sub.status != Status.TIME_LIMIT and near)


def _decided(ctx: PointContext, gamma_lb: float, X) -> bool:
    """The whole problem's decision in its normalised units (:func:`tritools.solve.decide.decide`, its resolution
    guard on the squares) on the carried bound and gamma(X') on all N views: with X' in every dropped region the gap
    is the sub-problem's own, but that was decided with the sub-problem's resolution (its kept views' coordinates,
    1e5-1e6 px where the whole problem's are 1-25 px: a 1.5e-3 relative gap certified, review 41a MEDIUM-1)."""
    with np.errstate(all="ignore"):
        g = float(gamma_validated(np.asarray(X, float)[None], ctx.cams, ctx.regions)[0])
    if not np.isfinite(g):
        return False
    s = ctx.norm.scale
    return bool(decide(c_from_gamma(min(gamma_lb, g), ctx.N, s), c_from_gamma(g, ctx.N, s), ctx.tolerances, ctx.N,
                       ctx.norm.resolution)[1])


#: the point stages the sub-problem never runs: itself (no recursion), and the degree-4 exact-variety step
_NEVER = frozenset({"sub_problem", "exact_variety"})
#: ... nor, where some kept view is not a point, the SDP steps: a delta = 2 step on regions costs 0.3 s in its
#: estimate's search alone (a 3-view ellipse / border sub-problem of a 4-view mixed scene) and the whole
#: problem's plan runs anyway; kept point views take the delta = 2 SDP (ms)
_REGION_NEVER = _NEVER | {"steps"}


def _plan_stages() -> tuple:
    """The point stages of an exact reduction: all but this one (no recursion)."""
    from . import POINT_STAGES

    return tuple(s for s in POINT_STAGES if s.name != "sub_problem")


def sub_stages(regions) -> tuple:
    """The point stages of the sub-problem on ``regions`` (module docstring, :data:`_NEVER`, :data:`_REGION_NEVER`)."""
    from . import POINT_STAGES     # (the stage list lives in the package that imports this module)

    never = _NEVER if all(r.is_point for r in regions) else _REGION_NEVER
    return tuple(s for s in POINT_STAGES if s.name not in never)


def _solve(ctx: PointContext, relax: Relaxation):
    """The relaxation's problem (:func:`sub_stages`, delta = 2 at most) within the time left."""
    from . import run_point

    left = ctx.settings.deadline.remaining()
    regions = list(relax.regions)
    try:
        # delta = 2 whatever degree the caller started from (a robust search asks its whole problem for delta >= 4),
        # and none of the caller's lower_bound_stop: a level of the whole problem, not of this one; an exact
        # reduction (``plan``) runs the caller's plan, with every point stage but this one
        opts = dataclasses.replace(ctx.opts, lower_bound_stop=None) if relax.plan else \
            dataclasses.replace(ctx.opts, delta=None, max_delta=2, path=SolvePath.AUTO, lower_bound_stop=None)
        if left is not None:
            opts = opts.replace(time_limit=max(1e-3, left))
        stages = _plan_stages() if relax.plan else sub_stages(regions)
        return run_point(ctx.cams[list(relax.keep)], regions, opts, stages=stages, fast=ctx.fast)
    except (ValueError, TypeError, ArithmeticError, np.linalg.LinAlgError):     # e.g. the kept views share one
        return None                                                             # centre: no sub-problem to solve
