"""Certification by verification for many point-region problems at once.

For M problems with the same number N of views and point regions, the Corollary 1 program at
delta = 2 (SPEC §7) is, in the normalised coordinates of :mod:`tritools.model.normalize` (observed
points at the origin of every view),

    f(v) = sum_i ||x_i||^2,   g_ij(v) = x~_i^T F_ij x~_j (i < j),   v = (x_1, ..., x_N),

f and every g_ij quadratic.  For each problem this module, with numpy over the stack:

1. normalises (:func:`tritools.model.normalize.normalization_stack`, the rule of the per-point path);
2. polishes the normalisation's locally refined L2 estimate (Levenberg-Marquardt,
   :func:`tritools.model.stacked.refine_points_stack`) and takes v^ = (Phi(X, P_1), ..., Phi(X, P_N)),
   a feasible point of g = 0;
3. builds the epipolar polynomials of the normalised cameras (pairs with coincident centres carry
   no constraint: their polynomial is zero);
4. calls :func:`sospoly.analysis.verify.verify_quadratic_batch`: KKT multipliers by least squares,
   PSD test of the Lagrangian Hessian, exact minimum c of the Lagrangian quadratic;
5. decides with :func:`tritools.solve.decide.decide` (the rule of every path); what the Lagrangian bound
   does not certify is certified through the trivial bound 0 when gamma(X^) is within the tolerance of it
   (:mod:`tritools.solve.trivial`).

The lower bound comes from the polynomial data and the multipliers only; the local solver merely
proposes v^.  Problems the vectorised code cannot handle (degenerate cameras, DLT at infinity,
overflow, LM failure) are simply not certified here: callers send them through
:func:`tritools.triangulate`, which reports the proper status.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from sospoly import DEFAULT_TOLERANCES, Tolerances
from sospoly.analysis.verify import verify_quadratic_batch
from sospoly.solvers.blas import with_single_threaded_blas

from ..model.geometry import camera_problems
from ..model.normalize import normalization_stack
from ..model.stacked import epipolar_quadratics, fundamental_stack, project_stack, refine_points_stack
from .decide import decide, decide_reported, gamma_from_c
from .trivial import trivially_certified, trivially_certified_reported

__all__ = ["FastPathBatch", "verify_points", "stack_point_problems"]


@dataclass(frozen=True)
class FastPathBatch:
    """Per-problem arrays (first axis = problem) of one vectorised verification run.

    ``certified[m]``: problem m was certified; where ``ok[m]`` (a candidate and a bound were computed):
    ``X`` the world point, ``gamma_lb`` from the Lagrangian bound, ``gamma_ub`` = gamma(X) on the caller's
    data, ``image_points`` v^ in pixels,
    ``c_lower`` / ``c_upper`` the bounds in the normalised units where the certificate is decided,
    ``scale`` the common image scale s; ``trivial[m]``: certified through the trivial bound 0
    (:mod:`tritools.solve.trivial`; then ``gamma_lb`` is 0).
    """
    certified: np.ndarray
    ok: np.ndarray
    X: np.ndarray
    gamma_lb: np.ndarray
    gamma_ub: np.ndarray
    image_points: np.ndarray
    c_lower: np.ndarray
    c_upper: np.ndarray
    scale: np.ndarray
    trivial: np.ndarray


def stack_point_problems(cameras, points2d, caller: str):
    """(cameras (M, N, 3, 4), points2d (M, N, 2), ok (M,)) as float arrays, shapes checked (ValueError).

    Problems with invalid cameras (:func:`tritools.model.geometry.camera_problems`, the rule of
    ``validate_cameras``) or non-finite points get ``ok = False`` and harmless stand-in numbers so the
    vectorised code runs on the rest."""
    C = np.asarray(cameras, float)
    x = np.asarray(points2d, float)
    if C.ndim != 4 or C.shape[2:] != (3, 4) or x.shape != C.shape[:2] + (2,) or C.shape[1] < 2:
        raise ValueError(f"{caller}: cameras must be (M, N, 3, 4) and points2d (M, N, 2) with N >= 2, "
                         f"got {C.shape} and {x.shape}")
    ok = camera_problems(C).valid & np.all(np.isfinite(x), axis=(1, 2))
    C = np.where(ok[:, None, None, None], C, np.eye(3, 4))
    x = np.where(ok[:, None, None], x, 0.0)
    return C, x, ok


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
        The certificate rule.
    """
    C, x, ok = stack_point_problems(cameras, points2d, "verify_points")
    M, N = x.shape[:2]
    norm = normalization_stack(C, x, ok)
    ok &= norm.ok
    Cn = norm.cameras_n
    xhat = np.zeros((M, N, 2))          # the observed points, normalised: s (x^_i - t_i) = 0
    Xn, ok = refine_points_stack(Cn, xhat, norm.Xn, ok)
    u, _, fin = project_stack(Cn, Xn)
    ok &= fin
    v = np.where(ok[:, None], u.reshape(M, -1), 0.0)
    F, defined = fundamental_stack(Cn)
    raw = fundamental_stack(C)[1]       # one centre or not: decided on the raw cameras (CentreRelations' rule)
    F, defined = np.where(raw[..., None, None], F, 0.0), defined & raw
    ok &= np.any(defined, axis=1) if F.shape[1] else ok
    g0, g1, G2 = epipolar_quadratics(F, N)
    finite = np.isfinite(g0).all(axis=1) & np.isfinite(g1).all(axis=(1, 2)) & np.isfinite(G2.vals).all(axis=1)
    ok &= finite
    g0, g1 = (np.where(ok.reshape((M,) + (1,) * (a.ndim - 1)), a, 0.0) for a in (g0, g1))
    G2 = dataclasses.replace(G2, vals=np.where(ok[:, None], G2.vals, 0.0))
    n = 2 * N
    # a minimiser v* has ||v*||^2 = f(v*) <= f(v^) = ||v^||^2 (observed points at the origin): the radius of the
    # rigorous margin of the Lagrangian bound
    ver = verify_quadratic_batch(np.zeros(M), np.zeros((M, n)), np.broadcast_to(np.eye(n), (M, n, n)), g0, g1, G2,
                                 v, tolerances=tolerances, radius=np.linalg.norm(v, axis=1))
    status, optimal, c_lower = decide(ver.lower_bound, ver.upper_bound, tolerances, N, norm.resolution)
    X = norm.world_points(Xn)
    uw, _, fin_w = project_stack(C, X)
    ok &= fin_w
    gamma_ub = np.where(fin_w, np.sqrt(np.sum((uw - x) ** 2, axis=(1, 2)) / (2 * N)), np.inf)
    gamma_lb = np.minimum(gamma_from_c(c_lower, N, norm.scale), gamma_ub)
    certified = ok & optimal & decide_reported(gamma_lb, gamma_ub, tolerances, N, norm.scale, norm.resolution)
    trivial = ok & ~certified & trivially_certified(ver.upper_bound, tolerances, N, norm.resolution) & \
        trivially_certified_reported(gamma_ub, tolerances, N, norm.scale, norm.resolution)
    gamma_lb = np.where(trivial, 0.0, gamma_lb)
    return FastPathBatch(certified | trivial, ok, X, gamma_lb, gamma_ub, x + u / norm.scale[:, None, None],
                         np.where(trivial, 0.0, c_lower), ver.upper_bound, norm.scale, trivial)
