"""The ``tritools`` command line: :mod:`.main` (parser, ``solve``, ``example``, ``dataset``),
:mod:`.colmap` (``colmap``, ``colmap-from-oxford``) and :mod:`.plot` (``figure3``, ``plot-dataset``)."""
from .app import main

__all__ = ["main"]
