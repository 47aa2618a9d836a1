"""The ``tritools`` command line (``python -m tritools`` or the ``tritools`` script).

Subcommands
-----------
``solve FILE``       triangulate the problems of a JSON problem file (:mod:`tritools.io.problem_file`)
``example K``        the paper's Example 2, 3, 4 (Tables 8-10) or a reduced Example 5 (Table 11)
``dataset NAME``     an Oxford sequence of the paper's Example 1 (Tables 1-6), summarised per N

The solver and data flags and their validation are :mod:`tritools.cli.flags` (re-exported here).
More subcommands come from the modules named in :data:`SUBCOMMAND_MODULES`: each exposes
``register(subparsers) -> None``, adding its parser with ``set_defaults(func=...)`` where
``func(args) -> int`` is the exit code.  A module that does not exist (yet) is skipped.

Exit codes: 0 success (whatever the statuses of the individual results), 1 unexpected
internal error (one line; ``TRITOOLS_DEBUG=1`` re-raises it with its traceback),
2 invalid input: bad arguments, an invalid problem file, missing data -- always one
line on stderr naming what is wrong (the flag, the field's location or ``file:line``).
Problems that are well formed but not well posed (equal or rank-deficient cameras) are
not input errors: they get a result row with a status.
"""
from __future__ import annotations

import argparse
import contextlib
import csv
import importlib
import json
import math
import os
import sys
import warnings
from collections import defaultdict
from collections.abc import Sequence

import numpy as np

from ..model.constraints import Method
from ..startup import (EXIT_INTERRUPTED, INTERRUPTED_MESSAGE, Terminated,
                       end_startup, terminate_unwinds)
from ..io.atomic import atomic_open
from ..io.oxford import is_float
from ..io.problem_file import (ProblemFileError, ProblemSpec, jsonable, load_problem_file, parse_problem_bytes,
                               parse_problem_text)
from ..result import Status, TriangulationResult, TriangulationResults
from ..solve.batch import PROGRESS_MIN_ITEMS
from ..solve.call_limit import call_limit
from ..solve.options import TriangulationOptions
from .flags import (METHODS, OPTION_FLAGS, PATHS, SPARSITIES, CLIError, add_data_dir_option,  # noqa: F401 - faces
                    add_robust_option, add_solver_options, add_track_options, option_flag_error, options_from_args,
                    refuse_input_as_output, robust_from_args, select_tracks, write_error)
from .conventions import (silence_stdout, add_logging_options, add_world_frame_option, cli_logging,
                          sequence_options)

__all__ = ["main", "build_parser", "CLIError", "exit_invalid", "add_solver_options", "options_from_args",
           "add_data_dir_option", "add_track_options", "select_tracks", "printable",
           "SUBCOMMAND_MODULES", "solve_problems", "format_table", "EXIT_OK", "EXIT_INTERNAL", "EXIT_INVALID"]

#: modules adding subcommands through ``register(subparsers)``; skipped while they do not exist.
SUBCOMMAND_MODULES = ("tritools.cli.colmap", "tritools.cli.plot")
EXIT_OK, EXIT_INTERNAL, EXIT_INVALID = 0, 1, 2
#: set to 1 to get the traceback of an internal error instead of the one-line message.
DEBUG_ENV = "TRITOOLS_DEBUG"
#: Example 5 thetas (the paper's Section 5.5).
EXAMPLE5_THETAS = (0.05, 0.1, 0.15, 0.2)
FULL_EXAMPLE5_COMMAND = "python benchmarks/paper_examples.py --only-example5"
#: which estimate is which in ``tritools example 2|3|4``.
EXAMPLE_NOTE = ("X_raw is the estimate extracted from the certificate (the X^ the paper tabulates); 'X refined' is "
                "X_raw after the local L2 refinement (the result's X), which can only lower gamma but, when the "
                "relaxation is not tight, may run off to a far point; gamma is the point's RMS reprojection error "
                "(gamma_UB), gamma_LB the certified lower bound")


