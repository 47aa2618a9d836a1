"""A-posteriori checks of a solver's certificates for the image form min q^T x s.t. b - A x in K: an
unboundedness ray (dual infeasibility, :func:`check_unbounded_ray`), a Farkas certificate of primal
infeasibility (:func:`check_infeasibility`), the dual certificate of a primal point's optimality
(:func:`check_dual_certificate`) and a point's feasibility at its cones' own scale (:func:`check_primal_point`),
both for :func:`sospoly.solve_conic_problem`.  The first two are shared by :func:`sospoly.solvers.solve.solve_conic`
(which reports ``unbounded`` / ``infeasible`` only with a checked certificate) and the Clarabel retry chain (which
goes on to its next attempt when one fails the check)."""
from __future__ import annotations

import numpy as np

from ..algebra.svec import smat
from ..lowering.conic import ConicProblem
from ..tolerances import Tolerances
from .balance import balanced_ray

__all__ = ["check_unbounded_ray", "check_infeasibility", "check_dual_certificate", "check_primal_point", "DUAL_RTOL"]

_RAY_DESCENT = 1e3 * np.finfo(float).eps   # q^T d below rounding of |q| |d| (relative)


def check_unbounded_ray(problem: ConicProblem, d: np.ndarray | None, tol: Tolerances) -> tuple[bool, str]:
    """A-posteriori check of an unboundedness certificate: a ray d of min q^T x s.t. b - A x in K with q^T d < 0 and
    -A d in K (every cone is its own recession cone).  Scale-free, cone by cone: with t = |A| |d| the sizes of the
    terms of each row of A d, every cone of -A d must hold within ``psd_margin`` of its *own* terms -- a
    nonnegative row r_i >= -psd_margin t_i, a PSD or second-order cone's smallest eigenvalue (or v_0 - ||v_1..||)
    >= -psd_margin max_cone t -- and every zero row within ``identity_residual`` of its terms,
    |r_i| <= identity_residual t_i; the descent must be clear of rounding, q^T d <= -1000 eps ||q|| ||d||.
    (Normalising by q^T d = -1 let a large objective shrink d until any violation hid under the margin's absolute
    floor, review 3 of wave 18; measuring every cone against the largest term of all let cones scaled by 1e-6
    beside rows scaled by 1e6 pass violated by 60% of their own entries, review 4.)  A d = 0 with q^T d < 0 is a
    ray (a direction no constraint sees).  For a Positivstellensatz program such a ray is itself a certificate that
    the constraint set is empty (c grows along it), so an unchecked one would make c* = +inf a claim: at f scaled
    by 1e8 Clarabel reported dual infeasibility of a bounded problem (review 18)."""
    return _candidates(_checked, problem, d, tol, "ray")


#: the relative sizes below which a certificate is also tried with its components set to 0 (:func:`_candidates`)
_RAY_CLEANING = (1e-12, 1e-10, 1e-8)


def _candidates(rules, problem: ConicProblem, v, tol: Tolerances, what: str) -> tuple[bool, str]:
    """``rules(problem, v, tol)`` on the certificate v scaled to max |v_i| = 1, then on v with its components below
    each of :data:`_RAY_CLEANING` set to 0: a solver's certificate carries its own accuracy as noise in the
    components that should be 0 (Clarabel: a 1e-10 component of the ray of min -x1 - x2 s.t.
    [[1, x1], [x1, 1]] >= 0, x2 >= 0 violated the PSD cone by 70% of its own terms), and each cleaned vector is
    another candidate, checked by the same rules.  (ok, why the first candidate failed)."""
    if v is None or not np.all(np.isfinite(v)):
        return False, f"no finite {what}"
    v = np.asarray(v, float)
    top = float(np.max(np.abs(v))) if v.size else 0.0
    if not top > 0:
        return False, f"the zero {what} is no {what}"
    v = v / top
    ok, why = rules(problem, v, tol)
    for cut in _RAY_CLEANING:
        if ok:
            break
        clean = np.where(np.abs(v) > cut, v, 0.0)
        if not np.array_equal(clean, v):
            ok = rules(problem, clean, tol)[0]
    return ok, "" if ok else why


def _cone_floor(kind: str, v: np.ndarray) -> float:
    """The smallest eigenvalue of v in a self-dual cone: min v (nonneg), lambda_min(smat v) (psd), v_0 - ||v_1..||
    (soc); >= 0 iff v is in the cone."""
    if kind == "nonneg":
        return float(v.min())
    if kind == "psd":
        return float(np.linalg.eigvalsh(smat(v))[0])
    return float(v[0]) - float(np.linalg.norm(v[1:]))


