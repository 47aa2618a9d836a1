"""The ``tritools`` command line: :mod:`.app` (parser, ``solve``, ``example``, ``dataset``, the shared
solver and track flags), :mod:`.colmap` (``colmap``, ``colmap-from-oxford``) and :mod:`.plot`
(``figure3``, ``plot-dataset``)."""
from .app import main

__all__ = ["main"]
