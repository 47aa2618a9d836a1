"""The interior-point method's direct LAPACK calls and reused buffers (sospoly.solvers.ipm.lapack, .moment, .core).

The direct calls promise bit-identical results to the scipy.linalg functions they replace (the same routine
with the same arguments and storage order), so they are compared with ``array_equal``, not a tolerance; the
Schur complement is compared with the public sparse product the same way and with dense traces.
"""
import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse as sp

from sospoly.solvers.ipm import core, moment
from sospoly.solvers.ipm.lapack import cho_solve, cholesky, solve_lower
from sospoly.solvers.ipm.moment import MomentReduction, reduction_for


def _spd(rng, n):
    G = rng.standard_normal((n, n))
    return G @ G.T + 0.1 * np.eye(n)


@pytest.mark.parametrize("n", [1, 7, 40])
@pytest.mark.parametrize("lower", [True, False])
def test_cholesky_and_cho_solve_equal_scipy_bitwise(n, lower):
    rng = np.random.default_rng(n)
    A = _spd(rng, n)
    b = rng.standard_normal(n)
    ref = sla.cho_factor(A, lower=lower, check_finite=False)
    c = cholesky(A, lower=lower)
    tri = np.tril if lower else np.triu
    assert np.array_equal(tri(c), tri(ref[0]))
    assert np.array_equal(cho_solve(c, b, lower=lower), sla.cho_solve(ref, b, check_finite=False))
    # in place on a Fortran-ordered copy: the same factor, written into that array
    F = np.array(A, order="F")
    cF = cholesky(F, lower=lower, overwrite=True)
    assert np.shares_memory(cF, F) and np.array_equal(tri(cF), tri(ref[0]))
    assert np.array_equal(A, _spd(np.random.default_rng(n), n))      # the input itself untouched


def test_cholesky_rejects_an_indefinite_matrix_like_scipy():
    A = np.diag([1.0, -1.0, 2.0])
    with pytest.raises(np.linalg.LinAlgError):
        cholesky(A, lower=True)
    with pytest.raises(np.linalg.LinAlgError):
        sla.cho_factor(A, lower=True)


@pytest.mark.parametrize("trans", [False, True])
def test_solve_lower_equals_scipy_bitwise_for_every_storage_order(trans):
    rng = np.random.default_rng(11)
    L = np.tril(rng.standard_normal((30, 30))) + 5 * np.eye(30)
    b, B = rng.standard_normal(30), rng.standard_normal((30, 4))
    Lf = np.asfortranarray(L)
    for Lx in (L, Lf, Lf[6:, 6:], L[6:, 6:]):          # C, Fortran and (non-contiguous) sub-blocks
        for r in (b[: Lx.shape[0]], B[: Lx.shape[0]], B[: Lx.shape[0]].T.copy().T):
            ref = sla.solve_triangular(Lx, r, lower=True, trans="T" if trans else "N", check_finite=False)
            got = solve_lower(Lx, r, trans=trans)
            assert np.array_equal(got, ref)
            # and it solves the system (an independent check of the orientation)
            np.testing.assert_allclose((Lx.T if trans else Lx) @ got, r, atol=1e-10)


def test_max_step_one_instance_follows_the_batched_rule():
    rng = np.random.default_rng(5)
    n = 6
    X = np.stack([_spd(rng, n) for _ in range(3)])
    dX = rng.standard_normal((3, n, n))
    dX = dX + dX.transpose(0, 2, 1)
    dX[2] = np.eye(n)                                  # PSD direction: no limit
    Li = np.linalg.inv(np.linalg.cholesky(X))
    batched = core._max_step(Li, dX)
    single = np.array([core._max_step(Li[k:k + 1], dX[k:k + 1])[0] for k in range(3)])
    assert np.isinf(batched[2]) and np.isinf(single[2])
    np.testing.assert_allclose(single[:2], batched[:2], rtol=1e-12)
    # the largest a with X + a dX >= 0, independently: lambda_min(X + a dX) = 0 there
    for k in range(2):
        a = single[k]
        assert abs(np.linalg.eigvalsh(X[k] + a * dX[k])[0]) < 1e-9 * np.abs(X[k]).max()
    # X = I, dX = -I: exactly 1
    assert core._max_step(np.eye(n)[None], -np.eye(n)[None])[0] == 1.0


def _gram_pair_program(n, rng):
    """An image-form single-block program whose columns are Gram pairs (+alpha on a non-canonical entry,
    -alpha on the canonical one of the same monomial) plus a few free columns: a toy moment structure."""
    ii, jj = np.triu_indices(n)
    L = ii.size
    # the 'monomial' of entry (i, j): i + j (a Hankel pattern)
    mono = ii + jj
    rows, cols, vals, col = [], [], [], 0
    for d in np.unique(mono):
        ent = np.nonzero(mono == d)[0]
        for e in ent[1:]:
            rows += [e, ent[0]]
            cols += [col, col]
            vals += [1.0, -1.0]
            col += 1
    n_alpha = col
    canon = [np.nonzero(mono == d)[0][0] for d in np.unique(mono)]
    for _ in range(3):                                 # free columns touching the canonical rows
        pick = rng.choice(canon, 3, replace=False)
        rows += list(pick)
        cols += [col] * 3
        vals += list(rng.standard_normal(3))
        col += 1
    A = sp.csc_matrix((vals, (rows, cols)), shape=(L, col))
    q = np.zeros(col)
    q[n_alpha:] = rng.standard_normal(col - n_alpha)
    return A, q


