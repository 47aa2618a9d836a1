"""The cheap sub-bounds of the robust (TLS) search (:mod:`tritools.solve.robust_bounds`): the pair packing bound
(superadditivity of L2* over disjoint view sets) against an independent multi-start L2 minimum of every subset,
and the search with the cheap paths against the plain path (every uncertified subset through the batched SDP)
and against the subset enumeration."""
import itertools

import numpy as np
import pytest

import tritools
import tritools.solve.robust_bounds as rb
import tritools.solve.robust_enum as enum_mod
from tritools.solve import robust_cells
from tritools.model.regions import Point
from tritools.scene import sphere_cameras
from tests.robust_refs import l2_min, outlier_track, tls_by_subsets


def _scene(N, n_out, seed, noise=1.0):
    return outlier_track(N, n_out, seed, noise, seed_offset=7)[:3]


def _tls_reference(cams, x, c, starts) -> float:
    return tls_by_subsets(cams, x, c, starts, with_ray=False)


@pytest.mark.parametrize("seed", range(3))
def test_packing_bound_below_every_subset_optimum(seed):
    """packing_bound(S) <= L2*(S) for every subset of >= 3 views of a 6-view track with two wrong matches (the
    reference an attained multi-start value, so the check can only fail if the bound is too high), and it is
    above 0 on the subsets holding a wrong match (the bound has content)."""
    cams, x, X = _scene(6, 2, seed)
    opts = tritools.TriangulationOptions()
    sb = rb.SubsetBounds(cams, [Point(p) for p in x], opts, opts.budget.deadline())
    sb.compute([frozenset(p) for p in itertools.combinations(range(6), 2)])
    starts = [X, X + 0.3, X - 0.3]
    positive = 0
    for k in range(3, 7):
        for S in itertools.combinations(range(6), k):
            b = sb.packing_bound(frozenset(S))
            assert b <= l2_min(cams[list(S)], x[list(S)], starts) * (1 + 1e-9) + 1e-9
            positive += b > 1.0
    assert positive > 10


def _packing_by_all_pairs(lb: dict, S: frozenset) -> float:
    """The packing bound as first written: every pair of S in view order, looked up in the cache, a stable sort
    by bound, greedy disjoint pairs, rounded down."""
    pairs = [(lb[P], P) for P in map(frozenset, itertools.combinations(sorted(S), 2)) if P in lb and lb[P] > 0]
    pairs.sort(key=lambda bp: bp[0], reverse=True)
    used, total = set(), 0.0
    for b, P in pairs:
        if not (P & used):
            total += b
            used |= P
    return total * rb.ROUND_DOWN


@pytest.mark.parametrize("seed", range(4))
def test_packing_bound_from_the_cache_equals_the_bound_from_all_pairs(seed):
    """packing_bound walks the cache instead of S's pairs where the cache is the shorter list (a large S): the same
    value bit for bit as the walk over all pairs of S (ties in bound included: equal bounds on purpose), on both
    sides of the switch."""
    rng = np.random.default_rng(seed)
    N = 60
    opts = tritools.TriangulationOptions()
    cams = sphere_cameras(N, rng)
    sb = rb.SubsetBounds(cams, [Point(p) for p in rng.uniform(0, 100, (N, 2))], opts, opts.budget.deadline())
    pool = [frozenset(p) for p in itertools.combinations(range(N), 2)]
    for k in rng.choice(len(pool), 300, replace=False):
        sb._lb[pool[k]] = float(rng.choice([0.0, 1.5, 2.0, rng.uniform(0, 10)]))     # ties and zeros on purpose
    for _ in range(40):                                                            # larger sets in the cache too
        sb._lb[frozenset(rng.choice(N, 5, replace=False).tolist())] = 3.0
    for size in (4, 10, 25, 40, 60):                    # 6 .. 1770 pairs against a cache of ~340 entries
        for _ in range(5):
            S = frozenset(rng.choice(N, size, replace=False).tolist())
            assert sb.packing_bound(S) == _packing_by_all_pairs(sb._lb, S)


