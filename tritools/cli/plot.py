"""Command-line plots: ``tritools figure3`` and ``tritools plot-dataset``.

``register(subparsers)`` adds the two sub-commands to the ``tritools`` argument
parser; each sets ``func`` to a handler ``func(args) -> exit code`` (0 success,
2 bad input, missing data or missing matplotlib, with a one-line message on stderr).

* ``tritools figure3 [--out DIR] [--examples 2 3 4]`` solves the paper's Examples 2-4
  (Theorem 1, delta = 4, as in the paper's Figure 3) and writes
  ``DIR/figure3_example{k}.png``.
* ``tritools plot-dataset NAME [--data-dir DIR] [--limit K] [--sample K --seed S] [--out FILE]``
  triangulates the tracks of an Oxford sequence (point regions) and writes
  :func:`tritools.plot.dataset_summary`.  ``--limit``/``--sample``/``--seed`` select the tracks
  exactly as for ``tritools dataset`` (:func:`tritools.cli.app.select_tracks`: the first K in
  file order, then K drawn at random); default: every track.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

from .app import (METHODS, CLIError, add_data_dir_option, add_solver_options, add_track_options, exit_invalid,
                  load_oxford, options_from_args, select_tracks, write_error)
from ..io.atomic import atomic_path, new_folders
from .conventions import add_world_frame_option, sequence_options
from ..model.constraints import Method

__all__ = ["register", "run_figure3", "run_plot_dataset"]


def run_figure3(args) -> int:
    """Handler of ``tritools figure3``."""
    os.environ.setdefault("RUST_BACKTRACE", "0")
    try:
        options_from_args(args)           # --method/--delta validated like every solver flag
        from ..plot import save_figure3_examples

        paths = save_figure3_examples(args.out, args.examples, method=args.method, delta=args.delta)
    except OSError as exc:
        return exit_invalid(write_error(exc.filename or args.out, exc))
    except (CLIError, ImportError, ValueError) as exc:
        return exit_invalid(str(exc))
    for p in paths:
        print(p)
    return 0


def run_plot_dataset(args) -> int:
    """Handler of ``tritools plot-dataset`` (bad flags, missing data or matplotlib: one line, exit 2)."""
    os.environ.setdefault("RUST_BACKTRACE", "0")
    try:
        return _plot_dataset(args)
    except CLIError as exc:
        return exit_invalid(exc)


def _plot_dataset(args) -> int:
    from ..solve.batch import triangulate_many
    from ..model.regions import Point

    options = options_from_args(args)
    select_tracks((), args.limit, args.sample, args.seed)            # the flags checked before any data is read
    try:
        from ..plot import require_matplotlib

        require_matplotlib()
    except ImportError as exc:
        return exit_invalid(str(exc))
    seq = load_oxford(args.name, args.data_dir, "plot-dataset", [("--out", args.out)])
    options = sequence_options(options, args, seq)
    tracks = select_tracks(seq.tracks, args.limit, args.sample, args.seed)
    if not tracks:
        return exit_invalid(f"plot-dataset: sequence {seq.name!r} has no track seen in 2 views")
    problems = []
    for t in tracks:
        cams, pts = seq.problem(t)
        problems.append((cams, [Point(x) for x in pts]))
    results = triangulate_many(problems, options=options, progress=args.progress)
    from ..plot import dataset_summary

    out = Path(args.out) if args.out else Path(f"{seq.name}_summary.png")   # by default in the working directory
    fig = dataset_summary(results, [t.n_views for t in tracks],
                          title=f"{seq.name}: {len(tracks)} of {len(seq.tracks)} tracks, {args.method}"
                                + (f" delta={args.delta}" if args.delta is not None else ""))
    try:
        with new_folders(out.parent), atomic_path(out) as tmp:
            fig.savefig(tmp, dpi=120)
    except OSError as exc:
        return exit_invalid(write_error(out, exc))
    n_cert = sum(bool(r.optimal) for r in results)
    print(f"{out}  ({n_cert}/{len(results)} certified)")
    return 0


def register(subparsers) -> None:
    """Add ``figure3`` and ``plot-dataset`` to an ``argparse`` sub-parser collection."""
    f3 = subparsers.add_parser("figure3", help="the paper's Figure 3 (Examples 2-4) as PNG files",
                               description="Solve Examples 2-4 and write figure3_example{k}.png "
                                           "(needs the extra 'plot').")
    f3.add_argument("--out", default="figures", help="output directory (default: figures)")
    f3.add_argument("--examples", type=int, nargs="+", choices=(2, 3, 4), default=[2, 3, 4],
                    help="examples to plot (default: 2 3 4)")
    f3.add_argument("--method", choices=METHODS, default=Method.THEOREM1.value,
                    help="certified method (default: theorem1, as the paper's Figure 3)")
    f3.add_argument("--delta", type=int, default=4, metavar="D", help="relaxation degree (even; default: 4)")
    f3.set_defaults(func=run_figure3)

    pd = subparsers.add_parser("plot-dataset", help="gamma_UB histogram and certified counts of an Oxford sequence",
                               description="Triangulate tracks of an Oxford sequence and plot a summary "
                                           "(needs the extra 'plot').")
    pd.add_argument("name", help="sequence name, e.g. library, house, dinosaur")
    add_data_dir_option(pd)
    add_track_options(pd)
    add_solver_options(pd)
    add_world_frame_option(pd)
    pd.add_argument("--out", default=None, help="output PNG (default: NAME_summary.png)")
    pd.set_defaults(func=run_plot_dataset)


if __name__ == "__main__":  # pragma: no cover - the whole command line, these subcommands included
    from .app import main

    sys.exit(main())
