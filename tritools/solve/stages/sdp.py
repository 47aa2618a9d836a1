"""The ``steps`` stage (the degree plan's SDPs, one after the other) and the ``sdp`` step stage.

``steps`` walks the plan (:func:`tritools.solve.plan.degree_plan`) under the point's deadline: each step
runs the step stages (:data:`tritools.solve.stages.STEP_STAGES`: sdp -> estimate -> rigor -> decide ->
resolve); a step whose lower bound contradicts its upper bound (NUMERICAL_FAILURE) is re-solved once with
100x tighter solver tolerances (``tight``); the walk stops at a certificate, an ill-posed problem, a
step beyond the budget (every later step is larger), or -- with the options' ``lower_bound_stop`` -- once the
best uncertified rigorous gamma_lb reaches that level (:data:`BOUND_STOP`; the exact-variety step is skipped too).

``sdp`` builds the step's program -- (f, g, h) in the step's formulation (:mod:`tritools.model.problem`)
and the certificate's shape: dense, or view cliques beside the dense degree-2 block -- compiled once per
structure key (:data:`~tritools.solve.structures.STRUCTURE_CACHE`) and sized against the budget before
anything is assembled, and solves it within the remaining time (the view-clique programs with Clarabel's
fast chain, dense degree-2 programs with regions with the split-cliques chain: :func:`_chain`).  Its fast
implementation, the batched delta = 2 SDP (:func:`tritools.solve.sdp_batch.solve_corollary1_points`, name
``"sdp-points"``), applies to point regions, Corollary 1, delta = 2, dense, the default multiplier, form
and back-end, with normalisation; it decides the step itself, and what it hands back goes to the generic
route.  A single call uses it only when asked (``fast``): batches run it on their stacks
(:mod:`tritools.solve.points`), and tests/test_sdp_batch.py compares them against a single call's generic route.
"""
from __future__ import annotations

import dataclasses
import time

import sospoly
from sospoly import BudgetExceeded, Multiplier
from sospoly.budget import TimeLimitReached, gram_block_exceeds
from sospoly.solvers import CLARABEL_FAST_CHAIN, CLARABEL_SPLIT_CHAIN, AutoBackend, level_scope

from ...errors import ProblemTooLarge
from ...model.constraints import Method
from ...model.normalize import data_magnitude, unconstrained_reason
from ...model.problem import TriangulationProblem, view_band, view_chain
from ...result import Attempt, Status, TriangulationResult
from ..plan import Step
from ..coplanar import futile_after
from ..decide import c_from_gamma
from ..sdp_batch import solve_corollary1_points
from ..structures import STRUCTURE_CACHE, structure_key
from .context import AttemptStep, ImplName, Implementation, PointContext, StepState
from .outcome import better, failed, join, replace, report_point

__all__ = ["BOUND_STOP", "steps_stage", "run_step", "sdp_stage", "solve_psatz", "SDP_FAST_NAME", "SDP_IMPLEMENTATIONS"]

#: the name of the batched delta = 2 SDP in ``fast`` (:class:`~tritools.solve.stages.context.PointContext`).
SDP_FAST_NAME = ImplName.SDP_POINTS


#: the message of a point whose plan stopped at the options' ``lower_bound_stop`` (``PointContext.bound_reached``)
BOUND_STOP = "stopped: gamma_lb reached lower_bound_stop (not certified)"
#: a step's statuses that become ``time_limit`` in its attempt when the caller's deadline cut the solver's retry chain
#: short (an answer kept from an earlier attempt: :attr:`sospoly.solvers.ConicSolution.stopped_for_time`)
CUT_BY_TIME = frozenset({Status.NOT_CERTIFIED, Status.SOLVER_FAILED, Status.NUMERICAL_FAILURE})


def steps_stage(ctx: PointContext) -> None:
    """Walk the degree plan (module docstring); ``ctx.best`` is the best result so far.  The local estimate (the
    answer of last resort, :meth:`PointContext.local`) is computed before the first step, so that a step cut by
    the deadline leaves only the report to do past it (it cost 7-10 ms past a 0.2 s limit at 30 views of regions)."""
    if ctx.steps and not (ctx.finished or ctx.expired):
        ctx.local()
    for step in ctx.steps:
        if ctx.finished or ctx.expired:
            break
        res = run_step(ctx, step)
        if res.status == Status.NUMERICAL_FAILURE:
            res = run_step(ctx, step, tight=True)
        ctx.best = res if ctx.best is None or better(res, ctx.best) else ctx.best
        if res.status == Status.BUDGET_EXCEEDED:
            ctx.skipped = res
        if res.status.certified or res.status in (Status.ILL_POSED, Status.BUDGET_EXCEEDED):
            break                   # certified, hopeless, or every later (larger) step exceeds the budget too
        if ctx.bound_reached:       # the caller's level: no later step (nor the exact-variety step)
            ctx.best = replace(ctx.best, message=join(ctx.best.message, BOUND_STOP))
            break
        why = futile_after(ctx.cams, ctx.regions, ctx.steps, res)      # coplanar centres: Corollary 1's ceiling
        if why is not None and step is not ctx.steps[-1]:
            ctx.best = replace(ctx.best, message=join(ctx.best.message, why))
            break


