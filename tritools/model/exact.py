"""Error-free transformations (Knuth's TwoSum, Dekker's TwoProduct) and the compensated dot product Dot2 of
Ogita, Rump and Oishi (2005): a sum of products as accurate as if computed in twice the working precision, for
the places where a plain sum cancels -- a georeferenced camera's P (X, 1), whose terms are ~|X| / depth times the
result.  Vectorised over leading axes; numpy has no fused multiply-add, so products split by Dekker's rule."""
from __future__ import annotations

import math
from fractions import Fraction

import numpy as np

__all__ = ["two_sum", "two_prod", "dot2", "dot2_one", "accurate_homogeneous", "homogeneous_images",
           "CANCELLATION_RATIO", "HOMOGENEOUS_RTOL", "COMPENSATED_DENOM_RTOL", "EXACT_ROUNDING_RATIO",
           "exactly_rounded", "exact_centre", "same_exact_centre", "one_exact_camera"]

#: a sum of products is recomputed by :func:`dot2` when the sum of its terms' magnitudes exceeds this many times
#: its magnitude (more than 6 bits lost to cancellation); below, the plain sum of 4 products errs by at most
#: 4u |terms| <= 4u CANCELLATION_RATIO |sum| (:data:`HOMOGENEOUS_RTOL`).
CANCELLATION_RATIO = 64.0
#: the rule for an undefined projection where P_i X~ was computed by :func:`dot2` (a view that cancels):
#: |P_3 . X~| <= this times sum_k |p3_k| |X~_k| (the point within round-off of the camera's principal plane).  The
#: compensated dot product errs by at most u |P_3 . X~| + 16 u^2 sum_k |p3_k X~_k| (Ogita, Rump and Oishi's Dot2 of
#: four terms, u = 2^-53), so above the rule the denominator errs by at most (u + 16 u^2 / rtol) |P_3 . X~| <=
#: :data:`HOMOGENEOUS_RTOL` |P_3 . X~| (needs rtol >= 16 u / 255 ~ 7e-18), the relative error that
#: :func:`tritools.solve.report.gamma_upper`'s margin assumes of every homogeneous image.  The numerators may cancel
#: further (a projection next to the image origin); :func:`dot2` rounds any entry that cancels more than 40 bits
#: exactly, so they keep that relative error too (~u), and a reported gamma_UB stays an upper bound.  A view that does
#: not cancel has |P_3 . X~| >= sum / CANCELLATION_RATIO and is never undefined.  The plain dot product's rule,
#: :data:`tritools.model.geometry.PROJECTION_DENOM_RTOL` = 1e-10, called views 1e5 times their round-off undefined
#: (georeferenced worlds, points next to nearly coincident centres) and reported their residuals as inf (review 23a
#: F2, F3).  Used by every compensated projection: :func:`tritools.model.frame.project_world` and
#: :func:`tritools.model.geometry.project_points_views` (the report of one point, :func:`tritools.project`).
COMPENSATED_DENOM_RTOL = 1e-17
#: the relative error of a homogeneous image P_i X~ from :func:`homogeneous_images` (either branch).
HOMOGENEOUS_RTOL = 4 * CANCELLATION_RATIO * 2.0 ** -53


def two_sum(a, b):
    """(s, e) with s = fl(a + b) and a + b = s + e exactly (Knuth)."""
    s = a + b
    bb = s - a
    return s, (a - (s - bb)) + (b - bb)


def two_prod(a, b):
    """(p, e) with p = fl(a b) and a b = p + e exactly (Dekker's splitting; no fused multiply-add in numpy)."""
    p = a * b
    ca, cb = 134217729.0 * a, 134217729.0 * b             # 2^27 + 1
    ah, bh = ca - (ca - a), cb - (cb - b)
    al, bl = a - ah, b - bh
    return p, al * bl - (((p - ah * bh) - al * bh) - ah * bl)


