"""The numbers a TLS result reports, and the last checks of its certificate (issue #19, review 7 F1/F2).

Every TLS path (the enumeration of :mod:`tritools.solve.robust_enum`, the branch and bound of
:mod:`tritools.solve.robust`, single calls and batches) ends in :meth:`TlsSearch.result`, which takes these from
here, in the caller's frame and units, by the L2 path's rules (:mod:`tritools.solve.report`,
:func:`tritools.solve.decide.decide_reported`):

* gamma_UB = sqrt(f_TLS(X) / 2N) at the float estimate X, with f_TLS = sum_i min(d_i(X), c_i)^2 from compensated
  projections, each distance enlarged by its round-off bound before truncation and the sum rounded up
  (:func:`tritools.solve.report.gamma_upper`): an upper bound of gamma*_TLS of the given float data.
* gamma_LB from the search's bound in pixels^2, lowered by the normalisation's round-off
  (:func:`tritools.solve.decide.gamma_lower`, with the L2 path's magnitudes: the points' obliquity and the frame
  origin's term, :func:`_magnitudes`), never above gamma_UB.
* The certificate, decided by the search in c units on its scale S = min(c^2, rho^2), must also pass on these
  numbers the L2 path's guard: a gap that does not pass through the relative part of the rule must be within
  the coordinates' resolution (``RESOLUTION_REL`` min_i max(f_i, |x_i|) pixels, f_i view i's pixel floor,
  :func:`tritools.model.magnitude.guard_resolutions`; thresholds far above the
  residuals make S = c^2 large, and without it a 250 px gap at 1e10 px coordinates certified).
  Until wave 26 gamma_LB was also lowered by the estimate's rounding spread
  (:func:`tritools.solve.report.rounding_spread`), and withdrawn (0, not certified) where that spread exceeded the
  resolution: a stand-in for the frame-origin and obliquity round-off terms that the lowering now carries (waves
  24-25).  It withdrew bounds the L2 path certifies on the same estimate (review 25a F4: a 6-view track 1.5e7 from
  the origin, the spread 7e-5 px at 0.86 px; 72 of 200 such TLS calls), although an ulp of X moves f only to
  second order at an optimum; the spread now only explains drift (:func:`rounding_drift`).
* The search's own value at its estimate must agree with the compensated f_TLS (:func:`drift_within`: relatively, or
  absolutely within a tenth of the resolution in gamma); gamma_LB is lowered by the drift seen.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sospoly import pow2_above

from ..model.cameras import power2_scale
from ..model.frame_floats import max_abs, null_vector_one
from ..model.magnitude import (RESOLUTION_REL, SCALAR_MAX_VIEWS, guard_resolutions, ieee_div, magnitudes,
                               resolution_pair, resolution_pair_floats, view_floors, world_origin_magnitude_one,
                               world_origin_magnitudes)
from ..model.stacked import norms, null_vectors
from .decide import within_resolution_one
from .robust_split import (_nodes_bound, _split_lower, _split_needed, exact_sets_bound, outside_split,  # noqa: F401
                           pair_nodes)
from .report import enlarged_distances, gamma_upper, projections_and_spread, projections_and_spread_stack

__all__ = ["TlsReported", "tls_reported", "tls_reported_stack", "guards_pass", "capped_resolution",
           "reported_resolution", "enumerated_result", "enumerated_results", "PRUNE_SHARE", "outside_split",
           "exact_sets_bound", "pair_nodes", "GAP_GUARD_REASON"]


@dataclass(frozen=True)
class TlsReported:
    gamma_lb: float
    gamma_ub: float
    residuals: np.ndarray          # (N,) d_i(X), inf where the projection is undefined
    inliers: np.ndarray            # (N,) d_i(X) < c_i (exactly, for point regions: :func:`inlier_mask`)
    holds: bool                    # the certificate passes on the reported numbers (module docstring)
    reason: str                    # why not, when it does not
    image_points: np.ndarray       # (N, 2) the compensated projections of X, NaN where d_i(X) is not finite


def tls_reported(C: np.ndarray, centres: np.ndarray, residuals, X, c: np.ndarray, lb: float, tolerances,
                 certified: bool, f_search: float | None = None, regions=None,
                 frame_terms: tuple | None = None, split: tuple | None = None) -> TlsReported:
    """The reported bounds and checks of a TLS result at X (module docstring): cameras C (N, 3, 4), the regions'
    centres (N, 2) (their magnitude sets the resolution), ``residuals`` the distances d_i(X) or None for point
    regions (computed here from compensated projections; ``centres`` are then the points), ``lb`` the search's
    bound of f*_TLS (pixels^2), ``certified`` the search's decision (on its scale S).  ``split`` = (views (N,) bool,
    lb_out): the search's bound split by the sets of views (:func:`_split_lower`): ``lb`` then holds for the sets
    without these views, ``lb_out`` for the sets holding one of them."""
    N = len(C)
    u, defined, spread = projections_and_spread(np.asarray(C, float), X)
    u = np.where(defined[:, None], u, np.inf)            # an undefined view: d_i = inf, counted c_i^2
    points_given = residuals is None
    if points_given:
        residuals = norms(u - centres, axis=1)
    res = np.where(np.isfinite(residuals), residuals, np.inf)
    g_ub = float(gamma_upper(np.where(np.isfinite(res), res, c), norms(np.where(np.isfinite(u), u, 0.0), axis=1),
                             cap=c))
    mag = _reported_magnitude(C, centres, X, frame_terms)
    resolution, floor = (float(r[0]) for r in _resolution_pair(np.asarray(centres, float)[None],
                                                                  np.asarray(C, float)[None]))
    checked = _checked(g_ub, spread, resolution, N, c, lb, tolerances, certified, res, f_search, max(mag, floor))
    if _split_needed(checked, certified, split):      # (the kept views' magnitude only where it can matter)
        inner = (max(_reported_magnitude(C, centres, X, frame_terms, ~np.asarray(split[0], bool)), floor),) + \
            tuple(split[1:])
        checked = _checked(g_ub, spread, resolution, N, c, lb, tolerances, certified, res, f_search, max(mag, floor),
                           inner)
    g_lb, g_ub, holds, reason = checked
    inliers = inlier_mask(C, X, centres, res, c, u, exact=points_given, regions=regions)
    image_points = np.where(np.isfinite(res)[:, None] & np.isfinite(u), u, np.nan)
    return TlsReported(g_lb, g_ub, residuals, inliers, holds, reason, image_points)


def tls_reported_stack(C: np.ndarray, points: np.ndarray, X: np.ndarray, c: np.ndarray, lb, tolerances, certified,
                       f_search, splits: list | None = None) -> list:
    """The twin of :func:`tls_reported` for M point problems of N views (tested equal, bit for bit): C (M, N, 3, 4),
    ``points`` (M, N, 2), X (M, 3), c (M, N), lb, certified and f_search (M,) (f_search NaN: none); one
    :class:`TlsReported` per problem.  The projections, distances, gamma_UB and inlier flags in stacked calls
    (:func:`tritools.solve.report.projections_and_spread_stack`), the checks per problem (:func:`_checked`).
    ``splits``: per problem None or :func:`tls_reported`'s ``split``."""
    M, N = points.shape[:2]
    u, defined, spread = projections_and_spread_stack(np.asarray(C, float), X)
    u = np.where(defined[..., None], u, np.inf)
    residuals = norms(u - points, axis=2)
    res = np.where(np.isfinite(residuals), residuals, np.inf)
    u_norm = norms(np.where(np.isfinite(u), u, 0.0), axis=2)
    g_ub = gamma_upper(np.where(np.isfinite(res), res, c), u_norm, cap=c)
    resolution, floor = _resolution_pair(points, C)
    magnitude = np.maximum(_magnitudes(np.asarray(C, float), points, X), floor)
    inliers = inlier_mask_stack(C, X, points, res, c, u, u_norm)
    image_points = np.where(np.isfinite(res)[:, :, None] & np.isfinite(u), u, np.nan)
    splits = [None] * M if splits is None else splits

    pre = _stack_pre(resolution, c, N, tolerances, res, f_search)

    def checked(k: int, inner=None) -> tuple:
        f_k = float(f_search[k])
        return _checked(float(g_ub[k]), float(spread[k]), float(resolution[k]), N, c[k], float(lb[k]), tolerances,
                        bool(certified[k]), res[k], f_k if f_k == f_k else None, float(magnitude[k]), inner, pre[k])

    told = [checked(k) for k in range(M)]
    again = [k for k in range(M) if _split_needed(told[k], bool(certified[k]), splits[k])]
    if again:                            # the kept views' magnitudes in one stacked call
        kept = np.array([~np.asarray(splits[k][0], bool) for k in again])
        mag_in = np.maximum(_magnitudes(np.asarray(C, float)[again], points[again], X[again], kept), floor[again])
        for k, m in zip(again, mag_in):
            told[k] = checked(k, (float(m),) + tuple(splits[k][1:]))
    return [TlsReported(t[0], t[1], residuals[k].copy(), inliers[k].copy(), t[2], t[3], image_points[k].copy())
            for k, t in enumerate(told)]


