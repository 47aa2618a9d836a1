"""Sparsity structure of sum-of-squares relaxations, as pure data (no SDP is solved here).

Three reductions, as in TSSOS (Wang, Magron, Lasserre 2021) and SumOfSquares.jl:

**Correlative sparsity** (Waki, Kim, Kojima, Muramatsu 2006; Lasserre 2006).  The
correlative sparsity pattern (csp) graph has a node per variable and an edge (i, j)
when x_i and x_j occur together in one term of the objective, or anywhere in one
constraint.  A chordal extension of it has maximal cliques I_1, ..., I_p; ordered along a
clique tree they satisfy the *running intersection property* (RIP)

    for every k > 1:  I_k ∩ (I_1 ∪ ... ∪ I_{k-1}) ⊆ I_j  for some j < k,

equivalently: for every variable the cliques containing it form a connected subtree.
Under RIP (plus an Archimedean condition per clique) the sparse hierarchy, with one
moment/Gram matrix per clique in the clique's variables only and each constraint
attached to a clique holding all its variables, converges (Lasserre 2006).

**Newton polytope** (Reznick 1978, "Extremal PSD forms with few terms", Thm. 1).  If
f = sum_i q_i^2 then every monomial m of every q_i satisfies 2m ∈ N(f) := conv(supp f),
so the Gram basis of an SOS decomposition of f can be cut to those m.  This is valid
for the SOS certificate of an *unconstrained* problem f - c = sigma_0 only: with
constraints f - c = sigma_0 + sum_k s_k g_k cancellations between the terms make
supp(sigma_0) unrelated to supp f.

**Term sparsity** (TSSOS, Wang, Magron, Lasserre 2021).  With support A = supp f ∪ 2B
(B the basis rows), the term sparsity pattern graph on B has an edge (a, b) when
b_a + b_b ∈ A.  A chordal extension's maximal cliques give the blocks of a block-diagonal
Gram matrix.  Iterating with A := A ∪ {b_a + b_b : (a, b) an edge of the previous chordal
graph} gives a monotone sequence of graphs that stabilises (the "sign-symmetry" blocks
when the extension is maximal).

Exponent arrays are numpy int64 arrays of shape (t, n), one monomial per row.
"""
from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from itertools import combinations

import importlib

import numpy as np

from ..algebra.basis import MonomialIndex
from ..budget import check_deadline

__all__ = [
    "HEURISTICS", "CorrelativeSparsity", "TermSparsity", "assign_constraints", "chordal_extension", "clique_tree",
    "correlative_sparsity", "csp_graph", "has_running_intersection", "in_newton_polytope", "maximal_cliques_chordal",
    "newton_reduce", "term_sparsity_blocks", "term_sparsity_graph", "term_sparsity_iterate", "variables_of",
    "TERM_COMPLETIONS",
]


class _OnFirstUse:
    """A module imported when one of its attributes is first read (networkx costs ~0.2 s to import; a program
    without sparsity never builds a graph, and importing sospoly need not pay for it)."""

    def __init__(self, name: str):
        self._name = name

    def __getattr__(self, attr: str):
        if attr.startswith("__") or attr == "_name":     # copy / pickle probe the instance before __init__
            raise AttributeError(attr)
        return getattr(importlib.import_module(self._name), attr)


nx = _OnFirstUse("networkx")

#: the chordal-extension heuristics understood by :func:`chordal_extension`.
HEURISTICS = ("min_degree", "min_fill", "mcs_m", "maximal")


# --------------------------------------------------------------------------- input checks
def _exponents(arr, name: str, n: int | None = None) -> np.ndarray:
    """``arr`` as a (t, n) int64 array of non-negative integers (ValueError otherwise)."""
    a = np.asarray(arr)
    if a.ndim != 2:
        raise ValueError(f"{name} must be a 2-D exponent array (t x n), got shape {a.shape}")
    if n is not None and a.shape[1] != n:
        raise ValueError(f"{name} has {a.shape[1]} columns, expected {n} (one per variable)")
    if a.size and not np.issubdtype(a.dtype, np.integer) and (not np.all(np.isfinite(a)) or np.any(a != np.round(a))):
        raise ValueError(f"{name} must hold integer exponents")
    a = a.astype(np.int64)
    if a.size and a.min() < 0:
        raise ValueError(f"{name} has a negative exponent")
    return a


