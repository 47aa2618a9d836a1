"""Certified uncertain multiple-view L2 triangulation (Theorem 1 and Corollary 1).

``triangulate(cameras, regions, method, delta, max_delta)``:

1. validate and normalise the data (:mod:`tritools.model.normalize`; the L2 problem is
   unchanged and every number reported is in the caller's units);
2. build (f, g, h) (:mod:`tritools.model.problem`) and the Positivstellensatz program
   at degree delta (:func:`sospoly.build_psatz`), solve it with sospoly
   (fixed q = (1 + ||v||^2)^(delta/2 - 1) by default, or the free-q GEVP);
3. gamma_LB = sqrt(c* / (2N)) (the paper's (52));
4. candidates v* from the Gram kernel and the moment matrix; X^ from the SVD of
   M0(v*) (the paper's (47)-(49)); the candidate with the smallest exact
   gamma(X^) is kept (when the kernel has dimension > 1 every candidate the
   kernel offers is tried -- this is the extraction rule);
5. optional local L2 refinement of X^ (Theorem 1 holds for any X^, so it can
   only lower gamma_UB); the raw extracted estimate is reported too;
6. certificate: in c units, ``c_UB - c_LB <= gap_abs + gap_rel * max(1, c_UB)``
   with the tolerances of :class:`sospoly.Tolerances`, c_UB = 2N gamma_UB'^2 in the
   normalised units where c is O(1).  An error dc in c moves gamma by about
   dc / (4 N gamma), so comparing gammas relatively would fail for tiny
   residuals; comparing c does not.  A lower bound above the upper bound by more
   than the tolerance is re-solved once with 100x tighter solver tolerances, and
   reported as NUMERICAL_FAILURE if it persists, never as a certificate;
7. not certified: delta <- delta + 2 up to ``max_delta``.
"""
from __future__ import annotations

import dataclasses
import enum
import time

import numpy as np

import sospoly
from sospoly import DEFAULT_TOLERANCES, GramForm, Multiplier, SolveStatus, Tolerances
from sospoly.analysis.extraction import best_in_family, kernel_family
from sospoly.analysis.verify import verify_quadratic

from ..model.constraints import Method
from ..model.geometry import dlt, gamma as gamma_of, point_from_image_points, project, refine_l2, validate_cameras
from ..model.normalize import Normalization, normalization_for
from ..model.problem import TriangulationProblem, build_problem
from .fastpath import fast_results
from ..model.regions import Point, Region
from ..result import Status, TriangulationResult

__all__ = ["triangulate", "validate_regions", "refine_l2", "MAX_FAMILY_DIM", "SolvePath", "STRUCTURE_CACHE"]


class SolvePath(str, enum.Enum):
    SDP = "sdp"
    AUTO = "auto"


#: kernel families of dimension up to this are searched for the best candidate.
MAX_FAMILY_DIM = 3


def validate_regions(regions, n_views: int) -> list:
    regions = list(regions)
    if len(regions) != n_views:
        raise ValueError(f"regions: expected one region per camera ({n_views}), got {len(regions)}")
    for i, r in enumerate(regions):
        if not isinstance(r, Region):
            raise TypeError(f"regions[{i}] must be a tritools Region (Point, Segment, Polytope, Ellipse, "
                            f"EllipseBorder), got {type(r).__name__}")
    return regions


def _estimate(problem: TriangulationProblem, psatz, sol, cams_n, regs_n, tol):
    """Best (gamma_n, X_n, image points_n) over the extracted candidates.

    Candidates: Henrion-Lasserre points and scaled kernel vectors of the optimal Gram
    matrix, the moment matrix's, and -- when the kernel has dimension > 1 -- the
    member of the kernel's affine family v(t) with the smallest gamma(X^(v(t)))
    (every member satisfies b(v*) in ker U* at half-degree 1, so each is a
    legitimate v* of the paper's (51)).
    """
    def evaluate(v):
        xn = problem.image_points(v)
        Xn = point_from_image_points(xn, cams_n)
        if Xn is None:
            return None
        g = gamma_of(Xn, cams_n, regs_n)
        return (float(g), np.asarray(Xn, float), xn) if np.isfinite(g) else None

    points = [c.point for c in sospoly.candidates_of(psatz, sol, tol)]
    fam = kernel_family(sol.grams["u"], psatz.u.gram.b, tol) if "u" in sol.grams else None
    if fam is not None and 0 < fam.dim <= MAX_FAMILY_DIM:
        v, _ = best_in_family(fam, lambda v: (evaluate(v) or (np.inf,))[0])
        points.append(v)
    best = None
    for v in points:
        e = evaluate(v)
        if e is not None and (best is None or e[0] < best[0]):
            best = e
    return best


