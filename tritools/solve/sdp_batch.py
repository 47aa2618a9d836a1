"""The Corollary 1, delta = 2 SDP path for many point-region problems at once (issue #5).

For M problems with N views and point regions, in the normalised coordinates of
:mod:`tritools.model.normalize` (observed points at the origin of every view, common scale s)
the program of SPEC §5/§7 at delta = 2 (q = 1) is

    max c  s.t.  u(v) = f(v) - c + sum_k r_k g_k(v)  is SOS,
    f = sum_i ||x_i||^2,  g_k = x~_i^T F_ij x~_j (i < j, ||F_ij||_F = 1),

i.e. the (2N+1)x(2N+1) LMI  G(c, r) = G0 - c E00 + sum_k r_k G_k >= 0  on the basis
b(v) = (1, x_11, x_12, ..., x_N2).  This module, with numpy over the whole stack:

1. validates and normalises (the formulas of :func:`tritools.model.normalize.normalization_for`,
   vectorised in :mod:`tritools.solve.fastpath`), computes every F_ij of the normalised cameras
   and fills the compiled structure's coefficient vector theta (the layout of
   :meth:`sospoly.CompiledPsatz.theta`, found once per N from coded template polynomials);
2. solves all the SDPs together with :func:`sospoly.solvers.ipm.ipm_solve_batch`;
3. applies the a-posteriori checks of :func:`sospoly.solvers.solve.check_certificate` (Gram
   matrix recomputed from x, lambda_min >= -psd_margin max(1, max|G_ij|)); c* = the
   objective, gamma_LB = sqrt(max(c*, 0) / (2N)) / s (the paper's (52));
4. extracts v* from the eigenvector of the smallest eigenvalue of the optimal Gram
   matrix scaled to a unit constant entry, X^ from the SVD of M0(v*) (paper (53)),
   refines it with the vectorised Levenberg-Marquardt of :mod:`tritools.solve.fastpath`, and
   decides the certificate in c units exactly as :func:`tritools.triangulate` does.

A problem is *handed back* (``None`` in the output) whenever the batch cannot reproduce
the per-point path's answer with this short route: invalid or degenerate data, an IPM
instance that did not converge (the per-point path's Clarabel fallback), a failed check,
a Gram kernel of dimension > 1 (the per-point kernel-family rule), w4 ~ 0 (ill-posed),
a lower bound above the upper bound (the per-point tight re-solve).  The caller solves
those with :func:`tritools.triangulate` (``path="sdp"``), so a batch never loses a point.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np

from sospoly import DEFAULT_TOLERANCES, GramForm, Multiplier, Polynomial, Tolerances, variables
from sospoly.solvers.blas import with_single_threaded_blas

from .fastpath import _epipolar_data, _normalise, _project_stack, _refine_stack, _stack
from ..model.geometry import POINT_AT_INFINITY_RTOL
from ..result import Status, TriangulationResult

__all__ = ["SdpBatch", "corollary1_structure", "corollary1_thetas", "solve_corollary1_points",
           "sdp_results", "SDP_CHUNK_BYTES"]

#: the dense batched IPM holds ~(m n^2 + n_rows m) floats per instance; chunks stay below this many bytes.
SDP_CHUNK_BYTES = 256 * 2 ** 20


def _gens(N: int) -> tuple:
    names = [f"x{i + 1}_{k + 1}" for i in range(N) for k in range(2)]   # as tritools.model.problem.build_problem
    return variables(names)[0].gens


def _pairs(N: int):
    I, J = np.triu_indices(N, 1)
    return I, J


def corollary1_structure(N: int):
    """(compiled structure, slot index) of the Corollary 1 delta = 2 point-region program with N views.

    The structure is :data:`tritools.solve.triangulate.STRUCTURE_CACHE`'s entry for
    (N, Point x N, corollary1, delta 2, image form), compiled on the full support
    (every F_ij entry may be non-zero).  ``slots`` (K, 3, 3) gives, for constraint k and
    entry F[a, b], its position in theta (F[a, b] multiplies x~_ia x~_jb); ``f_slots``
    the positions of the x_k^2 terms of f.  Found by filling template polynomials with
    coded coefficients 1, 2, 3, ... and reading where :meth:`CompiledPsatz.theta` puts them.
    """
    from .triangulate import STRUCTURE_CACHE

    gens = _gens(N)
    n = 2 * N
    code = 0

    def mono(*ks):
        e = [0] * n
        for k in ks:
            e[k] += 1
        return tuple(e)

    f_terms = {}
    for k in range(n):
        code += 1
        f_terms[mono(k, k)] = float(code)
    eq = []
    I, J = _pairs(N)
    for i, j in zip(I, J):
        terms = {}
        for a in range(3):
            for b in range(3):
                code += 1
                ks = ([2 * i + a] if a < 2 else []) + ([2 * j + b] if b < 2 else [])
                terms[mono(*ks)] = float(code)
        eq.append(Polynomial(gens, terms))
    f = Polynomial(gens, f_terms)
    key = (N, ("Point",) * N, "corollary1", 2, GramForm.IMAGE.value)   # triangulate._structure_key
    comp, _ = STRUCTURE_CACHE.get(f, eq, (), 2, Multiplier.FIXED, GramForm.IMAGE, gens=gens, key=key)
    th = comp.theta(f, eq, ())
    pos = np.full(code + 1, -1, np.int64)
    nz = np.nonzero(th)[0]
    pos[th[nz].astype(np.int64)] = nz
    f_slots = pos[1:n + 1]
    slots = pos[n + 1:].reshape(len(eq), 3, 3)
    return comp, f_slots, slots


def corollary1_thetas(comp_slots, F: np.ndarray) -> np.ndarray:
    """theta (M, n_theta) of M problems from their unit-norm F_ij (M, K, 3, 3); f = sum ||x_i||^2."""
    comp, f_slots, slots = comp_slots
    th = np.zeros((F.shape[0], comp.n_theta))
    th[:, f_slots] = 1.0
    th[:, slots.reshape(-1)] = F.reshape(F.shape[0], -1)
    return th


def _fundamentals(g0, g1, G2, N):
    """F_ij (M, K, 3, 3) back from fastpath's quadratic parts (g0, g1, G2) of x~_i^T F_ij x~_j."""
    I, J = _pairs(N)
    k = np.arange(len(I))
    F = np.zeros(g0.shape + (3, 3))
    F[..., 2, 2] = g0
    for a in range(2):
        F[..., a, 2] = g1[:, k, 2 * I + a]
        F[..., 2, a] = g1[:, k, 2 * J + a]
        for b in range(2):
            F[..., a, b] = 2 * G2[:, k, 2 * I + a, 2 * J + b]
    return F