def variables_of(support) -> frozenset[int]:
    """The variables (column indices) with a non-zero exponent in some row of ``support``."""
    a = _exponents(support, "support")
    return frozenset(int(k) for k in np.nonzero((a > 0).any(axis=0))[0])


def _check_heuristic(heuristic: str) -> None:
    if heuristic not in HEURISTICS:
        raise ValueError(f"unknown chordal-extension heuristic {heuristic!r}; expected one of {HEURISTICS}")


# --------------------------------------------------------------------------- graphs
def csp_graph(n_vars: int, objective_support, constraint_supports: Iterable = ()) -> nx.Graph:
    """The correlative sparsity pattern graph on the nodes 0..n_vars-1 (isolated ones included).

    Edge (i, j) when x_i, x_j both have a positive exponent in one row (term) of
    ``objective_support``, or both occur anywhere in one of ``constraint_supports``
    (equalities and inequalities alike, each a (t_k x n_vars) exponent array).
    """
    if int(n_vars) != n_vars or n_vars < 0:
        raise ValueError(f"n_vars must be a non-negative integer, got {n_vars!r}")
    n_vars = int(n_vars)
    obj = _exponents(objective_support, "objective_support", n_vars)
    groups = {tuple(np.nonzero(row)[0].tolist()) for row in (obj > 0)}
    for k, sup in enumerate(constraint_supports):
        groups.add(tuple(sorted(variables_of(_exponents(sup, f"constraint support {k}", n_vars)))))
    G = nx.Graph()
    G.add_nodes_from(range(n_vars))
    G.add_edges_from(e for g in sorted(groups) for e in combinations(g, 2))
    return G


def _node_order(G: nx.Graph) -> list:
    try:
        return sorted(G.nodes)
    except TypeError:
        return list(G.nodes)


def chordal_extension(G: nx.Graph, heuristic: str = "min_degree") -> nx.Graph:
    """A chordal supergraph of ``G`` on the same nodes (a new graph; ``G`` is not changed).

    A chordal input is returned as an (unchanged) copy.  Otherwise the graph is
    triangulated by the elimination game: repeatedly pick the remaining vertex of least
    ``"min_degree"`` (remaining degree) or ``"min_fill"`` (number of missing edges among its
    remaining neighbours), ties broken by node order, join its remaining neighbours into a
    clique and remove it.  ``"mcs_m"`` uses networkx's minimal triangulation
    (``complete_to_chordal_graph``); ``"maximal"`` completes every connected component
    (the coarsest extension, TSSOS's "MAX").  The result is deterministic.
    """
    _check_heuristic(heuristic)
    if nx.number_of_selfloops(G):
        raise ValueError("the graph has self-loops")
    order = _node_order(G)
    rank = {v: i for i, v in enumerate(order)}
    H = nx.Graph()
    H.add_nodes_from(order)
    H.add_edges_from(G.edges)
    if heuristic == "maximal":
        comps = (sorted(c, key=rank.__getitem__) for c in nx.connected_components(G))
        for comp in sorted(comps, key=lambda c: rank[c[0]]):
            H.add_edges_from(combinations(comp, 2))
        return H
    if nx.is_chordal(H):
        return H
    if heuristic == "mcs_m":
        chordal, _ = nx.complete_to_chordal_graph(H)
        H.add_edges_from(chordal.edges)
        return H
    adj = {v: set(H.adj[v]) for v in order}

    def score(v):
        nb = adj[v]
        if heuristic == "min_degree":
            return (len(nb), rank[v])
        missing = sum(1 for a, b in combinations(nb, 2) if b not in adj[a])
        return (missing, rank[v])

    scores = {v: score(v) for v in order}
    while scores:
        v = min(scores, key=scores.__getitem__)
        nb = sorted(adj[v], key=rank.__getitem__)
        for a, b in combinations(nb, 2):
            if b not in adj[a]:
                adj[a].add(b)
                adj[b].add(a)
                H.add_edge(a, b)
        for a in nb:
            adj[a].discard(v)
        del scores[v], adj[v]
        affected = set(nb)
        if heuristic == "min_fill":
            for a in nb:
                affected |= adj[a]
        for a in affected:
            scores[a] = score(a)
    return H


