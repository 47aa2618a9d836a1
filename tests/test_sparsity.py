"""Sparsity layer (sospoly.certificates.sparsity) and sparse minimiser extraction (sospoly.analysis.sparse_extraction),
checked against independent references (networkx clique enumeration, scipy convex hulls,
hand-derived blocks, exact moment matrices of known points)."""
from __future__ import annotations

import itertools

import networkx as nx
import numpy as np
import pytest
from scipy.spatial import ConvexHull

from sospoly.algebra.basis import MonomialIndex, monomials
from sospoly.analysis.sparse_extraction import (
    extract_from_clique_moments,
    join_clique_candidates,
)
from sospoly.certificates.sparsity import (
    HEURISTICS,
    assign_constraints,
    chordal_extension,
    clique_tree,
    correlative_sparsity,
    csp_graph,
    has_running_intersection,
    in_newton_polytope,
    maximal_cliques_chordal,
    newton_reduce,
    term_sparsity_blocks,
    term_sparsity_graph,
    term_sparsity_iterate,
    variables_of,
)


# --------------------------------------------------------------------------- helpers
def _check_decomposition(G: nx.Graph, heuristic: str):
    H = chordal_extension(G, heuristic)
    assert nx.is_chordal(H)
    assert set(H.nodes) == set(G.nodes)
    assert all(H.has_edge(u, v) for u, v in G.edges)
    cliques = maximal_cliques_chordal(H)
    assert all(list(c) == sorted(c) for c in cliques)
    assert list(cliques) == sorted(cliques)
    assert {frozenset(c) for c in cliques} == {frozenset(c) for c in nx.find_cliques(H)}
    assert len(set(cliques)) == len(cliques)
    for u, v in H.edges:
        assert any(u in c and v in c for c in cliques)
    parents = clique_tree(cliques)
    assert has_running_intersection(cliques, parents)
    # maximum weight: same total intersection weight as networkx's maximum spanning forest
    W = nx.Graph()
    W.add_nodes_from(range(len(cliques)))
    for i, j in itertools.combinations(range(len(cliques)), 2):
        w = len(set(cliques[i]) & set(cliques[j]))
        if w:
            W.add_edge(i, j, weight=w)
    ref = nx.maximum_spanning_tree(W).size(weight="weight")
    ours = sum(len(set(cliques[k]) & set(cliques[p])) for k, p in enumerate(parents) if p >= 0)
    assert ours == ref
    # one root per connected component of the graph
    assert sum(p == -1 for p in parents) == nx.number_connected_components(G)
    return H, cliques, parents


def _rosenbrock_support(n: int) -> np.ndarray:
    """sum_i 100 (x_{i+1} - x_i^2)^2 + (1 - x_i)^2: terms x_{i+1}^2, x_{i+1} x_i^2, x_i^4, x_i^2, x_i, 1."""
    rows = [np.zeros(n, dtype=np.int64)]
    for i in range(n - 1):
        for e in ({i + 1: 2}, {i + 1: 1, i: 2}, {i: 4}, {i: 2}, {i: 1}):
            r = np.zeros(n, dtype=np.int64)
            for k, v in e.items():
                r[k] = v
            rows.append(r)
    return np.unique(np.array(rows), axis=0)


# --------------------------------------------------------------------------- graphs and cliques
@pytest.mark.parametrize("heuristic", HEURISTICS)
def test_random_graphs(heuristic):
    for seed in range(8):
        n = 6 + 2 * seed
        G = nx.gnp_random_graph(n, 0.3, seed=seed)
        H, _, _ = _check_decomposition(G, heuristic)
        assert chordal_extension(G, heuristic).edges == H.edges  # deterministic


def test_chordal_graph_gets_no_fill():
    G = nx.Graph([(0, 1), (1, 2), (0, 2), (2, 3), (3, 4), (2, 4), (4, 5)])
    for h in ("min_degree", "min_fill", "mcs_m"):
        assert {frozenset(e) for e in chordal_extension(G, h).edges} == {frozenset(e) for e in G.edges}


def test_cycle_needs_fill():
    G = nx.cycle_graph(6)
    for h in ("min_degree", "min_fill", "mcs_m"):
        H = chordal_extension(G, h)
        assert H.number_of_edges() == 6 + 3  # a minimal triangulation of C6 has n - 3 chords
        assert all(len(c) == 3 for c in maximal_cliques_chordal(H))