def dot2(A: np.ndarray, x: np.ndarray, b: np.ndarray) -> np.ndarray:
    """sum_k A[..., k] x[..., k] + b, accurate as if computed in twice the working precision (Ogita, Rump and
    Oishi's Dot2), and rounded exactly where that is not enough: Dot2 errs by at most u |s| + gamma_5^2 S (S = |b| +
    sum_k |A_k x_k|, gamma_5 ~ 5u), so where S exceeds :data:`EXACT_ROUNDING_RATIO` |s| (more than 40 bits cancelled:
    a numerator next to the image origin in a georeferenced world) the result is recomputed as the correctly rounded
    sum of the exact products' parts (:func:`math.fsum` of b and the pairs of :func:`two_prod`).  Every entry then errs
    by at most ~1.003 u |s| (0 stays 0), the relative error :data:`HOMOGENEOUS_RTOL` covers; the plain sum where the
    splitting overflows.  :func:`tritools.model.frame._dot2_one` is the scalar twin (the same numbers)."""
    P, EP = two_prod(A, x)                  # every product at once (elementwise: the same numbers as one by one)
    s, c = b, np.zeros_like(b)
    S = np.abs(b)
    for k in range(A.shape[-1]):
        s, es = two_sum(s, P[..., k])
        c = c + (EP[..., k] + es)
        S = S + np.abs(P[..., k])
    out = s + c
    plain = np.einsum("...k,...k->...", A, x) + b
    out = np.where(np.isfinite(out), out, plain)
    with np.errstate(invalid="ignore", over="ignore"):
        flagged = np.nonzero(np.isfinite(out) & (S > EXACT_ROUNDING_RATIO * np.abs(out)))
    if flagged[0].size:
        out = np.array(out, dtype=float)
        for idx in zip(*flagged):
            out[idx] = exactly_rounded(b[idx], P[idx], EP[idx], out[idx])
    return out


def dot2_one(a, x, b: float) -> float:
    """:func:`dot2` of one row on floats (a, x sequences of floats, b a float): the same operations in its order,
    the plain sum (numpy's, for its bits) where the result is not finite, and the same exact rounding where more than
    40 bits cancel; equal bit for bit (tests/test_wave48.py)."""
    s, c, S = b, 0.0, abs(b)
    P, EP = [], []
    for ak, xk in zip(a, x):
        p, ep = two_prod(ak, xk)
        s, es = two_sum(s, p)
        c = c + (ep + es)
        S = S + abs(p)
        P.append(p)
        EP.append(ep)
    out = s + c
    if not math.isfinite(out):
        with np.errstate(all="ignore"):
            out = float(np.einsum("k,k->", np.asarray(a, float), np.asarray(x, float)) + b)
    if math.isfinite(out) and S > EXACT_ROUNDING_RATIO * abs(out):
        out = exactly_rounded(b, P, EP, out)
    return out


#: :func:`dot2` rounds a sum exactly where the sum of its terms' magnitudes exceeds this many times its value:
#: below, Dot2's bound u |s| + 25 u^2 S is at most (1 + 25 u 2^40) u |s| ~ 1.003 u |s|.
EXACT_ROUNDING_RATIO = 2.0 ** 40


def exactly_rounded(b: float, P, EP, fallback: float) -> float:
    """fl(b + sum_k (P_k + EP_k)): the exact sum of a dot product's parts (:func:`two_prod`'s pairs, exact unless
    a product underflows), correctly rounded by :func:`math.fsum`; ``fallback`` where the parts are not finite."""
    parts = [float(b)] + [float(v) for pair in zip(P, EP) for v in pair]
    try:
        out = math.fsum(parts)
    except (OverflowError, ValueError):
        return float(fallback)
    return out if math.isfinite(out) else float(fallback)


