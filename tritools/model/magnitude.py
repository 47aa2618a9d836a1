"""The magnitudes a reported bound is rounded by, and the coordinates' resolution (:mod:`tritools.model.normalize`).

A certificate holds for the normalised cameras and points, which are the caller's up to a few roundings per entry;
each distance d_i(X) then moves by a few u (|x_i| + |u_i|) (u the unit round-off), and gamma_LB is lowered by
that (:func:`tritools.solve.decide.gamma_lower`) with :func:`magnitudes` (the points' obliquity magnitudes) and the
frame origin's terms (:func:`origin_magnitudes`, :func:`world_origin_magnitudes`).  A gap that passes the
certificate rule only through its absolute part must also be within the coordinates' resolution
(:func:`guard_resolutions`): ``RESOLUTION_REL`` min_i max(f_i, |x_i|) pixels over the views, the floor f_i =
``PIXEL_FLOOR_REL`` times view i's focal length (:func:`view_floors`), so that rescaling the images rescales every
bound and decision alike (review 31b F10) and a view of fine pixels is not judged at a coarse view's resolution
(review 47b H1); the median rule RESOLUTION_REL max(f_px, median |x|) (:func:`resolutions`, f_px from the views'
median focal length, :func:`pixel_floors`) stays the floor of the lowering's magnitude.
"""
from __future__ import annotations

import math

import numpy as np

from sospoly import pow2_above

from .oblique import obliquities, obliquity_one
from .stacked import median_rows, pixel_scales

__all__ = ["magnitudes", "origin_magnitudes", "world_origin_magnitudes", "world_origin_magnitude_one",
           "frame_magnitude_one", "resolutions", "guard_resolutions", "view_floors", "resolution_pair",
           "resolution_pair_one", "resolution_pair_floats", "list_median", "median_pixel_scales", "pixel_floors",
           "ieee_div", "RESOLUTION_REL", "PIXEL_FLOOR_REL", "SCALAR_MAX_VIEWS"]

#: the resolution of the coordinates, relative to their magnitude (sqrt of the machine epsilon).
RESOLUTION_REL = 1e-8
#: the coordinates' magnitude floor relative to the views' median pixel scale (:func:`pixel_floors`).
PIXEL_FLOOR_REL = 1e-3


def magnitudes(x: np.ndarray, C: np.ndarray | None = None, at: np.ndarray | None = None) -> np.ndarray:
    """max_i |x_i| sec theta_i over the finite coordinates of each problem's points x (M, N, 2), in pixels (0 for none):
    a bound of the magnitude whose round-off each distance d_i carries (:func:`tritools.solve.decide.gamma_lower`,
    which floors it by the resolution's magnitude, max(pixel floor, median |x|); the resolution, by contrast, is of
    the median magnitude, review 12 F1).  With the cameras C (M, N, 3, 4) (at the
    points ``at``, default x: the normalised cameras at 0, the obliquity being the frame's), sec theta_i is the
    obliquity of view i's ray (:func:`tritools.model.oblique.obliquities`): the depth of a point on a ray with sec
    theta = 1e8 (an observation 1e11 px off-axis at f = 1e3) moves by ~1e8 times the round-off of the cameras, its
    projection with it, so a bound computed in a rounded frame held the caller's problem only to that (review 24a
    F2/F3: certified TLS bounds 13.5 and 654 px where the float data attain 0.51 and 3.3 px next to such a ray).
    Without C, sec theta = 1."""
    a = np.abs(np.asarray(x, float))
    a = np.where(np.isfinite(a), a, 0.0)
    if not a.size:
        return np.zeros(len(x))
    a = a.max(axis=2)
    if C is not None:
        at = np.where(np.isfinite(x), x, 0.0) if at is None else at
        if len(a) == 1 and a.shape[1] <= SCALAR_MAX_VIEWS:     # one problem: the scalar twin, the same numbers
            sec = np.array([_obliquities_one(np.asarray(C[0], float), at[0])])
        else:
            sec = obliquities(C, at)
        with np.errstate(invalid="ignore", over="ignore"):
            a = np.where(a > 0, a * sec, 0.0)
    # an obliquity that overflows (a ray parallel to the image plane): the largest finite magnitude, which lowers
    # gamma_LB to 0 (gamma_lower reads a non-finite magnitude as 1)
    return np.minimum(a.max(axis=1), np.finfo(float).max)


