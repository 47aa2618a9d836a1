"""The vectorised model path: options, per-camera geometry, and one chunk of points at a time.

:func:`prepare_geometry` works per camera and per image, once per model: the pinhole matrices
``P = K [R | t]`` of every image, and every keypoint that belongs to a track undistorted with one
numpy call per camera (:func:`tritools.io.colmap.camera_models.undistorted_pixels`).  A camera whose
model tritools cannot undistort (EQUIRECTANGULAR; pycolmap-only models without pycolmap) or whose parameters are invalid
(focal length <= 0) is *skipped*: its observations are left out of every track (a count and the
camera's reason go to the report), unless ``strict`` (then :class:`CameraError`).  So is an image whose
``K [R | t]`` is not a camera (:func:`image_problems`: not finite -- huge intrinsics or pose that overflow -- or rank
< 3 by the one camera rule), reported per image.

:func:`process_chunk` then handles a :class:`~tritools.io.colmap.arrays.PointChunk`: tracks are
grouped by their number N of usable observations, each group becomes stacked arrays (cameras
(M, N, 3, 4), undistorted points (M, N, 2)) for :func:`.certify.certify_stack`; gamma of the input
point, the depth of every observation (cheirality), the written xyz and COLMAP's mean reprojection
error (full distortion model) are computed with numpy over the whole chunk.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from types import SimpleNamespace

import numpy as np

from ..io.colmap.arrays import ModelArrays, PointChunk
from ..io.colmap.camera_models import (OPENCV_FAMILY, camera_problem, distort_rows, distortion, intrinsics,
                                       pixels_from_camera, undistorted_pixels)
from ..model.cameras import CAMERA_RANK_RTOL, camera_rank_ratio, depths_stack
from ..records import TriangulationResults
from ..result import Status
from ..solve.batch import executor_problem
from ..solve.decide import gamma_from_c
from ..solve.options import OptionError, TriangulationOptions
from .local_frame import local_translations, model_origin
from .certify import CertifyOptions, RecordColumns, certify_stack, robust_threshold, solver_options

__all__ = ["RetriangulationOptions", "OptionError", "CameraError", "ModelGeometry", "prepare_geometry",
           "ChunkResult", "process_chunk", "point_gammas", "rotations", "image_problems", "BEHIND_CHOICES",
           "DEFAULT_MAX_TRACK_LENGTH"]

BEHIND_CHOICES = ("keep-input", "write")
#: tracks with more usable observations than this are not solved by default: the Corollary 1
#: certificate has N(N-1)/2 constraints in 2N variables, so its cost grows as N^4.
DEFAULT_MAX_TRACK_LENGTH = 50


class CameraError(ValueError):
    """A camera that cannot be used, under ``strict=True``; the message names the camera and its
    place in the files."""


def _int_option(name, value, low):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
        raise OptionError(name, f"must be an integer >= {low}, got {value!r}")


@dataclass(frozen=True, init=False)
class RetriangulationOptions:
    """Settings of the model path (all validated on construction, :class:`OptionError` naming the field).

    solver
        The :class:`~tritools.solve.options.TriangulationOptions` of every point (None: the defaults of
        ``tritools.triangulate`` -- method auto, path auto, the default per-point budget of 60 s and
        2 GiB, no whole-call limit); ``tritools colmap`` builds it from the same flags as ``tritools solve``.
        Its ``total_time_limit`` bounds the whole run: the points not solved when it expires get status
        ``time_limit`` (and keep their input xyz).
    method, path, delta, max_delta
        Constructor shorthands for the solver's fields (None: the solver's value; read back as properties
        of ``solver``): method "auto" (Corollary 1 at delta = 2, then delta = 4 for the points that does
        not certify), "corollary1" or "theorem1"; path "auto" (certification by verification first, the SDP
        for the rest) or "sdp"; first and last relaxation degree (even, >= 2, ``max_delta >= delta``).
        ``max_delta=2`` keeps every point at delta = 2 (no escalation); higher degrees are bounded per point
        by the solver's budget (status ``time_limit`` / ``budget_exceeded`` when they do not fit).
    min_track_length, max_track_length
        Tracks with fewer / more usable observations are not solved (status invalid_input).
    behind
        "keep-input" (default): a point whose estimate lies behind one of its cameras keeps its
        input xyz; "write": it is written anyway.  Either way it is flagged (in_front = False,
        not certified) in the report.
    strict
        Raise :class:`CameraError` for an unusable camera instead of skipping its observations.
    chunk_points, progress, executor
        Points per chunk (bounds memory); a tqdm bar over the whole run, moved per stack of equal track
        lengths (None / False: never, the library's default; "auto": from ``PROGRESS_MIN_POINTS`` points on,
        the command line's default; True: always); executor of the per-point SDPs.
    robust
        None, or a threshold in undistorted pixels: certified truncated least squares
        (:mod:`tritools.solve.robust`); the outlier observations of every updated point are removed from its
        track (and their keypoints' POINT3D_ID set to -1 by the writer).
    """
    solver: TriangulationOptions
    min_track_length: int
    max_track_length: int
    behind: str
    strict: bool
    chunk_points: int
    progress: bool | str | None
    executor: object = field(compare=False)
    robust: float | None

    def __init__(self, method: str | None = None, path: str | None = None, delta: int | None = None,
                 max_delta: int | None = None, min_track_length: int = 2,
                 max_track_length: int = DEFAULT_MAX_TRACK_LENGTH, behind: str = "keep-input", strict: bool = False,
                 chunk_points: int = 100_000, progress: bool | str | None = None, executor: object = None,
                 solver: TriangulationOptions | None = None, robust: float | None = None):
        set_ = object.__setattr__
        set_(self, "solver", solver_options(solver, "solver", method=method, path=path, delta=delta,
                                            max_delta=max_delta))
        for name, value in (("min_track_length", min_track_length), ("max_track_length", max_track_length),
                            ("behind", behind), ("strict", strict), ("chunk_points", chunk_points),
                            ("progress", progress), ("executor", executor), ("robust", robust)):
            set_(self, name, value)
        self._check()

    def _check(self) -> None:
        _int_option("min_track_length", self.min_track_length, 2)
        _int_option("max_track_length", self.max_track_length, 2)
        if self.max_track_length < self.min_track_length:
            raise OptionError("max_track_length", f"must be >= min_track_length ({self.min_track_length}), "
                                                  f"got {self.max_track_length}")
        if self.behind not in BEHIND_CHOICES:
            raise OptionError("behind", f"must be one of {', '.join(BEHIND_CHOICES)}, got {self.behind!r}")
        if not isinstance(self.strict, (bool, np.bool_)):       # ("no" is truthy: it turned strict mode on)
            raise OptionError("strict", f"must be True or False, got {self.strict!r}")
        _int_option("chunk_points", self.chunk_points, 1)
        if self.progress is not None and self.progress != "auto" and not isinstance(self.progress, (bool, np.bool_)):
            raise OptionError("progress", f"must be True, False, None or 'auto', got {self.progress!r}")
        why = executor_problem(self.executor)
        if why:
            raise OptionError("executor", why)
        object.__setattr__(self, "robust", robust_threshold(self.robust))

    method = property(lambda self: self.solver.method.value, doc="the solver's method (a string)")
    path = property(lambda self: self.solver.path.value, doc="the solver's path (a string)")
    delta = property(lambda self: self.solver.delta, doc="the solver's first degree (None: delta_min)")
    max_delta = property(lambda self: self.solver.max_delta, doc="the solver's last degree (None: the plan's)")

    def certify_options(self) -> CertifyOptions:
        """The solver settings of :func:`.certify.certify_stack` (the ``solver`` options and the executor)."""
        return CertifyOptions(options=self.solver, executor=self.executor, robust=self.robust)


@dataclass(frozen=True, eq=False)
class ModelGeometry:
    """Per-model arrays of the fast path (see :func:`prepare_geometry`)."""
    camera_reason: tuple          # None, or why camera k cannot be used
    image_ok: np.ndarray          # (V,) the image's camera is usable
    R: np.ndarray                 # (V, 3, 3) cam_from_world rotations
    t: np.ndarray                 # (V, 3)
    P: np.ndarray                 # (V, 3, 4) K [R | t] (zeros for unusable cameras)
    focal: np.ndarray             # (V, 2) fx, fy of the image's camera
    centre: np.ndarray            # (V, 2) cx, cy
    dist: np.ndarray              # (V, 4) k1, k2, p1, p2 (OPENCV family; other models: zeros, unused)
    xy_u: np.ndarray              # (K, 2) undistorted keypoints (NaN where not computed)
    kp_ok: np.ndarray             # (K,) undistortion converged
    perspective: np.ndarray       # (V,) the image's camera sees only in front of it (False: spherical, no depth test)
    image_reason: tuple = ()      # None, or why image v cannot be used although its camera can (image_problems)
    origin: np.ndarray | None = None      # c of the local frame of a georeferenced model (:mod:`.local_frame`)
    P_local: np.ndarray | None = None     # (V, 3, 4) K [R | t + R(q) c], exact t_c rounded once (with ``origin``)

    def certified_frame(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(cameras (V, 3, 4), X (..., 3)) in the frame certificates are computed in: the local frame of a
        georeferenced model (``P_local``, X - ``origin``; :mod:`.local_frame`), else the model's own."""
        return (self.P, X) if self.origin is None else (self.P_local, X - self.origin)


def rotations(qvec: np.ndarray) -> np.ndarray:
    """Rotation matrices (V, 3, 3) of Hamilton quaternions (V, 4), w first (normalised first: divided by the power of
    two of their largest entry, exact, so that |q|^2 neither underflows nor overflows; review 50a F5)."""
    q = qvec / 2.0 ** np.frexp(np.max(np.abs(qvec), axis=1, keepdims=True))[1]
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
                     np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
                     np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], 1)


