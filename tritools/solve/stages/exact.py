"""The ``exact_variety`` point stage: one more certificate for a point the degree plan left uncertified.

Corollary 1's epipolar constraints admit image points no scene point projects to (with coplanar camera centres --
always with three views -- every view's point on the image line of the centres' plane, :mod:`tritools.solve.plan`),
so for observations far from every projection its bound can stop below the L2 optimum at every degree.  This
stage, between ``steps`` and ``settle``, runs :func:`tritools.solve.plan.exact_variety_step` -- Theorem 1 at
delta = 4, dense, whose minors vanish exactly on the image points of scene points -- through the step stages like
any plan step (:func:`tritools.solve.stages.sdp.run_step`: the same rigorous lower bound and the one decision
rule), and keeps its result where it is better (:func:`~tritools.solve.stages.outcome.better`).

It runs only when the plan ended NOT_CERTIFIED (not after a certificate, an ill-posed problem, a skipped step or
a contradiction), below the options' ``lower_bound_stop``, and time remains; running out of time gives TIME_LIMIT
(``settle``), a program beyond the budget BUDGET_EXCEEDED, and a step that does not certify leaves NOT_CERTIFIED
with the larger of the two lower bounds.  The attempt is recorded like any other (``method="theorem1"``, ``delta=4``).

Beyond the dense step's reach, a point whose Corollary 1 plan stopped at the ceiling of coplanar centres
(:func:`tritools.solve.coplanar.futile_after`: its bound equals the cost of the centres' plane component), or whose
centres are (nearly) collinear (:func:`tritools.solve.coplanar.nearly_collinear_centres`: a pencil of such planes),
gets :func:`tritools.solve.plan.exact_variety_views_step` instead (Theorem 1, delta = 4, view cliques, 5-8 views,
5-12 with collinear centres; no tight re-solve: its numerical failures are the formulation's, not the tolerances').
"""
from __future__ import annotations

from ...result import Status
from ..coplanar import futile_after, nearly_collinear_centres
from ..plan import exact_variety_step, exact_variety_views_step
from .context import PointContext
from .outcome import better, join, replace
from .sdp import run_step

__all__ = ["exact_variety_stage"]


def exact_variety_stage(ctx: PointContext) -> None:
    """The exact-variety step on a point the plan left NOT_CERTIFIED (module docstring)."""
    best = ctx.best
    if ctx.finished or ctx.expired or ctx.skipped is not None or best is None \
            or best.status != Status.NOT_CERTIFIED or ctx.bound_reached:
        return
    n_vars = 2 * ctx.N + sum(r.n_aux for r in ctx.regions)
    step = exact_variety_step(ctx.opts, ctx.N, n_vars, ctx.steps)
    collinear = nearly_collinear_centres(ctx.cams) if step is None else None
    why = futile_after(ctx.cams, ctx.regions, ctx.steps, best) or collinear if step is None else None
    if why is not None:                                                 # coplanar (5-8 views) or collinear (5-12)
        step = exact_variety_views_step(ctx.opts, ctx.N, n_vars, collinear=collinear is not None)
    if step is None:
        return
    res = run_step(ctx, step)
    if res.status == Status.NUMERICAL_FAILURE and step.formulation == "dense":
        res = run_step(ctx, step, tight=True)
    if res.status == Status.BUDGET_EXCEEDED:
        ctx.skipped = res
    if better(res, best):
        ctx.best = res if why is None or res.status.certified else replace(res, message=join(res.message, why))