def maximal_cliques_chordal(G: nx.Graph) -> tuple[tuple[int, ...], ...]:
    """The maximal cliques of the chordal graph ``G`` (isolated nodes are cliques of size 1).

    Each clique is sorted and the cliques are sorted lexicographically.  ValueError when
    ``G`` is not chordal.
    """
    n = G.number_of_nodes()
    if n == 0:
        return ()
    if not nx.number_of_selfloops(G) and G.number_of_edges() == n * (n - 1) // 2:
        return (tuple(sorted(G.nodes)),)       # complete: one clique (networkx's tests are slow on dense graphs)
    if nx.number_of_selfloops(G) or not nx.is_chordal(G):
        raise ValueError("maximal_cliques_chordal needs a chordal graph without self-loops")
    return tuple(sorted(tuple(sorted(c)) for c in nx.chordal_graph_cliques(G)))


# --------------------------------------------------------------------------- clique trees
def clique_tree(cliques: Sequence[Sequence[int]]) -> tuple[int, ...]:
    """Parent index of each clique in a clique tree (-1 for a root; a forest when disconnected).

    The tree is a maximum-weight spanning forest of the clique intersection graph (weight
    |I_j ∩ I_k|, only pairs that intersect), found by Kruskal's algorithm with ties broken
    by index.  For the maximal cliques of a chordal graph every such forest satisfies the
    running intersection property (Gavril 1974; Blair & Peyton 1993, Thm. 4.6).  Each
    component is rooted at its smallest clique index.
    """
    sets = [frozenset(int(v) for v in c) for c in cliques]
    m = len(sets)
    edges = sorted((-len(sets[i] & sets[j]), i, j) for i in range(m) for j in range(i + 1, m) if sets[i] & sets[j])
    root = list(range(m))

    def find(x):
        while root[x] != x:
            root[x] = root[root[x]]
            x = root[x]
        return x

    nbrs: list[list[int]] = [[] for _ in range(m)]
    for _, i, j in edges:
        ri, rj = find(i), find(j)
        if ri != rj:
            root[max(ri, rj)] = min(ri, rj)
            nbrs[i].append(j)
            nbrs[j].append(i)
    parents = [-2] * m
    for r in range(m):
        if parents[r] != -2:
            continue
        parents[r] = -1
        stack = [r]
        while stack:
            u = stack.pop()
            for w in sorted(nbrs[u]):
                if parents[w] == -2:
                    parents[w] = u
                    stack.append(w)
    return tuple(parents)


def _check_forest(parents: Sequence[int], m: int) -> list[list[int]]:
    """Children lists of a parent array; ValueError unless it is a forest on 0..m-1."""
    if len(parents) != m:
        raise ValueError(f"{len(parents)} parents for {m} cliques")
    children: list[list[int]] = [[] for _ in range(m)]
    for k, p in enumerate(parents):
        if int(p) != p or not -1 <= p < m or p == k:
            raise ValueError(f"bad parent {p!r} of clique {k}")
        if p >= 0:
            children[int(p)].append(k)
    seen, stack = set(), [k for k in range(m) if parents[k] == -1]
    while stack:
        u = stack.pop()
        seen.add(u)
        stack.extend(children[u])
    if len(seen) != m:
        raise ValueError("the parent array has a cycle (not a forest)")
    return children


