"""The polynomial program of uncertain multiple-view L2 triangulation (SPEC §2, §5).

v = (x_1, ..., x_N, y_1, ..., y_N) with x_i in R^2 the image point of view i and
y_i in R^{n_i} the auxiliary variables of region i.  Then

    f = sum_i f_i,   g = (g_1, ..., g_N, m2),   h = (h_1, ..., h_N),
    gamma*^2 = (1/(2N)) inf f  s.t.  g = 0, h >= 0            (the paper's (41))

Regions only declare (n_i, f_i, g_i, h_i); the projection constraints m2 come
from :mod:`tritools.model.constraints`.  Nothing here solves anything.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from sospoly import Polynomial, variables

from .constraints import Method, corollary1_constraints, theorem1_constraints

__all__ = ["TriangulationProblem", "build_problem"]


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

    def image_points(self, v: np.ndarray) -> np.ndarray:
        """(N, 2) image points x_i read from a vector v in ``gens`` order."""
        return np.asarray(v, float)[self.x_index].reshape(self.n_views, 2)


def build_problem(cameras: np.ndarray, regions, method: Method = Method.THEOREM1) -> TriangulationProblem:
    """Assemble (f, g, h) for validated cameras (N, 3, 4) and regions (SPEC §2 table)."""
    method = Method(method)
    N = len(regions)
    names = [f"x{i + 1}_{k + 1}" for i in range(N) for k in range(2)]
    for i, reg in enumerate(regions):
        names += [f"y{i + 1}_{k + 1}" for k in range(reg.n_aux)]
    v = variables(names)
    gens = v[0].gens
    x_index = np.arange(2 * N)
    f = Polynomial(gens, {})
    eq, ineq = [], []
    pos = 2 * N
    for i, reg in enumerate(regions):
        xi = (v[2 * i], v[2 * i + 1])
        yi = tuple(v[pos:pos + reg.n_aux])
        pos += reg.n_aux
        polys = reg.polynomials(xi, yi)
        f = f + polys.f
        eq += [p.with_gens(gens) for p in polys.eq]
        ineq += [p.with_gens(gens) for p in polys.ineq]
    if method == Method.THEOREM1:
        proj, info = theorem1_constraints(cameras, gens, x_index)
    else:
        proj, info = corollary1_constraints(cameras, gens, x_index)
    return TriangulationProblem(gens, x_index, f.with_gens(gens), tuple(eq) + tuple(proj), tuple(ineq), N,
                                method, tuple(proj), info)
