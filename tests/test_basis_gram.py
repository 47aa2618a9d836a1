"""Monomial bases, the L(alpha) parametrisation and the Gram-matrix method (SPEC §4).

References: sigma(n, k) = C(n + k, k) (stars and bars) and
tau(n, delta) = sigma(delta/2)(sigma(delta/2) + 1)/2 - sigma(delta) (SPEC §4, Chesi 2026); both are
also checked against brute-force counts that do not use the closed forms.
"""
import itertools
from math import comb

import numpy as np
import pytest

import sospoly as sp
from sospoly import GramBasis, MonomialIndex, Polynomial, SOSProgram, lower, monomials, sigma, tau
from sospoly.lowering.conic import gram_structure
from sospoly.algebra.svec import smat, svec, triu_pairs


def _count_exact(n, d):
    """Number of exponent tuples of n non-negative ints summing to d, by dynamic programming."""
    ways = [1] + [0] * d            # 0 variables
    for _ in range(n):
        ways = [sum(ways[: t + 1]) for t in range(d + 1)]
    return ways[d]


@pytest.mark.parametrize("n", range(1, 9))
def test_sigma_and_tau_closed_forms(n):
    for k in range(0, 7):
        assert sigma(n, k) == comb(n + k, k)
        assert sigma(n, k) == sum(_count_exact(n, d) for d in range(k + 1))
        assert len(monomials(n, k)) == sigma(n, k)
    for delta in (0, 2, 4, 6):
        d = delta // 2
        s = comb(n + d, d)
        assert tau(n, delta) == s * (s + 1) // 2 - comb(n + delta, delta)
    assert sigma(n, -1) == 0


