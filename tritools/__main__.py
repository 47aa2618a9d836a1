"""``python -m tritools``: the command line of :mod:`tritools.cli.app` (``tritools --help``)."""
from __future__ import annotations

import signal
import sys

from .startup import EXIT_INTERRUPTED, Terminated, guard_startup

guard_startup()                 # before the heavy imports (the package's __init__ installed it already)

from .cli import main  # noqa: E402

__all__ = ["main"]

if __name__ == "__main__":
    try:
        code = main()
    except Terminated as exc:          # between main's own handler and its return
        code = exc.exit_code
    except KeyboardInterrupt:
        code = EXIT_INTERRUPTED
    signal.signal(signal.SIGINT, signal.SIG_IGN)      # the exit code is decided: the shutdown is not interrupted
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    if hasattr(signal, "SIGHUP"):
        signal.signal(signal.SIGHUP, signal.SIG_IGN)
    sys.exit(code)
