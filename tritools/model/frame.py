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

import math
from dataclasses import dataclass

import numpy as np

from sospoly.budget import check_deadline

from .cameras import power2_scale
from .centres_few import null_vector_one
from .exact import (CANCELLATION_RATIO, COMPENSATED_DENOM_RTOL, EXACT_ROUNDING_RATIO, dot2, exactly_rounded,
                    homogeneous_images, two_prod, two_sum)
from .stacked import norms, project_quiet_views

__all__ = ["WorldFrame", "world_frame", "world_origins", "world_origin_one", "moved_cameras", "recentred",
           "project_world", "project_world_views", "project_world_one", "frame_centre_groups", "RECENTRE_RATIO",
           "RESOLVED_SPREAD_RTOL", "COMPENSATED_DENOM_RTOL"]

#: the origin moves to the cameras' mean centre when that is farther than this many times their spread ...
RECENTRE_RATIO = 100.0
#: ... and the spread is resolved by the data: above this fraction of the centres' distance to the origin (centres
#: closer than that are one centre up to round-off, which the re-centred cameras would turn into a baseline).  The
#: raw cameras' rule for distinct centres (:data:`tritools.model.geometry.SAME_CENTER_RTOL`, the sine of the angle
#: between homogeneous centres, ~ separation / distance) at the same level: 1e-9 joined centres 8.7e-4 apart 1.3e6
#: from the origin, which the untranslated scene certifies (review 22a F2: ``ill_posed``, its estimate 1e13 away).
RESOLVED_SPREAD_RTOL = 1e-10


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
    c, has = _view_centres(cameras)
    return c[has].reshape(-1, 3)