def _perspective_images(arrays: ModelArrays) -> np.ndarray:
    """(V,) True where the image's camera model is a perspective one (it sees only in front of its z = 0 plane);
    False for :data:`~tritools.io.colmap.lens.NON_PERSPECTIVE_MODELS` (a sphere)."""
    from ..io.colmap.lens import NON_PERSPECTIVE_MODELS

    spherical = np.array([m in NON_PERSPECTIVE_MODELS for m in arrays.camera_models], bool)
    return ~spherical[arrays.image_camera] if len(spherical) else np.ones(arrays.n_images, bool)


def prepare_geometry(arrays: ModelArrays, strict: bool = False) -> ModelGeometry:
    """Pinhole cameras of every image and every track keypoint undistorted (one call per camera)."""
    C, V = arrays.n_cameras, arrays.n_images
    reasons = tuple(camera_problem(m, p) for m, p in zip(arrays.camera_models, arrays.camera_params))
    used = np.zeros(C, bool)
    used[arrays.image_camera] = True
    if strict:
        for k in np.nonzero(used)[0]:
            if reasons[k] is not None:
                raise CameraError(f"{arrays.camera_source(k)}: camera {int(arrays.camera_ids[k])} "
                                  f"({arrays.camera_models[k]}) cannot be used: {reasons[k]}")
    Ks = np.zeros((C, 3, 3))
    dists = np.zeros((C, 4))
    for k in range(C):
        if reasons[k] is None:
            Ks[k] = intrinsics(arrays.camera_models[k], arrays.camera_params[k])
            if arrays.camera_models[k] in OPENCV_FAMILY:          # other models: ERROR via their own map
                dists[k] = distortion(arrays.camera_models[k], arrays.camera_params[k])
    R = rotations(arrays.image_qvec) if V else np.zeros((0, 3, 3))
    t = arrays.image_tvec
    Rt = np.concatenate([R, t[:, :, None]], axis=2)
    cam = arrays.image_camera
    with np.errstate(all="ignore"):             # huge intrinsics or poses: image_problems names them
        P = np.matmul(Ks[cam], Rt)
    cam_ok = np.array([r is None for r in reasons], bool)
    image_ok = cam_ok[cam] if V else np.zeros(0, bool)
    image_reason = image_problems(P, image_ok)
    if strict:
        for v, why in enumerate(image_reason):
            if why is not None:
                raise CameraError(f"image {int(arrays.image_ids[v])} ({arrays.image_names[v]}) cannot be used: {why}")
    image_ok = image_ok & np.array([r is None for r in image_reason], bool)
    counts = np.diff(arrays.kp_offsets)
    kp_cam = np.repeat(cam, counts)
    need = (arrays.kp_point3D != -1) & cam_ok[kp_cam] if len(kp_cam) else np.zeros(0, bool)
    xy_u = np.full(arrays.kp_xy.shape, np.nan)
    kp_ok = np.zeros(len(arrays.kp_xy), bool)
    rows = np.nonzero(need)[0]
    rows = rows[np.argsort(kp_cam[rows], kind="stable")]           # the needed keypoints, camera by camera
    bounds = np.searchsorted(kp_cam[rows], np.arange(C + 1))
    for k in np.nonzero(cam_ok)[0]:
        r = rows[bounds[k]:bounds[k + 1]]
        if r.size:
            xy_u[r], kp_ok[r] = undistorted_pixels(arrays.camera_models[k], arrays.camera_params[k], arrays.kp_xy[r])
    origin = model_origin(R, t, image_ok) if V else None
    P_local = None
    if origin is not None:           # a georeferenced model: certified about its cameras' centre (.local_frame)
        t_c = local_translations(arrays.image_qvec, t, origin)
        with np.errstate(all="ignore"):
            P_local = np.matmul(Ks[cam], np.concatenate([R, t_c[:, :, None]], axis=2))
    return ModelGeometry(reasons, image_ok, R, t, P, np.column_stack([Ks[cam, 0, 0], Ks[cam, 1, 1]]),
                         np.column_stack([Ks[cam, 0, 2], Ks[cam, 1, 2]]), dists[cam], xy_u, kp_ok,
                         _perspective_images(arrays), image_reason, origin, P_local)


