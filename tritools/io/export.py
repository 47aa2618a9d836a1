"""Point-cloud exports with certificate fields: binary PLY and numpy .npz, with small readers.

* :func:`write_ply` writes a binary little-endian PLY with one ``vertex`` element: ``x y z``
  (double), ``red green blue`` (uchar) and any extra per-vertex properties (numpy dtypes mapped to
  PLY types: double, float, int, uint, short, ushort, char, uchar; bool as uchar).  Viewers
  (MeshLab, CloudCompare, Open3D) show the extra properties as scalar fields.
* :func:`write_npz` writes the same arrays to an ``.npz`` (loadable without pickle).
* :func:`export_points` writes the certificate fields of a re-triangulation
  (:class:`tritools.sfm.RetriangulationReport`): ``point3D_id``, ``gamma_lb``, ``gamma_ub``,
  ``certified``, ``status`` (a code, legend :data:`STATUS_LEGEND`), ``in_front``; the .npz adds
  ``n_views``, ``updated``, ``delta``, ``gamma_input``, ``certified_by`` (codes, legend
  :data:`CERTIFIED_BY_LEGEND`) and the legends themselves.  The PLY header carries the status
  legend as a comment.

:func:`write_ply` and :func:`write_npz` write to a temporary file next to ``path`` and rename it
into place, so an existing file is replaced only by a complete one.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..result import Status
from .atomic import atomic_path

__all__ = ["write_ply", "read_ply", "write_npz", "read_npz", "export_points", "STATUS_LEGEND",
           "CERTIFIED_BY_LEGEND", "PLY_TYPES"]

#: status code -> value (the codes of the exports; same order as :class:`tritools.Status`).
STATUS_LEGEND = tuple(s.value for s in Status)
#: certified_by code -> value ("" when not certified).
CERTIFIED_BY_LEGEND = ("", "verification", "sdp", "trivial_bound", "branch-and-bound", "sub_problem")
#: PLY type name -> little-endian numpy dtype.
PLY_TYPES = {"char": "i1", "uchar": "u1", "short": "<i2", "ushort": "<u2", "int": "<i4", "uint": "<u4",
             "float": "<f4", "double": "<f8"}
_PLY_ALIASES = {"int8": "char", "uint8": "uchar", "int16": "short", "uint16": "ushort", "int32": "int",
                "uint32": "uint", "float32": "float", "float64": "double"}
_NP_TO_PLY = {np.dtype(v).str.lstrip("<|"): k for k, v in PLY_TYPES.items()}


def _atomic(path, write) -> Path:
    with atomic_path(path) as tmp:
        write(tmp)
    return Path(path)


def _columns(xyz, rgb, fields) -> dict:
    xyz = np.asarray(xyz, float).reshape(-1, 3)
    n = len(xyz)
    cols = {"x": xyz[:, 0], "y": xyz[:, 1], "z": xyz[:, 2]}
    if rgb is not None:
        rgb = np.asarray(rgb)
        if rgb.shape != (n, 3) or (rgb.size and (rgb.min() < 0 or rgb.max() > 255)):
            raise ValueError(f"rgb must be ({n}, 3) integers in 0..255, got shape {rgb.shape}")
        cols.update(red=rgb[:, 0].astype(np.uint8), green=rgb[:, 1].astype(np.uint8), blue=rgb[:, 2].astype(np.uint8))
    for name, v in fields.items():
        a = np.asarray(v)
        if a.shape != (n,):
            raise ValueError(f"field {name!r} must have shape ({n},), got {a.shape}")
        if not name.isidentifier():
            raise ValueError(f"field name {name!r} must be an identifier")
        cols[name] = a.astype(np.uint8) if a.dtype == bool else a
    return cols


def _write_ply_file(path, cols: dict, comments) -> None:
    types = {}
    for name, a in cols.items():
        key = a.dtype.str.lstrip("<|=")
        if key not in _NP_TO_PLY:
            raise ValueError(f"field {name!r}: dtype {a.dtype} has no PLY type (use one of {', '.join(PLY_TYPES)})")
        types[name] = _NP_TO_PLY[key]
    n = len(cols["x"])
    header = ["ply", "format binary_little_endian 1.0"] + [f"comment {' '.join(str(c).split())}" for c in comments]
    header += [f"element vertex {n}"] + [f"property {types[k]} {k}" for k in cols] + ["end_header"]
    dtype = np.dtype([(k, PLY_TYPES[types[k]]) for k in cols])
    rec = np.empty(n, dtype)
    for k, a in cols.items():
        rec[k] = a
    with open(path, "wb") as fh:
        fh.write(("\n".join(header) + "\n").encode("ascii"))
        fh.write(rec.tobytes())


def write_ply(path, xyz, rgb=None, comments=(), **fields) -> Path:
    """Binary little-endian PLY of points ``xyz`` (n, 3), colours ``rgb`` (n, 3) and extra
    per-vertex ``fields`` (name -> (n,) array); written atomically.  Returns the path."""
    cols = _columns(xyz, rgb, fields)
    return _atomic(path, lambda p: _write_ply_file(p, cols, comments))


def read_ply(path) -> tuple[dict, list]:
    """Read a binary little-endian PLY with one ``vertex`` element (as :func:`write_ply` writes):
    ``({property name: array}, [comments])``."""
    path = Path(path)
    data = path.read_bytes()
    end = data.find(b"end_header\n")
    if not data.startswith(b"ply\n") or end < 0:
        raise ValueError(f"{path}: not a PLY file (no 'ply' magic or 'end_header')")
    lines = data[:end].decode("ascii").splitlines()
    comments, props, n, fmt = [], [], None, None
    for line in lines[1:]:
        t = line.split()
        if not t:
            continue
        if t[0] == "format":
            fmt = t[1]
        elif t[0] == "comment":
            comments.append(line[8:])
        elif t[0] == "element":
            if t[1] != "vertex" or n is not None:
                raise ValueError(f"{path}: only one 'vertex' element is supported, got {line!r}")
            n = int(t[2])
        elif t[0] == "property":
            if t[1] == "list":
                raise ValueError(f"{path}: list properties are not supported")
            kind = _PLY_ALIASES.get(t[1], t[1])
            if kind not in PLY_TYPES:
                raise ValueError(f"{path}: unknown property type {t[1]!r}")
            props.append((t[2], PLY_TYPES[kind]))
    if fmt != "binary_little_endian" or n is None:
        raise ValueError(f"{path}: expected format binary_little_endian with a vertex element, got {fmt!r}")
    dtype = np.dtype(props)
    body = data[end + len(b"end_header\n"):]
    if len(body) != n * dtype.itemsize:
        raise ValueError(f"{path}: {n} vertices need {n * dtype.itemsize} bytes, the body has {len(body)}")
    rec = np.frombuffer(body, dtype, n)
    return {k: rec[k].copy() for k, _ in props}, comments


def write_npz(path, xyz, rgb=None, **fields) -> Path:
    """``.npz`` with ``xyz`` (n, 3), ``rgb`` (n, 3) uint8 when given, and the ``fields``
    (arrays of any numeric or fixed-width string dtype); written atomically."""
    cols = {"xyz": np.asarray(xyz, float).reshape(-1, 3)}
    if rgb is not None:
        cols["rgb"] = np.asarray(rgb).astype(np.uint8).reshape(-1, 3)
    for k, v in fields.items():
        a = np.asarray(v)
        if a.dtype == object:
            raise ValueError(f"field {k!r}: object arrays cannot be stored without pickle")
        cols[k] = a

    def write(p):
        """Write the arrays to the temporary path."""
        with open(p, "wb") as fh:                     # a file object: np.savez adds no suffix
            np.savez(fh, **cols)
    return _atomic(path, write)


def read_npz(path) -> dict:
    """The arrays of an .npz (no pickle)."""
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def export_points(path, xyz, rgb, report, fmt: str | None = None) -> Path:
    """Write points with the certificate fields of ``report`` (a
    :class:`tritools.sfm.RetriangulationReport`, same point order) as .ply or .npz (``fmt``
    "ply"/"npz", default from the suffix).  Not atomic by itself (callers stage it)."""
    fmt = fmt or Path(path).suffix.lower().lstrip(".")
    legend = ", ".join(f"{k} {v}" for k, v in enumerate(STATUS_LEGEND))
    base = {"point3D_id": np.asarray(report.point_ids), "gamma_lb": report.gamma_lb, "gamma_ub": report.gamma_ub,
            "certified": report.certified.astype(np.uint8), "status": report.status.astype(np.uint8),
            "in_front": report.in_front.astype(np.uint8)}
    if fmt == "ply":
        ids = base["point3D_id"]
        if ids.size and (ids.min() < 0 or ids.max() >= 2 ** 32):
            raise ValueError("point3D ids do not fit PLY's uint")
        base["point3D_id"] = ids.astype(np.uint32)
        cols = _columns(xyz, rgb, base)
        _write_ply_file(path, cols, ["tritools certified re-triangulation (Chesi 2026); gamma in undistorted "
                                     "pixels", f"status codes: {legend}"])
    elif fmt == "npz":
        by = np.array([CERTIFIED_BY_LEGEND.index(b) if b in CERTIFIED_BY_LEGEND else 0
                       for b in report.certified_by], np.uint8)
        cols = dict(base, n_views=report.n_views, updated=report.updated, delta=report.delta,
                    gamma_input=report.gamma_input, certified_by=by, status_legend=np.array(STATUS_LEGEND),
                    certified_by_legend=np.array(CERTIFIED_BY_LEGEND))
        cols["xyz"] = np.asarray(xyz, float).reshape(-1, 3)
        cols["rgb"] = np.asarray(rgb).astype(np.uint8).reshape(-1, 3)
        with open(path, "wb") as fh:
            np.savez(fh, **cols)
    else:
        raise ValueError(f"export format must be ply or npz, got {fmt!r}")
    return Path(path)
