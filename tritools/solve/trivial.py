"""The trivial lower bound gamma* >= 0, and the local estimate every result falls back on.

gamma(X) is an RMS of distances, so 0 is a lower bound of gamma* for every problem.  When an estimate X^
has gamma(X^) within the certificate tolerance of 0 -- :func:`tritools.solve.decide.decide` applied to
(c_LB, c_UB) = (0, 2N gamma'(X^)^2) in the normalised units, then confirmed on the numbers reported by
:func:`tritools.solve.decide.decide_reported` (the rule of every path, at the problem's own scale) --
X^ is a certified global minimiser (``certified_by = "trivial_bound"``) whatever the SDP did: problems
whose regions contain the projections of one point (gamma* = 0) certify even where every solver attempt
stopped short (Clarabel's "almost solved" at gamma* = 0 is common: the optimal face is degenerate).

:func:`local_estimate` is the estimate of last resort: the linear (DLT) point of the region centres in the
normalised frame (its origin, :mod:`tritools.model.normalize`) refined by Levenberg-Marquardt on the exact
distances to the regions (:func:`tritools.model.geometry.refine_l2`).  Every result other than
``invalid_input`` carries it when nothing better was found.
"""
from __future__ import annotations

import numpy as np

from ..model.geometry import gamma_validated
from ..model.geometry import refine_l2
from .decide import decide, decide_reported

__all__ = ["TRIVIAL_BOUND", "trivially_certified", "trivially_certified_reported", "local_estimate"]

#: ``certified_by`` of a certificate through the trivial lower bound 0.
TRIVIAL_BOUND = "trivial_bound"


def trivially_certified(c_upper, tolerances, n_views, resolution):
    """Does c_UB (normalised units, scalar or array) meet the trivial lower bound 0 under the rule of
    :func:`tritools.solve.decide.decide`?  False where c_UB is not finite."""
    up = np.asarray(c_upper, float)
    _, optimal, _ = decide(np.zeros_like(up), up, tolerances, n_views, resolution)
    out = np.asarray(optimal, bool) & np.isfinite(up)
    return bool(out) if out.ndim == 0 else out


def trivially_certified_reported(gamma_ub, tolerances, n_views, scale, resolution):
    """:func:`trivially_certified` on the numbers the user sees: gamma_UB in pixels against gamma_LB = 0
    (:func:`tritools.solve.decide.decide_reported`)."""
    up = np.asarray(gamma_ub, float)
    return decide_reported(np.zeros_like(up), up, tolerances, n_views, scale, resolution)


def local_estimate(cameras_n, regions_n) -> tuple[float, np.ndarray] | None:
    """(gamma'(X), X) in the normalised frame: Levenberg-Marquardt from the frame's origin (the DLT point of
    the region centres); None when the refinement fails or gamma is not finite."""
    X = refine_l2(np.zeros(3), cameras_n, regions_n)
    if X is None:
        return None
    g = float(gamma_validated(np.asarray(X, float)[None], np.asarray(cameras_n, float), regions_n)[0])   # (checked)
    return (g, X) if np.isfinite(g) else None
