"""Command-line subcommands for COLMAP models (registered by :mod:`tritools.cli.app`).

* ``colmap IN_DIR OUT_DIR``: read the COLMAP model in IN_DIR (binary ``*.bin`` or text ``*.txt``,
  detected), re-triangulate every 3D point with a certificate of global optimality, write the model
  (same format unless ``--output-type``), ``points3D_certificates.txt`` and copies of
  ``rigs``/``frames`` files to OUT_DIR -- staged, then each file renamed over its namesake once
  everything was written; nothing else in OUT_DIR is touched -- and print a summary (or JSON).
* ``colmap-from-oxford NAME OUT_DIR``: convert an Oxford VGG sequence to a COLMAP model.

Exit codes: 0 success (whatever the points' statuses), 2 bad input, bad option or unusable output
path -- one line ``tritools: error: ...`` naming the file and line/record, or the flag; 3 the model was
written but cameras that cannot be used (EQUIRECTANGULAR, a pycolmap-only model without pycolmap, focal
<= 0) left observations out -- one line ``tritools: warning: ...`` with the counts on stderr.
"""
from __future__ import annotations

import contextlib
import dataclasses
import json
import logging
import sys
from pathlib import Path

import numpy as np

from .app import (CLIError, add_data_dir_option, add_robust_option, add_solver_options, exit_invalid, option_flag_error,
                  options_from_args, printable, refuse_input_as_output, robust_from_args)
from .workers import executor_from_args
from ..io.problem_file import jsonable

__all__ = ["register", "run_colmap", "run_from_oxford", "MAX_LISTED", "EXIT_CAMERAS_SKIPPED"]

#: uncertified points listed in the text summary.
MAX_LISTED = 10
#: exit status of ``tritools colmap`` when unusable cameras left observations out (the model is written).
EXIT_CAMERAS_SKIPPED = 3