def run_step(ctx: PointContext, step: Step, tight: bool = False) -> TriangulationResult:
    """One plan step through ``ctx.step_stages``; the attempt is recorded.  Running out of time or memory while
    building, assembling, compiling or solving gives TIME_LIMIT / BUDGET_EXCEEDED."""
    tol = ctx.tolerances.tightened() if tight else ctx.tolerances
    st = StepState(step, tight, tol=dataclasses.replace(tol, accept_inaccurate=True))   # made rigorous later
    try:
        for stage in ctx.step_stages:
            if st.final:
                break
            stage.run(ctx, st)
    except TimeLimitReached as exc:
        return failed(ctx, step, Status.TIME_LIMIT, f"delta={step.delta}: {exc}", st.label, st.t0)
    except (BudgetExceeded, MemoryError) as exc:  # the native-memory guard, or an allocation that failed
        why = str(exc) or "out of memory (MemoryError)"
        return failed(ctx, step, Status.BUDGET_EXCEEDED, f"delta={step.delta} ({st.sparsity}): {why}", st.label,
                      st.t0)
    if st.recorded:
        return st.result
    res = st.result
    solution = st.lb.solution if st.lb is not None else None
    solver = tuple(f"{a.label}:{a.solver_status}" for a in (solution.attempts if solution else ()))
    status = res.status
    if status in CUT_BY_TIME and solution is not None and solution.stopped_for_time:
        status = Status.TIME_LIMIT      # the deadline cut the solver's chain: not the step's last word (review 34b)
    ctx.attempts.append(Attempt(step.method.value, step.delta, status.value, res.gamma_lb, res.gamma_ub,
                                st.label, st.sparsity, solver, time.perf_counter() - st.t0))
    return replace(res, method=step.result_method.value, delta=step.delta, sparsity=st.sparsity,
                   n_lmivar=st.psatz.n_lmivar)


def _fail(ctx: PointContext, st: StepState, status: Status, message: str) -> None:
    st.result, st.final, st.recorded = failed(ctx, st.step, status, message, st.label, st.t0), True, True


def sdp_stage(ctx: PointContext, st: StepState) -> None:
    """The step's SDP (module docstring): the first usable implementation of :data:`SDP_IMPLEMENTATIONS` that
    does not hand the step back."""
    for impl in SDP_IMPLEMENTATIONS:
        if impl.usable(ctx, st) and impl.run(ctx, st):
            return


def _generic(ctx: PointContext, st: StepState) -> bool:
    """Build (or bind the compiled structure) and solve; the lower bound in ``st.lb`` (True: never hands back)."""
    if not _build(ctx, st):
        return True
    t1 = st.t_solve = time.perf_counter()
    st.lb = solve_psatz(ctx, st.psatz, st.tol, chain=_chain(ctx, st.step), level=_level(ctx))
    ctx.timings[f"solve_d{st.step.delta}"] = time.perf_counter() - t1
    return True


#: the level a solve may stop at lies this much (relative, in c) above the options' ``lower_bound_stop`` (the
#: rigorous margin and the report's round-off lowering of gamma_lb come off after the solve: measured ~1e-11 of it)
LEVEL_MARGIN = 1e-6


def _level(ctx: PointContext) -> float | None:
    """The options' ``lower_bound_stop`` as a level of the normalised c* (:func:`sospoly.solvers.level_scope`: the
    solve may stop at an iterate proving it), raised by :data:`LEVEL_MARGIN`; None without one."""
    stop = ctx.opts.lower_bound_stop
    if stop is None:
        return None
    return float(c_from_gamma(stop, ctx.N, ctx.norm.scale)) * (1.0 + LEVEL_MARGIN)


