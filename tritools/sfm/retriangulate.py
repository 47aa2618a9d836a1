"""Certified re-triangulation of every 3D point of a COLMAP model (cameras and poses fixed).

For each Point3D with track ((image_id, point2D_idx), ...):

* the cameras are ``P_i = K_i [R_i | t_i]`` (``cam_from_world`` of the image, K of its camera);
* the regions are ``tritools.Point(x^_i)`` with the observed keypoints *undistorted* into the pixels
  of the pinhole camera K_i (:mod:`tritools.io.colmap.camera_models`), so gamma (SPEC §1) is the RMS
  reprojection error per coordinate in undistorted pixels;
* :func:`.certify.certify_stack` certifies whole groups of tracks at once and gives
  ``gamma_LB <= gamma* <= gamma_UB`` (the options of ``tritools.triangulate``, method auto by default:
  Corollary 1 at delta = 2, then delta = 4; see :class:`~.pipeline.RetriangulationOptions`).

The written xyz is the estimate X^ when it is finite, no worse than the input point
(``gamma(X^) <= gamma(xyz_in)``, always true when certified) and in front of every camera of its
track (positive depth ``(R_i X + t_i)_z``); a point whose estimate lies behind a camera keeps its
input xyz unless ``behind="write"``, and is never reported as certified (``in_front = False``).
``Point3D.error`` of an updated point is COLMAP's mean reprojection error: the mean over its usable
observations of ``|pi(X) - x_i|`` in recorded pixels, full camera model.  Observations in a camera
tritools cannot use (unsupported model, focal length <= 0) are left out of the track (counted in the
report); points with too few or too many usable observations, or a keypoint the undistortion cannot
invert, are not solved and left unchanged (status ``invalid_input`` with a message).
"""
from __future__ import annotations

import dataclasses
import inspect
import logging
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..io.colmap.arrays import ModelArrays
from ..io.colmap.model import NO_POINT3D, Model, Point3D
from ..io.colmap.pycolmap_bridge import from_pycolmap, import_pycolmap, is_pycolmap_reconstruction
from ..records import TriangulationResults
from ..result import Status, TriangulationResult
from ..solve.batch import stderr_is_terminal
from ..solve.call_limit import call_limit
from .certify import STATUS_LEGEND, RecordColumns, status_code, written_certified
from .pipeline import RetriangulationOptions, prepare_geometry, process_chunk
from .robust_tracks import removed_observations, without_observations

__all__ = ["PointCertificate", "RetriangulationReport", "retriangulate", "retriangulate_arrays", "progress_bar",
           "has_tqdm", "skipped_cameras", "skipped_images", "PROGRESS_MIN_POINTS", "REPORT_FIELDS",
           "SKIPPED_CAMERAS_LOGGER"]

logger = logging.getLogger(__name__)
#: the logger of the one warning per skipped camera (a child of ``tritools``: a caller that reports the skipped
#: cameras itself, as ``tritools colmap`` does with its exit 3, can quiet it alone).
SKIPPED_CAMERAS_LOGGER = f"{__name__}.cameras"
#: no progress bar for runs with fewer points than this.
PROGRESS_MIN_POINTS = 2000
#: per-point arrays of a report (and of a :class:`~.pipeline.ChunkResult`).
REPORT_FIELDS = ("n_views", "status", "gamma_lb", "gamma_ub", "optimal", "certified_by", "delta", "gamma_input",
                 "updated", "in_front", "message")