def register(subparsers) -> None:
    """Add the ``colmap`` and ``colmap-from-oxford`` subcommands."""
    from ..sfm.pipeline import BEHIND_CHOICES, DEFAULT_MAX_TRACK_LENGTH
    from ..sfm.retriangulate import PROGRESS_MIN_POINTS
    from .workers import add_worker_options

    p = subparsers.add_parser(
        "colmap", help="certified re-triangulation of a COLMAP model (binary or text)",
        description="Read the COLMAP model in IN_DIR (cameras/images/points3D as .bin or .txt), re-triangulate "
                    "every 3D point with a certificate of global optimality (cameras fixed), and write the model, "
                    "points3D_certificates.txt and copies of rigs/frames files to OUT_DIR. Everything is staged "
                    "first; each file then replaces its namesake in OUT_DIR, nothing else in OUT_DIR is touched, "
                    "and OUT_DIR is left exactly as it was if anything fails. The solver flags and "
                    "their defaults are those of 'tritools solve': method auto (Corollary 1 at delta = 2, then "
                    "delta = 4 for the points that does not certify), each point within --time-limit and "
                    "--memory-limit; --max-delta 2 keeps every point at delta = 2. --progress: a bar over all "
                    f"points (by default only for models of {PROGRESS_MIN_POINTS} points or more). --workers N / "
                    "--scheduler ADDRESS: where the per-point SDPs run. Exit status 3 (after writing the model): "
                    "cameras that cannot be used (EQUIRECTANGULAR, focal <= 0, ...) left observations out.")
    p.add_argument("in_dir", metavar="IN_DIR", help="folder of the input model (never modified)")
    p.add_argument("out_dir", metavar="OUT_DIR", help="output folder (created if needed; only the files written are "
                                                      "replaced; must not be IN_DIR, contain IN_DIR, or be a file)")
    p.add_argument("--input-type", choices=("auto", "bin", "txt"), default="auto",
                   help="format of IN_DIR (default auto: binary if cameras.bin, images.bin, points3D.bin exist, "
                        "else text)")
    p.add_argument("--output-type", choices=("bin", "txt"), default=None,
                   help="format of OUT_DIR (default: that of IN_DIR)")
    add_solver_options(p, progress_help=f"progress bar on stderr, moved per stack of equal track lengths (needs the "
                                        f"'progress' extra, tqdm; default: only for models of {PROGRESS_MIN_POINTS} "
                                        f"points or more)")   # the flags and defaults of `tritools solve`
    add_robust_option(p)             # --robust C: outlier observations leave the tracks (POINT3D_ID -1)
    add_worker_options(p)
    p.add_argument("--min-track-length", type=int, default=2, metavar="K",
                   help="do not solve points with fewer than K usable observations (default 2)")
    p.add_argument("--max-track-length", type=int, default=DEFAULT_MAX_TRACK_LENGTH, metavar="K",
                   help=f"do not solve points with more than K usable observations (default "
                        f"{DEFAULT_MAX_TRACK_LENGTH}; the certificate's cost grows as K^4)")
    p.add_argument("--behind", choices=BEHIND_CHOICES, default="keep-input",
                   help="a point whose estimate lies behind one of its cameras: keep the input xyz (default) or "
                        "write the estimate; either way IN_FRONT = 0 and CERTIFIED = 0 in the sidecar")
    p.add_argument("--strict", action="store_true",
                   help="refuse the model (exit 2) when a camera cannot be used (unsupported model, focal <= 0) "
                        "instead of leaving its observations out")
    p.add_argument("--export", action="append", default=[], metavar="FILE",
                   help="also write the points with their certificate fields to FILE (.ply or .npz; repeatable)")
    p.add_argument("--chunk-points", type=int, default=100_000, metavar="N",
                   help="points processed at a time (bounds memory; default 100000)")
    p.add_argument("--json", action="store_true", help="print a JSON summary with one record per point")
    _add_quality_options(p)
    p.set_defaults(func=run_colmap)

    o = subparsers.add_parser("colmap-from-oxford", help="convert an Oxford VGG sequence to a COLMAP model",
                              description="Convert an Oxford VGG sequence to a COLMAP model (PINHOLE cameras, DLT "
                                          "points), written atomically to OUT_DIR.")
    o.add_argument("name", metavar="NAME", help="sequence (library, merton1, merton2, merton3, wadham)")
    o.add_argument("out_dir", metavar="OUT_DIR", help="output folder (created if needed; only the model's files are "
                                                          "replaced)")
    add_data_dir_option(o)
    o.add_argument("--max-tracks", type=int, default=None, metavar="M", help="keep the first M tracks")
    o.add_argument("--output-type", choices=("bin", "txt"), default="txt", help="model format (default txt)")
    o.set_defaults(func=run_from_oxford)


def _add_quality_options(p) -> None:
    """Flags of :mod:`tritools.sfm.quality` (angle, certified uncertainty, filters; docs/uncertainty.md)."""
    from ..sfm.quality import COLMAP_MAX_REPROJ_ERROR, COLMAP_MIN_TRI_ANGLE

    g = p.add_argument_group("point quality (written to points3D_uncertainty.txt; filters remove points)")
    g.add_argument("--keypoint-radius", type=float, default=None, metavar="R",
                   help="keypoints are uncertain within R undistorted pixels: certify each point's 3D uncertainty "
                        "(radius around the written point, depth interval) from discs of radius R")
    g.add_argument("--keypoint-radii", default=None, metavar="FILE",
                   help="per-observation radii: lines 'IMAGE_ID POINT2D_IDX RADIUS' (# comments); unlisted "
                        "observations use --keypoint-radius")
    g.add_argument("--min-angle", type=float, default=None, metavar="DEG",
                   help=f"remove points whose largest triangulation angle is below DEG degrees (off by default; "
                        f"COLMAP's mapper uses {COLMAP_MIN_TRI_ANGLE})")
    g.add_argument("--max-error", type=float, default=None, metavar="PX",
                   help=f"remove points whose mean reprojection error exceeds PX pixels (off by default; COLMAP's "
                        f"mapper uses {COLMAP_MAX_REPROJ_ERROR})")
    g.add_argument("--max-uncertainty", type=float, default=None, metavar="D",
                   help="remove points whose certified uncertainty radius exceeds D world units, or is unbounded "
                        "or empty (needs --keypoint-radius)")
    g.add_argument("--max-depth-ratio", type=float, default=None, metavar="Q",
                   help="remove points whose certified depth interval has depth_hi / depth_lo > Q in a view "
                        "(needs --keypoint-radius)")


