"""Correctness of the Theorem 1 speed paths (issue #5).

* the reduced moment-form IPM of :func:`sospoly.solvers.ipm.ipm_solve_sparse` (disjoint-support
  Schur complement) against the dense formula tr(A_a Z A_b S^-1) and against Clarabel;
* the batched-determinant minors of :mod:`tritools.model.constraints` against exact polynomial
  determinants (:func:`sospoly.det`);
* the paper's Example 4 value and Example 5 cases against Clarabel.

Tolerances: the IPM and Clarabel both stop at the 1e-9 solver tolerances of
sospoly.Tolerances, so c agrees to ~1e-8 on these O(1)-scaled programs; 1e-7 leaves a decade.
The Schur identity and the minors are exact algebra in floating point: 1e-10 relative.
"""
from itertools import combinations

import numpy as np
import pytest

import sospoly
import tritools
from sospoly.solvers.backends import RawStatus
from sospoly.solvers.ipm import MomentReduction, ipm_solve_sparse, layout_of
from sospoly.solvers.ipm.core import mehrotra, result_of
from sospoly.solvers.ipm.moment import reduction_for
from sospoly.solvers.ipm.operators import SparseOperator
from sospoly.algebra.svec import smat
from tritools.model.constraints import minors_matrix, theorem1_constraints
from tritools.model.normalize import normalization_for
from tritools.model.problem import build_problem

TOL_C = 1e-7


def _instance(cams, regs, delta=4):
    norm = normalization_for(cams, regs)
    cams_n, regs_n = norm.cameras(cams), norm.regions(regs)
    pb = build_problem(cams_n, regs_n, "theorem1")
    comp = sospoly.compile_psatz(pb.f, pb.eq, pb.ineq, delta, gens=pb.gens)
    return comp, comp.instantiate(pb.f, pb.eq, pb.ineq)


@pytest.fixture(scope="module")
def example4():
    cams, regs = tritools.paper_example(4)
    return _instance(cams, regs)


def test_reduction_applies_and_schur_matches_dense_formula(example4):
    comp, inst = example4
    P = inst.problem
    lay = layout_of(P.cones)
    red = reduction_for(P.A, P.q, lay.sizes[0])
    assert isinstance(red, MomentReduction)
    # Example 4, delta 4: 495 coefficient-matching rows, 540 alphas, 51 free (c, r_k)
    assert (red.m2, red.alpha_cols.size, red.w_cols.size) == (495, 540, 51)
    # per-instance values as in solve(): e, V, EF
    A = P.A.tocsc()
    A.sort_indices()
    ap, ao = A.data[red.pdat], A.data[red.odat]
    e = np.ones(red.L)
    e[red.prow] = -ao / ap
    ws = red.workspace(red.Fpad * e[red.Rpad])
    rng = np.random.default_rng(7)
    n = red.n
    Z = rng.standard_normal((n, n))
    Z = Z @ Z.T + n * np.eye(n)
    R = rng.standard_normal((n, n))
    R = R @ R.T + n * np.eye(n)
    M = red.schur(Z, R, ws)
    # dense reference: A_a = smat(E^T e_a), M_ab = tr(A_a Z A_b R) on a sample of columns
    cols = rng.choice(red.m2, 40, replace=False)
    mats = []
    for a in cols:
        v = np.where(red.row2col == a, e, 0.0)
        mats.append(smat(v))
    ref = np.array([[np.trace(Aa @ Z @ Ab @ R) for Ab in mats] for Aa in mats])
    np.testing.assert_allclose(M[np.ix_(cols, cols)], ref, rtol=1e-10, atol=1e-10 * np.abs(ref).max())
    # E annihilates the alpha columns: the reduction describes the same affine set
    E = np.zeros((red.m2, red.L))
    E[red.row2col, np.arange(red.L)] = e
    assert np.abs(E @ A[:, red.alpha_cols].toarray()).max() < 1e-14


def test_reduced_ipm_equals_unreduced_ipm_and_clarabel(example4):
    comp, inst = example4
    P = inst.problem
    res = ipm_solve_sparse(P.A, P.b, P.q, P.cones)
    assert res.converged[0]
    lay = layout_of(P.cones)
    plain = result_of(*mehrotra(SparseOperator(P.A, lay), P.q[None], P.b[None], lay, sospoly.DEFAULT_TOLERANCES),
                      P.q[None], P.b[None], lay)
    assert plain.converged[0]
    clar = sospoly.solvers.backends.ClarabelBackend().solve(P)
    assert clar.raw_status == RawStatus.SOLVED
    # x[0] is c (the first block)
    assert abs(res.x[0, 0] - plain.x[0, 0]) < TOL_C
    assert abs(res.x[0, 0] - clar.x[0]) < TOL_C
    # the read-back x reproduces the returned slack (s = b - A x) and z is dual feasible
    assert np.abs(P.b - P.A @ res.x[0] - res.s[0]).max() < 1e-7
    assert np.abs(P.A.T @ res.z[0] + P.q).max() < 1e-7