def _checked(problem: ConicProblem, d: np.ndarray, tol: Tolerances) -> tuple[bool, str]:
    """The rules of :func:`check_unbounded_ray` for one candidate d (max |d_j| <= 1)."""
    qd, qn = float(problem.q @ d), float(np.linalg.norm(problem.q)) * float(np.linalg.norm(d))
    if not qd <= -_RAY_DESCENT * qn:
        return False, f"q^T d = {qd:.3g} is not clearly negative (|q| |d| = {qn:.3g})"
    v, size = -(problem.A @ d), np.abs(problem.A) @ np.abs(d)
    ok, why = _cones_hold(problem, v, size, tol)
    return balanced_ray(problem, v, size, tol) if ok else (ok, why)


def _cones_hold(problem: ConicProblem, v: np.ndarray, size: np.ndarray, tol: Tolerances) -> tuple[bool, str]:
    """Does the row vector ``v`` (one entry per row of the cones) lie in K at the rows' own sizes ``size``: a zero
    row |v_i| <= ``identity_residual`` size_i, a nonnegative row v_i >= -``psd_margin`` size_i, a PSD or
    second-order cone's floor (:func:`_cone_floor`) >= -``psd_margin`` max of its rows' sizes?  (ok, why not)."""
    row = 0
    for k, cone in enumerate(problem.cones):
        w, sz = v[row:row + cone.dim], size[row:row + cone.dim]
        row += cone.dim
        if not cone.dim:
            continue
        if cone.kind in ("zero", "nonneg"):
            bad = np.abs(w) > tol.identity_residual * sz if cone.kind == "zero" else w < -tol.psd_margin * sz
            if np.any(bad):
                i = int(np.argmax(bad))
                return False, f"{cone.kind} cone {k}: row {i} is {float(w[i]):.3g} with terms {float(sz[i]):.3g}"
            continue
        lam, scale = _cone_floor(cone.kind, w), float(sz.max())
        if not lam >= -tol.psd_margin * scale:
            return False, f"{cone.kind} cone {k}: violated by {-lam:.3g} (its terms {scale:.3g})"
    return True, ""


def check_infeasibility(problem: ConicProblem, z: np.ndarray | None, tol: Tolerances) -> tuple[bool, str]:
    """A-posteriori check of a Farkas certificate of primal infeasibility: z in K* (K's cones are self-dual, the
    zero cone's dual is free) with A^T z = 0 and b^T z < 0 -- then 0 <= z^T (b - A x) = b^T z < 0 for any
    feasible x, a contradiction.  The rules of :func:`check_unbounded_ray`, scale-free: z scaled to max |z_i| = 1,
    each column of A^T z within ``identity_residual`` of its terms |A|^T |z|, each cone of z within ``psd_margin``
    of its largest entry, b^T z <= -1000 eps sum_i |b_i z_i|; and again with the noise components of z (below
    1e-12-1e-8 of its largest) set to 0.  (An unchecked "infeasible" from Clarabel on rescaled feasible problems:
    14 of 200 in review 4's random programs.)"""
    return _candidates(_farkas, problem, z, tol, "certificate")


def _farkas(problem: ConicProblem, z: np.ndarray, tol: Tolerances) -> tuple[bool, str]:
    """The rules of :func:`check_infeasibility` for one candidate z (max |z_i| <= 1)."""
    b = np.asarray(problem.b, float)
    bz, bsize = float(b @ z), float(np.abs(b) @ np.abs(z))
    if not (bz < 0 and bz <= -_RAY_DESCENT * bsize):
        return False, f"b^T z = {bz:.3g} is not clearly negative (terms {bsize:.3g})"
    At = problem.A.T
    res, size = At @ z, abs(At) @ np.abs(z)
    bad = np.abs(res) > tol.identity_residual * size
    if np.any(bad):
        j = int(np.argmax(bad))
        return False, f"column {j} of A^T z is {float(res[j]):.3g} with terms {float(size[j]):.3g}"
    row = 0
    for k, cone in enumerate(problem.cones):
        v = z[row:row + cone.dim]
        row += cone.dim
        if not cone.dim or cone.kind == "zero":
            continue
        scale = float(np.max(np.abs(v)))
        lam = _cone_floor(cone.kind, v)
        if not lam >= -tol.psd_margin * scale:
            return False, f"{cone.kind} cone {k} of z: violated by {-lam:.3g} (its entries {scale:.3g})"
    return True, ""


#: the relative accuracy to which a dual certificate must prove a point optimal (:func:`check_dual_certificate`):
#: the solvers' own tolerances are ~1e-8 relative in their own scaling (absolute ~1e-9 through cvxpy: 5e-6 of a
#: problem scaled by 1e-3)
DUAL_RTOL = 1e-5