def solve_psatz(ctx: PointContext, psatz, tol, chain: tuple | None = None, tried: tuple = (),
                level: float | None = None):
    """sospoly's solve of a bound compiled instance or a built program, under the point's settings;
    ``chain``: the default back-end with this Clarabel retry chain (:func:`_chain`); ``tried``: solver attempts
    already made on this very program (``label:status``), whose settings the default back-end's retry chain
    skips (a deterministic solver repeats their answer at their cost); ``level``: the solve may stop at an iterate
    proving c* >= level (:func:`_level`; the status is then INACCURATE and the bound made rigorous as always)."""
    s = ctx.settings
    backend = s.backend
    if chain is not None and s.auto_backend:
        backend = AutoBackend(tol, clarabel_chain=chain)
    elif tried and s.auto_backend:
        backend = AutoBackend(tol, skip=tuple(t.split(":")[0] for t in tried))
    with level_scope(level):
        # prove=False: the numerical c* (checked a posteriori), which the rigour stage proves on its own box
        return sospoly.solve_psatz(psatz, backend=backend, form=s.form, tolerances=tol, deadline=s.deadline,
                                   prove=False)


def _chain(ctx: PointContext, step: Step) -> tuple | None:
    """Clarabel's retry chain for the step (None: the default).  The view-clique programs (many PSD blocks):
    :data:`~sospoly.solvers.CLARABEL_FAST_CHAIN`, a first attempt without iterative refinement (only its SOLVED
    answers are taken: the certificate and its rigorous bound are those of every attempt), where the refinement
    costs as much as the factorisation and the attempt ends SOLVED (benchmarks/RESULTS.md, issue #22).  Dense
    degree-2 programs with regions other than points (one large block): :data:`~sospoly.solvers.
    CLARABEL_SPLIT_CHAIN` (fewer iterations, "solved" more often; measured there); from ~12 views the default
    back-end tries sospoly's interior-point method on them first (one Gram block beside the regions' scalar
    multipliers, :data:`~sospoly.solvers.backends.AUTO_IPM_MIN_COST_SCALARS`; its stalled "almost solved" iterate
    is made rigorous like Clarabel's).  Other dense programs keep the default chain."""
    if step.formulation == "views":
        return CLARABEL_FAST_CHAIN
    if step.delta == 2 and not all(r.is_point for r in ctx.regions):
        return CLARABEL_SPLIT_CHAIN
    return None


def _build(ctx: PointContext, st: StepState) -> bool:
    """The step's program in ``st.psatz``; False (and ``st.result``) when it cannot be built."""
    step, t = st.step, st.t0
    why = _dense_floor_exceeds(ctx, step)
    if why:                                       # refused before its polynomials are built (seconds, gigabytes)
        _fail(ctx, st, Status.BUDGET_EXCEEDED, f"delta={step.delta} ({st.sparsity}): {why} (estimated before "
                                               "building the program); use the 'views' sparsity or a larger budget")
        return False
    try:
        problem = st.problem = ctx.problem(step.method, step.formulation)
    except ProblemTooLarge as exc:                # Theorem 1 with all minors for too many views
        _fail(ctx, st, Status.BUDGET_EXCEEDED, str(exc))
        return False
    except ValueError as exc:                     # numbers that overflow in the normalised frame (review 21b F2)
        _fail(ctx, st, Status.NUMERICAL_FAILURE, f"delta={step.delta} ({st.sparsity}): the program's numbers are not "
                                                 f"representable in floating point ({exc}): the regions' or cameras' "
                                                 "magnitudes overflow in the normalised frame")
        return False
    if not problem.projection:
        status, why = unconstrained_reason(ctx.cams, ctx.regions)
        _fail(ctx, st, Status(status), why)
        return False
    if ctx.cams_n_refusal is not None:           # no candidate of this frame could be evaluated (review 29b F8)
        _fail(ctx, st, Status.NUMERICAL_FAILURE, f"the image data (|x| up to {data_magnitude(ctx.regions):.3g}) are "
                                                 "too far from the cameras' image scale to be represented in the "
                                                 f"normalised frame: there, {ctx.cams_n_refusal}")
        return False
    if sospoly.delta_min(problem.f, problem.eq, problem.ineq) > step.delta:
        _fail(ctx, st, Status.INVALID_INPUT, f"delta {step.delta} is below delta_min of this problem")
        return False
    try:
        comp, theta = _compiled(ctx, problem, step)
    except BudgetExceeded as exc:
        _fail(ctx, st, Status.BUDGET_EXCEEDED, f"delta={step.delta} ({st.sparsity}): {exc}")
        return False
    ctx.timings[f"assemble_d{step.delta}"] = time.perf_counter() - t
    if comp is None:
        st.psatz = sospoly.build_psatz(problem.f, problem.eq, problem.ineq, step.delta, ctx.opts.multiplier,
                                       gens=problem.gens, sparsity=_shape(ctx, problem, step), budget=ctx.opts.budget)
    else:
        st.psatz = comp.bind(theta)
    return True


