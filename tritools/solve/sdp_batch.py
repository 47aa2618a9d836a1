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
caller solves those with :func:`tritools.triangulate`, so a batch never loses a point.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from sospoly import DEFAULT_TOLERANCES, Tolerances
from sospoly.analysis import image_form_stack_margin
from sospoly.solvers import with_single_threaded_blas

from ..model.geometry import POINT_AT_INFINITY_RTOL
from ..model.normalize import normalization_stack
from ..model.stacked import fundamental_stack, project_stack, refine_points_stack
from ..result import Status
from .decide import decide, decide_reported, gamma_from_c
from .fastpath import stack_point_problems
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
    ``reason`` why a problem was handed back, ``certified_by`` (``"sdp"``, ``"trivial_bound"`` or None).
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


def _chunk_size(N: int) -> int:
    n, m = 2 * N + 1, 1 + N * (N - 1) // 2
    per = 8 * (m * n * n * 3 + n * (n + 1) // 2 * m + m * m)
    return max(1, SDP_CHUNK_BYTES // per)


@with_single_threaded_blas
def solve_corollary1_points(cameras, points2d, *, tolerances: Tolerances = DEFAULT_TOLERANCES,
                            refine: bool = True) -> SdpBatch:
    """The delta = 2 SDP path (module docstring) for M point problems with N views: cameras (M, N, 3, 4)
    in pixels, points2d (M, N, 2) the point regions' centres."""
    C, x, ok = stack_point_problems(cameras, points2d, "solve_corollary1_points")
    M, N = x.shape[:2]
    reason = ["" if k else "invalid or degenerate data" for k in ok]
    tol = tolerances
    norm = normalization_stack(C, x, ok)
    Cn = norm.cameras_n
    F, defined = fundamental_stack(Cn)
    defined &= fundamental_stack(C)[1]          # one centre or not: decided on the raw cameras
    good = norm.ok & np.all(defined, axis=1) & np.all(np.isfinite(F), axis=(1, 2, 3))
    for m in np.nonzero(ok & ~good)[0]:
        reason[m] = "normalisation or epipolar data undefined (e.g. coincident camera centres)"
    ok &= good
    ps = corollary1_point_structure(N)
    comp = ps.compiled
    n = 2 * N + 1
    c_lb = np.full(M, np.nan)
    lam, V = np.tile(np.ones(n), (M, 1)), np.tile(np.eye(n), (M, 1, 1))
    gram_error = np.zeros(M)
    iters = np.zeros(M, int)
    idx = np.nonzero(ok)[0]
    th = ps.thetas(F[idx]) if idx.size else np.zeros((0, comp.n_theta))
    step = _chunk_size(N)
    ipm_tol = dataclasses.replace(tol, ipm_dual_residual_gap=max(tol.ipm_dual_residual_gap,
                                                                 tol.ipm_flat_face_dual_residual_gap))
    for start in range(0, idx.size, step):
        part = idx[start:start + step]
        bb = comp.batch_bounds(th[start:start + step], ipm_tol)
        iters[part], c_lb[part], lam[part], V[part] = bb.iterations, bb.lower_bound, bb.eigenvalues, bb.eigenvectors
        gram_error[part] = bb.gram_error
        for j in np.nonzero(~bb.ok)[0]:
            reason[part[j]] = bb.reason[j]
        ok[part[~bb.ok]] = False
    ok &= np.isfinite(c_lb)
    # ---- extraction: kernel dimension 1, v* = kernel vector / its constant entry
    kdim = tol.kernel_dimension(lam)
    w0 = V[:, 0, 0]
    single = (kdim == 1) & (np.abs(w0) > 1e-12)
    for m in np.nonzero(ok & ~single)[0]:
        reason[m] = f"Gram kernel of dimension {kdim[m]}: kernel-family rule of the per-point path"
    ok &= single
    v = V[:, 1:, 0] / np.where(ok, w0, 1.0)[:, None]
    xn = v.reshape(M, N, 2)
    rows = (Cn[:, :, :2, :] - xn[..., None] * Cn[:, :, 2:3, :]).reshape(M, 2 * N, 4)
    rows = np.where(ok[:, None, None] & np.isfinite(rows), rows, 0.0)
    w = np.linalg.svd(rows)[2][:, -1, :]
    finite = np.abs(w[:, 3]) > POINT_AT_INFINITY_RTOL * np.linalg.norm(w, axis=1)
    for m in np.nonzero(ok & ~finite)[0]:
        reason[m] = "w4 ~ 0 (ill-posed)"
    ok &= finite
    X_raw_n = w[:, :3] / np.where(finite, w[:, 3], 1.0)[:, None]
    u, _, fin = project_stack(Cn, X_raw_n)
    g_raw = np.where(fin, np.sqrt(np.sum(u ** 2, axis=(1, 2)) / (2 * N)), np.inf)
    ok &= np.isfinite(g_raw)
    X_n, g_n = X_raw_n.copy(), g_raw.copy()
    if refine:
        Xr, okr = refine_points_stack(Cn, np.zeros((M, N, 2)), X_raw_n, ok.copy())
        ur, _, finr = project_stack(Cn, Xr)
        gr = np.where(finr & okr, np.sqrt(np.sum(ur ** 2, axis=(1, 2)) / (2 * N)), np.inf)
        better = gr < g_n
        X_n[better], g_n[better] = Xr[better], gr[better]
    c_ub = 2 * N * g_n ** 2
    # rigorous bound (sospoly.analysis.rigor): the observed points are the origin, so f(v) = ||v||^2 and a
    # minimiser has ||v*||^2 = f(v*) <= c_ub; the basis is b = (1, v) (||b||^2 <= 1 + c_ub) and q = 1 (degree 2)
    assert comp.structure.q.degree == 0
    c_lb = c_lb - image_form_stack_margin(lam, gram_error, 1.0 + c_ub, q_min=float(comp.structure.q.coefficients()[0]))
    status, optimal, c_rep = decide(c_lb, c_ub, tol, N, norm.resolution)
    above = ok & (status == Status.NUMERICAL_FAILURE.value)
    for m in np.nonzero(above)[0]:
        reason[m] = "lower bound above the upper bound: per-point tight re-solve"
    ok &= ~above
    X_world = norm.world_points(X_n)
    g_lb = gamma_from_c(c_rep, N, norm.scale)
    u_w, _, fin_w = project_stack(C, X_world)
    g_ub = np.where(fin_w, np.sqrt(np.sum((u_w - x) ** 2, axis=(1, 2)) / (2 * N)), np.inf)
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
    return SdpBatch(ok, status, optimal & ok, c_rep, c_ub, g_lb,
                    X_world, norm.world_points(X_raw_n), x + xn / norm.scale[:, None, None],
                    comp.n_lmivar, iters, reason, by)
