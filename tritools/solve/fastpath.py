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
   PSD test of the Lagrangian Hessian, exact minimum c of the Lagrangian quadratic (:func:`lagrangian_bounds`;
   from ``BAND_MIN_VIEWS`` views first with the constraints of a band of view pairs only, by
   :func:`sospoly.analysis.verify_sparse.verify_quadratic_banded_batch`: a subset of the constraints gives a
   valid, possibly weaker bound at a cost linear in N; all pairs for what no band certifies);
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
import math
from dataclasses import dataclass

import numpy as np

from sospoly import DEFAULT_TOLERANCES, Tolerances
from sospoly.budget import Deadline, TimeLimitReached, cpu_share
from sospoly.analysis import verify_quadratic_batch
from sospoly.analysis import verify_quadratic_banded_batch
from sospoly.solvers import with_single_threaded_blas

from ..model.epipolar_data import epipolar_errors
from ..model.frame import project_world, project_world_one
from ..model.geometry import camera_problems
from ..model.normalize import normalization_stack
from ..model.stacked import (band_pairs, epipolar_quadratics, fundamental_stack_both, gauss_newton_polish, norms,
                             project_one, project_stack, refine_point, refine_points_stack, view_pairs)
from .decide import (decide, decide_one, decide_reported, decide_reported_one, gamma_from_c, gamma_lower,
                     gamma_lower_one, reported_lower, transfer_contradicts_one)
from .report import gamma_upper
from .trivial import trivially_certified, trivially_certified_reported

__all__ = ["FastPathBatch", "verify_points", "verify_checked", "verify_one", "stack_point_problems",
           "lagrangian_bounds", "BAND_MIN_VIEWS", "BAND_WIDTHS",
           "band_seconds", "BAND_SECONDS", "BAND_SECONDS_PER_VIEW", "seconds_fit", "all_pairs_seconds"]

#: from this many views on, the certificate is first tried with the epipolar constraints of bands of view
#: pairs (:func:`_band_bounds`, cost linear in N), of the widths ``BAND_WIDTHS`` in turn; problems no band
#: certifies fall back to all N(N - 1)/2 pairs.  Measured (benchmarks/pointscale.py): the multipliers of a
#: band carry the KKT residual along the chain of views, so they grow with N and the noise and the Lagrangian
#: Hessian can lose definiteness; width 4 certifies 1 px tracks up to N = 200, width 8 most of the rest.
BAND_MIN_VIEWS = 12
#: the widths tried: pairs (i, i + d), 1 <= d <= width.
BAND_WIDTHS = (4, 8)
#: memory of one call of the all-pairs bound (the fallback is chunked to stay below it).
ALL_PAIRS_CHUNK_BYTES = 256 * 2 ** 20
#: flops per second at which :func:`all_pairs_seconds` counts the all-pairs bound (measured ~2e9 n^2 K per second
#: on the 2-core machine at N = 200; half of it, so the estimate errs long).
ALL_PAIRS_FLOPS = 1e9
#: ... plus this many seconds per pair and problem (the stacked arrays' own cost, which the flop count leaves out:
#: measured 0.09-0.22 ms per problem at N = 7-11 against an n^2 K count of 0.004-0.03 ms, review 15 F1)
ALL_PAIRS_PAIR_SECONDS = 4e-6
#: seconds per view at which :func:`band_seconds` counts a band bound: a fixed part per view plus a part per view
#: and squared width, fitted to the measured times (one problem of 100-400 views, points and discs: ~2e-4 s per view
#: at width 4, ~7e-4 at width 8).  Not rounded up: the band's column loops stop at the active deadline
#: (:mod:`sospoly.analysis.banded`), so a band that runs longer than estimated costs the rest of the limit, never more,
#: while an estimate that errs long skips bands that would certify in time (review 10: N = 400 at 0.1-0.15 s).
BAND_SECONDS_PER_VIEW = 5.0e-5
BAND_SECONDS = 1.0e-5


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
    gamma_at_X: np.ndarray                 # gamma(X) on the caller's data: the upper bound
    image_points: np.ndarray
    c_lower: np.ndarray
    c_upper: np.ndarray
    scale: np.ndarray
    trivial: np.ndarray
    #: (M, N) the distances ||Phi(X, P_i) - x_i|| on the caller's data (inf where a projection is not finite),
    #: the residuals of the report (:func:`tritools.solve.report.points_report_stack`, the same formula)
    residuals: np.ndarray | None = None

    @property
    def gamma_ub(self) -> np.ndarray:
        """The upper bound ``gamma_ub = gamma(X)`` (``gamma_at_X``; the batch record of a result is
        :class:`tritools.records.TriangulationResults`)."""
        return self.gamma_at_X


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
def verify_points(cameras, points2d, *, tolerances: Tolerances = DEFAULT_TOLERANCES,
                  deadline: Deadline | None = None) -> FastPathBatch:
    """Vectorised certification by verification of M point problems with N views each.

    Parameters
    ----------
    cameras : array (M, N, 3, 4)
        Projection matrices of each problem (pixels).
    points2d : array (M, N, 2)
        Observed image points (the point regions' centres).
    tolerances : sospoly.Tolerances
        The certificate rule.
    deadline : sospoly.budget.Deadline, optional
        Checked between the steps of the stack (:func:`lagrangian_bounds`); problems not reached by then are
        not certified here.
    """
    C, x, ok = stack_point_problems(cameras, points2d, "verify_points")
    return verify_checked(C, x, ok, tolerances, deadline=deadline)


