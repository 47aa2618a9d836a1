"""The one decision step of every triangulation path, scalar and vectorised alike.

Every path -- the per-point SDP (:mod:`.triangulate`), the vectorised verification path
(:mod:`.fastpath`) and the batched degree-2 SDP (:mod:`.sdp_batch`) -- ends with a lower bound
c_LB and an upper bound c_UB = 2N gamma'(X^)^2 in the normalised units where c = O(1) (see
:mod:`tritools.model.normalize`), and calls :func:`decide` on them: the certificate rule of
:class:`sospoly.Tolerances` (``certified`` / ``contradicts`` / ``consistent``) applied in c units.
An error dc in c moves gamma by about dc / (4 N gamma), so comparing gammas relatively would fail
for tiny residuals; comparing c does not.  Then :func:`cheirality` tells whether the estimate lies in
front of every camera (and, with ``require_in_front``, turns a certified minimiser behind a camera into
``BEHIND_CAMERA``).  Both take scalars or arrays.  :func:`decide_one` / :func:`decide_reported_one` are their
scalar twins for one problem on Python floats (the single call's verification): the same operations in the same
order, so the same decisions and bits (tests/test_scalar_twins.py).
"""
from __future__ import annotations

import math

import numpy as np

from ..result import Status

__all__ = ["decide", "decide_reported", "gamma_from_c", "c_from_gamma", "cheirality", "decide_one", "gamma_lower_one",
           "decide_reported_one", "gamma_lower", "within_resolution", "within_resolution_one", "LB_ROUNDOFF_ULPS",
           "transfer_contradicts", "transfer_contradicts_one", "reported_lower"]

#: gamma_LB is lowered by this many units of round-off of the coordinates' magnitude (:func:`gamma_lower`).
LB_ROUNDOFF_ULPS = 64.0
_U = 2.0 ** -53

_CODES = np.array([Status.NOT_CERTIFIED.value, Status.OPTIMAL.value, Status.NUMERICAL_FAILURE.value], dtype=object)


def decide(c_lower, c_upper, tolerances, n_views=None, resolution=None, squares=True):
    """(status, optimal, reported lower bound) for lower/upper bounds in c units (scalars or arrays).

    OPTIMAL when the bounds meet (``tolerances.certified``) and -- when they meet only through the rule's absolute
    part taken at a scale above c_UB's own (c_UB < 1: ``tolerances.gap_tolerance(c_UB, min(1, |c_UB|))`` exceeded) --
    the gap is within ``resolution`` (the normalisation's resolution of the coordinates,
    :mod:`tritools.model.normalize`; with ``n_views``) on the squares, :func:`within_resolution`.  With
    ``squares=False`` (the repeat on the reported numbers, :func:`decide_reported`) the guard is the one of wave 40:
    a gap that does not pass the relative part alone must be within ``resolution`` in gamma.  NUMERICAL_FAILURE
    when the lower bound is above the upper bound beyond the tolerance (``tolerances.contradicts``: never a
    certificate), NOT_CERTIFIED otherwise; the reported lower bound is ``tolerances.consistent`` (never above
    the upper bound)."""
    certified = np.asarray(tolerances.certified(c_lower, c_upper), bool)
    if resolution is not None and n_views is not None:
        lo, up = np.asarray(c_lower, float), np.asarray(c_upper, float)
        with np.errstate(invalid="ignore"):
            if squares:         # the rule at c_UB's own scale where c_UB < 1 (the solver's absolute error is in c)
                own = np.asarray(up - lo <= tolerances.gap_tolerance(up, np.minimum(1.0, np.abs(up))), bool)
            else:
                own = np.asarray(tolerances.certified_relatively(lo, up), bool)
            resolved = within_resolution(gamma_from_c(lo, n_views, 1.0), gamma_from_c(up, n_views, 1.0), resolution,
                                         squares=squares)
            certified = certified & (own | resolved)
    contradicts = np.asarray(tolerances.contradicts(c_lower, c_upper), bool)
    code = np.where(contradicts, 2, np.where(certified, 1, 0))
    status = _CODES[code]
    optimal = certified & ~contradicts
    lower = tolerances.consistent(c_lower, c_upper)
    if np.ndim(code) == 0:
        return Status(status.item() if hasattr(status, "item") else status), bool(optimal), lower
    return status, optimal, lower