def printable(text) -> str:
    """``str(text)`` with every non-printable character (terminal escape sequences, other control
    characters, bidirectional overrides) written as its Python escape (``\\x1b``), so that names and
    messages from input files cannot drive the terminal; printable non-ASCII text is kept."""
    text = str(text)
    if text.isprintable():
        return text
    return "".join(ch if ch.isprintable() else repr(ch)[1:-1] for ch in text)


def exit_invalid(message) -> int:
    """Print the one-line ``tritools: error: MESSAGE`` on stderr; returns :data:`EXIT_INVALID`.

    Subcommand handlers return it for bad input, missing data or a missing extra.
    """
    text = printable(" ".join(str(message).splitlines()))          # one line, whatever the message holds
    print(f"tritools: error: {text}", file=sys.stderr)
    return EXIT_INVALID


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line instead of usage + message, and no SystemExit
        sub = self.prog.partition(" ")[2]          # "tritools colmap" -> "colmap"; the program is named once
        raise CLIError(f"{sub + ': ' if sub else ''}{message} (see '{self.prog} --help')")

    def parse_args(self, args=None, namespace=None):
        # unknown arguments are named even when the command is missing (argparse reports the missing
        # COMMAND first); the subcommand parsers collect theirs into the top-level parse
        ns, extra = self.parse_known_args(args, namespace)
        if extra:
            self.error(f"unrecognized arguments: {' '.join(extra)}")
        return ns

    def parse_known_args(self, args=None, namespace=None):
        try:
            return super().parse_known_args(args, namespace)
        except CLIError as exc:
            # without a COMMAND every argument is an unknown option: name it, not only the missing COMMAND
            unknown = [a for a in (sys.argv[1:] if args is None else args) if str(a).startswith("-")]
            if self._subparsers is None or "required: COMMAND" not in str(exc) or not unknown:
                raise
            self.error(f"unrecognized arguments: {' '.join(map(str, unknown))}")


# ----------------------------------------------------------------------------- formatting
def _num(v, digits: int = 3) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "NA"
    v = float(v)
    if v != 0 and (abs(v) >= 1e4 or abs(v) < 10 ** -digits):
        return f"{v:.{digits}e}"
    return f"{v:.{digits}f}"


def _sec(t) -> str:
    return "NA" if t is None else f"{t:.4f}"


def _point(X) -> str:
    return "NA" if X is None else "(" + ", ".join(_num(c) for c in X) + ")"


def _seconds(r: TriangulationResult):
    """The result's solve time: its own ``timings["total"]``, else its share of a vectorised batch
    (``timings["batch_share"]``); None when it has neither."""
    t = r.timings.get("total", r.timings.get("batch_share"))
    return float(t) if t is not None and math.isfinite(t) else None


#: ``seconds_source`` of a time: the result's own ``timings["total"]``, or its share of a vectorised batch.
OWN, BATCH_SHARE = "own", "batch_share"


def _timed_solve(problems: list, options: TriangulationOptions, progress, robust=None) -> tuple[list, list]:
    """:func:`triangulate_many` on ``problems`` and, per result, ``(seconds, source)``: the result's own
    ``timings["total"]`` (a per-problem solve), else its share of the vectorised batch that decided it
    (``timings["batch_share"]``).  ``robust``: TLS thresholds (``--robust``)."""
    from ..solve.batch import triangulate_many

    results = triangulate_many(problems, options=options, progress=progress, robust=robust)
    return results, [(_seconds(r), OWN if "total" in r.timings else BATCH_SHARE) for r in results]


def format_table(headers: Sequence[str], rows: Sequence[Sequence], right: Sequence[bool] | None = None) -> str:
    """Plain-text table; cells are str()-ed with non-printable characters escaped (:func:`printable`);
    ``right[j]``: right-align column j (default: all but the first)."""
    cells = [[printable(c) for c in row] for row in rows]
    widths = [max([len(h)] + [len(r[j]) for r in cells]) for j, h in enumerate(headers)]
    right = right if right is not None else [j > 0 for j in range(len(headers))]

    def line(row):
        return "  ".join(c.rjust(w) if r else c.ljust(w) for c, w, r in zip(row, widths, right)).rstrip()

    return "\n".join([line(headers), line(["-" * w for w in widths])] + [line(r) for r in cells])