@with_single_threaded_blas(min_stack=2)
def verify_checked(C: np.ndarray, x: np.ndarray, ok: np.ndarray, tolerances: Tolerances, *,
                   deadline: Deadline | None = None, scalar: bool | None = None) -> FastPathBatch:
    """:func:`verify_points` on data already checked: float arrays C (M, N, 3, 4), x (M, N, 2) and the mask
    ``ok`` of the problems with valid cameras and finite points (e.g. from
    :func:`tritools.model.geometry.validate_cameras`: a single call does not check its cameras twice).
    ``scalar``: a stack of one runs the scalar twin :func:`verify_one` (all pairs, below ``BAND_MIN_VIEWS`` views,
    the default :class:`sospoly.Tolerances` rule) and the stacked code where the twin leaves it; False: the stacked
    code throughout; None (default): the twin exactly when M = 1."""
    ok = np.array(ok, bool)
    M, N = x.shape[:2]
    if M == 1 and scalar is not False and ok[0]:
        one = verify_one(C[0], x[0], tolerances, deadline=deadline)
        if one is not None:
            return one
    norm = normalization_stack(C, x, ok, scalar=scalar)
    ok &= norm.ok
    Cn = norm.cameras_n
    xhat = np.zeros((M, N, 2))          # the observed points, normalised: s (x^_i - t_i) = 0
    Xn = norm.Xn.copy()
    polish = ~norm.converged                # the normalisation's refinement converged elsewhere
    if polish.any():
        Xn[polish], ok[polish] = refine_points_stack(Cn[polish], xhat[polish], norm.Xn[polish], ok[polish],
                                                     scalar=False)
    Xn = gauss_newton_polish(Cn, xhat, Xn, ok, scalar=False)     # a weak direction the damped LM left (tiny baselines)
    u, _, fin = project_stack(Cn, Xn)
    ok &= fin
    v = np.where(ok[:, None], u.reshape(M, -1), 0.0)
    # a minimiser v* has ||v*||^2 = f(v*) <= f(v^) = ||v^||^2 (observed points at the origin): the radius of the
    # rigorous margin of the Lagrangian bound
    lower, upper, ok = lagrangian_bounds(C, Cn, v, ok, norms(v, axis=1), norm.resolution, tolerances,
                                         deadline=deadline)
    status, optimal, c_lower = decide(lower, upper, tolerances, N, norm.resolution)
    X = norm.world_points(Xn)
    uw, _, fin_w = project_world(C, X)
    ok &= fin_w
    # the residuals and gamma(X) by the formulas of the report (tritools.solve.report.points_report_stack): the
    # same numbers, so a single call reports these without projecting again
    residuals = np.where(fin_w[:, None], norms(uw - x, axis=2), np.inf)
    gamma_ub = np.where(fin_w, gamma_upper(np.where(fin_w[:, None], residuals, 0.0), norms(uw, axis=2)), np.inf)
    gamma_lb = gamma_lower(gamma_from_c(c_lower, N, norm.scale), gamma_ub, norm.scale, norm.lowering_resolution,
                           norm.magnitudes_at(C, X))
    gamma_lb, contra = reported_lower(gamma_lb, gamma_ub, tolerances, N, norm.scale)     # (review 46a)
    certified = ok & optimal & ~contra & decide_reported(gamma_lb, gamma_ub, tolerances, N, norm.scale,
                                                         norm.resolution)
    trivial = ok & ~certified
    if trivial.any():               # (a stack of certified problems skips the trivial rule: no change)
        trivial &= trivially_certified(upper, tolerances, N, norm.resolution) & \
            trivially_certified_reported(gamma_ub, tolerances, N, norm.scale, norm.resolution)
    gamma_lb = np.where(trivial, 0.0, gamma_lb)
    return FastPathBatch(certified | trivial, ok, X, gamma_lb, gamma_ub, x + u / norm.scale[:, None, None],
                         np.where(trivial, 0.0, c_lower), upper, norm.scale, trivial, residuals)