def _row_scales(problem: ConicProblem, x: np.ndarray) -> np.ndarray:
    """t_i = |b_i| + ||A_i||_1 max(||x||_inf, 1): the size of row i's terms at x's magnitude (floored at 1, so that a
    row active at 0 -- x_j >= 0 with x_j = 0 -- is measured against its coefficients, not against round-off).
    Scales with the row (a rescaled cone scales its own t)."""
    return np.abs(np.asarray(problem.b, float)) + np.asarray(abs(problem.A).sum(axis=1)).ravel() * _magnitude(x)


def _magnitude(x: np.ndarray) -> float:
    """max(||x||_inf, 1): the length scale of a point's rows and dual residual (:func:`_row_scales`)."""
    return max(float(np.max(np.abs(x))) if x.size else 0.0, 1.0)


def check_dual_certificate(problem: ConicProblem, x: np.ndarray, z: np.ndarray | None,
                           tol: Tolerances) -> tuple[bool, str]:
    """A-posteriori check that the solver's dual z proves a (primal-checked) x optimal.  For feasible x',
    q^T x' = -b^T z + z^T s' + r^T x' with s' = b - A x' and r = A^T z + q, so -b^T z is a lower bound up to the
    error of z outside K* and of r: with eps_k the violation of cone k by z (its smallest eigenvalue below 0, per row
    for a nonnegative cone) and the rows' sizes t_i (:func:`_row_scales`), err = sum_k eps_k sum_{i in k} (|s_i| +
    t_i) + ||r||_1 max(||x||_inf, 1).  x is optimal when |q^T x + b^T z| + err <= :data:`DUAL_RTOL` (|q|^T |x| +
    |b|^T |z| + |z|^T t).  Invariant under a cone's row scaling and the objective's scale; a cone inactive at the
    optimum (z_k ~ 0, its noise ~1e-12) and an optimal value 0 pass.  A primal point alone says nothing of
    optimality: of review 4's random programs with a planted unboundedness ray, 14 of 200 came back "optimal" with
    a feasible x (their r is 50-99% of its terms)."""
    if z is None or not np.all(np.isfinite(z)):
        return False, "no finite dual certificate"
    z, x = np.asarray(z, float), np.asarray(x, float)
    q, b = np.asarray(problem.q, float), np.asarray(problem.b, float)
    t = _row_scales(problem, x)
    s_abs = np.abs(b - problem.A @ x)
    err_r = float(np.abs(problem.A.T @ z + q).sum()) * _magnitude(x)
    err_k, row = 0.0, 0
    for cone in problem.cones:
        v = z[row:row + cone.dim]
        w = s_abs[row:row + cone.dim] + t[row:row + cone.dim]
        row += cone.dim
        if not cone.dim or cone.kind == "zero":
            continue
        if cone.kind == "nonneg":
            err_k += float(np.maximum(-v, 0.0) @ w)
        else:
            err_k += max(0.0, -_cone_floor(cone.kind, v)) * float(w.sum())
    gap = float(q @ x + b @ z)
    size = float(np.abs(q) @ np.abs(x) + np.abs(b) @ np.abs(z) + np.abs(z) @ t)
    if abs(gap) + err_r + err_k > DUAL_RTOL * size:
        return False, (f"the dual proves the point optimal only to {abs(gap) + err_r + err_k:.3g} (gap {gap:.3g}, "
                       f"dual residual {err_r:.3g}, cone violation {err_k:.3g}) against terms {size:.3g}")
    return True, ""


def check_primal_point(problem: ConicProblem, x: np.ndarray, tol: Tolerances) -> tuple[bool, str]:
    """A-posteriori feasibility of x at each row's own scale: with s = b - A x and t the rows' sizes
    (:func:`_row_scales`), a zero row |s_i| <= ``identity_residual`` t_i, a nonnegative row s_i >= -``psd_margin``
    t_i, a PSD or second-order cone's floor (:func:`_cone_floor`) >= -``psd_margin`` max of its rows' t.  The
    a-posteriori check of :func:`sospoly.solvers.solve.solve_conic` measures a PSD block against max(1, its
    entries) -- right for a Gram matrix, whose PSD defect the rigorous bounds charge (:mod:`sospoly.analysis.rigor`),
    but a generic program whose PSD rows are scaled by 1e-6 then passes violated by 10% of its entries (wave 19: an
    "optimal" objective 48% below the true minimum)."""
    x = np.asarray(x, float)
    return _cones_hold(problem, np.asarray(problem.b, float) - problem.A @ x, _row_scales(problem, x), tol)
