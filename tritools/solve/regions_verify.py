"""Certification by verification for uncertain regions of every type (issue #22): the degree-2 certificate with
constant multipliers, the region variables eliminated exactly, view by view.

In the Corollary 1 program (SPEC §2, §7) of the normalised data (:mod:`tritools.model.normalize`) view i has
the image point x_i in R^2, region variables y_i and f = sum_i f_i(x_i, y_i), the epipolar constraints
g_jk(x) = 0 and the region constraints h_i(y_i) >= 0 (= 0 for an ellipse border), all quadratic.  For
multipliers lambda (free) and mu_i (>= 0 for inequalities, free for the border's equality) the Lagrangian

    L(x, y) = f(x, y) + lambda^T g(x) - sum_i mu_i^T h_i(y_i)

satisfies min L <= min {f : g = 0, h >= 0} (on the feasible set -mu^T h <= 0): the weak Positivstellensatz at
delta = 2 with constant multipliers (SPEC §5), so whatever this module certifies the delta = 2 SDP certifies
too.  For fixed x, L is a sum over views of quadratics in y_i; where each is strictly convex its minimum is
exact (a 2 x 2 Schur complement):

* filled ellipse ``h = 1 - (y - c)^T A (y - c)`` (A = D^-1) and polytope ``h_k = 1 - (B_k y + c_k)^2``
  (paper Section 4.2): -mu^T h = y^T H y + 2 b^T y + k0, with H = mu A, b = -mu A c, k0 = mu (c^T A c - 1)
  for the ellipse and H = B^T M B, b = B^T M c, k0 = sum_k mu_k (c_k^2 - 1), M = diag(mu), for the polytope;
  with I + H > 0 (always for mu >= 0: checked with a margin all the same)

      min_y ||x - y||^2 + y^T H y + 2 b^T y + k0 = x^T W x + 2 w^T x + q0,
      W = I - (I + H)^-1,  w = (I + H)^-1 b,  q0 = k0 - b^T (I + H)^-1 b;

* segment ``f = ||x - c - t d||^2, h = 1 - t^2``: min_t = (x - c)^T W (x - c) - mu, W = I - d d^T / (|d|^2 + mu);
* point: W = I, w = -c, q0 = |c|^2;
* ellipse border (its conic form is the filled ellipse, flagged convexified): the filled ellipse, a superset, so
  a valid lower bound (the border's free multiplier restricted to mu >= 0: a choice the SDP has too); its
  candidate's distance, the upper bound, is the border's own.

The region types are read from the regions' conic forms (:func:`region_forms`: the solvers ask the region, they
do not test its class), so a user region with an exact conic form is verified the same way.

The multipliers are the KKT ones at the local optimum (x^, y^ the closest region points): mu A (y^ - c) = e
(ellipse: the multiplier of its closest point, :func:`closest_on_ellipses`), sum_k mu_k s_k B_k = e over the
active faces, s_k = B_k y^ + c_k (polytope, corners included),
mu t^ = d^T e (segment), with e = x^ - y^; inequality multipliers are clipped at 0 (any mu >= 0 is valid).
A view whose candidate lies inside its region has mu = 0, W = 0: it drops out with its epipolar constraints
(fewer constraints: a weaker, valid bound), as for discs.

Per view, W = Q diag(omega) Q^T (omega rounded down) and x_i = a_i + Q_i z_i with W a_i = -w_i turn the
reduced Lagrangian into ``sum_i (omega_i . z_i^2 + const_i) + lambda^T g'(z)`` with the cameras of the z
frames P'_i = T_i^-1 P_i (T_i = [[Q_i, a_i], [0, 1]]): the point-region bound of
:func:`tritools.solve.fastpath.lagrangian_bounds` with per-coordinate weights, valid whenever its reduced
Hessian is PSD (checked rigorously there).  A direction with omega = 0 along which w is not 0 makes L
unbounded below: no claim.  The kept views of each problem are gathered into a compact stack
(:func:`compact_bounds`), so the band of view pairs of fastpath applies from ``BAND_MIN_VIEWS`` kept views
whatever views lie inside their regions.

Polytope faces are quadratic slabs here, so L is strictly convex in y (the |x - y|^2 term); a single active
face (or a candidate inside a segment) leaves omega = 0 along the face, which the PSD test of the Lagrangian
rejects unless the epipolar multipliers vanish there: :mod:`tritools.solve.faces` then tries a positive
multiplier on the inactive constraints, priced within the tolerance (``face_mu``); what that does not certify
goes to the SDP, which decides at delta = 2 with the best multipliers.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sospoly import DEFAULT_TOLERANCES, Tolerances
from sospoly.budget import Deadline

from ..model.regions import ConeKind, ConicForm, Region, conic_form_of, extent_of
from ..model.regions.shapes import shape_fields
from .fastpath import BAND_MIN_VIEWS, BAND_WIDTHS, all_pairs_seconds, band_seconds, lagrangian_bounds, seconds_fit

__all__ = ["ViewQuadratics", "view_quadratics", "reduce_views", "compact_bounds", "region_bound", "region_forms",
           "constraint_counts", "ellipse_axes", "closest_on_ellipses", "ACTIVE_RTOL", "PD_MARGIN",
           "ELLIPSE_NEWTON_ITER", "region_bound_fits", "REGION_SETUP_SECONDS"]

_ROUND_DOWN = 1 - 8 * np.finfo(float).eps
#: a polytope face k is active at y^ when |B_k y^ + c_k| >= 1 - ACTIVE_RTOL.
ACTIVE_RTOL = 1e-7
#: I + H must have eigenvalues >= PD_MARGIN, omega below
#: PD_MARGIN * max(1, |W|) counts as 0.
PD_MARGIN = 1e-12
#: Newton iterations of the secular equation of the closest ellipse point (quadratic convergence: < 10 in
#: practice; rows still moving after this many keep their last iterate, slightly inside the border).
ELLIPSE_NEWTON_ITER = 60


def region_forms(regions) -> list[ConicForm] | None:
    """The regions' conic forms (:meth:`~tritools.model.regions.Region.conic_form`, asked of each region) when
    this module eliminates every one exactly: an exact set of any kind (point, segment, polytope, filled
    ellipse), or a convexified ELLIPSE (e.g. an ellipse border: its filled ellipse is a superset, so the bound of
    the relaxation is a valid lower bound, the multiplier mu >= 0 one the SDP may choose too); None otherwise
    (also for a region without ``conic_form()`` or ``extent()``)."""
    if not all(isinstance(r, Region) for r in regions):
        return None
    try:
        forms = [conic_form_of(r) for r in regions]
        for r in regions:
            extent_of(r)
    except (TypeError, ValueError, AttributeError, NotImplementedError):
        return None
    if any(f.convexified and f.kind != ConeKind.ELLIPSE for f in forms):
        return None
    return forms


def constraint_counts(forms) -> tuple[int, int]:
    """(equalities, inequalities) the regions of these conic forms add to the Corollary 1 program, all quadratic
    (paper Section 4.2): a border (a convexified ellipse) one equality, a segment or filled ellipse one
    inequality, a polytope one per slab."""
    n_eq = sum(f.kind == ConeKind.ELLIPSE and f.convexified for f in forms)
    n_ineq = sum(len(f.c) if f.kind == ConeKind.POLYTOPE else int(f.kind == ConeKind.SEGMENT or
                                                                  (f.kind == ConeKind.ELLIPSE and not f.convexified))
                 for f in forms)
    return n_eq, n_ineq


def ellipse_axes(D: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R (..., 2, 2), sigma (..., 2)): D = R diag(sigma^2) R^T, largest semi-axis first; the closed forms of
    :func:`~tritools.model.regions.shapes.shape_fields` (the regions' own: eigh's minor semi-axis of a thin ellipse is
    off by ~eps lam_max / lam_min of itself, 3e-7 at an axis ratio of 1e5, so the verification bounded another
    ellipse); D = 0 (a point) gives sigma = 0."""
    D = np.asarray(D, float)
    flat = D.reshape(-1, 2, 2)
    _, axes, Q, _, lam = shape_fields(flat)
    with np.errstate(invalid="ignore"):
        sigma = np.sqrt(np.maximum(np.nan_to_num(lam[:, ::-1], nan=0.0), 0.0))
    zero = ~np.any(flat, axis=(1, 2))
    Q[zero] = np.eye(2)
    return Q.reshape(D.shape), sigma.reshape(D.shape[:-1])