def _posed(geom: ModelGeometry) -> np.ndarray:
    """(V,) False for the images :func:`image_problems` skips: their K [R | t] gives no depth to judge cheirality by
    (a skipped camera's image keeps its pose: its observations are judged)."""
    return np.array([why is None for why in geom.image_reason], bool) if geom.image_reason else \
        np.ones(len(geom.image_ok), bool)


def image_problems(P: np.ndarray, ok: np.ndarray) -> tuple:
    """Why each image's ``P = K [R | t]`` (V, 3, 4) cannot be used, None where it can or where ``ok`` is False (its
    camera is skipped already): not finite (intrinsics or a translation so large that the product overflows), or
    rank < 3 by the rule every camera of a problem meets (:func:`tritools.model.cameras.camera_rank_ratio`).  Such an
    image's observations are left out of the tracks, as a skipped camera's, instead of failing every point it sees
    with a message about a track-local ``cameras[k]`` (review 29b F8)."""
    with np.errstate(all="ignore"):
        finite = np.isfinite(P).all(axis=(1, 2))
        ratio = np.ones(len(P))
        sel = np.asarray(ok, bool) & finite
        if sel.any():
            ratio[sel] = camera_rank_ratio(P[sel])
    return tuple(None if not ok[v] else
                 "K [R | t] is not finite (its intrinsics or pose overflow in floating point)" if not finite[v] else
                 f"K [R | t] has rank < 3 (sigma3/sigma1 = {ratio[v]:.3g} <= {CAMERA_RANK_RTOL:g})"
                 if not ratio[v] > CAMERA_RANK_RTOL else None for v in range(len(P)))