def triangulate(cameras, regions, method: Method | str = Method.THEOREM1, delta: int | None = None,
                max_delta: int | None = None, *, path: SolvePath | str = SolvePath.SDP,
                multiplier=Multiplier.FIXED, refine: bool = True,
                normalize: bool = True, backend=None, form: GramForm = GramForm.IMAGE,
                tolerances: Tolerances = DEFAULT_TOLERANCES) -> TriangulationResult:
    """Certified triangulation of one scene point (see module docstring).

    Parameters
    ----------
    cameras : array (N, 3, 4)
    regions : N :class:`tritools.model.regions.Region` (Point, Segment, Polytope, EllipseBorder, Ellipse)
    method : "theorem1" (4x4 minors + SVD reduction) or "corollary1" (epipolar constraints)
    delta : first relaxation degree (even, >= delta_min; default delta_min)
    max_delta : last degree tried (default: delta if given, else delta_min + 2)
    multiplier : "fixed" (one SDP, the paper's q) or "free" (GEVP by bisection)
    path : "sdp" (always solve the SDP) or "auto" (at delta = 2 with point regions, first try
        certification by verification -- local optimum, KKT multipliers, Lagrangian bound,
        :mod:`sospoly.analysis.verify` -- and fall back to the SDP when it does not certify);
        ``certified_by`` says which path certified the result

    ``result.attempts`` lists, per degree tried, ``(delta, status, gamma_lb, gamma_ub,
    solver attempts)`` where the solver attempts are the retry chain's ``label:status``.
    """
    try:
        path = SolvePath(path)
    except ValueError:
        raise ValueError(f"path must be 'sdp' or 'auto', got {path!r}") from None
    t_start = time.perf_counter()
    try:
        method = Method(method)
    except ValueError:
        raise ValueError(f"method must be 'theorem1' or 'corollary1', got {method!r}") from None
    cams = validate_cameras(cameras)
    regions = validate_regions(regions, cams.shape[0])
    timings = {}

    t0 = time.perf_counter()
    norm = normalization_for(cams, regions, enabled=normalize)
    cams_n = norm.cameras(cams)
    regs_n = norm.regions(regions)
    problem = build_problem(cams_n, regs_n, method)
    timings["build"] = time.perf_counter() - t0

    dmin = sospoly.delta_min(problem.f, problem.eq, problem.ineq)
    if delta is None:
        delta = dmin
        last = max_delta if max_delta is not None else dmin + 2
    else:
        last = max_delta if max_delta is not None else delta
    if delta % 2 or delta < dmin:
        raise ValueError(f"delta must be even and >= delta_min = {dmin} for this problem, got {delta}")
    if last < delta:
        raise ValueError(f"max_delta ({last}) is below delta ({delta})")
    try:
        sospoly.certificates.psatz.check_degree_supported(len(problem.gens), last)
    except ValueError as exc:
        raise ValueError(f"{'max_delta' if last != delta else 'delta'}: {exc}") from None

    attempts = []
    result = None
    if SolvePath(path) == SolvePath.AUTO and delta == 2:
        result = _verify_fast(problem, norm, cams, regions, cams_n, regs_n, method, tolerances, timings)
        if result is not None:
            timings["total"] = time.perf_counter() - t_start
            return _replace(result, timings=dict(timings), attempts=((2, "verified", result.gamma_lb,
                                                                      result.gamma_ub),))
        attempts.append((2, "verification_failed", None, None))
    d = delta
    while d <= last:
        result = _solve_at(problem, norm, cams, regions, cams_n, regs_n, method, d, multiplier, refine,
                           backend, form, tolerances, timings)
        attempts.append((d, result.status.value, result.gamma_lb, result.gamma_ub, result.attempts))
        if result.status == Status.NUMERICAL_FAILURE:
            # a lower bound above a feasible value: solve again with 100x tighter solver tolerances
            tight = dataclasses.replace(tolerances, solver_gap_abs=tolerances.solver_gap_abs * 1e-2,
                                        solver_gap_rel=tolerances.solver_gap_rel * 1e-2,
                                        solver_feas=tolerances.solver_feas * 1e-2)
            result = _solve_at(problem, norm, cams, regions, cams_n, regs_n, method, d, multiplier, refine,
                               backend, form, tight, timings)
            attempts.append((d, "tight:" + result.status.value, result.gamma_lb, result.gamma_ub, result.attempts))
        if result.status == Status.OPTIMAL:
            break
        d += 2
    timings["total"] = time.perf_counter() - t_start
    return _replace(result, timings=dict(timings), attempts=tuple(attempts))


