"""Certification by verification for disc regions (uncertain keypoints), vectorised over a stack.

A disc region of radius rho around the keypoint c (:class:`~tritools.model.regions.Ellipse` with D = rho^2 I)
has, in the Corollary 1 program (SPEC §2, §7), variables x_i (the image point) and y_i (the region point),
f = sum_i ||x_i - y_i||^2, the epipolar constraints g_ij(x) = 0 and h_i(y) = 1 - ||y_i - c_i||^2 / rho_i^2 >= 0.
In the normalised frame (:mod:`tritools.model.normalize`, centres at the origin, radii rho_i' = s rho_i):

* the local optimum: Levenberg-Marquardt on the distances to the discs, e_i = u_i max(0, 1 - rho_i / |u_i|)
  with u_i = Phi(X, P_i) (:func:`refine_discs_stack`), from the point solution; y_i^ the closest disc point;
* the degree-2 certificate with constant multipliers (the weak Positivstellensatz at delta = 2, SPEC §5):
  L(x, y) = f + lambda^T g(x) - mu^T h(y) with mu >= 0 gives min L <= min {f : g = 0, h >= 0} (on that set
  -mu^T h <= 0).  The KKT conditions in y give mu_i = rho_i' (|x_i| - rho_i') for a view outside its disc,
  0 inside; for fixed x, L is a convex quadratic in y whose minimum is exact (Schur complement):

      min_y L(x, y) = -sum_i mu_i + sum_i kappa_i |x_i|^2 + lambda^T g(x),  kappa_i = mu_i / (rho_i'^2 + mu_i),

  (kappa_i = 1 - rho_i' / |x_i| at the candidate), i.e. the point-region bound of
  :func:`tritools.solve.fastpath.lagrangian_bounds` with weights kappa (rounded down, so the reduced
  Lagrangian is never above the exact one) and constant -sum mu.  Views inside their disc (kappa = 0) keep no
  epipolar constraint (dropped: a weaker, valid bound; at a local optimum their constraints are inactive); the
  views outside are gathered into a compact stack (:func:`tritools.solve.regions_verify.compact_bounds`), so
  from ``BAND_MIN_VIEWS`` of them on the bands of view pairs apply (cost linear in N), all pairs only for what
  no band certifies;
* the decision of every path (:func:`tritools.solve.decide.decide`), in c = 2N gamma^2 units, and again on the
  numbers reported in pixels.

Problems it does not certify go to :func:`tritools.triangulate` (the SDP).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sospoly import DEFAULT_TOLERANCES, Tolerances
from sospoly.budget import Deadline
from sospoly.solvers import with_single_threaded_blas

from ..model.cameras import numeric_cameras
from ..model.frame import project_world, recentred
from ..model.normalize import normalization_stack
from ..model.regions import ConeKind, Region
from ..model.stacked import LM_MAX_ITER, damped_step, lm_accept, norms, project_stack
from .decide import decide, decide_reported, gamma_from_c, gamma_lower, reported_lower
from .report import disc_distances, gamma_upper
from .regions_verify import compact_bounds, region_forms

__all__ = ["DiscBatch", "disc_radius", "verify_discs", "refine_discs_stack", "ellipse_shapes"]

_ROUND_DOWN = 1 - 8 * np.finfo(float).eps


def disc_radius(region) -> float | None:
    """rho when ``region`` is a filled disc of radius rho around its centre (the region's own
    :attr:`~tritools.model.regions.Region.disc_radius`: an ``Ellipse`` with D = rho^2 I exactly), else None (also
    for anything that is not a Region: the batch paths ask before validating)."""
    return region.disc_radius if isinstance(region, Region) else None


@dataclass(frozen=True)
class DiscBatch:
    """Per-problem arrays of :func:`verify_discs` (first axis = problem): as
    :class:`~tritools.solve.fastpath.FastPathBatch`; ``image_points`` are the projections of X (pixels)."""
    certified: np.ndarray
    ok: np.ndarray
    X: np.ndarray
    gamma_lb: np.ndarray
    gamma_at_X: np.ndarray                 # gamma(X) on the caller's data: the upper bound
    image_points: np.ndarray
    residuals: np.ndarray

    @property
    def gamma_ub(self) -> np.ndarray:
        """The upper bound ``gamma_ub = gamma(X)`` (``gamma_at_X``; the batch record of a result is
        :class:`tritools.records.TriangulationResults`)."""
        return self.gamma_at_X


def _disc_residual(u: np.ndarray, rho: np.ndarray):
    """(e, |u|, outside) with e = u - (closest point of the disc of radius rho at the origin)."""
    r = np.linalg.norm(u, axis=-1)
    outside = r > rho
    k = np.where(outside, 1.0 - rho / np.where(outside, r, 1.0), 0.0)
    return u * k[..., None], r, outside


def refine_discs_stack(C: np.ndarray, rho: np.ndarray, X: np.ndarray, ok: np.ndarray,
                       deadline: Deadline | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Levenberg-Marquardt on sum_i dist(Phi(X, P_i), disc_i)^2 (discs of radii rho (M, N) at the origin) from
    X (M, 3), for the problems where ``ok`` (the twin of :func:`tritools.model.stacked.refine_points_stack`).
    Past the ``deadline`` no iteration starts and the problems still iterating leave ``ok`` (review 40a LOW-3)."""
    X = X.copy()
    M = len(X)
    mu = np.full(M, 1e-3)

    def cost_of(Xc, Cc, rc):
        u, h, fin = project_stack(Cc, Xc)
        e = _disc_residual(u, rc)[0]
        return np.where(fin, np.sum(e ** 2, axis=(1, 2)), np.inf), u, h

    cost, _, _ = cost_of(X, C, rho)
    ok = ok & np.isfinite(cost)
    active = np.nonzero(ok)[0]
    eye2 = np.eye(2)
    for _ in range(LM_MAX_ITER):
        if active.size == 0:
            break
        if deadline is not None and deadline.expired:
            ok = ok.copy()
            ok[active] = False
            break
        Ca, ra, Xa = C[active], rho[active], X[active]
        u, h, _ = project_stack(Ca, Xa)
        e, r, out = _disc_residual(u, ra)
        # d e / d u = (1 - rho/|u|) I + rho u u^T / |u|^3 outside the disc, 0 inside
        rs = np.where(out, r, 1.0)
        De = np.where(out[..., None, None], (1 - ra / rs)[..., None, None] * eye2
                      + (ra / rs ** 3)[..., None, None] * u[..., :, None] * u[..., None, :], 0.0)
        Ju = (Ca[..., :2, :3] - u[..., None] * Ca[..., 2:3, :3]) / h[..., 2][..., None, None]
        # Gauss-Newton on the distance: d^2/du^2 (|u| - rho)^2 / 2 = De (not De^2, which underweights the
        # tangential direction by (1 - rho/|u|)^2 and converges only linearly), gradient Ju^T e
        JtJ = np.einsum("mnai,mnab,mnbj->mij", Ju, De, Ju)
        g = np.einsum("mnai,mna->mi", Ju, e)
        step = damped_step(JtJ, g, mu[active])
        Xt = Xa + step
        ct = cost_of(Xt, Ca, ra)[0]
        active = lm_accept(X, cost, mu, active, Xa, step, Xt, ct)
    return X, ok & np.all(np.isfinite(X), axis=1)