@dataclass(frozen=True, eq=False)
class ChunkResult(RecordColumns):
    """One processed chunk (see :class:`~.retriangulate.RetriangulationReport`): the solver's batch record
    ``results`` of its points (status ``invalid_input`` for the tracks not solved, ``in_front`` the cheirality of
    the written point, the messages; read as SfM columns through :class:`~.certify.RecordColumns`), and per point
    the written ``xyz`` and ``error``, ``gamma_input`` and ``updated``."""
    results: TriangulationResults
    xyz: np.ndarray
    error: np.ndarray
    gamma_input: np.ndarray
    updated: np.ndarray
    n_skipped_observations: int = 0
    keep_obs: np.ndarray | None = None        # (chunk observations,) False: an outlier removed (``robust``)
    n_inliers: np.ndarray | None = None       # (points,) inliers of the robust estimate (-1: not robust)
    removed: np.ndarray | None = None         # (K, 3) (point in the chunk, image id, keypoint) removed (``robust``)


#: columns of the solver's record a chunk does not keep (per-view arrays, steps): a model's report stays small.
DROPPED_COLUMNS = ("image_points", "depths", "residuals", "inliers", "attempts", "timings", "X_raw", "gamma_ub_raw",
                   "n_lmivar", "sparsity")


def _gamma(C: np.ndarray, x: np.ndarray, X: np.ndarray, c: float | None = None) -> np.ndarray:
    """gamma (SPEC §1) of points X (M, 3) for stacks C (M, N, 3, 4), x (M, N, 2); inf at infinity.  With a
    threshold ``c`` (pixels), the TLS gamma sqrt(sum_i min(d_i^2, c^2) / 2N) of :mod:`tritools.solve.robust`
    instead: the number a robust estimate's gamma_UB is compared with (a view at infinity then costs c^2)."""
    h = np.einsum("mnij,mj->mni", C, np.concatenate([X, np.ones((len(X), 1))], axis=1))
    den = h[..., 2]
    tiny = ~(np.abs(den) > 1e-300) | ~np.all(np.isfinite(h), axis=2)
    proj = h[..., :2] / np.where(tiny, 1.0, den)[..., None]
    d2 = np.sum((proj - x) ** 2, axis=2)
    if c is not None:
        d2 = np.where(tiny, c * c, np.minimum(d2, c * c))
        return gamma_from_c(np.sum(d2, axis=1), x.shape[1], 1.0)
    g = gamma_from_c(np.sum(d2, axis=1), x.shape[1], 1.0)
    return np.where(np.any(tiny, axis=1), np.inf, g)