def _quality_options(args):
    from ..sfm.quality import QualityOptions

    return QualityOptions(keypoint_radius=args.keypoint_radius, min_angle=args.min_angle,
                          max_error=args.max_error, max_uncertainty=args.max_uncertainty,
                          max_depth_ratio=args.max_depth_ratio, keypoint_radii=args.keypoint_radii)


def _os_message(exc: OSError) -> str:
    where = exc.filename if exc.filename is not None else ""
    return f"{where}: {exc.strerror}" if where and exc.strerror else str(exc)


def run_colmap(args) -> int:
    """``tritools colmap``: returns the exit code."""
    from ..io.colmap.model import ModelFormatError
    from ..sfm import CameraError, OptionError, OutputError, RetriangulationOptions, retriangulate_folder

    solver = options_from_args(args)                 # exactly as `tritools solve` (CLIError: exit 2 naming the flag)
    robust = robust_from_args(args)                  # the one --robust rule and wording of `tritools solve`
    try:
        options = RetriangulationOptions(solver=solver, min_track_length=args.min_track_length,
                                         max_track_length=args.max_track_length, behind=args.behind,
                                         strict=args.strict, chunk_points=args.chunk_points, progress=args.progress,
                                         robust=robust)
        quality = _quality_options(args)
    except OptionError as exc:
        return exit_invalid(option_flag_error(exc, args))
    _refuse_radii_as_output(args)
    try:
        with executor_from_args(args) as executor, _cameras_reported_here():
            result = retriangulate_folder(args.in_dir, args.out_dir, dataclasses.replace(options, executor=executor),
                                          input_format=None if args.input_type == "auto" else args.input_type,
                                          output_format=args.output_type, exports=args.export, quality=quality)
    except CLIError as exc:
        return exit_invalid(exc)
    except OptionError as exc:
        return exit_invalid(option_flag_error(exc, args))
    except (ModelFormatError, CameraError, OutputError) as exc:
        return exit_invalid(str(exc))
    except OSError as exc:
        return exit_invalid(_os_message(exc))
    except ValueError as exc:
        return exit_invalid(str(exc))
    q = result.quality                               # applied before anything was committed
    report = result.report
    summary = {"in_dir": str(args.in_dir), "out_dir": str(result.out_dir), "input_type": result.input_format,
               "output_type": result.output_format, "certificates": str(result.certificates),
               "exports": [str(e) for e in result.exports], "copied": list(result.copied), "notes": list(result.notes),
               "delta": solver.delta, "max_delta": solver.max_delta, "time_limit": solver.budget.time_limit,
               "memory_limit_bytes": solver.budget.max_bytes, "total_time_limit": solver.total_time_limit,
               **report.summary(), **_written_counts(report, q)}
    if args.json:
        summary["points"] = [{"point3D_id": r.point3D_id, "n_views": r.n_views, "status": r.status.value,
                              "gamma_lb": r.gamma_lb, "gamma_ub": r.gamma_ub, "certified": r.certified,
                              "certified_by": r.certified_by, "delta": r.delta, "gamma_input": r.gamma_input,
                              "updated": r.updated, "in_front": r.in_front, "message": r.message,
                              **({"n_inliers": r.n_inliers,
                                  "removed_observations": [list(t) for t in r.removed_observations]}
                                 if report.n_inliers is not None else {})}
                             for r in report.records]
        if q is not None:
            _add_quality_records(summary, q)
        print(json.dumps(jsonable(summary), indent=1, allow_nan=False))   # NaN/inf -> null, as tritools solve
        return _skipped_status(report, summary, getattr(args, "quiet", False))
    if q is not None:
        summary["quality"] = q.summary()
    _print_summary(report, result, summary)
    return _skipped_status(report, summary, getattr(args, "quiet", False))


