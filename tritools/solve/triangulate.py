"""Certified uncertain multiple-view L2 triangulation of one point (Theorem 1 and Corollary 1).

``triangulate(cameras, regions)`` with one :class:`~tritools.solve.options.TriangulationOptions`:

1. validate (:func:`tritools.model.geometry.validate_cameras`, :func:`tritools.model.regions.as_regions`),
   move a far-away world origin to the cameras (:mod:`tritools.model.frame`: georeferenced scenes and
   rescaled cameras give their twins' answers) and normalise the data (:mod:`tritools.model.normalize`;
   the L2 problem is unchanged and every number reported is in the caller's units);
2. walk the degree plan (:func:`tritools.solve.plan.degree_plan`): at each step build (f, g, h) in the
   step's formulation (:mod:`tritools.model.problem`) and the certificate's structure -- dense, or view
   cliques beside the dense degree-2 block -- from :data:`~tritools.solve.structures.STRUCTURE_CACHE`,
   sized against the budget before anything is assembled, and solve it within the remaining time;
   with ``path="auto"`` certification by verification is tried first at delta = 2;
3. gamma_LB = sqrt(c_LB / (2N)) / s (the paper's (52)), where c_LB is c* minus the rigorous margin of
   the returned certificate (:mod:`sospoly.analysis.rigor`: its PSD defect and identity residual on a
   ball that holds a minimiser, derived from the objective at the estimate);
4. the estimate: candidates from the Gram kernel and the moment matrices (clique moments for sparse
   certificates), X^ from the SVD of M0(v*) (the paper's (47)-(49)), the smallest exact gamma(X^);
   optional local L2 refinement (Theorem 1 holds for any X^, so it can only lower gamma_UB);
5. the decision (:func:`tritools.solve.decide.decide`, the rule of every path) in c units; a lower bound
   above the upper bound beyond the tolerance is re-solved once with 100x tighter solver tolerances and
   reported as NUMERICAL_FAILURE if it persists, never as a certificate; a certified point behind a
   camera becomes BEHIND_CAMERA (:func:`tritools.solve.decide.cheirality`);
6. not certified: the next step of the plan.  The best result is returned, with every step in
   ``attempts``; running out of time or memory gives TIME_LIMIT / BUDGET_EXCEEDED with the best bounds
   found so far.
"""
from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

import sospoly
from sospoly import BudgetExceeded, Multiplier, SolveStatus
from sospoly.analysis import best_in_family, kernel_family
from sospoly.analysis import rigorous_psatz_bound
from sospoly.analysis import verify_quadratic
from sospoly.budget import Deadline, TimeLimitReached, deadline_scope

from ..model.constraints import Method, centre_relations
from ..model.frame import WorldFrame, frame_centre_groups, world_frame
from ..model.geometry import (common_centre, dlt, gamma as gamma_of, gamma_validated, image_points,
                              point_from_image_points, project, refine_l2, validate_cameras)
from ..model.normalize import Normalization, normalization_for, unconstrained_reason
from ..model.problem import TriangulationProblem, build_problem, view_band, view_chain
from ..model.regions import as_regions
from ..result import Attempt, Status, TriangulationResult
from .decide import cheirality, decide, decide_reported, gamma_from_c
from .discs import disc_radius, verify_discs
from .fastpath import verify_checked
from .options import SolvePath, TriangulationOptions, options_from
from .plan import Step, degree_plan
from .report import point_report, points_report_stack, solve_ball, solve_radius
from .structures import STRUCTURE_CACHE, structure_key
from .trivial import TRIVIAL_BOUND, local_estimate, trivially_certified, trivially_certified_reported

__all__ = ["triangulate", "MAX_FAMILY_DIM", "INACCURATE_RESOLVE_MAX_SECONDS"]

#: kernel families of dimension up to this are searched for the best candidate.
MAX_FAMILY_DIM = 3
#: evaluations of gamma spent searching a Gram kernel's family for the best estimate (the local refinement
#: that follows does the fine work)
FAMILY_SEARCH_EVALS = 300