def point_gammas(arrays: ModelArrays, geom: ModelGeometry, xyz: np.ndarray | None = None) -> np.ndarray:
    """gamma (SPEC §1, undistorted pixels) of every point of ``arrays`` (or of ``xyz`` (P, 3) for its
    tracks) over its usable observations; NaN for points without any, inf at infinity."""
    X = arrays.point_xyz if xyz is None else np.asarray(xyz, float)
    owner = np.repeat(np.arange(arrays.n_points), np.diff(arrays.track_offsets))
    use = geom.image_ok[arrays.track_image]
    img, own = arrays.track_image[use], owner[use]
    gk = arrays.kp_offsets[img] + arrays.track_kp[use]
    P, X = geom.certified_frame(X)
    h = np.einsum("tij,tj->ti", P[img], np.concatenate([X[own], np.ones((len(own), 1))], axis=1))
    with np.errstate(all="ignore"):
        r2 = np.sum((h[:, :2] / h[:, 2:3] - geom.xy_u[gk]) ** 2, axis=1)
        n = np.bincount(own, minlength=arrays.n_points)
        return gamma_from_c(np.bincount(own, weights=r2, minlength=arrays.n_points), n, 1.0)


def _colmap_error(arrays, geom, X, obs_img, gk, owner, n) -> np.ndarray:
    """COLMAP's ERROR: mean over the observations of |pi(X) - x| in recorded pixels (full camera model).  An
    observation whose camera has X behind it (written with ``behind="write"``) has no distorted projection (COLMAP's
    own is NaN or garbage there: review 30a F6, ERROR NaN for EUCM, 4e5 px for DIVISION): it counts with its
    pinhole residual, K (X_c / z) against the undistorted keypoint -- the residual the certificate is about."""
    Xc = np.einsum("tij,tj->ti", geom.R[obs_img], X[owner]) + geom.t[obs_img]
    cam = arrays.image_camera[obs_img]
    opencv = np.array([m in OPENCV_FAMILY for m in arrays.camera_models], bool)[cam]
    with np.errstate(all="ignore"):
        uv = distort_rows(Xc[:, :2] / Xc[:, 2:3], geom.dist[obs_img])
        px = geom.focal[obs_img] * uv + geom.centre[obs_img]
        for k in np.unique(cam[~opencv]):                      # the other models: one call per camera
            sel = cam == k
            px[sel] = pixels_from_camera(arrays.camera_models[k], arrays.camera_params[k], Xc[sel])
        e = np.hypot(*(px - arrays.kp_xy[gk]).T)
        behind = ~(Xc[:, 2] > 0)
        if behind.any():
            pin = geom.focal[obs_img[behind]] * Xc[behind, :2] / Xc[behind, 2:3] + geom.centre[obs_img[behind]]
            e[behind] = np.hypot(*(pin - geom.xy_u[gk[behind]]).T)
    return np.bincount(owner, weights=e, minlength=n) / np.maximum(np.bincount(owner, minlength=n), 1)


