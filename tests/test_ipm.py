"""The batched interior-point method (sospoly.solvers.ipm) against closed forms and against Clarabel.

Tolerance: the IPM stops on Clarabel's criteria with the solver tolerances 1e-9 of
sospoly.Tolerances, so optimal values agree with closed forms to ~1e-8 on these well-scaled
problems; 1e-7 leaves a decade of margin.
"""
import numpy as np
import pytest
import scipy.sparse as sp

import sospoly
from sospoly.solvers.backends import ClarabelBackend, IpmBackend, RawStatus
from sospoly.lowering.conic import Cone, ConicProblem, GramForm
from sospoly.solvers.ipm import ipm_solve_batch, ipm_solve_sparse
from sospoly.algebra.svec import svec

TOL = 1e-7


def _lmin_problem(mats):
    """max c s.t. A - c I >= 0 (optimum lambda_min(A)) in the conic form min -c, s = svec(A) - c svec(I)."""
    n = mats.shape[-1]
    b = np.array([svec(M) for M in mats])
    A = np.repeat(svec(np.eye(n))[None, :, None], len(mats), 0)
    return A, b, np.array([-1.0]), (Cone("psd", n * (n + 1) // 2, n),)


def test_lambda_min_batch_matches_eigvalsh():
    rng = np.random.default_rng(3)
    M = rng.standard_normal((40, 6, 6))
    M = M + M.transpose(0, 2, 1)
    A, b, q, cones = _lmin_problem(M)
    res = ipm_solve_batch(A, b, q, cones)
    assert res.converged.all()
    np.testing.assert_allclose(res.x[:, 0], np.linalg.eigvalsh(M)[:, 0], atol=TOL)
    # the sparse (svec-Kronecker / gemm) Schur path on one instance gives the same optimum
    r1 = ipm_solve_sparse(sp.csr_matrix(A[0]), b[0], q, cones)
    assert r1.converged[0] and abs(r1.x[0, 0] - res.x[0, 0]) < TOL


def test_two_blocks_and_equality_rows_against_clarabel():
    """max c1 + c2 s.t. A1 - c1 I >= 0, A2 - c2 I >= 0, c1 - c2 = 0.5 (a zero-cone row):
    optimum c2 = min(lambda_min(A1) - 0.5, lambda_min(A2)), c1 = c2 + 0.5."""
    rng = np.random.default_rng(5)
    A1 = rng.standard_normal((4, 4))
    A1 = A1 + A1.T
    A2 = rng.standard_normal((3, 3))
    A2 = A2 + A2.T
    L1, L2 = 10, 6
    Amat = np.zeros((1 + L1 + L2, 2))
    Amat[0] = [1.0, -1.0]
    Amat[1:1 + L1, 0] = svec(np.eye(4))
    Amat[1 + L1:, 1] = svec(np.eye(3))
    b = np.concatenate([[0.5], svec(A1), svec(A2)])
    cones = (Cone("zero", 1), Cone("psd", L1, 4), Cone("psd", L2, 3))
    res = ipm_solve_batch(Amat[None], b[None], np.array([-1.0, -1.0]), cones)
    c2 = min(np.linalg.eigvalsh(A1)[0] - 0.5, np.linalg.eigvalsh(A2)[0])
    assert res.converged[0]
    np.testing.assert_allclose(res.x[0], [c2 + 0.5, c2], atol=TOL)
    ref = ClarabelBackend().solve(ConicProblem(np.array([-1.0, -1.0]), sp.csc_matrix(Amat), b, cones, 2, ()))
    np.testing.assert_allclose(res.x[0], ref.x, atol=TOL)


def test_trust_region_qcqp_bound_is_lambda_min_batched():
    """min x^T Q x s.t. ||x||^2 = 1 has value lambda_min(Q), and its degree-2 Lagrangian
    (Positivstellensatz) bound is exact (S-lemma), so the compiled batch must return it."""
    x = sospoly.variables("a b c")
    rng = np.random.default_rng(11)
    insts = []
    lams = []
    for _ in range(12):
        Q = rng.standard_normal((3, 3))
        Q = Q + Q.T
        f = sum(Q[i, j] * x[i] * x[j] for i in range(3) for j in range(3))
        insts.append((f, [1 - x[0] ** 2 - x[1] ** 2 - x[2] ** 2], []))
        lams.append(np.linalg.eigvalsh(Q)[0])
    comp = sospoly.compile_psatz(*insts[0], degree=2)
    out = comp.solve_batch(insts)
    assert all(lb.status == sospoly.SolveStatus.OPTIMAL for lb in out)
    np.testing.assert_allclose([lb.lower_bound for lb in out], lams, atol=TOL)
    assert all(lb.solution.attempts[0].label == "ipm-batch" for lb in out)


def _raw(A, b, q, cones):
    return ConicProblem(np.asarray(q, float), sp.csc_matrix(A), np.asarray(b, float), cones, A.shape[1], ())


@pytest.mark.parametrize("case, expected", [
    # S = -I - c * 0: never PSD (primal infeasible)
    ("infeasible", RawStatus.PRIMAL_INFEASIBLE),
    # S = I + c I, minimise -c: c -> +inf (unbounded)
    ("unbounded", RawStatus.DUAL_INFEASIBLE),
])
def test_infeasible_and_unbounded_report_a_status_via_fallback(case, expected):
    n = 3
    L = n * (n + 1) // 2
    if case == "infeasible":
        A, b = np.zeros((L, 1)), svec(-np.eye(n))
        A[0, 0] = 0.0
    else:
        A, b = -svec(np.eye(n))[:, None], svec(np.eye(n))
    cones = (Cone("psd", L, n),)
    res = ipm_solve_batch(A[None], b[None], np.array([-1.0]), cones)
    assert not res.converged[0] and res.reason[0]
    sol = IpmBackend().solve(_raw(A, b, [-1.0], cones))
    assert sol.attempts[0].label == "ipm" and sol.attempts[0].raw_status == RawStatus.FAILED
    assert sol.raw_status == expected


def test_bad_input_is_named():
    A, b, q, cones = _lmin_problem(np.eye(3)[None])
    with pytest.raises(ValueError, match="shape"):
        ipm_solve_batch(A[0], b, q, cones)
    bad = b.copy()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        ipm_solve_batch(A, bad, q, cones)
    with pytest.raises(ValueError, match="rows"):
        ipm_solve_batch(A, b, q, (Cone("psd", 3, 2),))
    with pytest.raises(ValueError, match="nonneg"):
        ipm_solve_batch(A, b, q, (Cone("nonneg", 6),))


def test_kernel_form_zero_rows_match_clarabel():
    """The kernel Gram form has coefficient-matching equality rows (the augmented Newton system)."""
    x, y = sospoly.variables("x y")
    f = (x - 1) ** 2 + (y + 0.5) ** 2 + x * y
    ineq = [1 - x ** 2 - y ** 2]
    comp = sospoly.compile_psatz(f, [], ineq, degree=2, form=GramForm.KERNEL)
    a = comp.solve(f, [], ineq, backend="ipm")
    c = comp.solve(f, [], ineq, backend="clarabel")
    assert a.status == c.status == sospoly.SolveStatus.OPTIMAL
    assert a.solution.attempts[0].label == "ipm" and a.solution.attempts[0].raw_status == RawStatus.SOLVED
    assert abs(a.lower_bound - c.lower_bound) <= TOL * max(1.0, abs(c.lower_bound))