def _stack_pre(resolution: np.ndarray, c: np.ndarray, N: int, tolerances, res: np.ndarray, f_search) -> list:
    """Per problem of a stack: (:func:`capped_resolution`, :func:`_compensated_f`) of :func:`_checked`, in whole-stack
    operations (the same operations row by row: the same numbers, tests/test_wave50.py)."""
    c = np.asarray(c, float)
    fin = np.isfinite(c)
    with np.errstate(over="ignore", invalid="ignore"):
        cmin = np.min(np.where(fin, c, np.inf), axis=1)
        resolved = np.minimum(resolution, np.where(fin.any(axis=1), cmin * math.sqrt(tolerances.gap_abs / (2.0 * N)),
                                                   np.inf))
        f_comp = np.sum(np.minimum(np.where(np.isfinite(res), res * res, np.inf), c * c), axis=1)
    f_search = np.asarray(f_search, float)
    keep = np.isfinite(f_search) & np.isfinite(f_comp)
    return [(float(r), float(f) if k else None) for r, f, k in zip(resolved, f_comp, keep)]


def _reported_magnitude(C, centres, X, frame_terms, views=None) -> float:
    """The magnitude gamma_LB is lowered by (:func:`_magnitudes`, or with the enumeration frame's own terms
    ``frame_terms``) over the ``views`` (N,) bool (None: all)."""
    C, centres = np.asarray(C, float), np.asarray(centres, float)
    if frame_terms is None:
        return float(_magnitudes(C[None], centres[None], np.asarray(X, float)[None],
                                 None if views is None else np.asarray(views, bool)[None])[0])
    kept = centres if views is None else np.where(np.asarray(views, bool)[:, None], centres, np.nan)
    return max(float(magnitudes(kept[None], C[None])[0]), _terms_magnitude(frame_terms, X, views))