def origin_magnitudes(Cn: np.ndarray, x: np.ndarray, o: np.ndarray, scale) -> np.ndarray:
    """(M,) max_i K_i, in pixels, for normalised cameras Cn (M, N, 3, 4) at their origin (the normalisation's point
    X0), the caller's points x (M, N, 2), the given frame's origin o (M, 3) in normalised coordinates and the image
    scales (M,): K_i = (max_k |h_ik(o)| / s + 2 |x_i| |h_i3(o)|) / |h_i3(X0)| with |h(o)| <= |Cn| |(o, 1)| (sums of
    absolute products), i.e. (|P_k o~| + |x_i| |P_3 o~|) / |P_3 X0~| of the cameras as given.  The cameras given to
    the normalisation are the caller's up to one rounding of their last column (a georeferenced world re-centred,
    :func:`tritools.model.frame.moved_cameras`, or the robust search's frame at the centres' mean): a relative error
    u there moves the projection of a point near X0 by u K_i, which the frame's other roundings (u |x_i| sec theta_i,
    :func:`magnitudes`) do not cover where the frame's origin is far from the point relative to its depth (review
    25a F1: the cameras' spread 700 depths, L2 bounds certified 6.7e-11 px above the real optimum; F2: an optimum
    1e-9 from a camera centre).  inf where a depth vanishes (gamma_LB then lowered to 0), NaN where not finite."""
    oh = np.concatenate([np.abs(o), np.ones(o.shape[:-1] + (1,))], axis=-1)[:, None, None, :]
    A = np.add.reduce(np.abs(Cn) * oh, axis=-1)                         # (M, N, 3): bounds of |h(o)|
    den = np.abs(Cn[..., 2, 3])
    ax = np.max(np.abs(np.where(np.isfinite(x), x, 0.0)), axis=-1, initial=0.0)
    K = (np.maximum(A[..., 0], A[..., 1]) / np.asarray(scale, float)[:, None] + 2.0 * ax * A[..., 2]) / den
    return np.minimum(np.max(K, axis=1, initial=0.0), np.finfo(float).max)


def world_origin_magnitudes(C: np.ndarray, x: np.ndarray, X: np.ndarray, o: np.ndarray,
                            entries: bool = False, views: np.ndarray | None = None) -> np.ndarray:
    """(M,) max_i K_i, in pixels, for the caller's cameras C (M, N, 3, 4) moved to a frame at origin o (M, 3) and the
    estimate X (M, 3): the cameras P' = P [I o; 0 1] have their last column P o~ rounded once, the rest as given, which
    moves the projection of X by u K_i, K_i = (max_k a_k + r_i a_3) / |P_3 X~| with a_k = |P_k o~| and r_i =
    max(|x_i|, |x^_i|) (the observed point and the projection): the frame origin's term (:func:`origin_magnitudes`).
    With ``entries`` every entry of P' errs by a few u relative (a frame normalised further, e.g. by a depth that
    is no power of two: the L2 paths' :meth:`tritools.model.normalize.NormalizationStack.magnitudes_at`), and a_k
    gains |P_k,1:3| . |X - o| (a_k then bounds |P'_k| . |(X - o)~|): large where X is close to a camera centre
    relative to its distance from o (review 45a HIGH-1: two cameras 2e-9 apart, the optimum 6e-8 of the scene size
    from their centres, gamma_LB clipped to gamma_UB 1.8e-11 px above the cost at X).  Plain float sums with their
    error bounds (gamma_4 times the sums of absolute products: |P_k o~| from above, |P_3 X~| from below), so no
    compensated sums are needed; inf where the depth's bound reaches 0 or the projection is not finite (gamma_LB
    then lowered to 0); a NaN coordinate of x (no observation) is left out of r_i.  ``views`` (M, N) bool: the max
    over these views only (0 for none).  :func:`world_origin_magnitude_one` is the scalar twin (the same
    operations)."""
    C, x, X, o = (np.asarray(a, float) for a in (C, x, X, o))
    P = [[C[..., k, c] for c in range(4)] for k in range(3)]              # (M, N) entries
    Xe = [X[:, c, None] for c in range(3)]
    oe = [o[:, c, None] for c in range(3)]
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        d = [np.abs(Xe[c] - oe[c]) for c in range(3)]
        a = []
        for k in range(3):
            Pk = P[k]
            ho = ((Pk[0] * oe[0] + Pk[1] * oe[1]) + Pk[2] * oe[2]) + Pk[3]
            ao = ((np.abs(Pk[0]) * np.abs(oe[0]) + np.abs(Pk[1]) * np.abs(oe[1])) + np.abs(Pk[2]) * np.abs(oe[2])) \
                + np.abs(Pk[3])
            dk = ((np.abs(Pk[0]) * d[0] + np.abs(Pk[1]) * d[1]) + np.abs(Pk[2]) * d[2]) if entries else 0.0
            a.append(((np.abs(ho) + _GAMMA4 * ao) + dk) * _UP)
        h = [((P[k][0] * Xe[0] + P[k][1] * Xe[1]) + P[k][2] * Xe[2]) + P[k][3] for k in range(3)]
        aX = ((np.abs(P[2][0]) * np.abs(Xe[0]) + np.abs(P[2][1]) * np.abs(Xe[1])) + np.abs(P[2][2]) * np.abs(Xe[2])) \
            + np.abs(P[2][3])
        den = np.abs(h[2]) - _GAMMA4 * aX
        rh = np.maximum(np.abs(h[0]), np.abs(h[1])) / den
        r = np.fmax(np.fmax(np.abs(x[..., 0]), np.abs(x[..., 1])), rh)          # a missing coordinate: not counted
        r = np.where(np.isfinite(r), r, 0.0)
        K = np.where((den > 0) & np.isfinite(rh), (np.maximum(a[0], a[1]) + r * a[2]) / den, np.inf)
        K = np.where(np.isnan(K), np.inf, K)
        if views is not None:
            K = np.where(views, K, 0.0)
    return np.minimum(np.max(K, axis=1, initial=0.0), np.finfo(float).max)