def _emit(text: str, output: str | None) -> None:
    if output in (None, "-"):
        print(text)
        return
    try:
        with atomic_open(output, "w", encoding="utf-8") as fh:
            fh.write(text + "\n")
    except OSError as exc:
        raise write_error(output, exc) from None


def _dumps(obj) -> str:
    return json.dumps(obj, indent=1, allow_nan=False)


# ----------------------------------------------------------------------------- solving
def problem_options(spec: ProblemSpec, options: TriangulationOptions) -> TriangulationOptions:
    """``options`` with the problem's own settings: they override the options, and a problem's ``delta``
    (``max_delta``) without the other raises the options' ``max_delta`` (lowers their ``delta``) to it."""
    delta, md = spec.delta, spec.max_delta
    if delta is not None and md is None and options.max_delta is not None:
        md = max(options.max_delta, delta)
    if md is not None and delta is None and options.delta is not None:
        delta = min(options.delta, md)
    return options.replace(method=spec.method, delta=delta, max_delta=md, path=spec.path)


def solve_problems(specs: Sequence[ProblemSpec], options: TriangulationOptions | None = None,
                   progress: bool | None = None) -> list[TriangulationResult]:
    """One result per problem, in order, through :func:`tritools.solve.batch.triangulate_many`.

    Per-problem ``method``/``delta``/``max_delta``/``path`` override ``options`` (:func:`problem_options`);
    problems sharing the same settings go through one batch call.  A failing problem gets a result with a
    status and a message.  ``progress``: None (the library's default: a bar only for large batches), True, False.
    """
    return _solve_specs(specs, options, progress)[0]


def _solve_specs(specs, options, progress, robust=None) -> tuple[list, list]:
    """(results, [(seconds, source)]) of :func:`solve_problems` (sources in :func:`_timed_solve`)."""
    options = options or TriangulationOptions()
    groups: dict = defaultdict(list)
    for i, s in enumerate(specs):
        try:
            groups[problem_options(s, options)].append(i)
        except (ValueError, TypeError) as exc:       # a problem's settings against the flags
            raise CLIError(f"problem {s.name if s.name is not None else f'#{i}'}: {exc}") from None
    out: list = [None] * len(specs)
    times: list = [(None, OWN)] * len(specs)
    with call_limit(options.total_time_limit):       # --total-time-limit: one end for every group
        for opts, idx in groups.items():
            res, tms = _timed_solve([(specs[i].cameras, specs[i].regions) for i in idx], opts, progress, robust)
            for i, r, t in zip(idx, res, tms):
                out[i], times[i] = r, t
    return out, times


def _read_specs(file: str) -> list[ProblemSpec]:
    if file == "-":
        stream = getattr(sys.stdin, "buffer", None)
        return parse_problem_bytes(stream.read(), "<stdin>") if stream is not None else \
            parse_problem_text(sys.stdin.read(), "<stdin>")
    return load_problem_file(file)


def _cmd_solve(args) -> int:
    # the input file, or the file stdin reads (`tritools solve - -o F.json < F.json`)
    source = ("stdin", "/dev/stdin") if args.file == "-" else ("FILE", args.file)
    refuse_input_as_output(args.output, "--output", [source])
    specs = _read_specs(args.file)
    results, times = _solve_specs(specs, options_from_args(args), args.progress, robust_from_args(args))
    if args.json:
        rows = enumerate(zip(specs, TriangulationResults.from_rows(results).to_dict()["results"]))  # its JSON form
        _emit(_dumps([jsonable(dict(index=i, name=s.name, n_views=s.n_views)) | r for i, (s, r) in rows]), args.output)
        return EXIT_OK
    headers = ("name", "N", "status", "X", "gamma_LB", "gamma_UB", "optimal", "delta", "N_LMIVAR", "time[s]")
    rows, notes = [], []
    for i, (s, r, (t, source)) in enumerate(zip(specs, results, times)):
        name = s.name if s.name is not None else f"#{i}"
        opt = "NA" if r.optimal is None else ("yes" if r.optimal else "no")
        rows.append((name, s.n_views, r.status.value, _point(r.X), _num(r.gamma_lb), _num(r.gamma_ub), opt,
                     "NA" if r.delta is None else r.delta, "NA" if r.n_lmivar is None else r.n_lmivar,
                     ("~" if source == BATCH_SHARE and t is not None else "") + _sec(t)))
        if r.message:
            notes.append(printable(f"{name}: {r.status.value}: {r.message}"))
    text = format_table(headers, rows, [False, True, False, False] + [True] * 6)
    if any(source == BATCH_SHARE for _, source in times):
        notes.insert(0, "time[s]: ~ marks a problem decided in a vectorised batch: its share of the batch's time")
    if notes:
        text += "\n\n" + "\n".join(notes)
    _emit(text, args.output)
    return EXIT_OK


