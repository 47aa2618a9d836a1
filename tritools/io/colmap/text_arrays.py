"""COLMAP's text format read into and written from arrays, vectorised where it pays.

A line of numbers is parsed by one ``np.fromstring`` call (C speed); ``points3D.txt`` is read in
chunks of lines (:class:`TextPointsReader`) and each chunk is parsed as one array.  Whenever the
fast parser meets anything unusual (a bad token, a wrong field count, a non-integer id), the line
is re-parsed by the per-line parsers of :mod:`.model`, whose :class:`~.model.ModelFormatError`
names the file and line.  Both accept every file COLMAP writes and give the same verdict on every other
(an integer field spelled ``3.0`` is refused by both: the fast parser checks the spelling of the integer
fields with one regular expression per chunk).  Writing gives the same
bytes as :func:`~.model.write_text_model` (floats as ``repr``: exact round trip).
"""
from __future__ import annotations

import os
import re
import shutil
import warnings
from pathlib import Path

import numpy as np

from ..atomic import atomic_open, naming_errors
from .model import (LineFields, read_camera_records, parse_image_header, parse_point,
                    parse_points2d)

__all__ = ["read_cameras_text", "read_images_text", "TextPointsReader", "write_cameras_text", "write_images_text",
           "TextPointsWriter"]

#: integers parsed through float64 are exact below this magnitude; larger ones take the slow parser.
_EXACT_INT = 2.0 ** 53
_INT = r"[+-]?\d+"
_SEP = r"[ \t]+"
#: a points3D.txt line whose integer fields are spelled as integers (POINT3D_ID, R G B, the track's IMAGE_ID
#: POINT2D_IDX pairs); the float fields are any token.  ``1.0`` in an integer field parses to the same float, so
#: only the text tells: a line that does not match goes to the exact parser (review 27a F6: the verdict on such a
#: file depended on which lines shared its chunk).
_POINT_LINE = re.compile(rf"^{_INT}(?:{_SEP}\S+){{3}}(?:{_SEP}{_INT}){{3}}{_SEP}\S+(?:{_SEP}{_INT}{_SEP}{_INT})*$",
                         re.M)
#: a POINTS2D line of images.txt with its POINT3D_IDs spelled as integers
_POINTS2D_LINE = re.compile(rf"^(?:\S+{_SEP}\S+{_SEP}{_INT}(?:{_SEP}|$))*$")


def _ints_spelled(pattern: re.Pattern, texts: list) -> bool:
    """Do all the (stripped, non-empty) lines match ``pattern`` (one C-level pass over the chunk)?"""
    return len(pattern.findall("\n".join(texts))) == len(texts)


