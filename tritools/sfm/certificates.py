"""The certificate sidecar ``points3D_certificates.txt`` (COLMAP ignores files it does not know).

``#`` comment lines, then one line per point, in the order of the points file::

    POINT3D_ID N_VIEWS GAMMA_LB GAMMA_UB CERTIFIED STATUS DELTA CERTIFIED_BY GAMMA_INPUT UPDATED IN_FRONT MESSAGE

GAMMA_* in undistorted pixels (``nan`` when absent, floats as ``repr``: exact; with ``--robust`` all three are
TLS gammas with the run's threshold, GAMMA_INPUT that of the input point), CERTIFIED, UPDATED
and IN_FRONT ``0``/``1``, STATUS a :class:`tritools.Status` value, DELTA the relaxation degree
(``-1`` when none), CERTIFIED_BY ``sdp``/``verification``/``-``, MESSAGE the rest of the line
(spaces allowed, line breaks replaced by spaces, ``-`` when empty).  :func:`read_certificates`
also reads the older 10-column form (without IN_FRONT and MESSAGE).
"""
from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np

from ..io.atomic import atomic_open, naming_errors
from ..io.colmap.model import ModelFormatError
from ..result import Status, TriangulationResult
from .certify import STATUS_LEGEND, written_certified
from .retriangulate import PointCertificate, RetriangulationReport

__all__ = ["CERTIFICATES_FILE", "CertificateWriter", "write_certificates", "read_certificates", "mark_removed",
           "COLUMNS", "REMOVED_MESSAGE"]

#: MESSAGE of a point that the quality filters removed from the written model (:func:`mark_removed`)
REMOVED_MESSAGE = "removed from the written model by the quality filters (points3D_uncertainty.txt: KEPT = 0)"

CERTIFICATES_FILE = "points3D_certificates.txt"
COLUMNS = ("POINT3D_ID", "N_VIEWS", "GAMMA_LB", "GAMMA_UB", "CERTIFIED", "STATUS", "DELTA", "CERTIFIED_BY",
           "GAMMA_INPUT", "UPDATED", "IN_FRONT", "MESSAGE")
_HEADER = ("# Certified re-triangulation (tritools, Chesi 2026) of points3D, one line per point:\n"
           f"#   {', '.join(COLUMNS)}\n"
           "# gamma: RMS reprojection error per coordinate in undistorted pixels; "
           "gamma_lb <= gamma* <= gamma_ub; CERTIFIED = 1 iff they meet and the point is in front of its cameras\n")


def _clean(msg: str) -> str:
    msg = " ".join(str(msg).replace("\r", " ").replace("\n", " ").split())
    return msg or "-"


class CertificateWriter:
    """The sidecar written chunk by chunk (:meth:`write`); :meth:`close` puts the header in front."""

    def __init__(self, folder, method: str = "", path: str = ""):
        self.path = Path(folder) / CERTIFICATES_FILE
        self.body_path = self.path.with_name(CERTIFICATES_FILE + ".body")
        self.fh = open(self.body_path, "w", encoding="utf-8")
        self.method, self.solve_path = method, path
        self.n_points = self.n_certified = 0

    def write(self, point_ids, r) -> None:
        """Append lines for ``point_ids`` from per-point arrays ``r`` (a report or a chunk result)."""
        certified = written_certified(r.status, r.optimal, r.in_front, r.updated)
        rows = zip(np.asarray(point_ids).tolist(), r.n_views.tolist(), r.gamma_lb.tolist(), r.gamma_ub.tolist(),
                   certified.tolist(), r.status.tolist(), r.delta.tolist(), r.certified_by.tolist(),
                   r.gamma_input.tolist(), r.updated.tolist(), r.in_front.tolist(), r.message.tolist())
        lines = [f"{pid} {n} {lb!r} {ub!r} {int(c)} {STATUS_LEGEND[s]} {d} {by or '-'} {g!r} {int(u)} {int(f)} "
                 f"{_clean(m)}" for pid, n, lb, ub, c, s, d, by, g, u, f, m in rows]
        if lines:
            with naming_errors(self.path):
                self.fh.write("\n".join(lines) + "\n")
        self.n_points += len(lines)
        self.n_certified += int(np.count_nonzero(certified))

    def close(self) -> Path:
        """Write the header, then the body; returns the sidecar path."""
        with naming_errors(self.path):
            self.fh.close()
        with atomic_open(self.path, "w", encoding="utf-8") as out, open(self.body_path, encoding="utf-8") as body:
            out.write(_HEADER + f"# Number of points: {self.n_points}, certified: {self.n_certified}, "
                                f"method: {self.method}, path: {self.solve_path}\n")
            shutil.copyfileobj(body, out, 1 << 22)
        os.remove(self.body_path)
        return self.path

    def abort(self) -> None:
        """Close and remove the side file."""
        self.fh.close()
        if self.body_path.exists():
            os.remove(self.body_path)