@with_single_threaded_blas
def verify_discs(cameras, centers, radii, *, tolerances: Tolerances = DEFAULT_TOLERANCES,
                 deadline: Deadline | None = None) -> DiscBatch:
    """Vectorised certification by verification of M disc-region problems with N views each (module docstring):
    cameras (M, N, 3, 4), disc centres (M, N, 2) and radii (M, N) in pixels, validated by the caller;
    ``deadline`` is checked between the steps of the stack (:func:`~tritools.solve.fastpath.lagrangian_bounds`)."""
    C = np.asarray(cameras, float)
    x = np.asarray(centers, float)
    rho = np.asarray(radii, float)
    M, N = x.shape[:2]
    ok = np.all(np.isfinite(x), axis=(1, 2)) & np.all(np.isfinite(rho) & (rho > 0), axis=1)
    Cw, origin = recentred(C)          # georeferenced worlds: solved in re-centred frames
    norm = normalization_stack(Cw, x, ok)
    ok &= norm.ok
    Cn = norm.cameras_n
    rho_n = rho * norm.scale[:, None]
    Xn, ok = refine_discs_stack(Cn, rho_n, norm.Xn, ok, deadline)
    u, _, fin = project_stack(Cn, Xn)
    ok &= fin
    u = np.where(ok[:, None, None], u, 0.0)
    _, r, outside = _disc_residual(u, rho_n)
    mu = np.where(outside, rho_n * (r - rho_n), 0.0)
    kappa = np.where(outside, mu / (rho_n ** 2 + mu), 0.0) * _ROUND_DOWN
    weights = np.repeat(kappa[..., None], 2, axis=2)         # per coordinate of x_i
    # a minimiser has |x_i| <= rho_i + |x_i - y_i|, so |x| <= |rho| + sqrt(f(v^)) (the rigorous margin's ball)
    upper_f = np.sum(np.where(outside, (r - rho_n) ** 2, 0.0), axis=1)
    radius = np.linalg.norm(rho_n, axis=1) + np.sqrt(upper_f)
    lower, ok_b = compact_bounds(Cw, Cn, u, weights, -mu, outside & ok[:, None], radius, norm.resolution,
                                 tolerances, deadline=deadline)
    ok &= ok_b
    status, optimal, c_lower = decide(lower, upper_f, tolerances, N, norm.resolution)
    mag = norm.magnitudes_at(Cw, norm.world_points(Xn))    # the estimate's, in the frame normalised
    X = norm.world_points(Xn) + origin
    uw, _, fin_w = project_world(C, X)
    ok &= fin_w
    dist = disc_distances(uw, x, np.broadcast_to(rho, x.shape[:2]))     # the rule of point_report (review 10)
    return reported_batch(ok, optimal, c_lower, X, uw, fin_w, dist, norm, tolerances, mag)