def triangulate(cameras: ArrayLike, regions: Sequence | ArrayLike, method: str | Method | None = None,
                delta: int | None = None, max_delta: int | None = None, *,
                options: TriangulationOptions | None = None, robust: ArrayLike | None = None,
                **overrides) -> TriangulationResult:
    """Certified triangulation of one scene point (see module docstring).

    Parameters
    ----------
    cameras : array (N, 3, 4)
    regions : N regions (:class:`~tritools.model.regions.Region`, ``to_dict`` mappings, 2-vectors), or an
        (N, 2) array of observed points
    method, delta, max_delta : as the fields of :class:`~tritools.solve.options.TriangulationOptions`
    options : a :class:`~tritools.solve.options.TriangulationOptions`; keyword ``overrides`` (``path``,
        ``sparsity``, ``multiplier``, ``refine``, ``normalize``, ``backend``, ``form``, ``tolerances``,
        ``budget``) replace its fields
    robust : None, or thresholds c in pixels (a positive scalar or one per view, ``inf`` allowed): certified
        truncated least squares (:mod:`tritools.solve.robust`): the bounds are those of
        gamma_TLS = sqrt(sum_i min(d_i^2, c_i^2) / 2N) and the result's ``inliers`` says which views count
    """
    t0 = time.perf_counter()
    opts = options_from(options, method=method, delta=delta, max_delta=max_delta, **overrides)
    cams = validate_cameras(cameras)
    regs = as_regions(regions, cams.shape[0])
    if robust is not None:
        from .robust import robust_thresholds, triangulate_robust

        return triangulate_robust(cams, regs, robust_thresholds(robust, cams.shape[0]), opts, t0)
    return _PointSolve(cams, regs, opts, t0).run()


def _delta_min(method: Method, n_views: int) -> int:
    """delta_min of a triangulation program: region polynomials and epipolar constraints are quadratic; Theorem
    1's minors are quadratic for two views and of degree 3-4 beyond (SPEC §3)."""
    return 2 if method == Method.COROLLARY1 or n_views == 2 else 4


#: an "almost solved" iterate that does not certify is re-solved with the solver's full retry chain when
#: its solve took at most this many seconds (measured: N = 30 mixed regions, delta = 2: 8 s per attempt,
#: four more attempts all "almost solved"; N = 3: milliseconds, and the chain certifies gamma* = 0 data).
INACCURATE_RESOLVE_MAX_SECONDS = 1.0