def has_running_intersection(cliques: Sequence[Sequence[int]], parents: Sequence[int]) -> bool:
    """Brute-force RIP check: for every variable, the cliques containing it induce a connected
    subtree of the forest given by ``parents`` (ValueError when ``parents`` is not a forest)."""
    sets = [frozenset(int(v) for v in c) for c in cliques]
    children = _check_forest(parents, len(sets))
    for v in sorted(set().union(*sets)) if sets else ():
        holding = {k for k, s in enumerate(sets) if v in s}
        start = min(holding)
        seen, stack = {start}, [start]
        while stack:
            u = stack.pop()
            for w in children[u] + ([parents[u]] if parents[u] >= 0 else []):
                if w in holding and w not in seen:
                    seen.add(w)
                    stack.append(w)
        if seen != holding:
            return False
    return True


def assign_constraints(cliques: Sequence[Sequence[int]], constraint_variable_sets: Iterable) -> tuple[int, ...]:
    """For each constraint, the index of the smallest clique (then the first) holding all its variables.

    A constraint without variables goes to clique 0.  ValueError naming the constraint when
    no clique holds its variables (impossible for cliques of a chordal extension of the csp graph).
    """
    sets = [frozenset(int(v) for v in c) for c in cliques]
    out = []
    for k, vs in enumerate(constraint_variable_sets):
        vs = frozenset(int(v) for v in vs)
        if not sets:
            raise ValueError(f"constraint {k} cannot be assigned: there are no cliques")
        if not vs:
            out.append(0)
            continue
        fits = [(len(s), j) for j, s in enumerate(sets) if vs <= s]
        if not fits:
            raise ValueError(f"constraint {k} (variables {sorted(vs)}) is contained in no clique")
        out.append(min(fits)[1])
    return tuple(out)


@dataclass(frozen=True)
class CorrelativeSparsity:
    """Correlative sparsity of a polynomial optimisation problem.

    Attributes
    ----------
    cliques : tuple of tuple of int
        Maximal cliques of the chordal extension of the csp graph, each sorted.
    parents : tuple of int
        Clique-tree parent per clique (-1 for roots), with the running intersection property.
    eq_assignment, ineq_assignment : tuple of int
        The clique of each equality / inequality constraint (it holds all its variables).
    graph : networkx.Graph
        The chordal extension of the csp graph (nodes 0..n_vars-1).
    """

    cliques: tuple[tuple[int, ...], ...]
    parents: tuple[int, ...]
    eq_assignment: tuple[int, ...]
    ineq_assignment: tuple[int, ...]
    graph: nx.Graph = field(repr=False, compare=False)

    @property
    def n_vars(self) -> int:
        """Number of variables (nodes of the graph)."""
        return self.graph.number_of_nodes()

    @property
    def is_dense(self) -> bool:
        """True when a single clique holds every variable (no correlative sparsity)."""
        return len(self.cliques) == 1 and len(self.cliques[0]) == self.n_vars


def correlative_sparsity(n_vars: int, objective_support, eq_supports: Sequence = (), ineq_supports: Sequence = (),
                         heuristic: str = "min_degree") -> CorrelativeSparsity:
    """csp graph -> chordal extension -> maximal cliques -> clique tree -> constraint assignment."""
    eq = [_exponents(s, f"equality support {k}", n_vars) for k, s in enumerate(eq_supports)]
    ineq = [_exponents(s, f"inequality support {k}", n_vars) for k, s in enumerate(ineq_supports)]
    G = csp_graph(n_vars, objective_support, eq + ineq)
    H = chordal_extension(G, heuristic)
    cliques = maximal_cliques_chordal(H)
    parents = clique_tree(cliques)
    assigned = assign_constraints(cliques, [variables_of(s) for s in eq + ineq])
    return CorrelativeSparsity(cliques, parents, assigned[:len(eq)], assigned[len(eq):], H)