def reported_batch(ok, optimal, c_lower, X, uw, fin_w, dist, norm, tolerances, magnitude) -> DiscBatch:
    """The :class:`DiscBatch` of a region verification from the world points X, their projections ``uw`` (finite
    where ``fin_w``) and distances ``dist`` (M, N) to the regions: gamma_UB at X, gamma_LB from the certified
    ``c_lower`` (normalised units, ``norm``'s scale; ``magnitude`` (M,) the round-off magnitudes at the estimates,
    :meth:`tritools.model.normalize.NormalizationStack.magnitudes_at`), the decision confirmed on these reported
    numbers."""
    N = dist.shape[1]
    gamma_ub = np.where(fin_w, gamma_upper(dist, norms(uw, axis=2)), np.inf)
    gamma_lb = gamma_lower(gamma_from_c(np.maximum(c_lower, 0.0), N, norm.scale), gamma_ub, norm.scale,
                           norm.lowering_resolution, magnitude)
    gamma_lb, contra = reported_lower(gamma_lb, gamma_ub, tolerances, N, norm.scale)     # (review 46a)
    certified = ok & optimal & ~contra & decide_reported(gamma_lb, gamma_ub, tolerances, N, norm.scale,
                                                         norm.resolution)
    return DiscBatch(certified, ok, X, gamma_lb, gamma_ub, uw, dist)


def as_disc_problem(cams, regions):
    """(cameras (N, 3, 4) float, centres (N, 2), radii (N,)) when every region is a disc, (cameras, centres,
    D (N, 2, 2)) when every region is a filled ellipse or a point (D = 0) by its conic form, not all discs nor all
    points (the vectorised ellipse path, :mod:`tritools.solve.ellipses`), and the cameras are a numeric
    (N, 3, 4) array, else None (the item then goes through :func:`tritools.triangulate`)."""
    if not isinstance(regions, (list, tuple)) or len(regions) < 2:
        return None
    radii = [disc_radius(r) for r in regions]
    if any(r is None for r in radii):
        radii = ellipse_shapes(regions)
        if radii is None:
            return None
    C = numeric_cameras(cams)
    if C is None:
        return None
    if C.shape != (len(regions), 3, 4):
        return None
    return C, np.array([r.center for r in regions]), np.array(radii)


def ellipse_shapes(regions) -> list | None:
    """D of every region when each is exactly a filled ellipse centred on its ``center`` or a point there (D = 0)
    by its conic form, not all points; else None."""
    forms = region_forms(regions)
    if forms is None or all(f.kind == ConeKind.POINT for f in forms):
        return None
    out = []
    for f, r in zip(forms, regions):
        exact = f.kind in (ConeKind.POINT, ConeKind.ELLIPSE) and not f.convexified
        if not exact or not np.array_equal(f.center, r.center):
            return None
        out.append(f.D if f.kind == ConeKind.ELLIPSE else np.zeros((2, 2)))
    return out