def _terms_magnitude(terms: tuple, X, views=None) -> float:
    """max_i num_i / min(|P_3 X0~|, |P_3 X~|) from a frame's origin terms (:attr:`tritools.model.normalize.
    Normalization.frame_terms`: the enumeration's frame, cameras moved to c0): the term of :func:`_magnitudes` at X
    and at the frame's own point X0 (the DLT of every view, which a wrong match may move), the smaller depth."""
    num, row3, c0, h3_0 = terms
    with np.errstate(all="ignore"):
        d = np.asarray(X, float) - c0
        h3 = np.abs(row3[:, 0] * d[0] + row3[:, 1] * d[1] + row3[:, 2] * d[2] + row3[:, 3])
        K = num / np.minimum(h3, h3_0)
        K = float(np.max(K if views is None else np.where(views, K, 0.0)))
    return min(K, float(np.finfo(float).max)) if K == K else float(np.finfo(float).max)


def _magnitudes(C: np.ndarray, points: np.ndarray, X: np.ndarray, views: np.ndarray | None = None) -> np.ndarray:
    """(M,) the magnitude that gamma_LB is lowered by (:func:`tritools.solve.decide.gamma_lower`): the points'
    obliquity magnitudes (:func:`tritools.model.magnitude.magnitudes`) and at least the frame's origin magnitude at
    X (:func:`tritools.model.magnitude.world_origin_magnitudes`) for the search's frame, the cameras moved to their
    centres' mean (:func:`tritools.solve.robust_enum.enum_frame`); ``views`` (M, N) bool: the largest over these views
    only (the frame still that of every view)."""
    if len(C) == 1 and C.shape[1] <= SCALAR_MAX_VIEWS:            # one problem: the twin on floats, the same bits
        return np.array([_magnitude_one(C[0], points[0], X[0], None if views is None else views[0])])
    with np.errstate(all="ignore"):
        Cs = C / power2_scale(C, (2, 3))
        a = null_vectors(Cs)
        c = a[..., :3] / a[..., 3:]
        o = np.add.reduce(c, axis=1) / C.shape[1]
        o = np.where(np.isfinite(o), o, 0.0)
    kept = points if views is None else np.where(views[..., None], points, np.nan)
    return np.maximum(magnitudes(kept, C), world_origin_magnitudes(C, points, X, o, views=views))