def world_origin_magnitude_one(C, x, X, o, entries: bool = False, views=None) -> float:
    """The scalar twin of :func:`world_origin_magnitudes` for one problem (C (N, 3, 4), x (N, 2), X (3,), o (3,),
    nested lists or arrays of floats; ``views`` (N,) bool or None): the same operations on Python floats, equal bit
    for bit, also on non-finite entries (tests/test_wave46.py, tests/test_wave47.py, tests/test_wave49.py)."""
    X0, X1, X2 = (float(v) for v in X)
    o0, o1, o2 = (float(v) for v in o)
    d0, d1, d2 = abs(X0 - o0), abs(X1 - o1), abs(X2 - o2)
    big = float(np.finfo(float).max)
    out = 0.0
    keep = [True] * len(C) if views is None else [bool(v) for v in views]
    for P, xi, use in zip(np.asarray(C, float).tolist(), np.asarray(x, float).tolist(), keep):
        if not use:
            continue
        a = []
        for Pk in P:
            ho = ((Pk[0] * o0 + Pk[1] * o1) + Pk[2] * o2) + Pk[3]
            ao = ((abs(Pk[0]) * abs(o0) + abs(Pk[1]) * abs(o1)) + abs(Pk[2]) * abs(o2)) + abs(Pk[3])
            dk = ((abs(Pk[0]) * d0 + abs(Pk[1]) * d1) + abs(Pk[2]) * d2) if entries else 0.0
            a.append(((abs(ho) + _GAMMA4 * ao) + dk) * _UP)
        h = [((Pk[0] * X0 + Pk[1] * X1) + Pk[2] * X2) + Pk[3] for Pk in P]
        P3 = P[2]
        aX = ((abs(P3[0]) * abs(X0) + abs(P3[1]) * abs(X1)) + abs(P3[2]) * abs(X2)) + abs(P3[3])
        den = abs(h[2]) - _GAMMA4 * aX
        if not den > 0:
            return big
        rh = _max_nan(abs(h[0]), abs(h[1])) / den
        if not math.isfinite(rh):
            return big
        r = _fmax(_fmax(abs(xi[0]), abs(xi[1])), rh)
        r = r if math.isfinite(r) else 0.0
        K = (_max_nan(a[0], a[1]) + r * a[2]) / den
        if K != K or K > big:
            return big
        out = max(out, K)
    return out


