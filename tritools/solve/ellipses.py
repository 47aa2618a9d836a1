"""Certification by verification for filled ellipses (uncertain keypoints with a covariance), vectorised over a
stack: the ellipse twin of :mod:`tritools.solve.discs`.

View i's region is {y : (y - c_i)^T A_i (y - c_i) <= 1}, A_i = D_i^-1 = R_i diag(alpha_i) R_i^T (semi-axes
sigma_ik = alpha_ik^-1/2).  In the normalised frame (:mod:`tritools.model.normalize`, centres at the origin,
D_i' = s^2 D_i), in each view's own axes (u_i^loc = R_i^T u_i):

* the local optimum: Levenberg-Marquardt on the distances to the ellipses (:func:`refine_ellipses_stack`), with
  the exact Hessian of d^2 / 2 in u: for the closest point y = G u
  (:func:`tritools.solve.regions_verify.closest_on_ellipses`), G = (I + t A)^-1, t >= 0 the multiplier of
  u - y = t A y, it is  I - dy/du = (I - G) + n n^T / (y^T A n),  n = G A y; from the frame's origin (the DLT of
  the centres) and, where at least two views are points or ellipses far smaller than another
  (:func:`tritools.solve.trivial.small_views`), also from the DLT of those views
  alone (:func:`tritools.solve.trivial.point_views_start`) where the first did not certify, the lower cost kept
  (an ellipse of ~1e3 px whose centre is far from the optimum's projection drew the first start to a local minimum
  at 262 px, the optimum 0.18 px: review 40a);
* the degree-2 certificate with constant multipliers (:mod:`tritools.solve.regions_verify`): mu_i = t_i (0 inside),
  min_y L = sum_i (omega_i . (R_i^T x_i)^2 - mu_i) + lambda^T g(x), omega_ik = mu_i alpha_ik / (1 + mu_i alpha_ik)
  (rounded down): the point-region bound in the rotated frames, cameras [R_i^T 0; 0 1] P_i, views inside their
  ellipse dropped, the kept views compacted (:func:`tritools.solve.regions_verify.compact_bounds`: bands of view
  pairs from ``BAND_MIN_VIEWS`` kept views);
* the decision of every path (:func:`tritools.solve.decide.decide`), again on the numbers reported in pixels.
"""
from __future__ import annotations

import numpy as np

from sospoly import DEFAULT_TOLERANCES, Tolerances
from sospoly.budget import Deadline
from sospoly.solvers import with_single_threaded_blas

from ..model.frame import project_world, recentred
from ..model.normalize import normalization_stack
from ..model.stacked import LM_MAX_ITER, damped_step, lm_accept, project_stack
from .decide import decide
from .discs import DiscBatch, reported_batch
from .regions_verify import closest_on_ellipses, compact_bounds, ellipse_axes
from .trivial import point_views_start, small_views

__all__ = ["refine_ellipses_stack", "verify_ellipses"]

_ROUND_DOWN = 1 - 8 * np.finfo(float).eps


def _local_residual(u, R, sigma):
    """(e = u - y, y, t, outside) of the projections u (M, N, 2) on the ellipses (axes R, sigma), t the multiplier
    of u - y = t A y (0 inside); e in the global frame, y in the ellipses' axes.  A point region (sigma = 0) has
    y = 0, e = u and is always ``outside`` (its t is unused)."""
    pt = sigma[..., 1] == 0
    ul = np.einsum("...ji,...j->...i", R, u)
    yl, t = closest_on_ellipses(ul, np.where(pt[..., None], 1.0, sigma))
    yl = np.where(pt[..., None], 0.0, yl)
    el = ul - yl
    outside = (t > 0) | pt
    back = np.einsum("...ij,...j->...i", R, el)
    return back, yl, np.where(pt, 0.0, t), outside


