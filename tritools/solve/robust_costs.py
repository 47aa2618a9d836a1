"""Costs of TLS candidates for point regions: squared image distances of candidates to the observed points.

d_i(X)^2 = ||Phi(X, P_i) - x_i||^2 with Phi the projection (SPEC §1), +inf where the projection is undefined (the
denominator below :data:`tritools.model.geometry.PROJECTION_DENOM_RTOL` of its scale, the rule of
:func:`tritools.model.geometry.project_homogeneous`): an outlier view then costs c_i^2 in f_TLS, as it should.
"""
from __future__ import annotations

import math

import numpy as np

from ..model.geometry import PROJECTION_DENOM_RTOL
from ..model.refine import disc_shapes

__all__ = ["robust_thresholds", "MIN_THRESHOLD", "tls_cost", "tls_costs2", "decision_scale", "scale_from",
           "point_distances2", "point_distances2_one", "point_distances2_rows", "point_distances2_stack", "projections",
           "disc_distances2", "disc_shapes", "tls_start_stack", "START_PAIRS"]


#: the smallest threshold accepted (pixels): below it c^2 leaves the normal floats (review finding F3).  Above
#: ~1.3e154, c^2 = inf: min(d^2, c^2) = d^2 for every finite d, which is f_TLS exactly (no threshold in floats).
MIN_THRESHOLD = 1.5e-154


def robust_thresholds(robust, n_views: int) -> np.ndarray:
    """The thresholds c (N,) from ``robust=`` (a positive scalar or one per view, pixels; ``inf`` allowed).
    ValueError naming ``robust`` otherwise."""
    if type(robust) is float and robust >= MIN_THRESHOLD:      # the common case, a valid float (NaN fails >=)
        return np.full(n_views, robust)
    if isinstance(robust, np.ma.MaskedArray):       # (np.asarray drops the mask: masked entries would count)
        raise ValueError("robust must not be a masked array (its mask would be ignored): fill the masked "
                         "thresholds, e.g. robust.filled(np.inf) for views without one")
    try:
        raw = np.asarray(robust)
        if raw.dtype.kind not in "iuf":                  # booleans, strings and bytes, objects (None), complex
            raise TypeError
        c = raw.astype(float)
    except (TypeError, ValueError):
        raise ValueError(f"robust must be a positive threshold in pixels (scalar or one per view), "
                         f"got {_short(robust)}") from None
    if c.ndim == 0:
        c = np.full(n_views, float(c))
    if c.shape != (n_views,):
        raise ValueError(f"robust must be a scalar or have one threshold per view ({n_views}), got shape {c.shape}")
    if np.any(np.isnan(c)) or np.any(c <= 0):
        raise ValueError(f"robust thresholds must be positive (inf allowed), got {_short(c.tolist())}")
    if np.any(c < MIN_THRESHOLD):
        raise ValueError(f"robust thresholds must be at least {MIN_THRESHOLD:g} pixels (c^2 underflows below), "
                         f"got {float(np.min(c))!r}")
    return c


def _short(value, limit: int = 120) -> str:
    """repr(value), cut to ``limit`` characters (a bad entry in a long list stays a one-line message)."""
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 5] + " ...]"


def projections(X, cameras) -> np.ndarray:
    """Phi(X, P_i) (N, 2) of one point X (3,) in every camera (inf / nan where the depth is 0)."""
    Xh = np.append(X, 1.0)
    u = cameras @ Xh
    with np.errstate(all="ignore"):
        return u[:, :2] / u[:, 2:]


def point_distances2(C: np.ndarray, x: np.ndarray, Xs: np.ndarray) -> np.ndarray:
    """Squared distances ||Phi(X_m, P_i) - x_i||^2 (M, N) of candidates Xs (M, 3) to point regions x (N, 2); inf
    for a view whose projection is undefined (denominator below PROJECTION_DENOM_RTOL of its scale, the rule of
    :func:`tritools.model.geometry.project_homogeneous`) or not finite."""
    Xh = np.concatenate([Xs, np.ones((len(Xs), 1))], axis=1)
    u = np.einsum("nij,mj->mni", C, Xh)
    denom = np.einsum("nj,mj->mn", np.abs(C[:, 2]), np.abs(Xh))
    ok = np.abs(u[..., 2]) > PROJECTION_DENOM_RTOL * denom
    with np.errstate(all="ignore"):
        d2 = np.sum((u[..., :2] / u[..., 2:] - x[None]) ** 2, axis=2)
    return np.where(ok & np.isfinite(d2), d2, np.inf)