# ----------------------------------------------------------------------------- example
def _example_paper(args) -> int:
    from ..scene import paper_example, paper_table
    from ..solve.triangulate import triangulate

    cams, regions = paper_example(args.k)
    paper = {(r["method"], r.get("delta")): r for r in paper_table(args.k)}
    rows = [("theorem1", 4), ("corollary1", 2), ("corollary1", 4)]
    out = []
    for method, delta in rows:
        r = triangulate(cams, regions, method, delta=delta)
        p = paper[(method, delta)]
        out.append({"method": method, "delta": delta,
                     "X_raw": None if r.X_raw is None else r.X_raw.round(6).tolist(), "gamma_ub_raw": r.gamma_ub_raw,
                     "X": None if r.X is None else r.X.round(6).tolist(),
                     "gamma_lb": r.gamma_lb, "gamma_ub": r.gamma_ub, "optimal": bool(r.optimal),
                     "n_lmivar": r.n_lmivar, "seconds": round(r.timings.get("total", float("nan")), 3),
                     "paper": {"X": p["X"], "gamma": p["gamma"], "optimal": p["optimal"], "n_lmivar": p["n_lmivar"]}})
    if args.json:
        _emit(_dumps(jsonable(out)), None)
        return EXIT_OK
    print(f"Example {args.k} of Chesi (2026): certified multiple-view L2 triangulation")
    table = []
    for o in out:
        p = o["paper"]
        table += [(f"{o['method']} d={o['delta']}", "X_raw", _point(o["X_raw"]), _num(o["gamma_ub_raw"]),
                   _num(o["gamma_lb"]), "yes" if o["optimal"] else "no", o["n_lmivar"]),
                  ("", "X refined", _point(o["X"]), _num(o["gamma_ub"]), "", "", ""),
                  ("", "paper X^", _point(p["X"]), _num(p["gamma"]), "", "yes" if p["optimal"] else "no",
                   p["n_lmivar"])]
    print(format_table(("method", "estimate", "point", "gamma", "gamma_LB", "optimal", "N_LMIVAR"), table,
                       [False, False, False] + [True] * 4))
    print(f"\nnote: {EXAMPLE_NOTE}")
    return EXIT_OK