def _verify_fast(problem, norm, cams, regions, cams_n, regs_n, method, tol, timings):
    """Certification by verification (:mod:`sospoly.analysis.verify`): local L2 optimum from the DLT
    estimate, KKT multipliers, Lagrangian bound.  Only for delta = 2 programs without
    inequalities or auxiliary variables (point regions); None when it does not certify.

    Corollary 1 with point regions goes through :func:`tritools.solve.fastpath.fast_results` (a
    batch of one, so :func:`tritools.solve.batch.triangulate_many` decides exactly as this does;
    it normalises the data itself, with the formulas of :mod:`tritools.model.normalize`); other
    delta = 2 programs (Theorem 1 with two views) use the generic code below."""
    if method == Method.COROLLARY1 and all(isinstance(r, Point) for r in regions):
        t0 = time.perf_counter()
        res = fast_results(cams[None], np.array([r.center for r in regions])[None], tolerances=tol,
                           method=method.value)[0]
        timings["verify"] = time.perf_counter() - t0
        return res
    if problem.ineq or any(r.n_aux for r in regs_n) or problem.f.degree > 2 or \
            any(g.degree > 2 for g in problem.eq):
        return None
    t0 = time.perf_counter()
    try:
        X0 = dlt(cams_n, np.array([r.center for r in regs_n]))
    except ValueError:
        return None
    Xn = refine_l2(X0, cams_n, regs_n)
    if Xn is None:
        return None
    g_n = gamma_of(Xn, cams_n, regs_n)
    if not np.isfinite(g_n):
        return None
    v = np.concatenate([project(Xn, P) for P in cams_n])[: 2 * problem.n_views]
    ver = verify_quadratic(problem.f, problem.eq, v, gens=problem.gens, tolerances=tol)
    timings["verify"] = time.perf_counter() - t0
    if not ver.certified:
        return None
    N = problem.n_views
    X = norm.world_point(Xn)
    gamma_ub = float(gamma_of(X, cams, regions))
    gamma_lb = float(np.sqrt(max(ver.lower_bound, 0.0) / (2 * N)) / norm.scale)
    n_lmivar = sospoly.n_lmivar_formula(len(problem.gens), 2, [g.degree for g in problem.eq])
    return TriangulationResult(method=method.value, status=Status.OPTIMAL, X=X, gamma_ub=gamma_ub, gamma_lb=gamma_lb,
                               optimal=True, delta=2, n_lmivar=n_lmivar, image_points=norm.image_points(v.reshape(N, 2)),
                               X_raw=X, gamma_ub_raw=gamma_ub, certified_by="verification")


def _replace(res: TriangulationResult, **kw) -> TriangulationResult:
    return dataclasses.replace(res, **kw)


#: compiled Positivstellensatz structures, keyed by (N, region types, method, delta, form):
#: a triangulation only fills numbers into the structure of its key (sospoly.lowering.compiled).
STRUCTURE_CACHE = sospoly.PsatzCache(maxsize=128)


def _structure_key(problem, regs_n, method, delta, form):
    return (problem.n_views, tuple(type(r).__name__ for r in regs_n), Method(method).value, int(delta),
            GramForm(form).value)


def _compiled_for(problem, regs_n, method, delta, multiplier, form):
    """(compiled structure, this problem's coefficient vector theta, multiplier) from the
    cache, or (None, None, multiplier) for a free multiplier or an instance whose degrees
    differ from its key's structure."""
    if isinstance(multiplier, str) and not isinstance(multiplier, sospoly.Polynomial):
        try:
            multiplier = Multiplier(multiplier)
        except ValueError:
            return None, None, multiplier
    if multiplier == Multiplier.FREE:
        return None, None, multiplier
    key = _structure_key(problem, regs_n, method, delta, form) if multiplier == Multiplier.FIXED else None
    try:
        comp, theta = STRUCTURE_CACHE.get(problem.f, problem.eq, problem.ineq, delta, multiplier, form,
                                          gens=problem.gens, key=key)
    except sospoly.StructureMismatch:
        return None, None, multiplier
    return comp, theta, multiplier


