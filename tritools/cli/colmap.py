"""Command-line subcommands for COLMAP models (registered by :mod:`tritools.cli.app`).

* ``colmap IN_DIR OUT_DIR [--method M] [--path P] [--min-track-length K] [--delta D]
  [--max-delta D] [--json] [--progress]``: read the COLMAP text model in IN_DIR,
  re-triangulate every point with a certificate, write the model and
  ``points3D_certificates.txt`` to OUT_DIR (``rigs.txt``/``frames.txt`` are copied when
  present), print a summary (or JSON with one record per point).
* ``colmap-from-oxford NAME OUT_DIR [--data-dir D] [--max-tracks M]``: convert an Oxford
  VGG sequence to a COLMAP text model (PINHOLE cameras, DLT points).

Exit codes: 0 success, 2 bad input (message names the file/line or field).
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

from .app import add_data_dir_option, add_solver_options, exit_invalid
from ..io.problem_file import jsonable

__all__ = ["register", "run_colmap", "run_from_oxford"]


def register(subparsers) -> None:
    from ..model.constraints import Method
    from ..solve.triangulate import SolvePath

    p = subparsers.add_parser("colmap", help="certified re-triangulation of a COLMAP text model",
                              description="Read IN_DIR/{cameras,images,points3D}.txt, re-triangulate every 3D "
                                          "point with a certificate of global optimality, write OUT_DIR.")
    p.add_argument("in_dir", metavar="IN_DIR")
    p.add_argument("out_dir", metavar="OUT_DIR")
    add_solver_options(p, Method.COROLLARY1.value, SolvePath.AUTO.value)
    p.add_argument("--min-track-length", type=int, default=2, metavar="K")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run_colmap)

    o = subparsers.add_parser("colmap-from-oxford", help="convert an Oxford VGG sequence to a COLMAP text model")
    o.add_argument("name", metavar="NAME", help="sequence (library, merton1, merton2, merton3, wadham)")
    o.add_argument("out_dir", metavar="OUT_DIR")
    add_data_dir_option(o)
    o.add_argument("--max-tracks", type=int, default=None, metavar="M", help="keep the first M tracks")
    o.set_defaults(func=run_from_oxford)


def run_colmap(args) -> int:
    from ..io.colmap import read_text_model, write_text_model
    from ..sfm import retriangulate, write_certificates

    try:
        model = read_text_model(args.in_dir)
    except (OSError, ValueError) as exc:
        return exit_invalid(str(exc))
    if Path(args.out_dir).resolve() == Path(args.in_dir).resolve():
        return exit_invalid("OUT_DIR must differ from IN_DIR (the input model is never overwritten)")
    try:
        new_model, report = retriangulate(model, args.method, args.path, args.min_track_length, args.delta,
                                          args.max_delta, progress=args.progress)
    except ValueError as exc:
        return exit_invalid(str(exc))
    out = write_text_model(new_model, args.out_dir)
    sidecar = write_certificates(report, out)
    for extra in ("rigs.txt", "frames.txt"):
        if (Path(args.in_dir) / extra).is_file():
            shutil.copyfile(Path(args.in_dir) / extra, out / extra)
    summary = {"in_dir": str(args.in_dir), "out_dir": str(out), "certificates": str(sidecar),
               "method": report.method, "path": report.path, "n_points": report.n_points,
               "n_certified": report.n_certified, "n_updated": report.n_updated, "status": report.status_counts()}
    if args.json:
        summary["points"] = [{"point3D_id": r.point3D_id, "n_views": r.n_views, "status": r.status.value,
                              "gamma_lb": r.gamma_lb, "gamma_ub": r.gamma_ub, "certified": r.certified,
                              "certified_by": r.certified_by, "delta": r.delta, "gamma_input": r.gamma_input,
                              "updated": r.updated, "message": r.message} for r in report.records]
        print(json.dumps(jsonable(summary), indent=1, allow_nan=False))   # NaN/inf -> null, as tritools solve
        return 0
    print(f"{report.n_points} points, {report.n_certified} certified globally optimal, {report.n_updated} updated "
          f"({report.method}, path {report.path})")
    print("status: " + ", ".join(f"{k} {v}" for k, v in summary["status"].items()))
    print(f"model written to {out}, certificates to {sidecar}")
    return 0


def run_from_oxford(args) -> int:
    from ..io.colmap import model_from_oxford, write_text_model
    from ..io.oxford import DataNotFoundError

    if args.max_tracks is not None and args.max_tracks < 1:
        return exit_invalid(f"--max-tracks must be >= 1, got {args.max_tracks}")
    try:
        model = model_from_oxford(args.name, args.data_dir, args.max_tracks)
    except (DataNotFoundError, ValueError) as exc:
        return exit_invalid(str(exc))
    out = write_text_model(model, args.out_dir)
    print(f"{args.name}: {len(model.images)} images, {len(model.points3D)} points written to {out}")
    return 0
