"""Sizing a certificate before it is assembled: the budget check of every build (:func:`check_size`), with the
aggregate sparsity of its Gram blocks where the dense estimate does not fit (:func:`gram_pattern_sides`).

The memory model of :mod:`sospoly.budget` charges Clarabel ~L^2 floats per PSD block of side s (L = s (s + 1) / 2),
the cost of a block whose pattern is dense.  Clarabel decomposes a PSD cone along the *aggregate sparsity* of its
rows (``chordal_decomposition_enable``, on in every attempt of sospoly's retry chains): an entry of S = b - A x
whose row of A is empty and whose b is 0 is zero in every feasible S, and the cone is replaced by the cones of the
maximal cliques of a chordal extension of the other entries' graph.  In the image form (:class:`~sospoly.lowering.
conic.GramForm` ``IMAGE``, the default) of u = q (f - c) + sum_k r_k g_k - sum_k s_k h_k = b(x)^T G b(x), the entry
(a, b) of a Gram block of u has a non-empty row only when its monomial m = b_a b_b

* is a monomial of the data, D = supp(q) (supp(f) + {1}) + U_k supp(r_k) supp(g_k) + U_k {products of the basis of
  s_k} supp(h_k) (sums of exponent rows), or
* is the monomial of another entry of u's blocks (their coefficient equation then couples them: pair columns);

otherwise its coefficient equation reads G_ab = 0 alone.  The diagonal is always kept.  A degree-2 certificate
with region variables has mostly such zeros: 30 views of mixed regions (a block of side 112) are estimated at
2.1 GiB dense; on their cliques (the image points, and each view's own variables beside its image point) at
0.37 GiB with the margin :data:`PATTERN_MARGIN`, and the process grew by 0.26 GB while Clarabel solved it
(benchmarks/RESULTS.md, wave 18).

The pattern is computed only where the dense estimate does not fit the budget (one ``numpy.unique`` over the
pairs, a minimum-degree elimination), for blocks of at most :data:`PATTERN_MAX_PAIRS` pairs in all;
other forms (``KERNEL``: the Gram matrix is the variable, every entry has a row) keep the dense estimate.
"""
from __future__ import annotations

import numpy as np

from ..algebra.basis import sigma
from ..budget import BudgetExceeded, ProgramSize, estimate_size

__all__ = ["check_size", "gram_pattern_sides", "PATTERN_MAX_PAIRS", "PATTERN_DENSE_FRACTION", "PATTERN_MARGIN",
           "PATTERN_MIN_SIDE", "PATTERN_MAX_SIDE"]

#: the most Gram entry pairs (over all of u's blocks) whose pattern is computed (beyond: the dense estimate)
PATTERN_MAX_PAIRS = 400_000
#: Clarabel's term on the clique blocks is multiplied by this: its peak grew 1.3-1.4x the clique blocks' estimate on
#: the degree-2 programs of 24-30 views of mixed regions (106-263 MB), 2x at 16 views (32 MB: fixed costs)
PATTERN_MARGIN = 2.0
#: u's blocks of a smaller side keep their dense estimate (no chordal extension computed: the view cliques of a
#: sparse certificate, 45-sided at degree 4, are nearly dense and many)
PATTERN_MIN_SIDE = 50
#: ... and blocks of a larger side too (the elimination's Python cost grows ~side^3)
PATTERN_MAX_SIDE = 600
#: a block whose kept entries exceed this fraction of its pairs is taken as dense (its chordal extension would be)
PATTERN_DENSE_FRACTION = 0.5


