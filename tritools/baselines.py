"""The comparison methods of the paper's Section 5 (no optimality certificate).

All methods minimise ``gamma(X)`` of SPEC §1 (paper eq. (6)) and return a
:class:`~tritools.result.TriangulationResult` with status ``NO_CERTIFICATE``
(``gamma_lb`` and ``optimal`` are ``None``), ``gamma_ub = gamma(X)`` with exact
distances, and the wall-clock time in ``timings["total"]``.  As in the paper,
Newton, Nelder-Mead and SQP start from the linear triangulation (DLT) of the region
centres ("minimising the algebraic error of (1) relative to the centre of the
admissible regions").

``init`` selects the linear start: ``"algebraic"`` (default; the unit ``X~`` minimising
``||M0(centres) X~||``, i.e. the paper's "minimum algebraic error" estimate, which
reproduces the paper's NMS and SQP rows of Tables 8-10) or ``"normalized"`` (the
Hartley-normalised :func:`~tritools.model.geometry.dlt`, advisable for pixel data).

Malformed input (shapes, NaN, bad cameras, wrong number of regions) raises
``ValueError``.  A well-formed problem a method cannot handle returns a result with
status ``INVALID_INPUT`` (Newton with a non-point region) or ``ILL_POSED`` (the DLT
start is a point at infinity).
"""
from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
from scipy import optimize

from .model.geometry import (PointAtInfinityError, gamma_validated, project_homogeneous, dlt, point_from_image_points,
                             validate_cameras)
from .model.regions import as_regions, positive_number
from .result import Status, TriangulationResult

__all__ = [
    "dlt_baseline", "newton", "nelder_mead", "particle_swarm", "sqp", "point_cost_derivatives", "BASELINES",
    "pycolmap_multiview", "decompose_camera",
    "NEWTON_MAX_ITER", "NEWTON_GTOL", "PSO_SWARM_PER_DIM", "PSO_MAX_SWARM", "PSO_INERTIA_RANGE",
    "PSO_SELF_WEIGHT", "PSO_SOCIAL_WEIGHT", "PSO_MIN_NEIGHBORS_FRACTION", "PSO_MAX_STALL", "PSO_FTOL",
    "BIG_COST", "tpml",
]

#: Newton: maximum iterations and gradient tolerance (relative to 1 + J).
NEWTON_MAX_ITER = 100
NEWTON_GTOL = 1e-12
#: MATLAB ``particleswarm`` defaults (R2023b documentation): SwarmSize = min(100, 10 nvars),
#: InertiaRange = [0.1, 1.1], SelfAdjustmentWeight = SocialAdjustmentWeight = 1.49,
#: MinNeighborsFraction = 0.25, MaxStallIterations = 20, FunctionTolerance = 1e-6,
#: MaxIterations = 200 nvars.
PSO_SWARM_PER_DIM = 10
PSO_MAX_SWARM = 100
PSO_INERTIA_RANGE = (0.1, 1.1)
PSO_SELF_WEIGHT = 1.49
PSO_SOCIAL_WEIGHT = 1.49
PSO_MIN_NEIGHBORS_FRACTION = 0.25
PSO_MAX_STALL = 20
PSO_FTOL = 1e-6
#: Value substituted for ``gamma = inf`` (projection at infinity) in SLSQP, which needs finite values.
BIG_COST = 1e10


# ----------------------------------------------------------------------------- common
def prepare_baseline(cameras, regions):
    C = validate_cameras(cameras)
    R = as_regions(regions, len(C))
    return C, R


def _gamma1(X: np.ndarray, C: np.ndarray, R) -> float:
    return float(gamma_validated(np.asarray(X, dtype=float).reshape(1, 3), C, R)[0])


INITS = ("algebraic", "normalized")


def _check_init(init: str) -> str:
    if init not in INITS:
        raise ValueError(f"init must be one of {INITS}, got {init!r}")
    return init