def verify_one(C: np.ndarray, x: np.ndarray, tolerances: Tolerances, *,
               deadline: Deadline | None = None) -> FastPathBatch | None:
    """The scalar (M = 1) twin of :func:`verify_checked` for one problem with valid cameras C (N, 3, 4) and finite
    points x (N, 2): the same steps (normalisation, refinement, polish, Lagrangian bound with all pairs, the
    decision of :func:`tritools.solve.decide.decide_one` in c units and on the reported numbers, the trivial rule),
    on plain arrays and floats where the stack had einsum and masks -- equal to the stacked code up to round-off
    (tests/test_scalar_twins.py).  gamma(X) and the residuals use the formulas of the report
    (:func:`tritools.solve.report.points_report_stack`) on the same arrays, so they are its bits.  A
    :class:`FastPathBatch` of one, or None where the data leave the common path (the normalisation or the
    refinement failed, a projection at round-off, no defined or a non-finite epipolar constraint, the deadline
    passed, points not finite), from ``BAND_MIN_VIEWS`` views (the stack tries bands of pairs first) and for
    tolerances other than :class:`sospoly.Tolerances` itself (a subclass may change the rule :func:`decide_one`
    writes out): the stacked code decides those."""
    N = len(x)
    if N >= BAND_MIN_VIEWS or type(tolerances) is not Tolerances or not np.isfinite(x).all():
        return None
    norm = normalization_stack(C[None], x[None], np.ones(1, bool))
    if not norm.ok[0] or expired(deadline):
        return None
    Cn, xhat, Xn = norm.cameras_n[0], np.zeros((N, 2)), norm.Xn[0]
    if not norm.converged[0]:
        Xn, ok_r, _ = refine_point(Cn, xhat, Xn)
        if not ok_r:
            return None
    Xn = gauss_newton_polish(Cn[None], xhat[None], Xn[None], np.ones(1, bool))[0]
    with np.errstate(over="ignore", invalid="ignore"):
        u, _, fin = project_one(Cn, Xn)
    v = u.ravel()
    upper = float(v @ v)
    lower = _lagrangian_one(C, Cn, v, math.sqrt(upper), tolerances) if fin else None
    if lower is None:
        return None
    scale, res = float(norm.scale[0]), float(norm.resolution[0])
    _, optimal, c_lower = decide_one(lower, upper, tolerances, N, res)
    X = norm.world_points(Xn[None])
    uw, defined = project_world_one(C.tolist(), X[0].tolist())       # (project_world's twin: its bits)
    if not all(defined):
        return None
    uw = np.array(uw)[None]
    residuals = norms(uw - x, axis=2)             # (the report's formulas: points_report_stack)
    gamma_ub = gamma_upper(residuals, norms(uw, axis=2))
    g_ub = float(gamma_ub[0])
    gamma_lb = gamma_lower_one(math.sqrt(max(c_lower, 0.0) / (2.0 * N)) / scale, g_ub, scale,
                               float(norm.lowering_resolution[0]), float(norm.magnitudes_at(C[None], X)[0]))
    contra = transfer_contradicts_one(gamma_lb, g_ub, tolerances, N, scale)     # no bound (review 46a)
    gamma_lb = math.nan if contra else min(gamma_lb, g_ub)
    certified = optimal and not contra and decide_reported_one(gamma_lb, g_ub, tolerances, N, scale, res)
    trivial = not certified and decide_one(0.0, upper, tolerances, N, res)[1] and math.isfinite(upper) and \
        decide_reported_one(0.0, g_ub, tolerances, N, scale, res)
    return FastPathBatch(np.array([certified or trivial]), np.ones(1, bool), X,
                         np.array([0.0 if trivial else gamma_lb]), gamma_ub, (x + u / scale)[None],
                         np.array([0.0 if trivial else c_lower]), np.array([upper]), norm.scale, np.array([trivial]),
                         residuals)