def _magnitude_one(C: np.ndarray, points: np.ndarray, X: np.ndarray, views=None) -> float:
    """:func:`_magnitudes` of one problem of at most ``SCALAR_MAX_VIEWS`` views on floats (the null vectors by
    :func:`tritools.model.frame_floats.null_vector_one`, the centres' mean summed in view order as numpy's reduction
    of so few rows, :func:`tritools.model.magnitude.world_origin_magnitude_one`): equal bit for bit
    (tests/test_wave48.py)."""
    N = len(C)
    o = [0.0, 0.0, 0.0]
    for P in C.tolist():
        k = pow2_above(max_abs(v for row in P for v in row))
        a = null_vector_one([[v / k for v in row] for row in P])
        o = [o[j] + ieee_div(a[j], a[3]) for j in range(3)]
    o = [t / N if math.isfinite(t / N) else 0.0 for t in o]
    kept = points if views is None else np.where(np.asarray(views, bool)[:, None], points, np.nan)
    return max(float(magnitudes(kept[None], C[None])[0]), world_origin_magnitude_one(C, points, X, o, views=views))


def _checked(g_ub: float, spread: float, resolution: float, N: int, c: np.ndarray, lb: float, tolerances,
             certified: bool, res: np.ndarray, f_search, magnitude: float = 1.0, inner: tuple | None = None,
             pre: tuple | None = None) -> tuple:
    """(gamma_LB, gamma_UB, holds, reason) of :func:`tls_reported` from gamma_UB (float), the rounding spread and the
    coordinates' resolution (module docstring): gamma_LB lowered by round-off, never above gamma_UB; the certificate
    withheld where the search's drift (beyond what the rounding ``spread`` explains) or the gap guard say so.
    ``inner`` = (magnitude of the kept views, lb_out): the split of :func:`_split_lower`.  ``pre``: (the gap guard's
    resolution, :func:`_compensated_f`) computed for a stack at once (:func:`_stack_pre`, the same numbers)."""
    # lowered by the normalisation's round-off, whose magnitude holds the frame origin's and the obliquity's terms
    # (review 7's 6-view track 4.5e8 px off-axis, whose frame bound sat 7e-4 px above an achievable value, stays
    # below it: tests/test_robust_report.py)
    g_lb = _split_lower(lb, 0.0, g_ub, N, resolution, magnitude, inner)
    g_lb = min(g_lb, g_ub)
    holds, reason = certified, ""
    f_ub = 2.0 * N * g_ub * g_ub
    resolved, f_comp = (capped_resolution(resolution, c, N, tolerances), _compensated_f(res, c, f_search)) \
        if pre is None else pre
    drift = 0.0 if f_comp is None else abs(f_search - f_comp) / max(f_comp, 1e-300)     # search_drift
    d_abs = 0.0 if f_comp is None else abs(f_search - f_comp)                           # search_drift_abs
    if d_abs > 0.0:                      # the search's bound is in its own arithmetic: lowered by the drift seen
        g_lb = min(g_lb, _split_lower(lb, d_abs, g_ub, N, resolution, magnitude, inner))
    if not drift_within(drift, d_abs, N, tolerances, resolved, rounding_drift(f_ub, spread, N)):
        # the search's bounds are not trusted; a certificate that needs none (0 <= gamma* <= gamma_UB within the
        # resolution: an optimum near 0 in a georeferenced world with tiny thresholds) still holds, at gamma_LB 0
        g_lb = 0.0
        if not (certified and guards_pass(0.0, g_ub, N, tolerances, resolved)):
            holds = False
            reason = f"the search's own value at its estimate differs from the compensated one by {drift:.2g} " \
                     "(relative): its arithmetic lost digits to cancellation (a georeferenced or rescaled frame), so " \
                     "its bounds are not trusted"
    elif certified and not guards_pass(g_lb, g_ub, N, tolerances, resolved):
        holds, reason = False, f"{GAP_GUARD_REASON} ({resolved:.3g} px, at most the thresholds' own scale)"
    return g_lb, g_ub if math.isfinite(g_ub) else math.inf, holds, reason


