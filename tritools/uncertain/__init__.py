"""Certified 3D uncertainty of a triangulated point (docs/uncertainty.md).

:mod:`.sets` (the per-view set as conic constraints), :mod:`.solve` (stacked bound problems),
:mod:`.rigour` (rigorous bounds from dual multipliers), :mod:`.witness` (feasible inner points,
ray checks), :mod:`.api` (``uncertainty``,
``uncertainty_many``), :mod:`.discs` (array entry for disc regions), :mod:`.angle`
(triangulation angles).
"""
from .angle import triangulation_angle, triangulation_angles
from .api import UncertaintyOptions, UncertaintyResult, UncertaintyStatus, uncertainty, uncertainty_many
from .discs import uncertainty_discs

__all__ = ["UncertaintyOptions", "UncertaintyResult", "UncertaintyStatus", "uncertainty", "uncertainty_many",
           "uncertainty_discs", "triangulation_angle", "triangulation_angles"]