def _hessian(yl, t, R, sigma, outside):
    """I - dy/du (module docstring) in the global frame, 0 inside, I for a point region."""
    pt = sigma[..., 1] == 0
    alpha = 1.0 / np.where(pt[..., None], 1.0, sigma) ** 2
    G = np.where(pt[..., None], 0.0, 1.0 / (1.0 + t[..., None] * alpha))
    n = G * alpha * yl
    den = np.sum(yl * alpha * n, axis=-1)
    den = np.where(outside & (den > 0), den, 1.0)
    H = (1.0 - G)[..., :, None] * np.eye(2) + n[..., :, None] * n[..., None, :] / den[..., None, None]
    H = np.einsum("...ij,...jk,...lk->...il", R, H, R)
    return np.where(outside[..., None, None], H, 0.0)


def _cost(Cn, R, sig_n, Xn):
    """The sum of squared distances to the ellipses at Xn (M, 3), inf where a projection is not finite."""
    u, _, fin = project_stack(Cn, Xn)
    e = _local_residual(np.where(fin[:, None, None], u, 0.0), R, sig_n)[0]
    return np.where(fin, np.sum(e ** 2, axis=(1, 2)), np.inf)


def refine_ellipses_stack(C, R, sigma, X, ok, deadline: Deadline | None = None):
    """Levenberg-Marquardt on sum_i dist(Phi(X, P_i), E_i)^2 (ellipses at the origin, axes R, sigma (M, N, ...))
    from X (M, 3), for the problems where ``ok`` (the twin of :func:`tritools.solve.discs.refine_discs_stack`, its
    ``deadline`` too)."""
    X = X.copy()
    mu = np.full(len(X), 1e-3)
    cost = _cost(C, R, sigma, X)
    ok = ok & np.isfinite(cost)
    active = np.nonzero(ok)[0]
    for _ in range(LM_MAX_ITER):
        if active.size == 0:
            break
        if deadline is not None and deadline.expired:
            ok = ok.copy()
            ok[active] = False
            break
        Ca, Ra, sa, Xa = C[active], R[active], sigma[active], X[active]
        u, h, _ = project_stack(Ca, Xa)
        e, yl, t, out = _local_residual(u, Ra, sa)
        De = _hessian(yl, t, Ra, sa, out)
        Ju = (Ca[..., :2, :3] - u[..., None] * Ca[..., 2:3, :3]) / h[..., 2][..., None, None]
        JtJ = np.einsum("mnai,mnab,mnbj->mij", Ju, De, Ju)
        g = np.einsum("mnai,mna->mi", Ju, e)
        step = damped_step(JtJ, g, mu[active])
        Xt = Xa + step
        ct = _cost(Ca, Ra, sa, Xt)
        active = lm_accept(X, cost, mu, active, Xa, step, Xt, ct)
    return X, ok & np.all(np.isfinite(X), axis=1)


def _bounds_at(Cw, Cn, R, sig_n, Xn, ok, resolution, tolerances, deadline):
    """(ok, optimal, c_lower) of the degree-2 certificate with constant multipliers at the local optima Xn (module
    docstring), decided by :func:`tritools.solve.decide.decide` in normalised units."""
    u, _, fin = project_stack(Cn, Xn)
    ok = ok & fin
    u = np.where(ok[:, None, None], u, 0.0)
    e, _, t, outside = _local_residual(u, R, sig_n)
    pt = sig_n[..., 1] == 0                              # point regions: weight 1, no multiplier
    alpha = 1.0 / np.where(pt[..., None], 1.0, sig_n) ** 2
    omega = np.where(outside[..., None], t[..., None] * alpha / (1.0 + t[..., None] * alpha), 0.0) * _ROUND_DOWN
    omega = np.where(pt[..., None], 1.0, omega)
    upper_f = np.sum(e ** 2, axis=(1, 2))
    radius = np.linalg.norm(sig_n[..., 0], axis=1) + np.sqrt(upper_f)
    z = np.einsum("mnji,mnj->mni", R, u)
    lower, ok_b = compact_bounds(Cw, _rotated(Cn, R), z, omega, -t, outside & ok[:, None], radius, resolution,
                                 tolerances, deadline=deadline)
    ok &= ok_b
    _, optimal, c_lower = decide(lower, upper_f, tolerances, Cn.shape[1], resolution)
    return ok, np.array(optimal, bool), np.array(c_lower, float)