@dataclass(frozen=True)
class PointCertificate:
    """Certificate of one re-triangulated point (gammas in undistorted pixels): its row ``result`` of the
    report's record (:class:`~tritools.result.TriangulationResult`), its number of usable views, the gamma of
    the input point and whether its xyz was replaced.

    ``optimal``: the solver certified its estimate; ``in_front``: the estimate (or, without one, the
    input point) has positive depth in every camera of the track; ``certified`` = both, with status
    ``optimal``, and the estimate written (``updated``): the *written* point is a certified global minimiser in front
    of its cameras."""
    point3D_id: int
    n_views: int
    result: TriangulationResult
    gamma_input: float | None = None
    updated: bool = False
    #: with ``robust``: the observations the robust estimate keeps (None: not robust, or no estimate) and the
    #: (image id, keypoint index) of those removed from the written track as outliers
    n_inliers: int | None = None
    removed_observations: tuple = ()

    @property
    def status(self) -> Status:
        """The row's status."""
        return self.result.status

    @property
    def gamma_lb(self) -> float | None:
        """Lower bound on gamma* (undistorted pixels), None when absent."""
        return self.result.gamma_lb

    @property
    def gamma_ub(self) -> float | None:
        """Upper bound gamma(X^) (undistorted pixels), None when absent."""
        return self.result.gamma_ub

    @property
    def optimal(self) -> bool:
        """The solver certified its estimate."""
        return bool(self.result.optimal)

    @property
    def certified_by(self) -> str | None:
        """How: "verification", "sdp", ... or None."""
        return self.result.certified_by or None

    @property
    def delta(self) -> int | None:
        """Relaxation degree of the certificate, None when none."""
        return self.result.delta

    @property
    def message(self) -> str:
        """Details (skips, cheirality, outliers)."""
        return self.result.message

    @property
    def in_front(self) -> bool:
        """The estimate (or the input point) has positive depth in every camera of the track."""
        return self.result.in_front is None or bool(self.result.in_front)

    @property
    def certified(self) -> bool:
        """Status optimal, certified, in front of the cameras, written anew (:func:`~.certify.written_certified`)."""
        return bool(written_certified(status_code(self.status), self.optimal, self.in_front, self.updated))


def _removed_rows(results: list) -> np.ndarray:
    """The chunks' removed observations (point in the chunk, image id, keypoint) with the points numbered over the
    whole report (in point order: each chunk's rows are by point)."""
    rows, offset = [], 0
    for r in results:
        rem = r.removed if r.removed is not None else np.zeros((0, 3), np.int64)
        rows.append(rem + np.array([offset, 0, 0]))
        offset += len(r.updated)
    return np.concatenate(rows) if rows else np.zeros((0, 3), np.int64)


def _opt(v) -> float | None:
    v = float(v)
    return v if np.isfinite(v) else None


