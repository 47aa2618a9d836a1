"""Certified uncertain multiple-view L2 triangulation of one point (Theorem 1 and Corollary 1).

``triangulate(cameras, regions)`` with one :class:`~tritools.solve.options.TriangulationOptions` runs the
named stages of :mod:`tritools.solve.stages` (plan -> verify -> trivial -> steps [sdp -> estimate -> rigor
-> decide -> resolve] -> settle -> world_frame -> report) on one point:

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

import time
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from sospoly.analysis import rigorous_psatz_bound  # noqa: F401 - re-exported (the rigor stage's bound)

from ..model.constraints import Method
from ..result import TriangulationResult
from .fastpath_cameras import validated_problem
from .identical_views import identical_views
from .options import TriangulationOptions, options_from
from .stages import run_point
from .stages.estimate import FAMILY_SEARCH_EVALS, INACCURATE_RESOLVE_MAX_SECONDS, MAX_FAMILY_DIM
from .stages.outcome import behind_message
from .structures import STRUCTURE_CACHE

__all__ = ["triangulate", "MAX_FAMILY_DIM", "INACCURATE_RESOLVE_MAX_SECONDS", "FAMILY_SEARCH_EVALS",
           "STRUCTURE_CACHE", "behind_message", "solve_validated"]


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
    cams, regs = validated_problem(cameras, regions)     # (the camera checks remembered for the last cameras)
    if robust is not None:
        from .robust import robust_thresholds

        return solve_validated(cams, regs, robust_thresholds(robust, cams.shape[0]), opts, t0)
    return solve_validated(cams, regs, None, opts, t0)


def solve_validated(cams: np.ndarray, regs, c: np.ndarray | None, opts: TriangulationOptions,
                    t0: float | None = None) -> TriangulationResult:
    """One validated problem: views listed more than once merged (:mod:`tritools.solve.identical_views`, an exact
    reduction), then the TLS search (thresholds ``c``) or the point stages."""
    merge = identical_views(cams, regs, c)
    reduced = None if merge is None else merge.reduce(cams, regs, c)
    if reduced is not None:
        return merge.expand(solve_validated(*reduced, merge.options(opts), t0))
    if c is not None:
        from .robust import triangulate_robust

        return triangulate_robust(cams, regs, c, opts, t0)
    with np.errstate(all="ignore"):     # extreme numbers over- and underflow in steps that check finiteness (as the
        return run_point(cams, regs, opts, t0)     # robust path): numpy's warnings are noise, an error under -W error