def write_certificates(report: RetriangulationReport, folder) -> Path:
    """Write ``points3D_certificates.txt`` for a whole report into ``folder`` (created if needed)."""
    Path(folder).mkdir(parents=True, exist_ok=True)
    w = CertificateWriter(folder, report.method, report.path)
    w.write(report.point_ids, report)
    return w.close()


def mark_removed(folder, point_ids, message: str = REMOVED_MESSAGE) -> None:
    """Rewrite the sidecar in ``folder`` (atomically) for points removed from the written model after it was
    written (``tritools colmap``'s quality filters): their CERTIFIED and UPDATED become 0 and ``message`` is added to
    MESSAGE -- the written model no longer holds them (review 29b F7: CERTIFIED = 1 was reported for a point absent
    from points3D) -- and the header's count of certified points is updated."""
    removed = {int(p) for p in np.asarray(point_ids).tolist()}
    if not removed:
        return
    path = Path(folder) / CERTIFICATES_FILE
    lines = path.read_text(encoding="utf-8").splitlines(keepends=True)
    body, n_certified = [], 0
    for line in lines:
        t = line.split(None, 11)
        if t and not t[0].startswith("#") and len(t) == 12 and int(t[0]) in removed:
            msg = message if t[11].strip() == "-" else f"{t[11].strip()}; {message}"
            t[4], t[9], t[11] = "0", "0", _clean(msg)
            line = " ".join(t) + "\n"
        if t and not t[0].startswith("#"):
            n_certified += t[4] == "1"
        body.append(line)
    with atomic_open(path, "w", encoding="utf-8") as out:
        for line in body:
            if line.startswith("# Number of points:"):
                head, _, rest = line.partition(", certified: ")
                line = f"{head}, certified: {n_certified}," + rest.partition(",")[2]
            out.write(line)


def _float(v: str) -> float | None:
    x = float(v)
    return None if x != x else x


def read_certificates(folder) -> dict[int, PointCertificate]:
    """Read the sidecar back: point3D_id -> :class:`PointCertificate` (12-column or old 10-column form)."""
    path = Path(folder) / CERTIFICATES_FILE
    out = {}
    with open(path, encoding="utf-8") as fh:
        for lineno, line in enumerate(fh, 1):
            t = line.split(None, 11)
            if not t or t[0].startswith("#"):
                continue
            if len(t) not in (10, 12):
                raise ModelFormatError(f"{path.name}:{lineno}: expected 12 fields (or the old 10), got {len(t)}")
            try:
                pid, n = int(t[0]), int(t[1])
                lb, ub, g_in = _float(t[2]), _float(t[3]), _float(t[8])
                cert, status, delta, by, upd = t[4] == "1", Status(t[5]), int(t[6]), t[7], t[9] == "1"
                front, msg = (t[10] == "1", t[11].strip()) if len(t) == 12 else (True, "-")
            except ValueError as exc:
                raise ModelFormatError(f"{path.name}:{lineno}: {exc}") from None
            if len(t) == 12 and t[10] not in ("0", "1"):
                raise ModelFormatError(f"{path.name}:{lineno}: IN_FRONT must be 0 or 1, got {t[10]!r}")
            # CERTIFIED = optimal and in front; a certified solver result behind a camera reads back
            # as optimal = (status == optimal) so that status, optimal and in_front round-trip
            optimal = cert or (status == Status.OPTIMAL and not front)
            row = TriangulationResult("", status, gamma_lb=lb, gamma_ub=ub, optimal=optimal,
                                      certified_by=None if by == "-" else by, delta=None if delta < 0 else delta,
                                      message="" if msg == "-" else msg, in_front=front)
            out[pid] = PointCertificate(pid, n, row, g_in, upd)
    return out