#: a certified disc/ellipse row behind a camera whose gamma_UB is at most this fraction of its smallest region goes to
#: the single call, which looks for an in-front minimiser (cost 0: the minimisers may form a set; the single call's
#: own rule is the trivial bound's, :func:`tritools.solve.trivial.trivially_certified_reported`)
FRONT_GAMMA_REL = 1e-6


def _region_size(shape) -> float:
    """The smallest positive radius of a row's discs (radii (N,)) or ellipses (D (N, 2, 2): sqrt of the larger
    eigenvalue); 0 where every view is a point."""
    a = np.asarray(shape, float)
    r = a if a.ndim == 1 else np.sqrt(np.maximum(np.linalg.eigvalsh(a)[:, -1], 0.0))
    r = r[r > 0]
    return float(r.min()) if r.size else 0.0


def solve_disc_group(group, opts):
    """Disc or ellipse problems of one N (``group``: [(index, cameras, centres, radii or D, regions)]) through
    :func:`verify_discs` / :func:`tritools.solve.ellipses.verify_ellipses`: ({index: certified result},
    [(index, cameras, regions, options, prefix)] for the per-point path, which continues with the SDP)."""
    from .ellipses import verify_ellipses

    done, rest = {}, []
    for part, verify in (([g for g in group if np.ndim(g[3]) == 1], verify_discs),
                         ([g for g in group if np.ndim(g[3]) == 3], verify_ellipses)):
        if part:
            d, r = _solve_group(part, opts, verify)
            done.update(d)
            rest.extend(r)
    return done, rest


def _solve_group(group, opts, verify):
    """:func:`solve_disc_group` on items of one kind, verified by ``verify`` (a :class:`DiscBatch`)."""
    import time

    from ..model.cameras import camera_problems, depths_stack
    from ..model.constraints import Method
    from ..result import Attempt, Status, TriangulationResult
    from .decide import cheirality
    from .settings import stack_deadline
    from .stages.context import AttemptStep
    from .stages.outcome import behind_message

    t0 = time.perf_counter()
    C = np.array([g[1] for g in group])
    x = np.array([g[2] for g in group])
    rho = np.array([g[3] for g in group])
    valid = camera_problems(C).valid
    C = np.where(valid[:, None, None, None], C, np.eye(3, 4))
    b = verify(C, x, rho, tolerances=opts.tolerances, deadline=stack_deadline(opts, len(group)))
    cert = b.certified & valid
    dep = depths_stack(C, b.X, opts.world_frame)
    status, in_front = cheirality(np.where(cert, Status.OPTIMAL.value, None), dep, opts.require_in_front)
    share = (time.perf_counter() - t0) / max(1, len(group))
    N = C.shape[1]
    n_lmivar = None
    done, rest = {}, []
    for k, (i, cams, _, _, regions) in enumerate(group):
        if not cert[k]:
            rest.append((i, cams, regions, opts.replace(path="sdp"),
                         (Attempt("corollary1", 2, "verification_failed", None, None, AttemptStep.VERIFICATION,
                                   "dense"),)))
            continue
        if not in_front[k] and b.gamma_ub[k] <= FRONT_GAMMA_REL * _region_size(group[k][3]):
            rest.append((i, cams, regions, opts, ()))    # cost ~0: minimisers in front may exist (tritools.solve.front)
            continue
        if n_lmivar is None:
            from sospoly import n_lmivar_formula

            n_lmivar = n_lmivar_formula(4 * N, 2, [2] * (N * (N - 1) // 2), [2] * N)
        g_ub = float(b.gamma_ub[k])
        msg = "" if in_front[k] else behind_message(dep[k])
        done[i] = TriangulationResult(
            Method.COROLLARY1.value, Status(status[k]), X=b.X[k], gamma_ub=g_ub, gamma_lb=float(b.gamma_lb[k]),
            optimal=True, delta=2, n_lmivar=n_lmivar, image_points=b.image_points[k], X_raw=b.X[k], gamma_ub_raw=g_ub,
            certified_by="verification", message=msg, timings={"batch_share": share},
            attempts=(Attempt("corollary1", 2, "verified", float(b.gamma_lb[k]), g_ub, AttemptStep.VERIFICATION,
                              "dense"),),
            sparsity="dense", in_front=bool(in_front[k]), depths=dep[k], residuals=b.residuals[k])
    return done, rest