def decide_reported(gamma_lb, gamma_ub, tolerances, n_views, scale, resolution):
    """Whether the bounds as reported in pixels (gamma_UB at the world point, after the normalisation's
    inverse) still pass :func:`decide`: the final consistency step of every path.  The world point can lose
    what the normalised one had (e.g. a depth of 1e-8 in world units), so a decision taken in normalised
    coordinates is confirmed on the numbers the user sees; False where either bound is missing.  The resolution
    guard is on the gap in gamma here (``squares=False``): the reported gamma_LB lies below the decided one by
    round-off bounds in gamma (:func:`gamma_lower`), which the squares would weigh by gamma_UB."""
    lo, up = np.asarray(gamma_lb, float), np.asarray(gamma_ub, float)
    known = np.isfinite(lo) & np.isfinite(up)
    lo, up = np.where(known, lo, 0.0), np.where(known, up, 0.0)
    _, optimal, _ = decide(c_from_gamma(np.minimum(lo, up), n_views, scale), c_from_gamma(up, n_views, scale),
                           tolerances, n_views, resolution, squares=False)
    out = np.asarray(optimal, bool) & known
    return bool(out) if out.ndim == 0 else out


def decide_one(c_lower: float, c_upper: float, tolerances, n_views: int, resolution: float,
               squares: bool = True) -> tuple:
    """The scalar twin of :func:`decide` for one problem: Python floats, ``n_views`` an int > 0, ``tolerances`` a
    :class:`sospoly.Tolerances` (not a subclass: its scalar twins ``gap_tolerance_one`` /
    ``certified_relatively_one`` are the rule here).  (status, optimal, reported lower bound) with the numbers of
    :func:`decide`: every comparison is on values whose NaN / inf cases are settled first (Python's ``max`` would
    drop a NaN)."""
    lo, up = float(c_lower), float(c_upper)
    fin_up, fin_lo = math.isfinite(up), math.isfinite(lo)
    tol = tolerances.gap_tolerance_one(up) if fin_up else math.nan
    certified = fin_up and not math.isnan(lo) and up - lo <= tol
    own = (up - lo <= tolerances.gap_tolerance_one(up, min(1.0, abs(up)))) if squares else \
        tolerances.certified_relatively_one(lo, up)
    if certified and not own:                   # only through the absolute part above c_UB's own scale
        two_n = 2.0 * n_views
        certified = within_resolution_one(math.sqrt(max(lo, 0.0) / two_n), math.sqrt(max(up, 0.0) / two_n),
                                          resolution, squares=squares)
    contradicts = fin_lo and fin_up and lo - up > tol
    status = Status.NUMERICAL_FAILURE if contradicts else Status.OPTIMAL if certified else Status.NOT_CERTIFIED
    return status, certified and not contradicts, up if fin_up and lo > up else lo


def decide_reported_one(gamma_lb: float, gamma_ub: float, tolerances, n_views: int, scale: float,
                        resolution: float) -> bool:
    """The scalar twin of :func:`decide_reported` (Python floats; :func:`decide_one`'s conditions)."""
    lo, up = float(gamma_lb), float(gamma_ub)
    if not (math.isfinite(lo) and math.isfinite(up)):
        return False
    two_n = 2.0 * n_views
    g_lo, g_up = min(lo, up) * scale, up * scale
    return decide_one(two_n * g_lo * g_lo, two_n * g_up * g_up, tolerances, n_views, resolution, squares=False)[1]


def within_resolution(gamma_lb, gamma_ub, resolution, share=1.0, squares=True):
    """Is the gap between ``gamma_lb`` <= ``gamma_ub`` within the coordinates' ``resolution`` (in the same units)?
    The rule is on the squares: gamma_UB^2 - gamma_LB^2 <= share resolution^2 -- for a solver's bounds, whose
    error is one of f = 2N gamma^2; with ``squares=False`` on gamma, gamma_UB - gamma_LB <= share resolution -- for
    bounds apart by round-off terms in gamma (:func:`decide_reported`, the TLS report's guard).

    Why squares: the resolution r = ``RESOLUTION_REL`` |x| (sqrt(eps) of the coordinates' magnitude) is where a
    least-squares optimum can be placed in floating point, and an error r in the projections raises the sum of
    squares f = 2N gamma^2 by ~r^2 per view, whatever gamma* is: a gap of f within 2N r^2.  At gamma_LB = 0 this
    is the gap in gamma of at most r (the rule before wave 41); above, it is ~r^2 / (2 gamma), far below r.  A gap in
    gamma of r let a 16% gap certify a 0.18 px optimum at principal points of 3.9e6 px (r = 0.039 px, a local
    estimate 1400 times the optimum set the normalised units; review 40a MEDIUM-3).  Scalars or arrays; NaN never
    passes."""
    lo, up = np.asarray(gamma_lb, float), np.asarray(gamma_ub, float)
    res = np.asarray(resolution, float)
    with np.errstate(invalid="ignore", over="ignore"):
        out = (up - lo) * (up + lo) <= share * res * res if squares else up - lo <= share * res
    return out.item() if out.ndim == 0 else out


