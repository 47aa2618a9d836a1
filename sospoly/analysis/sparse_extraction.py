"""Minimisers from the per-clique moment matrices of a correlatively sparse relaxation.

In the sparse hierarchy (Waki, Kim, Kojima, Muramatsu 2006; Lasserre 2006) clique k
has a moment matrix M_k = L(b_k b_k^T) over a basis b_k in its own variables x_{I_k}.
When the relaxation is exact and the M_k are flat, each M_k is (up to scaling) a
positive combination sum_j w_j b_k(v_j|I_k) b_k(v_j|I_k)^T of the projections of the
global minimisers v_j, so minimisers are found by

1. extracting candidate local points per clique: for rank 1 the first moments
   M_k[x_i, 1] / M_k[1, 1]; for rank r > 1 the Henrion-Lasserre procedure (2005) on the
   sqrt(lambda)-scaled range of M_k (:func:`sospoly.analysis.extraction.range_basis`,
   :func:`sospoly.analysis.extraction.candidates_from_span`);
2. joining them: a global point takes one candidate per clique such that candidates agree
   on every variable two cliques share (|a - b| <= agree_tol * max(1, |b|), b the running
   mean), the shared coordinates being averaged.  The search is depth-first along the
   clique tree (each clique after its parent, so by the running intersection property
   everything it shares with earlier cliques is in its parent), pruning on disagreement,
   with a cap on the number of partial combinations explored;
3. on request, when no combination agrees, joining greedily (:func:`greedy_join`: each clique's candidate
   nearest to the running mean), e.g. for two global minimisers that differ in a few variables and
   nearly, but not within the tolerance, coincide in the others (Broyden tridiagonal, n = 40).

Variables in no clique are set to 0.  The points returned are only *candidates*:
callers check feasibility and the objective themselves (as with
:mod:`sospoly.analysis.extraction`).  Note that when the local ranks differ from the number of
global minimisers (e.g. two minimisers with equal projection on a clique) the join still
works, as one local candidate may serve several global points.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..algebra.basis import MonomialIndex
from .extraction import candidates_from_span, henrion_lasserre, range_basis
from ..certificates.sparsity import clique_tree
from ..tolerances import DEFAULT_TOLERANCES, Tolerances

__all__ = ["clique_candidates", "extract_from_clique_moments", "greedy_join", "join_clique_candidates"]


def _degree1_rows(basis: np.ndarray) -> np.ndarray:
    n = basis.shape[1]
    index = MonomialIndex(basis)
    idx = index.find(np.eye(n, dtype=np.int64), missing_ok=True)
    if basis.shape[0] == 0 or np.any(basis[0] != 0) or np.any(idx < 0):
        raise ValueError("a local basis must start with the constant monomial and contain every degree-1 monomial")
    return idx


#: at most this many global points are joined from the cliques' candidates (:func:`join_clique_candidates`)
MAX_JOINED_POINTS = 256


def _dedupe(points: list[np.ndarray], tol: float) -> list[np.ndarray]:
    """The points in order, each dropped where it lies within ``tol max(1, |q|)`` (entrywise) of an earlier kept q
    (one vectorised comparison per point against those kept)."""
    out: list[np.ndarray] = []
    kept = np.empty((len(points), len(points[0]) if points else 0))
    for p in points:
        K = kept[:len(out)]
        if not np.any(np.all(np.abs(p - K) <= tol * np.maximum(1.0, np.abs(K)), axis=1)):
            kept[len(out)] = p
            out.append(p)
    return out


def clique_candidates(moment: np.ndarray, basis: np.ndarray, tolerances: Tolerances = DEFAULT_TOLERANCES,
                      agree_tol: float = 1e-4) -> list[np.ndarray]:
    """Candidate local points (in the clique's own variables) from one moment matrix.

    Rank 1 (numerical rank by ``tolerances.moment_rank_rel``) or a basis of degree 1: the first
    moments scaled by the constant entry.  Rank > 1: the Henrion-Lasserre points, or -- when the basis is too
    small for them (no flat extension) -- every candidate of
    :func:`sospoly.analysis.extraction.candidates_from_span`.  Non-finite points are dropped and
    near-duplicates merged; an empty list when M[0, 0] <= 0 or M is not finite.
    """
    M = np.asarray(moment, dtype=float)
    B = np.asarray(basis)
    deg1 = _degree1_rows(B)
    if not np.all(np.isfinite(M)) or M[0, 0] <= 0:
        return []
    M = M / M[0, 0]
    W = range_basis((M + M.T) / 2, tolerances)
    if W.shape[1] == 1 or int(B.sum(axis=1).max()) <= 1:
        # rank 1, or a basis of degree 1: the points v with b(v) in a span of dimension r > 1 then form
        # an (r-1)-dimensional affine set, no search can single minimisers out of it; the first
        # moments (the weighted mean of the minimisers) are the one candidate
        points = [M[deg1, 0]]
    else:
        hl = henrion_lasserre(W, B)
        if hl is not None:
            points = list(hl)
        else:
            cands = sorted(candidates_from_span(W, B, "moment"), key=lambda c: c.span_residual)
            points = [c.point for c in cands]
    points = [np.asarray(p, dtype=float) for p in points if np.all(np.isfinite(p))]
    return _dedupe(points, agree_tol)


def _dfs_order(parents: Sequence[int]) -> list[int]:
    m = len(parents)
    children: list[list[int]] = [[] for _ in range(m)]
    for k, p in enumerate(parents):
        if p >= 0:
            children[p].append(k)
    order: list[int] = []
    for r in (k for k in range(m) if parents[k] < 0):
        stack = [r]
        while stack:
            u = stack.pop()
            order.append(u)
            stack.extend(reversed(children[u]))
    return order


def join_clique_candidates(candidates: Sequence[Sequence[np.ndarray]], cliques: Sequence[Sequence[int]], n_vars: int,
                           agree_tol: float = 1e-4, max_combinations: int = 10_000,
                           max_points: int = MAX_JOINED_POINTS) -> list[np.ndarray]:
    """Global points made of one candidate per clique that agree on all shared variables.

    ``candidates[k]`` holds points over the variables ``cliques[k]`` (in that order).  The
    combinations are searched depth-first along :func:`sospoly.certificates.sparsity.clique_tree`,
    pruning as soon as a candidate disagrees with the running mean of a shared variable
    by more than ``agree_tol * max(1, |mean|)``; at most ``max_combinations`` partial
    combinations are explored and ``max_points`` points made (review 43b H1: 2^11 joined points of a star
    Rosenbrock, each deduplicated and polished, took 165 s of a 2 s limit).  Shared coordinates are averaged,
    variables in no clique are 0, near-duplicate results are merged.
    """
    m = len(cliques)
    if len(candidates) != m:
        raise ValueError(f"{len(candidates)} candidate lists for {m} cliques")
    if m == 0 or any(len(c) == 0 for c in candidates):
        return []
    idx = [np.asarray(c, dtype=np.int64) for c in cliques]
    order = _dfs_order(clique_tree(cliques))
    results: list[np.ndarray] = []
    budget = [int(max_combinations)]

    def search(pos: int, sums: np.ndarray, counts: np.ndarray) -> None:
        if pos == m:
            if len(results) >= max_points:
                budget[0] = 0
                return
            results.append(np.where(counts > 0, sums / np.maximum(counts, 1), 0.0))
            return
        k = order[pos]
        vs = idx[k]
        seen = counts[vs] > 0
        mean = sums[vs] / np.maximum(counts[vs], 1)
        for p in candidates[k]:
            if budget[0] <= 0:
                return
            budget[0] -= 1
            if np.any(seen & (np.abs(p - mean) > agree_tol * np.maximum(1.0, np.abs(mean)))):
                continue
            s2, c2 = sums.copy(), counts.copy()
            s2[vs] += p
            c2[vs] += 1
            search(pos + 1, s2, c2)

    search(0, np.zeros(n_vars), np.zeros(n_vars, dtype=np.int64))
    return _dedupe(results, agree_tol)


def greedy_join(candidates: Sequence[Sequence[np.ndarray]], cliques: Sequence[Sequence[int]],
                n_vars: int, agree_tol: float = 1e-4) -> list[np.ndarray]:
    """Global points joined without the agreement test: from each candidate of the first clique (in
    the clique-tree order of :func:`join_clique_candidates`), every later clique contributes its
    candidate nearest (largest relative difference) to the running mean on the shared variables.

    The fallback when no combination agrees within the tolerance, e.g. two global minimisers that
    differ in a few variables and nearly coincide (but not to the tolerance) in the rest, whose
    moment matrices are then numerically of rank one there.  The points are only starting points:
    callers polish them and check feasibility and the objective."""
    m = len(cliques)
    if m == 0 or len(candidates) != m or any(len(c) == 0 for c in candidates):
        return []
    idx = [np.asarray(c, dtype=np.int64) for c in cliques]
    order = _dfs_order(clique_tree(cliques))
    results = []
    for start in candidates[order[0]]:
        sums, counts = np.zeros(n_vars), np.zeros(n_vars, dtype=np.int64)
        sums[idx[order[0]]] += start
        counts[idx[order[0]]] += 1
        for k in order[1:]:
            vs = idx[k]
            seen = counts[vs] > 0
            mean = sums[vs] / np.maximum(counts[vs], 1)

            def miss(p):
                return float(np.max(np.where(seen, np.abs(p - mean) / np.maximum(1.0, np.abs(mean)), 0.0),
                                    initial=0.0))
            p = min(candidates[k], key=miss)
            sums[vs] += p
            counts[vs] += 1
        results.append(np.where(counts > 0, sums / np.maximum(counts, 1), 0.0))
    return _dedupe(results, agree_tol)


def extract_from_clique_moments(moments: Sequence[np.ndarray], bases: Sequence[np.ndarray],
                                cliques: Sequence[Sequence[int]], n_vars: int,
                                tolerances: Tolerances = DEFAULT_TOLERANCES, agree_tol: float = 1e-4,
                                max_combinations: int = 10_000, *, greedy: bool = False) -> list[np.ndarray]:
    """Candidate global minimisers from per-clique moment matrices (possibly an empty list).

    Parameters
    ----------
    moments : sequence of (s_k, s_k) arrays
        ``moments[k]`` is the moment matrix of clique k over the local basis ``bases[k]``.
    bases : sequence of (s_k, |I_k|) int arrays
        Exponent rows over the clique's variables only, in the order of
        :func:`sospoly.algebra.basis.monomials` (constant monomial first, every degree-1 monomial present).
    cliques : sequence of sorted int sequences
        The global variable indices I_k of each clique.
    n_vars : int
        Number of global variables.
    tolerances : Tolerances
        ``moment_rank_rel`` decides the numerical rank of each M_k.
    agree_tol : float
        Relative tolerance for two cliques to agree on a shared variable.
    max_combinations : int
        Cap on the partial combinations explored by the join.
    greedy : bool
        When no combination agrees, return the :func:`greedy_join` points instead of none.

    Returns
    -------
    list of numpy.ndarray
        Points of length ``n_vars`` (each consistent across cliques, or with ``greedy`` the
        :func:`greedy_join` points when none is); callers check feasibility and objective values.

    Raises
    ------
    ValueError
        On inconsistent lengths or shapes, bad clique indices or a basis without 1 and x_i.
    """
    if int(n_vars) != n_vars or n_vars < 0:
        raise ValueError(f"n_vars must be a non-negative integer, got {n_vars!r}")
    n_vars = int(n_vars)
    if not len(moments) == len(bases) == len(cliques):
        raise ValueError(f"{len(moments)} moment matrices, {len(bases)} bases and {len(cliques)} cliques")
    cands = []
    for k, (M, B, C) in enumerate(zip(moments, bases, cliques)):
        C = [int(v) for v in C]
        if not C or C != sorted(set(C)) or C[0] < 0 or C[-1] >= n_vars:
            raise ValueError(f"clique {k} must be a non-empty sorted list of distinct indices in [0, {n_vars})")
        B = np.asarray(B)
        if B.ndim != 2 or B.shape[1] != len(C):
            raise ValueError(f"basis {k} must have shape (s, {len(C)}), got {B.shape}")
        if not np.issubdtype(B.dtype, np.integer) or (B.size and B.min() < 0):
            raise ValueError(f"basis {k} must hold non-negative integer exponents")
        M = np.asarray(M, dtype=float)
        if M.shape != (B.shape[0], B.shape[0]):
            raise ValueError(f"moment matrix {k} has shape {M.shape}, expected {(B.shape[0], B.shape[0])}")
        cands.append(clique_candidates(M, B.astype(np.int64), tolerances, agree_tol))
    joined = join_clique_candidates(cands, cliques, n_vars, agree_tol, max_combinations)
    return joined if joined or not greedy else greedy_join(cands, cliques, n_vars, agree_tol)
