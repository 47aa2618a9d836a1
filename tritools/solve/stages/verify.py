"""The stages before the SDPs: ``plan``, ``verify`` and the early ``trivial`` bound.

``verify`` is certification by verification at delta = 2 (the plan's first step, ``path="auto"``): a
local L2 optimum v^, KKT multipliers, the Lagrangian bound (:mod:`sospoly.analysis`), decided by
:func:`tritools.solve.decide.decide`.  Its implementations are data, :data:`VERIFY_IMPLEMENTATIONS`,
tried in order; the first that applies runs:

* ``"verify-points"`` -- point regions, Corollary 1: the vectorised verification
  (:func:`tritools.solve.fastpath.verify_checked`) on a stack of one, so batches decide as a single call
  (the same rule; a stack of one runs the scalar twins of the LM and of the bound, equal up to round-off);
* ``"verify-discs"`` -- filled discs (uncertain keypoints), Corollary 1: :func:`tritools.solve.discs.verify_discs`;
* ``"verify-ellipses"`` -- filled ellipses, points among them: :func:`tritools.solve.ellipses.verify_ellipses`
  on a stack of one (as ``triangulate_many``);
* ``"verify-regions"`` -- every other mix of regions with a conic form (points, segments, polytopes, filled
  ellipses, ellipse borders through their filled ellipse), Corollary 1: the region multipliers eliminated
  exactly view by view (:mod:`tritools.solve.regions_verify`);
* ``"generic"`` -- any delta = 2 program without inequalities or auxiliary variables:
  :func:`sospoly.analysis.verify_quadratic` on the built problem.

The fast ones (:class:`~tritools.solve.stages.context.Implementation`) apply only when named in
``ctx.fast`` (:data:`~tritools.solve.stages.context.FAST_DEFAULT`);
tests/test_stages.py checks that they and the generic one take the same decision with the same bounds.
"""
from __future__ import annotations

import time


import numpy as np

import sospoly
from sospoly.analysis import verify_quadratic
from sospoly.budget import TimeLimitReached

from ...model.constraints import Method
from ...model.epipolar_data import polynomial_errors
from ...model.geometry import dlt, gamma as gamma_of, project, refine_l2
from ...result import Attempt, Status, TriangulationResult
from ..decide import cheirality, decide, gamma_from_c
from ..discs import disc_radius, ellipse_shapes, verify_discs
from ..ellipses import verify_ellipses
from ..fastpath import fits, verify_checked
from ..fastpath_cameras import depths_one
from ..options import SolvePath
from ..regions_verify import constraint_counts, region_bound, region_bound_fits, region_forms
from ..plan import Step, degree_plan, delta_min
from ..report import solve_ball
from .context import AttemptStep, ImplName, Implementation, PointContext
from .outcome import behind_message, report_point, trivial_certificate

__all__ = ["Implementation", "VERIFY_IMPLEMENTATIONS", "plan_stage", "verify_stage", "trivial_stage",
           "verification_step"]


def plan_stage(ctx: PointContext) -> None:
    """The degree plan (:func:`tritools.solve.plan.degree_plan`) of this problem."""
    first_method = ctx.opts.explicit_method or Method.COROLLARY1
    n_vars = 2 * ctx.N + sum(r.n_aux for r in ctx.regions)
    ctx.steps = degree_plan(ctx.opts, ctx.N, n_vars, delta_min(first_method, ctx.N))


def verification_step(ctx: PointContext) -> Step | None:
    """The plan's first step when certification by verification applies to it (``path="auto"``, delta = 2)."""
    if ctx.steps and ctx.opts.path == SolvePath.AUTO and ctx.steps[0].delta == 2:
        return ctx.steps[0]
    return None


def verify_stage(ctx: PointContext) -> None:
    """Certification by verification (module docstring); a certificate finishes the point."""
    step = verification_step(ctx)
    if step is None or ctx.finished or ctx.expired:
        return
    t = time.perf_counter()
    try:
        impl = next((i for i in VERIFY_IMPLEMENTATIONS if i.usable(ctx, step)), None)
        res = None if impl is None else impl.run(ctx, step)
    except TimeLimitReached:          # building the problem ran out of time: the SDP step reports it
        res = None
    except (np.linalg.LinAlgError, FloatingPointError):     # LAPACK on overflowed data (a 1e-180 px polytope's
        res = None                                          # B ~ 1e180, review 40a): not verified, the plan goes on
    ctx.timings["verify"] = time.perf_counter() - t
    cut = ctx.verify_cut or (res is None and ctx.expired)           # not run (or not finished) for lack of time
    failed = Status.TIME_LIMIT.value if cut else "verification_failed"
    ctx.attempts.append(Attempt(step.method.value, 2, "verified" if res is not None else failed,
                                None if res is None else res.gamma_lb, None if res is None else res.gamma_ub,
                                AttemptStep.VERIFICATION, "dense", (), time.perf_counter() - t))
    if res is not None:
        ctx.best, ctx.finished = res, True