def start_baseline(C, R, init: str = "algebraic"):
    """Linear triangulation of the region centres, or ``(None, message)``.

    ``"algebraic"``: the minimiser of the algebraic error ``||M0 X~||`` over unit
    ``X~`` (SVD of the raw ``M0``, SPEC §3), the paper's initialisation, which
    reproduces its NMS/SQP rows; ``"normalized"``: :func:`~tritools.model.geometry.dlt`
    (Hartley-normalised, better conditioned for pixel data).
    """
    centres = np.array([r.center for r in R])
    if init == "normalized":
        try:
            return dlt(C, centres), None
        except PointAtInfinityError as exc:
            return None, str(exc)
    X = point_from_image_points(centres, C)
    if X is None:
        return None, "linear triangulation of the region centres is a point at infinity: ill-posed problem"
    return X, None


def finish_baseline(method: str, X, C, R, t0: float, message: str = "", status: Status = Status.NO_CERTIFICATE,
            **extra) -> TriangulationResult:
    total = time.perf_counter() - t0
    if X is None:
        return TriangulationResult(method, status, message=message, timings={"total": total}, **extra)
    X = np.asarray(X, dtype=float)
    if not np.all(np.isfinite(X)):
        return TriangulationResult(method, Status.NUMERICAL_FAILURE, message=message + " (non-finite estimate)",
                                   timings={"total": total}, **extra)
    Xh = np.append(X, 1.0)[None, :]
    x = np.array([project_homogeneous(Xh, P)[0] for P in C])
    return TriangulationResult(method, status, X=X, gamma_ub=_gamma1(X, C, R),
                               image_points=x if np.all(np.isfinite(x)) else None,
                               message=message, timings={"total": total}, **extra)


# ----------------------------------------------------------------------------- DLT
def dlt_baseline(cameras, regions, *, init: str = "algebraic") -> TriangulationResult:
    """Linear triangulation of the region centres (Hartley & Zisserman §12.2): the
    starting point of the other methods (see ``init`` in the module notes)."""
    t0 = time.perf_counter()
    C, R = prepare_baseline(cameras, regions)
    X, err = start_baseline(C, R, _check_init(init))
    if X is None:
        return finish_baseline("dlt", None, C, R, t0, err, Status.ILL_POSED)
    return finish_baseline("dlt", X, C, R, t0)


# ----------------------------------------------------------------------------- Newton
def point_cost_derivatives(X, cameras, points2d) -> tuple[float, np.ndarray, np.ndarray]:
    """Cost ``J(X) = sum_i ||Phi(X, P_i) - x_i||^2`` (paper eq. (6) squared, times 2N),
    its gradient and Hessian in ``X``.

    With ``a = p1.X~``, ``b = p2.X~``, ``w = p3.X~`` and ``alpha, beta, pi`` the first
    three entries of ``p1, p2, p3``: ``d(a/w)/dX = (alpha w - a pi) / w^2`` and
    ``d2(a/w)/dX2 = -(alpha pi' + pi alpha') / w^2 + 2 a pi pi' / w^3`` (same for b);
    ``grad J = 2 sum J_i' r_i``, ``hess J = 2 sum (J_i' J_i + sum_k r_ik H_ik)``.

    Returns ``(inf, nan, nan)`` if some ``w`` vanishes.
    """
    X = np.asarray(X, dtype=float)
    Xh = np.append(X, 1.0)
    J = 0.0
    g = np.zeros(3)
    H = np.zeros((3, 3))
    for P, x in zip(cameras, points2d):
        w = float(P[2] @ Xh)
        if w == 0.0 or not np.isfinite(w):
            return float("inf"), np.full(3, np.nan), np.full((3, 3), np.nan)
        pi = P[2, :3]
        for k in range(2):
            a = float(P[k] @ Xh)
            al = P[k, :3]
            r = a / w - x[k]
            d1 = (al * w - a * pi) / (w * w)
            d2 = -(np.outer(al, pi) + np.outer(pi, al)) / (w * w) + 2.0 * a * np.outer(pi, pi) / w ** 3
            J += r * r
            g += 2.0 * r * d1
            H += 2.0 * (np.outer(d1, d1) + r * d2)
    return J, g, H