def frame_magnitude_one(Cn, x, o, scale: float) -> float:
    """The scalar twin of ``max(magnitudes(x, Cn, 0), origin_magnitudes(Cn, x, o, scale))`` (NaN of the latter read
    as 1: :meth:`tritools.model.normalize.NormalizationStack.magnitude`) for one problem (normalised cameras Cn
    (N, 3, 4), the caller's points x (N, 2), the given frame's origin o (3,) in normalised coordinates, the image
    scale): the same operations on Python floats, equal bit for bit (tests/test_wave48.py)."""
    o0, o1, o2 = (abs(float(v)) for v in o)
    scale = float(scale)
    big = float(np.finfo(float).max)
    mag, frame = 0.0, 0.0
    for P, (u, v) in zip(np.asarray(Cn, float).tolist(), np.asarray(x, float).tolist()):
        u, v = (u if math.isfinite(u) else 0.0), (v if math.isfinite(v) else 0.0)
        ax = _max_nan(abs(u), abs(v))
        if ax > 0:                                     # magnitudes(): |x_i| sec theta_i at the frame's origin
            k = pow2_above(max(abs(e) for row in P for e in row))
            mag = max(mag, ax * obliquity_one([[e / k for e in row] for row in P], (0.0, 0.0)))
        A = [((abs(r[0]) * o0 + abs(r[1]) * o1) + abs(r[2]) * o2) + abs(r[3]) for r in P]
        num = ieee_div(_max_nan(A[0], A[1]), scale) + 2.0 * ax * A[2]
        K = ieee_div(num, abs(P[2][3]))
        if K != K or frame != frame:
            frame = math.nan
        else:
            frame = max(frame, K)
    frame = 1.0 if frame != frame else min(frame, big)
    return _max_nan(min(mag, big), frame)


def ieee_div(a: float, b: float) -> float:
    """a / b on floats with numpy's answers where Python raises: +-inf for a / +-0 (a != 0, the signs' product),
    NaN for 0 / 0 and NaN / 0 (review 48b F2: an image scale of 0 raised ``ZeroDivisionError`` in a twin)."""
    if b != 0.0 or b != b:
        return a / b
    if a == 0.0 or a != a:
        return math.nan
    return math.copysign(math.inf, a) * math.copysign(1.0, b)


def _max_nan(a: float, b: float) -> float:
    """``numpy.maximum`` of two floats: NaN if either is (Python's ``max`` depends on the order; review 46c L2)."""
    if a != a or b != b:
        return math.nan
    return a if a >= b else b


def _fmax(a: float, b: float) -> float:
    """``numpy.fmax`` of two floats: the other where one is NaN."""
    if a != a:
        return b
    if b != b:
        return a
    return a if a >= b else b


#: gamma_4 (4 u / (1 - 4 u), rounded up): the error bound of a float sum of four products relative to the sum of
#: their absolute values; _UP rounds a sum of a few non-negative terms up.
_GAMMA4 = 5.0 * 2.0 ** -53
_UP = 1.0 + 8.0 * 2.0 ** -53


#: :func:`magnitudes` of one problem takes the scalar obliquities up to this many views.
SCALAR_MAX_VIEWS = 7


def _obliquities_one(C: np.ndarray, at: np.ndarray) -> list:
    """:func:`tritools.model.oblique.obliquities` of one problem (C (N, 3, 4), at (N, 2)) view by view
    (:func:`~tritools.model.oblique.obliquity_one` on the cameras divided by the same powers of two)."""
    out = []
    for P, p in zip(C.tolist(), at.tolist()):
        m = max(abs(v) for row in P for v in row)                 # power2_scale's power of two, on floats
        k = pow2_above(m)
        out.append(obliquity_one([[v / k for v in row] for row in P], p))
    return out


def resolutions(scale: np.ndarray, x: np.ndarray, floor=1.0) -> np.ndarray:
    """s RESOLUTION_REL max(floor, median |x|) per problem (x (M, N, 2)): the coordinates' resolution in normalised
    units (module docstring); ``floor`` (M,) the pixel floor of the problems' cameras (:func:`pixel_floors`), 1 px
    where their cameras are not known."""
    with np.errstate(all="ignore"):
        mag = median_rows(np.abs(x.reshape(len(x), -1))) if x.size else np.zeros(len(x))
        out = np.asarray(scale, float) * RESOLUTION_REL * np.maximum(floor, np.where(np.isfinite(mag), mag, 1.0))
    return np.where(np.isfinite(out) & (out > 0), out, np.inf)


