"""A frame local to a georeferenced model: its cameras formed about an origin c, the translations exact.

A COLMAP model aligned to a geographic frame (``model_aligner``, GPS priors) has cameras and points ~1e6-1e7 m from
its origin and depths of metres.  ``P = K [R | t]`` formed in floating point in that frame holds the rounding of
``R`` (from the quaternion) times |X| ~ 1e7: its projections differ from those of the stored pose by ~u |X| f / depth
px, 1e-8..1e-7 px, and a certificate of the float ``P`` had lower bounds that far above the optimum of the stored
model (review 44b HIGH-2, review 50a F2: 18 of 40 certified points at a UTM-like offset of 7e6 m).

The fix: the certificate is computed in Y = X - c with ``P_c = K [R | t_c]``, ``t_c = t + R(q) c`` evaluated
exactly in rationals (``R(q) = M(q) / |q|^2``, the rotation of the stored quaternion, entries quadratic in q) and
rounded once: the rounding of ``R`` now multiplies |Y| (the model's extent), not |X|.  The estimate is reported as
``Y + c`` (its float rounding: gamma_UB is attained at the exact sum; the written xyz moves by at most an ulp of |c|).
A model is re-centred only where its camera centres sit far from the origin for their spread
(:data:`LOCAL_FRAME_RATIO`): every other model keeps its cameras bit for bit.
"""
from __future__ import annotations

from fractions import Fraction

import numpy as np

__all__ = ["LOCAL_FRAME_RATIO", "model_origin", "local_translations"]

#: a model is certified about its cameras' mean centre c when |c| exceeds this many times the centres' spread
#: (the median distance to c): the rounding of R times |X| then dominates the rounding of R times the extent.
LOCAL_FRAME_RATIO = 100.0


def model_origin(R: np.ndarray, t: np.ndarray, ok: np.ndarray) -> np.ndarray | None:
    """The origin c (3,) of the local frame -- the mean camera centre -R_v' t_v over the usable images ``ok``, in
    floats -- or None where the model is local already (|c| <= LOCAL_FRAME_RATIO times the centres' spread, or
    fewer than one usable image, or anything not finite)."""
    if not np.any(ok):
        return None
    centres = -np.einsum("vji,vj->vi", R[ok], t[ok])
    if not np.all(np.isfinite(centres)):
        return None
    c = centres.mean(axis=0)
    spread = float(np.median(np.linalg.norm(centres - c, axis=1)))
    if not np.linalg.norm(c) > LOCAL_FRAME_RATIO * max(spread, np.finfo(float).tiny):
        return None
    return c


def local_translations(qvec: np.ndarray, t: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(V, 3) ``t_v + R(q_v) c`` of every image, exact in rationals and rounded once (R(q) the rotation of the stored
    quaternion q = (w, x, y, z), any nonzero norm; NaN rows where q or t is not finite or q = 0)."""
    C = [Fraction(float(v)) for v in c]
    out = np.full(np.shape(t), np.nan)
    for v, (q, tv) in enumerate(zip(np.asarray(qvec, float), np.asarray(t, float))):
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(tv)) and np.any(q)):
            continue
        w, x, y, z = (Fraction(float(a)) for a in q)
        n2 = w * w + x * x + y * y + z * z
        M = ((w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)),
             (2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)),
             (2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z))
        out[v] = [float(Fraction(float(tv[k])) + (M[k][0] * C[0] + M[k][1] * C[1] + M[k][2] * C[2]) / n2)
                  for k in range(3)]
    return out
