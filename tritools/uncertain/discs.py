"""Array entry for disc regions (uncertain keypoints): no Region objects, one stacked solve.

``uncertainty_discs(cameras, centres, radii, estimates)`` is :func:`tritools.uncertainty_many`
for regions ``Ellipse.circle(centres[m, i], radii[m, i])`` (``D = r^2 I``), built directly as stacked
:class:`~.sets.ViewBlock` arrays -- the SfM path (``tritools colmap --keypoint-radius``) calls it
for every track length.
"""
from __future__ import annotations

import numpy as np

from ..model.regions import real_array
from ..model.stacked import dlt_stack, null_vectors, project_stack
from .api import UncertaintyOptions, UncertaintyResult, group_blocks
from .sets import ViewBlock

__all__ = ["uncertainty_discs", "disc_blocks"]


def disc_blocks(centres: np.ndarray, radii: np.ndarray) -> list[ViewBlock]:
    """Per view, the stacked discs ``||y - centre|| <= r`` as ellipses ``D = r^2 I`` (diagonal matrices built by
    their diagonals: r^2 = inf for r > 1e154 stays off the zeros, where inf * 0 made NaN)."""
    out = []
    for i in range(centres.shape[1]):
        r = np.asarray(radii[:, i], float)
        with np.errstate(over="ignore", divide="ignore"):
            r2 = r * r
            out.append(ViewBlock("ellipse", centres[:, i].copy(), D=_diagonal(r2), Dinv=_diagonal(1.0 / r2),
                                 L=_diagonal(1.0 / r)))
    return out


def _diagonal(v: np.ndarray) -> np.ndarray:
    """(M, 2, 2) diagonal matrices v_m I."""
    out = np.zeros((len(v), 2, 2))
    out[:, 0, 0] = out[:, 1, 1] = v
    return out


def uncertainty_discs(cameras, centres, radii, estimates, options: UncertaintyOptions | None = None
                      ) -> list[UncertaintyResult]:
    """Certified uncertainty of M points seen in N views each through discs.

    cameras (M, N, 3, 4); centres (M, N, 2) pixels; radii: a number or (M, N), > 0; estimates (M, 3)
    (reference of ``max_distance``; the solver's centre where it reprojects onto the discs at least as
    closely as the DLT of their centres: :func:`solver_centres`).  ``options.dilation`` is ignored (give
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
    return group_blocks(C, disc_blocks(x, r), solver_centres(C, x, r, X), X, np.zeros(M, bool), opts)


#: :func:`solver_centres` replaces the caller's estimate by the DLT where it is this many times farther from the discs
FAR_ESTIMATE = 2.0


def solver_centres(C: np.ndarray, x: np.ndarray, r: np.ndarray, X: np.ndarray) -> np.ndarray:
    """The solver's centre per point (M, 3): the caller's estimate X, or the DLT of the disc centres (solved in a
    world moved to the mean camera centre, so that georeferenced coordinates do not drown it) where X lies outside
    a disc and :data:`FAR_ESTIMATE` times farther from the discs than the DLT -- by max_i ||Phi(., P_i) -
    centre_i|| / r_i.

    The bounds hold from any centre, but the Farkas and dual steps are solved in (X - X0) / sigma: a centre far
    from the set (a stale or default estimate, 1e8 away: boxes 2x wider, 1e10: 8x) loosens them and a local
    verdict is taken far from the set (review 26b F1/F5, which :func:`~tritools.uncertain.api.uncertainty_many`
    answers by always centring on the DLT).  Here the callers' estimates are usually their L2 optima, on or near
    the discs: they are kept (and with them the SfM path's results), and only a clearly worse one is replaced."""
    a = null_vectors(C)                                           # camera centres (homogeneous), (M, N, 4)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        cen = a[..., :3] / a[..., 3:]
        ok = np.isfinite(cen).all(axis=(1, 2))
        c0 = np.where(ok[:, None], np.mean(np.where(ok[:, None, None], cen, 0.0), axis=1), 0.0)
        Cc = C.copy()
        Cc[..., 3] = C[..., 3] + np.einsum("mnij,mj->mni", C[..., :3], c0)
        Xd, good = dlt_stack(Cc, x)
        Xd = Xd + c0
        good &= np.isfinite(Xd).all(axis=1)
        d_own, d_dlt = _disc_distance(C, x, r, X), _disc_distance(C, x, r, np.where(good[:, None], Xd, X))
    far = (d_own > 1.0) & (d_own > FAR_ESTIMATE * d_dlt)
    return np.where((good & far)[:, None], Xd, X)


def _disc_distance(C: np.ndarray, x: np.ndarray, r: np.ndarray, X: np.ndarray) -> np.ndarray:
    """max_i ||Phi(X_m, P_mi) - x_mi|| / r_mi per point (M,), inf where a projection is not finite."""
    u, _, fin = project_stack(C, X)
    d = np.max(np.linalg.norm(u - x, axis=2) / r, axis=1)
    return np.where(fin & np.isfinite(d), d, np.inf)