def trivial_stage(ctx: PointContext) -> None:
    """Where verification was tried and failed: a certificate through the trivial bound at the local estimate
    (:mod:`tritools.solve.trivial`) before any SDP."""
    step = verification_step(ctx)
    if step is None or ctx.finished or ctx.expired:
        return
    res = trivial_certificate(ctx, step)
    if res is not None:
        ctx.best, ctx.finished = res, True


# ---------------------------------------------------------------------------------------------- implementations
def _cor1(step: Step) -> bool:
    return step.method == Method.COROLLARY1


def _points_apply(ctx: PointContext, step: Step) -> bool:
    return _cor1(step) and all(r.is_point for r in ctx.regions)


def _verify_points(ctx: PointContext, step: Step) -> TriangulationResult | None:
    """The vectorised verification on a stack of one: it already decided the certificate on the reported
    numbers (gamma_LB <= gamma(X) in pixels), so only the residuals, depths and cheirality are added."""
    x = ctx.centres()[None]
    cut = not fits(ctx.settings.deadline, ctx.N)     # the all-pairs bound will not be started (its estimate)
    b = verify_checked(ctx.cams[None], x, np.isfinite(x).all(axis=(1, 2)), ctx.tolerances,
                       deadline=ctx.settings.deadline)
    if not b.certified[0]:
        # not started for time: before the call, or after the bands used up the time (no bound at all, and the
        # all-pairs bound no longer fits: review 4)
        ctx.verify_cut = cut or (not np.isfinite(b.gamma_lb[0]) and not fits(ctx.settings.deadline, ctx.N))
        return None
    X = b.X[0]
    # gamma(X) and the residuals as points_report_stack computes them (verify_checked uses its formulas on the
    # same cameras and X): only the depths are left
    gamma, res = float(b.gamma_at_X[0]), b.residuals[0]
    dep = depths_one(ctx.cams, X, ctx.opts.world_frame)
    status, in_front = cheirality(Status.OPTIMAL, dep, ctx.opts.require_in_front)
    K = ctx.N * (ctx.N - 1) // 2
    return TriangulationResult(step.result_method.value, status, X=X, gamma_ub=gamma,
                               gamma_lb=float(min(b.gamma_lb[0], gamma)), optimal=True, delta=2,
                               n_lmivar=sospoly.n_lmivar_formula(2 * ctx.N, 2, [2] * K),
                               image_points=b.image_points[0], X_raw=X, gamma_ub_raw=gamma,
                               certified_by="verification", message="" if in_front else behind_message(dep),
                               sparsity="dense", in_front=in_front, depths=dep, residuals=res)


def _discs_apply(ctx: PointContext, step: Step) -> bool:
    return _cor1(step) and all(disc_radius(r) is not None for r in ctx.regions)


def _verify_discs(ctx: PointContext, step: Step) -> TriangulationResult | None:
    radii = np.array([[disc_radius(r) for r in ctx.regions]])
    b = verify_discs(ctx.cams[None], ctx.centres()[None], radii, tolerances=ctx.tolerances,
                     deadline=ctx.settings.deadline)
    if not b.certified[0]:
        return None
    K = ctx.N * (ctx.N - 1) // 2
    return report_point(ctx, step, Status.OPTIMAL, True, float(b.gamma_lb[0]), lowered=True, X=b.X[0], X_raw=b.X[0],
                        image_points=b.image_points[0], certified_by="verification",
                        n_lmivar=sospoly.n_lmivar_formula(4 * ctx.N, 2, [2] * K, [2] * ctx.N))


def _ellipses_apply(ctx: PointContext, step: Step) -> bool:
    return _cor1(step) and ellipse_shapes(ctx.regions) is not None


def _verify_ellipses(ctx: PointContext, step: Step) -> TriangulationResult | None:
    """Filled ellipses (and points among them, D = 0): the vectorised verification on a stack of one, so a single
    call decides exactly as ``triangulate_many``."""
    D = np.array([ellipse_shapes(ctx.regions)])
    b = verify_ellipses(ctx.cams[None], ctx.centres()[None], D, tolerances=ctx.tolerances,
                        deadline=ctx.settings.deadline)
    if not b.certified[0]:
        return None
    K = ctx.N * (ctx.N - 1) // 2
    n_ell = int(np.count_nonzero(np.any(D[0], axis=(1, 2))))
    return report_point(ctx, step, Status.OPTIMAL, True, float(b.gamma_lb[0]), lowered=True, X=b.X[0], X_raw=b.X[0],
                        image_points=b.image_points[0], certified_by="verification",
                        n_lmivar=sospoly.n_lmivar_formula(2 * ctx.N + 2 * n_ell, 2, [2] * K, [2] * n_ell))