#: the start of the reason a report withholds a certificate the search gave (:func:`_checked`)
GAP_GUARD_REASON = "the bounds met on the search's scale, but their gap exceeds the coordinates' resolution"


def coordinate_resolution(centres: np.ndarray, C: np.ndarray) -> float:
    """The coordinates' resolution in pixels: ``RESOLUTION_REL`` min_i max(f_i, |x_i|) over the views, f_i the
    pixel floor of view i of the cameras C (N, 3, 4) at its centre (:func:`tritools.model.magnitude.
    guard_resolutions` at scale 1: the L2 path's rule; review 47b H1)."""
    return float(coordinate_resolutions(np.asarray(centres, float)[None], np.asarray(C, float)[None])[0])


def coordinate_resolutions(points: np.ndarray, C: np.ndarray) -> np.ndarray:
    """:func:`coordinate_resolution` of M problems' points (M, N, 2) and cameras (M, N, 3, 4) -> (M,) (the same rule,
    the same numbers)."""
    return guard_resolutions(np.ones(len(points)), points, view_floors(C, points))


def _resolution_pair(points: np.ndarray, C: np.ndarray) -> tuple:
    """((M,) :func:`coordinate_resolutions`, (M,) the magnitude in pixels that floors the lowering of gamma_LB: the
    median rule's (:func:`tritools.model.magnitude.resolution_pair` at scale 1, its second part / ``RESOLUTION_REL``),
    as before the per-view guard)."""
    one = resolution_pair_floats(1.0, points[0], C[0]) if len(points) == 1 else None     # (its twin, the same bits)
    guard, median_rule = resolution_pair(np.ones(len(points)), points, C) if one is None else one
    return guard, median_rule / RESOLUTION_REL


def capped_resolution(resolution: float, c: np.ndarray, N: int, tolerances) -> float:
    """The gamma gap the report lets pass as "within resolution": the coordinates' ``resolution`` capped by the
    thresholds' own scale (:func:`threshold_resolution`)."""
    return min(resolution, threshold_resolution(c, N, tolerances))


def reported_resolution(centres: np.ndarray, c: np.ndarray, tolerances, C: np.ndarray) -> float:
    """:func:`capped_resolution` of a problem with the regions' ``centres`` (N, 2) and thresholds ``c`` (N,): the
    ``resolved`` of the report's gap guard, which a search prunes within (:data:`PRUNE_SHARE`)."""
    return capped_resolution(coordinate_resolution(centres, C), c, len(centres), tolerances)


#: a TLS search prunes a node by the certificate rule only within this share of the report's gap guard
#: (:meth:`tritools.solve.robust.TlsSearch.meets`; the reported gamma_LB is lowered by round-off and drift after
#: the search, so its gap must pass with room).
PRUNE_SHARE = 0.5


def guards_pass(g_lb: float, g_ub: float, N: int, tolerances, resolved: float, share: float = 1.0) -> bool:
    """The reported numbers' gap guard (module docstring), within ``share`` of it: the relative part of the rule on
    f = 2N gamma^2, or a gamma gap within ``resolved`` (the coordinates' resolution capped by the thresholds' scale,
    :func:`threshold_resolution`).  Searches prune within :data:`PRUNE_SHARE` of it
    (:meth:`tritools.solve.robust.TlsSearch.meets`, also in :mod:`tritools.solve.robust_cells`)."""
    f_lb, f_ub = 2.0 * N * g_lb * g_lb, 2.0 * N * g_ub * g_ub
    return tolerances.certified_relatively_one(f_lb, f_ub, share) or \
        within_resolution_one(g_lb, g_ub, resolved, share, squares=False)


#: the search's value at its estimate may differ from the compensated f_TLS by at most this fraction of the decision
#: rule's gap_rel (relative to f_TLS) before its bounds are distrusted (:func:`search_drift`)
SEARCH_DRIFT_REL = 0.1


