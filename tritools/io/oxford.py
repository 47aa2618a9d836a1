"""Loaders for the Oxford VGG multi-view data (the paper's Example 1).

Formats (see the data folder's README):

* ``*.P``: a 3x4 camera matrix, whitespace separated, world -> pixel;
* ``*.corners``: one ``x y`` per line; the 0-based line number is the corner index;
* ``*nview-corners``: one row per track, one column per view (views in file order),
  each entry a corner index or ``*`` (also ``-1``) when the point is not visible;
* dinosaur: ``viff.xy`` (x1 y1 ... x36 y36 per track, ``-1 -1`` missing) and
  ``dino_Ps.mat`` (variable ``P``: a 1x36 cell of 3x4 matrices, read with scipy).

The data directory is, in order: the ``data_dir`` argument, the environment variable
``TRITOOLS_DATA``, then ``../shared/data/oxford`` relative to the working directory
and to the repository.  The data are never part of the repository.

A missing directory, sequence or file raises :class:`DataNotFoundError`; a file that cannot be
read or does not follow its format raises :class:`ValueError` whose message starts with
``path:line:`` (or ``path:``), e.g. ``house.000.P:2: expected a number, got 'x'``.

World frame: the corridor and house reconstructions are *reflected* (every camera has det M < 0
and every track has w > 0: by Hartley & Zisserman's depth rule in a right-handed frame the whole
scene would lie behind every camera); the colleges and the dinosaur are right-handed.
:attr:`Sequence.world_frame` reads this off the tracks' own DLT points
(:func:`tritools.model.cameras.world_frame_of`), and ``tritools dataset`` judges ``in_front`` in it.
"""
from __future__ import annotations

import functools
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["DATA_ENV", "SEQUENCES", "PAPER_SEQUENCES", "Track", "Sequence", "data_dir", "load_sequence",
           "read_camera", "read_corners", "read_nview_corners", "DataNotFoundError"]

DATA_ENV = "TRITOOLS_DATA"
#: sequences of the paper's Example 1 (Tables 1-6), in its order.
PAPER_SEQUENCES = ("corridor", "dinosaur", "house", "library", "merton3", "wadham")
SEQUENCES = PAPER_SEQUENCES + ("merton1", "merton2")
#: :attr:`Sequence.world_frame` reads the handedness off this many tracks (the first ones).
FRAME_TRACKS = 500


class DataNotFoundError(FileNotFoundError):
    """The Oxford data directory, a sequence, or one of its files is missing."""
    pass


@dataclass(frozen=True)
class Track:
    """One scene point: its row in the track file and its observations."""
    track_id: int              # 0-based row of nview-corners / viff.xy
    views: tuple               # view indices (0-based, file order)
    points2d: np.ndarray       # (len(views), 2) pixels

    @property
    def n_views(self) -> int:
        return len(self.views)


@dataclass(frozen=True)
class Sequence:
    """An Oxford sequence: its cameras (V, 3, 4) and the tracks seen in at least ``min_views`` views."""
    name: str
    cameras: np.ndarray        # (V, 3, 4)
    tracks: tuple              # Tracks seen in >= min_views views

    def problem(self, track: Track):
        """(cameras, points2d) of one track."""
        return self.cameras[list(track.views)], track.points2d

    @functools.cached_property
    def world_frame(self):
        """The handedness of the sequence's world frame (:class:`~tritools.model.cameras.WorldFrame`), from the
        depths of the DLT points of (at most) the first :data:`FRAME_TRACKS` tracks in their own views."""
        from ..model.cameras import world_frame_of
        from ..model.geometry import PointAtInfinityError, dlt

        cams, pts = [], []                  # one (camera, point) pair per observation
        for t in self.tracks[:FRAME_TRACKS]:
            C = self.cameras[list(t.views)]
            try:
                X = dlt(C, t.points2d)
            except (PointAtInfinityError, ValueError):
                continue
            cams.append(C)
            pts.append(np.broadcast_to(X, (len(C), 3)))
        if not cams:
            raise ValueError(f"{self.name}: no track to read the world frame from")
        return world_frame_of(np.concatenate(cams)[:, None], np.concatenate(pts))

    def histogram(self) -> dict:
        out: dict[int, int] = {}
        for t in self.tracks:
            out[t.n_views] = out.get(t.n_views, 0) + 1
        return dict(sorted(out.items()))


