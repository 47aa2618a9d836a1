"""Certification by verification for many point-region problems at once (issue #5).

For M problems with the same number N of views and point regions, the Corollary 1
program at delta = 2 (SPEC §7) is, in the normalised coordinates of
:mod:`tritools.model.normalize` (observed points at the origin of every view),

    f(v) = sum_i ||x_i - x^_i||^2,   g_ij(v) = x~_i^T F_ij x~_j (i < j),   v = (x_1, ..., x_N),

f and every g_ij quadratic.  For each problem this module

1. computes the normalisation of :func:`tritools.model.normalize.normalization_for`
   (same formulas, vectorised: scale s from the residual of the locally refined
   estimate, shifts = observed points, world origin = DLT estimate, depth = median
   camera distance);
2. finds a local minimiser of the L2 reprojection error from the DLT estimate by a
   vectorised Levenberg-Marquardt iteration on the 2N residuals Phi(X, P_i) - x^_i;
3. takes v^ = (Phi(X, P_1), ..., Phi(X, P_N)) -- a feasible point of g = 0 -- and the
   epipolar polynomials with F_ij = [e]_x P_i P_j^+ / ||.||_F of the normalised cameras;
4. calls :func:`sospoly.analysis.verify.verify_quadratic_batch`: KKT multipliers by least
   squares, PSD test of the Lagrangian Hessian with the ROUNDOFF margin, exact minimum
   c of the Lagrangian quadratic, certificate ``Tolerances.certified(c, f(v^))``.

The lower bound gamma_LB = sqrt(max(c, 0) / (2N)) / s comes from the polynomial data
and the multipliers only; the local solver merely proposes v^.  Every step is a numpy
operation over the stack of problems (no per-problem Python loop).  Problems whose data
the vectorised code cannot handle (degenerate cameras, DLT at infinity, coincident
centres, LM failure) are simply not certified here: the caller sends them through
:func:`tritools.triangulate`, which reports the proper status.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sospoly import DEFAULT_TOLERANCES, Tolerances, n_lmivar_formula
from sospoly.analysis.verify import verify_quadratic_batch
from sospoly.solvers.blas import with_single_threaded_blas

from ..model.geometry import (POINT_AT_INFINITY_RTOL, PROJECTION_DENOM_RTOL, SAME_CAMERA_RTOL,
                       SAME_CENTER_RTOL)
from ..model.normalize import RHO_FLOOR_REL, SCALE_BOUNDS
from ..result import Status, TriangulationResult

__all__ = ["FastPathBatch", "verify_points", "fast_results", "LM_MAX_ITER", "LM_STEP_RTOL", "FAST_RANK_RTOL"]

#: Levenberg-Marquardt iterations at most (from the DLT start it converges in ~5-10).
LM_MAX_ITER = 100
#: a problem's iteration stops when its step is below LM_STEP_RTOL * (1 + ||X||) (normalised units, X ~ 1).
LM_STEP_RTOL = 1e-13
#: cameras with sigma_3 / sigma_1 below this (cheap bound) go to the per-problem path (its exact test is 1e-10).
FAST_RANK_RTOL = 1e-8


@dataclass(frozen=True)
class FastPathBatch:
    """Per-problem arrays (first axis = problem) of one vectorised fast-path run.

    ``certified[m]`` says whether problem m was certified; the other fields are
    meaningful where ``ok[m]`` (a candidate and a bound were computed): ``X`` the world
    point, ``gamma_ub`` = gamma(X) on the caller's data, ``gamma_lb`` from the
    Lagrangian bound (NaN when none), ``image_points`` v^ in pixels, ``c_lower`` /
    ``c_upper`` the bound and f(v^) in the normalised units where the certificate is
    decided, ``scale`` the common image scale s.
    """
    certified: np.ndarray
    ok: np.ndarray
    X: np.ndarray
    gamma_ub: np.ndarray
    gamma_lb: np.ndarray
    image_points: np.ndarray
    c_lower: np.ndarray
    c_upper: np.ndarray
    scale: np.ndarray


def _cofactor_null(P: np.ndarray) -> np.ndarray:
    """Null vectors a (P a = 0) of a stack of 3x4 matrices (..., 3, 4), from the signed 3x3 minors
    (a_k = (-1)^k det P[:, columns != k]); ||a||^2 = det(P P^T) (Cauchy-Binet), 0 iff rank P < 3."""
    def det3(c0, c1, c2):
        A = np.stack([P[..., :, c0], P[..., :, c1], P[..., :, c2]], axis=-1)
        return (A[..., 0, 0] * (A[..., 1, 1] * A[..., 2, 2] - A[..., 1, 2] * A[..., 2, 1])
                - A[..., 0, 1] * (A[..., 1, 0] * A[..., 2, 2] - A[..., 1, 2] * A[..., 2, 0])
                + A[..., 0, 2] * (A[..., 1, 0] * A[..., 2, 1] - A[..., 1, 1] * A[..., 2, 0]))
    return np.stack([det3(1, 2, 3), -det3(0, 2, 3), det3(0, 1, 3), -det3(0, 1, 2)], axis=-1)


def _smallest_eigvec(A: np.ndarray) -> np.ndarray:
    """Unit right singular vector of the smallest singular value of each A (M, p, 4): the
    eigenvector of the smallest eigenvalue of A^T A (4x4, one batched eigh)."""
    return np.linalg.eigh(np.einsum("mki,mkj->mij", A, A))[1][..., 0]


def _dlt_stack(C: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`tritools.model.geometry.dlt` for a stack: C (M, N, 3, 4), x (M, N, 2) -> (X (M, 3), ok (M,))."""
    c = x.mean(axis=1)                                                     # (M, 2)
    dist = np.linalg.norm(x - c[:, None], axis=2).mean(axis=1)
    cmax = np.abs(c).max(axis=1)
    small = dist <= 1e-12 * (1.0 + cmax)
    s = np.where(small, 1.0 / (1.0 + cmax), np.sqrt(2.0) / np.where(small, 1.0, dist))
    T = np.zeros((len(x), 3, 3))
    T[:, 0, 0] = T[:, 1, 1] = s
    T[:, :2, 2] = -s[:, None] * c
    T[:, 2, 2] = 1.0
    xn = s[:, None, None] * (x - c[:, None])
    Cn = np.einsum("mab,mnbc->mnac", T, C)
    A = (Cn[:, :, :2, :] - xn[..., None] * Cn[:, :, 2:3, :]).reshape(len(x), -1, 4)
    norms = np.linalg.norm(A, axis=2, keepdims=True)
    A = A / np.where(norms > 0, norms, 1.0)
    w = _smallest_eigvec(A)
    ok = np.abs(w[:, 3]) > POINT_AT_INFINITY_RTOL
    return w[:, :3] / np.where(ok, w[:, 3], 1.0)[:, None], ok