def search_drift(res: np.ndarray, c: np.ndarray, f_search: float | None, f_ub: float) -> float:
    """|f_search - f_TLS(X)| / max(f_TLS(X), tiny): how far the search's own (plain-arithmetic) value of its estimate
    is from the value of the compensated distances ``res`` (0 without ``f_search``).  The search bounds f_TLS by the
    same arithmetic; where that lost digits to cancellation (a 3e7 georeferenced world seen by cameras scaled by
    1e-6 with 1e5 px offsets: 0.6% off, its bound 1.3e-4 above an attained value, review 8b F2) its bounds are not
    trusted."""
    f_comp = _compensated_f(res, c, f_search)
    return 0.0 if f_comp is None else abs(f_search - f_comp) / max(f_comp, 1e-300)


def search_drift_abs(res: np.ndarray, c: np.ndarray, f_search: float | None) -> float:
    """|f_search - f_TLS(X)| in pixels^2 (the absolute twin of :func:`search_drift`; 0 without ``f_search`` or a
    finite compensated value)."""
    f_comp = _compensated_f(res, c, f_search)
    return 0.0 if f_comp is None else abs(f_search - f_comp)


def _compensated_f(res: np.ndarray, c: np.ndarray, f_search: float | None) -> float | None:
    """f_TLS of the compensated distances ``res``; None without a finite ``f_search`` or a finite value."""
    if f_search is None or not math.isfinite(f_search):
        return None
    with np.errstate(over="ignore", invalid="ignore"):
        f_comp = float(np.sum(np.minimum(np.where(np.isfinite(res), res * res, np.inf), c * c)))
    return f_comp if math.isfinite(f_comp) else None


def drift_within(drift: float, d_abs: float, N: int, tolerances, resolved: float, explained: float = 0.0) -> bool:
    """Are the search's bounds trusted: its drift (:func:`search_drift`) within ``SEARCH_DRIFT_REL`` gap_rel; or its
    absolute drift ``d_abs`` (pixels^2) worth at most ``SEARCH_DRIFT_REL`` of the report's resolution ``resolved``
    in gamma, sqrt(d_abs / 2N) (the relative test alone refused every optimum near 0: a noise-free track in a
    georeferenced world, two values ~1e-17 px^2 differing by 100%, review 11 F1); or within what the estimate's own
    rounding ``explained`` (:func:`rounding_drift`) and at most ``EXPLAINED_DRIFT_GAPS`` gap_rel relative (near f = 0
    the rounding explains any relative drift, review 20 F3; the cap stays 60x below the 0.6% of review 8b F2's lost
    digits).  The reported gamma_LB is lowered by ``d_abs`` either way (:func:`_checked`)."""
    if drift <= SEARCH_DRIFT_REL * tolerances.gap_rel:
        return True
    if math.isfinite(d_abs) and math.sqrt(d_abs / (2.0 * N)) <= SEARCH_DRIFT_REL * resolved:
        return True
    return d_abs <= explained and drift <= EXPLAINED_DRIFT_GAPS * tolerances.gap_rel


#: a drift the rounding explains is trusted up to this many gap_rel (relative): review 20 G2, two certificates of
#: two-view problems at 3.4e-6 and 4.9e-5 relative drift, both correct against a 60-digit reference, were refused at 1
EXPLAINED_DRIFT_GAPS = 100.0


def rounding_drift(f: float, spread: float, N: int) -> float:
    """How far (pixels^2) f_TLS can move between the search's estimate and its float rounding in the caller's frame
    (a search in a re-centred frame rounds origin + X' to the world's float grid, review 19 F3: a tiny baseline 1e6
    from the origin moved f by 2e-7 relative), with the search's own plain arithmetic, equivalent to moving X~ by a
    few units in the last place: each coordinate moves by at most ``ROUNDING_ULPS`` ulps, so each projection by at
    most ROUNDING_ULPS m_i (m_i its largest move per ulp, sqrt(sum m_i^2 / 2N) the rounding ``spread``), and
    |sum_i (d_i + delta_i)^2 - d_i^2| <= 2 sqrt(f) ||delta|| + ||delta||^2 with ||delta|| <= 3 ROUNDING_ULPS
    sqrt(2N) spread (three coordinates; truncation at c_i is 1-Lipschitz in d_i^2).  0 where either is not finite."""
    if not (math.isfinite(f) and math.isfinite(spread)):
        return 0.0
    move = 3.0 * ROUNDING_ULPS * math.sqrt(2.0 * N) * spread
    return 2.0 * math.sqrt(max(f, 0.0)) * move + move * move


