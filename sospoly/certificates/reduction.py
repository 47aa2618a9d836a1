"""Exact reductions of a certificate shape's Gram bases (pure data, no SDP solved).

Both remove Gram-basis monomials that no feasible certificate needs, so the bound is unchanged;
both matter because interior-point solvers need a strictly feasible program: without them the
solver stalls ("numerical error") or returns an inaccurate bound.  :func:`reduce_shape` applies
:func:`ideal_reduction`, then :func:`diagonal_reduction`.

**Diagonal consistency.**
In the identity of :mod:`sospoly.certificates.psatz`

    u(v) = q(v) (f(v) - c) + sum_k r_k(v) g_k(v) - sum_k s_k(v) h_k(v),   u = sum_j b_j^T G_j b_j,

look at a monomial m of some Gram basis b_j and the coefficient of m^2 (exponent 2m).  It collects

* the diagonal entries G_j[m, m] of every block holding m (each >= 0 since G_j >= 0),
* off-diagonal entries G_j[a, b] with a + b = 2m, a != b, in some block,
* the data and multiplier terms: supp(q f) ∪ supp(q) and, for free multipliers,
  supp(r_k) + supp(g_k) (Minkowski sum) and (B_k + B_k) + supp(h_k) for s_k = B_k^T S_k B_k.

When 2m is reached by neither of the last two kinds, the identity forces the sum of the diagonal
entries to 0, so G_j[m, m] = 0 in *every* feasible certificate and (G_j >= 0) the whole row and
column of m vanish: m can be dropped from every block without changing the feasible set of
certificates.  Dropping monomials removes off-diagonal sums, so the test is repeated until nothing
changes (Löfberg 2009, "Pre- and post-processing sum-of-squares programs in practice", IEEE TAC
54(5), the diagonal-inconsistency test; Permenter and Parrilo 2014, facial reduction).

Typical case: a quartic certificate of a quadratic objective with bilinear constraints (x_i^4 is
reached by nothing but G[x_i^2, x_i^2]): the block has no interior.

**Normal forms modulo the equalities.**  When an equality g_k lies in the span of a block's basis,
G + t c_k c_k^T (c_k the coefficients of g_k) with r_k - t g_k is another certificate for every t:
the optimal face is unbounded and the moment matrix is singular (the dual has no interior).  Let
LM_k be the leading monomial of g_k (graded lexicographic order) and B a block's basis.  If (i) for
every m in B divisible by LM_k the monomials (m / LM_k) supp(g_k) lie in B and (ii) the multiplier
support supp(r_k) holds Q_k + B with Q_k = {m / LM_k}, then dividing each row p of the block by the
equalities (the division algorithm, which stays in span B by (i)) gives p = NF(p) + sum_k a_k g_k,
a_k in span Q_k, and p^2 = NF(p)^2 + sum_k g_k a_k (2 NF(p) + sum_l a_l g_l) with the bracketed
multipliers in supp(r_k) by (ii): every certificate has an equal-bound certificate whose block uses
only B minus the multiples of the LM_k.  Monomials of degree <= 1 are kept (they carry the first-order
moments read by extraction).

Both are computed from *supports* (data slots): the reduced shape gives a valid bound for every
instance whose coefficients live in those supports (any shape does); it is exact when the leading
coefficients of the g_k are non-zero, as they are for generic data.

A shape asks for them with ``CertificateShape.reduced()``; :func:`sospoly.certificates.psatz.psatz_structure`
applies :func:`reduce_shape` against the program's data slots.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..algebra.basis import MonomialIndex, unique_rows
from ..budget import check_deadline
from .shape import CertificateShape

__all__ = ["diagonal_reduction", "ideal_reduction", "reduce_shape", "leading_monomial"]


def _rows(*arrays, n: int) -> np.ndarray:
    arrs = [np.asarray(a, np.int64).reshape(-1, n) for a in arrays]
    arrs = [a for a in arrs if a.shape[0]]
    return unique_rows(np.vstack(arrs)) if arrs else np.zeros((0, n), np.int64)


def _minkowski(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """All sums a + b, a in A, b in B (distinct rows)."""
    n = A.shape[1]
    if not A.shape[0] or not B.shape[0]:
        return np.zeros((0, n), np.int64)
    check_deadline("reducing the certificate's bases")
    return unique_rows((A[:, None, :] + B[None, :, :]).reshape(-1, n))


def _pair_sums(B: np.ndarray, diagonal: bool) -> np.ndarray:
    ii, jj = np.triu_indices(B.shape[0], k=0 if diagonal else 1)
    return B[ii] + B[jj]


def diagonal_reduction(shape: CertificateShape, f_support, eq_supports=(), ineq_supports=(), q_support=None,
                       q_basis=None) -> CertificateShape:
    """``shape`` with every u-basis monomial dropped whose Gram diagonal the identity forces to zero
    (module docstring); the multiplier supports are kept.

    ``f_support``, ``eq_supports``, ``ineq_supports``: exponent rows of f, g_k, h_k (their data slots);
    the multiplier q is given by its support ``q_support`` (fixed q) or by the Gram basis ``q_basis`` of
    a free SOS q (then supp q ⊆ q_basis + q_basis).  Returns ``shape`` itself when nothing is dropped.
    """
    F = np.asarray(f_support, np.int64)
    n = F.shape[1]
    if q_basis is not None:
        Q = unique_rows(_pair_sums(np.asarray(q_basis, np.int64).reshape(-1, n), True))
    else:
        Q = np.zeros((1, n), np.int64) if q_support is None else _rows(q_support, n=n)
    reached = [Q, _minkowski(Q, _rows(F, n=n))]
    for R, G in zip(shape.r_supports, eq_supports):
        check_deadline("reducing the certificate's bases")
        reached.append(_minkowski(R, _rows(G, n=n)))
    for B, H in zip(shape.s_bases, ineq_supports):
        check_deadline("reducing the certificate's bases")
        reached.append(_minkowski(unique_rows(_pair_sums(B, True)), _rows(H, n=n)))
    reachable = MonomialIndex(_rows(*reached, n=n))

    bases = [np.asarray(B, np.int64) for B in shape.u_bases]
    changed = False
    while True:
        check_deadline("reducing the certificate's bases")
        offdiag = MonomialIndex(_rows(*[_pair_sums(B, False) for B in bases], n=n))
        candidates = _rows(*bases, n=n)
        if not candidates.shape[0]:
            break
        doubled = 2 * candidates
        forced = (reachable.find(doubled, missing_ok=True) < 0) & (offdiag.find(doubled, missing_ok=True) < 0)
        if not forced.any():
            break
        drop = MonomialIndex(candidates[forced])
        bases = [B[drop.find(B, missing_ok=True) < 0] for B in bases]
        changed = True
    if not changed:
        return shape
    kept = [k for k, B in enumerate(bases) if B.shape[0]]
    block_clique = tuple(shape.block_clique[k] for k in kept) if shape.block_clique else ()
    return replace(shape, u_bases=tuple(bases[k] for k in kept), block_clique=block_clique)


def leading_monomial(support) -> np.ndarray:
    """The leading exponent row of a support in the graded lexicographic order."""
    E = np.asarray(support, np.int64)
    top = E[E.sum(axis=1) == E.sum(axis=1).max()]
    return top[np.lexsort(top.T[::-1])[-1]]


def ideal_reduction(shape: CertificateShape, eq_supports) -> CertificateShape:
    """``shape`` with each u-block's multiples of the equalities' leading monomials dropped where the
    conditions (i) and (ii) of the module docstring hold; ``eq_supports`` the exponent rows of the g_k
    (their data slots).  Returns ``shape`` itself when nothing is dropped."""
    eqs = [np.asarray(G, np.int64) for G in eq_supports]
    if not eqs or not shape.u_bases:
        return shape
    n = shape.u_bases[0].shape[1]
    leads = [leading_monomial(G) if G.shape[0] else None for G in eqs]
    lead_vars = [None if L is None else frozenset(np.flatnonzero(L).tolist()) for L in leads]
    r_index: dict = {}                 # built on first use: most equalities divide no block (other cliques)
    bases, changed = [], False
    for B in shape.u_bases:
        check_deadline("reducing the certificate's bases")
        B = np.asarray(B, np.int64)
        in_B = MonomialIndex(B)
        block_vars = frozenset(np.flatnonzero(B.any(axis=0)).tolist())
        drop = np.zeros(B.shape[0], bool)
        for k, (G, L) in enumerate(zip(eqs, leads)):
            if L is None or L.sum() < 2 or not lead_vars[k] <= block_vars:
                continue                 # no monomial of B is a multiple of L
            check_deadline("reducing the certificate's bases")
            divisible = np.all(B >= L, axis=1) & (B.sum(axis=1) >= 2)
            if not divisible.any():
                continue
            Q = B[divisible] - L
            if np.any(in_B.find(_minkowski(Q, G), missing_ok=True) < 0):      # (i)
                continue
            if k not in r_index:
                r_index[k] = MonomialIndex(_rows(shape.r_supports[k], n=n))
            if np.any(r_index[k].find(_minkowski(Q, B), missing_ok=True) < 0):   # (ii)
                continue
            drop |= divisible
        changed |= bool(drop.any())
        bases.append(B[~drop])
    return replace(shape, u_bases=tuple(bases)) if changed else shape


def reduce_shape(shape: CertificateShape, f_support, eq_supports=(), ineq_supports=(), q_support=None,
                 q_basis=None) -> CertificateShape:
    """:func:`ideal_reduction`, then :func:`diagonal_reduction` (arguments as there)."""
    shape = ideal_reduction(shape, eq_supports)
    return diagonal_reduction(shape, f_support, eq_supports, ineq_supports, q_support, q_basis)
