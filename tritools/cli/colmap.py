"""Command-line subcommands for COLMAP models (registered by :mod:`tritools.cli.app`).

* ``colmap IN_DIR OUT_DIR``: read the COLMAP model in IN_DIR (binary ``*.bin`` or text ``*.txt``,
  detected), re-triangulate every 3D point with a certificate of global optimality, write the model
  (same format unless ``--output-type``), ``points3D_certificates.txt`` and copies of
  ``rigs``/``frames`` files to OUT_DIR -- all into a temporary directory that replaces OUT_DIR
  only once everything was written -- and print a summary (or JSON).
* ``colmap-from-oxford NAME OUT_DIR``: convert an Oxford VGG sequence to a COLMAP model.

Exit codes: 0 success (whatever the points' statuses), 2 bad input, bad option or unusable output
path -- one line ``tritools: error: ...`` naming the file and line/record, or the flag.
"""
from __future__ import annotations

import json
from pathlib import Path

from .app import add_data_dir_option, add_robust_option, add_solver_options, exit_invalid, options_from_args
from ..io.problem_file import jsonable

__all__ = ["register", "run_colmap", "run_from_oxford", "MAX_LISTED"]

#: uncertified points listed in the text summary.
MAX_LISTED = 10


def register(subparsers) -> None:
    """Add the ``colmap`` and ``colmap-from-oxford`` subcommands."""
    from ..sfm.pipeline import BEHIND_CHOICES, DEFAULT_MAX_TRACK_LENGTH

    p = subparsers.add_parser(
        "colmap", help="certified re-triangulation of a COLMAP model (binary or text)",
        description="Read the COLMAP model in IN_DIR (cameras/images/points3D as .bin or .txt), re-triangulate "
                    "every 3D point with a certificate of global optimality (cameras fixed), and write the model, "
                    "points3D_certificates.txt and copies of rigs/frames files to OUT_DIR. Everything is written "
                    "to a temporary directory next to OUT_DIR first; an existing OUT_DIR is replaced only after "
                    "everything was written, and is left exactly as it was if anything fails. The solver flags and "
                    "their defaults are those of 'tritools solve': method auto (Corollary 1 at delta = 2, then "
                    "delta = 4 for the points that does not certify), each point within --time-limit and "
                    "--memory-limit; --max-delta 2 keeps every point at delta = 2. --progress: a bar over all "
                    "points (by default only for models of 2000 points or more).")
    p.add_argument("in_dir", metavar="IN_DIR", help="folder of the input model (never modified)")
    p.add_argument("out_dir", metavar="OUT_DIR", help="output folder (created, or replaced as a whole; must not be "
                                                      "IN_DIR, contain IN_DIR, or be a file)")
    p.add_argument("--input-type", choices=("auto", "bin", "txt"), default="auto",
                   help="format of IN_DIR (default auto: binary if cameras.bin, images.bin, points3D.bin exist, "
                        "else text)")
    p.add_argument("--output-type", choices=("bin", "txt"), default=None,
                   help="format of OUT_DIR (default: that of IN_DIR)")
    add_solver_options(p)            # the flags and defaults of `tritools solve`: one TriangulationOptions
    add_robust_option(p)             # --robust C: outlier observations leave the tracks (POINT3D_ID -1)
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
    p.set_defaults(func=run_colmap)

    o = subparsers.add_parser("colmap-from-oxford", help="convert an Oxford VGG sequence to a COLMAP model",
                              description="Convert an Oxford VGG sequence to a COLMAP model (PINHOLE cameras, DLT "
                                          "points), written atomically to OUT_DIR.")
    o.add_argument("name", metavar="NAME", help="sequence (library, merton1, merton2, merton3, wadham)")
    o.add_argument("out_dir", metavar="OUT_DIR", help="output folder (created, or replaced as a whole)")
    add_data_dir_option(o)
    o.add_argument("--max-tracks", type=int, default=None, metavar="M", help="keep the first M tracks")
    o.add_argument("--output-type", choices=("bin", "txt"), default="txt", help="model format (default txt)")
    o.set_defaults(func=run_from_oxford)


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def _os_message(exc: OSError) -> str:
    where = exc.filename if exc.filename is not None else ""
    return f"{where}: {exc.strerror}" if where and exc.strerror else str(exc)


