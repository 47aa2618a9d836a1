"""The step stages after the SDP: ``estimate`` -> ``rigor`` -> ``decide`` -> ``resolve``.

* ``estimate`` -- the candidates of the returned certificate: Henrion-Lasserre points and scaled kernel
  vectors of the optimal Gram matrix, the moment matrices' (clique moments for sparse certificates), and
  -- when a dense kernel has dimension > 1 -- the member of the kernel's affine family v(t) with the
  smallest gamma(X^(v(t))) (every member is a legitimate v* of the paper's (51)); X^ from the SVD of
  M0(v*) (the paper's (47)-(49)), the smallest exact gamma(X^), then the local L2 refinement (Theorem 1
  holds for any X^, so it can only lower gamma_UB): c_UB = 2N gamma'(X^)^2;
  When an earlier step left an estimate (``PointContext.estimate_n``; before the first, the local estimate)
  whose c_UB the solved certificate's c* already meets by the decision rule, that estimate is taken and the
  extraction is skipped (it found the same point in every measured case and cost ~10% of a views step and
  up to 80% of a certifying degree-2 step with regions: benchmarks/RESULTS.md, issue #22); if
  the step's rigorous decision then does not certify, the extraction runs after all and ``rigor`` and
  ``decide`` follow again on its estimate, so nothing is decided on the shortcut alone.  Past the deadline the
  extraction is not started (its searches also stop when the deadline passes during them) and the earlier
  estimate stands in (:func:`_stand_in`);
* ``rigor`` -- c_LB = c* minus the rigorous margin of the certificate (:func:`sospoly.analysis.
  rigorous_psatz_bound`: its PSD defect and identity residual on the box / ball that holds a minimiser,
  :func:`tritools.solve.report.solve_radius` / :func:`~tritools.solve.report.solve_ball`, derived from
  c_UB -- so it follows the estimate);
* ``decide`` -- :func:`tritools.solve.decide.decide` in c units, gamma_LB = sqrt(c_LB / 2N) / s (the paper's
  (52), :func:`tritools.solve.decide.gamma_from_c`), the result of the estimate
  (:func:`tritools.solve.stages.outcome.report_point`);
* ``resolve`` -- an "almost solved" iterate that did not certify through the rigorous bound is re-solved
  with the solver's full retry chain when its solve was quick (:data:`INACCURATE_RESOLVE_MAX_SECONDS`; when a
  later plan step contains the program, :data:`INACCURATE_RESOLVE_CONTAINED_SECONDS`), and
  the stages between ``sdp`` and ``resolve`` run again on it; the chain skips the settings of the attempts
  already made on the program (with the default back-end: Clarabel is deterministic, a repeat gives the same
  iterate -- it was a quarter of the degree-2 step at 16 views with mixed regions).
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np

import sospoly
from sospoly import SolveStatus
from sospoly.analysis import OBJECTIVE_ERRORS, best_in_family, kernel_family, rigorous_psatz_bound
from sospoly.solvers import IPM_LEVEL

from ...model.geometry import (common_centre, gamma as gamma_of, gamma_validated, point_from_validated,
                               points_from_validated, refine_l2)
from ...model.cameras import camera_refusal
from ...model.refine import disc_shapes
from ...result import Status, TriangulationResult
from ..decide import decide, gamma_from_c
from ..plan import Step
from ..report import solve_ball, solve_radius
from .context import PointContext, StepState, bound_stop_reached
from .outcome import better, join, replace, report_point
from .sdp import resolve_chain, solve_psatz

__all__ = ["estimate_stage", "rigor_stage", "decide_stage", "resolve_stage", "MAX_FAMILY_DIM", "FAMILY_SEARCH_EVALS",
           "INACCURATE_RESOLVE_MAX_SECONDS"]

#: kernel families of dimension up to this are searched for the best candidate.
MAX_FAMILY_DIM = 3
#: evaluations of gamma spent searching a Gram kernel's family for the best estimate (the local refinement
#: that follows does the fine work)
FAMILY_SEARCH_EVALS = 300
#: an "almost solved" iterate that does not certify is re-solved with the solver's full retry chain when
#: its solve took at most this many seconds (measured: N = 30 mixed regions, delta = 2: 8 s per attempt,
#: four more attempts all "almost solved"; N = 3: milliseconds, and the chain certifies gamma* = 0 data).
INACCURATE_RESOLVE_MAX_SECONDS = 1.0
#: the same when a later plan step's program contains this one's (a views step holds the dense degree-2
#: certificate): a certificate the chain would find is found there too, so only a cheap chain is worth its
#: time (measured, mixed 16 px regions: the chain certified none at 16 views, 0.2-0.3 s per attempt; at
#: <= 10 views an attempt takes < 0.05 s)
INACCURATE_RESOLVE_CONTAINED_SECONDS = 0.1


def _iterate(lb) -> bool:
    """An inaccurate iterate that passed the a-posteriori checks (``Tolerances.accept_inaccurate``): used only
    through the rigorous bound, which charges its PSD defect and identity residual."""
    return lb.status == SolveStatus.INACCURATE and lb.solution is not None and lb.solution.objective is not None


def unsolved_result(step: Step, lb) -> TriangulationResult:
    """The result of an SDP that returned no usable bound."""
    status = {SolveStatus.TIME_LIMIT: Status.TIME_LIMIT, SolveStatus.BUDGET_EXCEEDED: Status.BUDGET_EXCEEDED}\
        .get(lb.status, Status.SOLVER_FAILED)
    return TriangulationResult(step.result_method.value, status,
                               message=f"SDP at delta={step.delta}: {lb.status.value} {lb.message}".strip())


def ill_posed_result(step: Step, gamma_lb) -> TriangulationResult:
    return TriangulationResult(step.result_method.value, Status.ILL_POSED, gamma_lb=gamma_lb, optimal=False,
                               message="every extracted candidate has w4 ~ 0 (ill-posed: e.g. equal cameras)")


def _unsolved(st: StepState) -> None:
    st.result = unsolved_result(st.step, st.lb)        # decided; ``resolve`` may still re-solve it


def estimate_stage(ctx: PointContext, st: StepState) -> None:
    """The best candidate, refined (module docstring); c* in ``st.c_lower``."""
    lb = st.lb
    if st.result is not None:
        return
    if lb.solution is None or (lb.lower_bound is None and not _iterate(lb)) or \
            lb.status not in (SolveStatus.OPTIMAL, SolveStatus.TIME_LIMIT, SolveStatus.INACCURATE):
        return _unsolved(st)
    st.c_lower = float(lb.lower_bound if lb.lower_bound is not None else lb.solution.objective)
    if _known_estimate_meets(ctx, st):
        st.estimate, st.shortcut = ctx.estimate_n, True
        return
    if level_stopped(lb) and ctx.estimate_n is not None and np.isfinite(ctx.estimate_n[0]):
        st.estimate, st.shortcut = ctx.estimate_n, False     # an iterate's moments hold no minimiser to extract
        return
    t = time.perf_counter()
    best = None if ctx.expired else _best_candidate(ctx, st.problem, st.psatz, lb.solution)
    ctx.timings[f"extract_d{st.step.delta}"] = time.perf_counter() - t
    if best is None and ctx.expired and _stand_in(ctx, st):
        return
    if best is None:
        if _iterate(lb):
            return _unsolved(st)
        st.result = ill_posed_result(st.step, gamma_from_c(st.c_lower, ctx.N, ctx.norm.scale))
        return
    g_raw_n, X_raw_n, x_star_n = best
    g_n, X_n = g_raw_n, X_raw_n
    if ctx.opts.refine:
        Xr = refine_l2(X_raw_n, ctx.cams_n, ctx.regs_n)
        if Xr is not None:
            gr = gamma_of(Xr, ctx.cams_n, ctx.regs_n)
            if np.isfinite(gr) and gr < g_n:
                g_n, X_n = float(gr), Xr
    st.estimate = (g_n, X_n, X_raw_n, x_star_n)
    if ctx.estimate_n is None or g_n < ctx.estimate_n[0]:
        ctx.estimate_n = st.estimate


def level_stopped(lb) -> bool:
    """Whether the solve stopped at an iterate proving the options' level (:func:`sospoly.solvers.level_scope`),
    not at the optimum."""
    return lb.solution is not None and any(a.solver_status == IPM_LEVEL for a in lb.solution.attempts)


def _stand_in(ctx: PointContext, st: StepState) -> bool:
    """Past the deadline: the earlier steps' estimate (the local one before the first) stands in for the
    extraction that was not made or found nothing in time (its span searches and family scans stop at the
    deadline: 0.5-1.4 s past a 0.2-1 s limit on a six-view track before); any X gives a valid c_UB.  Not a
    shortcut: a step that does not certify on it does not extract after all.  False without an estimate."""
    if ctx.estimate_n is None:
        ctx.estimate_n = _local_seed(ctx)
    if ctx.estimate_n is None or not np.isfinite(ctx.estimate_n[0]):
        return False
    st.estimate, st.shortcut = ctx.estimate_n, False
    return True


def _known_estimate_meets(ctx: PointContext, st: StepState) -> bool:
    """Whether the earlier steps' estimate may stand in for this step's extraction: a certificate (or an
    inaccurate iterate, which ``rigor`` charges as always) whose c* already meets that estimate's c_UB by the
    decision rule, and no shortcut tried on this step yet (module docstring)."""
    if st.shortcut is not None or (st.lb.lower_bound is None and not _iterate(st.lb)):
        return False
    if ctx.estimate_n is None:
        ctx.estimate_n = _local_seed(ctx)
    known = ctx.estimate_n
    if known is None or not np.isfinite(known[0]):
        return False
    _, optimal, _ = decide(st.c_lower, 2 * ctx.N * known[0] ** 2, st.tol, ctx.N, ctx.norm.resolution)
    return bool(optimal)


def _local_seed(ctx: PointContext) -> tuple | None:
    """The local estimate (:meth:`PointContext.local`: L2 refinement from the frame's origin) as an estimate
    tuple, its image points its projections (as an extraction's x_i* from v*, ``TriangulationResult.image_points``:
    the regions' closest points were reported before wave 41, so a step that took this estimate reported other
    image points than one that extracted the same X); None without one."""
    loc = ctx.local()
    if loc is None:
        return None
    g, X = loc
    h = ctx.cams_n @ np.append(X, 1.0)
    if not np.all(np.isfinite(h)) or np.any(h[:, 2] == 0):
        return None
    return (float(g), np.asarray(X, float), np.asarray(X, float), h[:, :2] / h[:, 2:])


def _after_shortcut(ctx: PointContext, st: StepState) -> None:
    """A step decided on the earlier estimate that did not certify: the extraction after all, then ``rigor``
    and ``decide`` again on its estimate (module docstring)."""
    st.shortcut = False                                # spent: the re-run extracts
    st.result, st.estimate = None, None
    resolve_chain(ctx, st, after="sdp", until="resolve")


def _c_upper(ctx: PointContext, st: StepState) -> float:
    return 2 * ctx.N * st.estimate[0] ** 2


def rigor_stage(ctx: PointContext, st: StepState) -> None:
    """c_LB = c* minus the certificate's rigorous margin on a set holding a minimiser (module docstring)."""
    if st.result is not None:
        return
    c_ub = _c_upper(ctx, st)
    R = solve_radius(ctx.regs_n, c_ub)
    if R is not None:
        errors = st.problem.eq_error
        n = len(st.problem.gens)
        st.c_lower = rigorous_psatz_bound(st.psatz, st.lb.solution, st.c_lower, R, ball=solve_ball(ctx.regs_n, c_ub),
                                          eq_error=None if errors is None else
                                          errors.bounds(np.broadcast_to(np.asarray(R, float), (n,)))).lower_bound
    elif _iterate(st.lb):
        _unsolved(st)


def decide_stage(ctx: PointContext, st: StepState) -> None:
    """The decision in c units and the result of the estimate (module docstring)."""
    if st.result is not None:
        return
    c, c_ub = st.c_lower, _c_upper(ctx, st)
    status, optimal, c_rep = decide(c, c_ub, st.tol, ctx.N, ctx.norm.resolution)
    if st.lb.status == SolveStatus.TIME_LIMIT:
        status, optimal = Status.TIME_LIMIT, False
    msg, gamma_lb = "", gamma_from_c(c_rep, ctx.N, ctx.norm.scale) if np.isfinite(c_rep) else None
    if status == Status.NUMERICAL_FAILURE:
        msg = f"lower bound c={c:.10g} above c at the estimate {c_ub:.10g}: numerical failure, no certificate"
        gamma_lb = None                     # it contradicts a feasible value: not a valid bound
    _, X_n, X_raw_n, x_star_n = st.estimate
    norm = ctx.norm
    res = report_point(ctx, st.step, status, optimal, gamma_lb, X=norm.world_point(X_n),
                       X_raw=norm.world_point(X_raw_n), image_points=norm.image_points(x_star_n),
                       certified_by="sdp" if optimal else None)
    st.result = replace(res, message=join(msg, res.message))
    if st.shortcut and not optimal:
        _after_shortcut(ctx, st)


def resolve_stage(ctx: PointContext, st: StepState) -> None:
    """The full retry chain for a quick "almost solved" iterate that did not certify (module docstring)."""
    key = f"solve_d{st.step.delta}"
    if st.lb is None or st.result is None or st.lb.status != SolveStatus.INACCURATE or st.result.optimal or \
            ctx.expired or ctx.timings.get(key, np.inf) > _resolve_limit(ctx, st.step) or \
            bound_stop_reached(ctx.opts.lower_bound_stop, st.result.gamma_lb, st.result.status.certified):
        return                                   # (an iterate at the options' level: what the caller asked for)
    first = (st.lb, st.result, st.estimate)
    attempts = st.lb.solution.attempts if st.lb.solution else ()
    # an iterate stopped at the level that fell short of it: the interior-point method again, to the optimum
    tried = () if level_stopped(st.lb) else tuple(f"{a.label}:{a.solver_status}" for a in attempts)
    st.lb = solve_psatz(ctx, st.psatz, dataclasses.replace(st.tol, accept_inaccurate=False), tried=tried)
    st.result, st.estimate = None, None
    resolve_chain(ctx, st)
    if st.result is None or not better(st.result, first[1]):
        # the chain did not help (again "almost solved", or failed): the first iterate's rigorous bounds stand
        st.lb, st.result, st.estimate = first
    ctx.timings[key] = time.perf_counter() - st.t_solve


def _resolve_limit(ctx: PointContext, step: Step) -> float:
    """The longest first solve that is re-solved with the full chain (:data:`INACCURATE_RESOLVE_MAX_SECONDS`, or
    :data:`INACCURATE_RESOLVE_CONTAINED_SECONDS` when a later step of the plan contains this step's program)."""
    later = ctx.steps[ctx.steps.index(step) + 1:] if step in ctx.steps else []
    contained = step.delta == 2 and step.formulation == "dense" and any(
        s.method == step.method and s.formulation == "views" and s.delta > step.delta for s in later)
    return INACCURATE_RESOLVE_CONTAINED_SECONDS if contained else INACCURATE_RESOLVE_MAX_SECONDS


_CHECK = object()


class CandidateCost:
    """gamma of the scene point of a candidate v (image points ``problem.image_points(v)`` -> X^ by the SVD of
    M0, :func:`tritools.model.geometry.point_from_validated`) for one problem's normalised cameras: the common
    centre, the regions' disc shapes and the cameras' check (:func:`camera_refusal`: a refusal raises its
    ValueError from every :meth:`one`, as the per-candidate check did) done once.  :meth:`one` gives
    (gamma, X^, image points) or None (no finite point or gamma); :meth:`many` the gammas of many candidates (the
    same numbers: tests/test_candidate_cost.py; stacked for point and disc regions), +inf where :meth:`one` gives
    None."""

    def __init__(self, problem, cams: np.ndarray, regs, refused=_CHECK):
        self.problem, self.cams, self.regs = problem, cams, regs
        self.centre = common_centre(cams)
        self.shapes = disc_shapes(regs)
        # ``refused``: the cameras' check (PointContext.cams_n_refusal, made once per call; made here when not
        # given): normalised cameras can lose rank in extreme data (a point at 1e308 px)
        self.refused = camera_refusal(cams) if refused is _CHECK else refused

    def one(self, v):
        if self.refused is not None:            # as the per-candidate check raised (best_in_family: +inf)
            raise ValueError(self.refused)
        xn = self.problem.image_points(v)
        Xn = point_from_validated(xn, self.cams, centre=self.centre)
        if Xn is None:
            return None
        g = gamma_validated(np.asarray(Xn, float)[None], self.cams, self.regs, shapes=self.shapes)[0]
        return (float(g), np.asarray(Xn, float), xn) if np.isfinite(g) else None

    def value(self, v) -> float:
        return (self.one(v) or (np.inf,))[0]

    def _value_or_inf(self, v) -> float:
        try:
            return self.value(v)
        except OBJECTIVE_ERRORS:                # best_in_family's rule
            return np.inf

    def many(self, V: np.ndarray) -> np.ndarray:
        if self.shapes is None or self.refused is not None:     # other regions: gamma's loop, point by point
            return np.array([self._value_or_inf(v) for v in V])
        xs = np.stack([self.problem.image_points(v) for v in V])
        Xs = points_from_validated(xs, self.cams, centre=self.centre)
        ok = np.isfinite(Xs).all(axis=1)
        g = np.full(len(V), np.inf)
        if ok.any():
            g[ok] = gamma_validated(Xs[ok], self.cams, self.regs, shapes=self.shapes)
        return np.where(np.isfinite(g), g, np.inf)


def _best_candidate(ctx: PointContext, problem, psatz, sol):
    """Best (gamma_n, X_n, image points_n) over the extracted candidates (module docstring)."""
    cost = CandidateCost(problem, ctx.cams_n, ctx.regs_n, ctx.cams_n_refusal)
    tol = ctx.tolerances
    points = [c.point for c in sospoly.candidates_of(psatz, sol, tol) if c.point.shape == (len(problem.gens),)]
    if len(psatz.u.block_names()) == 1 and "u" in sol.grams:
        fam = kernel_family(sol.grams["u"], psatz.u.gram.b, tol)
        if fam is not None and 0 < fam.dim <= MAX_FAMILY_DIM:
            v, _ = best_in_family(fam, cost.value, max_evals=FAMILY_SEARCH_EVALS, objective_many=cost.many)
            points.append(v)
    best = None
    for v in points:
        if best is not None and ctx.expired:    # past the deadline: the best candidate so far
            break
        e = cost.one(v)
        if e is not None and (best is None or e[0] < best[0]):
            best = e
    return best