def _solve_stacks(geom: ModelGeometry, chunk: PointChunk, options: RetriangulationOptions, d: dict, progress):
    """The solver's record of every point of the chunk (stacks of equal usable track length through
    :func:`.certify.certify_stack`; ``invalid_input`` rows for the tracks not solved), the outlier observations,
    the inlier counts (-1: not robust) and gamma of the input points."""
    n, n_used, solve = len(chunk), d["n_used"], d["solve"]
    used_obs = np.nonzero(d["usable"])[0]                 # CSR of the usable observations
    used_off = np.concatenate([[0], np.cumsum(n_used)])
    skip = np.nonzero(~solve)[0]
    parts = [TriangulationResults(method=[options.solver.method.value] * skip.size,
                                  status=[Status.INVALID_INPUT] * skip.size, n_views=n_used[skip])]
    order = [skip]
    outlier = np.zeros(len(d["obs_img"]), bool)
    n_inl = np.full(n, -1, np.int32)
    gamma_input = np.full(n, np.nan)
    copts = options.certify_options()
    for N in np.unique(n_used[solve]):
        pts = np.nonzero(solve & (n_used == N))[0]
        o = used_obs[used_off[pts][:, None] + np.arange(N)]
        P, xyz_in = geom.certified_frame(chunk.xyz[pts])         # a georeferenced model: Y = X - c (.local_frame)
        C, x = P[d["obs_img"][o]], geom.xy_u[d["gk"][o]]
        s = certify_stack(C, x, copts)
        if s.inliers is not None:
            outlier[o[~s.inliers]] = True
            n_inl[pts] = s.inliers.sum(axis=1)
        part = s.results.drop(*DROPPED_COLUMNS)
        parts.append(part if geom.origin is None or part.X is None else replace(part, X=part.X + geom.origin))
        order.append(pts)
        with np.errstate(all="ignore"):
            g = _gamma(C, x, xyz_in, options.robust)      # TLS gamma with robust: comparable
        gamma_input[pts] = np.where(np.isfinite(g), g, np.nan)
        if progress is not None:
            progress.update(len(pts))
    rec = TriangulationResults.concat(parts).take(np.argsort(np.concatenate(order), kind="stable"))
    # every row counts the track's usable observations (a row refused by the solver said 0: review 30a F8)
    return replace(rec, n_views=np.asarray(n_used, np.int64)), outlier, n_inl, gamma_input