#: units in the last place that the rounding of a re-centred estimate (1/2) and the search's plain arithmetic on
#: X~ (the dot products' backward error, 4 u |x_k| each, ~2 ulps) move a coordinate by, with room: 4
ROUNDING_ULPS = 4.0


def threshold_resolution(c: np.ndarray, N: int, tolerances) -> float:
    """The largest gamma gap that the thresholds' own scale lets pass as "within resolution": the gap of a zero
    lower bound whose f-gap is ``gap_abs`` c_min^2, i.e. c_min sqrt(gap_abs / 2N) (inf without a finite
    threshold).  With thresholds below the coordinates' resolution (c = 1e-9 px at 300 px coordinates) the
    resolution clause would certify any value in [0, c] (review 8 F2); this caps it at the search's own absolute
    tolerance on the scale c^2."""
    fin = np.asarray(c, float)[np.isfinite(c)]
    if fin.size == 0:
        return math.inf
    return float(fin.min()) * math.sqrt(tolerances.gap_abs / (2.0 * N))


def inlier_mask(C: np.ndarray, X, points: np.ndarray, res: np.ndarray, c: np.ndarray, u: np.ndarray,
                exact: bool, regions=None) -> np.ndarray:
    """(N,) bool, d_i(X) < c_i.  The float distances ``res`` err by at most their enlargement in
    :func:`tritools.solve.report.enlarged_distances`; where |res_i - c_i| is within that margin and the regions are
    points (``exact``), the comparison is made exactly in rational arithmetic on the float data and X (rare: a
    distance at the threshold to ~1e-13 relative, or thresholds below the round-off, review 8 F2).  For other regions
    such a view is an outlier (gamma_UB counts it c_i^2; review 8 F1b: Segments at c = 1e-150 px were inliers by
    float distances of 0 whose exact values are ~1e-14 px)."""
    inl = res < c
    with np.errstate(invalid="ignore", over="ignore"):
        margin = enlarged_distances(res, np.linalg.norm(np.where(np.isfinite(u), u, 0.0), axis=1)) - res
        ambiguous = np.isfinite(res) & np.isfinite(c) & (np.abs(res - c) <= margin)
    if not exact:                       # other regions: an undecided view is an outlier, as gamma_UB counts it,
        inl &= ~ambiguous               # unless the projection is inside its region with all of its margin
        for i in np.flatnonzero(ambiguous & (res == 0)) if regions is not None else ():
            inl[i] = _deep_inside(regions[i], u[i], float(margin[i]))
        return inl
    for i in np.flatnonzero(ambiguous):
        inl[i] = _exact_below(C[i], X, points[i], float(c[i]))
    return inl


def inlier_mask_stack(C: np.ndarray, X: np.ndarray, points: np.ndarray, res: np.ndarray, c: np.ndarray,
                      u: np.ndarray, u_norm: np.ndarray) -> np.ndarray:
    """The twin of :func:`inlier_mask` (``exact``) for M point problems (tested equal): (M, N) bool, d_i(X) < c_i,
    a view within its distance's round-off margin of its threshold compared exactly (:func:`_exact_below`); C (M,
    N, 3, 4), X (M, 3), ``res`` / ``c`` (M, N), ``u_norm`` (M, N) the norms of the finite projections ``u``."""
    inl = res < c
    with np.errstate(invalid="ignore", over="ignore"):
        margin = enlarged_distances(res, u_norm) - res
        ambiguous = np.isfinite(res) & np.isfinite(c) & (np.abs(res - c) <= margin)
    for m, i in zip(*np.nonzero(ambiguous)):
        inl[m, i] = _exact_below(C[m, i], X[m], points[m, i], float(c[m, i]))
    return inl


def _deep_inside(region, p: np.ndarray, margin: float) -> bool:
    """Is the square of half-side ``margin`` around the float projection p inside the (convex) region: its four
    corners at distance 0?  Then the exact projection is inside too, d_i = 0 < c_i (review 8b F4: a box region at
    c = 1e-12 px reported an outlier with its projection well inside)."""
    corners = p[None, :] + margin * np.array([[1.0, 1.0], [1.0, -1.0], [-1.0, 1.0], [-1.0, -1.0]])
    try:
        return bool(np.all(np.asarray(region.distance(corners), float) == 0.0))
    except (ValueError, TypeError):
        return False


