"""tritools: certified-optimal uncertain multiple-view L2 triangulation (Chesi 2026).

A thin front-end: regions declare (n_i, f_i, g_i, h_i) (:mod:`tritools.model.regions`), camera
geometry supplies the projection constraints (:mod:`tritools.model.constraints`), and :mod:`sospoly`
builds, solves and checks the certificate.  tritools never imports a solver.

Layout (docs/architecture.md): :mod:`tritools.model` (the problem as data), :mod:`tritools.solve`
(options, strategies, batches), :mod:`tritools.io` (problem files, Oxford data, COLMAP models),
:mod:`tritools.sfm` (COLMAP workflows), :mod:`tritools.cli`, :mod:`tritools.plot`.

>>> import tritools
>>> cams, regions = tritools.paper_example(4)            # doctest: +SKIP
>>> res = tritools.triangulate(cams, regions, "theorem1", delta=4)   # doctest: +SKIP
>>> res.X, res.gamma_lb, res.gamma_ub, res.optimal          # doctest: +SKIP
"""
from . import startup  # noqa: F401 - first: Ctrl-C while the command starts exits 130 with one line

import logging as _logging

from .model.constraints import Method
from .model.geometry import depths, dlt, fundamental_matrix, gamma, project, validate_cameras
from .model.opencv import PointsLayout, cameras_from_krt
from .model.regions import Ellipse, EllipseBorder, Point, Polytope, Region, Segment, as_regions
from .records import TriangulationResults
from .result import Attempt, IllPosedError, Status, TriangulationResult
from .scene import paper_example
from .solve.batch import triangulate_many
from .solve.options import DEFAULT_OPTIONS, OptionError, SolvePath, Sparsity, TriangulationOptions
from .solve.points import PointsResult, triangulate_points
from .solve.triangulate import triangulate
from .uncertain import (UncertaintyOptions, UncertaintyResult, UncertaintyStatus, triangulation_angle, uncertainty,
                        uncertainty_many)

__version__ = "0.2.0"

_logging.getLogger(__name__).addHandler(_logging.NullHandler())

__all__ = ["Method", "depths", "dlt", "fundamental_matrix", "gamma", "project", "validate_cameras", "Ellipse",
           "EllipseBorder", "Point", "Polytope", "Region", "Segment", "as_regions", "Attempt", "Status",
           "IllPosedError", "TriangulationResult", "paper_example", "triangulate_many", "DEFAULT_OPTIONS", "SolvePath",
           "Sparsity", "TriangulationOptions", "PointsResult", "triangulate_points", "triangulate", "PointsLayout",
           "cameras_from_krt", "UncertaintyOptions", "UncertaintyResult", "UncertaintyStatus", "triangulation_angle",
           "uncertainty", "uncertainty_many", "OptionError", "TriangulationResults"]