def _lagrangian_one(C: np.ndarray, Cn: np.ndarray, v: np.ndarray, radius: float, tolerances: Tolerances
                    ) -> float | None:
    """The Lagrangian lower bound (NaN: none) of :func:`_all_pairs_bounds` for one problem (raw cameras C and
    normalised Cn (N, 3, 4), the candidate v (2N,)), or None where that function would flag the problem (no
    defined pair, non-finite constraints).  Pairs with coincident centres carry no constraint, as there."""
    N = len(C)
    F, defined, raw, E = fundamental_stack_both(Cn[None], C[None])      # (one call for both, as the stack)
    if not raw.all():
        F, defined = np.where(raw[..., None, None], F, 0.0), defined & raw
    if not defined.any():
        return None
    g0, g1, G2 = epipolar_quadratics(F, N)
    if not (np.isfinite(g0).all() and np.isfinite(g1).all() and np.isfinite(G2.vals).all()):
        return None
    n = 2 * N
    ver = verify_quadratic_batch(np.zeros(1), np.zeros((1, n)), np.eye(n)[None], g0, g1, G2, v[None],
                                 tolerances=tolerances, radius=np.array([radius]),
                                 constraint_error=epipolar_errors(F, view_pairs(N), v[None], radius, proven=E))
    return float(ver.lower_bound[0])


def lagrangian_bounds(C, Cn, v, ok, radius, resolution, tolerances, f0=None, weights=None, views=None, *,
                      deadline: Deadline | None = None):
    """(lower bound (NaN: none), f(v^), ok) of the degree-2 certificate for M programs
    min f(v) = f0 + sum_k weights_k v_k^2 s.t. the epipolar constraints of the normalised cameras Cn (pairs with
    coincident centres decided on the raw cameras C), at the candidates v (M, 2N), ``radius`` bounding the
    norm of a minimiser (defaults: f0 = 0, weights = 1, the point-region objective ||v||^2).  From
    ``BAND_MIN_VIEWS`` views on the bands of ``BAND_WIDTHS`` are tried first, then all pairs.  ``views`` (M, N)
    bool: only the constraints of pairs of these views are held (the others are dropped: fewer constraints,
    a weaker but valid bound).  ``deadline``: a band width or an all-pairs chunk is started only where its
    estimated time (:func:`band_seconds`, :func:`all_pairs_seconds`) fits in what is left of it; the problems not
    reached by then keep no lower bound (NaN)."""
    M, N = C.shape[:2]
    n = 2 * N
    f0 = np.zeros(M) if f0 is None else np.asarray(f0, float)
    upper = f0 + (np.einsum("mi,mi->m", v, v) if weights is None else np.einsum("mi,mi,mi->m", weights, v, v))
    lower = np.full(M, np.nan)
    ok = ok.copy()
    todo = np.arange(M)

    def F2(idx):
        if weights is None:
            return np.broadcast_to(np.eye(n), (len(idx), n, n))
        return weights[idx][:, :, None] * np.eye(n)

    # a band with dropped pairs is a broken chain (its multipliers cannot carry the KKT residual): all pairs then
    band = todo if views is None else todo[views.all(axis=1)]
    for width in BAND_WIDTHS if N >= BAND_MIN_VIEWS else ():
        if width >= N - 1 or not band.size or not seconds_fit(deadline, band_seconds(N, width, band.size)):
            break
        try:
            lower_b, ok_b = _band_bounds(C[band], Cn[band], v[band], ok[band], radius[band], width, tolerances,
                                         f0[band], F2(band), None)
        except TimeLimitReached:        # the active deadline passed inside the band's column loops: no bound
            return lower, upper, ok
        good = ok_b & decide(lower_b, upper[band], tolerances, N, resolution[band])[1]
        lower[band[good]] = lower_b[good]
        band = band[~good]
    todo = todo[np.isnan(lower[todo])]
    step = all_pairs_chunk(N)
    if todo.size == M == 1:             # a single call: its arrays as they are (no copies by index)
        if fits(deadline, N, 1):
            lower, ok = _all_pairs_bounds(C, Cn, v, ok, radius, tolerances, f0, F2(todo), views)
        return lower, upper, ok
    k = 0
    while k < todo.size:
        part = todo[k:k + min(step, fitting(deadline, N, step))]     # as many as fit in what is left
        if not part.size:
            break
        k += part.size
        lower[part], ok[part] = _all_pairs_bounds(C[part], Cn[part], v[part], ok[part], radius[part], tolerances,
                                                  f0[part], F2(part), None if views is None else views[part])
    return lower, upper, ok


