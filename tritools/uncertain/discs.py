"""Array entry for disc regions (uncertain keypoints): no Region objects, one stacked solve.

``uncertainty_discs(cameras, centres, radii, estimates)`` is :func:`tritools.uncertainty_many`
for regions ``Ellipse.circle(centres[m, i], radii[m, i])`` (``D = r^2 I``), built directly as stacked
:class:`~.sets.ViewBlock` arrays -- the SfM path (``tritools colmap --keypoint-radius``) calls it
for every track length.
"""
from __future__ import annotations

import numpy as np

from ..model.regions import real_array
from .api import UncertaintyOptions, UncertaintyResult, group_blocks
from .sets import ViewBlock

__all__ = ["uncertainty_discs", "disc_blocks"]


def disc_blocks(centres: np.ndarray, radii: np.ndarray) -> list[ViewBlock]:
    """Per view, the stacked discs ``||y - centre|| <= r`` as ellipses ``D = r^2 I``."""
    out = []
    eye = np.eye(2)
    for i in range(centres.shape[1]):
        r = radii[:, i]
        r2 = r * r
        out.append(ViewBlock("ellipse", centres[:, i].copy(), D=r2[:, None, None] * eye,
                             Dinv=(1.0 / r2)[:, None, None] * eye, L=(1.0 / r)[:, None, None] * eye))
    return out


def uncertainty_discs(cameras, centres, radii, estimates, options: UncertaintyOptions | None = None
                      ) -> list[UncertaintyResult]:
    """Certified uncertainty of M points seen in N views each through discs.

    cameras (M, N, 3, 4); centres (M, N, 2) pixels; radii: a number or (M, N), > 0; estimates (M, 3)
    (reference of ``max_distance`` and the solver's centre).  ``options.dilation`` is ignored (give
    the radius you mean).  Cameras are not validated here (the callers have done so)."""
    C = real_array(cameras, "cameras")
    x = real_array(centres, "centres")
    X = real_array(estimates, "estimates")
    if C.ndim != 4 or C.shape[2:] != (3, 4):
        raise ValueError(f"cameras must have shape (M, N, 3, 4), got {C.shape}")
    M, N = C.shape[:2]
    if x.shape != (M, N, 2):
        raise ValueError(f"centres must have shape ({M}, {N}, 2), got {x.shape}")
    if X.shape != (M, 3):
        raise ValueError(f"estimates must have shape ({M}, 3), got {X.shape}")
    r = np.broadcast_to(real_array(radii, "radii"), (M, N)).astype(float)
    if not (np.all(np.isfinite(r)) and np.all(r > 0)):
        raise ValueError("radii must be finite and > 0")
    if not (np.all(np.isfinite(C)) and np.all(np.isfinite(x)) and np.all(np.isfinite(X))):
        raise ValueError("cameras, centres and estimates must be finite")
    opts = options or UncertaintyOptions()
    if M == 0:
        return []
    return group_blocks(C, disc_blocks(x, r), X, X, np.zeros(M, bool), opts)