# --------------------------------------------------------------------------- Newton polytope
def in_newton_polytope(support, points) -> np.ndarray:
    """Boolean mask: is each row of ``points`` in conv(rows of ``support``)?

    Decided by the feasibility LP  lambda >= 0, sum lambda = 1, support^T lambda = p
    (HiGHS).  The data are small integers, so the LP answer is exact in practice; a
    "feasible" answer is additionally checked by its residual.  Points outside the
    bounding box of the support, or equal to a support row, are decided without an LP.
    """
    S = _exponents(support, "support")
    P = _exponents(points, "points", S.shape[1])
    out = np.zeros(P.shape[0], dtype=bool)
    if S.shape[0] == 0 or P.shape[0] == 0:
        return out
    S = np.unique(S, axis=0)
    index = MonomialIndex(S)
    lo, hi = S.min(axis=0), S.max(axis=0)
    A_eq = np.vstack([S.T.astype(float), np.ones((1, S.shape[0]))])
    hit = index.find(P, missing_ok=True) >= 0
    for k, p in enumerate(P):
        if hit[k]:
            out[k] = True
            continue
        if np.any(p < lo) or np.any(p > hi):
            continue
        b_eq = np.append(p.astype(float), 1.0)
        from scipy.optimize import linprog            # (on first use: scipy.optimize costs ~0.3 s to import)

        res = linprog(np.zeros(S.shape[0]), A_eq=A_eq, b_eq=b_eq, bounds=(0, None), method="highs")
        if res.status == 0:
            out[k] = bool(np.max(np.abs(A_eq @ res.x - b_eq)) <= 1e-7 * max(1.0, float(np.abs(b_eq).max())))
        elif res.status != 2:  # 2 = infeasible; anything else is a solver failure
            raise RuntimeError(f"Newton-polytope LP failed for {tuple(int(e) for e in p)}: {res.message}")
    return out


def newton_reduce(support, basis) -> np.ndarray:
    """The rows m of ``basis`` with 2m in the Newton polytope conv(supp f), in input order.

    ``support`` is the (t x n) support of f, ``basis`` an (s x n) candidate Gram basis.
    By Reznick (1978) the monomials of any SOS decomposition f = sum q_i^2 lie in
    (1/2) N(f), so the dropped rows carry zero Gram entries in every decomposition.  Only
    valid for the SOS multiplier of an *unconstrained* problem (see the module docstring).
    """
    S = _exponents(support, "support")
    B = _exponents(basis, "basis", S.shape[1])
    return B[in_newton_polytope(S, 2 * B)]


# --------------------------------------------------------------------------- term sparsity
def _pair_sums_in(B: np.ndarray, index: MonomialIndex) -> list[tuple[int, int]]:
    s = B.shape[0]
    ii, jj = np.triu_indices(s, k=1)
    if ii.size == 0:
        return []
    hit = index.find(B[ii] + B[jj], missing_ok=True) >= 0
    return list(zip(ii[hit].tolist(), jj[hit].tolist()))


def term_sparsity_graph(support, basis) -> nx.Graph:
    """Term sparsity pattern graph on the basis rows 0..s-1: edge (a, b), a != b, when
    basis[a] + basis[b] lies in supp ∪ {2 basis[c]}."""
    S = _exponents(support, "support")
    B = _exponents(basis, "basis", S.shape[1])
    if B.shape[0] and np.unique(B, axis=0).shape[0] != B.shape[0]:
        raise ValueError("duplicate rows in the basis")
    A = np.unique(np.vstack([S, 2 * B]), axis=0)
    G = nx.Graph()
    G.add_nodes_from(range(B.shape[0]))
    G.add_edges_from(_pair_sums_in(B, MonomialIndex(A)))
    return G


def _edge_set(H: nx.Graph) -> set[tuple[int, int]]:
    return {(min(a, b), max(a, b)) for a, b in H.edges}


def _blocks(H: nx.Graph) -> tuple[np.ndarray, ...]:
    return tuple(np.array(c, dtype=np.int64) for c in maximal_cliques_chordal(H))