def _solve_at(problem, norm: Normalization, cams, regions, cams_n, regs_n, method, delta, multiplier, refine,
              backend, form, tol: Tolerances, timings) -> TriangulationResult:
    """One degree: the compiled structure of (N, region types, method, delta) from
    :data:`STRUCTURE_CACHE` filled with this problem's numbers and solved by ``backend``
    (default ``"auto"``: Clarabel for small SDPs, the interior-point method of
    :mod:`sospoly.solvers.ipm` with Clarabel fallback for large ones); the free-q GEVP goes
    through :func:`sospoly.build_psatz` / :func:`sospoly.solve_psatz`."""
    t0 = time.perf_counter()
    comp, theta, multiplier = _compiled_for(problem, regs_n, method, delta, multiplier, form)
    if comp is None:
        psatz = sospoly.build_psatz(problem.f, problem.eq, problem.ineq, delta, multiplier, gens=problem.gens)
        timings[f"assemble_d{delta}"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        lb = sospoly.solve_psatz(psatz, backend=backend, form=form, tolerances=tol)
    else:
        psatz = comp.bind(theta)
        timings[f"assemble_d{delta}"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        lb = sospoly.solve_psatz(psatz, backend=backend if backend is not None else "auto", tolerances=tol)
    timings[f"solve_d{delta}"] = time.perf_counter() - t0
    return _finish(problem, norm, cams, regions, cams_n, regs_n, method, delta, refine, tol, timings, psatz, lb)


def _finish(problem, norm, cams, regions, cams_n, regs_n, method, delta, refine, tol, timings, psatz,
            lb) -> TriangulationResult:
    """gamma_LB from c*, the estimate from the certificate, refinement, the certificate test."""
    N = problem.n_views
    solver_attempts = tuple(f"{a.label}:{a.solver_status}" for a in (lb.solution.attempts if lb.solution else ()))
    common = dict(method=method.value, delta=delta, n_lmivar=psatz.n_lmivar, attempts=solver_attempts)
    if lb.status != SolveStatus.OPTIMAL or lb.solution is None or lb.solution.x is None:
        return TriangulationResult(status=Status.SOLVER_FAILED, X=None, gamma_ub=None,
                                   message=f"SDP at delta={delta}: {lb.status.value} {lb.message}".strip(), **common)
    c_lb = float(lb.lower_bound)
    gamma_lb = float(np.sqrt(max(c_lb, 0.0) / (2 * N)) / norm.scale)

    t0 = time.perf_counter()
    best = _estimate(problem, psatz, lb.solution, cams_n, regs_n, tol)
    timings[f"extract_d{delta}"] = time.perf_counter() - t0
    if best is None:
        return TriangulationResult(status=Status.ILL_POSED, X=None, gamma_ub=None, gamma_lb=gamma_lb, optimal=False,
                                   message="every extracted candidate has w4 ~ 0 (ill-posed: e.g. equal cameras)",
                                   **common)
    g_raw_n, X_raw_n, x_star_n = best
    g_n, X_n = g_raw_n, X_raw_n
    if refine:
        t0 = time.perf_counter()
        Xr = refine_l2(X_raw_n, cams_n, regs_n)
        if Xr is not None:
            gr = gamma_of(Xr, cams_n, regs_n)
            if np.isfinite(gr) and gr < g_n:
                g_n, X_n = float(gr), Xr
        timings[f"refine_d{delta}"] = time.perf_counter() - t0
    c_ub = 2 * N * g_n ** 2
    X = norm.world_point(X_n)
    X_raw = norm.world_point(X_raw_n)
    # report gamma in the caller's units, evaluated on the original data
    gamma_ub = float(gamma_of(X, cams, regions))
    gamma_raw = float(gamma_of(X_raw, cams, regions))
    optimal = tol.certified(c_lb, c_ub)
    status = Status.OPTIMAL if optimal else Status.NOT_CERTIFIED
    msg = ""
    if c_lb - c_ub > tol.gap_abs + tol.gap_rel * max(1.0, c_ub):
        status, optimal = Status.NUMERICAL_FAILURE, False
        msg = f"lower bound c={c_lb:.10g} above c at the estimate {c_ub:.10g}: numerical failure, no certificate"
    return TriangulationResult(status=status, X=X, gamma_ub=gamma_ub, gamma_lb=gamma_lb, optimal=optimal,
                               image_points=norm.image_points(x_star_n), X_raw=X_raw, gamma_ub_raw=gamma_raw,
                               certified_by="sdp" if optimal else None, message=msg, **common)