def _rotated(Cn, R):
    """The cameras of the ellipses' frames: [R^T 0; 0 1] P per view."""
    T = np.zeros(R.shape[:-2] + (3, 3))
    T[..., :2, :2] = np.swapaxes(R, -1, -2)
    T[..., 2, 2] = 1.0
    return np.einsum("...ij,...jk->...ik", T, Cn)


@with_single_threaded_blas
def verify_ellipses(cameras, centers, D, *, tolerances: Tolerances = DEFAULT_TOLERANCES,
                    deadline: Deadline | None = None) -> DiscBatch:
    """Vectorised certification by verification of M filled-ellipse problems with N views each (module
    docstring): cameras (M, N, 3, 4), centres (M, N, 2) and shape matrices D (M, N, 2, 2) positive definite, in
    pixels, validated by the caller; D = 0 is a point region (weight 1, no region variable).  The result is a
    :class:`tritools.solve.discs.DiscBatch`."""
    C, x, D = (np.asarray(a, float) for a in (cameras, centers, D))
    M, N = x.shape[:2]
    R, sigma = ellipse_axes(D)
    ok = np.all(np.isfinite(x), axis=(1, 2)) & np.all(np.isfinite(sigma), axis=(1, 2)) \
        & np.all((sigma[..., 1] > 0) | ~np.any(D, axis=(2, 3)), axis=1)
    Cw, origin = recentred(C)          # georeferenced worlds: solved in re-centred frames
    norm = normalization_stack(Cw, x, ok)
    ok &= norm.ok
    Cn = norm.cameras_n
    sig_n = sigma * norm.scale[:, None, None]
    start_ok = ok
    Xn, ok = refine_ellipses_stack(Cn, R, sig_n, norm.Xn, ok, deadline)
    ok, optimal, c_lower = _bounds_at(Cw, Cn, R, sig_n, Xn, ok, norm.resolution, tolerances, deadline)
    idx = np.nonzero(start_ok & ~optimal)[0]                 # not certified from the centres: the second start
    if idx.size:
        X2, second = point_views_start(Cn[idx], small_views(sig_n[idx, :, 0]))
        idx, X2 = idx[second], X2[second]
    if idx.size and not (deadline is not None and deadline.expired):
        Xb, okb = refine_ellipses_stack(Cn[idx], R[idx], sig_n[idx], X2, np.ones(idx.size, bool), deadline)
        better = okb & (_cost(Cn[idx], R[idx], sig_n[idx], Xb) < _cost(Cn[idx], R[idx], sig_n[idx], Xn[idx]))
        j, Xb = idx[better], Xb[better]
        if j.size:
            Xn = Xn.copy()
            Xn[j] = Xb
            ok[j], optimal[j], c_lower[j] = _bounds_at(Cw[j], Cn[j], R[j], sig_n[j], Xb, np.ones(j.size, bool),
                                                       norm.resolution[j], tolerances, deadline)
    mag = norm.magnitudes_at(Cw, norm.world_points(Xn))    # the estimate's, in the frame normalised
    X = norm.world_points(Xn) + origin
    uw, _, fin_w = project_world(C, X)    # the reported numbers: compensated projections, as verify_discs (review 10)
    ok &= fin_w
    ew = _local_residual(np.where(fin_w[:, None, None], uw - x, 0.0), R, sigma)[0]
    return reported_batch(ok, optimal, c_lower, X, uw, fin_w, np.linalg.norm(ew, axis=2), norm, tolerances, mag)