def run_colmap(args) -> int:
    """``tritools colmap``: returns the exit code."""
    from ..io.colmap.model import ModelFormatError
    from ..sfm import CameraError, OptionError, OutputError, RetriangulationOptions, retriangulate_folder

    solver = options_from_args(args)                 # exactly as `tritools solve` (CLIError: exit 2 naming the flag)
    try:
        options = RetriangulationOptions(solver=solver, min_track_length=args.min_track_length,
                                         max_track_length=args.max_track_length, behind=args.behind,
                                         strict=args.strict, chunk_points=args.chunk_points, progress=args.progress,
                                         robust=args.robust)
    except OptionError as exc:
        return exit_invalid(f"{_flag(exc.field)} {exc.detail}")
    try:
        result = retriangulate_folder(args.in_dir, args.out_dir, options,
                                      input_format=None if args.input_type == "auto" else args.input_type,
                                      output_format=args.output_type, exports=args.export)
    except OptionError as exc:
        return exit_invalid(f"{_flag(exc.field)} {exc.detail}")
    except (ModelFormatError, CameraError, OutputError) as exc:
        return exit_invalid(str(exc))
    except OSError as exc:
        return exit_invalid(_os_message(exc))
    except ValueError as exc:
        return exit_invalid(str(exc))
    report = result.report
    summary = {"in_dir": str(args.in_dir), "out_dir": str(result.out_dir), "input_type": result.input_format,
               "output_type": result.output_format, "certificates": str(result.certificates),
               "exports": [str(e) for e in result.exports], "copied": list(result.copied), "notes": list(result.notes),
               "delta": solver.delta, "max_delta": solver.max_delta, "time_limit": solver.budget.time_limit,
               "memory_limit_bytes": solver.budget.max_bytes,
               **report.summary()}
    if args.json:
        summary["points"] = [{"point3D_id": r.point3D_id, "n_views": r.n_views, "status": r.status.value,
                              "gamma_lb": r.gamma_lb, "gamma_ub": r.gamma_ub, "certified": r.certified,
                              "certified_by": r.certified_by, "delta": r.delta, "gamma_input": r.gamma_input,
                              "updated": r.updated, "in_front": r.in_front, "message": r.message}
                             for r in report.records]
        print(json.dumps(jsonable(summary), indent=1, allow_nan=False))   # NaN/inf -> null, as tritools solve
        return 0
    _print_summary(report, result, summary)
    return 0


def _print_summary(report, result, summary) -> None:
    first = summary["delta"] or "min"
    last = summary["max_delta"] or ("4" if report.method == "auto" else "min+2" if summary["delta"] is None
                                    else summary["delta"])
    print(f"{report.n_points} points, {report.n_certified} certified globally optimal, {report.n_updated} updated, "
          f"{report.n_behind} behind a camera ({report.method}, path {report.path}, delta {first}..{last})")
    print("status: " + (", ".join(f"{k} {v}" for k, v in summary["status"].items()) or "-"))
    for cid, model, reason, n_obs in report.skipped_cameras:
        print(f"skipped camera {cid} ({model}): {reason}; {n_obs} observation(s) left out")
    bad = report.uncertified(MAX_LISTED)
    if bad:
        n_bad = report.n_points - report.n_certified
        print(f"not certified: {n_bad} point(s)" + (f", first {len(bad)}:" if n_bad > len(bad) else ":"))
        for r in bad:
            print(f"  point3D {r.point3D_id} ({r.n_views} views): {r.status.value}"
                  + ("" if r.in_front else ", behind a camera") + (f" -- {r.message}" if r.message else ""))
    for note in result.notes:
        print(f"note: {note}")
    print(f"model ({result.output_format}) written to {result.out_dir}, certificates to {result.certificates}")
    for e in result.exports:
        print(f"exported {e}")


def run_from_oxford(args) -> int:
    """``tritools colmap-from-oxford``: returns the exit code."""
    from ..io.colmap import model_from_oxford, write_model
    from ..io.oxford import DataNotFoundError
    from ..sfm import OutputError, atomic_directory

    if args.max_tracks is not None and args.max_tracks < 1:
        return exit_invalid(f"--max-tracks must be >= 1, got {args.max_tracks}")
    if Path(args.out_dir).exists() and not Path(args.out_dir).is_dir():
        return exit_invalid(f"OUT_DIR {args.out_dir}: exists and is not a directory")
    try:
        model = model_from_oxford(args.name, args.data_dir, args.max_tracks)
        with atomic_directory(args.out_dir) as tmp:
            write_model(model, tmp, args.output_type)
    except (DataNotFoundError, OutputError, ValueError) as exc:
        return exit_invalid(str(exc))
    except OSError as exc:
        return exit_invalid(_os_message(exc))
    print(f"{args.name}: {len(model.images)} images, {len(model.points3D)} points written to {args.out_dir}")
    return 0
