"""Certified 3D uncertainty of a triangulated point (docs/uncertainty.md).

:mod:`.sets` (the per-view set as conic constraints), :mod:`.solve` (stacked bound problems),
:mod:`.rigour` (rigorous bounds from dual multipliers), :mod:`.api` (``uncertainty``,
``uncertainty_many``), :mod:`.angle` (triangulation angles).
"""
from .api import UncertaintyOptions, UncertaintyResult, UncertaintyStatus, uncertainty, uncertainty_many

__all__ = ["UncertaintyOptions", "UncertaintyResult", "UncertaintyStatus", "uncertainty", "uncertainty_many"]
