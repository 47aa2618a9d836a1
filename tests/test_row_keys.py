"""Exact row keys of exponent rows (issue #22: the reductions of many-variable certificate shapes).

References: numpy's row-wise ``np.unique(E, axis=0)`` and a brute-force row search; the reduction of a
many-variable clique shape against the same reduction with ``np.unique(axis=0)`` rows."""
from __future__ import annotations

import numpy as np
import pytest

from sospoly.algebra.basis import MonomialIndex, monomials, sparse_row_keys, unique_rows
from sospoly.certificates import reduction


def _random_rows(n: int, m: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    M = monomials(n, 2)
    return M[rng.integers(0, len(M), m)] + M[rng.integers(0, len(M), m)]


@pytest.mark.parametrize("n", [1, 4, 30, 93, 120])
def test_unique_rows_is_numpy_unique_as_a_set(n):
    E = _random_rows(n, 3000, n)
    ref = np.unique(E, axis=0)
    got, inv = unique_rows(E, return_inverse=True)
    assert got.shape == ref.shape
    assert np.array_equal(np.unique(got, axis=0), ref)
    assert np.array_equal(got[inv], E)                       # the inverse rebuilds every row


@pytest.mark.parametrize("n", [30, 93, 120])
def test_sparse_keys_distinct_exactly_for_distinct_rows(n):
    E = np.unique(_random_rows(n, 4000, 7 + n), axis=0)
    keys = sparse_row_keys(E, 4)
    assert keys is not None and len(np.unique(keys)) == E.shape[0]
    # a permutation of variables inside a row's support gives another row, another key
    swapped = E.copy()
    swapped[:, [0, 1]] = swapped[:, [1, 0]]
    differs = np.any(swapped != E, axis=1)
    assert np.all(sparse_row_keys(swapped, 4)[differs] != keys[differs])


def test_sparse_keys_refuse_what_does_not_fit():
    assert sparse_row_keys(np.zeros((3, 10**7), np.int64), 4) is None          # (n + 1)^4 >= 2^62
    with pytest.raises(ValueError, match="max_degree"):
        sparse_row_keys(np.array([[3, 2]]), 4)


@pytest.mark.parametrize("n", [93, 120])
def test_monomial_index_sparse_keys_match_brute_force(n):
    basis = np.unique(_random_rows(n, 800, n), axis=0)
    index = MonomialIndex(basis)
    assert index._use_sparse                                  # the dense radix does not fit 93+ variables
    queries = np.vstack([basis[::5], _random_rows(n, 200, 1) + np.eye(n, dtype=np.int64)[0],
                         np.zeros((1, n), np.int64), 3 * basis[:5]])
    ref = np.array([next(iter(np.flatnonzero((basis == q).all(axis=1))), -1) for q in queries])
    assert np.array_equal(index.find(queries, missing_ok=True), ref)
    with pytest.raises(KeyError):
        index.find(3 * basis[:2])


def test_reduction_of_a_many_variable_clique_shape_unchanged(monkeypatch):
    """The reduced shape of a 60-variable band of cliques equals the one computed with numpy's row-wise unique."""
    from sospoly import clique_shape

    n, w = 60, 6
    cliques = [list(range(k, k + w)) for k in range(0, n - w + 1, 3)]
    rng = np.random.default_rng(3)
    eq_vars = [sorted(rng.choice(c, 2, replace=False).tolist()) for c in cliques]
    eqs = []
    for a, b in eq_vars:                       # bilinear equalities x_a x_b + x_a - 1 on each clique
        G = np.zeros((3, n), np.int64)
        G[0, a] = G[0, b] = 1
        G[1, a] = 1
        eqs.append(G)
    f = np.vstack([2 * np.eye(n, dtype=np.int64), np.eye(n, dtype=np.int64), np.zeros((1, n), np.int64)])
    shape = clique_shape(n, 4, cliques, eq_vars, (), [2] * len(eqs), (), low_degree=2)
    fast = reduction.reduce_shape(shape, f, eqs)

    def numpy_rows(E):
        return np.unique(np.asarray(E, np.int64), axis=0)

    monkeypatch.setattr(reduction, "unique_rows", numpy_rows)
    slow = reduction.reduce_shape(shape, f, eqs)
    assert sum(b.shape[0] for b in fast.u_bases) < sum(b.shape[0] for b in shape.u_bases)   # something dropped
    assert len(fast.u_bases) == len(slow.u_bases)
    assert all(np.array_equal(a, b) for a, b in zip(fast.u_bases, slow.u_bases))