def _regions_apply(ctx: PointContext, step: Step) -> bool:
    return _cor1(step) and region_forms(ctx.regions) is not None


def _verify_regions(ctx: PointContext, step: Step) -> TriangulationResult | None:
    """The degree-2 certificate with the region multipliers (:func:`tritools.solve.regions_verify.region_bound`)
    at the local estimate of the normalised problem, decided by the rule of every path."""
    local = ctx.local()
    if local is None or ctx.expired:        # past the deadline (the local estimate can end there): not started
        return None
    if not region_bound_fits(ctx.settings.deadline, ctx.N):     # its set-up and a bound no longer fit: not started
        ctx.verify_cut = True
        return None
    Xn = local[1]
    extents = [r.extent().radius for r in ctx.regs_n]
    forms = region_forms(ctx.regs_n)
    if forms is None:
        return None
    c_lb, c_ub, u = region_bound(ctx.cams, ctx.cams_n, ctx.regs_n, Xn, extents, forms=forms,
                                 tolerances=ctx.tolerances, resolution=ctx.norm.resolution,
                                 deadline=ctx.settings.deadline)
    status, optimal, c_lb = decide(c_lb, c_ub, ctx.tolerances, ctx.N, ctx.norm.resolution)
    if not optimal:
        return None
    X = ctx.norm.world_point(Xn)
    K = ctx.N * (ctx.N - 1) // 2
    n_eq, n_ineq = constraint_counts(forms)
    eq, ineq = [2] * (K + n_eq), [2] * n_ineq
    n_vars = 2 * ctx.N + sum(r.n_aux for r in ctx.regions)
    return report_point(ctx, step, Status.OPTIMAL, True, gamma_from_c(c_lb, ctx.N, ctx.norm.scale), X=X, X_raw=X,
                        image_points=ctx.norm.image_points(u), certified_by="verification",
                        n_lmivar=sospoly.n_lmivar_formula(n_vars, 2, eq, ineq))


def _generic_applies(ctx: PointContext, step: Step) -> bool:
    return True


def _verify_generic(ctx: PointContext, step: Step) -> TriangulationResult | None:
    """Verification of the built delta = 2 problem: quadratic f and g, no inequalities, no auxiliary variables."""
    problem = ctx.problem(step.method, "dense")
    if problem.ineq or any(r.n_aux for r in ctx.regs_n) or problem.f.degree > 2 or \
            any(g.degree > 2 for g in problem.eq) or not problem.projection:
        return None
    try:
        X0 = dlt(ctx.cams_n, np.array([r.center for r in ctx.regs_n]))
    except ValueError:
        return None
    Xn = refine_l2(X0, ctx.cams_n, ctx.regs_n)
    if Xn is None or not np.isfinite(gamma_of(Xn, ctx.cams_n, ctx.regs_n)):
        return None
    v = np.concatenate([project(Xn, P) for P in ctx.cams_n])[: 2 * ctx.N]
    ball = solve_ball(ctx.regs_n, float(problem.f(v)))          # holds a minimiser: a rigorous bound
    error = polynomial_errors(problem.eq, v, ball)
    if problem.eq_error is not None:            # the projection constraints' proven coefficient errors on the ball
        error = np.maximum(error, problem.eq_error.bounds(np.full(len(problem.gens), float(ball))))
    ver = verify_quadratic(problem.f, problem.eq, v, gens=problem.gens, tolerances=ctx.tolerances, radius=ball,
                           constraint_error=error)
    status, optimal, c_lb = decide(ver.lower_bound, ver.upper_bound, ctx.tolerances, ctx.N, ctx.norm.resolution)
    if not optimal:
        return None
    X = ctx.norm.world_point(Xn)
    return report_point(ctx, step, Status.OPTIMAL, True, gamma_from_c(c_lb, ctx.N, ctx.norm.scale), X=X, X_raw=X,
                        image_points=ctx.norm.image_points(v.reshape(ctx.N, 2)), certified_by="verification",
                        n_lmivar=sospoly.n_lmivar_formula(len(problem.gens), 2, [g.degree for g in problem.eq]))


#: the implementations of the verify stage, tried in order (module docstring).
VERIFY_IMPLEMENTATIONS: tuple[Implementation, ...] = (
    Implementation(ImplName.VERIFY_POINTS, _points_apply, _verify_points),
    Implementation(ImplName.VERIFY_DISCS, _discs_apply, _verify_discs),
    Implementation(ImplName.VERIFY_ELLIPSES, _ellipses_apply, _verify_ellipses),
    Implementation(ImplName.VERIFY_REGIONS, _regions_apply, _verify_regions),
    Implementation(ImplName.GENERIC, _generic_applies, _verify_generic, fast=False),
)