def within_resolution_one(gamma_lb: float, gamma_ub: float, resolution: float, share: float = 1.0,
                          squares: bool = True) -> bool:
    """The scalar twin of :func:`within_resolution` for floats (the same operations)."""
    if not squares:
        return gamma_ub - gamma_lb <= share * resolution
    return (gamma_ub - gamma_lb) * (gamma_ub + gamma_lb) <= share * resolution * resolution


def gamma_from_c(c, n_views, scale=1.0):
    """gamma = sqrt(max(c, 0) / (2N)) / s (the paper's (52)): a bound in c units as an RMS error in the caller's
    pixels; with s = 1 and c a sum of squared distances, the RMS error gamma of SPEC §1.  The one place this
    formula is written (scalars or arrays; N = 0 gives NaN)."""
    c = np.maximum(np.asarray(c, float), 0.0)
    if isinstance(n_views, (int, np.integer)) and n_views > 0 and isinstance(scale, (int, float)) and scale > 0:
        out = np.sqrt(c / (2.0 * n_views)) / scale          # no 0 / 0 possible: no error-state switch (hot path)
    else:
        with np.errstate(invalid="ignore"):
            out = np.sqrt(c / (2 * np.asarray(n_views, float))) / np.asarray(scale, float)
    return out.item() if out.ndim == 0 else out


def gamma_lower(gamma_lb, gamma_ub, scale, resolution, magnitude=None):
    """gamma_LB of the caller's float data from gamma_LB of the normalised data: lowered by
    ``LB_ROUNDOFF_ULPS`` u (A + gamma_UB), A the coordinates' magnitude in pixels: ``magnitude`` = max_i |x_i| sec
    theta_i (:func:`tritools.model.magnitude.magnitudes`) where given, at least max(f_px, median |x_i|) =
    ``resolution / (scale RESOLUTION_REL)`` (f_px the pixel floor, :func:`tritools.model.magnitude.pixel_floors`;
    1 px where the resolution is not known); never below 0.  The largest
    coordinate, not the median: a minority of views 1e5..1e11 px off-axis among ~300 px ones moved the optimum by
    their own round-off, and a median-based lowering left gamma_LB up to 4.7x above an attained value (review 12 F1).

    Why: the certificate holds for the normalised cameras and points, which are the caller's up to a few
    roundings per entry; each distance d_i(X) then moves by a few u (|x_i| + |u_i|) (|u_i| <= |x_i| + d_i), so
    the optimum's ||d|| / sqrt(2N) by at most ~u (A + gamma) times a small constant (measured excess of the
    unlowered bound over the exact optimum: <= 4e-14 px at ~300 px; the slack is ~2e-12 px there).  Scalars or
    arrays; where gamma_UB is not finite, gamma_LB itself stands in for it."""
    from ..model.normalize import RESOLUTION_REL

    g = np.asarray(gamma_lb, float)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        A = np.asarray(resolution, float) / (np.asarray(scale, float) * RESOLUTION_REL)
        A = np.where(np.isfinite(A), A, 1.0)
        if magnitude is not None:
            mag = np.asarray(magnitude, float)
            A = np.maximum(A, np.where(np.isfinite(mag), mag, 1.0))
        ub = np.asarray(gamma_ub, float)
        out = np.maximum(0.0, g - LB_ROUNDOFF_ULPS * _U * (A + np.where(np.isfinite(ub), ub, g)))
    out = np.where(np.isnan(g), g, out)
    return out.item() if out.ndim == 0 else out