def expired(deadline: Deadline | None) -> bool:
    """Has ``deadline`` (None: no limit) passed?"""
    return deadline is not None and deadline.expired


def all_pairs_seconds(n_views: int, problems: int = 1) -> float:
    """Estimated seconds of the all-pairs bound of ``problems`` problems of ``n_views`` views: its least squares
    over K = N(N - 1)/2 multipliers with n = 2N rows costs ~n^2 K flops per problem, counted at
    :data:`ALL_PAIRS_FLOPS` (review 8 F1: one 200-view problem, 19,900 pairs, took 1.5 s in one uninterruptible
    call and ran a 1 s time limit to 2.1-2.7 s), plus :data:`ALL_PAIRS_PAIR_SECONDS` per pair."""
    n, K = 2 * n_views, n_views * (n_views - 1) // 2
    return problems * K * (n * n / ALL_PAIRS_FLOPS + ALL_PAIRS_PAIR_SECONDS)


def band_seconds(n_views: int, width: int, problems: int = 1) -> float:
    """Estimated seconds of the band bound of ``width`` (:func:`_band_bounds`) on ``problems`` problems of
    ``n_views`` views: linear in N, a fixed part and a part quadratic in the width per view
    (:data:`BAND_SECONDS_PER_VIEW` + :data:`BAND_SECONDS` width^2; one band call at N = 400 takes 0.08-0.29 s)."""
    return problems * n_views * (BAND_SECONDS_PER_VIEW + width * width * BAND_SECONDS)


def fits(deadline: Deadline | None, n_views: int, problems: int = 1) -> bool:
    """Does the all-pairs bound of ``problems`` problems fit in what is left of ``deadline`` (None: always)?
    The problems it does not fit keep no lower bound (NaN), which is valid."""
    return seconds_fit(deadline, all_pairs_seconds(n_views, problems))