def guard_resolutions(scale, x: np.ndarray, view_floor) -> np.ndarray:
    """s RESOLUTION_REL min_i max(f_i, |x_i|) per problem (x (M, N, 2), ``view_floor`` (M, N) the views' pixel floors,
    :func:`view_floors`): the resolution below which the decision lets a gap pass (module docstring), of the view
    resolved most finely.  Per view, not of the median: a view's pixels weigh in gamma as its own, so with two views
    of pixel scales 1e-3 and 1e6 a median (their mean) let a gap of 1e-5 pass on the first view's ~1e-6 coordinates
    (review 47b H1: gamma_UB certified 68 % above the optimum).  Never above :func:`resolutions` (the median rule,
    which the lowering of gamma_LB keeps as its floor); views without a finite point are left out."""
    x = np.asarray(x, float)
    with np.errstate(all="ignore"):
        a = np.max(np.abs(x), axis=2) if x.size else np.zeros(x.shape[:2])
        per = np.where(np.isfinite(a), np.maximum(np.asarray(view_floor, float), a), np.inf)
        mag = np.min(per, axis=1, initial=np.inf)
        out = np.asarray(scale, float) * RESOLUTION_REL * mag
    median_rule = resolutions(scale, x, _nanmedian_rows(np.where(np.isfinite(view_floor), view_floor, np.nan))
                              if x.shape[1] else 1.0)
    return np.where(np.isfinite(out) & (out > 0), np.minimum(out, median_rule), median_rule)


