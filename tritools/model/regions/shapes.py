"""The shape fields of 2 x 2 symmetric positive definite matrices, exact to round-off for thin ellipses too.

An eigensolver's small eigenvalue carries an error of ~eps lam_max: at an axis ratio of 1e5 the minor semi-axis of an
ellipse was off by ~3e-7 of itself, and D^-1 (from an LU inverse) by ~1e-7, so distances and the ellipse's polynomial
described slightly different ellipses (found when long thin ellipses became certifiable, wave 43).  For D = [[a, b],
[b, d]], scaled by a power of two so that its largest entry is in [1, 2) (exact):

* lam_max = (a + d) / 2 + hypot((a - d) / 2, b) (no cancellation for a positive semidefinite D);
* det = a d - b^2 from error-free products (Dekker's product, Veltkamp's split), so lam_min = det / lam_max and
  D^-1 = adj(D) / det are exact to a few units of round-off;
* the major axis (h + s, b) for h = (a - d) / 2 >= 0, (b, s - h) otherwise (s = hypot(h, b)), the minor axis its
  normal.
"""
from __future__ import annotations

import numpy as np

__all__ = ["shape_fields"]

_SPLIT = 2.0 ** 27 + 1.0


def _two_product(x: np.ndarray, y: np.ndarray) -> tuple:
    """(p, e) with p = fl(x y) and p + e = x y exactly for |x|, |y| < 2 (Dekker's product, Veltkamp's split)."""
    p = x * y
    sx, sy = _SPLIT * x, _SPLIT * y
    xh, yh = sx - (sx - x), sy - (sy - y)
    xl, yl = x - xh, y - yh
    return p, ((xh * yh - p) + xh * yl + xl * yh) + xl * yl


def shape_fields(D: np.ndarray) -> tuple:
    """(D symmetrised, semi-axes sqrt(eig D) descending, the matching axis directions (columns), D^-1, the eigenvalues
    ascending) of stacked matrices D (M, 2, 2) symmetric to round-off (module docstring); NaN fields where D is not
    finite, and an inverse of NaN where det D <= 0 (the caller refuses such a matrix)."""
    D = 0.5 * D + 0.5 * np.swapaxes(D, 1, 2)        # (not 0.5 (D + D^T): that overflows for entries near 1e308)
    with np.errstate(all="ignore"):
        top = np.max(np.abs(D), axis=(1, 2))
        sc = np.where((top > 0) & np.isfinite(top), np.ldexp(1.0, np.frexp(top)[1] - 1), 1.0)   # entries < 2
        a, b, d = D[:, 0, 0] / sc, D[:, 0, 1] / sc, D[:, 1, 1] / sc
        h = 0.5 * a - 0.5 * d
        sq = np.hypot(h, b)
        big = (0.5 * a + 0.5 * d) + sq
        p1, e1 = _two_product(a, d)
        p2, e2 = _two_product(b, b)
        det = (p1 - p2) + (e1 - e2)
        lam = np.stack([det / big, big], axis=1) * sc[:, None]
        vx, vy = np.where(h >= 0, h + sq, b), np.where(h >= 0, b, sq - h)
        nv = np.hypot(vx, vy)
        round_ = ~(nv > 0)                           # a circle: any axes
        vx, vy, nv = np.where(round_, 1.0, vx), np.where(round_, 0.0, vy), np.where(round_, 1.0, nv)
        ux, uy = vx / nv, vy / nv
        Q = np.stack([np.stack([ux, -uy], axis=1), np.stack([uy, ux], axis=1)], axis=1)    # columns: major, minor
        inv = np.stack([np.stack([d, -b], axis=1), np.stack([-b, a], axis=1)], axis=1) / (det * sc)[:, None, None]
        inv[~(det > 0)] = np.nan
    return D, np.sqrt(lam[:, ::-1]), Q, inv, lam
