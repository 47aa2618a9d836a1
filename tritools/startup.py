"""Ctrl-C while the ``tritools`` command starts: one line and exit code 130, no traceback.

Importing tritools (numpy, scipy, sospoly) takes about a second; an interrupt during it would print a
long traceback and kill the process by the signal.  :func:`guard_startup` runs first in
``tritools/__init__.py`` (stdlib only) and, only when this process *is* the command (``python -m
tritools`` or the ``tritools`` script; a library import is never affected), handles SIGINT by
printing ``tritools: interrupted`` and exiting 130.  :func:`end_startup` (called by the command's
``main``) restores Python's handler, so that an interrupt while solving raises KeyboardInterrupt and
every ``finally`` (staging directories, temporary files) runs before the same exit code.  SIGTERM (what
``timeout``, SLURM and ``docker stop`` send) unwinds the same way while the command runs
(:func:`terminate_unwinds`: :class:`Terminated`, exit 143; review 27a F7: it left a staging directory in OUT).
"""
from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading

__all__ = ["guard_startup", "end_startup", "is_command", "terminate_unwinds", "Terminated", "EXIT_INTERRUPTED",
           "INTERRUPTED_MESSAGE", "EXIT_TERMINATED", "TERMINATED_MESSAGE"]

EXIT_INTERRUPTED = 130
INTERRUPTED_MESSAGE = "tritools: interrupted"
EXIT_TERMINATED = 128 + signal.SIGTERM
TERMINATED_MESSAGE = "tritools: terminated"


class Terminated(KeyboardInterrupt):
    """SIGTERM (or SIGHUP: the terminal closed) while the command runs: unwinds as Ctrl-C does (every cleanup runs),
    then exit 128 + ``signum`` (:data:`EXIT_TERMINATED` for SIGTERM) with :meth:`message`."""

    def __init__(self, signum: int = signal.SIGTERM):
        super().__init__(signum)
        self.signum = int(signum)

    @property
    def exit_code(self) -> int:
        return 128 + self.signum

    @property
    def message(self) -> str:
        return TERMINATED_MESSAGE if self.signum == signal.SIGTERM else f"tritools: {signal.Signals(self.signum).name}"


#: the signals :func:`terminate_unwinds` turns into :class:`Terminated` (SIGHUP where the platform has it: closing
#: the terminal left a 16 MB staging folder in OUT_DIR, review 29b F15)
UNWOUND_SIGNALS = tuple(getattr(signal, name) for name in ("SIGTERM", "SIGHUP") if hasattr(signal, name))


def _terminate(signum, frame) -> None:
    raise Terminated(signum)


@contextlib.contextmanager
def terminate_unwinds():
    """While inside, SIGTERM raises :class:`Terminated` in the main thread (where Python's default would kill the
    process and skip every ``finally``); the previous handler is restored on the way out.  Elsewhere (another
    thread, or a handler the host program set) nothing changes."""
    main = threading.current_thread() is threading.main_thread()
    mine = [s for s in UNWOUND_SIGNALS if main and signal.getsignal(s) == signal.SIG_DFL]
    for s in mine:
        signal.signal(s, _terminate)
    try:
        yield
    finally:
        for s in mine:
            signal.signal(s, signal.SIG_DFL)


def is_command() -> bool:
    """True when this process runs the tritools command line (``-m tritools`` or the script)."""
    argv = list(getattr(sys, "orig_argv", ()) or ())
    if "-m" in argv[:-1] and argv[argv.index("-m") + 1] in ("tritools", "tritools.__main__"):
        return True
    return bool(sys.argv) and os.path.basename(sys.argv[0] or "") in ("tritools", "tritools.exe")


def _interrupted(signum, frame) -> None:      # pragma: no cover - runs in the subprocess of the test
    try:
        os.write(2, (INTERRUPTED_MESSAGE + "\n").encode())
    finally:
        os._exit(EXIT_INTERRUPTED)


def guard_startup() -> None:
    """Exit 130 with one line on SIGINT until :func:`end_startup` (only for the command)."""
    if is_command() and signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        signal.signal(signal.SIGINT, _interrupted)


def end_startup() -> None:
    """Back to KeyboardInterrupt on SIGINT (the command's ``main`` turns it into exit 130)."""
    if signal.getsignal(signal.SIGINT) is _interrupted:
        signal.signal(signal.SIGINT, signal.default_int_handler)


guard_startup()