def _sphere_scene(N, n_out, rng):
    """The CVPR 2023 protocol (benchmarks/robust.py): cameras on a sphere of radius 2 looking at the origin, the
    point in [-0.5, 0.5]^3, 1 px noise, outliers uniform in the 2108 x 1162 image."""
    P = sphere_cameras(N, rng)
    X = rng.uniform(-0.5, 0.5, 3)
    h = P @ np.append(X, 1.0)
    x = h[:, :2] / h[:, 2:] + rng.normal(size=(N, 2))
    out = rng.choice(N, n_out, replace=False)
    x[out] = rng.uniform([0, 0], [2108, 1162], size=(n_out, 2))
    return P, x, X


@pytest.mark.parametrize("seed", [100, 103, 108])
def test_cheap_paths_equal_the_plain_path_and_the_enumeration(seed, monkeypatch):
    """The search with the cheap sub-bounds (packing, verification-only requests) gives the plain path's
    certificate, inlier set and estimate on the same points with fewer SDP rows; no lower bound above the
    enumerated TLS optimum, and the certified value reaches it."""
    N = 8
    cams, x, X = _sphere_scene(N, 3, np.random.default_rng(seed))
    c = np.full(N, 200.0)
    monkeypatch.setattr(enum_mod, "ENUM_MAX_VIEWS", 0)         # the branch and bound's sub-bounds (robust_enum: N <= 8)
    monkeypatch.setattr(robust_cells, "ENABLED", False)      # the inlier-set search itself (robust_cells)
    sdp_rows = []
    real = rb._sdp_stack
    monkeypatch.setattr(rb, "_sdp_stack", lambda C, x_, o, d=None: sdp_rows.append(len(C)) or real(C, x_, o, d))
    fast = tritools.triangulate(cams, x, robust=c)
    n_fast, sdp_rows[:] = sum(sdp_rows), []
    monkeypatch.setattr(rb, "PACKING", False)
    plain = tritools.triangulate(cams, x, robust=c)
    assert fast.optimal and plain.optimal
    np.testing.assert_array_equal(fast.inliers, plain.inliers)
    assert fast.gamma_ub == pytest.approx(plain.gamma_ub, rel=1e-6)
    np.testing.assert_allclose(fast.X, plain.X, rtol=1e-5, atol=1e-8)
    assert n_fast < sum(sdp_rows)                              # the cheap paths replaced SDP rows
    f_ref = _tls_reference(cams, x, c, [X, X + 0.3, X - 0.3])
    for r in (fast, plain):
        assert 2 * N * r.gamma_lb ** 2 <= f_ref * (1 + 1e-9) + 1e-9
        assert 2 * N * r.gamma_ub ** 2 <= f_ref * (1 + 1e-6) + 1e-9


@pytest.mark.parametrize("seed", [0, 2, 3])
def test_leave_one_out_root_bound(seed, monkeypatch):
    """A clean 7-view track whose L2 optimum costs more than c^2 (1 px noise, c = 3 px): the root bound
    min(L2LB, c^2) cannot certify it, the leave-one-out bound does, with no branch and bound (0 nodes); same
    inlier set and value as the plain path, every bound against the enumeration."""
    cams, x, X = _scene(7, 0, seed)
    c = np.full(7, 3.0)
    monkeypatch.setattr(enum_mod, "ENUM_MAX_VIEWS", 0)         # the branch and bound's root (robust_enum: N <= 8)
    monkeypatch.setattr(robust_cells, "ENABLED", False)      # the inlier-set search itself (robust_cells)
    fast = tritools.triangulate(cams, x, robust=c)
    monkeypatch.setattr(rb, "PACKING", False)
    plain = tritools.triangulate(cams, x, robust=c)
    assert fast.optimal and plain.optimal
    assert 2 * 7 * fast.gamma_ub ** 2 > 9.0                    # L2* > c^2: the root bound alone does not decide
    assert "0 nodes" in fast.message and "0 nodes" not in plain.message
    np.testing.assert_array_equal(fast.inliers, plain.inliers)
    assert fast.inliers.all()
    assert fast.gamma_ub == pytest.approx(plain.gamma_ub, rel=1e-9)
    f_ref = _tls_reference(cams, x, c, [X, X + 0.3, X - 0.3])
    assert 2 * 7 * fast.gamma_lb ** 2 <= f_ref * (1 + 1e-9) + 1e-9
    assert 2 * 7 * fast.gamma_ub ** 2 <= f_ref * (1 + 1e-6) + 1e-9