def _dense_floor_exceeds(ctx: PointContext, step: Step) -> str | None:
    """Why a dense step cannot fit the budget whatever its constraints (None: it may): its Gram block has side
    sigma(n, delta / 2) over the n = 2N + sum of the regions' auxiliary variables (:func:`sospoly.budget.
    gram_block_exceeds`, a floor of the estimate the built program gets).  At N = 200 points the dense Corollary 1
    program took 17 s and 2.6 GB to build before its estimate (339 GiB) refused it."""
    if step.formulation != "dense":
        return None
    n = 2 * ctx.N + sum(int(r.n_aux) for r in ctx.regions)
    return gram_block_exceeds(sospoly.sigma(n, step.delta // 2), ctx.opts.budget)


def _shape(ctx: PointContext, problem: TriangulationProblem, step: Step):
    """The certificate shape: dense, or view cliques beside the dense degree-2 certificate -- a cyclic band of
    view pairs (Corollary 1) or a chain of view triples (Theorem 1, whose minors need three views) -- with
    sospoly's exact basis reductions (tritools only says which variables belong together)."""
    if step.formulation == "dense":
        return "none"
    groups = view_chain(problem.n_views, 3) if step.method == Method.THEOREM1 else view_band(problem.n_views)
    cliques = [sorted(problem.variables_of_views(t)) for t in groups]
    n = len(problem.gens)
    return sospoly.clique_shape(n, step.delta, cliques, [problem.variables_of_views(v) for v in problem.eq_views],
                                [problem.variables_of_views(v) for v in problem.ineq_views],
                                [g.degree for g in problem.eq], [h.degree for h in problem.ineq], low_degree=2,
                                max_gram_side=ctx.opts.budget.max_gram_side).reduced()


def _compiled(ctx: PointContext, problem: TriangulationProblem, step: Step):
    """(compiled structure, theta) from the cache, or (None, None) for a free or user multiplier."""
    m = ctx.opts.multiplier
    if not (isinstance(m, Multiplier) and m != Multiplier.FREE):
        return None, None
    form = ctx.settings.form
    key = structure_key(ctx.N, tuple(r.kind for r in ctx.regions), step.method, step.delta, step.formulation, form)
    try:
        return STRUCTURE_CACHE.get(problem.f, problem.eq, problem.ineq, step.delta, m, form, gens=problem.gens,
                                   key=key, sparsity=_shape(ctx, problem, step), budget=ctx.opts.budget)
    except sospoly.StructureMismatch:
        return None, None


# ---------------------------------------------------------------------------------------------- the batched SDP
def _batched_applies(ctx: PointContext, st: StepState) -> bool:
    step, o = st.step, ctx.opts
    return not st.tight and step.method == Method.COROLLARY1 and step.delta == 2 \
        and step.formulation == "dense" and o.multiplier == Multiplier.FIXED and ctx.settings.auto_backend \
        and ctx.settings.form == sospoly.GramForm.IMAGE and o.normalize and all(r.is_point for r in ctx.regions)


def _batched(ctx: PointContext, st: StepState) -> bool:
    """The batched delta = 2 SDP on a stack of one; False when it hands the point back."""
    b = solve_corollary1_points(ctx.cams[None], ctx.centres()[None], tolerances=ctx.tolerances,
                                refine=ctx.opts.refine, deadline=ctx.settings.deadline)
    if not b.done[0]:
        return False
    opt = bool(b.optimal[0])
    res = report_point(ctx, st.step, Status(b.status[0]), opt, float(b.gamma_lb[0]), lowered=True, X=b.X[0],
                       X_raw=b.X_raw[0], image_points=b.image_points[0],
                       certified_by=b.certified_by[0] if opt else None, n_lmivar=b.n_lmivar)
    ctx.attempts.append(Attempt(st.step.method.value, 2, res.status.value, res.gamma_lb, res.gamma_ub,
                                AttemptStep.SDP_BATCH, "dense", ("ipm-batch:converged",),
                                time.perf_counter() - st.t0))
    st.result, st.final, st.recorded = res, True, True
    return True


#: the implementations of the sdp stage, tried in order (module docstring).
SDP_IMPLEMENTATIONS: tuple[Implementation, ...] = (
    Implementation(SDP_FAST_NAME, _batched_applies, _batched),
    Implementation(ImplName.GENERIC, lambda ctx, st: True, _generic, fast=False),
)


def resolve_chain(ctx: PointContext, st: StepState, after: str = "sdp", until: str = "resolve") -> None:
    """Re-run the step stages strictly between ``after`` and ``until`` (the estimate, rigor and decide of a
    re-solved program, and any stage inserted among them)."""
    names = [s.name for s in ctx.step_stages]
    lo = names.index(after) + 1 if after in names else 0
    hi = names.index(until) if until in names else len(names)
    for stage in ctx.step_stages[lo:hi]:
        if st.final:
            break
        stage.run(ctx, st)