def term_sparsity_blocks(support, basis, heuristic: str = "min_degree") -> tuple[np.ndarray, ...]:
    """One TSSOS term-sparsity step: the sorted basis-row indices of each Gram block.

    The blocks are the maximal cliques of the chordal extension of
    :func:`term_sparsity_graph` (isolated rows are blocks of size 1), sorted lexicographically.
    """
    return _blocks(chordal_extension(term_sparsity_graph(support, basis), heuristic))


@dataclass(frozen=True)
class TermSparsity:
    """Result of :func:`term_sparsity_iterate`.

    Attributes
    ----------
    blocks : tuple of numpy.ndarray
        Sorted basis-row indices of each block (maximal cliques of ``graph``).
    graph : networkx.Graph
        The last chordal graph on the basis rows.
    support : numpy.ndarray
        The last support used, supp ∪ 2B ∪ {sums along earlier chordal edges}, sorted rows.
    iterations : int
        Number of term-sparsity steps carried out (>= 1).
    stable : bool
        True when the last step reproduced the previous chordal graph.
    """

    blocks: tuple[np.ndarray, ...]
    graph: nx.Graph = field(repr=False, compare=False)
    support: np.ndarray = field(repr=False, compare=False)
    iterations: int = 1
    stable: bool = False


#: how a term-sparsity graph is completed: ``"chordal"`` (an approximately minimal chordal extension, TSSOS
#: "MD"; SumOfSquares.jl's ``ChordalCompletion``) or ``"block"`` (every connected component made complete,
#: TSSOS "block"; SumOfSquares.jl's ``ClusterCompletion``).
TERM_COMPLETIONS = ("chordal", "block")


def _complete(G: nx.Graph, completion: str, heuristic: str) -> nx.Graph:
    if completion == "chordal":
        return chordal_extension(G, heuristic)
    if completion != "block":
        raise ValueError(f"completion must be one of {TERM_COMPLETIONS}, got {completion!r}")
    H = nx.Graph()
    H.add_nodes_from(G.nodes)
    for comp in nx.connected_components(G):
        comp = sorted(comp)
        H.add_edges_from((a, b) for k, a in enumerate(comp) for b in comp[k + 1:])
    return H


def term_sparsity_iterate(support, basis, steps: int, heuristic: str = "min_degree",
                          completion: str = "chordal") -> TermSparsity:
    """Iterate the term-sparsity step at most ``steps`` times, support := support ∪
    {basis[a] + basis[b] : (a, b) an edge of the previous completed graph}, stopping early once
    the completed graph no longer changes.  The completed graphs grow monotonically, so the
    iteration always stabilises after at most s(s-1)/2 steps (the TSSOS hierarchy, Wang, Magron &
    Lasserre 2021).  ``completion`` (:data:`TERM_COMPLETIONS`): ``"chordal"`` or ``"block"``; with
    ``"block"`` the stable level of an unconstrained problem gives the dense bound (its blocks are
    those of the sign symmetries, TSSOS Theorem 3.3)."""
    if int(steps) != steps or steps < 1:
        raise ValueError(f"steps must be a positive integer, got {steps!r}")
    S = _exponents(support, "support")
    B = _exponents(basis, "basis", S.shape[1])
    A = np.unique(np.vstack([S, 2 * B]), axis=0)
    H = _complete(term_sparsity_graph(A, B), completion, heuristic)
    done, stable = 1, False
    while done < steps:
        check_deadline("completing the term-sparsity graph")
        edges = np.array(sorted(H.edges), dtype=np.int64).reshape(-1, 2)
        A = np.unique(np.vstack([A, B[edges[:, 0]] + B[edges[:, 1]]]), axis=0)
        H_next = _complete(term_sparsity_graph(A, B), completion, heuristic)
        done += 1
        stable = _edge_set(H_next) == _edge_set(H)
        H = H_next
        if stable:
            break
    return TermSparsity(_blocks(H), H, A, done, stable)