def accurate_homogeneous(P: np.ndarray, Xh: np.ndarray) -> np.ndarray:
    """P (X, 1) (..., 3) for cameras P (..., 3, 4) and homogeneous points Xh broadcast to (..., 1, 4) by
    :func:`dot2` (each row a compensated dot product)."""
    Xb = np.broadcast_to(Xh, P.shape)
    return dot2(P, Xb, np.zeros(P.shape[:-1]))


def homogeneous_images(C: np.ndarray, Xh: np.ndarray) -> np.ndarray:
    """P_i X~ (..., N, 3) for cameras C (..., N, 3, 4) and homogeneous points Xh (..., 4): the plain sum, recomputed
    by :func:`dot2` in the views where it cancels (|P_i| |X~| > CANCELLATION_RATIO |P_i X~| in some row; a
    georeferenced world), decided per view so that a problem gets the same numbers alone or in a stack."""
    h = np.einsum("...nij,...j->...ni", C, Xh)
    mag = np.einsum("...nij,...j->...ni", np.abs(C), np.abs(Xh))
    with np.errstate(invalid="ignore"):
        idx = np.nonzero(~np.all(mag <= CANCELLATION_RATIO * np.abs(h), axis=-1))
    if idx[0].size:
        Xb = np.broadcast_to(Xh[..., None, :], C.shape[:-2] + (4,))
        h[idx] = accurate_homogeneous(C[idx], Xb[idx][..., None, :])
    return h


def exact_centre(P) -> tuple:
    """The null vector of the float 3 x 4 camera P in exact integer arithmetic: the signed 3 x 3 cofactors
    C_k = (-1)^k det(P without column k) of P scaled to integers (every float is m 2^e), a tuple of 4 Python ints
    (all 0 when P has rank < 3).  The camera centre of the caller's data, with no round-off."""
    ratios = [float(v).as_integer_ratio() for v in np.asarray(P, float).ravel()]
    den = max(d for _, d in ratios)
    M = [[n * (den // d) for n, d in ratios[4 * r:4 * r + 4]] for r in range(3)]

    def det3(cols):
        (a, b, c), (d, e, f), (g, h, i) = ([M[r][k] for k in cols] for r in range(3))
        return a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)

    return tuple((-1) ** k * det3([m for m in range(4) if m != k]) for k in range(4))


def same_exact_centre(Pi, Pj) -> bool:
    """Do the float cameras P_i and P_j have one centre in exact arithmetic (their :func:`exact_centre` null vectors
    proportional, neither zero)?  A pair whose centres agree only to round-off has a micro-baseline: next to the
    centres the exact problem sees parallax, so the one-centre constraints (a homography) would cut off points."""
    a, b = exact_centre(Pi), exact_centre(Pj)
    if not any(a) or not any(b):
        return False
    return all(a[p] * b[q] == a[q] * b[p] for p in range(4) for q in range(p + 1, 4))


def one_exact_camera(cameras) -> bool:
    """Are the float cameras (N, 3, 4) one camera given N times: each exactly a multiple of the first (the 12-vectors
    proportional in exact rational arithmetic)?  Only then does every view project each X to the same point; cameras
    equal only to round-off may have a micro-baseline, and near their centres the exact problem sees parallax
    (:func:`same_exact_centre`).  A float screen (a necessary condition: an exact multiple leaves ~1e-16 in it) rejects
    distinct cameras before the exact test."""
    C = np.asarray(cameras, float).reshape(len(cameras), 12)
    k = int(np.argmax(np.abs(C[0])))
    if not (np.isfinite(C).all() and C[0, k] != 0):
        return False
    top = float(np.max(np.abs(C[0])))
    for row in C[1:]:
        if not np.array_equal(row == 0, C[0] == 0) or \
                np.max(np.abs(row * C[0, k] - row[k] * C[0])) > 1e-12 * abs(row[k]) * top:
            return False
    a = [Fraction(float(v)) for v in C[0]]
    for row in C[1:]:
        b = [Fraction(float(v)) for v in row]
        if any(b[i] * a[k] != b[k] * a[i] for i in range(12)):
            return False
    return True
