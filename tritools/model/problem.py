"""The polynomial program of uncertain multiple-view L2 triangulation (SPEC §2, §5).

v = (x_1, ..., x_N, y_1, ..., y_N) with x_i in R^2 the image point of view i and y_i in R^{n_i}
the auxiliary variables of region i.  Then

    f = sum_i f_i,   g = (g_1, ..., g_N, m2),   h = (h_1, ..., h_N),
    gamma*^2 = (1/(2N)) inf f  s.t.  g = 0, h >= 0            (the paper's (41))

Regions only declare (n_i, f_i, g_i, h_i); the projection constraints m2 come from
:mod:`tritools.model.constraints`.  Every constraint records the views it involves
(``eq_views`` / ``ineq_views``) and every view its variables (``view_vars``): that is all a sparse
certificate needs to know (the solve layer turns view cliques into variable cliques for
:func:`sospoly.clique_shape`).  Nothing here solves anything.

Formulations (``formulation``):

* ``"dense"`` -- the paper's: Theorem 1's minors of all views (C(2N, 4), for N <=
  :data:`~tritools.model.constraints.THEOREM1_DENSE_MAX_VIEWS`) or Corollary 1's epipolar pairs;
* ``"views"`` -- for sparse certificates over view cliques (a cyclic band of view pairs for Corollary 1, a
  chain of view triples for Theorem 1): every epipolar pair (they enter the dense degree-2 block) and,
  for Theorem 1, the minors of each triple of the chain.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from sospoly import Polynomial, sum_in_order, variables
from sospoly.budget import check_deadline

from ..errors import ProblemTooLarge
from .coef_error import ConstraintErrors
from .constraints import (THEOREM1_DENSE_MAX_VIEWS, Method, centre_relations, corollary1_constraints, minor_count,
                          theorem1_constraints, triple_minor_constraints)

__all__ = ["TriangulationProblem", "build_problem", "view_chain", "view_band", "FORMULATIONS"]

FORMULATIONS = ("dense", "views")


@dataclass(frozen=True)
class TriangulationProblem:
    gens: tuple
    x_index: np.ndarray           # position in gens of x_11, x_12, x_21, ...
    f: Polynomial
    eq: tuple                     # region equalities, then the projection constraints
    ineq: tuple
    n_views: int
    method: Method
    projection: tuple             # the m2 polynomials alone
    info: dict = field(default_factory=dict)
    view_vars: tuple = ()         # per view: indices in gens of x_i and y_i
    eq_views: tuple = ()          # per equality: the views it involves
    ineq_views: tuple = ()        # per inequality: the views it involves
    formulation: str = "dense"
    #: how far the coefficients of ``eq`` are from exact constraints' (:class:`~.coef_error.ConstraintErrors`: the
    #: regions' are exact, the projection constraints' computed), charged by :func:`sospoly.rigorous_psatz_bound`
    eq_error: ConstraintErrors | None = None

    def image_points(self, v: np.ndarray) -> np.ndarray:
        """(N, 2) image points x_i read from a vector v in ``gens`` order."""
        return np.asarray(v, float)[self.x_index].reshape(self.n_views, 2)

    def variables_of_views(self, views) -> frozenset:
        return frozenset(i for view in views for i in self.view_vars[view])


def view_band(n_views: int, reach: int = 3) -> tuple:
    """The view pairs {i, i + d mod N} for d = 1..``reach``: a cyclic band of pairs (N * reach pairs, all
    pairs when N <= 2 reach + 1), sorted and without repeats.

    Why a closed band of reach 3: the first and last views' epipolar constraint gets a quartic multiplier
    too, and pairs up to three apart tie each view to more than its two neighbours.  On random
    mixed-region scenes with regions as large as the noise (16 px at f = 800) the open chain of pairs
    left gaps of 1e-4..1e-2 at N = 10..16, reach 2 still one of four at N = 16 (gap 5e-3), reach 3 none,
    at a cost linear in N (benchmarks/manyview.py)."""
    if n_views <= 2:
        return (tuple(range(n_views)),)
    pairs = {tuple(sorted((i, (i + d) % n_views))) for d in range(1, max(1, int(reach)) + 1)
             for i in range(n_views)}
    return tuple(sorted(p for p in pairs if p[0] != p[1]))


def view_chain(n_views: int, width: int = 3) -> tuple:
    """Consecutive view groups of ``width`` (the chain of triples by default): a chordal band whose
    clique tree is a path; one group of all views when there are at most ``width``."""
    width = max(1, min(int(width), n_views))
    return tuple(tuple(range(k, k + width)) for k in range(n_views - width + 1))


def build_problem(cameras: np.ndarray, regions, method: Method = Method.THEOREM1,
                  formulation: str = "dense", relations=None) -> TriangulationProblem:
    """Assemble (f, g, h) for validated cameras (N, 3, 4) and regions (SPEC §2 table).  ``relations``: which
    views share a centre (:func:`~tritools.model.constraints.centre_relations` of the raw cameras when
    ``cameras`` are normalised ones; default: decided on ``cameras``)."""
    method = Method(method)
    if formulation not in FORMULATIONS:
        raise ValueError(f"formulation must be one of {FORMULATIONS}, got {formulation!r}")
    N = len(regions)
    names = [f"x{i + 1}_{k + 1}" for i in range(N) for k in range(2)]
    for i, reg in enumerate(regions):
        names += [f"y{i + 1}_{k + 1}" for k in range(reg.n_aux)]
    v = variables(names)
    gens = v[0].gens
    x_index = np.arange(2 * N)
    fs, eq, ineq, eq_views, ineq_views, view_vars = [], [], [], [], [], []
    pos = 2 * N
    for i, reg in enumerate(regions):
        check_deadline("building the regions' polynomials")
        xi = (v[2 * i], v[2 * i + 1])
        yi = tuple(v[pos:pos + reg.n_aux])
        view_vars.append((2 * i, 2 * i + 1) + tuple(range(pos, pos + reg.n_aux)))
        pos += reg.n_aux
        polys = reg.polynomials(xi, yi)
        fs.append(polys.f)
        eq += [p.with_gens(gens) for p in polys.eq]
        ineq += [p.with_gens(gens) for p in polys.ineq]
        eq_views += [(i,)] * len(polys.eq)
        ineq_views += [(i,)] * len(polys.ineq)
    f = sum_in_order(gens, fs)
    if method == Method.THEOREM1 and formulation == "dense":
        if N > THEOREM1_DENSE_MAX_VIEWS:
            raise ProblemTooLarge(f"Theorem 1 with all minors is built for at most {THEOREM1_DENSE_MAX_VIEWS} views "
                             f"(C(2N, 4) = {minor_count(2 * N)} minors for N = {N}); use the 'views' formulation")
        rel = centre_relations(cameras) if relations is None else relations
        proj, info = theorem1_constraints(cameras, gens, x_index, rel.groups, rel.loose)
        proj_views, errors = [tuple(range(N))] * len(proj), [info["errors"]]
        if rel.coincident:          # views with one centre: their minors vanish; the pair's homography instead
            hom, hinfo = corollary1_constraints(cameras, gens, x_index, sorted(rel.coincident), relations=rel)
            errors.append(hinfo["errors"].shifted(len(proj)))
            proj, proj_views = proj + hom, proj_views + list(hinfo["pairs"])
            info = {**info, "N1": info["N1"] + hinfo["N1"], "N2": info["N2"] + hinfo["N2"],
                    "homography": hinfo["homography"]}
    else:
        proj, info = corollary1_constraints(cameras, gens, x_index, relations=relations)
        proj_views, errors = list(info["pairs"]), [info["errors"]]
        if method == Method.THEOREM1:
            minors, tinfo = triple_minor_constraints(cameras, gens, x_index, view_chain(N),
                                                     None if relations is None else relations.groups,
                                                     () if relations is None else relations.loose)
            errors += [e.shifted(len(proj)) for e in tinfo["errors"]]
            proj, proj_views = proj + minors, proj_views + tinfo["views"]
            info = {**info, "N1": info["N1"] + tinfo["N1"], "N2": info["N2"] + tinfo["N2"], "triples": view_chain(N)}
    return TriangulationProblem(gens, x_index, f.with_gens(gens), tuple(eq) + tuple(proj), tuple(ineq), N,
                                method, tuple(proj), info, tuple(view_vars), tuple(eq_views) + tuple(proj_views),
                                tuple(ineq_views), formulation,
                                ConstraintErrors(len(eq) + len(proj), tuple(e.shifted(len(eq)) for e in errors)))