def _written_counts(report, q) -> dict:
    """``n_certified`` and ``n_updated`` of the written model: a point the quality filters removed is neither (as
    the sidecar and the per-point records say: :func:`~tritools.sfm.certificates.mark_removed`); without filters,
    the report's own counts."""
    if q is None:
        return {}
    gone = np.isin(report.point_ids, q.point_ids[~q.kept])
    return {"n_certified": int(np.count_nonzero(report.certified & ~gone)),
            "n_updated": int(np.count_nonzero(report.updated & ~gone))}


def _refuse_radii_as_output(args) -> None:
    """CLIError when an export, or a file the command writes into OUT_DIR, is the ``--keypoint-radii`` file it
    reads (:func:`refuse_input_as_output`; OUT_DIR = IN_DIR is refused by the library's ``check_output``)."""
    from ..sfm.folder import written_names

    radii = [("--keypoint-radii", args.keypoint_radii)]
    for e in args.export:
        refuse_input_as_output(e, "--export", radii)
    for name in written_names():
        refuse_input_as_output(Path(args.out_dir) / name, f"OUT_DIR/{name}", radii)


@contextlib.contextmanager
def _cameras_reported_here():
    """The command reports the skipped cameras itself (the summary, and one warning line with exit 3): the
    library's warning per camera (:data:`~tritools.sfm.retriangulate.SKIPPED_CAMERAS_LOGGER`) is shown only
    from ``-v`` (info) on, so that exit 3 prints one line."""
    from ..sfm.retriangulate import SKIPPED_CAMERAS_LOGGER

    lg = logging.getLogger(SKIPPED_CAMERAS_LOGGER)
    saved = lg.level
    if not lg.isEnabledFor(logging.INFO):
        lg.setLevel(logging.ERROR)
    try:
        yield
    finally:
        lg.setLevel(saved)


def _skipped_status(report, summary: dict, quiet: bool = False) -> int:
    """0, or :data:`EXIT_CAMERAS_SKIPPED` with one warning line (unless ``quiet``) when unusable cameras left
    observations out."""
    used = [c for c in report.skipped_cameras if c[3] > 0]
    images = [i for i in report.skipped_images if i[3] > 0]
    if not used and not images:
        return 0
    what = [f"{len(used)} camera(s) could not be used ({', '.join(sorted({c[1] for c in used}))})"] if used else []
    what += [f"{len(images)} image(s) could not be used (K [R | t] not a camera)"] if images else []
    n_obs = sum(c[3] for c in used) + sum(i[3] for i in images)
    if not quiet:
        print(f"tritools: warning: {' and '.join(what)}: {n_obs} "
              f"observation(s) left out, {summary['n_certified']} of {report.n_points} point(s) certified",
              file=sys.stderr)
    return EXIT_CAMERAS_SKIPPED


def _add_quality_records(summary, q) -> None:
    """The quality summary and, per point record, angle, uncertainty radius, depth interval, kept (a point not kept
    is not in the written model: not certified, not updated, :data:`~tritools.sfm.certificates.REMOVED_MESSAGE`)."""
    from ..sfm.certificates import REMOVED_MESSAGE

    summary["quality"] = q.summary()
    index = {int(p): i for i, p in enumerate(q.point_ids.tolist())}
    for rec in summary["points"]:
        i = index.get(int(rec["point3D_id"]))
        if i is not None:
            rec.update(angle_deg=float(q.angle_deg[i]), uncertainty_status=str(q.status[i]) or None,
                       uncertainty_radius=float(q.radius[i]), depth_lo=float(q.depth_lo[i]),
                       depth_hi=float(q.depth_hi[i]), depth_ratio=float(q.depth_ratio[i]), kept=bool(q.kept[i]))
            if not q.kept[i]:                 # not in the written model: as the sidecar says (mark_removed)
                rec.update(certified=False, updated=False,
                           message="; ".join(m for m in (rec.get("message"), REMOVED_MESSAGE) if m))