def _exact_below(P: np.ndarray, X, x: np.ndarray, c: float) -> bool:
    """|pi(P (X, 1)) - x| < c in exact rational arithmetic (False where the projection is undefined)."""
    from fractions import Fraction

    Xh = [Fraction(float(v)) for v in X] + [Fraction(1)]
    h = [sum(Fraction(float(P[r, k])) * Xh[k] for k in range(4)) for r in range(3)]
    if h[2] == 0:
        return False
    dx, dy = h[0] / h[2] - Fraction(float(x[0])), h[1] / h[2] - Fraction(float(x[1]))
    return dx * dx + dy * dy < Fraction(c) ** 2


def enumerated_result(search, lb: float, n_bounded: int, n_sets: int, split: tuple | None = None):
    """The result of a search decided by the enumeration (:meth:`tritools.solve.robust.TlsSearch.result` at the lower
    bound ``lb``, pixels^2, and its ``split``, :func:`outside_split`), its message saying so; ``n_bounded`` subsets
    were bounded."""
    return enumerated_results([search], [lb], [n_bounded], n_sets, [split])[0]


def enumerated_results(searches: list, lbs, n_bounded, n_sets: int, splits: list | None = None) -> list:
    """:func:`enumerated_result` of point searches of one view count at once (``splits``: each one's or None): their
    reported numbers from one
    :func:`tritools.solve.robust_report.tls_reported_stack` (the twin of :meth:`TlsSearch.result`'s
    :func:`~tritools.solve.robust_report.tls_reported`, equal bit for bit), then each search's
    :meth:`~tritools.solve.robust.TlsSearch.finish`; a search without an estimate (or not of points) takes
    :meth:`~tritools.solve.robust.TlsSearch.result` itself."""
    import time

    from .robust_enum import ENUMERATED

    note = f"; {ENUMERATED} ({n_sets} sets of >= 2 views)"
    splits = [None] * len(searches) if splits is None else splits
    timings = []
    for s, n in zip(searches, n_bounded):
        s.bounds.n_solved += int(n)
        t = time.perf_counter() - s.t0
        timings.append({"enumeration": t, "total": t})
    first = searches[0]
    stack = [k for k, s in enumerate(searches) if s.points and s.best_X is not None and not s.cells_decided
             and s.N == first.N and s.tol is first.tol]
    out = [None] * len(searches)
    if len(stack) > 1:
        group = [searches[k] for k in stack]
        lb = np.array([float(lbs[k]) for k in stack])
        X, reps = _estimates_in_front(group, lb)
        certified = [s.tol.certified_one(float(b), s.best_f, s.scale) for s, b in zip(group, lb)]
        told = tls_reported_stack(np.stack([s.C_user for s in group]), np.stack([s.x for s in group]), X,
                                  np.stack([s.c for s in group]), lb, first.tol, certified,
                                  np.array([s.best_f for s in group]), [splits[k] for k in stack])
        for k, s, Xk, rep, t, b in zip(stack, group, X, reps, told, lb):
            out[k] = s.finish(Xk.copy(), rep, t, float(b), None, timings[k], note)
    for k, s in enumerate(searches):
        if out[k] is None:
            out[k] = s.result(float(lbs[k]), None, timings[k], note, splits[k])
    return out


def _estimates_in_front(group: list, lb: np.ndarray) -> tuple:
    """The estimates (P, 3) of a stack of searches in the caller's frame and their reports, each estimate first moved
    along a line of minimisers where :func:`tritools.solve.robust_front.front_tie` moves it (as
    :meth:`~tritools.solve.robust.TlsSearch.result` does)."""
    from .robust_front import front_tie

    X = np.array([s.user_estimate() for s in group])
    reps = [s.report(Xk) for s, Xk in zip(group, X)]
    for j, (s, b) in enumerate(zip(group, lb)):
        if front_tie(s, float(b), reps[j].depths):
            X[j] = s.user_estimate()
            reps[j] = s.report(X[j])
    return X, reps