def data_dir(path: str | os.PathLike | None = None) -> Path:
    """Resolve the Oxford data directory (argument, $TRITOOLS_DATA, ../shared/data/oxford)."""
    candidates = []
    if path is not None:
        candidates.append(Path(path))
    elif os.environ.get(DATA_ENV):
        candidates.append(Path(os.environ[DATA_ENV]))
    else:
        candidates.append(Path.cwd().parent / "shared" / "data" / "oxford")
        candidates.append(Path(__file__).resolve().parents[2] / "shared" / "data" / "oxford")
    for c in candidates:
        if c.is_dir():
            return c
    raise DataNotFoundError(f"Oxford data directory not found (tried {', '.join(map(str, candidates))}); "
                            f"pass data_dir=... or set ${DATA_ENV}")


def _read_text(path) -> str:
    """A data file's text: DataNotFoundError when it is missing, ValueError naming it when it is unreadable
    (a directory, no permission) or not text."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise DataNotFoundError(f"{path} is missing") from None
    except OSError as exc:
        raise ValueError(f"{path}: cannot read: {exc.strerror or exc}") from None
    try:
        return raw.decode("utf-8-sig")              # a byte-order mark skipped (review 29b F10)
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        raise ValueError(f"{path}:{line}: not a text file "
                         f"(byte 0x{raw[exc.start]:02x} at offset {exc.start})") from None


def _read_table(path, columns: int | None = None, what: str = "numbers") -> np.ndarray:
    """Whitespace-separated finite numbers, one row per non-empty line, every row of the same length
    (``columns`` when given); ValueError naming ``path:line`` otherwise.  Shape (rows, columns)."""
    rows = []
    for lineno, line in enumerate(_read_text(path).splitlines(), 1):
        tokens = line.split()
        if not tokens or tokens[0].startswith("#"):
            continue
        want = columns if columns is not None else (len(rows[0]) if rows else len(tokens))
        if len(tokens) != want:
            raise ValueError(f"{path}:{lineno}: expected {want} {what} per line, got {len(tokens)}")
        try:
            row = [float(t) for t in tokens]
        except ValueError:
            bad = next(t for t in tokens if not is_float(t))
            raise ValueError(f"{path}:{lineno}: expected a number, got {bad[:40]!r}") from None
        if not all(np.isfinite(row)):
            raise ValueError(f"{path}:{lineno}: non-finite number (NaN and Infinity are not allowed)")
        rows.append(row)
    if not rows:
        raise ValueError(f"{path}: no data")
    return np.array(rows, dtype=float)


def is_float(token: str) -> bool:
    """Does the text token parse as a float (``float(token)``)?  (Data files and the command line.)"""
    try:
        float(token)
    except ValueError:
        return False
    return True


def read_camera(path: Path) -> np.ndarray:
    """A 3x4 camera matrix from a ``*.P`` file (ValueError naming the file when it is not one)."""
    P = _read_table(path, 4, "numbers (a 3x4 camera matrix)")
    if P.shape != (3, 4):
        raise ValueError(f"{path}: expected a 3x4 camera matrix, got {P.shape[0]} rows")
    return P


def read_corners(path: Path) -> np.ndarray:
    """The ``x y`` rows of a ``*.corners`` file, shape (K, 2)."""
    return _read_table(path, 2, "numbers ('x y')")


def read_nview_corners(path: Path, n_views: int) -> list[list[int | None]]:
    """Rows of corner indices, None where missing (``*`` or ``-1``)."""
    return [row for _, row in _nview_rows(path, n_views)]


def _nview_rows(path: Path, n_views: int) -> list[tuple[int, list[int | None]]]:
    """(line number, row) of :func:`read_nview_corners`, for messages about a row's content."""
    rows = []
    for lineno, line in enumerate(_read_text(path).splitlines(), 1):
        tokens = line.split()
        if not tokens:
            continue
        if len(tokens) != n_views:
            raise ValueError(f"{path}:{lineno}: expected {n_views} entries, got {len(tokens)}")
        row = []
        for tok in tokens:
            if tok in ("*", "-1"):
                row.append(None)
            else:
                try:
                    row.append(int(tok))
                except ValueError:
                    raise ValueError(f"{path}:{lineno}: bad corner index {tok!r}") from None
        rows.append((lineno, row))
    return rows