def test_schur_equals_the_sparse_product_and_the_dense_traces():
    rng = np.random.default_rng(2)
    n = 6
    A, q = _gram_pair_program(n, rng)
    A.sort_indices()
    red = reduction_for(A, q, n)
    assert isinstance(red, MomentReduction)
    e = np.ones(red.L)
    ws = red.workspace(red.Fpad * e[red.Rpad])
    Z, R = _spd(rng, n), _spd(rng, n)
    M = red.schur(Z, R, ws)
    ref = ws["EF"] @ ws["PT"]                          # the public product on the same P^T
    assert np.array_equal(M, ref)
    # independently: M_ab = <A_a, Z A_b R> with A_a = smat(E^T e_a)
    from sospoly.algebra.svec import smat
    mats = [smat(np.where(red.row2col == a, e, 0.0)) for a in range(red.m2)]
    dense = np.array([[np.trace(Aa @ Z @ Ab @ R) for Ab in mats] for Aa in mats])
    np.testing.assert_allclose(M, dense, rtol=1e-12, atol=1e-12 * np.abs(dense).max())
    # a second call with the arguments swapped gives the transpose
    M2 = red.schur(R, Z, ws)
    np.testing.assert_allclose(M2, dense.T, rtol=1e-12, atol=1e-12 * np.abs(dense).max())


def test_regularized_cholesky_raises_the_shift_100x_while_indefinite():
    reg = 1e-16
    # PSD up to round-off but indefinite by ~1e-15 relative: the first shift (1e-16) fails, the second (1e-14) holds
    A = np.array([[1.0, 1.0], [1.0, 1.0 - 1e-15]])
    buf = np.empty((2, 2), order="F")
    L = moment._regularized_cholesky(A, buf, reg)
    L = np.tril(L)
    np.testing.assert_allclose(L @ L.T, A + 1e-14 * np.eye(2), rtol=0, atol=1e-15)   # not 1e-16, not 1e-12
    assert np.array_equal(A, [[1.0, 1.0], [1.0, 1.0 - 1e-15]])        # A itself untouched
    with pytest.raises(np.linalg.LinAlgError):                         # beyond the last shift (1e-12)
        moment._regularized_cholesky(np.diag([1.0, -1e-9]), buf, reg)


def test_moment_form_solves_a_program_with_dependent_equality_rows():
    """A Theorem 1 (delta = 4) sub-problem of the robust benchmark (three views, 5 px, one wrong match; seed 103,
    track 1) whose equality rows (E A_w)^T are numerically dependent: their Schur complement C^T C is singular,
    its once-regularised Cholesky failed at the first iteration and the program went to the unreduced method.
    Regularised like M, the moment form converges; its optimum equals the unreduced IPM's and Clarabel's."""
    from pathlib import Path

    import sospoly
    from sospoly.lowering.conic import Cone, ConicProblem
    from sospoly.solvers.backends import ClarabelBackend
    from sospoly.solvers.ipm.core import mehrotra, result_of
    from sospoly.solvers.ipm.core import layout_of as _layout_of
    from sospoly.solvers.ipm.operators import SparseOperator

    d = np.load(Path(__file__).parent / "data" / "moment_dependent_equalities.npz")
    A = sp.csc_matrix((d["data"], d["indices"], d["indptr"]), shape=tuple(d["shape"]))
    b, q = d["b"], d["q"]
    cones = (Cone("psd", 406, 28),)
    red = reduction_for(A, q, 28)
    assert isinstance(red, MomentReduction)
    res = red.solve(A, b, q, sospoly.DEFAULT_TOLERANCES)
    assert res is not None and res.converged[0], res.reason
    lay = _layout_of(cones)
    plain = result_of(*mehrotra(SparseOperator(A, lay), q[None], b[None], lay, sospoly.DEFAULT_TOLERANCES),
                      q[None], b[None], lay)
    assert plain.converged[0]
    ref = ClarabelBackend().solve(ConicProblem(q, A, b, cones, A.shape[1], ()))
    assert abs(res.primal_objective[0] - plain.primal_objective[0]) < 1e-7
    assert abs(res.primal_objective[0] - float(q @ ref.x)) < 1e-7
    # the returned slack is the image form's: s = b - A x, PSD up to the solver tolerance
    from sospoly.algebra.svec import smat
    np.testing.assert_allclose(res.s[0], b - A @ res.x[0], atol=1e-7)
    assert np.linalg.eigvalsh(smat(res.s[0], 28))[0] > -1e-7