class _PointSolve:
    """One triangulation: data, options, normalisation, the problems built so far, the attempts."""

    def __init__(self, cams, regions, opts: TriangulationOptions, t0: float):
        self.frame: WorldFrame = world_frame(cams)          # georeferenced worlds, rescaled cameras
        self.cams_user = cams                               # the caller's: the final report is made on these
        cams = self.frame.cameras(cams)
        self.cams, self.regions, self.opts, self.t0 = cams, regions, opts, t0
        self.N = cams.shape[0]
        self.deadline: Deadline = opts.budget.deadline()
        self.timings: dict = {}
        self.attempts: list[Attempt] = []
        self._problems: dict = {}
        self._relations = None
        self._local = _UNSET

    # ------------------------------------------------------------------ the normalised data (when needed)
    @functools.cached_property
    def norm(self) -> Normalization:
        """The normalisation (:mod:`tritools.model.normalize`), computed on first use: a point certified by the
        vectorised verification never needs it here (that path normalises inside its stack of one)."""
        t = time.perf_counter()
        norm = normalization_for(self.cams, self.regions, enabled=self.opts.normalize)
        self.timings["normalise"] = self.timings.get("normalise", 0.0) + time.perf_counter() - t
        return norm

    @functools.cached_property
    def cams_n(self) -> np.ndarray:
        return self.norm.cameras(self.cams)

    @functools.cached_property
    def regs_n(self) -> list:
        return self.norm.regions(self.regions)

    # ------------------------------------------------------------------ problems
    def problem(self, method: Method, formulation: str) -> TriangulationProblem:
        key = (method, formulation)
        if key not in self._problems:
            t = time.perf_counter()
            if self._relations is None:
                self._relations = centre_relations(self.cams, frame_centre_groups(self.cams, self.frame))
            self._problems[key] = build_problem(self.cams_n, self.regs_n, method, formulation, self._relations)
            self.timings["build"] = self.timings.get("build", 0.0) + time.perf_counter() - t
        return self._problems[key]

    def run(self) -> TriangulationResult:
        """The degree plan under the deadline: the build loops of sospoly check it too
        (:func:`sospoly.budget.deadline_scope`), so building, assembling and sizing stop at the limit."""
        with deadline_scope(self.deadline):
            return self._run()

    def _run(self) -> TriangulationResult:
        first_method = self.opts.explicit_method or Method.COROLLARY1
        n_vars = 2 * self.N + sum(r.n_aux for r in self.regions)
        steps = degree_plan(self.opts, self.N, n_vars, _delta_min(first_method, self.N))
        best, skipped = None, None
        for k, step in enumerate(steps):
            if self.deadline.expired:
                break
            if k == 0 and self.opts.path == SolvePath.AUTO and step.delta == 2:
                res = self.verify(step) or self.trivial(step)
                if res is not None:
                    best = res
                    break
            res = self.solve_step(step)
            if res.status == Status.NUMERICAL_FAILURE:
                res = self.solve_step(step, tight=True)
            best = res if best is None or _better(res, best) else best
            if res.status == Status.BUDGET_EXCEEDED:
                skipped = res
            if res.status.certified or res.status in (Status.ILL_POSED, Status.BUDGET_EXCEEDED):
                break                   # certified, hopeless, or every later (larger) step exceeds the budget too
        if best is None:
            best = TriangulationResult(self._method_name(steps), Status.TIME_LIMIT,
                                       message="time limit reached before any certificate was computed")
        elif self.deadline.expired and not best.status.certified and best.status != Status.ILL_POSED:
            best = _replace(best, status=Status.TIME_LIMIT,
                            message=(best.message + "; " if best.message else "") + "time limit reached")
        elif skipped is not None and skipped is not best and not best.status.certified and \
                best.status != Status.ILL_POSED:
            # the best bounds so far, and why the plan stopped short of a certificate
            best = _replace(best, status=Status.BUDGET_EXCEEDED,
                            message="; ".join(m for m in (best.message, f"skipped {skipped.message}") if m))
        best = self.settle(best, steps)
        self.timings["total"] = time.perf_counter() - self.t0
        best = self.in_user_frame(best)
        return _replace(best, timings=dict(self.timings), attempts=tuple(self.attempts))

    def in_user_frame(self, res: TriangulationResult) -> TriangulationResult:
        """``res`` with X moved back to the caller's world frame (:mod:`tritools.model.frame`) and gamma_UB,
        residuals and depths evaluated there on the caller's cameras -- the numbers a user re-computes -- the
        certificate confirmed on them (:func:`tritools.solve.decide.decide_reported`)."""
        if not self.frame.moved or res.X is None:
            return res
        X, X_raw = self.frame.user_point(res.X), self.frame.user_point(res.X_raw)
        rep = point_report(X, self.cams_user, self.regions)
        kw = dict(X=X, X_raw=X_raw, gamma_ub=rep.gamma, residuals=rep.residuals, depths=rep.depths,
                  gamma_ub_raw=point_report(X_raw, self.cams_user, self.regions).gamma)
        if res.gamma_lb is not None and rep.gamma is not None and np.isfinite(rep.gamma):
            kw["gamma_lb"] = min(res.gamma_lb, rep.gamma)
            if res.optimal and not decide_reported(kw["gamma_lb"], rep.gamma, self.opts.tolerances, self.N,
                                                   self.norm.scale, self.norm.resolution):
                kw.update(status=Status.NOT_CERTIFIED, optimal=False, certified_by=None,
                          message="; ".join(m for m in (res.message, "the bounds met in the re-centred frame, "
                                                        "but not at the estimate in the caller's frame") if m))
        return _replace(res, **kw)

    def _method_name(self, steps) -> str:
        return steps[0].result_method.value if steps else (self.opts.explicit_method or Method.COROLLARY1).value

    # ------------------------------------------------------------------ certification by verification
    def verify(self, step: Step) -> TriangulationResult | None:
        """Certification by verification at delta = 2 (:mod:`sospoly.analysis.verify`): local L2 optimum,
        KKT multipliers, Lagrangian bound.  Corollary 1 with point regions: the vectorised path on a stack of
        one (so batches decide exactly as this); other delta = 2 programs without inequalities or auxiliary
        variables: the generic test.  None when it does not certify."""
        t = time.perf_counter()
        try:
            res = self._verify(step)
        except TimeLimitReached:          # building the problem ran out of time: the SDP step reports it
            res = None
        self.timings["verify"] = time.perf_counter() - t
        self.attempts.append(Attempt(step.method.value, 2, "verified" if res is not None else "verification_failed",
                                     None if res is None else res.gamma_lb, None if res is None else res.gamma_ub,
                                     "verification", "dense", (), time.perf_counter() - t))
        return res

    def _verify(self, step: Step) -> TriangulationResult | None:
        res = None
        if step.method == Method.COROLLARY1 and all(r.is_point for r in self.regions):
            x = self._centres()[None]
            b = verify_checked(self.cams[None], x, np.isfinite(x).all(axis=(1, 2)), self.opts.tolerances)
            if b.certified[0]:
                res = self._report_verified_points(step, b)
        elif step.method == Method.COROLLARY1 and all(disc_radius(r) is not None for r in self.regions):
            b = verify_discs(self.cams[None], self._centres()[None],
                             np.array([[disc_radius(r) for r in self.regions]]), tolerances=self.opts.tolerances)
            if b.certified[0]:
                n_vars = 4 * self.N
                K = self.N * (self.N - 1) // 2
                res = self._report(step, Status.OPTIMAL, True, float(b.gamma_lb[0]), X=b.X[0], X_raw=b.X[0],
                                   image_points=b.image_points[0], certified_by="verification",
                                   n_lmivar=sospoly.n_lmivar_formula(n_vars, 2, [2] * K, [2] * self.N))
        else:
            res = self._verify_generic(step)
        return res

    def _report_verified_points(self, step: Step, b) -> TriangulationResult:
        """The result of a point problem certified by :func:`~tritools.solve.fastpath.verify_points` (a stack of
        one): that function already decided the certificate on the reported numbers (gamma_LB <= gamma(X) in
        pixels), so only the residuals, depths and cheirality are added (vectorised, no second decision)."""
        X = b.X[0]
        gamma, res, dep = points_report_stack(self.cams[None], self._centres()[None], X[None],
                                             self.opts.world_frame)
        status, in_front = cheirality(Status.OPTIMAL, dep[0], self.opts.require_in_front)
        K = self.N * (self.N - 1) // 2
        return TriangulationResult(step.result_method.value, status, X=X, gamma_ub=float(gamma[0]),
                                   gamma_lb=float(min(b.gamma_lb[0], gamma[0])), optimal=True, delta=2,
                                   n_lmivar=sospoly.n_lmivar_formula(2 * self.N, 2, [2] * K),
                                   image_points=b.image_points[0], X_raw=X, gamma_ub_raw=float(gamma[0]),
                                   certified_by="verification", message="" if in_front else behind_message(dep[0]),
                                   sparsity="dense", in_front=in_front, depths=dep[0], residuals=res[0])

    def _centres(self) -> np.ndarray:
        return np.array([r.center for r in self.regions], float)

    def _verify_generic(self, step: Step) -> TriangulationResult | None:
        problem = self.problem(step.method, "dense")
        if problem.ineq or any(r.n_aux for r in self.regs_n) or problem.f.degree > 2 or \
                any(g.degree > 2 for g in problem.eq) or not problem.projection:
            return None
        try:
            X0 = dlt(self.cams_n, np.array([r.center for r in self.regs_n]))
        except ValueError:
            return None
        Xn = refine_l2(X0, self.cams_n, self.regs_n)
        if Xn is None or not np.isfinite(gamma_of(Xn, self.cams_n, self.regs_n)):
            return None
        v = np.concatenate([project(Xn, P) for P in self.cams_n])[: 2 * self.N]
        ball = solve_ball(self.regs_n, float(problem.f(v)))          # holds a minimiser: a rigorous bound
        ver = verify_quadratic(problem.f, problem.eq, v, gens=problem.gens, tolerances=self.opts.tolerances,
                               radius=ball)
        status, optimal, c_lb = decide(ver.lower_bound, ver.upper_bound, self.opts.tolerances, self.N,
                                       self.norm.resolution)
        if not optimal:
            return None
        lb = gamma_from_c(c_lb, self.N, self.norm.scale)
        X = self.norm.world_point(Xn)
        return self._report(step, Status.OPTIMAL, True, lb, X=X, X_raw=X,
                            image_points=self.norm.image_points(v.reshape(self.N, 2)), certified_by="verification",
                            n_lmivar=sospoly.n_lmivar_formula(len(problem.gens), 2, [g.degree for g in problem.eq]))

    # ------------------------------------------------------------------ the trivial bound, the local estimate
    def local(self) -> tuple[float, np.ndarray] | None:
        """The local estimate (:func:`tritools.solve.trivial.local_estimate`), computed once."""
        if self._local is _UNSET:
            t = time.perf_counter()
            try:
                self._local = local_estimate(self.cams_n, self.regs_n)
            except (ValueError, np.linalg.LinAlgError, FloatingPointError):
                self._local = None
            self.timings["local"] = time.perf_counter() - t
        return self._local

    def trivial(self, step: Step, X=None) -> TriangulationResult | None:
        """A certificate through the trivial bound gamma* >= 0 (:mod:`tritools.solve.trivial`) at ``X`` (world
        frame; default the local estimate), or None when gamma(X) is not within the tolerance of 0."""
        t = time.perf_counter()
        if X is None:
            est = self.local()
            if est is None or not trivially_certified(2 * self.N * est[0] ** 2, self.opts.tolerances, self.N,
                                                      self.norm.resolution):
                return None
            X = self.norm.world_point(est[1])
        rep = point_report(X, self.cams, self.regions)
        if rep.gamma is None or not trivially_certified_reported(rep.gamma, self.opts.tolerances, self.N,
                                                                 self.norm.scale, self.norm.resolution):
            return None
        with np.errstate(all="ignore"):
            x = image_points(np.asarray(X, float), self.cams)
        res = self._report(step, Status.OPTIMAL, True, 0.0, X=X, X_raw=X, image_points=x, certified_by=TRIVIAL_BOUND)
        if not res.optimal:
            return None
        self.attempts.append(Attempt(step.method.value, step.delta, Status.OPTIMAL.value, 0.0, res.gamma_ub,
                                     TRIVIAL_BOUND, res.sparsity, (), time.perf_counter() - t))
        return _replace(res, message="; ".join(m for m in ("gamma_UB within the certificate tolerance of the "
                                                            "trivial lower bound 0", res.message) if m))

    def settle(self, best: TriangulationResult, steps) -> TriangulationResult:
        """The final result: a certificate through the trivial bound at the best estimate (or the local one) when
        one holds; otherwise ``best``, with the local estimate when it has none (every status but
        ``invalid_input`` carries an estimate when one can be computed)."""
        if best.status.certified or best.status == Status.INVALID_INPUT:
            return best
        step = _step_of(best, steps, self.opts)
        cert = (self.trivial(step, best.X) if best.X is not None else None) or self.trivial(step)
        if cert is not None:
            why = f" (before: {best.status.value}{': ' + best.message if best.message else ''})"
            return _replace(cert, n_lmivar=best.n_lmivar, message=cert.message + why)
        est = self.local()
        if best.X is not None or est is None:
            return best
        X = self.norm.world_point(est[1])
        with np.errstate(all="ignore"):
            x = image_points(X, self.cams)
        rep = self._report(step, best.status, False, best.gamma_lb, X=X, X_raw=X, image_points=x, certified_by=None)
        note = "X and gamma_UB from the local L2 refinement of the DLT point"
        return _replace(rep, delta=best.delta, n_lmivar=best.n_lmivar, sparsity=best.sparsity,
                        message="; ".join(m for m in (best.message, note) if m))

    # ------------------------------------------------------------------ the SDP
    def solve_step(self, step: Step, tight: bool = False) -> TriangulationResult:
        opts = self.opts
        tol = opts.tolerances.tightened() if tight else opts.tolerances
        tol = dataclasses.replace(tol, accept_inaccurate=True)     # made rigorous in _finish
        label = "tight" if tight else "sdp"
        sparsity = "dense" if step.formulation == "dense" else "views"
        common = dict(method=step.result_method.value, delta=step.delta, sparsity=sparsity)
        t = time.perf_counter()
        try:
            return self._solve_step(step, tol, label, common, t)
        except TimeLimitReached as exc:               # building, assembling or compiling ran out of time
            return self._failed(step, Status.TIME_LIMIT, f"delta={step.delta}: {exc}", label, t)
        except (BudgetExceeded, MemoryError) as exc:  # the native-memory guard, or an allocation that failed
            why = str(exc) or "out of memory (MemoryError)"
            return self._failed(step, Status.BUDGET_EXCEEDED, f"delta={step.delta} ({sparsity}): {why}", label, t)

    def _solve_step(self, step: Step, tol, label: str, common: dict, t: float) -> TriangulationResult:
        opts = self.opts
        sparsity = common["sparsity"]
        try:
            problem = self.problem(step.method, step.formulation)
        except ValueError as exc:                     # e.g. Theorem 1 with all minors for too many views
            return self._failed(step, Status.BUDGET_EXCEEDED, str(exc), label, t)
        if not problem.projection:
            status, why = unconstrained_reason(self.cams, self.regions)
            return self._failed(step, Status(status), why, label, t)
        if sospoly.delta_min(problem.f, problem.eq, problem.ineq) > step.delta:
            return self._failed(step, Status.INVALID_INPUT, f"delta {step.delta} is below delta_min of this "
                                                            f"problem", label, t)
        try:
            comp, theta = self._compiled(problem, step)
        except BudgetExceeded as exc:
            return self._failed(step, Status.BUDGET_EXCEEDED, f"delta={step.delta} ({sparsity}): {exc}", label, t)
        self.timings[f"assemble_d{step.delta}"] = time.perf_counter() - t
        t1 = time.perf_counter()
        if comp is None:
            psatz = sospoly.build_psatz(problem.f, problem.eq, problem.ineq, step.delta, opts.multiplier,
                                        gens=problem.gens, sparsity=self._shape(problem, step), budget=opts.budget)
            backend, form = opts.backend, opts.form
        else:
            psatz = comp.bind(theta)
            backend, form = (opts.backend if opts.backend is not None else "auto"), sospoly.GramForm.IMAGE
        lb = self._solve_psatz(psatz, backend, form, tol)
        self.timings[f"solve_d{step.delta}"] = time.perf_counter() - t1
        res = self._finish(problem, step, psatz, lb, tol, label)
        if lb.status == SolveStatus.INACCURATE and not res.optimal and not self.deadline.expired and \
                self.timings[f"solve_d{step.delta}"] <= INACCURATE_RESOLVE_MAX_SECONDS:
            # the inaccurate iterate did not certify through the rigorous bound: the full retry chain (only for
            # quick programs -- on large ones the chain mostly repeats "almost solved" at 4x the cost)
            lb = self._solve_psatz(psatz, backend, form, dataclasses.replace(tol, accept_inaccurate=False))
            res = self._finish(problem, step, psatz, lb, tol, label)
            self.timings[f"solve_d{step.delta}"] = time.perf_counter() - t1
        solver = tuple(f"{a.label}:{a.solver_status}" for a in (lb.solution.attempts if lb.solution else ()))
        self.attempts.append(Attempt(step.method.value, step.delta, res.status.value, res.gamma_lb, res.gamma_ub, label,
                                     sparsity, solver, time.perf_counter() - t))
        return _replace(res, **common, n_lmivar=psatz.n_lmivar)

    def _solve_psatz(self, psatz, backend, form, tol):
        return sospoly.solve_psatz(psatz, backend=backend, form=form, tolerances=tol, deadline=self.deadline)

    def _shape(self, problem: TriangulationProblem, step: Step):
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
                                    max_gram_side=self.opts.budget.max_gram_side).reduced()

    def _compiled(self, problem: TriangulationProblem, step: Step):
        """(compiled structure, theta) from the cache, or (None, None) for a free or user multiplier."""
        m = self.opts.multiplier
        if not (isinstance(m, Multiplier) and m != Multiplier.FREE):
            return None, None
        key = structure_key(self.N, tuple(r.kind for r in self.regions), step.method, step.delta, step.formulation,
                            self.opts.form)
        try:
            return STRUCTURE_CACHE.get(problem.f, problem.eq, problem.ineq, step.delta, m, self.opts.form,
                                       gens=problem.gens, key=key, sparsity=self._shape(problem, step),
                                       budget=self.opts.budget)
        except sospoly.StructureMismatch:
            return None, None

    def _finish(self, problem, step: Step, psatz, lb, tol, label) -> TriangulationResult:
        """Rigorous gamma_LB, the estimate, the decision."""
        # an inaccurate iterate that passed the a-posteriori checks (Tolerances.accept_inaccurate) is used only
        # through the rigorous bound below, which charges its PSD defect and identity residual
        iterate = lb.status == SolveStatus.INACCURATE and lb.solution is not None and \
            lb.solution.objective is not None
        if lb.solution is None or (lb.lower_bound is None and not iterate) or \
                lb.status not in (SolveStatus.OPTIMAL, SolveStatus.TIME_LIMIT, SolveStatus.INACCURATE):
            return self._unsolved(step, lb)
        t = time.perf_counter()
        best = self._estimate(problem, psatz, lb.solution)
        self.timings[f"extract_d{step.delta}"] = time.perf_counter() - t
        c = float(lb.lower_bound if lb.lower_bound is not None else lb.solution.objective)
        if best is None:
            if iterate:
                return self._unsolved(step, lb)
            lb_g = gamma_from_c(c, self.N, self.norm.scale)
            return TriangulationResult(step.result_method.value, Status.ILL_POSED, gamma_lb=lb_g, optimal=False,
                                       message="every extracted candidate has w4 ~ 0 (ill-posed: e.g. equal cameras)")
        g_raw_n, X_raw_n, x_star_n = best
        g_n, X_n = g_raw_n, X_raw_n
        if self.opts.refine:
            Xr = refine_l2(X_raw_n, self.cams_n, self.regs_n)
            if Xr is not None:
                gr = gamma_of(Xr, self.cams_n, self.regs_n)
                if np.isfinite(gr) and gr < g_n:
                    g_n, X_n = float(gr), Xr
        c_ub = 2 * self.N * g_n ** 2
        R = solve_radius(self.regs_n, c_ub)
        if R is not None:
            c = rigorous_psatz_bound(psatz, lb.solution, c, R, ball=solve_ball(self.regs_n, c_ub)).lower_bound
        elif iterate:
            return self._unsolved(step, lb)
        status, optimal, c_rep = decide(c, c_ub, tol, self.N, self.norm.resolution)
        if lb.status == SolveStatus.TIME_LIMIT:
            status, optimal = Status.TIME_LIMIT, False
        msg, gamma_lb = "", gamma_from_c(c_rep, self.N, self.norm.scale) if np.isfinite(c_rep) else None
        if status == Status.NUMERICAL_FAILURE:
            msg = f"lower bound c={c:.10g} above c at the estimate {c_ub:.10g}: numerical failure, no certificate"
            gamma_lb = None                     # it contradicts a feasible value: not a valid bound
        res = self._report(step, status, optimal, gamma_lb, X=self.norm.world_point(X_n),
                           X_raw=self.norm.world_point(X_raw_n), image_points=self.norm.image_points(x_star_n),
                           certified_by="sdp" if optimal else None)
        return _replace(res, message="; ".join(m for m in (msg, res.message) if m))

    @staticmethod
    def _unsolved(step: Step, lb) -> TriangulationResult:
        status = {SolveStatus.TIME_LIMIT: Status.TIME_LIMIT, SolveStatus.BUDGET_EXCEEDED: Status.BUDGET_EXCEEDED}\
            .get(lb.status, Status.SOLVER_FAILED)
        return TriangulationResult(step.result_method.value, status,
                                   message=f"SDP at delta={step.delta}: {lb.status.value} {lb.message}".strip())

    def _estimate(self, problem: TriangulationProblem, psatz, sol):
        """Best (gamma_n, X_n, image points_n) over the extracted candidates: Henrion-Lasserre points and scaled
        kernel vectors of the optimal Gram matrix, the moment matrices' (clique moments for sparse
        certificates), and -- when a dense kernel has dimension > 1 -- the member of the kernel's affine family
        v(t) with the smallest gamma(X^(v(t))) (every member is a legitimate v* of the paper's (51))."""
        centre = common_centre(self.cams_n)                 # once for every candidate below

        def evaluate(v):
            xn = problem.image_points(v)
            Xn = point_from_image_points(xn, self.cams_n, centre=centre)
            if Xn is None:
                return None
            g = gamma_validated(np.asarray(Xn, float)[None], self.cams_n, self.regs_n)[0]
            return (float(g), np.asarray(Xn, float), xn) if np.isfinite(g) else None

        tol = self.opts.tolerances
        points = [c.point for c in sospoly.candidates_of(psatz, sol, tol) if c.point.shape == (len(problem.gens),)]
        if len(psatz.u.block_names()) == 1 and "u" in sol.grams:
            fam = kernel_family(sol.grams["u"], psatz.u.gram.b, tol)
            if fam is not None and 0 < fam.dim <= MAX_FAMILY_DIM:
                v, _ = best_in_family(fam, lambda v: (evaluate(v) or (np.inf,))[0], max_evals=FAMILY_SEARCH_EVALS)
                points.append(v)
        best = None
        for v in points:
            e = evaluate(v)
            if e is not None and (best is None or e[0] < best[0]):
                best = e
        return best

    # ------------------------------------------------------------------ reporting
    def _report(self, step: Step, status, optimal, gamma_lb, *, X, X_raw, image_points, certified_by,
                n_lmivar=None) -> TriangulationResult:
        rep = point_report(X, self.cams, self.regions, self.opts.world_frame)
        raw = point_report(X_raw, self.cams, self.regions)
        msg = ""
        if gamma_lb is not None and rep.gamma is not None and np.isfinite(rep.gamma):
            gamma_lb = min(gamma_lb, rep.gamma)          # consistent in pixels too (decided in c units)
            if optimal:                                  # the decision again, on the numbers reported
                optimal = decide_reported(gamma_lb, rep.gamma, self.opts.tolerances, self.N, self.norm.scale,
                                          self.norm.resolution)
                if not optimal:
                    status = Status.NOT_CERTIFIED
                    msg = "the bounds met in normalised coordinates, but not at the estimate in world coordinates"
        if optimal and (rep.gamma is None or not np.isfinite(rep.gamma)):
            # e.g. views sharing one centre, where the extracted point is the centre itself: no upper bound
            status, optimal = Status.NOT_CERTIFIED, False
            msg = "the estimate's projection is undefined in some view (a point at a camera centre)"
        status, in_front = cheirality(status, rep.depths, self.opts.require_in_front)
        if optimal and not in_front:
            msg = behind_message(rep.depths)
        return TriangulationResult(step.result_method.value, status, X=X, gamma_ub=rep.gamma, gamma_lb=gamma_lb,
                                   optimal=optimal, delta=step.delta, n_lmivar=n_lmivar, image_points=image_points,
                                   X_raw=X_raw, gamma_ub_raw=raw.gamma, certified_by=certified_by if optimal else None,
                                   message=msg, sparsity="dense" if step.formulation == "dense" else "views",
                                   in_front=in_front, depths=rep.depths, residuals=rep.residuals)

    def _failed(self, step: Step, status: Status, message: str, label: str, t: float) -> TriangulationResult:
        sparsity = "dense" if step.formulation == "dense" else "views"
        self.attempts.append(Attempt(step.method.value, step.delta, status.value, None, None, label, sparsity, (),
                                     time.perf_counter() - t))
        return TriangulationResult(step.result_method.value, status, delta=step.delta, message=message,
                                   sparsity=sparsity)