def _example5(args) -> int:
    from ..scene import example5_cases

    for name in ("points", "trials"):
        if getattr(args, name) < 1:
            raise CLIError(f"example 5: --{name} must be a positive integer, got {getattr(args, name)}")
    if args.seed < 0:
        raise CLIError(f"example 5: --seed must be a non-negative integer, got {args.seed}")
    cases = example5_cases(seed=args.seed, n_points=args.points, thetas=EXAMPLE5_THETAS, trials=args.trials)
    results, times = _solve_specs([ProblemSpec(c.cameras, c.regions) for c in cases],
                                  TriangulationOptions(Method.THEOREM1, 4, 4), args.progress)
    summary = []
    for theta in EXAMPLE5_THETAS:
        sel = [(c, r, t) for c, r, (t, _) in zip(cases, results, times) if c.theta == theta]
        gub = [r.gamma_ub for _, r, _ in sel if r.gamma_ub is not None]
        dist = [float(np.linalg.norm(r.X - c.X_obj)) for c, r, _ in sel if r.X is not None]
        secs = [t for _, _, t in sel if t is not None]
        summary.append({"theta": theta, "cases": len(sel),
                        "certified": sum(r.status == Status.OPTIMAL for _, r, _ in sel),
                        "mean_gamma_ub": float(np.mean(gub)) if gub else None,
                        "mean_distance_to_X_obj": float(np.mean(dist)) if dist else None,
                        "n_lmivar": sorted({r.n_lmivar for _, r, _ in sel if r.n_lmivar is not None}),
                        "mean_seconds": float(np.mean(secs)) if secs else None})
    note = (f"reduced run: {args.points} points x {len(EXAMPLE5_THETAS)} theta x {args.trials} trials, seed "
            f"{args.seed}; the paper certifies all 250 cases per theta with Theorem 1 at delta = 4; full run "
            f"(Tables 11-12): {FULL_EXAMPLE5_COMMAND}")
    if args.json:
        _emit(_dumps(jsonable({"method": "theorem1", "delta": 4, "seed": args.seed,
                                           "points": args.points, "trials": args.trials, "per_theta": summary,
                                           "note": note})), None)
        return EXIT_OK
    print("Example 5 of Chesi (2026): certified cases of Theorem 1 at delta = 4 per uncertainty level theta")
    rows = [(s["theta"], s["cases"], s["certified"], _num(s["mean_gamma_ub"]), _num(s["mean_distance_to_X_obj"]),
             ",".join(map(str, s["n_lmivar"])) or "NA", _sec(s["mean_seconds"])) for s in summary]
    print(format_table(("theta", "cases", "certified", "mean gamma_UB", "mean |X^-X_obj|", "N_LMIVAR",
                        "mean time[s]"), rows))
    print(f"\nnote: {note}")
    return EXIT_OK


def _cmd_example(args) -> int:
    if args.k == 5:
        return _example5(args)
    return _example_paper(args)


# ----------------------------------------------------------------------------- dataset
def _summary_row(rs: list[TriangulationResult], times: list) -> dict:
    gub = [r.gamma_ub for r in rs if r.gamma_ub is not None]
    secs = [t for t, _ in times if t is not None]
    return {"cases": len(rs), "certified": sum(r.status == Status.OPTIMAL for r in rs),
            "mean_gamma_ub": float(np.mean(gub)) if gub else None,
            # the sample standard deviation (ddof = 1), as the paper's Tables 1-6 and benchmarks/example1.py;
            # 0 for a single case (the paper prints .000)
            "std_gamma_ub": (float(np.std(gub, ddof=1)) if len(gub) > 1 else 0.0) if gub else None,
            "n_lmivar": sorted({r.n_lmivar for r in rs if r.n_lmivar is not None}),
            "mean_seconds": float(np.mean(secs)) if secs else None}


def load_oxford(name: str, data_dir, command: str, outputs=()):
    """:func:`tritools.io.oxford.load_sequence` for a subcommand: a missing or unreadable sequence is a
    :class:`CLIError` naming what was tried (``--data-dir``, ``$TRITOOLS_DATA``) or the bad file.
    ``outputs``: ``(flag, path)`` of the files the command will write, refused (:func:`refuse_input_as_output`)
    when one is a file of the sequence's folder or lies anywhere inside that folder (review 29b F11)."""
    from ..io.oxford import DATA_ENV, DataNotFoundError, load_sequence
    from ..io.oxford import data_dir as oxford_data_dir

    try:
        seq = load_sequence(name, data_dir)
        folder = oxford_data_dir(data_dir) / name
        for flag, path in outputs:
            refuse_input_as_output(path, flag, [("the data file", f) for f in folder.iterdir()] +
                                   [("the sequence folder", folder)])
        return seq
    except DataNotFoundError as exc:
        msg = str(exc).replace("pass data_dir=...", "pass --data-dir DIR")
        if DATA_ENV not in msg:
            msg += f" (pass --data-dir DIR or set ${DATA_ENV})"
        raise CLIError(f"{command}: {msg}") from None
    except (ValueError, OSError) as exc:
        raise CLIError(f"{command}: {exc}") from None


