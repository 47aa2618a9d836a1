"""``python -m tritools``: the command line of :mod:`tritools.cli.app` (``tritools --help``)."""
from __future__ import annotations

import sys

from .cli import main

__all__ = ["main"]

if __name__ == "__main__":
    sys.exit(main())