def test_rosenbrock_chain():
    n = 7
    cs = correlative_sparsity(n, _rosenbrock_support(n))
    assert cs.cliques == tuple((i, i + 1) for i in range(n - 1))
    assert cs.parents == (-1, 0, 1, 2, 3, 4)
    assert has_running_intersection(cs.cliques, cs.parents)
    assert not cs.is_dense
    _check_decomposition(csp_graph(n, _rosenbrock_support(n)), "min_fill")


def test_star_disconnected_complete():
    star = nx.star_graph(5)  # centre 0
    _, cliques, parents = _check_decomposition(star, "min_degree")
    assert cliques == tuple((0, i) for i in range(1, 6))
    assert sum(p == -1 for p in parents) == 1

    G = nx.Graph([(0, 1), (1, 2), (3, 4)])
    G.add_node(5)
    _, cliques, parents = _check_decomposition(G, "min_degree")
    assert cliques == ((0, 1), (1, 2), (3, 4), (5,))
    assert parents == (-1, 0, -1, -1)

    K = nx.complete_graph(5)
    _, cliques, parents = _check_decomposition(K, "min_degree")
    assert cliques == ((0, 1, 2, 3, 4),) and parents == (-1,)
    supp = np.array([[1, 1, 1, 1, 1], [0, 0, 0, 0, 0]])
    assert correlative_sparsity(5, supp).is_dense


def test_rip_checker_rejects_bad_tree():
    cliques = ((0, 1), (1, 2), (2, 3))
    assert has_running_intersection(cliques, (-1, 0, 1))
    assert not has_running_intersection(cliques, (-1, 0, 0))  # x2 in cliques 1, 2: not adjacent
    with pytest.raises(ValueError):
        has_running_intersection(cliques, (1, 2, 0))  # a cycle
    with pytest.raises(ValueError):
        has_running_intersection(cliques, (-1, 0))


def test_csp_graph_hand_example():
    obj = np.array([[1, 1, 0, 0, 0],   # x0 x1
                    [0, 0, 2, 0, 0],   # x2^2
                    [1, 0, 0, 0, 0],   # x0 (no new edge)
                    [0, 0, 0, 1, 0]])  # x3 alone
    ineq = np.array([[0, 0, 1, 0, 0], [0, 0, 0, 0, 3]])  # x2 + x4^3: x2, x4 in one constraint
    eq = np.array([[0, 1, 0, 0, 0], [1, 0, 0, 0, 0], [0, 0, 0, 0, 0]])  # x1 - x0 + c
    G = csp_graph(5, obj, [ineq, eq])
    assert sorted(G.nodes) == [0, 1, 2, 3, 4]
    assert {frozenset(e) for e in G.edges} == {frozenset((0, 1)), frozenset((2, 4))}
    # x0 x1 occur in separate terms of the objective only -> no edge
    assert csp_graph(2, np.array([[1, 0], [0, 1]])).number_of_edges() == 0
    cs = correlative_sparsity(5, obj, eq_supports=[eq], ineq_supports=[ineq, np.array([[0, 0, 0, 2, 0]])])
    assert cs.cliques == ((0, 1), (2, 4), (3,))
    assert cs.eq_assignment == (0,) and cs.ineq_assignment == (1, 2)
    assert variables_of(ineq) == frozenset({2, 4})


def test_assign_constraints():
    cliques = ((0, 1, 2), (1, 2), (2, 3))
    assert assign_constraints(cliques, [{1}, {2, 3}, set(), {0, 2}, {2}]) == (1, 2, 0, 0, 1)
    with pytest.raises(ValueError, match="constraint 1"):
        assign_constraints(cliques, [{1}, {0, 3}])


def test_bad_input():
    with pytest.raises(ValueError):
        csp_graph(3, np.array([[1, 0]]))
    with pytest.raises(ValueError):
        csp_graph(2, np.array([[1, -1]]))
    with pytest.raises(ValueError):
        csp_graph(2, np.array([1, 0]))
    with pytest.raises(ValueError):
        newton_reduce(np.array([[2, 0]]), np.array([[1, 0, 0]]))
    with pytest.raises(ValueError):
        newton_reduce(np.array([[2.5, 0]]), np.array([[1, 0]]))
    with pytest.raises(ValueError):
        chordal_extension(nx.path_graph(3), "nope")
    with pytest.raises(ValueError):
        maximal_cliques_chordal(nx.cycle_graph(4))
    with pytest.raises(ValueError):
        term_sparsity_iterate(np.array([[0]]), np.array([[0]]), 0)