def test_not_reducible_falls_back_to_svec_kronecker_path():
    """One PSD block without pair columns (lambda_min LMI): no reduction, still solved."""
    from sospoly.lowering.conic import Cone
    from sospoly.algebra.svec import svec
    import scipy.sparse as sp

    rng = np.random.default_rng(1)
    B = rng.standard_normal((5, 5))
    B = B + B.T
    A = sp.csr_matrix(svec(np.eye(5))[:, None])
    cones = (Cone("psd", 15, 5),)
    assert reduction_for(A, np.array([-1.0]), 5) is None
    r = ipm_solve_sparse(A, svec(B), np.array([-1.0]), cones)
    assert r.converged[0] and abs(r.x[0, 0] - np.linalg.eigvalsh(B)[0]) < TOL_C


def test_minors_matrix_equals_polynomial_determinants():
    rng = np.random.default_rng(11)
    N = 3
    cams = rng.standard_normal((N, 3, 4))
    names = [f"x{i}_{k}" for i in range(N) for k in range(2)]
    v = sospoly.variables(names)
    rows = []
    for i in range(N):
        for k in range(2):   # row of [I2, -x_i] P_i
            rows.append([float(cams[i, k, c]) - v[2 * i + k] * float(cams[i, 2, c]) for c in range(4)])
    M1, B1 = minors_matrix(cams)
    for r, R in enumerate(combinations(range(2 * N), 4)):
        d = sospoly.det([rows[k] for k in R]).with_gens(v[0].gens)
        got = {tuple(int(x) for x in e): c for e, c in zip(B1, M1[r]) if c != 0.0}
        ref = {e: c for e, c in d.terms.items() if abs(c) > 1e-12}
        assert set(ref) <= set(got)
        scale = max(abs(c) for c in ref.values())
        for e, c in got.items():
            assert abs(c - ref.get(e, 0.0)) <= 1e-10 * scale


def test_theorem1_constraints_span_the_minors():
    """m2 = M2 b1 has the same row space as the normalised M1 (same zero set)."""
    rng = np.random.default_rng(2)
    cams = rng.standard_normal((4, 3, 4))
    names = [f"x{i}" for i in range(8)]
    gens = sospoly.variables(names)[0].gens
    polys, info = theorem1_constraints(cams, gens, np.arange(8))
    M1, B1 = minors_matrix(cams)
    keys = [tuple(int(x) for x in e) for e in B1]
    M2 = np.array([[p.terms.get(k, 0.0) for k in keys] for p in polys])
    assert info["N2"] == len(polys) == np.linalg.matrix_rank(M1 / np.linalg.norm(M1, axis=1, keepdims=True), 1e-6)
    # every row of M1 lies in span(M2): projection residual ~ round-off
    Q, _ = np.linalg.qr(M2.T)
    resid = M1.T - Q @ (Q.T @ M1.T)
    assert np.abs(resid).max() < 1e-8 * np.abs(M1).max()


def test_example4_certified_paper_values():
    cams, regs = tritools.paper_example(4)
    for _ in range(2):   # first call compiles, the second reuses the structure
        r = tritools.triangulate(cams, regs, "theorem1", delta=4)
        assert r.status == tritools.Status.OPTIMAL and r.n_lmivar == 591
        # paper: X = (-0.901, -0.039, 0.897), gamma = 0.760; the values before issue #5 (Clarabel
        # and the unreduced IPM) were X = (-0.90140382, -0.03946573, 0.89651549), 0.76011535395
        np.testing.assert_allclose(r.X, [-0.90140382, -0.03946573, 0.89651549], atol=1e-5)
        assert abs(r.gamma_ub - 0.7601153539538577) < 1e-9
        assert abs(r.gamma_lb - r.gamma_ub) < 1e-6


def test_example3_certified_values_unchanged():
    cams, regs = tritools.paper_example(3)
    r = tritools.triangulate(cams, regs, "theorem1", delta=4)
    assert r.status == tritools.Status.OPTIMAL and r.n_lmivar == 721
    # gamma is flat at its minimiser (an error d in X moves gamma by O(d^2)): X to 1e-5, gamma to 1e-9
    np.testing.assert_allclose(r.X, [-0.72245684, -0.10773748, 0.69834037], atol=1e-5)
    assert abs(r.gamma_ub - 0.13778172354185286) < 1e-9


def test_example5_cases_agree_with_clarabel():
    cases = tritools.scene.example5_cases(seed=3, n_points=1, thetas=(0.05, 0.2), trials=1)
    for case in cases:
        comp, inst = _instance(case.cameras, case.regions)
        ipm = sospoly.solve_psatz(inst, backend="auto")
        ref = sospoly.solve_psatz(inst, backend="clarabel")
        assert ipm.status == ref.status == sospoly.SolveStatus.OPTIMAL
        assert ipm.solution.attempts[0].label == "ipm"
        assert abs(ipm.lower_bound - ref.lower_bound) < TOL_C