def point_distances2_stack(C: np.ndarray, x: np.ndarray, Xs: np.ndarray) -> np.ndarray:
    """:func:`point_distances2` of P problems at once: cameras C (P, N, 3, 4), points x (P, N, 2), candidates
    Xs (P, M, 3) -> (P, M, N), the same rule."""
    P, N, M = C.shape[0], C.shape[1], Xs.shape[1]
    Xh = np.concatenate([Xs, np.ones(Xs.shape[:2] + (1,))], axis=2)
    u = (Xh @ np.swapaxes(C.reshape(P, N * 3, 4), 1, 2)).reshape(P, M, N, 3)       # (batched matmul, not einsum)
    denom = np.abs(Xh) @ np.swapaxes(np.abs(C[:, :, 2]), 1, 2)
    ok = np.abs(u[..., 2]) > PROJECTION_DENOM_RTOL * denom
    with np.errstate(all="ignore"):
        d2 = np.sum((u[..., :2] / u[..., 2:] - x[:, None]) ** 2, axis=3)
    return np.where(ok & np.isfinite(d2), d2, np.inf)


def point_distances2_one(C: np.ndarray, absC2: np.ndarray, x: np.ndarray, X) -> np.ndarray:
    """:func:`point_distances2` for one candidate X (3,): (N,), the same rule; ``absC2`` = |C[:, 2, :]|."""
    Xh = np.array([X[0], X[1], X[2], 1.0], float)
    u = C @ Xh
    ok = np.abs(u[:, 2]) > PROJECTION_DENOM_RTOL * (absC2 @ np.abs(Xh))
    if ok.all() and np.isfinite(u).all():            # the common case, without np.errstate (its cost dominates):
        d = u[:, :2] / u[:, 2:] - x                   # |u_3| > 1e-10 |p_3| |X~| bounds the quotient
        if np.abs(d).max() < 1e150:                   # no overflow in the squares
            return d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]
    with np.errstate(all="ignore"):
        d = u[:, :2] / u[:, 2:] - x
        d2 = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]
    return np.where(ok & np.isfinite(d2), d2, np.inf)


def point_distances2_rows(C: np.ndarray, x: np.ndarray, X: np.ndarray) -> np.ndarray:
    """:func:`point_distances2_one` of R problems, one candidate each (tested equal, bit for bit): cameras C (R, N,
    3, 4), points x (R, N, 2), X (R, 3) -> (R, N), the same rule; the same matrix-vector products per camera (the
    stacked matmul of (3, 4) by (4, 1) items)."""
    Xh = np.concatenate([X, np.ones((len(X), 1))], axis=1)
    with np.errstate(all="ignore"):
        u = np.matmul(C, Xh[:, None, :, None])[..., 0]
        ok = np.abs(u[..., 2]) > PROJECTION_DENOM_RTOL * np.matmul(np.abs(C[:, :, 2]), np.abs(Xh)[:, :, None])[..., 0]
        d = u[..., :2] / u[..., 2:] - x
        d2 = d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1]
    return np.where(ok & np.isfinite(d2), d2, np.inf)


def disc_distances2(C: np.ndarray, centres: np.ndarray, radii: np.ndarray, Xs: np.ndarray) -> np.ndarray:
    """Squared distances (M, N) of the projections of candidates Xs (M, 3) to discs (centres (N, 2), radii (N,)):
    d = max(0, ||Phi(X_m, P_i) - c_i|| - rho_i) (the rule of :func:`point_distances2` for undefined projections:
    inf).  Plain arithmetic: for ranking candidates (exact costs decide, :func:`tritools.solve.report.point_report`)."""
    d2 = point_distances2(C, centres, Xs)
    if not np.any(radii):
        return d2
    with np.errstate(invalid="ignore"):
        d = np.maximum(np.sqrt(d2) - radii[None], 0.0)
    return np.where(np.isfinite(d2), d * d, np.inf)