@dataclass(frozen=True, eq=False)
class RetriangulationReport(RecordColumns):
    """Outcome of a re-triangulation: the solver's batch record ``results`` of every point (in the order of
    the points; read as SfM columns through :class:`~.certify.RecordColumns`, so :data:`REPORT_FIELDS` are
    per-point arrays), ``point_ids``, ``gamma_input`` and ``updated``, the method and path, and the skipped
    cameras as ``((camera_id, model, reason, n_observations), ...)``.  ``records`` gives one
    :class:`PointCertificate` per point (built on first use)."""
    method: str
    path: str
    point_ids: np.ndarray
    results: TriangulationResults
    gamma_input: np.ndarray
    updated: np.ndarray
    skipped_cameras: tuple = ()
    n_skipped_observations: int = 0
    #: ((image_id, name, reason, n_observations), ...) of the images left out although their camera is usable
    #: (:func:`.pipeline.image_problems`: a K [R | t] that overflows or has rank < 3)
    skipped_images: tuple = ()
    #: with ``robust``: (P,) inliers of each robust estimate (-1: none) and (K, 3) rows (point index, image id,
    #: keypoint index) of the observations removed from the written tracks, by point; None otherwise
    n_inliers: np.ndarray | None = None
    removed: np.ndarray | None = None

    @classmethod
    def from_chunks(cls, options: RetriangulationOptions, ids: list, results: list, skipped_cameras=(),
                    skipped_images=()):
        """Concatenate per-chunk :class:`~.pipeline.ChunkResult`."""
        def cat(name, dtype):
            """Concatenation of one field over the chunks."""
            parts = [getattr(r, name) for r in results]
            return np.concatenate(parts) if parts else np.zeros(0, dtype)
        robust = options.robust is not None
        return cls(options.method, options.path, np.concatenate(ids) if ids else np.zeros(0, np.int64),
                   TriangulationResults.concat([r.results for r in results]), cat("gamma_input", float),
                   cat("updated", bool), skipped_cameras=tuple(skipped_cameras), skipped_images=tuple(skipped_images),
                   n_skipped_observations=sum(r.n_skipped_observations for r in results),
                   n_inliers=cat("n_inliers", np.int32) if robust else None,
                   removed=_removed_rows(results) if robust else None)

    @property
    def n_points(self) -> int:
        """Number of points."""
        return len(self.point_ids)

    @property
    def certified(self) -> np.ndarray:
        """(P,) bool: status optimal, certified by the solver, in front of the cameras, written anew
        (:func:`~.certify.written_certified`)."""
        return written_certified(self.status, self.optimal, self.in_front, self.updated)

    @property
    def n_certified(self) -> int:
        """Number of certified points."""
        return int(np.count_nonzero(self.certified))

    @property
    def n_updated(self) -> int:
        """Number of points whose xyz was replaced."""
        return int(np.count_nonzero(self.updated))

    @property
    def n_behind(self) -> int:
        """Number of points behind one of their cameras."""
        return int(np.count_nonzero(~self.in_front))

    def status_counts(self) -> dict:
        """{status value: number of points} (statuses that occur, sorted by name)."""
        counts = np.bincount(self.status.astype(np.int64), minlength=len(STATUS_LEGEND))
        return dict(sorted((STATUS_LEGEND[k], int(c)) for k, c in enumerate(counts) if c))

    def record(self, i: int) -> PointCertificate:
        """The :class:`PointCertificate` of the i-th point."""
        n_inl, gone = None, ()
        if self.n_inliers is not None:
            n_inl = int(self.n_inliers[i]) if self.n_inliers[i] >= 0 else None
            a, b = np.searchsorted(self.removed[:, 0], [i, i + 1])
            gone = tuple((int(img), int(kp)) for img, kp in self.removed[a:b, 1:])
        return PointCertificate(int(self.point_ids[i]), int(self.n_views[i]), self.results[int(i)],
                                _opt(self.gamma_input[i]), bool(self.updated[i]), n_inl, gone)

    @cached_property
    def records(self) -> tuple:
        """One :class:`PointCertificate` per point (built on first use)."""
        return tuple(self.record(i) for i in range(self.n_points))

    def uncertified(self, limit: int | None = None) -> list:
        """Records of the points that are not certified (at most ``limit``)."""
        idx = np.nonzero(~self.certified)[0][:limit]
        return [self.record(int(i)) for i in idx]

    def summary(self) -> dict:
        """Counts, JSON-ready."""
        return {"method": self.method, "path": self.path, "n_points": self.n_points,
                "n_certified": self.n_certified, "n_updated": self.n_updated, "n_behind": self.n_behind,
                "n_skipped_observations": self.n_skipped_observations, "status": self.status_counts(),
                "skipped_cameras": [{"camera_id": c, "model": m, "reason": r, "n_observations": k}
                                    for c, m, r, k in self.skipped_cameras],
                "skipped_images": [{"image_id": i, "name": n, "reason": r, "n_observations": k}
                                   for i, n, r, k in self.skipped_images]}


def has_tqdm() -> bool:
    """Is the optional extra 'progress' (tqdm) installed?"""
    import importlib.util

    return importlib.util.find_spec("tqdm") is not None


def progress_bar(total: int | None, enabled: bool | str | None):
    """A tqdm bar over points (moved once per stack of equal track lengths), or None: ``enabled`` None / False
    (the library's default: no bar unless asked), ``"auto"`` (the command line's default) with fewer than
    PROGRESS_MIN_POINTS points, an unknown total or a standard error that is not a terminal (a captured or
    redirected stream gets its one error line and nothing else, review 21b F3), or tqdm missing (a warning when
    ``enabled`` is True)."""
    if enabled is None or enabled is False or (enabled == "auto" and (total is None or total < PROGRESS_MIN_POINTS
                                                                      or not stderr_is_terminal())):
        return None
    try:
        from tqdm import tqdm
    except ImportError:  # optional extra 'progress'
        if enabled is True:
            logger.warning("progress=True needs tqdm (pip install 'sospoly-tritools[progress]'): no progress bar")
        return None
    return tqdm(total=total, desc="re-triangulating", unit="pt", leave=False)


