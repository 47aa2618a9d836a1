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
from .exact import dot2, homogeneous_images
from .stacked import norms, project_quiet

__all__ = ["WorldFrame", "world_frame", "world_origins", "moved_cameras", "recentred", "project_world",
           "frame_centre_groups", "RECENTRE_RATIO",
           "RESOLVED_SPREAD_RTOL"]

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
        """The cameras in this frame, each divided by a power of two near its largest entry
        (:func:`moved_cameras` of a stack of one)."""
        return moved_cameras(np.asarray(cameras, float)[None], self.origin[None])[0]

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
    """The frame of the module docstring for validated cameras (N, 3, 4) (:func:`world_origins` of a stack of
    one)."""
    return WorldFrame(world_origins(np.asarray(cameras, float)[None])[0])


def world_origins(C: np.ndarray) -> np.ndarray:
    """The origin of the frame of the module docstring for each problem of a stack of validated cameras
    (M, N, 3, 4): the mean of its finite camera centres where that lies farther than ``RECENTRE_RATIO`` times
    their spread from the origin and the spread is resolved (above ``RESOLVED_SPREAD_RTOL`` times that
    distance); 0 elsewhere (fewer than two finite centres included).  The centres are the cameras' null
    vectors (:func:`tritools.model.stacked.null_vectors` of each camera divided by its largest entry)."""
    from .stacked import null_vectors

    C = np.asarray(C, float)
    M = C.shape[0]
    with np.errstate(all="ignore"):
        # each camera divided by its largest entry (|entries| <= 1, so the minors are <= 6: nothing overflows;
        # a centre is a ratio of minors, invariant to the camera's scale)
        a = null_vectors(C / np.maximum.reduce(np.abs(C).reshape(C.shape[:2] + (12,)), axis=2)[..., None, None])
        c = a[..., :3] / a[..., 3:]
        fin = np.all(np.isfinite(c), axis=2) & (a[..., 3] != 0)
        k = fin.sum(axis=1)
        mean = np.where(fin[..., None], c, 0.0).sum(axis=1) / np.maximum(k, 1)[:, None]
        dev = np.where(fin, norms(c - mean[:, None], axis=2), 0.0)
        spread = np.max(dev, axis=1, initial=0.0)
        far = norms(mean, axis=1)
        move = (k >= 2) & np.isfinite(spread) & np.isfinite(far) & (far > RECENTRE_RATIO * spread) & \
            (spread > RESOLVED_SPREAD_RTOL * far)
    return np.where(move[:, None], mean, 0.0) if M else np.zeros((0, 3))


def moved_cameras(C: np.ndarray, origins: np.ndarray) -> np.ndarray:
    """The cameras (M, N, 3, 4) in the frames X = origin_m + X' (``origins`` (M, 3), 0: not moved):
    P' = P [[I, origin], [0, 1]], each camera divided by a power of two near its largest entry before and after
    (exact).  The new last column P[:, :3] origin + P[:, 3] cancels ~log10(|origin| / spread) digits, so it is
    evaluated with error-free transformations (:func:`tritools.model.exact.dot2`: as if in twice the working
    precision, then rounded once): the moved cameras are then the caller's problem up to one rounding of each
    entry, as the caller's cameras are."""
    C = np.asarray(C, float)
    o = np.asarray(origins, float)
    with np.errstate(all="ignore"):
        C = C / power2_scale(C, (2, 3))
        moved = np.any(o != 0, axis=1)
        if not moved.any():
            return C
        C = C.copy()
        Cm = C[moved]
        Cm[..., 3] = dot2(Cm[..., :3], o[moved][:, None, None, :], Cm[..., 3])
        C[moved] = Cm / power2_scale(Cm, (2, 3))
    return C


def recentred(C: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(cameras in their re-centred frames, origins (M, 3)) of a stack (M, N, 3, 4): :func:`world_origins`
    and :func:`moved_cameras`; a point X' found in the frame is X = origin + X' (the stack itself, each camera
    divided by a power of two, where no problem moves)."""
    o = world_origins(C)
    return moved_cameras(C, o), o


def project_world(C: np.ndarray, X: np.ndarray) -> tuple:
    """:func:`tritools.model.stacked.project_stack` for evaluating estimates in the caller's frame: the
    homogeneous images P_i (X, 1) (M, N, 3) of a stack C (M, N, 3, 4), X (M, 3), recomputed by the compensated
    dot product (:func:`tritools.model.exact.dot2`) in the views where the plain sum cancels (a georeferenced
    world loses ~log10(|X| / depth) digits there), so each is accurate to a few units of round-off; decided per
    view, as :func:`tritools.model.geometry.project_homogeneous` does, so a problem gets the same numbers in any
    batch.  Then the same rule: (u (M, N, 2), h, finite (M,)).  The reported gamma_UB rests on it
    (:func:`tritools.solve.report.gamma_upper`)."""
    with np.errstate(over="ignore", invalid="ignore"):
        h = homogeneous_images(C, np.concatenate([X, np.ones((len(X), 1))], axis=1))
        return project_quiet(C, X, h=h)


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
