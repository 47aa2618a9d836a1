"""Certified re-triangulation of every 3D point of a COLMAP model, and the certificate sidecar.

For a Point3D with track ((image_i, point2D_idx_i), i = 1..N):

* cameras ``P_i = K_i [R_i | t_i]`` (K of the image's camera, ``[R | t]`` = ``cam_from_world``);
* regions ``R_i = Point(x^_i)``, x^_i the observed keypoint *undistorted* into the pixels of
  the pinhole camera K_i (:mod:`tritools.io.colmap.camera_models`), so gamma (SPEC §1) is the
  RMS reprojection error per coordinate in undistorted pixels;
* :func:`tritools.solve.batch.triangulate_many` solves every track (one result per point, always)
  and gives ``gamma_LB <= gamma* <= gamma_UB`` (Theorem 1 / Corollary 1).

The written xyz is the estimate X^ when it is finite and no worse than the input point
(``gamma(X^) <= gamma(xyz_in)``, always true when certified); otherwise the input point
is kept.  ``Point3D.error`` is COLMAP's mean reprojection error of the written point: the
mean over the track of ``|pi(X) - x_i|`` in (distorted) image pixels with the full camera
model.  Points whose track is shorter than ``min_track_length``, or with a keypoint the
undistortion cannot invert, are not solved and are left unchanged (status
``invalid_input`` with a message).

Sidecar ``points3D_certificates.txt`` (COLMAP ignores unknown files), one line per point::

    # POINT3D_ID N_VIEWS GAMMA_LB GAMMA_UB CERTIFIED STATUS DELTA CERTIFIED_BY GAMMA_INPUT UPDATED

GAMMA_* in undistorted pixels (``nan`` when absent), CERTIFIED and UPDATED ``0``/``1``,
STATUS a :class:`tritools.result.Status` value, DELTA the relaxation degree (``-1`` when
absent), CERTIFIED_BY ``sdp``/``verification``/``-``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..solve.batch import triangulate_many
from ..model.geometry import gamma as gamma_of
from ..model.regions import Point
from ..result import Status
from ..solve.triangulate import SolvePath
from ..model.constraints import Method
from ..io.colmap.camera_models import camera_model, undistorted_pixels
from ..io.colmap.model import Model, ModelFormatError, Point3D
from ..io.colmap.projection import projection_matrix, reprojection_error

__all__ = ["PointCertificate", "RetriangulationReport", "retriangulate", "write_certificates",
           "read_certificates", "CERTIFICATES_FILE"]

CERTIFICATES_FILE = "points3D_certificates.txt"
_HEADER = ("# Certified re-triangulation (tritools, Chesi 2026) of points3D.txt, one line per point:\n"
           "#   POINT3D_ID, N_VIEWS, GAMMA_LB, GAMMA_UB, CERTIFIED, STATUS, DELTA, CERTIFIED_BY, GAMMA_INPUT, UPDATED\n"
           "# gamma: RMS reprojection error per coordinate in undistorted pixels; "
           "gamma_lb <= gamma* <= gamma_ub; CERTIFIED = 1 iff they meet\n")


@dataclass(frozen=True)
class PointCertificate:
    """Certificate of one re-triangulated point (gammas in undistorted pixels)."""
    point3D_id: int
    n_views: int
    status: Status
    gamma_lb: float | None = None
    gamma_ub: float | None = None
    optimal: bool = False
    certified_by: str | None = None
    delta: int | None = None
    gamma_input: float | None = None
    updated: bool = False
    message: str = ""

    def __post_init__(self):
        object.__setattr__(self, "status", Status(self.status))

    @property
    def certified(self) -> bool:
        return self.status == Status.OPTIMAL and bool(self.optimal)


@dataclass(frozen=True)
class RetriangulationReport:
    """Outcome of :func:`retriangulate` over a whole model: one :class:`PointCertificate`
    per 3D point of the input (``records``, in point-id order, skipped points included
    with their status), the method and solve path used, and counts
    (``n_points``, ``n_certified``, ``n_updated``, ``status_counts()``)."""

    method: str
    path: str
    records: tuple

    @property
    def n_points(self) -> int:
        return len(self.records)

    @property
    def n_certified(self) -> int:
        return sum(r.certified for r in self.records)

    @property
    def n_updated(self) -> int:
        return sum(r.updated for r in self.records)

    def status_counts(self) -> dict:
        out: dict[str, int] = {}
        for r in self.records:
            out[r.status.value] = out.get(r.status.value, 0) + 1
        return dict(sorted(out.items()))


def _problem(model: Model, point: Point3D):
    """(cameras (N, 3, 4), Point regions) of a track, or an error message."""
    cams, regions = [], []
    for image_id, idx in point.track:
        im = model.images[image_id]
        cam = model.cameras[im.camera_id]
        xy, ok = undistorted_pixels(cam.model, cam.params, np.array(im.points2D[idx][:2]))
        if not ok[0]:
            return None, (f"keypoint {idx} of image {image_id} cannot be undistorted "
                          f"(Newton did not converge for camera {cam.id}, {cam.model})")
        cams.append(projection_matrix(model, image_id))
        regions.append(Point(xy[0]))
    return (np.array(cams), regions), ""


def retriangulate(model: Model, method: Method | str = Method.COROLLARY1, path: SolvePath | str = SolvePath.AUTO,
                  min_track_length: int = 2, delta: int | None = None, max_delta: int | None = None,
                  progress: bool = False, **batch_options) -> tuple[Model, RetriangulationReport]:
    """Re-triangulate every Point3D of ``model`` with a certificate of global optimality.

    Parameters: ``method`` ("corollary1" or "theorem1"), ``path`` ("auto": certification
    by verification first, then the SDP; "sdp"), ``delta``/``max_delta`` as in
    :func:`tritools.triangulate`, ``min_track_length`` (>= 2), ``progress`` (tqdm bar);
    other keyword options go to :func:`tritools.solve.batch.triangulate_many`.

    Returns ``(new_model, report)``; ``report.records`` follow the point ids in increasing
    order.  See the module docstring for the rule deciding the written xyz.
    """
    method, path = Method(method), SolvePath(path)
    if isinstance(min_track_length, bool) or int(min_track_length) != min_track_length or min_track_length < 2:
        raise ValueError(f"min_track_length must be an integer >= 2, got {min_track_length!r}")
    for cam in model.cameras.values():
        camera_model(cam.model)                  # unsupported model: clear error before solving
    ids = sorted(model.points3D)
    records: dict[int, PointCertificate] = {}
    todo, problems = [], []
    for pid in ids:
        p = model.points3D[pid]
        n = len(p.track)
        if n < min_track_length:
            records[pid] = PointCertificate(pid, n, Status.INVALID_INPUT,
                                            message=f"skipped: track length {n} < min_track_length {min_track_length}")
            continue
        prob, msg = _problem(model, p)
        if prob is None:
            records[pid] = PointCertificate(pid, n, Status.INVALID_INPUT, message=f"skipped: {msg}")
            continue
        todo.append(pid)
        problems.append(prob)
    results = triangulate_many(problems, method=method.value, delta=delta, max_delta=max_delta, progress=progress,
                               path=path.value, **batch_options) if problems else []
    new_points = []
    for pid, (cams, regions), res in zip(todo, problems, results):
        p = model.points3D[pid]
        g_in = float(gamma_of(np.array(p.xyz), cams, regions))
        g_in = g_in if math.isfinite(g_in) else None
        better = (res.X is not None and np.all(np.isfinite(res.X)) and res.gamma_ub is not None
                  and (g_in is None or res.gamma_ub <= g_in or bool(res.optimal)))
        if better:
            xyz = tuple(float(v) for v in res.X)
            new_points.append(Point3D(pid, xyz, p.rgb, reprojection_error(model, xyz, p.track), p.track))
        records[pid] = PointCertificate(pid, len(p.track), res.status, res.gamma_lb, res.gamma_ub,
                                        bool(res.optimal), res.certified_by, res.delta, g_in, bool(better),
                                        res.message)
    report = RetriangulationReport(method.value, path.value, tuple(records[pid] for pid in ids))
    return model.replace_points(new_points), report


# ----------------------------------------------------------------------------- sidecar
def _f(v) -> str:
    return "nan" if v is None else repr(float(v))


def write_certificates(report: RetriangulationReport, folder) -> Path:
    """Write ``points3D_certificates.txt`` (format in the module docstring) into ``folder``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    lines = [_HEADER + f"# Number of points: {report.n_points}, certified: {report.n_certified}, "
             f"method: {report.method}, path: {report.path}"]
    for r in report.records:
        lines.append(" ".join([str(r.point3D_id), str(r.n_views), _f(r.gamma_lb), _f(r.gamma_ub),
                               str(int(r.certified)), r.status.value, str(-1 if r.delta is None else r.delta),
                               r.certified_by or "-", _f(r.gamma_input), str(int(r.updated))]))
    out = folder / CERTIFICATES_FILE
    out.write_text("\n".join(lines) + "\n")
    return out


def read_certificates(folder) -> dict[int, PointCertificate]:
    """Read the sidecar back: point3D_id -> :class:`PointCertificate` (without messages)."""
    path = Path(folder) / CERTIFICATES_FILE
    out = {}
    for lineno, line in enumerate(path.read_text().splitlines(), 1):
        t = line.split()
        if not t or t[0].startswith("#"):
            continue
        if len(t) != 10:
            raise ModelFormatError(f"{path.name}:{lineno}: expected 10 fields, got {len(t)}")
        try:
            pid, n = int(t[0]), int(t[1])
            lb, ub, g_in = (None if v == "nan" else float(v) for v in (t[2], t[3], t[8]))
            cert, status, delta, by, upd = t[4] == "1", Status(t[5]), int(t[6]), t[7], t[9] == "1"
        except ValueError as exc:
            raise ModelFormatError(f"{path.name}:{lineno}: {exc}") from None
        out[pid] = PointCertificate(pid, n, status, lb, ub, cert, None if by == "-" else by,
                                    None if delta < 0 else delta, g_in, upd)
    return out