def _cmd_dataset(args) -> int:
    from ..model.regions import Point

    options = options_from_args(args)
    select_tracks((), args.limit, args.sample, args.seed)            # the flags checked before any data is read
    seq = load_oxford(args.name, args.data_dir, "dataset", [("--csv", args.csv)])
    options = sequence_options(options, args, seq)
    tracks = select_tracks(seq.tracks, args.limit, args.sample, args.seed)
    specs = []
    for tr in tracks:
        cams, pts = seq.problem(tr)
        specs.append(ProblemSpec(cams, tuple(Point(p) for p in pts), name=f"{seq.name}:{tr.track_id}"))
    results, times = _solve_specs(specs, options, args.progress)
    by_n: dict[int, tuple] = defaultdict(lambda: ([], []))
    for tr, r, t in zip(tracks, results, times):
        by_n[tr.n_views][0].append(r)
        by_n[tr.n_views][1].append(t)
    summary = [{"N": n, **_summary_row(*by_n[n])} for n in sorted(by_n)]
    total = _summary_row(results, times)
    if args.csv:
        _write_dataset_csv(args.csv, seq.name, tracks, results, times)
    if args.json:
        _emit(_dumps({"sequence": seq.name, "method": args.method, "tracks": len(tracks), "per_N": summary,
                      "total": total, "world_frame": options.world_frame.value}), None)
        return EXIT_OK
    print(printable(f"{seq.name}: {len(tracks)} tracks, method {args.method}"))
    rows = [(s["N"], s["cases"], s["certified"], _num(s["mean_gamma_ub"]), _num(s["std_gamma_ub"]),
             ",".join(map(str, s["n_lmivar"])) or "NA", _sec(s["mean_seconds"]))
            for s in summary + [{"N": "total", **total}]]
    print(format_table(("N", "#cases", "#certified", "mean gamma_UB", "std gamma_UB", "N_LMIVAR", "mean time[s]"),
                       rows))
    if args.csv:
        print(f"per-track results: {args.csv}")
    return EXIT_OK


#: columns of ``tritools dataset --csv`` (``seconds``: the track's own solve time when ``seconds_source`` is
#: ``own``, its share of a vectorised batch when ``batch_share``; see :func:`_timed_solve`).
DATASET_CSV_COLUMNS = ("sequence", "track_id", "views", "N", "status", "X1", "X2", "X3", "gamma_lb", "gamma_ub",
                       "optimal", "delta", "n_lmivar", "certified_by", "seconds", "seconds_source", "message")


