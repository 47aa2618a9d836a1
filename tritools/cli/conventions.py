"""Command-line conventions shared by every subcommand: the logging flags (``-v``, ``-q``, ``--log-level``, one
stderr handler for the duration of a command), ``--progress`` without tqdm, a quiet end when the reader of stdout
goes away (``| head``), and ``--world-frame`` (the handedness in which ``in_front`` is judged)."""
from __future__ import annotations

import argparse
import contextlib
import os
import sys

from ..solve.options import TriangulationOptions

__all__ = ["LOG_LEVELS", "add_logging_options", "cli_logging", "add_world_frame_option", "sequence_options"]


#: ``--log-level`` choices (``-v``: info, ``-vv``: debug, ``--quiet``: errors only; default: warnings).
LOG_LEVELS = ("debug", "info", "warning", "error")


def add_logging_options(p, top: bool = False) -> None:
    """``-v/--verbose``, ``-q/--quiet``, ``--log-level`` (before or after the subcommand: the subcommands'
    copies default to SUPPRESS, so they never overwrite a value given before it)."""
    d = {} if top else {"default": argparse.SUPPRESS}
    p.add_argument("-v", "--verbose", action="count", help="more log messages on stderr (-v info, -vv debug)",
                   **({"default": 0} if top else d))
    p.add_argument("-q", "--quiet", action="store_true", help="only errors on stderr (no warnings, no progress bar)",
                   **({"default": False} if top else d))
    p.add_argument("--log-level", choices=LOG_LEVELS, dest="log_level", help="log level (default warning)",
                   **({"default": None} if top else d))


@contextlib.contextmanager
def cli_logging(args):
    """For the duration of one command: a stderr handler on the ``tritools`` and ``sospoly`` loggers at the
    level the flags ask for (``tritools: <level>: message``); the loggers are restored afterwards (``main`` may
    run inside a host program or a test)."""
    import logging

    level = getattr(args, "log_level", None)
    if level is None:
        level = "error" if getattr(args, "quiet", False) else \
            {0: "warning", 1: "info"}.get(getattr(args, "verbose", 0) or 0, "debug")
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_LowerLevelFormatter())
    saved = []
    for name in ("tritools", "sospoly"):
        lg = logging.getLogger(name)
        saved.append((lg, lg.level, lg.propagate))
        lg.addHandler(handler)
        lg.setLevel(level.upper())
        lg.propagate = False                       # one line per message, whatever the host's root logger does
    try:
        _progress_flag(args)
        yield
    finally:
        for lg, lvl, prop in saved:
            lg.removeHandler(handler)
            lg.setLevel(lvl)
            lg.propagate = prop


def _progress_flag(args) -> None:
    """``--quiet`` turns the automatic bar off; ``--progress`` without tqdm says so once."""
    import logging

    if getattr(args, "quiet", False) and getattr(args, "progress", None) == "auto":
        args.progress = False
    if getattr(args, "progress", None) is True and not _has_tqdm():
        logging.getLogger("tritools").warning("--progress needs tqdm (pip install 'sospoly-tritools[progress]'): "
                                              "continuing without a progress bar")
        args.progress = False                      # said once, here


def _has_tqdm() -> bool:
    try:
        import tqdm  # noqa: F401
    except ImportError:
        return False
    return True


class _LowerLevelFormatter:
    """``tritools: warning: message`` (logging's level names in lower case)."""

    def format(self, record) -> str:
        return f"tritools: {record.levelname.lower()}: {record.getMessage()}"


def add_world_frame_option(p, sequence: bool = True) -> None:
    """``--world-frame``: the handedness in which ``in_front`` is judged (:class:`tritools.model.cameras.WorldFrame`);
    for the subcommands reading an Oxford sequence ``auto`` (their default) reads it off the sequence's tracks."""
    if sequence:
        p.add_argument("--world-frame", choices=("auto", "right_handed", "reflected"), default="auto",
                       dest="world_frame",
                       help="handedness of the cameras' world frame for in_front / --require-in-front: auto (read "
                            "off the sequence's tracks: corridor and house are reflected), right_handed or "
                            "reflected; default auto")
    else:
        p.add_argument("--world-frame", choices=("right_handed", "reflected"), default="right_handed",
                       dest="world_frame",
                       help="handedness of the cameras' world frame for in_front / --require-in-front (reflected: "
                            "a mirrored reconstruction, every det M < 0); default right_handed")


def sequence_options(options: TriangulationOptions, args, seq) -> TriangulationOptions:
    """``options`` with the world frame of ``--world-frame`` (``auto``: :attr:`Sequence.world_frame`)."""
    frame = getattr(args, "world_frame", "auto")
    if frame != "auto":
        return options.replace(world_frame=frame)
    try:
        return options.replace(world_frame=seq.world_frame)
    except ValueError as exc:                   # no track to read it from (an empty nview-corners file: review 29b F6)
        from .app import CLIError

        raise CLIError(f"--world-frame auto: {exc}; give --world-frame right_handed or reflected") from None


def silence_stdout() -> None:
    """Point stdout at /dev/null so that the interpreter's final flush does not fail again."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):   # stdout without a file descriptor (tests)
        pass