def _view_centres(cameras: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(centre (N, 3), has (N,)): row i is ``_centres(cameras[i:i + 1])`` where that is not empty."""
    C = np.asarray(cameras, float)
    with np.errstate(all="ignore"):
        A = C / np.maximum(norms(C, axis=2, keepdims=True), 1e-300)
        try:
            w = np.linalg.svd(A)[2][:, -1]
        except np.linalg.LinAlgError:
            rows = [_centres_loop(C[i:i + 1]) for i in range(len(C))]
            return (np.array([r[0] if len(r) else np.zeros(3) for r in rows]).reshape(-1, 3),
                    np.array([len(r) > 0 for r in rows], bool))
        keep = (np.abs(w[:, 3]) > 1e-300) & np.isfinite(w).all(axis=1)
        c = np.where(keep[:, None], w[:, :3], 0.0) / np.where(keep, w[:, 3], 1.0)[:, None]
    has = keep & np.isfinite(c).all(axis=1)
    return np.where(has[:, None], c, 0.0), has


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
    one; up to :data:`SCALAR_MAX_VIEWS` cameras its scalar twin :func:`world_origin_one`)."""
    C = np.asarray(cameras, float)
    if C.ndim == 3 and C.shape[1:] == (3, 4) and len(C) <= SCALAR_MAX_VIEWS:
        return WorldFrame(world_origin_one(C))
    return WorldFrame(world_origins(C[None])[0])


#: :func:`world_frame` takes the scalar twin :func:`world_origin_one` up to this many cameras (numpy's sum over the
#: views is sequential below 8 terms; from 8 on, its order depends on the memory layout).
SCALAR_MAX_VIEWS = 7


def world_origin_one(C: np.ndarray) -> np.ndarray:
    """The scalar twin of :func:`world_origins` for one problem's finite cameras (N, 3, 4), N <= 7: the same
    operations in the same order on Python floats (each camera divided by its largest |entry|, the null vector
    from the signed minors, the mean of the finite centres summed view by view, the norms as x^2 + y^2 + z^2), so
    bit for bit the stack's origin (tests/test_single_call_twins.py).  Returns a new (3,) array."""
    cs, rows = [], []                               # the finite centres; every view's summand (0 where not finite)
    for P in C.tolist():
        m = max(abs(v) for row in P for v in row)
        c = None
        if m > 0:                                   # (an all-zero camera, not a validated one: no centre)
            P = [[v / m for v in row] for row in P]
            a0, a1, a2, a3 = null_vector_one(P)     # (the signed minors of the stack's null_vectors, in its order)
            if a3 != 0:
                c = (a0 / a3, a1 / a3, a2 / a3)
                c = c if all(math.isfinite(v) for v in c) else None
        if c is not None:
            cs.append(c)
        rows.append(c or (0.0, 0.0, 0.0))
    k = len(cs)
    if k < 2:
        return np.zeros(3)
    sx, sy, sz = rows[0]
    for x, y, z in rows[1:]:                        # np.sum over the views: in view order from the first
        sx, sy, sz = sx + x, sy + y, sz + z
    mean = (sx / k, sy / k, sz / k)
    spread = 0.0
    for c in cs:
        dx, dy, dz = c[0] - mean[0], c[1] - mean[1], c[2] - mean[2]
        dev = math.sqrt(dx * dx + dy * dy + dz * dz)
        if not math.isfinite(dev):
            return np.zeros(3)                      # the spread is not finite: no move
        spread = max(spread, dev)
    far = math.sqrt(mean[0] * mean[0] + mean[1] * mean[1] + mean[2] * mean[2])
    move = math.isfinite(far) and far > RECENTRE_RATIO * spread and spread > RESOLVED_SPREAD_RTOL * far
    return np.array(mean) if move else np.zeros(3)


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
    u, h, defined = project_world_views(C, X)
    return u, h, defined.all(axis=1)


def project_world_views(C: np.ndarray, X: np.ndarray) -> tuple:
    """:func:`project_world` with its rule per view (:func:`tritools.model.stacked.project_quiet_views`): (u (M, N,
    2), h, defined (M, N))."""
    with np.errstate(over="ignore", invalid="ignore"):
        h = homogeneous_images(C, np.concatenate([X, np.ones((len(X), 1))], axis=1))
        return project_quiet_views(C, X, h=h, rtol=COMPENSATED_DENOM_RTOL)


def project_world_one(C: list, X: list, absC: list | None = None) -> tuple:
    """The scalar twin of :func:`project_world` for one point: cameras C (N lists of 3 rows of 4 floats), X (3
    floats) -> (u (N pairs), defined (N bools), the rule per view of :func:`project_world_views`); ``absC`` the
    cameras' |entries| when the caller has them.  The same numbers
    bit for bit (tests/test_single_call_twins.py): each homogeneous coordinate as numpy's einsum sums four
    products, (p_0 + p_2) + (p_1 + p_3); a view recomputed by the compensated dot product
    (:func:`tritools.model.exact.dot2`'s steps, the plain sum where it is not finite) where some row's sum of
    |products| exceeds CANCELLATION_RATIO times |sum|; then the rule of :func:`tritools.model.stacked.project_quiet`
    (its |P_3| . |X~| is that sum of |products| of the third row)."""
    x0, x1, x2 = X
    a0, a1, a2 = abs(x0), abs(x1), abs(x2)
    u, defined = [], []
    for P, A in zip(C, absC or [[[abs(v) for v in row] for row in P] for P in C]):
        h = [_dot4(r, (x0, x1, x2, 1.0)) for r in P]
        mag = [_dot4(r, (a0, a1, a2, 1.0)) for r in A]
        if not (mag[0] <= CANCELLATION_RATIO * abs(h[0]) and mag[1] <= CANCELLATION_RATIO * abs(h[1])
                and mag[2] <= CANCELLATION_RATIO * abs(h[2])):
            h = [_dot2_one(r, (x0, x1, x2, 1.0)) for r in P]
        den = h[2]
        if abs(den) <= COMPENSATED_DENOM_RTOL * mag[2]:
            u.append((h[0] / 1.0, h[1] / 1.0))
            defined.append(False)
            continue
        ui = (h[0] / den, h[1] / den)
        defined.append(math.isfinite(ui[0]) and math.isfinite(ui[1]))
        u.append(ui)
    return u, defined


def _dot4(a, x) -> float:
    """sum_k a_k x_k of four terms in numpy einsum's order, (p_0 + p_2) + (p_1 + p_3)."""
    return (a[0] * x[0] + a[2] * x[2]) + (a[1] * x[1] + a[3] * x[3])


def _dot2_one(a, x) -> float:
    """:func:`tritools.model.exact.dot2` of one row (b = 0) on floats: the same operations, in its order, and the same
    exact rounding where more than 40 bits cancel (:func:`tritools.model.exact.exactly_rounded`)."""
    s, c, S = 0.0, 0.0, 0.0
    parts = []
    for ak, xk in zip(a, x):
        p, ep = two_prod(ak, xk)
        s, es = two_sum(s, p)
        c = c + (ep + es)
        S = S + abs(p)
        parts.append((p, ep))
    out = s + c
    if not math.isfinite(out):
        out = _dot4(a, x) + 0.0
    if math.isfinite(out) and S > EXACT_ROUNDING_RATIO * abs(out):
        out = exactly_rounded(0.0, [p for p, _ in parts], [ep for _, ep in parts], out)
    return out


def frame_centre_groups(cameras_f: np.ndarray, frame: WorldFrame) -> np.ndarray:
    """Which views share a centre, for cameras in ``frame``: the rule of
    :func:`tritools.model.constraints.centre_groups` on them, and -- when the frame moved -- views whose centres
    differ by at most ``RESOLVED_SPREAD_RTOL`` |origin| joined (a baseline at the caller's data's round-off, which
    the re-centring cannot resolve)."""
    from .centres import merged_labels
    from .constraints import centre_groups

    label = centre_groups(cameras_f)
    if not frame.moved:
        return label
    tol = RESOLVED_SPREAD_RTOL * float(np.linalg.norm(frame.origin))
    return merged_labels(len(label), _close_pairs(*_view_centres(cameras_f), tol), label)


#: pairs per block of :func:`_close_pairs` (memory bounded at any N).
CLOSE_PAIR_BLOCK = 2 ** 16


def _close_pairs(c: np.ndarray, has: np.ndarray, tol: float) -> list:
    """The pairs i < j (combinations order) of views with centres whose distance ``np.linalg.norm(c_i - c_j)`` (the
    same numbers: :func:`~tritools.model.centres.dot_norms`) is at most ``tol``, in blocks of rows."""
    from .centres import dot_norms

    N = len(c)
    rows = max(1, CLOSE_PAIR_BLOCK // max(N, 1))
    out = []
    for i0 in range(0, N, rows):
        check_deadline("comparing the camera centres")
        i = np.arange(i0, min(N, i0 + rows))[:, None]
        j = np.arange(N)[None, :]
        I, J = np.nonzero((i < j) & has[i] & has[j])
        I, J = I + i0, J
        close = dot_norms(c[I] - c[J]) <= tol
        out += zip(I[close].tolist(), J[close].tolist())
    return out
