"""The solver and data flags shared by the subcommands, and their one validation.

:func:`add_solver_options` adds the flags of every subcommand that solves; :func:`options_from_args` builds the
:class:`~tritools.solve.options.TriangulationOptions` they stand for -- the one validation of the flags and the
problem-file fields -- and turns its :class:`~tritools.solve.options.OptionError` into a one-line
:class:`CLIError` naming the flag (:data:`OPTION_FLAGS` maps the error's ``field`` to it; no message is parsed).
:mod:`tritools.cli.app` re-exports every name here.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..solve.batch import PROGRESS_MIN_ITEMS
from ..solve.options import TRIANGULATION_BUDGET, MethodChoice, OptionError, SolvePath, TriangulationOptions

__all__ = ["CLIError", "METHODS", "PATHS", "SPARSITIES", "OPTION_FLAGS", "add_solver_options", "option_flag_error",
           "options_from_args", "add_robust_option", "robust_from_args", "add_track_options", "add_data_dir_option",
           "select_tracks", "refuse_input_as_output", "write_error"]

METHODS = tuple(m.value for m in MethodChoice)
PATHS = tuple(p.value for p in SolvePath)
SPARSITIES = ("auto", "none", "views")          # the spellings of tritools.solve.options.SPARSITY_CHOICES


class CLIError(Exception):
    """Invalid usage or input: printed as one line, exit code 2."""


def write_error(path, exc: OSError) -> CLIError:
    """The one-line :class:`CLIError` ``cannot write PATH: reason`` of an output that could not be written (the
    target named, never a temporary file: :mod:`tritools.io.atomic`)."""
    return CLIError(f"cannot write {path}: {exc.strerror or exc}")


def refuse_input_as_output(output, name: str, inputs) -> None:
    """CLIError (exit 2, before any work) when the output ``output`` of the flag ``name`` is one of the command's
    ``inputs`` (``(name, path)`` pairs; :func:`tritools.io.atomic.input_clash`, the rule ``tritools colmap``
    applies to OUT_DIR); None and ``-`` (stdout) are never refused."""
    from ..io.atomic import input_clash

    if output is None or str(output) == "-":
        return
    clash = input_clash(output, name, [(n, p) for n, p in inputs if p is not None and str(p) != "-"])
    if clash:
        raise CLIError(clash)


def add_solver_options(p, default_method: str = "auto", default_path: str = "auto",
                       progress_help: str | None = None) -> None:
    """The solver flags of every subcommand that solves (``--method --delta --max-delta --path --sparsity
    --time-limit --total-time-limit --memory-limit --require-in-front --progress``); :func:`options_from_args`
    validates them exactly like the fields of a problem file."""
    p.add_argument("--method", choices=METHODS, default=default_method,
                   help=f"auto (Corollary 1 at delta 2, then delta 4), theorem1 (4x4 minors) or corollary1 "
                        f"(epipolar); default {default_method}")
    p.add_argument("--delta", type=int, default=None, metavar="D",
                   help="first relaxation degree (even >= 2; default delta_min)")
    p.add_argument("--max-delta", type=int, default=None, dest="max_delta", metavar="D",
                   help="last degree tried (even >= delta; default 4 for method auto, else delta or delta_min + 2)")
    p.add_argument("--path", choices=PATHS, default=default_path,
                   help=f"'auto' first tries certification by verification (delta 2, point regions); 'sdp' always "
                        f"solves the SDP; default {default_path}")
    p.add_argument("--sparsity", choices=SPARSITIES, default="auto",
                   help="formulation above delta 2: auto (dense where small), none (dense), views (view cliques)")
    p.add_argument("--time-limit", type=float, default=None, dest="time_limit", metavar="S",
                   help=f"seconds per point (default {TRIANGULATION_BUDGET.time_limit:g}); exceeding it gives status "
                        f"time_limit")
    p.add_argument("--total-time-limit", type=float, default=None, dest="total_time_limit", metavar="S",
                   help="seconds for the whole run (default: no limit); the points not finished by then get status "
                        "time_limit, each still with its row")
    p.add_argument("--memory-limit", type=float, default=None, dest="memory_limit", metavar="GIB",
                   help="largest estimated program, GiB (default 2); larger ones give status budget_exceeded")
    p.add_argument("--require-in-front", action="store_true", dest="require_in_front",
                   help="a certified point behind a camera gets status behind_camera (default: optimal, in_front "
                        "false)")
    p.add_argument("--progress", action="store_true", default="auto",
                   help=progress_help or f"progress bar on stderr (needs the 'progress' extra, tqdm; default: only "
                                         f"for batches of {PROGRESS_MIN_ITEMS} problems or more)")


#: the flag of each option field (:attr:`OptionError.field`); a field without a flag is reported as "options".
OPTION_FLAGS = {"method": "--method", "delta": "--delta", "max_delta": "--max-delta", "path": "--path",
                "sparsity": "--sparsity", "time_limit": "--time-limit", "max_bytes": "--memory-limit",
                "total_time_limit": "--total-time-limit", "require_in_front": "--require-in-front",
                "world_frame": "--world-frame"}
#: the unit of the limit flags, for their messages (the flag's value, not the field's: GiB, not bytes).
_LIMIT_UNITS = {"time_limit": ("time_limit", "seconds"), "max_bytes": ("memory_limit", "GiB"),
                "total_time_limit": ("total_time_limit", "seconds")}


def option_flag_error(exc: OptionError, args=None) -> CLIError:
    """The one-line :class:`CLIError` ``FLAG: message`` of an invalid option, for every subcommand: the flag of a
    solver option from :data:`OPTION_FLAGS` (then the option's message), the flag of any other field spelt from
    it (``min_track_length`` -> ``--min-track-length``, then the reason: ``--robust: must be ...``)."""
    if exc.field not in OPTION_FLAGS:
        return CLIError(f"--{exc.field.replace('_', '-')}: {exc.text}")
    flag = OPTION_FLAGS[exc.field]
    if exc.field in _LIMIT_UNITS and args is not None:
        dest, unit = _LIMIT_UNITS[exc.field]
        return CLIError(f"{flag}: must be a positive number of {unit}, got {vars(args).get(dest)}")
    return CLIError(f"{flag}: {exc}")


def options_from_args(args) -> TriangulationOptions:
    """The :class:`TriangulationOptions` of parsed solver flags; a bad value is a :class:`CLIError` naming the flag
    (the same rules as the problem-file fields: the :class:`OptionError` of the options names the field)."""
    get = vars(args).get                     # subcommands with only some of the flags (figure3: method, delta)
    memory = get("memory_limit")
    try:
        options = TriangulationOptions(method=get("method", "auto"), delta=get("delta"), max_delta=get("max_delta"),
                                       path=get("path", "auto"), sparsity=get("sparsity", "auto"),
                                       require_in_front=bool(get("require_in_front")),
                                       world_frame=get("world_frame") if get("world_frame") not in (None, "auto")
                                       else "right_handed", total_time_limit=get("total_time_limit"))
        return options.replace(time_limit=get("time_limit"), max_bytes=None if memory is None else memory * 2 ** 30)
    except OptionError as exc:
        raise option_flag_error(exc, args) from None


def add_robust_option(p) -> None:
    """``--robust C``: certified truncated least squares with threshold C pixels (:mod:`tritools.solve.robust`)."""
    p.add_argument("--robust", type=float, default=None, metavar="C",
                   help="certified outlier-robust triangulation: truncated least squares with threshold C pixels "
                        "(views farther than C from the estimate are outliers; see docs/robust.md)")


def robust_from_args(args):
    """The ``--robust`` threshold of every subcommand that has the flag (None when absent), validated by the
    library's one rule (:func:`tritools.sfm.certify.robust_threshold`: positive, at least
    :data:`tritools.solve.robust.MIN_THRESHOLD`; ``inf`` is the plain L2 problem); a :class:`CLIError`
    ``--robust: ...`` otherwise (:func:`option_flag_error`)."""
    from ..sfm.certify import robust_threshold

    try:
        return robust_threshold(getattr(args, "robust", None))
    except OptionError as exc:
        raise option_flag_error(exc, args) from None


def add_track_options(p) -> None:
    """``--limit K --sample K --seed S`` of the subcommands running an Oxford sequence (:func:`select_tracks`)."""
    p.add_argument("--limit", type=int, default=None, metavar="K",
                   help="only the first K tracks, in file order (default: all)")
    p.add_argument("--sample", type=int, default=None, metavar="K",
                   help="K tracks drawn at random (after --limit; kept in file order; default: no sampling)")
    p.add_argument("--seed", type=int, default=0, metavar="S", help="seed of --sample (default 0)")


def add_data_dir_option(p) -> None:
    """``--data-dir`` of the subcommands reading an Oxford sequence (:func:`tritools.io.oxford.load_sequence`)."""
    p.add_argument("--data-dir", default=None, dest="data_dir",
                   help="Oxford data directory (default: $TRITOOLS_DATA, else ../shared/data/oxford)")


def select_tracks(tracks: Sequence, limit: int | None = None, sample: int | None = None, seed: int = 0) -> list:
    """The tracks of ``--limit K`` (the first K, in file order) then ``--sample K`` (K of those drawn at random
    with ``--seed``, kept in file order); CLIError for a bad value."""
    for flag, value in (("--limit", limit), ("--sample", sample)):
        if value is not None and value < 1:
            raise CLIError(f"{flag}: must be a positive integer, got {value}")
    if seed < 0:
        raise CLIError(f"--seed: must be a non-negative integer, got {seed}")
    out = list(tracks[:limit] if limit is not None else tracks)
    if sample is not None and sample < len(out):
        idx = np.sort(np.random.default_rng(seed).choice(len(out), size=sample, replace=False))
        out = [out[j] for j in idx]
    return out