def newton(cameras, regions, *, max_iter: int = NEWTON_MAX_ITER, init: str = "algebraic") -> TriangulationResult:
    """Damped Newton method on ``J(X) = sum_i ||Phi(X, P_i) - x_i||^2`` (point regions only),
    started at the DLT estimate, with the analytic gradient and Hessian of
    :func:`point_cost_derivatives`.

    Each step solves ``(H + mu I) d = -g`` with the smallest ``mu >= 0`` (0, then
    ``1e-8 * (1 + ||H||)`` multiplied by 10) giving a positive definite matrix, then
    backtracks (halving, Armijo constant 1e-4) until ``J`` decreases.  Stops when
    ``||g|| <= NEWTON_GTOL (1 + J)``, the step no longer changes ``X``, no decrease is
    found, or after ``max_iter`` iterations.

    Returns status ``INVALID_INPUT`` if some region is not a single point (``Region.is_point``).
    """
    t0 = time.perf_counter()
    C, R = prepare_baseline(cameras, regions)
    if not all(r.is_point for r in R):
        return finish_baseline("newton", None, C, R, t0, "Newton needs point regions (not applicable)",
                       Status.INVALID_INPUT)
    x = np.array([r.center for r in R])
    X, err = start_baseline(C, R, _check_init(init))
    if X is None:
        return finish_baseline("newton", None, C, R, t0, err, Status.ILL_POSED)
    J, g, H = point_cost_derivatives(X, C, x)
    msg = f"max_iter={max_iter} reached"
    for it in range(max_iter):
        if not np.isfinite(J):
            msg = "projection at infinity"
            break
        if np.linalg.norm(g) <= NEWTON_GTOL * (1.0 + J):
            msg = f"converged (gradient) after {it} iterations"
            break
        mu = 0.0
        step = None
        hn = np.linalg.norm(H)
        for _ in range(30):
            try:
                L = np.linalg.cholesky(H + mu * np.eye(3))
                step = -np.linalg.solve(L.T, np.linalg.solve(L, g))
                break
            except np.linalg.LinAlgError:
                mu = 1e-8 * (1.0 + hn) if mu == 0.0 else 10.0 * mu
        if step is None:
            msg = "no positive definite damped Hessian"
            break
        slope = float(g @ step)
        t = 1.0
        accepted = False
        for _ in range(60):
            Xn = X + t * step
            Jn = point_cost_derivatives(Xn, C, x)[0]
            if np.isfinite(Jn) and Jn <= J + 1e-4 * t * slope:
                accepted = True
                break
            t *= 0.5
        if not accepted:
            msg = f"line search failed after {it} iterations (local minimum reached)"
            break
        if np.all(Xn == X):
            msg = f"converged (step) after {it} iterations"
            break
        X = Xn
        J, g, H = point_cost_derivatives(X, C, x)
    return finish_baseline("newton", X, C, R, t0, msg)


# ----------------------------------------------------------------------------- Nelder-Mead
def nelder_mead(cameras, regions, *, init: str = "algebraic", **options) -> TriangulationResult:
    """Nelder-Mead simplex (``scipy.optimize.minimize(method="Nelder-Mead")``, default
    options as MATLAB ``fminsearch``: xatol = fatol = 1e-4, 200 * 3 iterations, initial
    simplex 5% perturbations) on ``gamma(X)`` with exact distances, started at DLT.
    ``options`` are passed to scipy."""
    t0 = time.perf_counter()
    C, R = prepare_baseline(cameras, regions)
    X0, err = start_baseline(C, R, _check_init(init))
    if X0 is None:
        return finish_baseline("nms", None, C, R, t0, err, Status.ILL_POSED)
    res = optimize.minimize(lambda X: _gamma1(X, C, R), X0, method="Nelder-Mead", options=options or None)
    return finish_baseline("nms", res.x, C, R, t0, f"{res.message} (nfev={res.nfev})")