def _view_files(folder: Path) -> list[tuple[Path, Path]]:
    """(NNN.P, NNN.corners) of every view, in name order; a view with one file but not the other is named (a
    missing camera file was reported as a wrong count in nview-corners: review 29b F8)."""
    Ps = sorted(folder.glob("*.P"), key=lambda p: p.name)
    if not Ps:
        raise DataNotFoundError(f"{folder}: no *.P camera files")
    for corners in sorted(folder.glob("*.corners"), key=lambda p: p.name):
        if not corners.with_suffix(".P").exists():
            raise DataNotFoundError(f"{corners.with_suffix('.P')} is missing (its {corners.name} is there)")
    pairs = []
    for P in Ps:
        corners = P.with_suffix(".corners")
        if not corners.exists():
            raise DataNotFoundError(f"{corners} is missing")
        pairs.append((P, corners))
    return pairs


def _load_vgg(folder: Path, name: str, min_views: int) -> Sequence:
    views = _view_files(folder)
    cameras = np.array([read_camera(p) for p, _ in views])
    corners = [read_corners(c) for _, c in views]
    nv = [p for p in folder.glob("*nview-corners") if not p.name.endswith("~")]
    if len(nv) != 1:
        raise DataNotFoundError(f"{folder}: expected one *nview-corners file, found {len(nv)}")
    tracks = []
    for tid, (lineno, row) in enumerate(_nview_rows(nv[0], len(views))):
        vis = [(v, k) for v, k in enumerate(row) if k is not None]
        if len(vis) < min_views:
            continue
        for v, k in vis:
            if not 0 <= k < len(corners[v]):
                raise ValueError(f"{nv[0]}:{lineno}: track {tid} refers to corner {k} of view {v}, "
                                 f"which has {len(corners[v])} corners")
        tracks.append(Track(tid, tuple(v for v, _ in vis), np.array([corners[v][k] for v, k in vis])))
    return Sequence(name, cameras, tuple(tracks))


def _read_dino_cameras(path: Path) -> np.ndarray:
    """The (V, 3, 4) cameras of ``dino_Ps.mat`` (variable ``P``, a 1xV cell of 3x4 matrices)."""
    from scipy.io import loadmat

    if not path.exists():
        raise DataNotFoundError(f"{path} is missing")
    try:
        mat = loadmat(path)
    except Exception as exc:  # noqa: BLE001 - scipy raises many types for a file that is not MATLAB data
        raise ValueError(f"{path}: not a readable MATLAB file ({type(exc).__name__}: {exc})") from None
    if "P" not in mat:
        raise ValueError(f"{path}: no variable 'P'")
    try:
        cameras = np.array([np.asarray(p, float) for p in np.asarray(mat["P"], dtype=object).ravel()])
    except (TypeError, ValueError):
        cameras = None
    if cameras is None or cameras.ndim != 3 or cameras.shape[1:] != (3, 4) or not np.all(np.isfinite(cameras)):
        raise ValueError(f"{path}: variable 'P' must be a cell of finite 3x4 camera matrices")
    return cameras


def _load_dinosaur(folder: Path, min_views: int) -> Sequence:
    cameras = _read_dino_cameras(folder / "dino_Ps.mat")
    V = cameras.shape[0]
    xy = _read_table(folder / "viff.xy", 2 * V, f"numbers (x y for each of the {V} cameras)")
    tracks = []
    for tid, row in enumerate(xy):
        pts = row.reshape(V, 2)
        vis = [v for v in range(V) if not np.all(pts[v] == -1.0)]
        if len(vis) >= min_views:
            tracks.append(Track(tid, tuple(vis), pts[vis].copy()))
    return Sequence("dinosaur", cameras, tuple(tracks))


def load_sequence(name: str, data_dir_: str | os.PathLike | None = None, min_views: int = 2) -> Sequence:
    """Load one Oxford sequence (cameras and tracks seen in >= ``min_views`` views)."""
    if not re.fullmatch(r"[A-Za-z0-9_]+", str(name)):
        raise ValueError(f"bad sequence name {name!r}")
    folder = data_dir(data_dir_) / name
    if not folder.is_dir():
        raise DataNotFoundError(f"sequence {name!r} not found in {folder.parent} (known: {', '.join(SEQUENCES)})")
    if (folder / "viff.xy").exists():
        return _load_dinosaur(folder, min_views)
    return _load_vgg(folder, name, min_views)