@dataclass(frozen=True)
class SdpBatch:
    """Per-problem arrays (first axis = problem) of one batched delta = 2 SDP run.

    ``done[m]``: the batch produced problem m's result (else it must go to the per-point
    path); where done: ``c_lower`` = c*, ``c_upper`` = 2N gamma'(X^)^2 (normalised units),
    ``certified`` the certificate test, ``X`` / ``X_raw`` the refined / extracted world
    points, ``gamma_ub`` / ``gamma_ub_raw`` on the caller's data, ``gamma_lb``,
    ``image_points`` (pixels) of v*, ``reason`` why a problem was handed back.
    """
    done: np.ndarray
    certified: np.ndarray
    c_lower: np.ndarray
    c_upper: np.ndarray
    gamma_lb: np.ndarray
    gamma_ub: np.ndarray
    gamma_ub_raw: np.ndarray
    X: np.ndarray
    X_raw: np.ndarray
    image_points: np.ndarray
    n_lmivar: int
    iterations: np.ndarray
    reason: tuple


def _chunk_size(N: int) -> int:
    n, m = 2 * N + 1, 1 + N * (N - 1) // 2
    per = 8 * (m * n * n * 3 + n * (n + 1) // 2 * m + m * m)
    return max(1, SDP_CHUNK_BYTES // per)


@with_single_threaded_blas
def solve_corollary1_points(cameras, points2d, *, tolerances: Tolerances = DEFAULT_TOLERANCES,
                            refine: bool = True) -> SdpBatch:
    """The delta = 2 SDP path (module docstring) for M point problems with N views.

    Parameters
    ----------
    cameras : array (M, N, 3, 4)  (pixels)
    points2d : array (M, N, 2)    the point regions' centres
    """
    C, x, ok = _stack(cameras, points2d, "solve_corollary1_points")
    M, N = x.shape[:2]
    reason = [""] * M
    tol = tolerances
    for m in np.nonzero(~ok)[0]:
        reason[m] = "invalid or degenerate data"
    s, origin, depth, Cn, ok_n, _ = _normalise(C, x)
    g0, g1, G2, ok_f = _epipolar_data(Cn)
    for m in np.nonzero(ok & ~(ok_n & ok_f))[0]:
        reason[m] = "normalisation or epipolar data undefined"
    ok &= ok_n & ok_f
    cs = corollary1_structure(N)
    comp = cs[0]
    F = _fundamentals(g0, g1, G2, N)
    n = 2 * N + 1
    c_lb = np.full(M, np.nan)
    lam, V = np.tile(np.ones(n), (M, 1)), np.tile(np.eye(n), (M, 1, 1))
    iters = np.zeros(M, int)
    idx = np.nonzero(ok)[0]
    th = corollary1_thetas(cs, F[idx]) if idx.size else np.zeros((0, comp.n_theta))
    step = _chunk_size(N)
    ipm_tol = dataclasses.replace(tol, ipm_dual_residual_gap=max(tol.ipm_dual_residual_gap,
                                                                        tol.ipm_flat_face_dual_residual_gap))
    for start in range(0, idx.size, step):
        part = idx[start:start + step]
        bb = comp.batch_bounds(th[start:start + step], ipm_tol)
        iters[part], c_lb[part], lam[part], V[part] = bb.iterations, bb.lower_bound, bb.eigenvalues, bb.eigenvectors
        for j in np.nonzero(~bb.ok)[0]:
            reason[part[j]] = bb.reason[j]
        ok[part[~bb.ok]] = False
    ok &= np.isfinite(c_lb)
    # ---- extraction: kernel dimension 1, v* = kernel vector / its constant entry (sospoly.analysis.extraction)
    top = np.maximum(np.abs(lam[:, -1]), 1e-300)
    kdim = np.maximum(1, np.sum(lam <= tol.kernel_rel * top[:, None], axis=1))
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
    u, _, fin = _project_stack(Cn, X_raw_n)
    g_raw = np.where(fin, np.sqrt(np.sum(u ** 2, axis=(1, 2)) / (2 * N)), np.inf)
    ok &= np.isfinite(g_raw)
    X_n, g_n = X_raw_n.copy(), g_raw.copy()
    if refine:
        Xr, okr = _refine_stack(Cn, np.zeros((M, N, 2)), X_raw_n, ok.copy())
        ur, _, finr = _project_stack(Cn, Xr)
        gr = np.where(finr & okr, np.sqrt(np.sum(ur ** 2, axis=(1, 2)) / (2 * N)), np.inf)
        better = gr < g_n
        X_n[better], g_n[better] = Xr[better], gr[better]
    c_ub = 2 * N * g_n ** 2
    X = origin + depth[:, None] * X_n
    X_raw = origin + depth[:, None] * X_raw_n

    def gamma_world(Xw):
        uw, _, fw = _project_stack(C, Xw)
        return np.where(fw, np.sqrt(np.sum((uw - x) ** 2, axis=(1, 2)) / (2 * N)), np.inf)

    gamma_ub, gamma_raw = gamma_world(X), gamma_world(X_raw)
    gap_tol = tol.gap_abs + tol.gap_rel * np.maximum(1.0, np.abs(c_ub))
    certified = ok & (c_ub - c_lb <= gap_tol)
    above = ok & (c_lb - c_ub > tol.gap_abs + tol.gap_rel * np.maximum(1.0, c_ub))
    for m in np.nonzero(above)[0]:
        reason[m] = "lower bound above the upper bound: per-point tight re-solve"
    ok &= ~above & np.isfinite(gamma_ub) & np.isfinite(gamma_raw)
    gamma_lb = np.sqrt(np.maximum(c_lb, 0.0) / (2 * N)) / s
    reason = [("" if done else r) for done, r in zip(ok, reason)]
    return SdpBatch(ok, certified & ok, c_lb, c_ub, gamma_lb, gamma_ub, gamma_raw, X, X_raw,
                    x + xn / s[:, None, None], comp.n_lmivar, iters, tuple(reason))


def sdp_results(cameras, points2d, *, tolerances: Tolerances = DEFAULT_TOLERANCES, refine: bool = True,
                final: bool = False, method: str = "corollary1") -> list[TriangulationResult | None]:
    """:func:`solve_corollary1_points` as :class:`TriangulationResult` objects (``delta=2``).

    A problem gets a result when the batch decided it and it is certified -- or, with
    ``final=True`` (delta = 2 is the last degree the caller tries), also when it is not
    certified (status NOT_CERTIFIED, as ``triangulate(..., 2, 2, path="sdp")``).  Otherwise
    ``None``: solve it per point.  ``timings`` hold each problem's share of the batch time.
    """
    t0 = time.perf_counter()
    out = solve_corollary1_points(cameras, points2d, tolerances=tolerances, refine=refine)
    M = len(out.done)
    share = (time.perf_counter() - t0) / max(M, 1)
    results: list[TriangulationResult | None] = [None] * M
    for m in np.nonzero(out.done & (out.certified | final))[0]:
        opt = bool(out.certified[m])
        status = Status.OPTIMAL if opt else Status.NOT_CERTIFIED
        lb, ub = float(out.gamma_lb[m]), float(out.gamma_ub[m])
        results[m] = TriangulationResult(
            method=method, status=status, X=out.X[m], gamma_ub=ub, gamma_lb=lb, optimal=opt, delta=2,
            n_lmivar=out.n_lmivar, image_points=out.image_points[m], X_raw=out.X_raw[m],
            gamma_ub_raw=float(out.gamma_ub_raw[m]), certified_by="sdp" if opt else None,
            timings={"solve_d2": share, "total": share},
            attempts=((2, status.value, lb, ub, ("ipm-batch:converged",)),))
    return results
