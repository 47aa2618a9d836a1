"""The a-posteriori check of an unboundedness ray (a solver's dual-infeasibility certificate of the image form),
shared by :func:`sospoly.solvers.solve.solve_conic` (which reports ``unbounded`` only with a checked ray) and the
Clarabel retry chain (which goes on to its next attempt when a ray fails the check)."""
from __future__ import annotations

import numpy as np

from ..algebra.svec import smat
from ..lowering.conic import ConicProblem
from ..tolerances import Tolerances

__all__ = ["check_unbounded_ray"]

_RAY_DESCENT = 1e3 * np.finfo(float).eps   # q^T d below rounding of |q| |d| (relative)


def check_unbounded_ray(problem: ConicProblem, d: np.ndarray | None, tol: Tolerances) -> tuple[bool, str]:
    """A-posteriori check of an unboundedness certificate: a ray d of min q^T x s.t. b - A x in K with q^T d < 0 and
    -A d in K (every cone is its own recession cone).  The check is scale-free: d is scaled so that the largest
    term of A d is 1, each cone of -A d must hold within ``psd_margin`` of that unit size (zero rows within
    ``identity_residual`` of the size of their terms), and the descent must be clear of rounding,
    q^T d <= -1000 eps ||q|| ||d||.  (Normalising by q^T d = -1 instead let a large objective shrink
    d until any violation hid under the margin's absolute floor: review 3 of wave 18.)  For a Positivstellensatz
    program such a ray is itself a certificate that the constraint set is empty (c grows along it), so an
    unchecked one would make c* = +inf a claim: at f scaled by 1e8 Clarabel reported dual infeasibility of a
    bounded problem (review 18)."""
    if d is None or not np.all(np.isfinite(d)):
        return False, "no finite ray"
    d = np.asarray(d, float)
    size = np.abs(problem.A) @ np.abs(d)
    unit = float(size.max()) if size.size else 0.0
    if not unit > 0:
        return False, "A d = 0: no ray (the problem has free directions only)"
    d = d / unit
    size = size / unit
    qd, qn = float(problem.q @ d), float(np.linalg.norm(problem.q)) * float(np.linalg.norm(d))
    if not qd <= -_RAY_DESCENT * qn:
        return False, f"q^T d = {qd:.3g} is not clearly negative (|q| |d| = {qn:.3g})"
    r = -(problem.A @ d)
    row = 0
    for k, cone in enumerate(problem.cones):
        v, sz = r[row:row + cone.dim], size[row:row + cone.dim]
        row += cone.dim
        if not cone.dim:
            continue
        if cone.kind == "zero":
            bad = float(np.max(np.abs(v) / np.maximum(sz, 1.0)))
            if bad > tol.identity_residual:
                return False, f"zero cone {k}: residual {bad:.3g} of its terms"
            continue
        if cone.kind == "psd":
            lam = float(np.linalg.eigvalsh(smat(v))[0])
        elif cone.kind == "nonneg":
            lam = float(v.min())
        else:
            lam = float(v[0]) - float(np.linalg.norm(v[1:]))
        if not lam >= -tol.psd_margin:
            return False, f"{cone.kind} cone {k}: violated by {-lam:.3g} (terms of size <= 1)"
    return True, ""