def check_size(shape, budget, free: bool, n: int, degree: int, deg_f: int, *, slots=None, q=None,
               image_form: bool = False) -> None:
    """:class:`~sospoly.budget.BudgetExceeded` when the program of ``shape`` does not fit ``budget`` (its estimate,
    :meth:`~sospoly.certificates.shape.CertificateShape.size`, checked before anything is assembled).  Where the
    dense estimate does not fit, a fixed-multiplier program lowered in the image form (``image_form``, with its
    data ``slots`` and multiplier ``q``) is estimated again with Clarabel's blocks on its Gram blocks' aggregate
    sparsity (module docstring)."""
    if budget is None:
        return
    q_side = sigma(n, (degree - max(deg_f, 0)) // 2) if free else 0
    size = shape.size(q_side)
    why = size.exceeds(budget)
    if why and image_form and not free and slots is not None:
        blocks = gram_pattern_sides(shape, slots, q)
        if blocks is not None:
            size = _with_clarabel_sides(size, shape, blocks)
            why = size.exceeds(budget)
    if why:
        raise BudgetExceeded(why, size, "use a lower degree, a sparse certificate (sparsity='correlative'), "
                                        "or a larger budget")


def _with_clarabel_sides(size: ProgramSize, shape, blocks) -> ProgramSize:
    """``size`` with Clarabel's term on the blocks ``blocks`` (one tuple of clique sides per Gram block of u, then
    one per multiplier block), the decomposed blocks' cliques charged :data:`PATTERN_MARGIN` times (the columns,
    rows and the interior-point method's term stay those of the dense blocks)."""
    sides = [c for b in blocks for c in b]
    split = [c for b, s0 in zip(blocks, size.gram_sides) if tuple(b) != (s0,) for c in b]
    clar = estimate_size(sides, 1 + shape.n_free()).clarabel_bytes
    if split:
        clar += (PATTERN_MARGIN - 1.0) * estimate_size(split).clarabel_bytes
    return ProgramSize(size.gram_sides, size.n_columns, size.n_rows, min(size.clarabel_bytes, clar), size.ipm_bytes)


def gram_pattern_sides(shape, slots, q=None) -> tuple | None:
    """The PSD blocks Clarabel's chordal decomposition may keep (module docstring), one tuple of sides per Gram block
    (u's, then the multipliers'): for u's blocks the maximal cliques of a chordal extension of its kept entries, the
    multipliers' blocks as they are; None when
    there are more than :data:`PATTERN_MAX_PAIRS` pairs.  ``slots``: the data's
    :class:`~sospoly.certificates.psatz.DataSlots`; ``q``: the fixed multiplier (None: 1)."""
    bases = [np.asarray(B, np.int64) for B in shape.u_bases]
    if sum(B.shape[0] * (B.shape[0] + 1) // 2 for B in bases) > PATTERN_MAX_PAIRS:
        return None
    n = len(slots.gens)
    w = _weights(n)
    pairs, owners = [], []
    for k, B in enumerate(bases):
        i, j = np.triu_indices(B.shape[0])
        kb = _keys(B, w)
        with np.errstate(over="ignore"):
            pairs.append(kb[i] + kb[j])              # the key of b_a b_b (the keys are additive)
        owners.append((k, i, j))
    keys = np.concatenate(pairs) if pairs else np.zeros(0, np.uint64)
    data = np.unique(_data_keys(shape, slots, q, w))
    uniq, ids, counts = np.unique(keys, return_inverse=True, return_counts=True)
    kept_all = np.isin(uniq, data, assume_unique=True)[ids] | (counts[ids] >= 2)
    blocks, at = [], 0
    for (k, i, j), P in zip(owners, pairs):
        kept = kept_all[at:at + P.size] & (i != j)
        at += P.size
        blocks.append(tuple(_clique_sides(bases[k].shape[0], i[kept], j[kept])))
    return tuple(blocks) + tuple((np.asarray(B).shape[0],) for B in shape.s_bases)


def _weights(n: int) -> np.ndarray:
    """The monomial keys' linear form: ``n`` fixed random odd 64-bit words."""
    return np.random.default_rng(_KEY_SEED).integers(1, 2 ** 63, size=n, dtype=np.uint64) | np.uint64(1)


def _keys(rows, w: np.ndarray) -> np.ndarray:
    """One 64-bit key per exponent row: w . row modulo 2^64, additive (the key of a product is the sum of the
    keys).  Equal rows get equal keys; two monomials sharing a key by accident only keep more entries (one taken
    for data, or for shared), so the estimate can only grow."""
    rows = np.asarray(rows, np.int64).reshape(-1, w.size)
    with np.errstate(over="ignore"):
        return (rows.astype(np.uint64) * w[None]).sum(axis=1, dtype=np.uint64)


#: the seed of the keys' linear form (any: collisions are harmless, :func:`_keys`)
_KEY_SEED = 20261204


def _data_keys(shape, slots, q, w: np.ndarray) -> np.ndarray:
    """The keys of D (module docstring), with repetitions."""
    sup = slots.supports
    q_keys = np.zeros(1, np.uint64) if q is None else _keys(list(q.terms.keys()), w)
    parts = [_sums(q_keys, np.append(_keys(sup[0], w), np.uint64(0)))]
    for k, E in enumerate(shape.r_supports):
        parts.append(_sums(_keys(E, w), _keys(sup[1 + k], w)))
    for k, B in enumerate(shape.s_bases):
        kb = _keys(B, w)
        i, j = np.triu_indices(kb.size)
        with np.errstate(over="ignore"):
            parts.append(_sums(kb[i] + kb[j], _keys(sup[1 + slots.n_eq + k], w)))
    return np.concatenate(parts)


def _sums(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Every key of a plus every key of b (the keys of the products)."""
    with np.errstate(over="ignore"):
        return (a[:, None] + b[None, :]).reshape(-1)


def _clique_sides(s: int, i: np.ndarray, j: np.ndarray) -> list:
    """The sides of the maximal cliques of the chordal extension that eliminating a node of least degree first
    gives (the graph on s nodes with edges (i, j); Clarabel orders its decomposition by approximate minimum
    degree); [s] when the graph is nearly complete or small (:data:`PATTERN_MIN_SIDE`) or large
    (:data:`PATTERN_MAX_SIDE`)."""
    if s < PATTERN_MIN_SIDE or s > PATTERN_MAX_SIDE or i.size > PATTERN_DENSE_FRACTION * s * (s - 1) / 2:
        return [s]
    adj = [set() for _ in range(s)]
    for a, b in zip(i.tolist(), j.tolist()):
        adj[a].add(b)
        adj[b].add(a)
    alive, holding, cliques = set(range(s)), [[] for _ in range(s)], []
    while alive:
        v = min(alive, key=lambda u: (len(adj[u]), u))
        clique = frozenset(adj[v]) | {v}
        # {v} + its remaining neighbours is a clique of the extension; maximal unless inside an earlier one
        if not any(clique <= c for c in holding[v]):
            cliques.append(clique)
            for u in clique:
                holding[u].append(clique)
        for a in adj[v]:
            adj[a] |= adj[v]
            adj[a].discard(a)
            adj[a].discard(v)
        alive.discard(v)
    return [len(c) for c in cliques]
