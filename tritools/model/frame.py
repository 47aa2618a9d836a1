"""The world frame, normalised before anything is judged: georeferenced scenes and rescaled cameras.

A world frame and a camera's scale are the caller's choice; the L2 problem (SPEC §1) does not depend on
either.  Camera centres 1e7 from the origin, about 10 apart, make every test that reads the cameras'
entries -- which views share a centre, whether the normalised cameras still constrain the point -- see
the centres' common offset instead of their separation.  So the per-point path first moves the world
origin to the cameras' mean centre when it lies far outside their spread (X = origin + X'; not when the
spread is at the data's round-off).  Which views share a centre is decided in the new frame, views whose
centres differ by less than the caller's round-off (``RESOLVED_SPREAD_RTOL`` |origin|) counting as one centre
(:func:`frame_centre_groups`):
P' = P [[I, origin], [0, 1]] (each camera divided by a power of two near its largest entry, an exact
projective rescaling, so P and s P give the same numbers up to the rounding of s P itself).  The points
it finds are moved back (X = origin + X'); gamma, residuals and depths are those of the re-centred
cameras, the user's up to the projections' round-off (which the georeferenced P carries anyway: its last
column is ~|origin| times its rotation part).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .cameras import power2_scale
from .stacked import norms

__all__ = ["WorldFrame", "world_frame", "frame_centre_groups", "RECENTRE_RATIO", "RESOLVED_SPREAD_RTOL"]

#: the origin moves to the cameras' mean centre when that is farther than this many times their spread ...
RECENTRE_RATIO = 100.0
#: ... and the spread is resolved by the data: above this fraction of the centres' distance to the origin (centres
#: closer than that are one centre up to round-off, which the re-centred cameras would turn into a baseline).
RESOLVED_SPREAD_RTOL = 1e-9


@dataclass(frozen=True)
class WorldFrame:
    """X_user = origin + X (``origin`` 0: the caller's frame)."""
    origin: np.ndarray

    @property
    def moved(self) -> bool:
        return bool(np.any(self.origin != 0))

    def cameras(self, cameras: np.ndarray) -> np.ndarray:
        """The cameras in this frame, each divided by a power of two near its largest entry."""
        C = np.asarray(cameras, float)
        with np.errstate(all="ignore"):
            C = C / power2_scale(C, (1, 2))
            if self.moved:
                C = C.copy()
                C[:, :, 3] = C[:, :, :3] @ self.origin + C[:, :, 3]
                C = C / power2_scale(C, (1, 2))
        return C

    def user_point(self, X):
        return None if X is None else self.origin + np.asarray(X, float)


def _centres(cameras: np.ndarray) -> np.ndarray:
    """Finite camera centres (K, 3) from the null vectors of the cameras (rows scaled to unit norm): one batched
    SVD of the stack (the same LAPACK routine per camera as a loop of single SVDs, so the same numbers), a loop
    only when the batch fails (:func:`_centres_loop`)."""
    C = np.asarray(cameras, float)
    with np.errstate(all="ignore"):
        A = C / np.maximum(norms(C, axis=2, keepdims=True), 1e-300)
        try:
            w = np.linalg.svd(A)[2][:, -1]
        except np.linalg.LinAlgError:
            return _centres_loop(C)
        keep = (np.abs(w[:, 3]) > 1e-300) & np.isfinite(w).all(axis=1)
        c = w[keep, :3] / w[keep, 3:]
    return c[np.isfinite(c).all(axis=1)].reshape(-1, 3)


def _centres_loop(cameras: np.ndarray) -> np.ndarray:
    """:func:`_centres` camera by camera (a camera whose SVD fails is skipped)."""
    out = []
    for P in np.asarray(cameras, float):
        with np.errstate(all="ignore"):
            A = P / np.maximum(np.linalg.norm(P, axis=1, keepdims=True), 1e-300)
            try:
                w = np.linalg.svd(A)[2][-1]
            except np.linalg.LinAlgError:
                continue
            if abs(w[3]) > 1e-300 and np.all(np.isfinite(w)):
                c = w[:3] / w[3]
                if np.all(np.isfinite(c)):
                    out.append(c)
    return np.array(out).reshape(-1, 3)


def world_frame(cameras) -> WorldFrame:
    """The frame of the module docstring for validated cameras (N, 3, 4)."""
    c = _centres(cameras)
    if len(c) < 2:
        return WorldFrame(np.zeros(3))
    mean = c.mean(axis=0)
    spread = float(np.max(norms(c - mean, axis=1)))
    far = float(np.linalg.norm(mean))
    if not np.isfinite(spread) or far <= RECENTRE_RATIO * spread or spread <= RESOLVED_SPREAD_RTOL * far:
        return WorldFrame(np.zeros(3))
    return WorldFrame(mean)


def frame_centre_groups(cameras_f: np.ndarray, frame: WorldFrame) -> np.ndarray:
    """Which views share a centre, for cameras in ``frame``: the rule of
    :func:`tritools.model.constraints.centre_groups` on them, and -- when the frame moved -- views whose centres
    differ by at most ``RESOLVED_SPREAD_RTOL`` |origin| joined (a baseline at the caller's data's round-off, which
    the re-centring cannot resolve)."""
    from .constraints import centre_groups

    label = centre_groups(cameras_f)
    if not frame.moved:
        return label
    tol = RESOLVED_SPREAD_RTOL * float(np.linalg.norm(frame.origin))
    N = len(cameras_f)
    cs = [_centres(cameras_f[i:i + 1]) for i in range(N)]
    for i in range(N):
        for j in range(i + 1, N):
            if len(cs[i]) and len(cs[j]) and np.linalg.norm(cs[i][0] - cs[j][0]) <= tol:
                label[label == label[j]] = label[i]
    return label