def behind_message(depths) -> str:
    """The message of a certified optimum behind some camera(s): which ones."""
    return "certified L2 optimum, but behind camera(s) " + \
        ", ".join(str(i) for i in np.nonzero(~(np.asarray(depths, float) > 0))[0])


#: "not computed yet" (the local estimate may be None)
_UNSET = object()


def _replace(res: TriangulationResult, **kw) -> TriangulationResult:
    return dataclasses.replace(res, **kw)


def _step_of(res: TriangulationResult, steps, opts: TriangulationOptions) -> Step:
    """The plan step a result belongs to (for reporting an estimate under it)."""
    first = steps[0] if steps else Step(opts.explicit_method or Method.COROLLARY1, 2, "dense")
    try:
        method = Method(res.method)
    except ValueError:
        method = first.method
    return Step(method, res.delta if res.delta is not None else first.delta,
                "views" if res.sparsity == "views" else "dense")


def _better(a: TriangulationResult, b: TriangulationResult) -> bool:
    """Is ``a`` a better result to report than ``b``: certified first, then any estimate with a lower bound
    (the larger one), then any estimate."""
    if a.status.certified != b.status.certified:
        return a.status.certified
    if (a.gamma_lb is not None) != (b.gamma_lb is not None):
        return a.gamma_lb is not None
    if a.gamma_lb is not None and b.gamma_lb is not None and a.gamma_lb != b.gamma_lb:
        return a.gamma_lb > b.gamma_lb
    return a.X is not None and b.X is None