def test_tau_equals_dimension_of_L_by_brute_force():
    """dim{L = L^T : b^T L b == 0} computed as the null space of the coefficient map."""
    for n, delta in [(1, 2), (1, 4), (2, 2), (2, 4), (3, 4), (2, 6)]:
        b = monomials(n, delta // 2)
        s = len(b)
        pairs = [(i, j) for j in range(s) for i in range(j + 1)]
        prods = {}
        rows = []
        for i, j in pairs:
            rows.append(prods.setdefault(tuple(b[i] + b[j]), len(prods)))
        # coefficient of monomial m in b^T L b: L_ii (diagonal) or 2 L_ij (off-diagonal)
        C = np.zeros((len(prods), len(pairs)))
        for p, ((i, j), m) in enumerate(zip(pairs, rows)):
            C[m, p] = 1.0 if i == j else 2.0
        dim_null = len(pairs) - np.linalg.matrix_rank(C)
        assert dim_null == tau(n, delta), (n, delta)


def test_monomial_order_is_documented_order():
    for n in (1, 2, 3, 5):
        E = monomials(n, 3)
        assert np.all(E[0] == 0)                           # constant first
        np.testing.assert_array_equal(E[1:n + 1], np.eye(n, dtype=int))   # then v1 .. vn
        deg = E.sum(axis=1)
        assert np.all(np.diff(deg) >= 0)                   # graded
        for d in range(4):
            block = [tuple(r) for r in E[deg == d]]
            assert block == sorted(block, reverse=True)    # lexicographically decreasing in a degree
        assert len({tuple(r) for r in E}) == len(E)        # distinct
    E = monomials(3, 4, mindeg=2)
    assert E.sum(axis=1).min() == 2 and len(E) == sigma(3, 4) - sigma(3, 1)
    assert monomials(2, 1, mindeg=2).shape == (0, 2)


def test_monomial_index_lookup():
    E = monomials(3, 3)
    idx = MonomialIndex(E)
    rng = np.random.default_rng(0)
    pick = rng.integers(0, len(E), size=30)
    np.testing.assert_array_equal(idx.find(E[pick]), pick)
    out = idx.find(np.array([[4, 0, 0], [0, 0, 9]]), missing_ok=True)
    assert list(out) == [-1, -1]
    with pytest.raises(KeyError):
        idx.find(np.array([[0, 4, 0]]))
    with pytest.raises(ValueError):
        MonomialIndex(np.array([[1, 0], [1, 0]]))


CASES = [(1, 1), (1, 2), (2, 1), (2, 2), (3, 2), (2, 3)]


@pytest.mark.parametrize("n,half", CASES)
def test_gram_basis_product_table_brute_force(n, half):
    gb = GramBasis.full(n, half)
    s = gb.size
    assert s == sigma(n, half)
    # pairs are the upper triangle, column by column (svec order)
    expected_pairs = [(i, j) for j in range(s) for i in range(j + 1)]
    assert list(zip(gb.pair_i.tolist(), gb.pair_j.tolist())) == expected_pairs
    # each pair's product monomial, by brute force
    for p, (i, j) in enumerate(expected_pairs):
        np.testing.assert_array_equal(gb.products[gb.pair_monomial[p]], gb.b[i] + gb.b[j])
    # the products of the full basis are exactly the monomials of degree <= 2*half, in documented order
    np.testing.assert_array_equal(gb.products, monomials(n, 2 * half))
    brute = {tuple(gb.b[i] + gb.b[j]) for i, j in itertools.product(range(s), repeat=2)}
    assert brute == {tuple(r) for r in gb.products}
    # pairs_of lists every pair of a monomial
    m = len(gb.products) - 1
    assert all(tuple(gb.b[i] + gb.b[j]) == tuple(gb.products[m]) for i, j in gb.pairs_of(m))


def _L_matrices(gb):
    """The explicit L(alpha) basis of sospoly.lowering.conic.gram_structure as symmetric matrices.

    Alpha k contributes +1 x (monomial m) through its own pair and -1 x m through the canonical
    pair of m (see the module docstring of sospoly.lowering.conic), i.e. L_ii = +-1 on a diagonal pair
    and L_ij = L_ji = +-1/2 off the diagonal.
    """
    st = gram_structure(gb)
    s = gb.size
    mats = []
    for pa, pc in zip(st.alpha_pairs, st.alpha_canonical):
        L = np.zeros((s, s))
        for pair, sign in ((pa, 1.0), (pc, -1.0)):
            i, j = gb.pair_i[pair], gb.pair_j[pair]
            if i == j:
                L[i, i] += sign
            else:
                L[i, j] += sign / 2
                L[j, i] += sign / 2
        mats.append(L)
    return st, mats


@pytest.mark.parametrize("n,half", CASES)
def test_L_alpha_basis(n, half):
    gb = GramBasis.full(n, half)
    st, Ls = _L_matrices(gb)
    assert len(Ls) == tau(n, 2 * half)
    assert all(np.array_equal(L, L.T) for L in Ls)
    if Ls:
        assert np.linalg.matrix_rank(np.array([svec(L) for L in Ls])) == len(Ls)
    # every product monomial has exactly one canonical pair, which produces it
    assert len(st.canonical) == len(gb.products)
    np.testing.assert_array_equal(gb.pair_monomial[st.canonical], np.arange(len(gb.products)))
    # canonical pair is diagonal whenever the monomial is a square of a basis element
    diag_monos = set(gb.pair_monomial[gb.pair_i == gb.pair_j].tolist())
    for m in diag_monos:
        assert gb.pair_i[st.canonical[m]] == gb.pair_j[st.canonical[m]]
    rng = np.random.default_rng(n * 10 + half)
    pts = rng.uniform(-2, 2, size=(10, n))
    w = np.where(gb.pair_i == gb.pair_j, 1.0, 2.0)
    for L in Ls:
        # b(v)^T L b(v) == 0 at random points ...
        for v in pts:
            bv = gb.evaluate(v)
            assert abs(bv @ L @ bv) <= 1e-12 * max(1.0, bv @ bv)
        # ... and identically: the coefficient of every monomial sums to zero
        coef = np.zeros(len(gb.products))
        np.add.at(coef, gb.pair_monomial, w * L[gb.pair_i, gb.pair_j])
        assert np.all(coef == 0.0)


def _random_sos(rng, gens, half, nsq=3):
    E = monomials(len(gens), half)
    p = Polynomial.constant(0.0, gens)
    for _ in range(nsq):
        c = rng.standard_normal(len(E))
        p = p + Polynomial(gens, {tuple(e): float(x) for e, x in zip(E, c)}) ** 2
    return p


@pytest.mark.parametrize("seed", range(3))
def test_particular_gram_reproduces_polynomial(seed):
    rng = np.random.default_rng(seed)
    gens = ("x", "y")
    p = _random_sos(rng, gens, 2)
    prog = SOSProgram(gens)
    con = prog.add_sos(p, name="p")
    cp_ = lower(prog, sp.GramForm.IMAGE)
    assert cp_.n_cols == tau(2, 4)                    # only the alpha columns
    gb = con.gram.blocks[0]
    pts = rng.uniform(-1.5, 1.5, size=(20, 2))
    vals = p.evaluate(pts)
    for x in (np.zeros(cp_.n_cols), rng.standard_normal(cp_.n_cols)):
        G = cp_.gram_matrices(x)["p"]                # U (alpha = 0) and U + L(alpha)
        assert np.allclose(G, G.T)
        got = np.array([gb.evaluate(v) @ G @ gb.evaluate(v) for v in pts])
        np.testing.assert_allclose(got, vals, rtol=1e-10, atol=1e-10)
    # the solved Gram (a PSD one) also reproduces p, and is PSD
    res = sp.is_sos(p)
    assert res.is_sos
    G = res.gram
    assert np.linalg.eigvalsh(G)[0] >= -1e-7 * max(1.0, np.abs(G).max())
    got = np.array([gb.evaluate(v) @ G @ gb.evaluate(v) for v in pts])
    np.testing.assert_allclose(got, vals, rtol=1e-7, atol=1e-7)


def test_svec_convention():
    rng = np.random.default_rng(3)
    A = rng.standard_normal((4, 4))
    X, Y = A + A.T, A @ A.T
    assert np.isclose(svec(X) @ svec(Y), np.trace(X @ Y))       # <X, Y> = svec(X).svec(Y)
    np.testing.assert_allclose(smat(svec(X)), X)
    i, j = triu_pairs(3)
    assert list(zip(i.tolist(), j.tolist())) == [(0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2)]
    with pytest.raises(ValueError):
        smat(np.ones(5))