def view_floors(C: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(M, N) ``PIXEL_FLOOR_REL`` times each view's pixel scale at its point (:func:`tritools.model.stacked.
    pixel_scales`), the problem's :func:`pixel_floors` where a view has none."""
    ps = pixel_scales(C, x)
    good = np.isfinite(ps) & (ps > 0)
    fallback = pixel_floors(medians=_nanmedian_rows(np.where(good, ps, np.nan)))
    return np.where(good, PIXEL_FLOOR_REL * ps, fallback[:, None])


def resolution_pair(scale, x: np.ndarray, C: np.ndarray | None, floor=None) -> tuple:
    """((M,) the decision's resolution, (M,) the median rule's) of problems with points x (M, N, 2) and cameras C
    (M, N, 3, 4) (None: 1 px floors) at image scales ``scale``: :func:`guard_resolutions` and :func:`resolutions`
    (``floor``: the problems' pixel floors, when known)."""
    if C is None:
        return guard_resolutions(scale, x, np.ones(x.shape[:2])), resolutions(scale, x, 1.0)
    floor = pixel_floors(C, x) if floor is None else floor
    return guard_resolutions(scale, x, view_floors(C, x)), resolutions(scale, x, floor)


def resolution_pair_one(s: float, xi: list, ps_all: list, med: float) -> tuple:
    """The scalar twin of :func:`resolution_pair` for one problem on the common path of
    :func:`tritools.model.normalize._normalization_one`
    (points xi as N pairs, every view's pixel scale ``ps_all``, their median over the finite positive ones ``med``):
    the same operations on floats, equal bit for bit (tests/test_wave47.py)."""
    good = [p for p in ps_all if 0.0 < p < math.inf]
    vmed = list_median(good)
    fallback = PIXEL_FLOOR_REL * vmed if 0.0 < vmed < math.inf else 1.0            # view_floors' fill
    vf = [PIXEL_FLOOR_REL * p if 0.0 < p < math.inf else fallback for p in ps_all]
    per = [max(f, max(abs(a), abs(b))) for f, (a, b) in zip(vf, xi)
           if math.isfinite(a) and math.isfinite(b)]
    coords = [abs(v) for pair in xi for v in pair]
    xmed = math.nan if any(v != v for v in coords) else list_median(coords)         # (median_rows: NaN sorts last)
    xmag = xmed if math.isfinite(xmed) else 1.0

    def rule(floor: float) -> float:                     # resolutions(): s RESOLUTION_REL max(floor, median |x|)
        out = s * RESOLUTION_REL * max(floor, xmag)
        return out if math.isfinite(out) and out > 0 else math.inf

    median_rule = rule(list_median(vf))
    out = s * RESOLUTION_REL * min(per) if per else math.inf
    guard = min(out, median_rule) if math.isfinite(out) and out > 0 else median_rule
    return np.array([guard]), np.array([rule(PIXEL_FLOOR_REL * med if 0.0 < med < math.inf else 1.0)])


def resolution_pair_floats(s: float, xi, C) -> tuple | None:
    """:func:`resolution_pair` of one problem (points xi (N, 2), cameras C (N, 3, 4)) on floats: the views' pixel
    scales by :func:`tritools.model.frame_floats.pixel_scale_one` (numpy's bits), then :func:`resolution_pair_one`;
    ((1,), (1,)) arrays, or None where no view has a finite positive pixel scale or one is near overflow (the stacked
    code decides those cases)."""
    from .frame_floats import pixel_scale_one

    pts = np.asarray(xi, float).tolist()
    ps_all = [pixel_scale_one(P, q) for P, q in zip(np.asarray(C, float).tolist(), pts)]
    good = [p for p in ps_all if 0.0 < p < math.inf]
    if not good or max(good) > _FLOATS_MAX_SCALE:      # (near overflow the medians' rules part: review 48b F1)
        return None
    return resolution_pair_one(float(s), pts, ps_all, list_median(good))


#: :func:`resolution_pair_floats` leaves pixel scales above this to the stacked code (its median's mean of the two
#: middle scales overflows there, the float twin's does not)
_FLOATS_MAX_SCALE = 1e300


def list_median(values: list) -> float:
    """The median of a non-empty list of floats without NaN: the middle one, or the mean of the middle two as
    (lo + hi) / 2 (:func:`median_rows`' formula)."""
    v = sorted(values)
    n = len(v)
    return v[n // 2] if n % 2 else (v[n // 2 - 1] + v[n // 2]) / 2


def median_pixel_scales(C: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(M,) the median over the views of the finite positive pixel scales
    (:func:`tritools.model.stacked.pixel_scales`: the focal lengths) of M problems (C (M, N, 3, 4), x (M, N, 2));
    NaN where no view has one."""
    ps = pixel_scales(C, x)
    return _nanmedian_rows(np.where(np.isfinite(ps) & (ps > 0), ps, np.nan))


def pixel_floors(C: np.ndarray | None = None, x: np.ndarray | None = None, *, medians=None) -> np.ndarray | float:
    """The least magnitude in pixels that the coordinates' resolution and round-off are taken of: ``PIXEL_FLOOR_REL``
    times the views' median pixel scale (:func:`median_pixel_scales` of C, x, or the given ``medians``), 1 px where
    there is none.  Relative to the focal length, not a fixed pixel: rescaling the images by k rescales every bound,
    resolution and decision by k (review 31b F10: with a 1 px floor, images scaled by 1e-12 were certified at a 1e-3
    relative gap); at f = 1000 px the floor is the 1 px it was.  (M,) array, or a float for a float ``medians``."""
    med = median_pixel_scales(C, x) if medians is None else medians
    if isinstance(med, float):
        return PIXEL_FLOOR_REL * med if 0.0 < med < math.inf else 1.0
    with np.errstate(invalid="ignore"):
        return np.where(np.isfinite(med) & (med > 0), PIXEL_FLOOR_REL * med, 1.0)


def _nanmedian_rows(a: np.ndarray) -> np.ndarray:
    """``numpy.nanmedian(a, axis=1)`` for a 2-D array (NaN for an all-NaN row), without its per-call overhead:
    NaNs sort last, so the median of row m is the mean of its middle non-NaN entries."""
    s = np.sort(a, axis=1)
    k = np.sum(~np.isnan(a), axis=1)
    if s.shape[1] == 0:
        return np.full(len(a), np.nan)
    rows = np.arange(len(a))
    lo = s[rows, np.maximum((k - 1) // 2, 0)]
    hi = s[rows, k // 2]                                             # k <= N, so k // 2 < N
    return np.where(k > 0, (lo + hi) / 2, np.nan)