def _print_summary(report, result, summary) -> None:
    first = summary["delta"] or "min"
    last = summary["max_delta"] or ("4" if report.method == "auto" else "min+2" if summary["delta"] is None
                                    else summary["delta"])
    print(f"{report.n_points} points, {summary['n_certified']} certified globally optimal, {summary['n_updated']} "
          "updated, "
          f"{report.n_behind} behind a camera ({report.method}, path {report.path}, delta {first}..{last})")
    print("status: " + (", ".join(f"{k} {v}" for k, v in summary["status"].items()) or "-"))
    for cid, model, reason, n_obs in report.skipped_cameras:
        print(printable(f"skipped camera {cid} ({model}): {reason}; {n_obs} observation(s) left out"))
    for iid, name, reason, n_obs in report.skipped_images:
        print(printable(f"skipped image {iid} ({name}): {reason}; {n_obs} observation(s) left out"))
    bad = report.uncertified(MAX_LISTED)
    if bad:
        n_bad = report.n_points - summary["n_certified"]        # of the written model (quality filters too)
        print(f"not certified: {n_bad} point(s)" + (f", first {len(bad)}:" if n_bad > len(bad) else ":"))
        for r in bad:
            print(printable(f"  point3D {r.point3D_id} ({r.n_views} views): {r.status.value}"
                  + ("" if r.in_front else ", behind a camera") + (f" -- {r.message}" if r.message else "")))
    for note in result.notes:
        print(printable(f"note: {note}"))
    print(f"model ({result.output_format}) written to {result.out_dir}, certificates to {result.certificates}")
    for e in result.exports:
        print(f"exported {e}")
    if "quality" in summary:
        qs = summary["quality"]
        print(f"quality: {qs['n_kept']} of {qs['n_points']} points kept, median angle {qs['median_angle_deg']} deg, "
              f"median certified radius {qs['median_radius']}; written to points3D_uncertainty.txt")


def run_from_oxford(args) -> int:
    """``tritools colmap-from-oxford``: returns the exit code."""
    from ..io.atomic import input_clash
    from ..io.colmap import model_from_oxford, write_model
    from ..io.oxford import DataNotFoundError
    from ..io.oxford import data_dir as oxford_dir
    from ..sfm import OutputError, atomic_directory

    if args.max_tracks is not None and args.max_tracks < 1:
        return exit_invalid(f"--max-tracks: must be an integer >= 1, got {args.max_tracks}")
    if Path(args.out_dir).exists() and not Path(args.out_dir).is_dir():
        return exit_invalid(f"OUT_DIR {args.out_dir}: exists and is not a directory")
    try:
        clash = input_clash(args.out_dir, "OUT_DIR", [("the sequence folder", oxford_dir(args.data_dir) / args.name)],
                            folder=True)          # never into (or over) the data it reads (review 29b F11)
        if clash:
            return exit_invalid(clash)
        model = model_from_oxford(args.name, args.data_dir, args.max_tracks)
        with atomic_directory(args.out_dir) as tmp:
            write_model(model, tmp, args.output_type)
    except (DataNotFoundError, OutputError, ValueError) as exc:
        return exit_invalid(str(exc))
    except OSError as exc:
        return exit_invalid(_os_message(exc))
    print(f"{args.name}: {len(model.images)} images, {len(model.points3D)} points written to {args.out_dir}")
    return 0