def process_chunk(arrays: ModelArrays, geom: ModelGeometry, chunk: PointChunk, options: RetriangulationOptions,
                  progress=None) -> ChunkResult:
    """Re-triangulate the points of ``chunk`` (see the module docstring)."""
    n = len(chunk)
    owner = np.repeat(np.arange(n), chunk.track_lengths)
    obs_img = chunk.track_image
    gk = arrays.kp_offsets[obs_img] + chunk.track_kp
    usable = geom.image_ok[obs_img]
    n_used = np.bincount(owner[usable], minlength=n)
    stuck = np.bincount(owner[usable & ~geom.kp_ok[gk]], minlength=n) > 0
    solve = (n_used >= options.min_track_length) & (n_used <= options.max_track_length) & ~stuck
    rec, outlier, n_inl, gamma_input = _solve_stacks(geom, chunk, options, dict(
        n_used=n_used, solve=solve, usable=usable, obs_img=obs_img, gk=gk), progress)
    X = rec.X
    # cheirality: depth of every observation of the track (skipped cameras included) of the
    # estimate, or of the input point where there is none
    has_X = np.all(np.isfinite(X), axis=1)
    test = np.where(has_X[:, None], X, chunk.xyz)
    # (the one depth rule, tritools.model.cameras; a COLMAP frame is right-handed: [R | t] with det R = +1)
    Rt = np.concatenate([geom.R, geom.t[:, :, None]], axis=2)
    depth = depths_stack(Rt[obs_img][:, None], test[owner])[:, 0]
    # cheirality on the observations the estimate keeps: a robust estimate's outliers may lie "behind" their
    # camera (docs/robust.md), as triangulate(..., robust=c) judges in_front; a spherical camera
    # (EQUIRECTANGULAR) sees every direction, so its observations have no side to be behind (review 27a F2)
    judged = ~outlier & geom.perspective[obs_img] & _posed(geom)[obs_img]
    behind = np.bincount(owner[~(depth > 0) & judged], minlength=n) > 0
    ub, g_in = rec.gamma_ub, gamma_input
    better = has_X & np.isfinite(ub) & (rec.optimal | ~np.isfinite(g_in) | (ub <= g_in))
    # a robust estimate that keeps fewer than two observations does not determine the point (any point of one
    # ray costs the same): the input point and its track stay
    undetermined = has_X & (n_inl >= 0) & (n_inl < 2)
    upd = better & (~behind | (options.behind == "write")) & ~undetermined
    xyz, error = chunk.xyz.copy(), chunk.error.copy()
    xyz[upd] = X[upd]
    # outliers leave the tracks of the points written anew (at least two inliers remain: ``undetermined``)
    keep = ~(outlier & upd[owner])
    message = np.array(rec.message)
    if options.robust is not None:
        _outlier_notes(arrays, obs_img, owner, keep, message)
        for p in np.nonzero(undetermined)[0]:
            note = (f"the robust estimate keeps {int(n_inl[p])} of {int(n_used[p])} observations: the point is not "
                    "determined; the input point and its track are kept")
            message[p] = f"{message[p]}; {note}" if message[p] else note
    if upd.any():
        sel = upd[owner] & usable & keep
        error[upd] = _colmap_error(arrays, geom, xyz, obs_img[sel], gk[sel], owner[sel], n)[upd]
    notes = SimpleNamespace(message=message, n_views=n_used, updated=upd)
    _messages(arrays, geom, chunk, notes, dict(owner=owner, obs_img=obs_img, usable=usable,
                                               depth=np.where(judged, depth, np.inf), solve=solve,
                                               stuck=stuck, behind=behind, has_X=has_X, better=better), options)
    if progress is not None:
        progress.update(int(np.count_nonzero(~solve)))
    robust = options.robust is not None
    return ChunkResult(replace(rec, in_front=~behind, message=message), xyz, error, gamma_input, upd,
                       int(np.count_nonzero(~usable)), keep if robust else None, n_inl if robust else None,
                       _removed(arrays, chunk, owner, obs_img, keep) if robust else None)


