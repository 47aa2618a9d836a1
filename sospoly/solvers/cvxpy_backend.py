"""The cvxpy back-end of :mod:`sospoly.solvers.backends`: the conic data re-expressed as a cvxpy problem and solved
by any installed cvxpy SDP solver (for cross-checking the default back-ends)."""
from __future__ import annotations

import time
import warnings

import numpy as np
import scipy.sparse as sp

from ..algebra.svec import svec_scale, triu_pairs
from ..budget import Deadline
from ..lowering.conic import ConicProblem
from ..tolerances import DEFAULT_TOLERANCES, Tolerances, as_tolerances
from .backends import Attempt, ConicSolution, RawStatus, import_cvxpy

__all__ = ["CvxpyBackend"]


def _svec_operator(s: int) -> sp.csr_matrix:
    """Sparse T with svec(S) = T @ vec(S) (vec column-major, as cvxpy's)."""
    i, j = triu_pairs(s)
    return sp.csr_matrix((svec_scale(s), (np.arange(i.size), j * s + i)), shape=(i.size, s * s))


class CvxpyBackend:
    """Re-expresses the conic data in cvxpy and solves it with ``solver`` (any SDP solver)."""

    name = "cvxpy"

    def __init__(self, solver: str | None = None, tolerances: Tolerances = DEFAULT_TOLERANCES, **solver_kwargs):
        self.solver = solver
        self.tolerances = as_tolerances(tolerances)
        self.solver_kwargs = solver_kwargs

    def _tolerance_kwargs(self, solver):
        t = self.tolerances
        if solver == "CLARABEL":
            return {"tol_gap_abs": t.solver_gap_abs, "tol_gap_rel": t.solver_gap_rel, "tol_feas": t.solver_feas,
                    "max_iter": t.solver_max_iter}
        if solver == "SCS":
            return {"eps_abs": 1e-9, "eps_rel": 1e-9, "max_iters": 200000}
        return {}

    def _constraints(self, cp, problem: ConicProblem, x, b):
        """The cone constraints b - A x in K as cvxpy constraints, and per cone (row, kind, the constraint whose
        dual is z on its rows): the equality, the inequality, the second-order cone, and for a PSD cone the equality
        svec(S) = b - A x (cvxpy's Lagrangian f + nu^T (lhs - rhs) makes each of these duals z of
        min q^T x s.t. b - A x in K, q + A^T z = 0)."""
        cons, duals = [], []
        row = 0
        for cone in problem.cones:
            rows = slice(row, row + cone.dim)
            Ar, br = problem.A[rows], b[rows]
            if cone.kind == "zero":
                cons.append(Ar @ x == br)
            elif cone.kind == "nonneg":
                cons.append(Ar @ x <= br)
            elif cone.kind == "soc":
                e = br - Ar @ x
                cons.append(cp.SOC(e[0], e[1:]))
            else:
                S = cp.Variable((cone.size, cone.size), symmetric=True)
                cons.append(_svec_operator(cone.size) @ cp.vec(S, order="F") == br - Ar @ x)
                duals.append((row, cone.kind, cons[-1]))
                cons.append(S >> 0)
                row += cone.dim
                continue
            duals.append((row, cone.kind, cons[-1]))
            row += cone.dim
        return cons, duals

    @staticmethod
    def _dual(problem: ConicProblem, duals) -> np.ndarray | None:
        """z (the dual of every row, :meth:`_constraints`), or None where cvxpy gives no dual value."""
        z = np.zeros(problem.n_rows)
        for row, kind, c in duals:
            v = c.dual_value
            if v is None:
                return None
            if kind == "soc":
                v = np.concatenate([np.ravel(np.asarray(v[0], float)), np.ravel(np.asarray(v[1], float))])
            v = np.ravel(np.asarray(v, float))
            z[row:row + v.size] = v
        return z if np.all(np.isfinite(z)) else None

    def _run(self, cp, prob, solver):
        """Solve ``prob`` with the configured solver; returns cvxpy's status (or the error as a string)."""
        kwargs = dict(self._tolerance_kwargs(solver))
        kwargs.update(self.solver_kwargs)
        try:
            with warnings.catch_warnings():          # inaccuracy is reported through the status, not a warning
                warnings.simplefilter("ignore")
                prob.solve(solver=solver, **kwargs)
            return prob.status
        except (KeyboardInterrupt, SystemExit):
            raise
        except BaseException as exc:
            return f"error: {type(exc).__name__}: {exc}"[:200]

    def _ray(self, cp, problem: ConicProblem, solver):
        """cvxpy reports unboundedness without a ray; the ray of min q^T x s.t. b - A x in K is found as the
        solution of the homogeneous program min q^T d s.t. -A d in K, q^T d >= -1 (None if it gives none), so
        that the caller's ray check (:func:`~sospoly.solvers.solve.check_unbounded_ray`) can verify it."""
        d = cp.Variable(problem.n_cols)
        cons, _ = self._constraints(cp, problem, d, np.zeros(problem.n_rows))
        prob = cp.Problem(cp.Minimize(problem.q @ d), cons + [problem.q @ d >= -1.0])
        status = self._run(cp, prob, solver)
        if status not in ("optimal", "optimal_inaccurate") or d.value is None:
            return None
        return np.asarray(d.value, float)

    def _farkas(self, cp, problem: ConicProblem, solver) -> np.ndarray:
        """cvxpy reports infeasibility without a certificate; a Farkas certificate z of b - A x in K (z in K*,
        A^T z = 0, b^T z = -1) is found by a feasibility program, so that the caller's check
        (:func:`~sospoly.solvers.rays.check_infeasibility`) can verify it; NaN where the program gives none (the
        check then fails: ``numerical_error``, never an unchecked ``infeasible``)."""
        z = cp.Variable(problem.n_rows)
        cons, row = [], 0
        for cone in problem.cones:
            zr = z[row:row + cone.dim]
            if cone.kind == "nonneg":
                cons.append(zr >= 0)
            elif cone.kind == "soc":
                cons.append(cp.SOC(zr[0], zr[1:]))
            elif cone.kind == "psd":
                S = cp.Variable((cone.size, cone.size), symmetric=True)
                cons += [_svec_operator(cone.size) @ cp.vec(S, order="F") == zr, S >> 0]
            row += cone.dim                            # the zero cone's dual: free
        At = sp.csr_matrix(problem.A.T)
        cons += [At @ z == 0, np.asarray(problem.b, float) @ z == -1.0]
        status = self._run(cp, cp.Problem(cp.Minimize(0), cons), solver)
        if status not in ("optimal", "optimal_inaccurate") or z.value is None:
            return np.full(problem.n_rows, np.nan)
        return np.asarray(z.value, float)

    def solve(self, problem: ConicProblem, accept=None, retry: bool = True,
              deadline: Deadline | None = None) -> ConicSolution:
        cp = import_cvxpy()
        t0 = time.perf_counter()
        x = cp.Variable(problem.n_cols)
        cons, duals = self._constraints(cp, problem, x, problem.b)
        prob = cp.Problem(cp.Minimize(problem.q @ x), cons)
        solver = self.solver
        if solver is None:
            solver = "CLARABEL" if "CLARABEL" in cp.installed_solvers() else None
        status = self._run(cp, prob, solver)
        raw = {"optimal": RawStatus.SOLVED, "optimal_inaccurate": RawStatus.ALMOST_SOLVED,
               "infeasible": RawStatus.PRIMAL_INFEASIBLE, "unbounded": RawStatus.DUAL_INFEASIBLE,
               "infeasible_inaccurate": RawStatus.ALMOST_INFEASIBLE,
               "unbounded_inaccurate": RawStatus.ALMOST_INFEASIBLE}.get(status, RawStatus.FAILED)
        # cvxpy gives no certificate of either infeasibility: each is found by a program of its own (its time counted)
        ray = self._ray(cp, problem, solver) if raw == RawStatus.DUAL_INFEASIBLE else None
        farkas = self._farkas(cp, problem, solver) if raw == RawStatus.PRIMAL_INFEASIBLE else None
        att = Attempt(f"cvxpy:{solver or 'default'}", raw, str(status), 0, time.perf_counter() - t0)
        if raw in (RawStatus.DUAL_INFEASIBLE, RawStatus.PRIMAL_INFEASIBLE):
            return ConicSolution(raw, ray, farkas, None, None, (att,))
        if x.value is None:
            return ConicSolution(raw, None, None, None, None, (att,))
        xv = np.asarray(x.value, float)
        z = self._dual(problem, duals)
        obj = float(problem.q @ xv)
        if raw == RawStatus.SOLVED and accept is not None and not accept(xv, z):
            raw = RawStatus.ALMOST_SOLVED
        return ConicSolution(raw, xv, z, obj, obj, (att,))