def fitting(deadline: Deadline | None, n_views: int, most: int) -> int:
    """How many problems' all-pairs bounds (at most ``most``) fit in what is left of ``deadline``, by the rule of
    :func:`seconds_fit`: a batch cut by its time limit bounds those it can instead of none (six 100-view tracks whose
    all-pairs estimate exceeded a 1 s ``total_time_limit`` by 20% certified 2 of 6, the band's)."""
    if deadline is None or deadline.remaining() is None:
        return most
    per = all_pairs_seconds(n_views, 1)
    room = deadline.remaining() * cpu_share()
    return int(min(most, room // per)) if per > 0 else most


def seconds_fit(deadline: Deadline | None, seconds: float) -> bool:
    """Is more than ``seconds`` of CPU time left of ``deadline`` (None: no limit), a wall-clock deadline, at the
    share of a core the process can expect (:func:`sospoly.budget.cpu_share`)?  The one rule of the bounds not
    started where they would end past the deadline."""
    if deadline is None:
        return True
    remaining = deadline.remaining()
    return remaining is None or (remaining > 0 and seconds <= remaining * cpu_share())


def all_pairs_chunk(n_views: int) -> int:
    """Problems per call of the all-pairs bound: its arrays take ~8 (4 K n + 8 n^2) bytes per problem
    (K = N(N-1)/2 pairs, n = 2N), kept under ALL_PAIRS_CHUNK_BYTES."""
    K, n = n_views * (n_views - 1) // 2, 2 * n_views
    return int(max(1, ALL_PAIRS_CHUNK_BYTES // (8 * (4 * K * n + 8 * n * n + 64))))


def _held(F: np.ndarray, pairs, views) -> np.ndarray:
    """F with the pairs not between two ``views`` zeroed (their constraints dropped)."""
    if views is None:
        return F
    I, J = pairs
    return np.where((views[:, I] & views[:, J])[..., None, None], F, 0.0)


def _zero_rows(g0, g1, G2, keep: np.ndarray) -> tuple:
    """The constraint data (g0, g1, G2) with the problems not in ``keep`` zeroed (harmless numbers for the
    stack).  Always new arrays, also when every problem is kept: their memory layout decides the summation
    order downstream, so the bounds' last bits."""
    M = len(keep)
    g0, g1 = (np.where(keep.reshape((M,) + (1,) * (a.ndim - 1)), a, 0.0) for a in (g0, g1))
    return g0, g1, dataclasses.replace(G2, vals=np.where(keep[:, None], G2.vals, 0.0))


def _all_pairs_bounds(C, Cn, v, ok, radius, tolerances, f0, F2, views=None) -> tuple[np.ndarray, np.ndarray]:
    """(Lagrangian lower bound (NaN: none), ok) with the epipolar constraints of all N(N - 1)/2 view pairs,
    vectorised over the stack (:func:`sospoly.analysis.verify.verify_quadratic_batch`)."""
    M, N = C.shape[:2]
    F, defined, raw, E = fundamental_stack_both(Cn, C)
    F, defined = np.where(raw[..., None, None], F, 0.0), defined & raw
    ok = ok & np.any(defined, axis=1) if F.shape[1] else ok
    Fh = _held(F, view_pairs(N), views)
    g0, g1, G2 = epipolar_quadratics(Fh, N)
    finite = np.isfinite(g0).all(axis=1) & np.isfinite(g1).all(axis=(1, 2)) & np.isfinite(G2.vals).all(axis=1)
    ok &= finite
    g0, g1, G2 = _zero_rows(g0, g1, G2, ok)
    n = 2 * N
    err = epipolar_errors(np.where(ok[:, None, None, None], Fh, 0.0), view_pairs(N), v, radius, proven=E)
    ver = verify_quadratic_batch(f0, np.zeros((M, n)), F2, g0, g1, G2, v, tolerances=tolerances, radius=radius,
                                 constraint_error=err)
    return ver.lower_bound, ok


def _band_bounds(C, Cn, v, ok, radius, width, tolerances, f0, F2, views=None) -> tuple[np.ndarray, np.ndarray]:
    """(Lagrangian lower bound (NaN: none), usable) with the epipolar constraints of a band of view pairs only
    (:func:`tritools.model.stacked.band_pairs` of that ``width``): a subset of Corollary 1's constraints, so
    the bound stays a valid lower bound of the all-pairs program (fewer constraints enlarge the feasible set,
    :mod:`sospoly.analysis.verify_sparse`), at O(N) cost per problem instead of O(N^3).  A problem with an
    undefined band pair (coincident centres) or non-finite data is not usable here (the caller falls back to
    all pairs)."""
    M, N = C.shape[:2]
    pairs = band_pairs(N, width)
    F, defined, raw, E = fundamental_stack_both(Cn, C, pairs)
    defined &= raw
    Fh = _held(F, pairs, views)
    g0, g1, G2 = epipolar_quadratics(Fh, N, pairs)
    use = ok & defined.all(axis=1) & np.isfinite(g0).all(axis=1) & np.isfinite(g1).all(axis=(1, 2)) \
        & np.isfinite(G2.vals).all(axis=1)
    g0, g1, G2 = _zero_rows(g0, g1, G2, use)
    n = 2 * N
    ver = verify_quadratic_banded_batch(f0, np.zeros((M, n)), F2, g0, g1, G2, v, tolerances=tolerances,
                                        radius=radius, constraint_error=epipolar_errors(
                                            np.where(use[:, None, None, None], Fh, 0.0), pairs, v, radius, proven=E))
    lower = np.where(use, ver.lower_bound, np.nan)
    return lower, use