def _removed(arrays, chunk, owner, obs_img, keep) -> np.ndarray:
    """(K, 3) int64 rows (point in the chunk, image id, keypoint index) of the observations ``keep`` drops, by point."""
    gone = np.nonzero(~keep)[0]
    return np.stack([owner[gone], arrays.image_ids[obs_img[gone]], chunk.track_kp[gone]], axis=1).astype(np.int64)


def _outlier_notes(arrays, obs_img, owner, keep, message) -> None:
    """A note on every point whose outlier observations are removed from its track (``robust``)."""
    for p in np.nonzero(np.bincount(owner[~keep], minlength=len(message)))[0]:
        gone = np.nonzero(~keep & (owner == p))[0]
        note = f"{len(gone)} outlier observation(s) removed (image ids " + \
            ", ".join(str(int(arrays.image_ids[obs_img[j]])) for j in gone) + ")"
        message[p] = f"{message[p]}; {note}" if message[p] else note


def _unusable_notes(message, owner: np.ndarray, ids: np.ndarray, what: str) -> None:
    """"K observation(s) in unusable WHAT ids left out" on the points ``owner`` (one entry per observation left out,
    ``ids`` its camera or image id)."""
    if not owner.size:
        return
    pairs = np.unique(np.stack([owner, ids], axis=1), axis=0)
    counts = np.bincount(owner, minlength=len(message))
    starts = np.searchsorted(pairs[:, 0], np.arange(len(message) + 1))
    for p in np.nonzero(counts)[0]:
        note = f"{int(counts[p])} observation(s) in unusable {what} " + \
            ", ".join(str(c) for c in pairs[starts[p]:starts[p + 1], 1]) + " left out"
        message[p] = note if not message[p] else f"{message[p]}; {note}"


def _messages(arrays, geom, chunk, r, d, options) -> None:
    """Per-point messages for the points that need one (skips, skipped observations, cheirality)."""
    owner, off = d["owner"], chunk.track_offsets
    unusable = np.nonzero(~d["usable"])[0]
    if unusable.size:
        img = d["obs_img"][unusable]
        skipped_camera = np.array([why is not None for why in geom.camera_reason], bool)
        by_camera = skipped_camera[arrays.image_camera[img]]
        _unusable_notes(r.message, owner[unusable[by_camera]], arrays.camera_ids[arrays.image_camera[img[by_camera]]],
                        "camera(s)")
        _unusable_notes(r.message, owner[unusable[~by_camera]], arrays.image_ids[img[~by_camera]], "image(s)")
    for p in np.nonzero(~d["solve"])[0]:
        k = int(r.n_views[p])
        if d["stuck"][p]:
            why = "a keypoint cannot be undistorted (no pinhole ray, e.g. a fisheye keypoint beyond 90 degrees, or " \
                  "the undistortion did not converge)"
        elif k < options.min_track_length:
            why = f"{k} usable observation(s) < min_track_length {options.min_track_length}"
        else:
            why = f"{k} usable observations > max_track_length {options.max_track_length}"
        r.message[p] = f"skipped: {why}" + (f"; {r.message[p]}" if r.message[p] else "")
    for p in np.nonzero(d["behind"] & d["has_X"])[0]:
        j = int(off[p] + np.argmin(d["depth"][off[p]:off[p + 1]]))
        what = "written anyway (behind = write)" if r.updated[p] else "input point kept"
        note = (f"behind camera: the estimate has depth {d['depth'][j]:.6g} in image "
                f"{int(arrays.image_ids[d['obs_img'][j]])}; {what}")
        r.message[p] = note if not r.message[p] else f"{note}; {r.message[p]}"