def transfer_contradicts(gamma_lb, gamma_ub, tolerances, n_views, scale):
    """Whether gamma_LB of the caller's data (:func:`gamma_lower`) lies above gamma_UB = gamma(X) beyond the
    certificate rule (``tolerances.contradicts`` in c units): the normalised problem's bound, lowered by its
    round-off allowance, still exceeds a cost the caller's data attain, so the allowance did not hold (review 46a:
    1.5e-4 relative next to two near-duplicate camera centres) and the bound is not one.  Clipping it to gamma_UB
    would report a certificate; scalars or arrays (False where either is missing)."""
    lo, up = np.asarray(gamma_lb, float), np.asarray(gamma_ub, float)
    known = np.isfinite(lo) & np.isfinite(up)
    with np.errstate(invalid="ignore", over="ignore"):
        out = known & np.asarray(tolerances.contradicts(c_from_gamma(np.where(known, lo, 0.0), n_views, scale),
                                                        c_from_gamma(np.where(known, up, 0.0), n_views, scale)), bool)
    return bool(out) if out.ndim == 0 else out


def transfer_contradicts_one(gamma_lb: float, gamma_ub: float, tolerances, n_views: int, scale: float) -> bool:
    """The scalar twin of :func:`transfer_contradicts` for floats (``tolerances.contradicts_one``, c = 2N (s
    gamma)^2 on floats: the same operations, tests/test_wave48.py)."""
    lo, up, sc = float(gamma_lb), float(gamma_ub), float(scale)
    if not (math.isfinite(lo) and math.isfinite(up)):
        return False
    n2 = 2 * float(n_views)
    return tolerances.contradicts_one(n2 * (lo * sc) * (lo * sc), n2 * (up * sc) * (up * sc))


def reported_lower(gamma_lb, gamma_ub, tolerances, n_views, scale):
    """(gamma_LB to report, contradicts) for a lowered bound (:func:`gamma_lower`) of stacked problems: NaN where
    :func:`transfer_contradicts` (no bound), else never above gamma_UB."""
    contra = transfer_contradicts(gamma_lb, gamma_ub, tolerances, n_views, scale)
    return np.where(contra, np.nan, np.minimum(gamma_lb, gamma_ub)), contra


def gamma_lower_one(gamma_lb: float, gamma_ub: float, scale: float, resolution: float,
                    magnitude: float | None = None) -> float:
    """The scalar twin of :func:`gamma_lower` for floats (a single result's report: plain Python arithmetic, the same
    operations, equal bit for bit, tests/test_scalar_twins.py); non-finite inputs take :func:`gamma_lower` itself."""
    from ..model.normalize import RESOLUTION_REL

    g, up, sc, res = float(gamma_lb), float(gamma_ub), float(scale), float(resolution)
    if not (math.isfinite(g) and math.isfinite(sc) and sc > 0 and math.isfinite(res)):
        return float(gamma_lower(g, up, sc, res, magnitude))
    A = res / (sc * RESOLUTION_REL)
    A = A if math.isfinite(A) else 1.0
    if magnitude is not None:
        mag = float(magnitude)
        A = max(A, mag if math.isfinite(mag) else 1.0)
    return max(0.0, g - LB_ROUNDOFF_ULPS * _U * (A + (up if math.isfinite(up) else g)))


def c_from_gamma(gamma, n_views, scale):
    """c = 2N (s gamma)^2: the inverse of :func:`gamma_from_c` (for gamma >= 0)."""
    g = np.asarray(gamma, float) * np.asarray(scale, float)
    out = 2 * np.asarray(n_views, float) * g * g
    return out.item() if out.ndim == 0 else out


def cheirality(status, depths, require_in_front: bool = False):
    """(status, in_front): ``in_front`` whether every depth is positive (``depths`` (N,) or (M, N); NaN counts as
    not in front).  The L2 problem ignores cheirality, so a certified minimiser may lie behind a camera; with
    ``require_in_front`` such an OPTIMAL status becomes ``BEHIND_CAMERA``."""
    d = np.asarray(depths, float)
    in_front = np.all(np.isfinite(d) & (d > 0), axis=-1)
    if np.ndim(in_front) == 0:
        st = Status(status)
        behind = require_in_front and st == Status.OPTIMAL and not in_front
        return (Status.BEHIND_CAMERA if behind else st), bool(in_front)
    st = np.asarray(status, dtype=object)
    if not require_in_front:
        return st, in_front
    return np.where((st == Status.OPTIMAL.value) & ~in_front, Status.BEHIND_CAMERA.value, st), in_front
