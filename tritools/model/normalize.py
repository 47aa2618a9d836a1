"""Data normalisation that keeps the L2 problem the same (SPEC §9).

Image side: view i is translated by its region centre t_i and **all** views are
scaled by one common factor s, x' = s (x - t_i).  A common isotropic scale
multiplies every distance by s, so gamma' = s gamma and the minimiser is
unchanged (a per-view scale would re-weight the views and change the problem).
The scale is chosen so that the unknowns are O(1) at the optimum: s = 1 / rho with
rho the RMS residual of a *locally refined* L2 estimate of the region centres (the
linear (DLT) estimate, then Levenberg-Marquardt on the reprojection residuals), an
approximation of gamma* from above, floored at ``RHO_FLOOR_REL`` times the image
coordinates' magnitude so that noise-free data does not blow the scale up.  Then
c = 2N gamma'^2 is O(1), well above the solver's absolute tolerances (shrinking
everything to O(1) pixels-per-image instead makes c ~ 1e-6 and the bounds
unreliable).

Why the refined residual and not the DLT residual: with noisy cameras the DLT
residual can exceed gamma* by two orders of magnitude (Example 5 at theta >= 0.1:
rho_DLT ~ 30-200 for gamma* ~ 1).  The unknowns are then ~1e-2 at the optimum, so
the fixed multiplier q = (1 + ||v||^2)^(delta/2 - 1) is ~1 there and the delta = 4
relaxation loses most of its strength (measured: Example 5 cases with
gamma_LB = 0.627 < gamma* = 0.653 at the DLT scale are certified at the refined
scale).  The degree-2 certificate (q = 1) is invariant under this scaling.

World side: X = X0 + d X' with X0 the DLT estimate and d the median distance to
the camera centres (an affine change of the 3D frame leaves reprojections
unchanged).  Cameras become P_i' = T_i P_i H, each scaled to unit Frobenius norm
(the overall scale of a camera does not change its projection).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import camera_center, dlt, refine_l2
from .regions import Point

__all__ = ["Normalization", "normalization_for", "RHO_FLOOR_REL", "SCALE_BOUNDS", "REFINE_TOL", "REFINE_MAX_NFEV"]

#: floor of the residual scale rho, relative to max(1, typical |centre|) of the views.
RHO_FLOOR_REL = 1e-4
#: the common image scale s is clipped to this range.
SCALE_BOUNDS = (1e-6, 1e6)
#: the local refinement that sets the scale: its tolerance and function evaluations (a few ms at most).
REFINE_TOL = 1e-10
REFINE_MAX_NFEV = 200


@dataclass(frozen=True)
class Normalization:
    scale: float
    shifts: np.ndarray      # (N, 2)
    origin: np.ndarray      # (3,)
    depth: float

    @classmethod
    def identity(cls, n_views: int) -> "Normalization":
        return cls(1.0, np.zeros((n_views, 2)), np.zeros(3), 1.0)

    def transform(self, i: int) -> np.ndarray:
        s, (tx, ty) = self.scale, self.shifts[i]
        return np.array([[s, 0.0, -s * tx], [0.0, s, -s * ty], [0.0, 0.0, 1.0]])

    def world(self) -> np.ndarray:
        H = np.eye(4)
        H[:3, :3] *= self.depth
        H[:3, 3] = self.origin
        return H

    def cameras(self, cameras: np.ndarray) -> np.ndarray:
        H = self.world()
        out = np.array([self.transform(i) @ P @ H for i, P in enumerate(cameras)])
        return out / np.linalg.norm(out, axis=(1, 2))[:, None, None]

    def regions(self, regions) -> list:
        return [r.similarity(self.scale, self.shifts[i]) for i, r in enumerate(regions)]

    def world_point(self, Xn: np.ndarray) -> np.ndarray:
        return self.origin + self.depth * np.asarray(Xn, float)

    def normalized_point(self, X: np.ndarray) -> np.ndarray:
        return (np.asarray(X, float) - self.origin) / self.depth

    def image_points(self, xn: np.ndarray) -> np.ndarray:
        return self.shifts + np.asarray(xn, float) / self.scale


def _view_distances(X: np.ndarray, cameras: np.ndarray, centers: np.ndarray) -> np.ndarray:
    """Per-view distances ||Phi(X, P_i) - centre_i|| (inf where a projection is at infinity)."""
    Xh = np.append(X, 1.0)
    res = []
    for P, c in zip(cameras, centers):
        p = P @ Xh
        res.append(np.linalg.norm(p[:2] / p[2] - c) if abs(p[2]) > 1e-300 else np.inf)
    return np.array(res)


def normalization_for(cameras: np.ndarray, regions, enabled: bool = True) -> Normalization:
    N = len(regions)
    if not enabled:
        return Normalization.identity(N)
    centers = np.array([r.center for r in regions], float)
    try:
        X0 = np.asarray(dlt(cameras, centers), float)
        if not np.all(np.isfinite(X0)):
            raise ValueError
    except (ValueError, np.linalg.LinAlgError):
        X0 = None
    rho_floor = RHO_FLOOR_REL * max(1.0, float(np.median(np.abs(centers))))
    if X0 is None:
        return Normalization(1.0, centers, np.zeros(3), 1.0)
    # image scale from the refined residual; the world frame stays at the DLT estimate (the
    # refinement may run towards a point at infinity, and a huge depth d ruins the cameras'
    # conditioning: Example 5 seed 7 case 455 had d ~ 1e8 and a bound 2e-6 above f in c units)
    X_ref = refine_l2(X0, cameras, [Point(c) for c in centers], xtol=REFINE_TOL, ftol=REFINE_TOL,
                      max_nfev=REFINE_MAX_NFEV)
    res = _view_distances(X0, cameras, centers)
    if X_ref is not None:
        res_ref = _view_distances(X_ref, cameras, centers)
        if np.sum(res_ref ** 2) < np.sum(res ** 2):          # the refined point only where it is better
            res = res_ref
    rho = float(np.sqrt(np.mean(res ** 2))) if np.all(np.isfinite(res)) else 1.0
    rho = max(rho, rho_floor)
    s = float(np.clip(1.0 / rho, *SCALE_BOUNDS))
    dists = []
    for P in cameras:
        C = camera_center(P)
        if C is not None and np.all(np.isfinite(C)):
            dists.append(np.linalg.norm(C - X0))
    d = float(np.median(dists)) if dists and np.median(dists) > 0 else 1.0
    return Normalization(s, centers, X0, d)
