"""tritools: certified-optimal uncertain multiple-view L2 triangulation (Chesi 2026).

A thin front-end: regions declare (n_i, f_i, g_i, h_i) (:mod:`tritools.model.regions`),
camera geometry supplies the projection constraints (:mod:`tritools.model.constraints`),
and :mod:`sospoly` builds, solves and checks the certificate.  tritools never
imports a solver.

>>> import tritools
>>> cams, regions = tritools.paper_example(4)            # doctest: +SKIP
>>> res = tritools.triangulate(cams, regions, "theorem1", delta=4)   # doctest: +SKIP
>>> res.X, res.gamma_lb, res.gamma_ub, res.optimal          # doctest: +SKIP
"""
from .solve.batch import triangulate_many
from .model.constraints import Method
from .model.geometry import dlt, fundamental_matrix, gamma, project, validate_cameras
from .model.regions import Ellipse, EllipseBorder, Point, Polytope, Region, Segment
from .result import Status, TriangulationResult
from .scene import paper_example
from .solve.triangulate import triangulate

__version__ = "0.1.0"


__all__ = ["Method", "dlt", "fundamental_matrix", "gamma", "project", "validate_cameras", "Ellipse",
           "EllipseBorder", "Point", "Polytope", "Region", "Segment", "Status", "TriangulationResult",
           "triangulate", "triangulate_many", "paper_example"]
