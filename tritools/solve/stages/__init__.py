"""One point's triangulation as named stages over a per-point context.

:func:`run_point` (what :func:`tritools.triangulate` runs) builds a
:class:`~tritools.solve.stages.context.PointContext` -- data, world frame, normalisation (lazy), options and
:class:`~tritools.solve.settings.SolveSettings`, problems built so far, attempts, timings -- and runs the
stages of :data:`POINT_STAGES` in order, each a module-level function ``stage(ctx) -> None``:

``plan`` -> ``verify`` -> ``trivial`` -> ``sub_problem`` -> ``steps`` ->
``exact_variety`` -> ``settle`` -> ``world_frame`` -> ``report``

``steps`` walks the degree plan; each plan step runs :data:`STEP_STAGES`, functions
``stage(ctx, step_state) -> None``:

``sdp`` (delta, formulation) -> ``estimate`` -> ``rigor`` -> ``decide`` -> ``resolve``

(the rigorous margin needs the estimate's ball, so ``rigor`` follows ``estimate``).  The stage lists are
data: :func:`with_stage` returns a list with one more stage before or after a named one, and
``run_point(..., stages=..., step_stages=...)`` runs it, so a stage (an inlier-set search before
``verify``, an uncertainty stage after ``settle``) is added without touching the others
(docs/architecture.md, "Stages").  Batches of point problems run :data:`BATCH_STAGES` over a
:class:`~tritools.solve.stages.batch.BatchContext` (a column record plus the mask of the rows still open;
:func:`run_batch`): ``plan`` -> ``verify`` -> ``sdp`` -> ``per_point`` -> ``report``, the last but one
the point stages on the rows still open.  The fast implementations of ``verify`` and ``sdp`` (vectorised
verification of points and discs, the batched delta = 2 SDP) are registered in
:mod:`tritools.solve.stages.verify` / :mod:`tritools.solve.stages.sdp` and chosen where they apply.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

from sospoly.budget import deadline_scope

from ...result import TriangulationResult
from .batch import (BATCH_SDP_IMPLEMENTATIONS, BATCH_VERIFY_IMPLEMENTATIONS, BatchContext, per_point_batch_stage,
                    plan_batch_stage, report_batch_stage, sdp_batch_stage, verify_batch_stage)
from .context import FAST_DEFAULT, AttemptStep, ImplName, Implementation, PointContext, StepState
from .estimate import decide_stage, estimate_stage, resolve_stage, rigor_stage
from .exact import exact_variety_stage
from .outcome import report_stage, settle_stage, world_frame_stage
from .subproblem import sub_problem_stage
from .sdp import SDP_FAST_NAME, SDP_IMPLEMENTATIONS, run_step, sdp_stage, steps_stage
from .verify import VERIFY_IMPLEMENTATIONS, plan_stage, trivial_stage, verify_stage

__all__ = ["Stage", "POINT_STAGES", "STEP_STAGES", "with_stage", "run_point", "PointContext", "StepState",
           "AttemptStep", "ImplName", "Implementation", "VERIFY_IMPLEMENTATIONS", "SDP_IMPLEMENTATIONS", "FAST_DEFAULT",
           "FAST_ALL", "run_step", "BATCH_STAGES", "BatchContext", "run_batch", "BATCH_VERIFY_IMPLEMENTATIONS",
           "BATCH_SDP_IMPLEMENTATIONS"]


@dataclass(frozen=True)
class Stage:
    """A named stage: ``run(ctx)`` for a point stage, ``run(ctx, step_state)`` for a step stage."""
    name: str
    run: Callable


#: the stages of one point, in order (module docstring).
POINT_STAGES: tuple[Stage, ...] = (
    Stage("plan", plan_stage),
    Stage("verify", verify_stage),
    Stage("trivial", trivial_stage),
    Stage("sub_problem", sub_problem_stage),            # views whose regions hold the estimate left out
    Stage("steps", steps_stage),
    Stage("exact_variety", exact_variety_stage),        # the plan left it uncertified: Theorem 1, delta 4
    Stage("settle", settle_stage),
    Stage("world_frame", world_frame_stage),
    Stage("report", report_stage),
)

#: the stages of one step of the degree plan, in order (module docstring).
STEP_STAGES: tuple[Stage, ...] = (
    Stage("sdp", sdp_stage),
    Stage("estimate", estimate_stage),
    Stage("rigor", rigor_stage),
    Stage("decide", decide_stage),
    Stage("resolve", resolve_stage),
)

#: the stages of a batch of point problems, in order (:mod:`tritools.solve.stages.batch`).
BATCH_STAGES: tuple[Stage, ...] = (
    Stage("plan", plan_batch_stage),
    Stage("verify", verify_batch_stage),
    Stage("sdp", sdp_batch_stage),
    Stage("per_point", per_point_batch_stage),
    Stage("report", report_batch_stage),
)

#: every fast implementation (the batched delta = 2 SDP included).
FAST_ALL = FAST_DEFAULT | {SDP_FAST_NAME}


def with_stage(stages, stage: Stage, *, before: str | None = None, after: str | None = None) -> tuple[Stage, ...]:
    """``stages`` with ``stage`` inserted before or after the stage of that name (ValueError naming an unknown
    stage or a duplicate name)."""
    names = [s.name for s in stages]
    if (before is None) == (after is None):
        raise ValueError("with_stage needs exactly one of before= and after=")
    anchor = before if before is not None else after
    if anchor not in names:
        raise ValueError(f"no stage named {anchor!r}; stages: {', '.join(names)}")
    if stage.name in names:
        raise ValueError(f"a stage named {stage.name!r} is already in the list")
    k = names.index(anchor) + (after is not None)
    return tuple(stages[:k]) + (stage,) + tuple(stages[k:])


def run_point(cams, regions, opts, t0: float | None = None, *, stages=POINT_STAGES, step_stages=STEP_STAGES,
              fast=FAST_DEFAULT) -> TriangulationResult:
    """The stages on one validated problem (cameras (N, 3, 4) array, regions) under validated options, within
    the point's deadline: the build loops of sospoly check it too (:func:`sospoly.budget.deadline_scope`), so
    building, assembling, compiling and sizing stop at the limit."""
    ctx = PointContext(cams, regions, opts, time.perf_counter() if t0 is None else t0, stages=stages,
                       step_stages=step_stages, fast=fast)
    with deadline_scope(ctx.settings.deadline):
        for stage in ctx.stages:
            stage.run(ctx)
    return ctx.best


def run_batch(cameras, points2d, opts, *, stages=BATCH_STAGES, fast=FAST_ALL, per_point=None) -> BatchContext:
    """The batch stages on M point problems of N views (cameras (M, N, 3, 4), points (M, N, 2)) under validated
    options: the filled :class:`~tritools.solve.stages.batch.BatchContext`.  ``per_point`` runs the rows the
    batch stages leave open (:mod:`tritools.solve.batch` gives the executor's); without it they stay open."""
    return BatchContext(cameras, points2d, opts, stages=stages, fast=fast, per_point=per_point).run()