def skipped_cameras(arrays: ModelArrays, geom) -> tuple:
    """((camera_id, model, reason, n_observations), ...) of the cameras whose observations are left out."""
    kp_cam = np.repeat(arrays.image_camera, np.diff(arrays.kp_offsets))
    n_obs = np.bincount(kp_cam[arrays.kp_point3D != -1], minlength=arrays.n_cameras)
    out = []
    for k, reason in enumerate(geom.camera_reason):
        if reason is not None and np.any(arrays.image_camera == k):
            out.append((int(arrays.camera_ids[k]), arrays.camera_models[k],
                        f"{arrays.camera_source(k)}: {reason}", int(n_obs[k])))
            logging.getLogger(SKIPPED_CAMERAS_LOGGER).warning("camera %d (%s) skipped: %s", arrays.camera_ids[k],
                                                              arrays.camera_models[k], reason)
    return tuple(out)


def skipped_images(arrays: ModelArrays, geom) -> tuple:
    """((image_id, name, reason, n_observations), ...) of the images whose observations are left out although their
    camera is usable (:func:`.pipeline.image_problems`), each also logged as a warning."""
    n_obs = np.bincount(np.repeat(np.arange(arrays.n_images), np.diff(arrays.kp_offsets))[arrays.kp_point3D != -1],
                        minlength=arrays.n_images)
    out = []
    for v, reason in enumerate(geom.image_reason):
        if reason is not None:
            out.append((int(arrays.image_ids[v]), arrays.image_names[v], reason, int(n_obs[v])))
            logging.getLogger(SKIPPED_CAMERAS_LOGGER).warning("image %d (%s) skipped: %s", arrays.image_ids[v],
                                                              arrays.image_names[v], reason)
    return tuple(out)


def retriangulate_arrays(arrays: ModelArrays, options: RetriangulationOptions | None = None
                         ) -> tuple[ModelArrays, RetriangulationReport]:
    """Re-triangulate every point of ``arrays`` (in chunks of ``options.chunk_points``).

    Returns the model with new xyz/errors (with ``robust``, the outlier observations out of the tracks:
    :func:`.robust_tracks.without_observations`) and the report (points in the arrays' order)."""
    options = options or RetriangulationOptions()
    geom = prepare_geometry(arrays, options.strict)
    bar = None
    ids, results = [], []
    try:
        with call_limit(options.solver.total_time_limit):          # the whole run within total_time_limit
            for a in range(0, arrays.n_points, options.chunk_points):
                chunk = arrays.points(a, a + options.chunk_points)
                if a == 0:              # (after the first records read: a header count alone starts no bar)
                    bar = progress_bar(arrays.n_points, options.progress)
                results.append(process_chunk(arrays, geom, chunk, options, bar))
                ids.append(chunk.ids)
    finally:
        if bar is not None:
            bar.close()
    report = RetriangulationReport.from_chunks(options, ids, results, skipped_cameras(arrays, geom),
                                               skipped_images(arrays, geom))
    xyz = np.concatenate([r.xyz for r in results]) if results else arrays.point_xyz
    err = np.concatenate([r.error for r in results]) if results else arrays.point_error
    new = arrays.with_points(xyz, err)
    if options.robust is not None and results:
        # outlier observations leave their tracks, as `tritools colmap --robust` writes them (robust_tracks)
        new = without_observations(new, np.concatenate([r.keep_obs for r in results]))
    return new, report


