"""Monomial bases, their sizes and index look-ups (SPEC §4).

Order (used everywhere in sospoly): **graded, then lexicographically decreasing
exponent tuples**.  For variables ``(v1, ..., vn)`` the basis of degree <= 2 is::

    1, v1, v2, ..., vn, v1^2, v1 v2, ..., v1 vn, v2^2, ..., vn^2

so the constant monomial has index 0 and ``v_k`` has index ``k`` (1-based), which
is what minimiser extraction relies on.

``sigma(n, k) = C(n + k, k)`` is the number of monomials of degree <= k in n
variables; ``tau(n, delta) = sigma(n, delta/2)(sigma(n, delta/2) + 1)/2 - sigma(n, delta)``
is the dimension of the space L of symmetric matrices with ``b(v)^T L b(v) = 0``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from math import comb

import numpy as np

from .svec import triu_pairs

__all__ = ["sigma", "tau", "monomials", "MonomialIndex", "GramBasis", "GramBlocks", "graded_order",
           "exponent_rows", "even_degree", "sparse_row_keys", "unique_rows"]


def exponent_rows(basis, n_vars: int, what: str) -> np.ndarray:
    """A user's monomial basis as (s, n_vars) exponent rows: non-negative integers, at least one row
    (ValueError naming ``what`` otherwise; a float exponent is never truncated silently)."""
    try:
        raw = np.asarray(basis)
    except (TypeError, ValueError):
        raw = np.asarray(None)
    ok = raw.dtype.kind in "iu" or (raw.dtype.kind == "f" and np.all(np.isfinite(raw)) and np.all(raw == np.round(raw)))
    if not ok or raw.ndim not in (1, 2) or raw.size == 0 or raw.shape[-1] != n_vars or np.any(raw < 0):
        raise ValueError(f"{what} must be a non-empty array of exponent rows of {n_vars} non-negative integers, "
                         f"got {basis!r}")
    return raw.astype(np.int64).reshape(-1, n_vars)


def even_degree(degree, low: int, what: str) -> int:
    """``degree`` as an even integer >= ``low`` (ValueError naming ``what`` otherwise)."""
    if isinstance(degree, bool) or not isinstance(degree, (int, np.integer)) or degree % 2 or degree < low:
        raise ValueError(f"{what} must be an even integer >= {low}, got {degree!r}")
    return int(degree)


def sigma(n: int, k: int) -> int:
    """Number of monomials of degree <= k in n variables, C(n+k, k) (0 for k < 0)."""
    if k < 0:
        return 0
    return comb(n + k, k)


def tau(n: int, delta: int) -> int:
    """Number of free parameters alpha of L(alpha) for even degree ``delta`` (SPEC §4)."""
    if delta % 2:
        raise ValueError(f"the Gram degree delta must be even, got {delta}")
    s = sigma(n, delta // 2)
    return s * (s + 1) // 2 - sigma(n, delta)


def _compositions_desc(n: int, d: int):
    """Exponent tuples of total degree d in n variables, lexicographically decreasing."""
    if n == 0:
        if d == 0:
            yield ()
        return
    if n == 1:
        yield (d,)
        return
    for first in range(d, -1, -1):
        for rest in _compositions_desc(n - 1, d - first):
            yield (first,) + rest


@lru_cache(maxsize=256)
def _monomials_cached(n: int, k: int, mindeg: int) -> np.ndarray:
    rows = [e for d in range(mindeg, k + 1) for e in _compositions_desc(n, d)]
    arr = np.array(rows, dtype=np.int64).reshape(len(rows), n)
    arr.setflags(write=False)
    return arr


def monomials(n: int, k: int, mindeg: int = 0) -> np.ndarray:
    """All exponent vectors of degree in [mindeg, k] in n variables, in the documented order.

    Returns a read-only integer array of shape ``(sigma(n, k) - sigma(n, mindeg - 1), n)``.
    """
    if n < 0 or k < -1:
        raise ValueError(f"bad basis size n={n}, k={k}")
    if k < mindeg:
        return np.zeros((0, n), dtype=np.int64)
    return _monomials_cached(int(n), int(k), int(mindeg))


def graded_order(E: np.ndarray) -> np.ndarray:
    """The permutation sorting exponent rows in the documented order (graded, then lexicographically
    decreasing)."""
    E = np.asarray(E, dtype=np.int64)
    if E.shape[0] == 0:
        return np.zeros(0, np.int64)
    return np.lexsort(tuple((-E[:, k]) for k in range(E.shape[1] - 1, -1, -1)) + (E.sum(axis=1),))


def sparse_row_keys(E: np.ndarray, max_degree: int) -> np.ndarray | None:
    """Exact int64 keys of non-negative exponent rows of degree <= ``max_degree``, or None when they do not fit.

    A row of degree d is the multiset of its variables' indices i_1 <= ... <= i_d; its key is
    sum_p (i_p + 1) (n + 1)^(p - 1), the digits of that multiset in base n + 1 (0 = no variable): distinct
    rows have distinct keys while (n + 1)^max_degree < 2^62.  The dense mixed radix (one digit per variable)
    needs base^n instead, which many-variable programs (n ~ 100) exceed; certificate monomials have a small
    degree, so this encoding fits them (n = 100, degree <= 9).  Cost O(m n) for m rows."""
    E = np.asarray(E, dtype=np.int64)
    m, n = E.shape
    D = int(max_degree)
    if D < 0 or D * np.log2(n + 1) >= 62:
        return None
    deg = E.sum(axis=1)
    if m and int(deg.max()) > D:
        raise ValueError(f"an exponent row has degree {int(deg.max())} > max_degree {D}")
    r, c = np.nonzero(E)                              # row-major: variable indices increase within a row
    counts = E[r, c]
    rr, cc = np.repeat(r, counts), np.repeat(c, counts)
    pos = np.arange(rr.size) - np.repeat((np.cumsum(deg) - deg)[r], counts)
    digits = np.zeros((m, max(D, 1)), np.int64)
    digits[rr, pos] = cc + 1
    return digits @ ((n + 1) ** np.arange(max(D, 1), dtype=np.int64))


def unique_rows(E: np.ndarray, return_inverse: bool = False):
    """The distinct exponent rows of ``E`` (non-negative integers), in an unspecified but deterministic order: for
    callers that only test membership, sum by row or re-sort (:func:`graded_order`); with ``return_inverse`` also
    the index of each row of ``E`` among them.  Hashes exact integer keys (:func:`sparse_row_keys`) instead of
    ``np.unique(E, axis=0)``'s row-wise sort, which dominated the reductions of many-variable shapes
    (:mod:`sospoly.certificates.reduction`: 2.8 s -> 0.3 s at 93 variables, benchmarks/RESULTS.md)."""
    E = np.asarray(E, dtype=np.int64)
    if E.ndim != 2:
        raise ValueError(f"exponent rows must be a 2-D array, got shape {E.shape}")
    keys = None if E.shape[0] <= 1 else sparse_row_keys(E, int(E.sum(axis=1).max()))
    if keys is None:
        uniq, inv = np.unique(E, axis=0, return_inverse=True)
        inv = np.asarray(inv).ravel()
    else:
        _, first, inv = np.unique(keys, return_index=True, return_inverse=True)
        uniq = E[first]
    return (uniq, inv.astype(np.int64)) if return_inverse else uniq


class MonomialIndex:
    """Vectorised look-up of exponent rows in a fixed list of distinct monomials.

    Rows are encoded to int64 keys by a mixed radix when that fits, else compared as
    raw bytes; both give exact matches.
    """

    def __init__(self, exponents: np.ndarray):
        E = np.ascontiguousarray(np.asarray(exponents, dtype=np.int64))
        if E.ndim != 2:
            raise ValueError("exponents must be a 2-D array")
        self.exponents = E
        self.n = E.shape[1]
        maxdeg = int(E.max()) if E.size else 0
        self._base = maxdeg + 1
        self._use_int = self.n == 0 or self.n * np.log2(max(self._base, 2)) < 62
        # many variables: exact keys of the rows' variable multisets (sparse_row_keys) while they fit, else bytes
        self._degree = int(E.sum(axis=1).max()) if E.size else 0
        self._use_sparse = not self._use_int and sparse_row_keys(E[:0], self._degree) is not None
        keys = self._keys(E)
        order = np.argsort(keys, kind="stable")
        self._sorted = keys[order]
        self._order = order
        if len(keys) > 1 and np.any(self._sorted[1:] == self._sorted[:-1]):
            raise ValueError("duplicate monomials in the basis")

    def _keys(self, E: np.ndarray):
        if self._use_int:
            radix = self._base ** np.arange(self.n, dtype=np.int64)
            return E @ radix
        if self._use_sparse:
            return sparse_row_keys(E, self._degree)
        return np.ascontiguousarray(E).view(np.dtype((np.void, 8 * self.n))).ravel()

    def __len__(self) -> int:
        return self.exponents.shape[0]

    def find(self, E: np.ndarray, missing_ok: bool = False) -> np.ndarray:
        """Indices of the rows of E in the basis (-1 where absent if ``missing_ok``)."""
        E = np.ascontiguousarray(np.asarray(E, dtype=np.int64)).reshape(-1, self.n)
        if len(self) == 0:
            idx = np.full(E.shape[0], -1, dtype=np.int64)
        else:
            if self._use_int and E.size and int(E.max()) >= self._base:
                big = (E >= self._base).any(axis=1)
            elif self._use_sparse and E.size:
                big = E.sum(axis=1) > self._degree       # above the basis's degree: in no row
            else:
                big = np.zeros(E.shape[0], dtype=bool)
            Ec = np.where(big[:, None], 0, E)
            keys = self._keys(Ec)
            pos = np.searchsorted(self._sorted, keys)
            pos = np.minimum(pos, len(self._sorted) - 1)
            hit = (self._sorted[pos] == keys) & ~big
            idx = np.where(hit, self._order[pos], -1)
        if not missing_ok and np.any(idx < 0):
            bad = E[np.argmax(idx < 0)]
            raise KeyError(f"monomial with exponent {tuple(int(k) for k in bad)} is not in the basis")
        return idx


@dataclass(frozen=True)
class GramBasis:
    """The half-degree basis b(v) of a Gram matrix and its product table.

    ``b`` holds the exponents of b(v) (all monomials of degree <= delta/2 unless
    given explicitly).  ``products`` is the basis of all monomials of b(v) b(v)^T.
    For every upper-triangular pair ``(i, j)``, ``i <= j`` (listed column-wise as in
    the svec convention of :mod:`sospoly.algebra.svec`), ``pair_monomial[p]`` is the index in
    ``products`` of ``b_i b_j``.
    """

    b: np.ndarray
    products: np.ndarray
    pair_i: np.ndarray
    pair_j: np.ndarray
    pair_monomial: np.ndarray
    product_index: MonomialIndex = field(repr=False, compare=False)

    @classmethod
    def full(cls, nvars: int, half_degree: int) -> GramBasis:
        return cls.from_exponents(monomials(nvars, half_degree))

    @classmethod
    def from_exponents(cls, b: np.ndarray) -> GramBasis:
        b = np.asarray(b, dtype=np.int64)
        s = b.shape[0]
        ii, jj = triu_pairs(s)  # column-wise upper triangle, the svec order
        prod_exps = b[ii] + b[jj]
        uniq, inverse = unique_rows(prod_exps, return_inverse=True)
        # reorder the products in the documented graded-lex-decreasing order
        order = graded_order(uniq)
        rank = np.empty_like(order)
        rank[order] = np.arange(len(order))
        products = uniq[order]
        pair_monomial = rank[np.asarray(inverse).ravel()]
        return cls(b=b, products=products, pair_i=ii, pair_j=jj,
                   pair_monomial=pair_monomial.astype(np.int64), product_index=MonomialIndex(products))

    @property
    def size(self) -> int:
        return self.b.shape[0]

    @property
    def n_pairs(self) -> int:
        return self.pair_i.shape[0]

    def pairs_of(self, monomial_index: int) -> list[tuple[int, int]]:
        sel = np.nonzero(self.pair_monomial == monomial_index)[0]
        return [(int(self.pair_i[p]), int(self.pair_j[p])) for p in sel]

    def evaluate(self, point: np.ndarray) -> np.ndarray:
        """b(v) at a point."""
        point = np.asarray(point, dtype=float)
        return np.prod(point[None, :] ** self.b, axis=1)


@dataclass(frozen=True)
class GramBlocks:
    """Several Gram bases whose sum represents one polynomial: p(v) = sum_j b_j(v)^T G_j b_j(v).

    A dense certificate has one block (the full basis of degree delta/2); a sparse one has a
    block per clique (correlative sparsity), per term-sparsity component, or a dense low-degree
    block beside clique blocks.  The *pairs* (i <= j) of all blocks are concatenated block by
    block, each block's pairs in its svec order, so a pair's index is also its row in the
    concatenated svec vectors of the blocks.  ``products`` is the union of the blocks'
    products (documented monomial order) and ``pair_monomial[p]`` the index in it of pair p's
    monomial.
    """

    blocks: tuple
    products: np.ndarray
    pair_block: np.ndarray
    pair_diag: np.ndarray
    pair_monomial: np.ndarray
    block_offsets: np.ndarray          # first pair (svec row) of each block
    product_index: MonomialIndex = field(repr=False, compare=False)

    @classmethod
    def of(cls, bases) -> GramBlocks:
        """Blocks from GramBasis objects or exponent arrays (a single basis or a sequence)."""
        if isinstance(bases, GramBasis) or (isinstance(bases, np.ndarray) and bases.ndim == 2):
            bases = [bases]
        blocks = tuple(b if isinstance(b, GramBasis) else GramBasis.from_exponents(b) for b in bases)
        if not blocks:
            raise ValueError("an SOS polynomial needs at least one Gram block")
        n = blocks[0].b.shape[1]
        if any(b.b.shape[1] != n for b in blocks):
            raise ValueError("Gram blocks over different numbers of variables")
        if len(blocks) == 1:
            gb = blocks[0]
            return cls(blocks, gb.products, np.zeros(gb.n_pairs, np.int64), gb.pair_i == gb.pair_j,
                       gb.pair_monomial, np.zeros(1, np.int64), gb.product_index)
        allp = np.vstack([b.products for b in blocks])
        uniq = unique_rows(allp)
        products = uniq[graded_order(uniq)]
        index = MonomialIndex(products)
        pm = np.concatenate([index.find(b.products)[b.pair_monomial] for b in blocks])
        sizes = np.array([b.n_pairs for b in blocks], np.int64)
        return cls(blocks, products, np.repeat(np.arange(len(blocks)), sizes),
                   np.concatenate([b.pair_i == b.pair_j for b in blocks]), pm.astype(np.int64),
                   np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64), index)

    @property
    def sizes(self) -> tuple:
        return tuple(b.size for b in self.blocks)

    @property
    def n_pairs(self) -> int:
        return int(self.pair_monomial.size)

    @property
    def n_products(self) -> int:
        return int(self.products.shape[0])

    @property
    def b(self) -> np.ndarray:
        """The basis of the first (for a dense certificate: the only) block."""
        return self.blocks[0].b