def closest_on_ellipses(U: np.ndarray, sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(closest points Y, multipliers t) of the filled ellipses sum_k x_k^2 / sigma_k^2 <= 1 (per row) to the points
    U (..., 2) in the ellipses' own axes: Y = U inside (t = 0), else y_k = u_k / (1 + t alpha_k) with t > 0 the
    root of the secular equation r(t)^2 = sum_k alpha_k u_k^2 / (1 + t alpha_k)^2 = 1 (alpha = sigma^-2): t is
    the KKT multiplier of u - y = t A y.  Newton on K(t) = 1 / r(t) - 1, increasing and concave in t (as in
    More and Sorensen's trust-region iteration), from t = 0: the iterates rise monotonically to the root,
    quadratically near it (exact in one step for a disc).

    Computed in the units of each ellipse's larger axis rounded to a power of two, lam (U / lam, sigma / lam: exact,
    so the same numbers for ordinary sizes), then t = t' lam^2 and Y = Y' lam: alpha^2 of a radius below ~1e-77 px
    overflowed, the Newton step was NaN and a point far outside a tiny ellipse came back "inside" (Y = U, t = 0;
    review 39a F5: a false certificate in a batch).  A Y that Newton left outside the ellipse (it rises from the
    left: short of the root, Y is outside) is scaled onto the border, so |U - Y| is always an upper bound of the
    distance; a row whose iteration fails (non-finite) gets the centre Y = 0 and t = 0."""
    lam = np.ldexp(1.0, np.frexp(np.max(sigma, axis=-1))[1])[..., None]
    Y, t = _closest_scaled(U / lam, sigma / lam)
    level = np.sum((Y * lam / sigma) ** 2, axis=-1)
    far = level > 1.0 + 1e-12             # Newton stopped short (from the left: outside): scaled onto the border
    if np.any(far):
        Y = np.where(far[..., None], Y * ((1.0 - 4 * np.finfo(float).eps) / np.sqrt(np.where(far, level, 1.0)))[
            ..., None], Y)
    t = t * lam[..., 0] ** 2
    Y = Y * lam
    bad = ~(np.all(np.isfinite(Y), axis=-1) & np.isfinite(t))
    if np.any(bad):
        Y, t = np.where(bad[..., None], 0.0, Y), np.where(bad, 0.0, t)
    return Y, t


def _closest_scaled(U: np.ndarray, sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`closest_on_ellipses` in the units of the larger axis (sigma <= 1)."""
    alpha = 1.0 / sigma ** 2
    level = np.sum(alpha * U * U, axis=-1)
    out = level > 1.0
    t = np.zeros(level.shape)
    active = out.copy()
    for _ in range(ELLIPSE_NEWTON_ITER):
        if not active.any():
            break
        q = 1.0 / (1.0 + t[..., None] * alpha)
        r2 = np.sum(alpha * (U * q) ** 2, axis=-1)
        dr2 = -2.0 * np.sum(alpha ** 2 * U ** 2 * q ** 3, axis=-1)          # d r^2 / dt
        r2 = np.where(active, r2, 1.0)
        K = 1.0 / np.sqrt(r2) - 1.0
        dK = -0.5 * (dr2 / r2) / np.sqrt(r2)                                # (r2^1.5 overflows first)
        step = np.where(active & (dK > 0), -K / np.where(dK > 0, dK, 1.0), 0.0)
        t_new = np.maximum(t + step, t)                                     # monotone from the left
        active &= t_new - t > 4 * np.finfo(float).eps * np.maximum(t_new, np.finfo(float).tiny)
        t = t_new
    Y = np.where(out[..., None], U / (1.0 + t[..., None] * alpha), U)
    return Y, t


@dataclass(frozen=True)
class ViewQuadratics:
    """min over y_i of the view's Lagrangian, x^T W x + 2 w^T x + q0 (module docstring), for M x N views:
    ``W`` (M, N, 2, 2), ``w`` (M, N, 2), ``q0`` (M, N); ``valid`` False where the minimum is not exact
    (I + H not positive definite) or the data not finite."""
    W: np.ndarray
    w: np.ndarray
    q0: np.ndarray
    valid: np.ndarray


def _from_y_quadratic(H, b, k0):
    """(W, w, q0, ok) of min_y ||x - y||^2 + y^T H y + 2 b^T y + k0 (module docstring), over leading axes."""
    S = np.eye(2) + H
    det = S[..., 0, 0] * S[..., 1, 1] - S[..., 0, 1] * S[..., 1, 0]
    tr = S[..., 0, 0] + S[..., 1, 1]
    ok = (det > PD_MARGIN * np.maximum(1.0, tr) ** 2) & (tr > 0)
    det = np.where(ok, det, 1.0)
    G = np.stack([np.stack([S[..., 1, 1], -S[..., 0, 1]], -1), np.stack([-S[..., 1, 0], S[..., 0, 0]], -1)], -2)
    G = G / det[..., None, None]
    G = (G + np.swapaxes(G, -1, -2)) / 2
    W = np.eye(2) - G
    w = np.einsum("...ij,...j->...i", G, b)
    bw = np.einsum("...i,...i->...", b, w)
    q0 = k0 - bw - 16 * np.finfo(float).eps * (np.abs(k0) + np.abs(bw))     # rounded down
    return W, w, q0, ok & np.isfinite(q0)


def _ellipse(form: ConicForm, u):
    """(W, w, q0, ok) of the filled ellipse of ``form`` at the candidate u: mu = t of its closest point."""
    A, c = form.Dinv, form.center
    R, sigma = ellipse_axes(form.D)
    mu = float(closest_on_ellipses((R.T @ (u - c))[None], sigma[None])[1][0])
    return _from_y_quadratic(mu * A, -mu * (A @ c), mu * (float(c @ A @ c) - 1.0))


def _polytope(form: ConicForm, u, y, face_mu: float = 0.0):
    """(W, w, q0, ok) of a polytope ||B y + c||_inf <= 1 (faces h_k = 1 - (B_k y + c_k)^2), y the closest point;
    ``face_mu`` > 0: on a single active slab, that multiplier on every inactive slab (:mod:`tritools.solve.faces`)."""
    B, c = form.B, form.c
    s = B @ y + c
    e = u - y
    mu = np.zeros(len(c))
    act = np.abs(s) >= 1.0 - ACTIVE_RTOL
    J = (B[act] * s[act, None]).T                         # 2 x n_active: columns s_k B_k
    if np.any(act) and np.any(e != 0) and np.all(np.isfinite(J)) and np.all(np.isfinite(e)):
        sol = np.linalg.lstsq(J, e, rcond=None)[0]        # (overflowed data, B ~ 1e180: no multipliers, not verified)
        mu[act] = np.maximum(sol, 0.0)
        if face_mu > 0 and act.sum() == 1:
            mu[~act] = face_mu / max(1, int((~act).sum()))
    H = (B.T * mu) @ B
    return _from_y_quadratic(H, B.T @ (mu * c), float(mu @ (c * c) - mu.sum()))


def _segment(form: ConicForm, u, face_mu: float = 0.0):
    """(W, w, q0, ok) of a segment {c + t d : |t| <= 1} (h = 1 - t^2); ``face_mu``: the multiplier of h where
    the closest point is inside the segment (KKT: 0; :mod:`tritools.solve.faces`)."""
    c, d = form.center, form.direction
    dd = float(d @ d)
    t = float(np.clip(d @ (u - c) / dd, -1.0, 1.0)) if dd > 0 else 0.0
    e = u - c - t * d
    mu = max(float(d @ e) / t, 0.0) if abs(t) >= 1.0 else max(float(face_mu), 0.0)
    den = dd + mu
    W = np.eye(2) - (np.outer(d, d) / den if den > 0 else 0.0)
    w = -W @ c
    return W, w, float(c @ W @ c) - mu, np.isfinite(den)


def view_quadratics(forms, regions_n, u: np.ndarray, face_mu: float = 0.0) -> ViewQuadratics:
    """:class:`ViewQuadratics` of one problem (M = 1): the conic forms of the normalised regions
    (:func:`region_forms`), the regions (asked for a polytope's closest point) and the candidate projections
    u (N, 2); ``face_mu`` >= 0 the multiplier given to the inactive constraints of a view whose closest point lies
    inside a segment or on one face of a polytope (0: the KKT multipliers; :mod:`tritools.solve.faces`)."""
    N = len(forms)
    W, w, q0, valid = np.zeros((1, N, 2, 2)), np.zeros((1, N, 2)), np.zeros((1, N)), np.zeros((1, N), bool)
    for i, (f, r, ui) in enumerate(zip(forms, regions_n, u)):
        if f.kind == ConeKind.POINT:
            out = (np.eye(2), -f.center, float(f.center @ f.center), True)
        elif f.kind == ConeKind.SEGMENT:
            out = _segment(f, ui, face_mu)
        elif f.kind == ConeKind.POLYTOPE:
            out = _polytope(f, ui, r.closest_point(ui), face_mu)
        else:
            out = _ellipse(f, ui)
        W[0, i], w[0, i], q0[0, i], valid[0, i] = out
    return ViewQuadratics(W, w, q0, valid & np.isfinite(W).all(axis=(2, 3)) & np.isfinite(w).all(axis=2))


def reduce_views(vq: ViewQuadratics):
    """(omega (M, N, 2), Q (M, N, 2, 2), a (M, N, 2), const (M, N), bounded (M, N)): W = Q diag(omega) Q^T with
    omega rounded down, a solving W a = -w on the range of W, const = q0 - a^T W a rounded down; ``bounded``
    False where w has a component along a zero omega (L unbounded below) or the view is not valid."""
    W = np.where(vq.valid[..., None, None], vq.W, np.eye(2))
    omega, Q = np.linalg.eigh(W)
    scale = np.maximum(1.0, np.abs(omega).max(axis=-1, keepdims=True))
    zero = np.abs(omega) <= PD_MARGIN * scale
    wq = np.einsum("...ji,...j->...i", Q, vq.w)              # Q^T w
    bounded = vq.valid & ~np.any(zero & (np.abs(wq) > PD_MARGIN * np.maximum(1.0, np.abs(wq).max(-1,
                                                                                           keepdims=True))), -1)
    omega = np.where(zero, 0.0, omega)
    za = np.where(zero, 0.0, -wq / np.where(zero, 1.0, omega))   # a = Q za
    a = np.einsum("...ij,...j->...i", Q, za)
    const = vq.q0 - np.einsum("...i,...i,...i->...", za, omega, za)
    const = const - 16 * np.finfo(float).eps * (np.abs(vq.q0) + np.einsum("...i,...i,...i->...", za, np.abs(omega), za))
    # every W is PSD in exact arithmetic (mu >= 0): its eigenvalues are >= 0 and within 8 eps |W| of the computed
    # ones, so rounding down by that much and clipping at 0 keeps each weight at or below the exact one
    omega = np.maximum(omega * _ROUND_DOWN - 8 * np.finfo(float).eps * scale, 0.0)
    return omega, Q, a, const, bounded


def _frame_cameras(Cn: np.ndarray, Q: np.ndarray, a: np.ndarray) -> np.ndarray:
    """The cameras of the z frames: P' = T^-1 P, T^-1 = [[Q^T, -Q^T a], [0, 1]] (per view)."""
    Ti = np.zeros(Q.shape[:-2] + (3, 3))
    Ti[..., :2, :2] = np.swapaxes(Q, -1, -2)
    Ti[..., :2, 2] = -np.einsum("...ji,...j->...i", Q, a)
    Ti[..., 2, 2] = 1.0
    return np.einsum("...ij,...jk->...ik", Ti, Cn)


def compact_bounds(C, Cn, z, weights, const, kept, radius, resolution, tolerances: Tolerances, *,
                   deadline: Deadline | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(lower bound in c units (NaN: none), ok) of min sum_i (weights_i . z_i^2 + const_i) s.t. the epipolar
    constraints between the ``kept`` views (M, N) of the cameras ``Cn`` (frames of z; raw cameras ``C`` decide
    coincident centres), at the candidates z (M, N, 2).  Views not kept contribute const_i (their z free, no
    constraint).  Problems are grouped by their number of kept views and each group's kept views gathered into
    one compact stack for :func:`tritools.solve.fastpath.lagrangian_bounds` (bands of view pairs from
    BAND_MIN_VIEWS kept views, all pairs for the rest)."""
    M, N = kept.shape
    lower = np.full(M, np.nan)
    ok = np.ones(M, bool)
    base = np.sum(np.where(kept, 0.0, const), axis=1)
    counts = kept.sum(axis=1)
    for n in np.unique(counts):
        rows = np.nonzero(counts == n)[0]
        if n < 2:                                       # no epipolar constraint: min over z is at z = 0
            lower[rows] = base[rows] + np.sum(np.where(kept[rows], const[rows], 0.0), axis=1)
            continue
        cols = np.argsort(~kept[rows], axis=1, kind="stable")[:, :n]
        take = (rows[:, None], cols)
        v = z[take].reshape(len(rows), -1)
        wts = weights[take].reshape(len(rows), -1)
        f0 = np.sum(const[take], axis=1)
        lo, _, okr = lagrangian_bounds(C[take], Cn[take], v, np.ones(len(rows), bool), radius[rows],
                                       resolution[rows], tolerances, f0=f0, weights=wts, deadline=deadline)
        lower[rows] = np.where(okr, lo + base[rows], np.nan)
        ok[rows] = okr
    return lower, ok


#: seconds per view of :func:`region_bound`'s set-up before its Lagrangian bound (closest points, view quadratics:
#: per-view Python; measured ~0.3 ms a view of mixed regions at N = 100).
REGION_SETUP_SECONDS = 3e-4


def region_bound_fits(deadline: Deadline | None, n_views: int) -> bool:
    """Can :func:`region_bound` bound anything in what is left of ``deadline`` (None: always)?  Its set-up
    (:data:`REGION_SETUP_SECONDS` a view) and then its cheapest Lagrangian bound (the narrowest band from
    BAND_MIN_VIEWS views, else all pairs) must fit, by the rule of the point bounds
    (:func:`tritools.solve.fastpath.lagrangian_bounds`, which would skip the bound after the set-up: 30 ms past a
    0.05 s limit at 100 views of mixed regions)."""
    bound = band_seconds(n_views, BAND_WIDTHS[0]) if n_views >= BAND_MIN_VIEWS and BAND_WIDTHS[0] < n_views - 1 \
        else all_pairs_seconds(n_views)
    return seconds_fit(deadline, n_views * REGION_SETUP_SECONDS + bound)


def region_bound(C, Cn, regions_n, Xn, extents, *, forms=None, tolerances: Tolerances = DEFAULT_TOLERANCES,
                 resolution: float = np.inf, deadline: Deadline | None = None):
    """(c_lower (NaN: none), c_upper = f at the candidate, image points u (N, 2)) of one problem: raw and
    normalised cameras (N, 3, 4), normalised regions (their conic forms ``forms``, default
    :func:`region_forms`, must not be None), the normalised local optimum Xn and the regions' extents (radii of
    balls around the normalised origin holding them)."""
    from ..model.stacked import project_stack

    forms = region_forms(regions_n) if forms is None else forms
    u, _, fin = project_stack(Cn[None], np.asarray(Xn, float)[None])
    u = u[0]
    if not fin[0] or not np.all(np.isfinite(u)):
        return np.nan, np.inf, u
    y = np.array([r.closest_point(ui) for r, ui in zip(regions_n, u)])
    c_upper = float(np.sum((u - y) ** 2))
    from .faces import face_bound

    lower = face_bound(lambda mu: _bound_at(C, Cn, forms, regions_n, u, extents, c_upper, mu, tolerances,
                                            resolution, deadline), forms, c_upper, tolerances,
                       deadline=deadline)
    return lower, c_upper, u


def _bound_at(C, Cn, forms, regions_n, u, extents, c_upper, face_mu, tolerances, resolution, deadline) -> float:
    """The lower bound (NaN: none) of :func:`region_bound` with the face multiplier ``face_mu``."""
    omega, Q, a, const, bounded = reduce_views(view_quadratics(forms, regions_n, u, face_mu))
    if not bounded.all():
        return np.nan
    kept = np.any(omega != 0, axis=-1)
    z = np.einsum("mnji,mnj->mni", Q, u[None] - a)
    radius = np.array([np.linalg.norm(np.asarray(extents) + np.linalg.norm(a[0], axis=1)) + np.sqrt(c_upper)])
    lower, ok = compact_bounds(np.asarray(C, float)[None], _frame_cameras(Cn[None], Q, a), z, omega, const, kept,
                               radius, np.array([resolution]), tolerances, deadline=deadline)
    return float(lower[0]) if ok[0] else np.nan
