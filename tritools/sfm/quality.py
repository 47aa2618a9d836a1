"""Per-point quality of a COLMAP model: triangulation angle, certified uncertainty, filters.

For every point of a model (cameras and poses fixed, keypoints undistorted as in
:mod:`.pipeline`):

* ``angle_deg``: the largest angle between two of its usable viewing rays
  (:func:`tritools.uncertain.triangulation_angles`);
* with a keypoint radius R (pixels, undistorted; or one per observation from a file of lines
  ``IMAGE_ID POINT2D_IDX RADIUS``, :func:`read_keypoint_radii`): the certified uncertainty of the point
  (docs/uncertainty.md): the set S of scene points whose projection lies within R of every
  observed keypoint and in front of the cameras -- ``radius`` bounds ``||X - xyz||`` over S
  (inf when S is unbounded, NaN when it is empty: R is smaller than the observations' own
  inconsistency), ``depth_lo``/``depth_hi`` the depth interval in the track's first usable view,
  ``depth_ratio`` the largest ``depth_hi / depth_lo`` over the track's views;
* filters: ``min_angle`` (degrees), ``max_error`` (COLMAP's mean reprojection error in pixels),
  ``max_uncertainty`` (world units, needs R), ``max_depth_ratio`` (needs R).  COLMAP's own mapper
  defaults are ``filter_min_tri_angle = 1.5`` degrees and ``filter_max_reproj_error = 4`` pixels
  (:data:`COLMAP_MIN_TRI_ANGLE`, :data:`COLMAP_MAX_REPROJ_ERROR`); ours are off unless given.

The sidecar ``points3D_uncertainty.txt`` (:func:`write_quality`) has one line per point of the
model *before* filtering, with KEPT 0/1.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from ..io.colmap.arrays import ModelArrays
from ..uncertain import UncertaintyOptions, triangulation_angles, uncertainty_discs
from ..solve.options import OptionError
from .pipeline import ModelGeometry

__all__ = ["QualityOptions", "PointQuality", "point_quality", "drop_points", "write_quality", "apply_quality_folder",
           "apply_quality_staged",
           "read_keypoint_radii",
           "QUALITY_FILE",
           "COLMAP_MIN_TRI_ANGLE", "COLMAP_MAX_REPROJ_ERROR"]

#: COLMAP's mapper default minimum triangulation angle (degrees) and maximum reprojection error (pixels).
COLMAP_MIN_TRI_ANGLE = 1.5
COLMAP_MAX_REPROJ_ERROR = 4.0
QUALITY_FILE = "points3D_uncertainty.txt"
_COLUMNS = ("POINT3D_ID", "N_VIEWS", "ANGLE_DEG", "ERROR", "STATUS", "RADIUS", "DEPTH_LO", "DEPTH_HI",
            "DEPTH_RATIO", "KEPT")


@dataclass(frozen=True)
class QualityOptions:
    """Keypoint radius (pixels, > 0) and filter thresholds; None: not used.  ``exact_depths``:
    solve the depth bound problems (else the depths are bounded over the certified box: rigorous,
    looser, faster)."""
    keypoint_radius: float | None = None
    min_angle: float | None = None
    max_error: float | None = None
    max_uncertainty: float | None = None
    max_depth_ratio: float | None = None
    exact_depths: bool = False
    keypoint_radii: str | Path | None = None

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "keypoint_radii":
                if v is not None:
                    try:
                        _parse_radii(v)
                    except (OSError, ValueError) as exc:
                        raise OptionError(f.name, str(exc)) from None
                continue
            if f.name == "exact_depths":
                if not isinstance(v, (bool, np.bool_)):
                    raise OptionError(f.name, f"must be True or False, got {v!r}")
                continue
            if v is None:
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) or not np.isfinite(v):
                raise OptionError(f.name, f"must be a finite number, got {v!r}")
            low_ok = v > 0 if f.name in ("keypoint_radius", "max_uncertainty") else \
                v >= 1 if f.name == "max_depth_ratio" else v >= 0
            if not low_ok or (f.name == "min_angle" and v > 180):      # an angle between rays is <= 180 deg
                if f.name == "min_angle":
                    raise OptionError(f.name, f"out of range [0, 180] degrees, got {v!r}")
                raise OptionError(f.name, f"out of range, got {v!r}")
        for name in ("max_uncertainty", "max_depth_ratio"):
            if getattr(self, name) is not None and self.keypoint_radius is None and self.keypoint_radii is None:
                raise OptionError(name, "needs keypoint_radius (the uncertainty is that of keypoints within the "
                                        "radius)")

    @property
    def active(self) -> bool:
        return any(getattr(self, f.name) is not None for f in fields(self) if f.name != "exact_depths")

    @property
    def filtering(self) -> bool:
        """A filter is set (points may be removed from the model)."""
        return any(getattr(self, k) is not None for k in ("min_angle", "max_error", "max_uncertainty",
                                                           "max_depth_ratio"))

    @property
    def uncertain(self) -> bool:
        """Keypoint radii are given (a default radius and/or a file)."""
        return self.keypoint_radius is not None or self.keypoint_radii is not None


@dataclass(frozen=True, eq=False)
class PointQuality:
    """Per-point arrays (in the arrays' point order); ``status`` a string per point ("" without
    a keypoint radius, else an :class:`tritools.UncertaintyStatus` value, "too_few_views")."""
    point_ids: np.ndarray
    n_views: np.ndarray
    angle_deg: np.ndarray
    error: np.ndarray
    status: np.ndarray
    radius: np.ndarray
    depth_lo: np.ndarray
    depth_hi: np.ndarray
    depth_ratio: np.ndarray
    kept: np.ndarray

    def summary(self) -> dict:
        """Counts, JSON-ready."""
        st, cnt = np.unique(self.status[self.status != ""], return_counts=True)
        fin = np.isfinite(self.radius)
        return {"n_points": int(len(self.point_ids)), "n_kept": int(np.count_nonzero(self.kept)),
                "n_removed": int(np.count_nonzero(~self.kept)),
                "median_angle_deg": _nan_median(self.angle_deg),
                "median_radius": float(np.median(self.radius[fin])) if np.any(fin) else None,
                "uncertainty_status": {str(k): int(c) for k, c in zip(st, cnt)}}


def _nan_median(values: np.ndarray) -> float | None:
    """Median of the defined values (an angle is NaN at a camera centre), None when there is none."""
    fin = values[np.isfinite(values)]
    return float(np.median(fin)) if len(fin) else None


def _usable(arrays: ModelArrays, geom: ModelGeometry):
    """(owner point, image index, global keypoint row) of the usable observations."""
    owner = np.repeat(np.arange(arrays.n_points), np.diff(arrays.track_offsets))
    gk = arrays.kp_offsets[arrays.track_image] + arrays.track_kp
    use = geom.image_ok[arrays.track_image] & geom.kp_ok[gk]
    return owner[use], arrays.track_image[use], gk[use]


def _parse_radii(path) -> list:
    """[(file:line, image_id, point2D_idx, radius, text)] of a radii file (syntax and radius > 0 checked)."""
    out = []
    try:
        text = Path(path).read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:                   # (review 31b F7: the message named no file)
        raise ValueError(f"{path}: not UTF-8 text (byte {exc.start}: {exc.reason})") from None
    for n, line in enumerate(text.splitlines(), 1):
        t = line.split("#", 1)[0].split()
        if not t:
            continue
        where = f"{path}:{n}"
        try:
            if len(t) != 3:
                raise ValueError
            img, idx, r = int(t[0]), int(t[1]), float(t[2])
        except ValueError:
            raise ValueError(f"{where}: expected 'IMAGE_ID POINT2D_IDX RADIUS', got {line.strip()!r}") from None
        if not (np.isfinite(r) and r > 0):
            raise ValueError(f"{where}: RADIUS must be finite and > 0, got {t[2]}")
        out.append((where, img, idx, r))
    return out


def read_keypoint_radii(path, arrays: ModelArrays, default: float | None) -> np.ndarray:
    """Radius (pixels) of every keypoint row of ``arrays`` from a text file of lines
    ``IMAGE_ID POINT2D_IDX RADIUS`` (``#`` comments); unlisted keypoints get ``default`` (NaN if None).
    ValueError naming ``file:line`` for a malformed line or a radius <= 0 (the options' check, where it becomes an
    :class:`OptionError` of ``keypoint_radii``), an OptionError of ``keypoint_radii`` naming ``file:line`` for an
    unknown keypoint: one form of message for every error of the file (review 31b F7)."""
    out = np.full(len(arrays.kp_xy), np.nan if default is None else float(default))
    index = {int(i): k for k, i in enumerate(arrays.image_ids.tolist())}
    first: dict = {}
    for where, img, idx, r in _parse_radii(path):
        if img not in index:
            raise OptionError("keypoint_radii", f"{where}: unknown IMAGE_ID {img}")
        v = index[img]
        if not 0 <= idx < arrays.kp_offsets[v + 1] - arrays.kp_offsets[v]:
            raise OptionError("keypoint_radii", f"{where}: image {img} has no keypoint {idx}")
        row = int(arrays.kp_offsets[v] + idx)
        if row in first:            # (the last one won, silently: review 27a)
            raise OptionError("keypoint_radii",
                              f"{where}: image {img} keypoint {idx} listed again (first at {first[row]})")
        first[row] = where
        out[row] = r
    return out


def point_quality(arrays: ModelArrays, geom: ModelGeometry, options: QualityOptions) -> PointQuality:
    """Angles, uncertainty and the filter decision of every point (module docstring)."""
    P = arrays.n_points
    kp_r = None
    if options.keypoint_radii is not None:
        kp_r = read_keypoint_radii(options.keypoint_radii, arrays, options.keypoint_radius)
    own, img, gk = _usable(arrays, geom)
    n = np.bincount(own, minlength=P)
    centres = -np.einsum("vji,vj->vi", geom.R, geom.t)                    # C = -R' t
    angle = np.zeros(P)
    status = np.full(P, "", dtype=object)
    radius, dlo, dhi, ratio = (np.full(P, np.nan) for _ in range(4))
    order = np.argsort(own, kind="stable")
    own, img, gk = own[order], img[order], gk[order]
    start = np.concatenate([[0], np.cumsum(n)])
    for k in np.unique(n):
        pts = np.nonzero(n == k)[0]
        if k < 2:
            status[pts] = "too_few_views" if options.uncertain else ""
            continue
        rows = start[pts][:, None] + np.arange(k)[None, :]
        X = arrays.point_xyz[pts]
        angle[pts] = triangulation_angles(centres[img[rows]], X)
        if not options.uncertain:
            continue
        radii = float(options.keypoint_radius) if kp_r is None else kp_r[gk[rows]]
        if kp_r is not None and np.any(np.isnan(radii)):
            j = np.argwhere(np.isnan(radii))[0]
            raise OptionError("keypoint_radii", f"{options.keypoint_radii}: no radius for point3D "
                              f"{int(arrays.point_ids[pts[j[0]]])}'s observation {int(j[1])} and no default "
                              "(keypoint_radius, --keypoint-radius)")
        Pc, Xc = geom.certified_frame(X)       # a georeferenced model: its local frame (radii and depths are the same)
        res = uncertainty_discs(Pc[img[rows]], geom.xy_u[gk[rows]], radii, Xc,
                                UncertaintyOptions(depth_bounds=bool(options.exact_depths)))
        for j, r in zip(pts, res):
            status[j] = r.status.value
            radius[j] = r.max_distance
            dlo[j], dhi[j] = r.depth_lo[0], r.depth_hi[0]
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio[j] = float(np.max(r.depth_hi / r.depth_lo)) if r.status.value != "empty" else np.nan
    err = np.asarray(arrays.point_error, float)
    keep = np.ones(P, bool)
    if options.min_angle is not None:
        keep &= angle >= options.min_angle
    if options.max_error is not None:
        keep &= err <= options.max_error
    if options.max_uncertainty is not None:
        keep &= radius <= options.max_uncertainty              # NaN (empty, too few views) fails
    if options.max_depth_ratio is not None:
        keep &= ratio <= options.max_depth_ratio
    return PointQuality(arrays.point_ids.copy(), n, angle, err, status.astype(str), radius, dlo, dhi, ratio, keep)


def drop_points(arrays: ModelArrays, keep: np.ndarray) -> ModelArrays:
    """The model without the points where ``keep`` is False (their keypoints' POINT3D_ID set to -1)."""
    keep = np.asarray(keep, bool)
    lengths = np.diff(arrays.track_offsets)
    obs_keep = np.repeat(keep, lengths)
    dropped = np.setdiff1d(arrays.point_ids, arrays.point_ids[keep])
    kp = arrays.kp_point3D.copy()
    kp[np.isin(kp, dropped)] = -1
    f = {k: getattr(arrays, k) for k in arrays.__dataclass_fields__}
    f.update(point_ids=arrays.point_ids[keep], point_xyz=arrays.point_xyz[keep], point_rgb=arrays.point_rgb[keep],
             point_error=arrays.point_error[keep], kp_point3D=kp,
             track_offsets=np.concatenate([[0], np.cumsum(lengths[keep])]).astype(np.int64),
             track_image=arrays.track_image[obs_keep], track_kp=arrays.track_kp[obs_keep])
    return ModelArrays(**f)


def write_quality(folder, q: PointQuality, options: QualityOptions) -> Path:
    """``points3D_uncertainty.txt`` in ``folder`` (module docstring); floats as ``repr``."""
    path = Path(folder) / QUALITY_FILE
    head = [f"# Per-point quality (tritools): {', '.join(_COLUMNS)}",
            f"# keypoint radius {options.keypoint_radius} px (undistorted); RADIUS: certified bound on |X - xyz| "
            "over the points whose projections lie within the radius of every keypoint (inf: unbounded, nan: "
            "empty or not computed); DEPTH_LO/HI: certified depth interval in the track's first view",
            f"# filters: min_angle {options.min_angle} deg, max_error {options.max_error} px, max_uncertainty "
            f"{options.max_uncertainty}, max_depth_ratio {options.max_depth_ratio} (COLMAP's mapper defaults: "
            f"{COLMAP_MIN_TRI_ANGLE} deg, {COLMAP_MAX_REPROJ_ERROR} px)"]
    rows = zip(q.point_ids.tolist(), q.n_views.tolist(), q.angle_deg.tolist(), q.error.tolist(), q.status.tolist(),
               q.radius.tolist(), q.depth_lo.tolist(), q.depth_hi.tolist(), q.depth_ratio.tolist(), q.kept.tolist())
    lines = [f"{p} {n} {a!r} {e!r} {s or '-'} {r!r} {lo!r} {hi!r} {dr!r} {int(k)}"
             for p, n, a, e, s, r, lo, hi, dr, k in rows]
    path.write_text("\n".join(head + lines) + "\n", encoding="utf-8")
    return path


def _update_export(path: Path, q: PointQuality, filtered: bool) -> None:
    """Add the quality columns to an export of :func:`tritools.io.export.export_points` (matched by
    point3D_id), dropping the removed points when filtering."""
    from ..io.export import read_npz, read_ply, write_npz, write_ply

    index = {int(p): i for i, p in enumerate(q.point_ids.tolist())}
    if path.suffix.lower() == ".ply":
        cols, comments = read_ply(path)
    else:
        cols, comments = read_npz(path), []
    rows = np.array([index.get(int(p), -1) for p in cols["point3D_id"]], np.int64)
    ok = rows >= 0
    if filtered:
        ok &= q.kept[np.maximum(rows, 0)]
    r = rows[ok]
    extra = {"angle_deg": q.angle_deg[r], "radius": q.radius[r], "depth_lo": q.depth_lo[r],
             "depth_hi": q.depth_hi[r], "depth_ratio": q.depth_ratio[r], "kept": q.kept[r].astype(np.uint8)}
    if path.suffix.lower() == ".ply":
        xyz = np.column_stack([cols.pop("x"), cols.pop("y"), cols.pop("z")])[ok]
        rgb = np.column_stack([cols.pop("red"), cols.pop("green"), cols.pop("blue")])[ok] if "red" in cols else None
        rest = {k: v[ok] for k, v in cols.items()}
        write_ply(path, xyz, rgb, comments + ["quality: angle_deg, certified uncertainty radius and depth interval "
                                              "(tritools.sfm.quality)"], **rest, **extra)
    else:
        n = len(cols["point3D_id"])
        rest = {k: (v[ok] if v.ndim and len(v) == n and k not in ("xyz", "rgb") else v) for k, v in cols.items()}
        rest["xyz"], rest["rgb"] = cols["xyz"][ok], cols["rgb"][ok]
        xyz, rgb = rest.pop("xyz"), rest.pop("rgb")
        write_npz(path, xyz, rgb, **rest, **extra)


def apply_quality_staged(stage, options: QualityOptions, exports=()) -> PointQuality:
    """:func:`apply_quality_folder` on a staged output that the caller commits (``tritools colmap``: inside the
    stage of :func:`tritools.sfm.folder.retriangulate_folder`, so that a bad radius file or any other failure
    leaves OUT_DIR and the exports as they were): the model files in ``stage`` are rewritten in place,
    :data:`QUALITY_FILE` is added, and ``exports`` (their staged paths) get the quality columns."""
    from ..io.colmap.formats import detect_format, read_model_arrays, write_model_arrays
    from .certificates import CERTIFICATES_FILE, mark_removed
    from .pipeline import prepare_geometry

    stage = Path(stage)
    fmt = detect_format(stage)
    arrays = read_model_arrays(stage, fmt)
    q = point_quality(arrays, prepare_geometry(arrays), options)
    filtered = options.filtering
    write_model_arrays(drop_points(arrays, q.kept) if filtered else arrays, stage, fmt)
    if filtered and (stage / CERTIFICATES_FILE).is_file():
        mark_removed(stage, q.point_ids[~q.kept])          # the sidecar describes the written model
    write_quality(stage, q, options)
    for e in exports:
        _update_export(Path(e), q, filtered)
    return q


def apply_quality_folder(folder, options: QualityOptions, exports=()) -> PointQuality:
    """Compute the quality of the model in ``folder`` (a ``tritools colmap`` output), write
    :data:`QUALITY_FILE`, remove the filtered points from the model (when a filter is set) and add
    the quality columns to ``exports``; the folder is replaced atomically (:func:`apply_quality_staged` on a
    copy staged in it), then the exports are updated, each atomically."""
    import shutil

    from .folder import atomic_directory

    folder = Path(folder)
    with atomic_directory(folder) as tmp:
        for f in folder.iterdir():
            if f.is_file():
                shutil.copyfile(f, tmp / f.name)
        q = apply_quality_staged(tmp, options)
    filtered = options.filtering
    for e in exports:
        _update_export(Path(e), q, filtered)
    return q
