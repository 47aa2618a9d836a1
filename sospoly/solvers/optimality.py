"""The optimality rule shared by :func:`sospoly.solve_program` and :func:`sospoly.solve_conic_problem` (review 26a F4).

For the standard form min q^T x s.t. s = b - A x in K, with the solver's dual z (A^T z + q = 0, z in K* = K at
the optimum) and any x', s' = b - A x':

    q^T x' = -b^T z + z^T s' + r^T x',        r = A^T z + q.

A returned pair (x, z) is *optimal* when it proves its objective p = q^T x to within the objective's own scale,
from both sides:

* **over-claim** (p below the true optimum p*, possible only when x is infeasible): the value function
  v(b) = min{q^T x : b - A x in K} is convex with subgradient -z* at b, so moving x's slack back into K by
  Delta (Delta = eps_k I on a PSD cone whose smallest eigenvalue is -eps_k, eps_k on a nonnegative row, |s_i| on a
  zero row, eps_k (1, 0, ..., 0) on a second-order cone whose t falls short of ||y|| by eps_k) gives
  p* <= p + z*^T Delta, i.e. the effect of the defect is ``E_p = sum_k eps_k tr(Z_k)`` (z_0 for a second-order
  cone, |z_i| on scalar rows).  For an SOS constraint Z_k is the moment matrix, and tr(Z_k) = ||b(v*)||^2 at a
  minimiser v*: this is the defect lambda_min times the squared basis, where it matters, that the old rule
  (lambda_min against 1e-7 max|G|) could not see -- x^4 - 3e4 x^2 + 1e8 - c SOS came back "optimal" 8.6e4 above
  its optimum with lambda_min = -1.9e-4 accepted against a margin of 22, while ||b(v*)||^2 = 2.25e8.
* **under-claim** (p above p*): p - p* <= |p - d| + (the dual's own defect), d = -b^T z, with the dual defect
  ``E_d = sum_k delta_k tr(S_k) + |r|^T |x|`` (delta_k: z's violation of cone k; the residual r weighed by x's
  own magnitude, the proxy for the unknown optimal x*).

The pair is optimal when ``|p - d| + E_p + E_d <= DUAL_RTOL * scale``
(:data:`~sospoly.solvers.rays.DUAL_RTOL` = 1e-5: the solvers' own accuracy, ~1e-8 relative in their scaling and
~1e-9 absolute through cvxpy, is 1e-6..5e-6 of an objective scaled by 1e-3) with
``scale = |q|^T |x| + |b|^T |z|``, the
size of the terms of the primal and the dual objective (for max c s.t. f - c SOS: |c| plus the sizes of f's
terms at the minimiser, through the moments z) -- not the size of the data, which for
1e16 x^4 - 3e12 x^2 + 1e8 is 1e16 while the optimum and the terms at the minimiser are ~1e8 -- plus the floor
max|q| max(||x_q||_inf, 1), one unit of the magnitude of the objective's own variables x_q (those with q_j != 0) on
the objective (an optimum 0 whose terms all vanish, e.g. max c s.t. x^2 - c SOS, is judged against the objective's
unit, not against 0; the floor scales with q, so an objective scaled by 1e-9 is judged at its own scale, not against
an absolute 1e-6).  Not over all of x: a multiplier's Gram entry of 5e13 (min 1e8 x on a disc of radius 1e-6) let a
level 17x below the program's optimum pass as optimal (review 43b M2).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..algebra.svec import smat
from ..lowering.conic import ConicProblem
from ..tolerances import Tolerances
from .rays import DUAL_RTOL

__all__ = ["Optimality", "check_optimality"]


@dataclass(frozen=True)
class Optimality:
    """The terms of the rule (module docstring): ``primal_effect`` E_p, ``dual_effect`` E_d, the objectives' ``gap``
    p - d, the ``scale`` and the ``allowed`` total.  ``primal_ok``: E_p within ``allowed`` (the point's value is a
    value of the program to that accuracy); ``ok``: the whole rule."""
    primal_effect: float
    dual_effect: float
    gap: float
    scale: float
    allowed: float

    @property
    def primal_ok(self) -> bool:
        return bool(self.primal_effect <= self.allowed)

    @property
    def ok(self) -> bool:
        return bool(abs(self.gap) + self.primal_effect + self.dual_effect <= self.allowed)

    def describe(self) -> str:
        total = abs(self.gap) + self.primal_effect + self.dual_effect
        return (f"the primal-dual pair proves its objective only to {total:.3g} (gap {self.gap:.3g}, effect of the "
                f"primal cone violation {self.primal_effect:.3g}, of the dual's {self.dual_effect:.3g}) where "
                f"{self.allowed:.3g} is allowed at the objective's scale {self.scale:.3g}")


def _floor_and_size(kind: str, v: np.ndarray) -> tuple[float, float]:
    """(max(0, -smallest eigenvalue), the trace-like size) of v in a self-dual cone: the violation of the cone
    and the weight it has against the other side's violation (module docstring)."""
    if kind == "nonneg":
        return 0.0, 0.0           # (scalar rows: handled per row)
    if kind == "psd":
        M = smat(v)
        return max(0.0, -float(np.linalg.eigvalsh(M)[0])), float(max(np.trace(M), 0.0))
    t, y = float(v[0]), float(np.linalg.norm(v[1:]))
    return max(0.0, y - t), max(t, 0.0)


def check_optimality(problem: ConicProblem, x: np.ndarray, z: np.ndarray, tol: Tolerances) -> Optimality:
    """The terms of the optimality rule of the module docstring for the primal x and the dual z of ``problem``."""
    x, z = np.asarray(x, float), np.asarray(z, float)
    q, b = np.asarray(problem.q, float), np.asarray(problem.b, float)
    s = b - problem.A @ x
    r = problem.A.T @ z + q
    e_p = 0.0
    e_d = float(np.abs(r) @ np.abs(x))
    row = 0
    for cone in problem.cones:
        sl, zl = s[row:row + cone.dim], z[row:row + cone.dim]
        row += cone.dim
        if not cone.dim:
            continue
        if cone.kind == "zero":
            e_p += float(np.abs(sl) @ np.abs(zl))
        elif cone.kind == "nonneg":
            e_p += float(np.maximum(-sl, 0.0) @ np.abs(zl))
            e_d += float(np.maximum(-zl, 0.0) @ np.abs(sl))
        else:
            v_s, size_s = _floor_and_size(cone.kind, sl)
            v_z, size_z = _floor_and_size(cone.kind, zl)
            e_p += v_s * size_z
            e_d += v_z * size_s
    p, d = float(q @ x), float(-(b @ z))
    if not np.any(q):                      # a constant objective: every feasible point is optimal
        return Optimality(0.0, 0.0, 0.0, 0.0, np.inf)
    floor = float(np.max(np.abs(q))) * max(float(np.max(np.abs(x[q != 0]), initial=0.0)), 1.0)
    scale = float(np.abs(q) @ np.abs(x) + np.abs(b) @ np.abs(z)) + floor
    allowed = DUAL_RTOL * scale
    return Optimality(e_p, e_d, p - d, scale, allowed)
