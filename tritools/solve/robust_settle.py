"""A TLS problem settled by its L2 certificate (:mod:`tritools.solve.robust_batch`'s step 2, and the single call's
first step for problems with regions other than points: one rule for both).

A certified L2 result with every residual below its threshold and 2N gamma_UB^2 <= min_i c_i^2 certifies the TLS
problem: any inlier set other than all views pays at least min_i c_i^2 >= f_TLS(X), so f_TLS* = L2*, and the L2
bounds (already bounds of the caller's data) are the TLS bounds.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from ..model.regions import as_regions
from ..result import Attempt, TriangulationResult
from .options import MethodChoice
from .stages.outcome import behind_message

__all__ = ["settled_by_l2", "l2_suffices", "first_pass", "settle_by_l2"]


def settled_by_l2(res: TriangulationResult) -> TriangulationResult:
    """An L2 result that settles the TLS problem (module docstring, 2) in the TLS result's form, as the single call
    gives it for the same problem (its root bound, the L2 bound of all views, settles it the same way, review 8 F8):
    method ``tls``, every view an inlier, certified by the branch and bound's root (0 nodes), one TLS attempt.  The
    numbers are the L2 certificate's (f_TLS = f_L2 at X, and TLS* = L2* there)."""
    n = len(res.residuals)
    total = float(res.timings.get("total", 0.0)) if res.timings else 0.0
    attempt = Attempt("tls", None, res.status.value, res.gamma_lb, res.gamma_ub, "branch-and-bound", None, (), total)
    msg = f"TLS: {n}/{n} inliers, 0 nodes, 1 L2 sub-problems"
    if res.optimal and res.in_front is False and res.depths is not None:     # as the L2 message says it (33a L9)
        msg += f"; {behind_message(res.depths, 'TLS')}"
    return dataclasses.replace(res, method="tls", certified_by="branch-and-bound", inliers=np.ones(n, bool),
                               message=msg, attempts=(attempt,))


def l2_suffices(res: TriangulationResult, c: np.ndarray, cameras, regions, tolerances) -> bool:
    """Whether the certified L2 result settles the TLS problem: every residual below its threshold, f_L2 <= min c^2,
    and its gap within the TLS report's guard (:func:`tritools.solve.robust_report.guards_pass` on the coordinates'
    resolution capped by the thresholds' scale, as a single call's report checks it; review 12 F2: a 0.0144 px
    threshold settled by an L2 certificate whose gap passed only the L2 guard)."""
    from .robust_report import guards_pass, reported_resolution

    if not res.optimal or res.residuals is None or res.gamma_ub is None or res.gamma_lb is None:
        return False
    n = len(res.residuals)
    if not (np.all(res.residuals < c) and 2 * n * res.gamma_ub ** 2 <= np.min(c * c)):
        return False
    centres = np.array([r.center for r in as_regions(regions, n)], float)
    return guards_pass(res.gamma_lb, res.gamma_ub, n, tolerances,
                       reported_resolution(centres, c, tolerances, np.asarray(cameras, float)))


def first_pass(opts):
    """The options of (2)'s L2 pass: the default plan stops at degree 2 (verification, the batched degree-2 SDP);
    a problem it does not settle gets the branch and bound, whose sub-problems take the full plan where the search
    needs them, as a single call's do.  The full plan here ran a dense degree-4 program (~6 s) on every 3-view disc
    track with a wrong match, whose L2 result cannot settle it (review 31b F3: 2.2 s per track in a batch, 0.15 s
    alone).  Explicit methods and degrees are the caller's and kept."""
    if opts.method == MethodChoice.AUTO and opts.delta is None and opts.max_delta is None:
        return opts.replace(max_delta=2)
    return opts


def settle_by_l2(cams, regions, c: np.ndarray, opts) -> tuple:
    """The single call's first step for a problem with regions other than points (module docstring): (the TLS
    result when the L2 result under :func:`first_pass`'s options settles the problem (:func:`l2_suffices`), else
    None; that L2 result when it is the search's root solve -- the degree-2 plan, which the search then takes instead
    of solving it again (:meth:`tritools.solve.robust_bounds.SubsetBounds.seed`) -- else None).  A batch settles the
    same problems the same way (review 40a M2: a batch certified what the single call's search left uncertified, its
    report lowering the same bound again)."""
    from .triangulate import triangulate

    options = first_pass(opts)
    try:
        res = triangulate(cams, regions, options=options)
    except (ValueError, TypeError, ArithmeticError, np.linalg.LinAlgError):
        return None, None
    if l2_suffices(res, c, cams, regions, opts.tolerances):
        return settled_by_l2(res), None
    return None, (res if options is not opts else None)    # (max_delta = 2: the search's light root solve)