def _write_dataset_csv(path, name, tracks, results, times) -> None:
    try:
        with atomic_open(path, "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(DATASET_CSV_COLUMNS)
            for tr, r, (t, source) in zip(tracks, results, times):
                X = [None] * 3 if r.X is None else [float(v) for v in r.X]
                w.writerow([name, tr.track_id, " ".join(map(str, tr.views)), tr.n_views, r.status.value, *X,
                            r.gamma_lb, r.gamma_ub, r.optimal, r.delta, r.n_lmivar, r.certified_by,
                            t, source, r.message])
    except OSError as exc:
        raise write_error(path, exc) from None


# ----------------------------------------------------------------------------- parser
def register_builtin(sub) -> None:
    """The built-in subcommands: solve, example, dataset."""
    p = sub.add_parser("solve", help="triangulate the problems of a JSON problem file",
                       description="Triangulate every problem of FILE (one problem, a list, or "
                                   "{\"problems\": [...]}; schema in docs/cli.md).")
    p.add_argument("file", metavar="FILE", help="problem file, or - for stdin")
    add_solver_options(p)
    add_world_frame_option(p, sequence=False)
    add_robust_option(p)
    p.add_argument("--json", action="store_true", help="one JSON object per problem, all result fields")
    p.add_argument("--output", "-o", default=None, metavar="OUT", help="write the output to OUT instead of stdout")
    p.set_defaults(func=_cmd_solve)

    p = sub.add_parser("example", help="the paper's Example 2, 3, 4 (Tables 8-10) or a reduced Example 5")
    p.add_argument("k", type=int, choices=(2, 3, 4, 5), metavar="K",
                   help="2, 3, 4: the paper's Tables 8-10 (X_raw, refined X and the paper's X^); 5: reduced Table 11")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.add_argument("--points", type=int, default=5, help="Example 5: scene points (paper: 25)")
    p.add_argument("--trials", type=int, default=2, help="Example 5: trials per point and theta (paper: 10)")
    p.add_argument("--seed", type=int, default=0, help="Example 5: random seed")
    p.add_argument("--progress", action="store_true", default="auto",
                   help=f"Example 5: progress bar on stderr (needs tqdm; default: only for {PROGRESS_MIN_ITEMS} "
                        f"cases or more)")
    p.set_defaults(func=_cmd_example)

    p = sub.add_parser("dataset", help="triangulate the tracks of an Oxford sequence (Example 1)",
                       description="Per-N summary of an Oxford sequence (the paper's Tables 1-6).")
    p.add_argument("name", metavar="NAME", help="sequence (corridor, dinosaur, house, library, merton1-3, wadham)")
    add_data_dir_option(p)
    add_track_options(p)
    add_solver_options(p)
    add_world_frame_option(p)
    p.add_argument("--json", action="store_true", help="summary as JSON")
    p.add_argument("--csv", default=None, metavar="OUT", help="write per-track results to OUT")
    p.set_defaults(func=_cmd_dataset)


def _registered_modules():
    for name in SUBCOMMAND_MODULES:
        try:
            yield importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name != name:      # the module exists but something it imports does not: a real error
                raise


def build_parser() -> argparse.ArgumentParser:
    from .. import __version__

    ap = _Parser(prog="tritools", description="certified multiple-view L2 triangulation (Chesi 2026)")
    ap.add_argument("--version", action="version", version=f"tritools {__version__}",
                    help="print the version and exit")
    add_logging_options(ap, top=True)
    sub = ap.add_subparsers(dest="command", required=True, metavar="COMMAND", help="the subcommand")
    register_builtin(sub)
    for module in _registered_modules():
        module.register(sub)
    for p in sub.choices.values():
        add_logging_options(p)
    return ap


def _joined_negative_values(argv: list) -> list:
    """``--flag -inf`` as ``--flag=-inf``: argparse reads a value that starts with "-" but is not a plain negative
    number (``-inf``, ``-nan``, ``-1e5`` ...) as an option and says "expected one argument" instead of the flag's own
    message (review 22a F4).  Only a token that parses as a float after a ``--flag`` without "=" is joined."""
    out: list = []
    for tok in (str(t) for t in argv):
        prev = out[-1] if out else ""
        if prev.startswith("--") and "=" not in prev and tok.startswith("-") and is_float(tok):
            out[-1] = f"{prev}={tok}"
        else:
            out.append(tok)
    return out


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit code (0 ok, 1 internal error, 2 invalid input)."""
    os.environ.setdefault("RUST_BACKTRACE", "0")
    try:
        args = build_parser().parse_args(_joined_negative_values(sys.argv[1:] if argv is None else list(argv)))
        end_startup()                   # from here on Ctrl-C is a KeyboardInterrupt: cleanups run, then 130
        with cli_logging(args), terminate_unwinds():      # SIGTERM too (then 143)
            if os.environ.get(DEBUG_ENV):
                return int(args.func(args) or EXIT_OK)
            # extreme but finite input (|x| ~ 1e308) overflows inside numpy: its RuntimeWarnings would add
            # lines to the one-line error (the affected problems get their status rows or the one-line error)
            with warnings.catch_warnings(), np.errstate(all="ignore"):
                warnings.simplefilter("ignore", RuntimeWarning)
                return int(args.func(args) or EXIT_OK)
    except (CLIError, ProblemFileError) as exc:
        return exit_invalid(exc)
    except SystemExit as exc:            # --help
        return exc.code if isinstance(exc.code, int) else EXIT_OK if exc.code is None else EXIT_INVALID
    except Terminated as exc:
        with contextlib.suppress(OSError):     # after a hang-up the terminal may be gone
            print(exc.message, file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print(INTERRUPTED_MESSAGE, file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:              # `tritools ... | head`: the reader is gone; stop quietly
        silence_stdout()
        return EXIT_OK
    except Exception as exc:  # noqa: BLE001 - one line instead of a traceback, unless debugging
        if os.environ.get(DEBUG_ENV):
            raise
        print(f"tritools: internal error: {type(exc).__name__}: {exc} (set {DEBUG_ENV}=1 for the traceback)",
              file=sys.stderr)
        return EXIT_INTERNAL