# --------------------------------------------------------------------------- Newton polytope
def test_newton_motzkin():
    motzkin = np.array([[4, 2], [2, 4], [2, 2], [0, 0]])
    kept = newton_reduce(motzkin, monomials(2, 3))
    assert [tuple(r) for r in kept] == [(0, 0), (1, 1), (2, 1), (1, 2)]  # 1, xy, x^2y, xy^2 in basis order
    assert kept.dtype == np.int64


def test_newton_univariate():
    # x^2 + x^6: N = [2, 6], so 2m in [2, 6] keeps x, x^2, x^3 and drops 1 and x^4
    kept = newton_reduce(np.array([[2], [6]]), monomials(1, 4))
    assert kept[:, 0].tolist() == [1, 2, 3]
    kept = newton_reduce(np.array([[0], [4]]), monomials(1, 3))  # 1 + x^4
    assert kept[:, 0].tolist() == [0, 1, 2]
    assert newton_reduce(np.zeros((0, 1), dtype=np.int64), monomials(1, 2)).shape == (0, 1)


@pytest.mark.parametrize("n", [2, 3])
def test_newton_random_against_hull(n):
    rng = np.random.default_rng(n)
    for _ in range(4):
        support = rng.integers(0, 7, size=(9, n))
        assert np.linalg.matrix_rank(support[1:] - support[0]) == n  # full-dimensional (seeded)
        hull = ConvexHull(support.astype(float))
        basis = monomials(n, 3)
        pts = 2 * basis
        ref = np.all(pts @ hull.equations[:, :-1].T + hull.equations[:, -1] <= 1e-9, axis=1)
        assert np.array_equal(in_newton_polytope(support, pts), ref)
        assert np.array_equal(newton_reduce(support, basis), basis[ref])


def test_newton_degenerate_support_by_enumeration():
    # a support on a line (hull is a segment; ConvexHull cannot be used): 2m in conv iff on the segment
    support = np.array([[0, 0, 0], [2, 2, 0], [6, 6, 0]])
    basis = monomials(3, 3)
    ref = [(a == b and c == 0 and 0 <= 2 * a <= 6) for a, b, c in basis]
    assert np.array_equal(in_newton_polytope(support, 2 * basis), np.array(ref))


# --------------------------------------------------------------------------- term sparsity
def _covered(support, basis, blocks):
    idx = MonomialIndex(np.unique(np.vstack([basis[a] + basis[b] for blk in blocks for a in blk for b in blk]),
                                  axis=0))
    sums = np.unique((basis[:, None, :] + basis[None, :, :]).reshape(-1, basis.shape[1]), axis=0)
    reachable = MonomialIndex(sums).find(support, missing_ok=True) >= 0
    return bool(np.all(idx.find(support[reachable], missing_ok=True) >= 0))


def test_term_sparsity_hand_example():
    # f = 1 + x^4 + y^4, basis 1, x, y, x^2, xy, y^2; supp ∪ squares = {1, x^2, y^2, x^4, x^2y^2, y^4}:
    # 1*x^2 = x^2, 1*y^2 = y^2, x^2*y^2 = x^2y^2 are the only off-diagonal hits -> {1, x^2, y^2}, {x}, {y}, {xy}
    f = np.array([[0, 0], [4, 0], [0, 4]])
    B = monomials(2, 2)
    blocks = term_sparsity_blocks(f, B)
    assert [b.tolist() for b in blocks] == [[0, 3, 5], [1], [2], [4]]
    assert _covered(f, B, blocks)
    it = term_sparsity_iterate(f, B, steps=5)
    assert it.stable and it.iterations == 2
    assert [b.tolist() for b in it.blocks] == [[0, 3, 5], [1], [2], [4]]