def retriangulate(model: Model, method: str | None = None, path: str | None = None, min_track_length: int = 2,
                  delta: int | None = None, max_delta: int | None = None, progress: bool | None = None, *,
                  options: RetriangulationOptions | None = None, **kw) -> tuple[Model, RetriangulationReport]:
    """Re-triangulate every Point3D of ``model`` with a certificate of global optimality.

    ``method``, ``path``, ``min_track_length``, ``delta``, ``max_delta``, ``progress`` and any
    other field of :class:`~.pipeline.RetriangulationOptions` (``solver``, ``behind``, ``strict``,
    ``max_track_length``, ``executor``, ...) as keywords, or a whole ``options`` object.  The solver
    defaults are those of :func:`tritools.triangulate` (method auto: Corollary 1 at delta = 2, then
    delta = 4 for the points that does not certify, within the per-point budget); ``max_delta=2``
    keeps every point at delta = 2.

    ``model`` may also be a ``pycolmap.Reconstruction`` (in memory, no disk): the result is then a new
    ``pycolmap.Reconstruction``, a copy of the input whose updated points get the new xyz and ERROR
    (rigs, frames, colours and tracks unchanged; :mod:`tritools.io.colmap.pycolmap_bridge`).  With ``robust``,
    the outlier observations of every updated point leave its track and their keypoints get POINT3D_ID -1, in
    memory as on disk (``tritools colmap --robust``; :mod:`.robust_tracks`).

    Returns ``(new_model, report)``; ``report.records`` follow the point ids in increasing order.
    """
    if is_pycolmap_reconstruction(model):
        return _retriangulate_pycolmap(model, method, path, min_track_length, delta, max_delta, progress,
                                       options=options, **kw)
    if not isinstance(model, Model):
        raise TypeError(f"model must be a tritools.io.colmap.Model or a pycolmap.Reconstruction, got "
                        f"{type(model).__name__}")
    options = _options_of(options, kw, method=method, path=path, min_track_length=min_track_length, delta=delta,
                          max_delta=max_delta, progress=progress)
    arrays = ModelArrays.from_model(model)
    new, report = retriangulate_arrays(arrays, options)
    changed = np.nonzero(report.updated)[0]
    gone = set(removed_observations(arrays, new))
    points = []
    for i in changed:
        p = model.points3D[int(arrays.point_ids[i])]
        track = tuple(e for e in p.track if e not in gone) if gone else p.track
        points.append(Point3D(p.id, tuple(new.point_xyz[i].tolist()), p.rgb, float(new.point_error[i]), track))
    if not gone:
        return model.replace_points(points), report
    return _without_observations(model, gone, points), report


def _options_of(options, kw: dict, **settings) -> RetriangulationOptions:
    """The run's options: ``options`` as given, else the individual ``settings`` and keywords ``kw``.  Both at once
    is a TypeError naming them (review 50a F4: ``options=`` silently dropped ``robust=5``, and a plain L2 model came
    back with the outliers in its tracks); so is an ``options`` that is not a :class:`RetriangulationOptions`."""
    if options is None:
        return RetriangulationOptions(**settings, **kw)
    if not isinstance(options, RetriangulationOptions):
        raise TypeError(f"options must be a RetriangulationOptions, got {type(options).__name__}")
    defaults = inspect.signature(retriangulate).parameters           # the settings as given vs their defaults
    given = sorted(kw) + [k for k, v in settings.items() if v != defaults[k].default]
    if given:
        raise TypeError(f"retriangulate: pass either options= or the individual settings, not both (got options "
                        f"and {', '.join(given)}; set them on the RetriangulationOptions)")
    return options


def _without_observations(model: Model, gone: set, points: list) -> Model:
    """``model`` with the Point3D records ``points`` (their tracks already without ``gone``) and the keypoints
    ``gone`` ((image id, keypoint index), ...) without a 3D point (POINT3D_ID -1): one construction, which
    checks the cross references of both."""
    images = dict(model.images)
    for img in {i for i, _ in gone}:
        im = images[img]
        pts = tuple((x, y, NO_POINT3D if (img, k) in gone else pid) for k, (x, y, pid) in enumerate(im.points2D))
        images[img] = dataclasses.replace(im, points2D=pts)
    new_points = dict(model.points3D)
    new_points.update({p.id: p for p in points})
    return Model(model.cameras, images, new_points)



def _retriangulate_pycolmap(rec, *args, **kw):
    """:func:`retriangulate` of a ``pycolmap.Reconstruction``: a copy with the updated points changed."""
    pycolmap = import_pycolmap()
    model = from_pycolmap(rec)
    new, report = retriangulate(model, *args, **kw)
    out = pycolmap.Reconstruction(rec)
    for i in np.nonzero(report.updated)[0]:
        pid = int(report.point_ids[i])
        p = new.points3D[pid]
        for image_id, idx in set(model.points3D[pid].track) - set(p.track):
            out.delete_observation(image_id, idx)          # an outlier (robust): >= 2 inliers stay in the track
        q = out.points3D[pid]
        q.xyz, q.error = np.asarray(p.xyz, float), float(p.error)
    return out, report