def _project_stack(C: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Projections Phi(X_m, P_mi) (M, N, 2), homogeneous images (M, N, 3) and a finite mask (M,)."""
    Xh = np.concatenate([X, np.ones((len(X), 1))], axis=1)
    h = np.einsum("mnij,mj->mni", C, Xh)
    den = h[..., 2]
    tiny = np.abs(den) <= PROJECTION_DENOM_RTOL * np.linalg.norm(C[:, :, 2, :], axis=2) * \
        np.linalg.norm(Xh, axis=1)[:, None]
    x = h[..., :2] / np.where(tiny, 1.0, den)[..., None]
    ok = ~np.any(tiny, axis=1) & np.all(np.isfinite(x), axis=(1, 2))
    return x, h, ok


def _valid_cameras(C: np.ndarray) -> np.ndarray:
    """The checks of :func:`tritools.model.geometry.validate_cameras` (finite, rank 3, not all equal), per problem.

    Rank: sigma_3^2 / sigma_1^2 >= det(P P^T) / trace(P P^T)^3 (the product of the squared singular
    values over the cube of their sum), required above ``FAST_RANK_RTOL^2``; cameras failing this
    cheap, conservative test are left to the per-problem path and its exact SVD test.
    """
    finite = np.all(np.isfinite(C), axis=(1, 2, 3))
    Cs = np.where(finite[:, None, None, None], C, 0.0)
    tr = np.sum(Cs ** 2, axis=(2, 3))
    det = np.sum(_cofactor_null(Cs) ** 2, axis=2)
    rank3 = np.all(det > FAST_RANK_RTOL ** 2 * np.maximum(tr, 1e-300) ** 3, axis=1)
    U = Cs / np.maximum(np.sqrt(tr), 1e-300)[:, :, None, None]
    diff = np.minimum(np.linalg.norm(U - U[:, :1], axis=(2, 3)), np.linalg.norm(U + U[:, :1], axis=(2, 3)))
    distinct = ~np.all(diff <= SAME_CAMERA_RTOL, axis=1)
    return finite & rank3 & distinct


def _stack(cameras, points2d, caller: str):
    """(cameras (M, N, 3, 4), points2d (M, N, 2), ok (M,)) as float arrays, shapes checked.

    Problems with non-finite or degenerate data get ``ok = False`` and harmless stand-in
    numbers (identity-like cameras, zero points) so the vectorised code runs on the rest."""
    C = np.asarray(cameras, float)
    x = np.asarray(points2d, float)
    if C.ndim != 4 or C.shape[2:] != (3, 4) or x.shape != C.shape[:2] + (2,) or C.shape[1] < 2:
        raise ValueError(f"{caller}: cameras must be (M, N, 3, 4) and points2d (M, N, 2) with N >= 2, "
                         f"got {C.shape} and {x.shape}")
    ok = _valid_cameras(C) & np.all(np.isfinite(x), axis=(1, 2))
    C = np.where(ok[:, None, None, None], C, np.eye(3, 4))
    x = np.where(ok[:, None, None], x, 0.0)
    return C, x, ok


def _normalise(C: np.ndarray, x: np.ndarray):
    """Vectorised :func:`tritools.model.normalize.normalization_for` and the normalised cameras.

    Returns (scale (M,), origin (M, 3), depth (M,), cameras_n (M, N, 3, 4), ok (M,),
    Xn (M, 3)): Xn is the locally refined estimate in the normalised world frame (the
    scale comes from its residual; 0, the DLT point, where the refinement failed).
    """
    M, N = x.shape[:2]
    X0, ok = _dlt_stack(C, x)
    rho_floor = RHO_FLOOR_REL * np.maximum(1.0, np.median(np.abs(x.reshape(M, -1)), axis=1))
    Xh = np.concatenate([X0, np.ones((M, 1))], axis=1)
    h = np.einsum("mnij,mj->mni", C, Xh)
    far = np.abs(h[..., 2]) > 1e-300
    res = np.where(far, np.linalg.norm(h[..., :2] / np.where(far, h[..., 2], 1.0)[..., None] - x, axis=2), np.inf)
    finite = np.all(np.isfinite(res), axis=1)
    rho = np.where(finite, np.sqrt(np.mean(np.where(finite[:, None], res, 0.0) ** 2, axis=1)), 1.0)
    rho = np.maximum(rho, rho_floor)
    s = np.clip(1.0 / rho, *SCALE_BOUNDS)
    a = _cofactor_null(C)
    a /= np.linalg.norm(a, axis=2, keepdims=True)                          # (M, N, 4) camera centres
    affine = np.abs(a[..., 3]) <= POINT_AT_INFINITY_RTOL
    ok &= ~np.any(affine, axis=1)
    centres = a[..., :3] / np.where(affine, 1.0, a[..., 3])[..., None]
    d = np.median(np.linalg.norm(centres - X0[:, None], axis=2), axis=1)
    d = np.where(np.isfinite(d) & (d > 0), d, 1.0)
    # P_i' = T_i P_i H / ||.||_F with T_i = [[s, 0, -s t_i], [0, s, -s t_i'], [0, 0, 1]], H = [[d I, X0], [0, 1]]
    CH = C.copy()
    CH[..., :3] *= d[:, None, None, None]
    CH[..., 3] = np.einsum("mnij,mj->mni", C, Xh)
    Cn = CH.copy()
    Cn[:, :, :2, :] = s[:, None, None, None] * (CH[:, :, :2, :] - x[..., None] * CH[:, :, 2:3, :])
    Cn /= np.linalg.norm(Cn, axis=(2, 3))[..., None, None]
    # the scale from the residual of the locally refined estimate (as normalization_for): refine
    # from the DLT point (Xn = 0), then the exact image similarity x' = k x', k = s_new / s
    Xn, ok_r = _refine_stack(Cn, np.zeros((M, N, 2)), np.zeros((M, 3)), ok.copy())
    u, _, fin = _project_stack(Cn, Xn)
    r = np.sqrt(np.mean(np.sum(np.where(fin[:, None, None], u, 0.0) ** 2, axis=2), axis=1)) / s
    use = ok_r & fin & np.isfinite(r)
    rho_ref = np.where(use, np.maximum(np.minimum(r, rho), rho_floor), rho)
    s_new = np.clip(1.0 / rho_ref, *SCALE_BOUNDS)
    Cn[:, :, :2, :] *= (s_new / s)[:, None, None, None]
    Cn /= np.linalg.norm(Cn, axis=(2, 3))[..., None, None]
    return s_new, X0, d, Cn, ok, np.where(use[:, None], Xn, 0.0)


def _refine_stack(Cn: np.ndarray, xhat: np.ndarray, X: np.ndarray, ok: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vectorised Levenberg-Marquardt on sum_i ||Phi(X, P_i) - x^_i||^2 from X (M, 3)."""
    X = X.copy()
    mu = np.full(len(X), 1e-3)

    def cost_of(Xc, Cc, xc):
        u, _, fin = _project_stack(Cc, Xc)
        return np.where(fin, np.sum((u - xc) ** 2, axis=(1, 2)), np.inf), u, fin

    cost, _, fin = cost_of(X, Cn, xhat)
    ok = ok & fin
    active = np.nonzero(ok)[0]
    for _ in range(LM_MAX_ITER):
        if active.size == 0:
            break
        Ca, xa, Xa = Cn[active], xhat[active], X[active]
        u, h, _ = _project_stack(Ca, Xa)
        # d Phi / d X = (P[:2, :3] - u P[2, :3]) / (P[2] . X~)
        Jac = (Ca[..., :2, :3] - u[..., None] * Ca[..., 2:3, :3]) / h[..., 2][..., None, None]
        Jac = Jac.reshape(len(active), -1, 3)
        r = (u - xa).reshape(len(active), -1)
        JtJ = np.einsum("mki,mkj->mij", Jac, Jac)
        g = np.einsum("mki,mk->mi", Jac, r)
        A = JtJ + mu[active, None, None] * np.eye(3) * (1.0 + np.trace(JtJ, axis1=1, axis2=2))[:, None, None] / 3
        try:
            step = -np.linalg.solve(A, g[..., None])[..., 0]
        except np.linalg.LinAlgError:
            step = -np.einsum("mij,mj->mi", np.linalg.pinv(A), g)
        Xt = Xa + step
        ct, _, _ = cost_of(Xt, Ca, xa)
        better = np.isfinite(ct) & (ct <= cost[active])
        X[active[better]] = Xt[better]
        cost[active[better]] = ct[better]
        mu[active] = np.where(better, np.maximum(mu[active] / 10, 1e-12), mu[active] * 10)
        small = np.linalg.norm(step, axis=1) <= LM_STEP_RTOL * (1.0 + np.linalg.norm(Xa, axis=1))
        stalled = mu[active] > 1e12
        active = active[~((better & small) | stalled | (~better & small))]
    return X, ok & np.all(np.isfinite(X), axis=1)


def _epipolar_data(Cn: np.ndarray):
    """Quadratic parts (g0 (M, K), g1 (M, K, 2N), G2 (M, K, 2N, 2N)) of x~_i^T F_ij x~_j, i < j,
    F_ij = [e]_x P_i P_j^+ with e = P_i a_j, P_j a_j = 0 (SPEC §7), scaled to unit Frobenius norm;
    and a mask of the problems where every F_ij is defined (distinct centres)."""
    M, N = Cn.shape[:2]
    pairs = [(i, j) for i in range(N) for j in range(i + 1, N)]
    I = np.array([p[0] for p in pairs], int)
    J = np.array([p[1] for p in pairs], int)
    Pi, Pj = Cn[:, I], Cn[:, J]                                            # (M, K, 3, 4)
    a = _cofactor_null(Cn)                                                 # centres of the views (M, N, 4)
    # P^+ = P^T (P P^T)^-1 for a full-rank 3x4 P (one batched 3x3 inverse per view)
    pinv = np.einsum("mnij,mnjk->mnik", np.swapaxes(Cn, 2, 3), np.linalg.inv(Cn @ np.swapaxes(Cn, 2, 3)))
    e = np.einsum("mkij,mkj->mki", Pi, a[:, J])
    ex = np.zeros(e.shape + (3,))
    ex[..., 0, 1], ex[..., 0, 2], ex[..., 1, 2] = -e[..., 2], e[..., 1], -e[..., 0]
    ex[..., 1, 0], ex[..., 2, 0], ex[..., 2, 1] = e[..., 2], -e[..., 1], e[..., 0]
    F = ex @ Pi @ pinv[:, J]
    nrm = np.linalg.norm(F, axis=(2, 3))
    ok = np.all(nrm > SAME_CENTER_RTOL * np.linalg.norm(Pi, axis=(2, 3)) * np.linalg.norm(Pj, axis=(2, 3)), axis=1)
    F = F / np.where(nrm > 0, nrm, 1.0)[..., None, None]
    K, n = len(pairs), 2 * N
    g0 = F[..., 2, 2]
    g1 = np.zeros((M, K, n))
    G2 = np.zeros((M, K, n, n))
    k = np.arange(K)
    for a_ in range(2):
        g1[:, k, 2 * I + a_] = F[:, :, a_, 2]
        g1[:, k, 2 * J + a_] = F[:, :, 2, a_]
        for b_ in range(2):
            G2[:, k, 2 * I + a_, 2 * J + b_] = F[:, :, a_, b_] / 2
            G2[:, k, 2 * J + b_, 2 * I + a_] = F[:, :, a_, b_] / 2
    return g0, g1, G2, ok


@with_single_threaded_blas
def verify_points(cameras, points2d, *, tolerances: Tolerances = DEFAULT_TOLERANCES) -> FastPathBatch:
    """Vectorised certification by verification of M point problems with N views each.

    Parameters
    ----------
    cameras : array (M, N, 3, 4)
        Projection matrices of each problem (pixels).
    points2d : array (M, N, 2)
        Observed image points (the point regions' centres).
    tolerances : sospoly.Tolerances
        The certificate rule, as in :func:`sospoly.analysis.verify.verify_quadratic`.
    """
    C, x, ok = _stack(cameras, points2d, "verify_points")
    M, N = x.shape[:2]
    s, origin, depth, Cn, ok_n, Xn0 = _normalise(C, x)
    ok &= ok_n
    xhat = np.zeros((M, N, 2))          # the observed points, normalised: s (x^_i - t_i) = 0
    # the world origin is the DLT estimate of the data; the local refinement of the
    # normalisation (Xn0) is polished in the final coordinates
    Xn, ok = _refine_stack(Cn, xhat, Xn0, ok)
    u, _, fin = _project_stack(Cn, Xn)
    ok &= fin
    v = np.where(ok[:, None], u.reshape(M, -1), 0.0)
    g0, g1, G2, ok_f = _epipolar_data(Cn)
    # data that overflowed in the normalisation (e.g. |x| ~ 1e308) is not certified here; zero
    # polynomials keep the batched linear algebra finite for the other problems
    ok &= ok_f & np.isfinite(g0).all(axis=1) & np.isfinite(g1).all(axis=(1, 2)) & np.isfinite(G2).all(axis=(1, 2, 3))
    g0, g1, G2 = (np.where(ok.reshape((M,) + (1,) * (a.ndim - 1)), a, 0.0) for a in (g0, g1, G2))
    n = 2 * N
    f0 = np.sum(xhat.reshape(M, -1) ** 2, axis=1)
    f1 = -2 * xhat.reshape(M, -1)
    F2 = np.broadcast_to(np.eye(n), (M, n, n))
    ver = verify_quadratic_batch(f0, f1, F2, g0, g1, G2, v, tolerances=tolerances)
    X = origin + depth[:, None] * Xn
    uw, _, fin_w = _project_stack(C, X)
    ok &= fin_w
    gamma_ub = np.sqrt(np.sum((uw - x) ** 2, axis=(1, 2)) / (2 * N))
    gamma_lb = np.sqrt(np.maximum(ver.lower_bound, 0.0) / (2 * N)) / s
    certified = ok & ver.certified
    return FastPathBatch(certified, ok, X, gamma_ub, gamma_lb, x + u / s[:, None, None], ver.lower_bound,
                         ver.upper_bound, s)


def fast_results(cameras, points2d, *, tolerances: Tolerances = DEFAULT_TOLERANCES,
                 method: str = "corollary1") -> list[TriangulationResult | None]:
    """:func:`verify_points` as one :class:`TriangulationResult` per certified problem (None otherwise),
    ``certified_by="verification"``, ``delta=2``; ``timings`` hold each problem's share of the batch time."""
    import time

    t0 = time.perf_counter()
    batch = verify_points(cameras, points2d, tolerances=tolerances)
    M, N = np.shape(points2d)[:2]
    n_lmivar = n_lmivar_formula(2 * N, 2, [2] * (N * (N - 1) // 2))
    share = (time.perf_counter() - t0) / max(M, 1)
    out: list[TriangulationResult | None] = [None] * M
    for m in np.nonzero(batch.certified)[0]:
        X, lb, ub = batch.X[m], float(batch.gamma_lb[m]), float(batch.gamma_ub[m])
        out[m] = TriangulationResult(method=method, status=Status.OPTIMAL, X=X, gamma_ub=ub, gamma_lb=lb,
                                     optimal=True, delta=2, n_lmivar=n_lmivar, image_points=batch.image_points[m],
                                     X_raw=X, gamma_ub_raw=ub, certified_by="verification",
                                     timings={"verify": share, "total": share},
                                     attempts=((2, "verified", lb, ub),))
    return out