def test_term_sparsity_extension_and_iteration():
    # f = 1 + x^2 y^2 + x y^3 + x^3 y ... built so the graph is the 4-cycle 1 - x - xy - y - 1 plus isolated rows:
    # basis 1, x, y, xy; supp f = {x, y, x^2 y, x y^2}: edges 1x, 1y, x*xy = x^2y, y*xy = xy^2 (squares add
    # 1*xy? no: 2*basis = {1, x^2, y^2, x^2y^2}; x*y = xy not in it)
    B = np.array([[0, 0], [1, 0], [0, 1], [1, 1]])
    f = np.array([[1, 0], [0, 1], [2, 1], [1, 2]])
    G = term_sparsity_graph(f, B)
    assert {frozenset(e) for e in G.edges} == {frozenset(e) for e in [(0, 1), (0, 2), (1, 3), (2, 3)]}
    blocks = term_sparsity_blocks(f, B, heuristic="min_degree")
    # min-degree eliminates row 0 first (all degree 2, lowest index) -> chord (1, 2)
    assert [b.tolist() for b in blocks] == [[0, 1, 2], [1, 2, 3]]
    assert _covered(f, B, blocks)
    # next step adds x*y = xy to the support: now 1*xy = xy joins (0, 3) -> one block
    it = term_sparsity_iterate(f, B, steps=10)
    assert [b.tolist() for b in it.blocks] == [[0, 1, 2, 3]]
    assert it.stable and it.iterations == 3
    one = term_sparsity_iterate(f, B, steps=1)
    assert [b.tolist() for b in one.blocks] == [[0, 1, 2], [1, 2, 3]] and not one.stable


def test_term_sparsity_motzkin_is_diagonal():
    motzkin = np.array([[4, 2], [2, 4], [2, 2], [0, 0]])
    B = newton_reduce(motzkin, monomials(2, 3))
    assert [b.tolist() for b in term_sparsity_blocks(motzkin, B)] == [[0], [1], [2], [3]]


@pytest.mark.parametrize("heuristic", ["min_degree", "min_fill"])
def test_term_sparsity_random_covering(heuristic):
    rng = np.random.default_rng(7)
    B = monomials(3, 2)
    for _ in range(5):
        f = np.unique(rng.integers(0, 5, size=(6, 3)), axis=0)
        blocks = term_sparsity_blocks(f, B, heuristic)
        assert _covered(f, B, blocks)
        assert sorted(set(np.concatenate(blocks).tolist())) == list(range(B.shape[0]))


# --------------------------------------------------------------------------- sparse extraction
CHAIN = ((0, 1), (1, 2), (2, 3))


def _moments(points, weights, cliques, half_degree=2):
    Ms, Bs = [], []
    for c in cliques:
        B = monomials(len(c), half_degree)
        M = np.zeros((B.shape[0], B.shape[0]))
        for v, w in zip(points, weights):
            b = np.prod(np.asarray(v, float)[list(c)][None, :] ** B, axis=1)
            M += w * np.outer(b, b)
        Ms.append(M)
        Bs.append(B)
    return Ms, Bs


def _match(found, expected, tol=1e-6):
    assert len(found) == len(expected)
    for v in expected:
        assert min(np.max(np.abs(p - v)) for p in found) < tol


def test_extract_rank_one_chain():
    v = np.array([0.7, -1.2, 0.4, 2.0])
    Ms, Bs = _moments([v], [1.3], CHAIN)
    _match(extract_from_clique_moments(Ms, Bs, CHAIN, 4), [v])


def test_extract_two_points_chain():
    v1 = np.array([0.7, -1.2, 0.4, 2.0])
    v2 = np.array([-0.5, 0.9, 1.1, -0.3])
    Ms, Bs = _moments([v1, v2], [0.4, 0.6], CHAIN)
    _match(extract_from_clique_moments(Ms, Bs, CHAIN, 4), [v1, v2])


def test_extract_unused_variable_is_zero():
    v = np.array([0.3, 0.0, -0.8, 1.5, 0.0])
    cliques = ((0, 2), (2, 3))
    Ms, Bs = _moments([v], [1.0], cliques)
    found = extract_from_clique_moments(Ms, Bs, cliques, 5)
    _match(found, [v])
    assert found[0][1] == 0.0 and found[0][4] == 0.0


