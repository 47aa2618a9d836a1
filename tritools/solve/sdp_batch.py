"""The Corollary 1, delta = 2 SDP for many point-region problems at once.

For M problems with N views and point regions, in the normalised coordinates of
:mod:`tritools.model.normalize` (observed points at the origin of every view, common scale s) the
program of SPEC §5/§7 at delta = 2 (q = 1) is

    max c  s.t.  u(v) = f(v) - c + sum_k r_k g_k(v)  is SOS,
    f = sum_i ||x_i||^2,  g_k = x~_i^T F_ij x~_j (i < j, ||F_ij||_F = 1),

i.e. the (2N+1)x(2N+1) LMI on the basis b(v) = (1, x_11, ..., x_N2).  With numpy over the stack:

1. normalise (:func:`tritools.model.normalize.normalization_stack`), compute every F_ij of the
   normalised cameras (:func:`tritools.model.stacked.fundamental_stack`) and fill theta through the
   public data slots of the compiled structure (:func:`tritools.solve.structures.corollary1_point_structure`);
2. solve all SDPs together and check every Gram matrix
   (:meth:`sospoly.CompiledPsatz.batch_bounds`); gamma_LB from c* (the paper's (52));
3. extract v* from the Gram kernel (dimension 1: :meth:`sospoly.Tolerances.kernel_dimension`), X^ from
   the SVD of M0(v*) (paper (53)), refine it with the vectorised Levenberg-Marquardt, and decide with
   :func:`tritools.solve.decide.decide` (the rule of every path); what c_LB does not certify is certified
   through the trivial bound 0 when gamma(X^) is within the tolerance of it (:mod:`tritools.solve.trivial`).

A problem is *handed back* (``done = False``) whenever the batch cannot reproduce the per-point path's
answer with this short route: invalid data, an IPM instance that did not converge (the per-point
path's Clarabel fallback), a failed check, a Gram kernel of dimension > 1 (the per-point
kernel-family rule), w4 ~ 0 (ill-posed), contradicting bounds (the per-point tight re-solve).  The
caller solves those with :func:`tritools.triangulate`, so a batch never loses a point.  A ``deadline``
(:mod:`tritools.solve.settings`) is checked before the compilation and before every chunk of the IPM;
the problems not reached by then are handed back ("time limit").

This is the registered fast implementation of the ``sdp`` stage (:mod:`tritools.solve.stages.sdp`) for
its case; the kernel test is sospoly's (:func:`sospoly.analysis.has_constant_entry`), gamma is
:func:`tritools.solve.decide.gamma_from_c`.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from sospoly import DEFAULT_TOLERANCES, Tolerances, n_lmivar_formula
from sospoly.analysis import constraint_error_stack, has_constant_entry, image_form_stack_margin
from sospoly.budget import Deadline, TimeLimitReached, deadline_scope
from sospoly.solvers import with_single_threaded_blas

from ..model.frame import project_world
from ..model.geometry import POINT_AT_INFINITY_RTOL
from ..model.normalize import normalization_stack
from ..model.stacked import fundamental_stack_both, norms, project_stack, refine_points_stack
from ..result import Status
from .decide import decide, decide_reported, gamma_from_c, gamma_lower, transfer_contradicts
from .report import gamma_upper
from .fastpath import expired, stack_point_problems
from .structures import corollary1_point_structure
from .trivial import TRIVIAL_BOUND, trivially_certified, trivially_certified_reported

__all__ = ["SdpBatch", "solve_corollary1_points", "SDP_CHUNK_BYTES"]

#: the dense batched IPM holds ~(m n^2 + n_rows m) floats per instance; chunks stay below this many bytes.
SDP_CHUNK_BYTES = 256 * 2 ** 20


@dataclass(frozen=True)
class SdpBatch:
    """Per-problem arrays (first axis = problem) of one batched delta = 2 SDP run.

    ``done[m]``: the batch produced problem m's result (else it must go to the per-point path); where
    done: ``c_lower`` / ``c_upper`` (normalised units), ``status`` and ``optimal`` of the decision,
    ``X`` / ``X_raw`` the refined / extracted world points, ``gamma_lb``, ``image_points`` (pixels) of v*,
    ``reason`` why a problem was handed back, ``certified_by`` (``"sdp"``, ``"trivial_bound"`` or None),
    ``scale`` the normalisation's image scale s.
    """
    done: np.ndarray
    status: np.ndarray
    optimal: np.ndarray
    c_lower: np.ndarray
    c_upper: np.ndarray
    gamma_lb: np.ndarray
    X: np.ndarray
    X_raw: np.ndarray
    image_points: np.ndarray
    n_lmivar: int
    iterations: np.ndarray
    reason: tuple
    certified_by: np.ndarray
    scale: np.ndarray | None = None


def _chunk_size(N: int) -> int:
    n, m = 2 * N + 1, 1 + N * (N - 1) // 2
    per = 8 * (m * n * n * 3 + n * (n + 1) // 2 * m + m * m)
    return max(1, SDP_CHUNK_BYTES // per)


def _hand_back(ok: np.ndarray, bad: np.ndarray, reason: list, why) -> None:
    """Mark the problems ``ok & bad`` as handed back with ``why`` (a string or a function of the index)."""
    for m in np.nonzero(ok & bad)[0]:
        reason[m] = why(m) if callable(why) else why
    ok &= ~bad


@with_single_threaded_blas
def solve_corollary1_points(cameras, points2d, *, tolerances: Tolerances = DEFAULT_TOLERANCES,
                            refine: bool = True, deadline: Deadline | None = None,
                            scalar: bool | None = None) -> SdpBatch:
    """The delta = 2 SDP path (module docstring) for M point problems with N views: cameras (M, N, 3, 4)
    in pixels, points2d (M, N, 2) the point regions' centres.  ``scalar``: as in
    :func:`tritools.model.stacked.refine_points_stack` (None: a stack of one normalised and refined by the scalar
    twins; False: the stacked code, so a problem's numbers do not depend on the other rows of its stack)."""
    C, x, ok = stack_point_problems(cameras, points2d, "solve_corollary1_points")
    M, N = x.shape[:2]
    if expired(deadline):                       # nothing started past the deadline (the epipolar data: ~0.4 s at
        return _handed_back(C, x, ["time limit reached before the batched SDP"] * M)    # 6 x 100 views)
    reason = ["" if k else "invalid or degenerate data" for k in ok]
    norm = normalization_stack(C, x, ok, scalar=scalar)
    Cn = norm.cameras_n
    F, defined, raw, E = fundamental_stack_both(Cn, C)
    defined &= raw                              # one centre or not: decided on the raw cameras too
    good = norm.ok & np.all(defined, axis=1) & np.all(np.isfinite(F), axis=(1, 2, 3))
    _hand_back(ok, ~good, reason, "normalisation or epipolar data undefined (e.g. coincident camera centres)")
    solved = _solve_stack(F, ok, N, tolerances, reason, deadline)
    if solved is None:                          # the compilation ran out of time: every problem handed back
        return _handed_back(C, x, reason)
    c_lb, lam, V, gram_error, iters, comp, xs = solved
    X_raw_n, xn = _extract(V, lam, Cn, ok, reason, tolerances)
    X_n, g_n = _refined(Cn, X_raw_n, ok, refine, scalar)
    c_ub = 2 * N * g_n ** 2
    # rigorous bound (sospoly.analysis.rigor): the observed points are the origin, so f(v) = ||v||^2 and a
    # minimiser has ||v*||^2 = f(v*) <= c_ub; the basis is b = (1, v) (||b||^2 <= 1 + c_ub) and q = 1 (degree 2)
    assert comp.structure.q.degree == 0
    c_lb = c_lb - image_form_stack_margin(lam, gram_error, 1.0 + c_ub, q_min=float(comp.structure.q.coefficients()[0]))
    c_lb = c_lb - _data_error(comp, xs, Cn, F, E, ok, c_ub)
    return _decided(C, x, norm, ok, reason, tolerances, c_lb, c_ub, X_n, X_raw_n, xn, comp, iters)


def _data_error(comp, xs, Cn, F, E, ok, c_ub) -> np.ndarray:
    """(M,) sum_k |r_k| e_k: the certificates' multipliers r_k (constants at degree 2) times bounds e_k of the computed
    constraints at a true minimiser v* (exactly feasible for the exact fundamental matrices of the normalised float
    cameras): |g~_k(v*)| <= ||F~_k - lambda F_k||_F ||v~*_i|| ||v~*_j|| <= that norm times (1 + ||v*||^2 / 2), with
    ||v*||^2 <= c_ub (E: :func:`tritools.model.stacked.fundamental_stack`'s proven ``errors``;
    :func:`sospoly.analysis.rigor.constraint_error_stack`).  0 for the problems not solved."""
    M, N = Cn.shape[:2]
    if not ok.any() or not F.shape[1]:
        return np.zeros(M)
    E = np.where(ok[:, None], E, 0.0)
    with np.errstate(invalid="ignore", over="ignore"):
        e = E * (1.0 + np.where(ok, c_ub, 0.0) / 2)[:, None]
    out = constraint_error_stack(comp.structure, np.where(ok[:, None], xs, 0.0), np.sqrt(np.where(ok, c_ub, 0.0)), e)
    return np.where(ok, out, 0.0)


def _solve_stack(F, ok, N: int, tol: Tolerances, reason: list, deadline):
    """(c* (M,), Gram eigenvalues (M, n), eigenvectors (M, n, n), Gram error (M,), IPM iterations (M,), compiled
    structure): every SDP of the stack, in chunks below SDP_CHUNK_BYTES, the deadline checked before the
    compilation and before every chunk; ``ok`` and ``reason`` updated in place.  None when the compilation
    ran out of time."""
    M = len(ok)
    n = 2 * N + 1
    c_lb = np.full(M, np.nan)
    lam, V = np.tile(np.ones(n), (M, 1)), np.tile(np.eye(n), (M, 1, 1))
    gram_error, iters, xs = np.zeros(M), np.zeros(M, int), None
    try:
        with deadline_scope(deadline):
            ps = corollary1_point_structure(N)
    except TimeLimitReached:
        _hand_back(ok, np.ones(M, bool), reason, "time limit reached while compiling the batched SDP")
        return None
    comp = ps.compiled
    idx = np.nonzero(ok)[0]
    th = ps.thetas(F[idx]) if idx.size else np.zeros((0, comp.n_theta))
    step = _chunk_size(N)
    ipm_tol = dataclasses.replace(tol, ipm_dual_residual_gap=max(tol.ipm_dual_residual_gap,
                                                                 tol.ipm_flat_face_dual_residual_gap))
    for start in range(0, idx.size, step):
        part = idx[start:start + step]
        if expired(deadline):
            late = np.zeros(M, bool)
            late[idx[start:]] = True
            _hand_back(ok, late, reason, "time limit reached before its SDP chunk")
            break
        bb = comp.batch_bounds(th[start:start + step], ipm_tol, deadline)
        iters[part], c_lb[part], lam[part], V[part] = bb.iterations, bb.lower_bound, bb.eigenvalues, bb.eigenvectors
        gram_error[part] = bb.gram_error
        if xs is None:
            xs = np.zeros((M, bb.x.shape[1]))
        xs[part] = bb.x
        for j in np.nonzero(~bb.ok)[0]:
            reason[part[j]] = bb.reason[j]
        ok[part[~bb.ok]] = False
    ok &= np.isfinite(c_lb)
    return c_lb, lam, V, gram_error, iters, comp, (np.zeros((M, 0)) if xs is None else xs)


def _extract(V, lam, Cn, ok, reason: list, tol: Tolerances) -> tuple[np.ndarray, np.ndarray]:
    """(X^, v* as (M, N, 2) image points) in the normalised frame, from the Gram kernel of dimension 1 (v* =
    kernel vector / its constant entry, the kernel test of :func:`sospoly.analysis.has_constant_entry`) and
    the SVD of M0(v*) (paper (53))."""
    M = len(ok)
    N = Cn.shape[1]
    kdim = tol.kernel_dimension(lam)
    single = (kdim == 1) & has_constant_entry(V[:, :, 0])
    _hand_back(ok, ~single, reason, lambda m: f"Gram kernel of dimension {kdim[m]}: kernel-family rule of the "
                                              f"per-point path")
    xn = (V[:, 1:, 0] / np.where(ok, V[:, 0, 0], 1.0)[:, None]).reshape(M, N, 2)
    rows = (Cn[:, :, :2, :] - xn[..., None] * Cn[:, :, 2:3, :]).reshape(M, 2 * N, 4)
    rows = np.where(ok[:, None, None] & np.isfinite(rows), rows, 0.0)
    w = np.linalg.svd(rows)[2][:, -1, :]
    finite = np.abs(w[:, 3]) > POINT_AT_INFINITY_RTOL * np.linalg.norm(w, axis=1)
    _hand_back(ok, ~finite, reason, "w4 ~ 0 (ill-posed)")
    return w[:, :3] / np.where(finite, w[:, 3], 1.0)[:, None], xn


def _handed_back(C, x, reason: list) -> SdpBatch:
    """Every problem handed back (nothing solved)."""
    M, N = x.shape[:2]
    nan = np.full(M, np.nan)
    return SdpBatch(np.zeros(M, bool), np.full(M, None, dtype=object), np.zeros(M, bool), nan, nan.copy(),
                    nan.copy(), np.full((M, 3), np.nan), np.full((M, 3), np.nan), np.full((M, N, 2), np.nan),
                    n_lmivar_formula(2 * N, 2, [2] * (N * (N - 1) // 2)), np.zeros(M, int), tuple(reason),
                    np.full(M, None, dtype=object))


def _gamma_n(Cn, X, usable) -> np.ndarray:
    """gamma of the normalised problems (observed points at the origin) at X; inf where not ``usable``."""
    u, _, fin = project_stack(Cn, X)
    return np.where(fin & usable, gamma_from_c(np.sum(u ** 2, axis=(1, 2)), Cn.shape[1], 1.0), np.inf)


def _refined(Cn, X_raw_n, ok, refine: bool, scalar: bool | None = None):
    """(X_n, gamma_n): the extracted points, replaced by their Levenberg-Marquardt refinement where better."""
    M, N = Cn.shape[:2]
    g_raw = _gamma_n(Cn, X_raw_n, np.ones(M, bool))
    ok &= np.isfinite(g_raw)
    X_n, g_n = X_raw_n.copy(), g_raw.copy()
    if refine:
        Xr, okr = refine_points_stack(Cn, np.zeros((M, N, 2)), X_raw_n, ok.copy(), scalar=scalar)
        gr = _gamma_n(Cn, Xr, okr)
        better = gr < g_n
        X_n[better], g_n[better] = Xr[better], gr[better]
    return X_n, g_n


def _decided(C, x, norm, ok, reason, tol, c_lb, c_ub, X_n, X_raw_n, xn, comp, iters) -> SdpBatch:
    """The decision of every path (:func:`tritools.solve.decide.decide`), confirmed on the reported numbers,
    then the trivial bound (:mod:`tritools.solve.trivial`)."""
    N = x.shape[1]
    status, optimal, c_rep = decide(c_lb, c_ub, tol, N, norm.resolution)
    _hand_back(ok, status == Status.NUMERICAL_FAILURE.value, reason,
               "lower bound above the upper bound: per-point tight re-solve")
    X_world = norm.world_points(X_n)
    u_w, _, fin_w = project_world(C, X_world)
    g_ub = np.where(fin_w, gamma_upper(norms(u_w - x, axis=2), norms(u_w, axis=2)), np.inf)
    g_lb = gamma_lower(gamma_from_c(c_rep, N, norm.scale), g_ub, norm.scale, norm.lowering_resolution,
                       norm.magnitudes_at(C, X_world))
    _hand_back(ok, transfer_contradicts(g_lb, g_ub, tol, N, norm.scale), reason,
               "the lower bound transferred to the caller's data lies above gamma(X): per-point re-solve")
    reported = decide_reported(g_lb, g_ub, tol, N, norm.scale, norm.resolution)
    for m in np.nonzero(ok & optimal & ~reported)[0]:
        reason[m] = "the bounds met in normalised coordinates, but not at the estimate in world coordinates"
    status = np.where(optimal & ~reported, Status.NOT_CERTIFIED.value, status)
    optimal = optimal & reported
    trivial = ok & ~optimal & trivially_certified(c_ub, tol, N, norm.resolution) & \
        trivially_certified_reported(g_ub, tol, N, norm.scale, norm.resolution)
    status = np.where(trivial, Status.OPTIMAL.value, status)
    optimal, c_rep, g_lb = optimal | trivial, np.where(trivial, 0.0, c_rep), np.where(trivial, 0.0, g_lb)
    by = np.where(trivial, TRIVIAL_BOUND, np.where(optimal, "sdp", None))
    reason = tuple("" if done else r for done, r in zip(ok, reason))
    return SdpBatch(ok, status, optimal & ok, c_rep, c_ub, g_lb, X_world, norm.world_points(X_raw_n),
                    x + xn / norm.scale[:, None, None], comp.n_lmivar, iters, reason, by, norm.scale)