def _floats(text: str) -> np.ndarray | None:
    """The whitespace-separated numbers of ``text``, or None when a token is not a number."""
    if not text:
        return np.zeros(0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            return np.fromstring(text, sep=" ")
        except (ValueError, DeprecationWarning):
            return None


def _ints_ok(v: np.ndarray) -> bool:
    return bool(np.all(np.abs(v) < _EXACT_INT) and np.all(v == np.floor(v)))


def _data_lines(path: Path):
    """(line number, stripped text) of the non-comment lines, read lazily."""
    with open(path, encoding="utf-8-sig", errors="surrogateescape") as fh:   # a BOM (review 29b F10) skipped
        for lineno, line in enumerate(fh, 1):
            s = line.strip()
            if not s.startswith("#"):
                yield lineno, s


def read_cameras_text(path) -> dict:
    """Camera table of ``cameras.txt`` (same keys as :func:`.binary.read_cameras_binary`)."""
    path = Path(path)
    cams, where = read_camera_records(path)
    order = list(cams)
    return {"ids": [cams[c].id for c in order], "models": [cams[c].model for c in order],
            "width": [cams[c].width for c in order], "height": [cams[c].height for c in order],
            "params": [np.array(cams[c].params, float) for c in order], "sources": [where[c] for c in order]}


def read_images_text(path, camera_ids: np.ndarray) -> dict:
    """Images of ``images.txt`` (same keys as :func:`.binary.read_images_binary`)."""
    path = Path(path)
    cam_index = {int(c): k for k, c in enumerate(camera_ids)}
    ids, qv, tv, cams, names, kps, seen, sources = [], [], [], [], [], [], set(), []
    lines = _data_lines(path)
    for lineno, text in lines:
        if not text:
            continue
        iid, q, t, cid, name = parse_image_header(path, lineno, text)
        f = LineFields(path, lineno, "")
        if iid in seen:
            f.fail(f"duplicate IMAGE_ID {iid}")
        if cid not in cam_index:
            f.fail(f"image {iid} refers to camera {cid}, which does not exist")
        try:
            plineno, ptext = next(lines)
        except StopIteration:
            f.fail(f"image {iid} has no POINTS2D line (two lines per image)")
        v = _floats(ptext)
        if v is None or len(v) % 3 or not np.all(np.isfinite(v)) or not _ints_ok(v[2::3]) \
                or (len(v) and v[2::3].min() < -1) or not _POINTS2D_LINE.match(ptext):
            # the exact parser: raises with file:line, or reads what the fast one could not
            pts = parse_points2d(path, plineno, ptext, iid)
            kp = (np.array([q[:2] for q in pts], float).reshape(-1, 2), np.array([q[2] for q in pts], np.int64))
        else:
            kp = (v.reshape(-1, 3)[:, :2], v[2::3].astype(np.int64))
        seen.add(iid)
        ids.append(iid)
        qv.append(q)
        tv.append(t)
        cams.append(cam_index[cid])
        names.append(name)
        kps.append(kp)
        sources.append(f"{path.name}:{lineno}")
    xy = np.concatenate([k[0] for k in kps]) if kps else np.zeros((0, 2))
    pid = np.concatenate([k[1] for k in kps]) if kps else np.zeros(0, np.int64)
    counts = np.array([len(k[1]) for k in kps], np.int64)
    return {"ids": np.array(ids, np.int64), "qvec": np.array(qv, float).reshape(-1, 4),
            "tvec": np.array(tv, float).reshape(-1, 3), "camera": np.array(cams, np.int64), "names": tuple(names),
            "kp_offsets": np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
            "kp_xy": np.ascontiguousarray(xy), "kp_point3D": pid,
            "sources": tuple(sources)}


class TextPointsReader:
    """``points3D.txt`` in chunks of lines; :meth:`chunks` yields the arrays of
    :class:`.binary.BinaryPointsReader` with line numbers instead of byte offsets."""

    def __init__(self, path):
        self.path = Path(path)
        self.n_points = None                           # unknown before reading

    def where(self, record: int, lineno: int) -> str:
        """Location of a line, for messages."""
        return f"{self.path.name}:{lineno}"

    def count(self) -> int:
        """Number of data lines (a quick pass, for progress bars)."""
        n = 0
        for _, text in _data_lines(self.path):
            n += bool(text)
        return n

    def chunks(self, size: int):
        """Yield the points in chunks of at most ``size`` lines."""
        batch: list[tuple[int, str]] = []
        for lineno, text in _data_lines(self.path):
            if text:
                batch.append((lineno, text))
                if len(batch) >= size:
                    yield self._parse(batch)
                    batch = []
        if batch:
            yield self._parse(batch)

    def _parse(self, batch):
        texts = [t for _, t in batch]
        linenos = np.array([n for n, _ in batch], np.int64)
        joined = " ".join(texts)
        vals = _floats(joined)
        counts = None
        if vals is not None:
            if "\t" not in joined and "  " not in joined:
                counts = np.array([t.count(" ") + 1 for t in texts], np.int64)
            else:
                counts = np.array([len(t.split()) for t in texts], np.int64)
            if counts.sum() != len(vals):
                counts = None
        if counts is None or np.any((counts <= 8) | ((counts - 8) % 2 == 1)) or not _ints_spelled(_POINT_LINE, texts):
            return self._slow(batch, linenos)
        starts = np.cumsum(counts) - counts
        head = vals[starts[:, None] + np.arange(8)]
        lens = (counts - 8) // 2
        first = np.repeat(np.cumsum(lens) - lens, lens)
        pos = np.repeat(starts + 8, lens) + 2 * (np.arange(int(lens.sum())) - first)
        tr = vals[pos[:, None] + np.arange(2)]
        ids, xyz, rgb, err = head[:, 0], head[:, 1:4], head[:, 4:7], head[:, 7]
        rows_bad = ~(np.all(np.isfinite(xyz), axis=1) & (np.abs(ids) < _EXACT_INT) & (ids == np.floor(ids))
                     & np.all((rgb >= 0) & (rgb <= 255) & (rgb == np.floor(rgb)), axis=1))
        tr_bad = ~(np.all(np.abs(tr) < _EXACT_INT, axis=1) & np.all(tr == np.floor(tr), axis=1) & (tr[:, 1] >= 0))
        if tr_bad.any():
            rows_bad[np.repeat(np.arange(len(batch)), lens)[tr_bad]] = True
        if rows_bad.any():
            return self._slow(batch, linenos)
        return (ids.astype(np.int64), np.ascontiguousarray(xyz), rgb.astype(np.uint8), err.copy(), lens,
                tr[:, 0].astype(np.int64), tr[:, 1].astype(np.int64), linenos)

    def _slow(self, batch, linenos):
        """Parse the chunk line by line with the exact parser (raises with file:line at the first
        bad line), for the chunks the fast parser cannot take."""
        pts = [parse_point(self.path, n, t) for n, t in batch]
        lens = np.array([len(p.track) for p in pts], np.int64)
        track = np.array([e for p in pts for e in p.track], np.int64).reshape(-1, 2)
        return (np.array([p.id for p in pts], np.int64), np.array([p.xyz for p in pts], float).reshape(-1, 3),
                np.array([p.rgb for p in pts], np.uint8).reshape(-1, 3), np.array([p.error for p in pts], float),
                lens, track[:, 0].copy(), track[:, 1].copy(), linenos)


# ----------------------------------------------------------------------------- writing
def _num(v: float) -> str:
    return repr(v)


def write_cameras_text(arrays, path) -> None:
    """``cameras.txt`` of a :class:`~.arrays.ModelArrays` (records in table order)."""
    lines = ["# Camera list with one line of data per camera:", "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]",
             f"# Number of cameras: {arrays.n_cameras}"]
    for cid, model, w, h, params in zip(arrays.camera_ids.tolist(), arrays.camera_models, arrays.camera_width.tolist(),
                                        arrays.camera_height.tolist(), arrays.camera_params):
        lines.append(" ".join([str(cid), model, str(w), str(h)] + [_num(p) for p in np.asarray(params).tolist()]))
    with atomic_open(path, "w", encoding="utf-8", errors="surrogateescape") as fh:
        fh.write("\n".join(lines) + "\n")


def write_images_text(arrays, path) -> None:
    """``images.txt`` of a :class:`~.arrays.ModelArrays`."""
    n_obs = int(np.count_nonzero(arrays.kp_point3D != -1))
    mean_obs = n_obs / arrays.n_images if arrays.n_images else 0.0
    off = arrays.kp_offsets.tolist()
    xs, ys, ps = arrays.kp_xy[:, 0].tolist(), arrays.kp_xy[:, 1].tolist(), arrays.kp_point3D.tolist()
    with atomic_open(path, "w", encoding="utf-8", errors="surrogateescape") as fh:
        fh.write("# Image list with two lines of data per image:\n"
                 "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
                 "#   POINTS2D[] as (X, Y, POINT3D_ID)\n"
                 f"# Number of images: {arrays.n_images}, mean observations per image: {mean_obs:.6g}\n")
        for v, iid in enumerate(arrays.image_ids.tolist()):
            cid = int(arrays.camera_ids[arrays.image_camera[v]])
            pose = arrays.image_qvec[v].tolist() + arrays.image_tvec[v].tolist()
            fh.write(" ".join([str(iid)] + [_num(x) for x in pose] + [str(cid), arrays.image_names[v]]) + "\n")
            a, b = off[v], off[v + 1]
            fh.write(" ".join([f"{x!r} {y!r} {p}" for x, y, p in zip(xs[a:b], ys[a:b], ps[a:b])]) + "\n")


class TextPointsWriter:
    """``points3D.txt`` written chunk by chunk; the header (count, mean track length) is put in
    front by :meth:`close` (the body goes to a side file first)."""

    def __init__(self, path):
        self.path = Path(path)
        self.body_path = self.path.with_name(self.path.name + ".body")
        self.fh = open(self.body_path, "w", encoding="utf-8")
        self.n_points = 0
        self.n_observations = 0

    def write(self, ids, xyz, rgb, error, track_lengths, track_image_ids, track_kp) -> None:
        """Append points (arrays as for :class:`.binary.BinaryPointsWriter`)."""
        pairs = [f"{i} {k}" for i, k in zip(np.asarray(track_image_ids).tolist(), np.asarray(track_kp).tolist())]
        off = np.concatenate([[0], np.cumsum(track_lengths)]).tolist()
        out = []
        for p, (pid, (x, y, z), (r, g, b), e) in enumerate(zip(np.asarray(ids).tolist(), np.asarray(xyz).tolist(),
                                                               np.asarray(rgb).tolist(), np.asarray(error).tolist())):
            track = " ".join(pairs[off[p]:off[p + 1]])
            out.append(f"{pid} {x!r} {y!r} {z!r} {r} {g} {b} {e!r}" + (" " + track if track else ""))
        if out:
            with naming_errors(self.path):
                self.fh.write("\n".join(out) + "\n")
        self.n_points += len(out)
        self.n_observations += len(pairs)

    def close(self) -> None:
        """Write the header, then the body, and remove the side file."""
        with naming_errors(self.path):
            self.fh.close()
        mean = self.n_observations / self.n_points if self.n_points else 0.0
        with atomic_open(self.path, "w", encoding="utf-8") as out, open(self.body_path, encoding="utf-8") as body:
            out.write("# 3D point list with one line of data per point:\n"
                      "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n"
                      f"# Number of points: {self.n_points}, mean track length: {mean:.6g}\n")
            shutil.copyfileobj(body, out, 1 << 22)
        os.remove(self.body_path)

    def abort(self) -> None:
        """Close and remove the side file."""
        self.fh.close()
        if self.body_path.exists():
            os.remove(self.body_path)