def test_extract_inconsistent_cliques():
    a = np.array([0.7, -1.2, 0.4, 2.0])
    b = np.array([0.7, 0.5, 0.4, 2.0])  # differs on x1, shared by cliques 0 and 1
    Ma, Ba = _moments([a], [1.0], CHAIN)
    Mb, _ = _moments([b], [1.0], CHAIN)
    assert extract_from_clique_moments([Ma[0], Mb[1], Ma[2]], Ba, CHAIN, 4) == []
    # two points per clique, but clique 1 mixes in a point agreeing with neither on x1
    c = np.array([0.1, 3.0, -0.6, 0.2])
    M2, B2 = _moments([a, c], [0.5, 0.5], CHAIN)
    Md, _ = _moments([a + np.array([0, 0.25, 0, 0]), c + np.array([0, 0.25, 0, 0])], [0.5, 0.5], CHAIN)
    assert extract_from_clique_moments([M2[0], Md[1], M2[2]], B2, CHAIN, 4) == []


def test_join_cap_and_validation():
    cands = [[np.array([0.0, k]) for k in range(10)], [np.array([k, 0.0]) for k in range(10)]]
    cliques = ((0, 1), (1, 2))
    assert len(join_clique_candidates(cands, cliques, 3)) == 10
    assert len(join_clique_candidates(cands, cliques, 3, max_combinations=5)) < 10
    Ms, Bs = _moments([np.ones(4)], [1.0], CHAIN)
    with pytest.raises(ValueError):
        extract_from_clique_moments(Ms, Bs, ((1, 0), (1, 2), (2, 3)), 4)
    with pytest.raises(ValueError):
        extract_from_clique_moments(Ms[:2], Bs, CHAIN, 4)
    with pytest.raises(ValueError):
        extract_from_clique_moments(Ms, [B[1:] for B in Bs], CHAIN, 4)


def test_min_fill_finds_minimum_fill():
    # two K4 joined through a degree-2 vertex v (chordal, v of least degree but not simplicial), plus a C4:
    # the minimum fill-in is one chord of the C4; min-fill eliminates simplicial vertices first and finds it
    G = nx.complete_graph(4)
    G.add_edges_from(itertools.combinations(range(4, 8), 2))
    G.add_edges_from([(8, 0), (8, 4)])
    G.add_edges_from([(9, 10), (10, 11), (11, 12), (12, 9)])
    assert not nx.is_chordal(G)
    H = chordal_extension(G, "min_fill")
    assert H.number_of_edges() == G.number_of_edges() + 1
    assert nx.is_chordal(H)


def _naive_elimination(G: nx.Graph, heuristic: str) -> set[frozenset]:
    """Reference elimination game recomputing every score at every step (ties -> smallest node)."""
    adj = {v: set(G.adj[v]) for v in G.nodes}
    edges = {frozenset(e) for e in G.edges}
    while adj:
        def score(v):
            nb = adj[v]
            if heuristic == "min_degree":
                return (len(nb), v)
            return (sum(1 for a, b in itertools.combinations(nb, 2) if b not in adj[a]), v)
        v = min(adj, key=score)
        for a, b in itertools.combinations(adj[v], 2):
            adj[a].add(b)
            adj[b].add(a)
            edges.add(frozenset((a, b)))
        for a in adj.pop(v):
            adj[a].discard(v)
    return edges


@pytest.mark.parametrize("heuristic", ["min_degree", "min_fill"])
def test_elimination_matches_naive_reference(heuristic):
    checked = 0
    for seed in range(12):
        G = nx.gnp_random_graph(14, 0.25, seed=100 + seed)
        if nx.is_chordal(G):
            continue
        checked += 1
        assert {frozenset(e) for e in chordal_extension(G, heuristic).edges} == _naive_elimination(G, heuristic)
    assert checked >= 8


def test_extract_shared_projection():
    # the two minimisers coincide on clique 0: its moment matrix has rank 1, the others rank 2
    v1 = np.array([0.7, -1.2, 0.4, 2.0])
    v2 = np.array([0.7, -1.2, 1.1, -0.3])
    Ms, Bs = _moments([v1, v2], [0.3, 0.7], CHAIN)
    assert np.linalg.matrix_rank(Ms[0], tol=1e-9) == 1
    _match(extract_from_clique_moments(Ms, Bs, CHAIN, 4), [v1, v2])