# ----------------------------------------------------------------------------- SQP
def sqp(cameras, regions, *, bounds: float = 100.0, init: str = "algebraic", **options) -> TriangulationResult:
    """Sequential quadratic programming (scipy SLSQP, default options, finite-difference
    gradients) on ``gamma(X)`` in the box ``[-bounds, bounds]^3``, started at the DLT
    estimate clipped to the box."""
    t0 = time.perf_counter()
    C, R = prepare_baseline(cameras, regions)
    b = _check_bounds(bounds)
    X0, err = start_baseline(C, R, _check_init(init))
    if X0 is None:
        return finish_baseline("sqp", None, C, R, t0, err, Status.ILL_POSED)

    def fun(X):
        v = _gamma1(X, C, R)
        return v if np.isfinite(v) else BIG_COST

    res = optimize.minimize(fun, np.clip(X0, -b, b), method="SLSQP", bounds=[(-b, b)] * 3,
                            options=options or None)
    status = Status.NO_CERTIFICATE if res.success or np.isfinite(fun(res.x)) else Status.SOLVER_FAILED
    return finish_baseline("sqp", res.x, C, R, t0, f"{res.message} (nit={res.nit})", status)


def _check_bounds(bounds) -> float:
    return positive_number(bounds, "bounds")


# ----------------------------------------------------------------------------- PSO
def _pso(fun: Callable[[np.ndarray], np.ndarray], lb: np.ndarray, ub: np.ndarray, rng: np.random.Generator,
         max_iter: int | None = None, x_init: np.ndarray | None = None) -> tuple[np.ndarray, float, int, str]:
    """Particle swarm following the algorithm of MATLAB's ``particleswarm``.

    ``fun`` maps an (S, n) array to (S,) values.  Returns (best x, best f, iterations, message).
    """
    n = len(lb)
    S = min(PSO_MAX_SWARM, PSO_SWARM_PER_DIM * n)
    max_iter = 200 * n if max_iter is None else int(max_iter)
    span = ub - lb
    x = lb + rng.uniform(size=(S, n)) * span
    if x_init is not None:  # like MATLAB's InitialSwarmMatrix with one row
        x[0] = np.clip(x_init, lb, ub)
    v = rng.uniform(-1.0, 1.0, size=(S, n)) * span
    f = fun(x)
    p, fp = x.copy(), f.copy()
    ib = int(np.argmin(fp))
    best_f, best_x = float(fp[ib]), p[ib].copy()
    min_nb = max(2, int(np.floor(S * PSO_MIN_NEIGHBORS_FRACTION)))
    nb = min_nb
    W = PSO_INERTIA_RANGE[1]
    c = 0
    history = [best_f]
    msg = f"max iterations ({max_iter}) reached"
    it = 0
    for it in range(1, max_iter + 1):
        # random neighbourhood of nb other particles for each particle
        keys = rng.uniform(size=(S, S))
        keys[np.arange(S), np.arange(S)] = np.inf
        nbrs = np.argsort(keys, axis=1)[:, :nb]
        best_nb = nbrs[np.arange(S), np.argmin(fp[nbrs], axis=1)]
        g = p[best_nb]
        u1 = rng.uniform(size=(S, n))
        u2 = rng.uniform(size=(S, n))
        v = W * v + PSO_SELF_WEIGHT * u1 * (p - x) + PSO_SOCIAL_WEIGHT * u2 * (g - x)
        x = x + v
        low, high = x < lb, x > ub
        x = np.clip(x, lb, ub)
        v[(low & (v < 0)) | (high & (v > 0))] = 0.0
        f = fun(x)
        imp = f < fp
        p[imp], fp[imp] = x[imp], f[imp]
        ib = int(np.argmin(fp))
        if fp[ib] < best_f:
            best_f, best_x = float(fp[ib]), p[ib].copy()
            c = max(0, c - 1)
            nb = min_nb
            if c < 2:
                W = 2.0 * W
            elif c > 5:
                W = W / 2.0
            W = float(np.clip(W, *PSO_INERTIA_RANGE))
        else:
            c += 1
            nb = min(nb + min_nb, S - 1)
        history.append(best_f)
        if it >= PSO_MAX_STALL:
            old = history[-1 - PSO_MAX_STALL]
            if abs(old - best_f) / max(1.0, abs(best_f)) < PSO_FTOL:
                msg = f"stall: relative change < {PSO_FTOL} over {PSO_MAX_STALL} iterations"
                break
    return best_x, best_f, it, msg


