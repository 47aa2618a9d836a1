"""Admissible image regions R_i and their polynomial descriptions (SPEC §2).

Each region declares the number ``n_aux`` (``n_i``) of auxiliary variables
``y_i`` and, given polynomial image coordinates ``x_i`` and auxiliaries ``y_i``,
the quadratic ``f_i`` with ``f_i = d(x_i, R_i)^2`` at the minimising ``y_i``
(paper eq. (14)), the equalities ``g_i = 0`` and inequalities ``h_i >= 0``
(paper eq. (13)), Section 4.2 cases I-V:

=================  ====  ========================  ==============================
region             n_i   f_i                       g_i / h_i
=================  ====  ========================  ==============================
Point {x^}         0     ||x - x^||^2              --
Segment            1     ||x - x^ - y d^||^2       h = 1 - y^2
Polytope           2     ||x - y||^2               h_k = 1 - (B y + c)_k^2
EllipseBorder      2     ||x - y||^2               g = 1 - (y-x^)' D^-1 (y-x^)
Ellipse (filled)   2     ||x - y||^2               h = 1 - (y-x^)' D^-1 (y-x^)
=================  ====  ========================  ==============================

Besides the polynomials, every region computes the exact Euclidean distance
``d(p, R)`` (paper eq. (7)) and closest point, used to evaluate ``gamma(X)``.
A new region type subclasses :class:`Region` (as a frozen dataclass with
``eq=False``) and implements ``n_aux``, ``polynomials``, ``closest_point``,
``center`` and ``similarity``; to be triangulated with the SDP it also declares
``extent`` (the bound behind the rigorous lower bound), and ``conic_form`` for the
certified uncertainty; ``is_point`` and ``disc_radius`` open the fast paths (their
defaults, False and None, are always correct).  A missing ``extent`` or
``conic_form`` raises a TypeError naming it when it is needed -- a region is never
certified without the margin.  docs/regions.md has a worked example; a class
attribute ``kind`` registers it for :meth:`Region.from_dict`.

Layout: :mod:`.base` (the interface, the registry and the validation helpers),
:mod:`.point` (Point, Segment), :mod:`.polytope` (Polytope and its vertices),
:mod:`.ellipse` (EllipseBorder, Ellipse), :mod:`.coerce` (:func:`as_regions`, the one
input boundary for regions), :mod:`.forms` (:class:`RegionExtent`, :class:`ConicForm`: what
the solvers need of a region), :mod:`.dilation` (:func:`dilate`, from the conic form).  Every
public name is importable from this package.
"""
from __future__ import annotations

# The import order is the registration order of the region kinds (Region.__subclasses__ order,
# which tritools.io.problem_file lists in its messages): point, segment, polytope, ellipse_border,
# ellipse.  Keep it; import sorters are told to leave this block alone.
# isort: off
from .forms import EXTENT_ROUND_UP, ConeKind, ConicForm, RegionExtent, conic_form_of, extent_of
from .base import (Region, RegionPolynomials, as_matrix, as_points, as_vector, check_xy, declares_extent,
                   positive_number, real_array, require_extent, similarity_args, square)
from .point import Point, Segment
from .polytope import (POLYTOPE_CHUNK, POLYTOPE_RANK_RTOL, POLYTOPE_ROUNDOFF, POLYTOPE_VERTEX_RTOL, Polytope,
                       polytope_vertices)
from .ellipse import ELLIPSE_MAX_ITER, ELLIPSE_SCALAR_MAX, PD_RTOL, SYMMETRY_RTOL, Ellipse, EllipseBorder
from .coerce import as_region, as_regions
from .dilation import DILATION_GROW, dilate
from .stack import RegionStack
# isort: on

__all__ = [
    "Region", "RegionPolynomials", "Point", "Segment", "Polytope", "EllipseBorder", "Ellipse",
    "as_region", "as_regions",
    # what the solvers need of a region (issue 18): its extent, conic form and dilation
    "RegionExtent", "ConeKind", "ConicForm", "dilate", "EXTENT_ROUND_UP", "DILATION_GROW", "extent_of", "conic_form_of",
    "declares_extent", "require_extent",
    # added with the package split
    "polytope_vertices", "positive_number", "real_array", "as_vector", "as_matrix", "as_points", "similarity_args",
    "check_xy", "square",
    "POLYTOPE_RANK_RTOL", "POLYTOPE_VERTEX_RTOL", "POLYTOPE_ROUNDOFF", "POLYTOPE_CHUNK", "SYMMETRY_RTOL", "PD_RTOL",
    "ELLIPSE_MAX_ITER", "ELLIPSE_SCALAR_MAX",
    # one closest point per view, stacked by kind (issue 22)
    "RegionStack",
]
