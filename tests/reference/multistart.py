"""Dense multi-start local search for the L2 triangulation of image points (a reference).

Independent of ``tritools`` and of the SOS machinery: scipy's Levenberg-Marquardt on the
reprojection residuals ``Phi(X, P_i) - x_i`` from every given start; the best RMS residual
``gamma = sqrt(sum_i ||Phi(X, P_i) - x_i||^2 / (2N))`` reached is an upper bound on the
global optimum gamma*, equal to it as soon as one start lands in its basin.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

__all__ = ["best_local_gamma"]


def best_local_gamma(cameras, points2d, starts) -> float:
    """Smallest gamma reached by LM from the 3-vectors ``starts`` (inf when no run ends finite).

    Tolerances 1e-15 (xtol, ftol, gtol) and up to 2000 evaluations per run: the runs stop at
    round-off, so agreement with a certified optimum can be asked to ~1e-7 px.  A start at
    which the residual is not finite (a point on a camera's principal plane) is skipped.
    """
    cameras = np.asarray(cameras, float)
    points2d = np.asarray(points2d, float)

    def residuals(X):
        p = cameras @ np.append(X, 1.0)
        return (p[:, :2] / p[:, 2:3] - points2d).ravel()

    best = np.inf
    for start in starts:
        try:
            r = least_squares(residuals, start, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=2000)
        except ValueError:          # residuals not finite at the start
            continue
        if np.all(np.isfinite(r.fun)):
            best = min(best, float(np.sqrt(np.mean(r.fun ** 2))))
    return best