def particle_swarm(cameras, regions, *, seed=0, bounds: float = 100.0, max_iter: int | None = None,
                   include_dlt: bool = True, init: str = "algebraic") -> TriangulationResult:
    """Particle swarm optimisation of ``gamma(X)`` in ``[-bounds, bounds]^3`` with
    MATLAB ``particleswarm`` defaults (swarm 10 * 3 = 30 particles, uniform initial
    swarm in the box, velocities uniform in ``[-range, range]``, adaptive inertia in
    [0.1, 1.1], self/social weights 1.49, random neighbourhoods of at least 25% of the
    swarm, stop when the best value changes by < 1e-6 (relative) over 20 iterations
    or after 600 iterations).  Seeded by ``seed`` (``numpy.random.default_rng``).
    With ``include_dlt`` the DLT estimate of the region centres (clipped to the box)
    replaces the first particle of the initial swarm (MATLAB's ``InitialSwarmMatrix``
    with one row); the paper's MATLAB runs used a purely random swarm
    (``include_dlt=False``).
    """
    t0 = time.perf_counter()
    C, R = prepare_baseline(cameras, regions)
    b = _check_bounds(bounds)
    rng = np.random.default_rng(seed)
    X0 = start_baseline(C, R, _check_init(init))[0] if include_dlt else None
    X, fbest, it, msg = _pso(lambda Xs: gamma_validated(Xs, C, R), np.full(3, -b), np.full(3, b), rng,
                             max_iter, X0)
    return finish_baseline("pso", X, C, R, t0, f"{msg} (iterations={it})")


# ----------------------------------------------------------------------------- pycolmap (optional)
def decompose_camera(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """P ~ K [R | t] (RQ decomposition, K upper triangular with positive diagonal, K[2,2] = 1,
    det R = +1).  Returns (K, cam_from_world = [R | t])."""
    from scipy.linalg import rq

    P = np.asarray(P, float)
    if np.linalg.det(P[:, :3]) < 0:
        P = -P
    K, R = rq(P[:, :3])
    S = np.diag(np.sign(np.diag(K)))
    K, R = K @ S, S @ R
    t = np.linalg.solve(K, P[:, 3])
    scale = K[2, 2]
    return K / scale, np.hstack([R, t[:, None]])


def pycolmap_multiview(cameras, regions) -> TriangulationResult:
    """COLMAP's multi-view linear triangulation (``pycolmap.triangulate_multi_view_point``) of
    the region centres, each P decomposed into K [R | t] and each point turned into the
    bearing K^-1 [x, 1].  Needs the optional ``pycolmap`` package (extra ``colmap``)."""
    import pycolmap

    t0 = time.perf_counter()
    C, R = prepare_baseline(cameras, regions)
    cams, rays = [], []
    for P, reg in zip(C, R):
        K, Rt = decompose_camera(P)
        ray = np.linalg.solve(K, np.append(reg.center, 1.0))
        cams.append(Rt)
        rays.append(ray / np.linalg.norm(ray))
    X = pycolmap.triangulate_multi_view_point(cams, np.array(rays))
    if X is None:
        return finish_baseline("pycolmap", None, C, R, t0, "pycolmap found no point", Status.ILL_POSED)
    return finish_baseline("pycolmap", np.asarray(X, float).ravel(), C, R, t0)


BASELINES: dict[str, Callable[..., TriangulationResult]] = {
    "dlt": dlt_baseline,
    "newton": newton,
    "nms": nelder_mead,
    "pso": particle_swarm,
    "sqp": sqp,
}



def tpml(cameras, regions, degree: int = 4, **options) -> TriangulationResult:
    """The world-domain TPML-style baseline (:func:`tritools.tpml.tpml`: a sum-of-ratios SOS relaxation in the
    scene point's coordinates; an estimate without certificate)."""
    from .tpml import tpml as world_tpml

    return world_tpml(cameras, regions, degree, **options)