def tls_cost(residuals, c) -> float:
    """f_TLS = sum_i min(d_i^2, c_i^2) (an undefined projection, d_i = inf, counts c_i^2)."""
    d = np.asarray(residuals, float)
    with np.errstate(over="ignore"):                  # c or d above 1e154: c^2 = inf, as it should
        d2 = np.where(np.isfinite(d), d * d, np.inf)
        return float(tls_costs2(d2, np.asarray(c, float) ** 2))


def tls_costs2(d2: np.ndarray, c2: np.ndarray) -> np.ndarray:
    """:func:`tls_cost` from squared distances along the last axis (any leading axes, ``c2`` broadcast):
    sum_i min(d_i^2, c_i^2)."""
    with np.errstate(invalid="ignore"):
        return np.sum(np.minimum(d2, c2), axis=-1)


def decision_scale(cams, regions, c2: np.ndarray) -> float:
    """The scale of the certificate rule on f_TLS (pixels^2): ``min(min_i c_i^2, rho^2)`` with rho = 1 / s the
    residual scale of the L2 normalisation (:mod:`tritools.model.normalize`; an L2 certificate allows
    ``gap_abs`` at c = s^2 f = 1).  Thresholds far above the residuals (or so large that c^2 overflows) thus
    never loosen the rule beyond the L2 one: f_TLS = L2 there."""
    from ..model.normalize import normalization_for

    return scale_from(normalization_for(cams, regions).scale, c2)


def scale_from(s: float, c2: np.ndarray) -> float:
    """:func:`decision_scale` from the L2 normalisation's image scale s (a batch computes s for many problems in
    one :func:`tritools.model.normalize.normalization_stack` call)."""
    finite = c2[np.isfinite(c2) & (c2 > 0)]
    rho2 = 1.0 / (s * s) if np.isfinite(s) and s > 0 else math.inf
    scale = min([rho2, *finite.tolist()])
    return float(scale) if np.isfinite(scale) and scale > 0 else 1.0


#: view pairs (i, i + 1), i = 0, 1, ... (cyclic) whose DLT points :func:`tls_start_stack` offers beside the DLT point
#: of all views: with a fraction e of wrong matches a pair is clean with probability ~(1 - e)^2, so 8 pairs miss
#: every clean one with probability ~(1 - (1 - e)^2)^8 (0.5% at e = 0.3) where the DLT point of all views is pulled
#: off by any wrong match.
START_PAIRS = 8


def tls_start_stack(C: np.ndarray, x: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A cheap TLS estimate of M problems (cameras C (M, N, 3, 4), points or region centres x (M, N, 2),
    thresholds c (M, N)): of the DLT point of all views and those of :data:`START_PAIRS` view pairs, the one of
    least sum_i min(d_i^2, c_i^2) on the distances to x -- (X (M, 3), ok (M,)).  For the rows of problems not solved
    before a time limit (:func:`tritools.solve.robust_batch.expired_tls`): no refinement, any X is a valid
    estimate (its exact TLS value is what is reported), and the DLT point of all views alone fits every wrong
    match (120 six-view problems of one wrong match: 0 inliers of 6 at c = 3 px in each)."""
    from ..model.stacked import dlt_stack

    M, N = x.shape[:2]
    X_all, ok_all = dlt_stack(C, x)
    K = min(N if N > 2 else 0, START_PAIRS)
    if not K:
        return X_all, ok_all
    i = np.arange(K)
    j = (i + 1) % N
    Cp = np.stack([C[:, i], C[:, j]], axis=2).reshape(M * K, 2, 3, 4)
    xp = np.stack([x[:, i], x[:, j]], axis=2).reshape(M * K, 2, 2)
    with np.errstate(all="ignore"):
        Xp, okp = dlt_stack(Cp, xp)
    Xs = np.concatenate([X_all[:, None], Xp.reshape(M, K, 3)], axis=1)              # (M, K + 1, 3)
    ok = np.concatenate([ok_all[:, None], okp.reshape(M, K)], axis=1) & np.isfinite(Xs).all(axis=2)
    d2 = point_distances2_stack(C, x, np.where(ok[..., None], Xs, 0.0))
    with np.errstate(over="ignore"):
        cost = tls_costs2(d2, (np.asarray(c, float) ** 2)[:, None])
    cost = np.where(ok & np.isfinite(cost), cost, np.inf)
    best = np.argmin(cost, axis=1)
    rows = np.arange(M)
    return Xs[rows, best], ok[rows, best]
