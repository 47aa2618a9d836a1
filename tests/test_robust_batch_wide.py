"""Batches enumerate every inlier set up to 10 views (robust_batch.BATCH_ENUM_MAX_VIEWS; wave 9).

Checked against independent references: the TLS value by inlier-set enumeration with multi-start scipy least
squares (tests/robust_refs.py: an attained value, so a lower bound above it is wrong), per-subset scipy L2 optima
for the subset bounds, and brute-force constructions of the subset tables and of the superadditive closure."""
from __future__ import annotations

import itertools

import numpy as np
import pytest

import tritools
import tritools.solve.robust_enum as enum_mod
import tritools.solve.robust_enum_run as run_mod
from tests.robust_refs import l2_min, outlier_track, tls_by_subsets
from tritools.scene import robust_protocol_scene
from tritools.solve.robust_batch import BATCH_ENUM_MAX_VIEWS
from tritools.solve.robust_bounds import ROUND_DOWN

TOL = tritools.TriangulationOptions().tolerances


def _assert_valid(res, cams, x, c, X_true, spread=(0.3, -0.3)):
    """lb <= the enumerated reference; a certified result reaches it; the reported inliers are d < c."""
    N = len(x)
    ref = tls_by_subsets(cams, x, c, [X_true] + [X_true + d for d in spread] + ([res.X] if res.X is not None else []))
    assert 2 * N * res.gamma_lb ** 2 <= ref * (1 + 1e-9) + 1e-300, (res.gamma_lb, ref)
    if res.optimal:
        assert 2 * N * res.gamma_ub ** 2 <= ref * (1 + 1e-6) + 1e-300, (res.gamma_ub, ref)
    np.testing.assert_array_equal(res.inliers, res.residuals < c)


@pytest.mark.parametrize("N", [2, 3, 5, 8, 10])
def test_subset_tables_match_itertools(N):
    """subset_masks: by size, then the combinations' order; _splits: per S, every split into two non-empty parts
    once, T holding S's lowest view (brute force from itertools)."""
    W = enum_mod.subset_masks(N)
    want = [S for k in range(2, N + 1) for S in itertools.combinations(range(N), k)]
    assert [tuple(np.nonzero(r)[0]) for r in W] == want
    for S_bits, T, R, starts in enum_mod._splits(N):
        ends = list(starts[1:]) + [len(T)]
        for S, a, b in zip(S_bits, starts, ends):
            views = [i for i in range(N) if S >> i & 1]
            low = 1 << views[0]
            expect = {(low | sum(1 << i for i in extra), S ^ (low | sum(1 << i for i in extra)))
                      for r in range(len(views) - 1) for extra in itertools.combinations(views[1:], r)}
            got = set(zip(T[a:b].tolist(), R[a:b].tolist()))
            assert got == expect and len(got) == b - a


def _closure_brute(N, L):
    """The closure by its definition: by increasing size, every two-part split of S, sums rounded down."""
    L = L.copy()
    for k in range(2, N + 1):
        for S in itertools.combinations(range(N), k):
            bits = sum(1 << i for i in S)
            for r in range(1, k):
                for T in itertools.combinations(S, r):
                    t = sum(1 << i for i in T)
                    L[bits] = max(L[bits], (L[t] + L[bits ^ t]) * ROUND_DOWN)
    return L


def test_closure_in_chunks_matches_the_definition():
    """closure over more problems than CLOSURE_CHUNK (chunked) equals the brute-force closure of each problem."""
    N = 6
    rng = np.random.default_rng(5)
    L = rng.random((enum_mod.CLOSURE_CHUNK * 2 + 3, 1 << N)) * (rng.random((1, 1 << N)) < 0.3)
    L[:, [0] + [1 << i for i in range(N)]] = 0.0
    got = enum_mod.closure(N, L)
    for p in (0, enum_mod.CLOSURE_CHUNK, len(L) - 1):
        np.testing.assert_array_equal(got[p], _closure_brute(N, L[p]))


def test_closed_terms_of_a_track_bounded_at_all_views_only():
    """A problem whose only bound is that of all views (its closure skipped) gets the same terms as the closure;
    another problem of the same stack with pair bounds gets them closed."""
    N = 5
    W = enum_mod.subset_masks(N)
    lb = np.zeros((2, len(W)))
    lb[0, -1] = 3.0                                   # all views only
    lb[1, 0], lb[1, -1] = 2.0, 1.0                    # pair {0, 1} and all views: closure lifts supersets of {0, 1}
    rest = np.zeros((2, len(W)))
    bits = W.astype(np.int64) @ (1 << np.arange(N))
    table = np.zeros((2, 1 << N))
    table[:, bits] = lb
    want = enum_mod.closure(N, table)[:, bits] * ROUND_DOWN
    np.testing.assert_array_equal(run_mod.closed_terms(N, W, lb, rest), want)
    assert run_mod.closed_terms(N, W, lb, rest)[1, -1] >= 2.0 * ROUND_DOWN ** 3


@pytest.mark.parametrize("pixel_scale", [1e-3, 1e6])
def test_ten_view_subset_bounds_below_every_subset_optimum(pixel_scale):
    """At 10 views (each row bounded on its own views): every sampled subset's bound is below its multi-start
    scipy L2 optimum, and tight (1e-6) on subsets without a wrong match, at pixel scales 1e-3 and 1e6."""
    N = 10
    rng = np.random.default_rng(31)
    P, obs, X, out = robust_protocol_scene(N, 4, 1.0, rng)
    A = np.diag([pixel_scale, pixel_scale, 1.0])
    cams, x = np.einsum("ij,njk->nik", A, P), obs * pixel_scale
    norm, Cn = enum_mod.enum_frame(cams, x)
    W = enum_mod.subset_masks(N)
    pick = np.sort(np.random.default_rng(2).choice(len(W), 60, replace=False))
    clean = np.nonzero(~W[:, out].any(axis=1))[0]               # subsets without a wrong match
    pick = np.union1d(pick, np.concatenate([[len(W) - 1, 0, 1], clean[::5], clean[-3:]]))
    Xn = enum_mod.enum_candidates(Cn, W[pick])
    lb, _ = enum_mod.enum_bounds(cams, Cn, W[pick], Xn, norm.scale, TOL)
    tight = 0
    for m, row in zip(range(len(pick)), W[pick]):
        S = np.nonzero(row)[0]
        ref = l2_min(cams[S], x[S], [X, X + 0.2, X - 0.2, norm.world_point(Xn[m])])
        assert lb[m] <= ref * (1 + 1e-9) + 1e-300, (S, lb[m], ref)
        if not out[S].any():
            assert lb[m] == pytest.approx(ref, rel=1e-6, abs=1e-12 * pixel_scale ** 2)
            tight += 1
    assert tight >= 10


def test_single_calls_keep_their_limit():
    """Single calls enumerate up to ENUM_MAX_VIEWS views; batches up to BATCH_ENUM_MAX_VIEWS."""
    from tritools.solve.robust import TlsSearch

    P, obs, _, _ = robust_protocol_scene(10, 4, 1.0, np.random.default_rng(3))
    s = TlsSearch(P, None, np.full(10, 200.0), tritools.TriangulationOptions(), 0.0, points=obs)
    assert enum_mod.ENUM_MAX_VIEWS < 10 <= BATCH_ENUM_MAX_VIEWS
    assert not run_mod.eligible(s) and run_mod.eligible(s, BATCH_ENUM_MAX_VIEWS)
    one = tritools.triangulate(P, obs, robust=200.0)
    assert enum_mod.ENUMERATED not in one.message


def test_nine_view_batch_with_four_wrong_matches():
    """A 9-view protocol track with four wrong matches in a batch with a clean 10-view track: certified by the
    enumeration, the wrong matches dropped, the bounds below the enumerated reference (two starts per set)."""
    rng = np.random.default_rng(47)
    (P, obs, X, out), (P2, obs2, _, _) = robust_protocol_scene(9, 4, 5.0, rng), robust_protocol_scene(10, 0, 1.0, rng)
    res = tritools.triangulate_many([(P, obs), (P2, obs2)], robust=200.0)
    assert all(r.optimal and enum_mod.ENUMERATED in r.message for r in res)
    assert "1 L2 sub-problems" in res[1].message           # the clean track: the bound of all views only
    assert res[0].inliers[~out].all()                       # (a wrong match may land within c of the point)
    _assert_valid(res[0], P, obs, np.full(9, 200.0), X, spread=())


@pytest.mark.slow
def test_ten_view_batch_with_forty_percent_wrong_matches():
    """9-10-view tracks with up to four wrong matches (protocol, c = 200 px) and a per-view-threshold track
    (c = 10..40 px): certified by the batch's enumeration, the wrong matches dropped, every bound below the
    enumerated reference."""
    rng = np.random.default_rng(41)
    probs, cs, truth, outs = [], [], [], []
    for N, k in [(10, 4), (9, 4), (10, 0)]:
        P, obs, X, out = robust_protocol_scene(N, k, 1.0, rng)
        probs.append((P, obs))
        cs.append(np.full(N, 200.0))
        truth.append(X)
        outs.append(out)
    cams, x, X, out_idx = outlier_track(10, 3, 7)
    probs.append((cams, x))
    cs.append(np.geomspace(10.0, 40.0, 10))
    truth.append(X)
    outs.append(np.isin(np.arange(10), out_idx))
    res = tritools.triangulate_many(probs, robust=cs)
    for (cams, x), c, X, out, r in zip(probs, cs, truth, outs, res):
        assert r.optimal and enum_mod.ENUMERATED in r.message, r.message
        assert not r.inliers[out].any()
        _assert_valid(r, cams, x, c, X)


def test_row_chunks_give_the_same_results(monkeypatch):
    """Stacked calls cut into chunks of ENUM_ROWS rows (here 5) give the same certificates, inlier sets and
    bounds as one call (to round-off: a chunk's polish stops when its own rows settle)."""
    rng = np.random.default_rng(43)
    probs = [robust_protocol_scene(N, k, 1.0, rng)[:2] for N, k in [(9, 3), (10, 4), (9, 0), (10, 2)]]
    whole = tritools.triangulate_many(probs, robust=200.0)
    monkeypatch.setattr(run_mod, "ENUM_ROWS", 5)
    cut = tritools.triangulate_many(probs, robust=200.0)
    for a, b in zip(whole, cut):
        assert a.optimal and b.optimal
        np.testing.assert_array_equal(a.inliers, b.inliers)
        assert b.gamma_ub == pytest.approx(a.gamma_ub, rel=1e-9)
        assert b.gamma_lb == pytest.approx(a.gamma_lb, rel=1e-6)


def test_outside_sums_with_infinite_thresholds():
    """c^2(V - S) by one matrix product where every c_i is finite, by the masked sum where one is infinite (inf
    where that view is outside S, never NaN); a batch with an infinite per-view threshold stays below the
    reference and keeps that view."""
    W = enum_mod.subset_masks(4)
    c2 = np.array([[1.0, 4.0, 9.0, 16.0], [1.0, np.inf, 9.0, 16.0]])
    got = run_mod._outside_sums(c2, W)
    want = np.array([[sum(c2[p, i] for i in range(4) if not row[i]) for row in W] for p in range(2)]) * ROUND_DOWN
    np.testing.assert_array_equal(got, want)
    assert not np.isnan(got).any()
    rng = np.random.default_rng(53)
    probs, cs, truth = [], [], []
    for N, k in [(5, 2), (6, 1)]:
        P, obs, X, _ = robust_protocol_scene(N, k, 1.0, rng)
        probs.append((P, obs))
        truth.append(X)
        cs.append(np.full(N, 200.0))
    cs[0][0] = np.inf
    res = tritools.triangulate_many(probs, robust=cs)
    assert res[0].inliers[0]
    for (cams, x), c, X, r in zip(probs, cs, truth, res):
        _assert_valid(r, cams, x, c, X)


def test_a_stack_charges_each_problem_its_share_of_the_time():
    """Time limits stay per problem in a stack: after t seconds each of P problems is charged t / P, its deadline
    moved on by the rest; a stack of one moves nothing (a single call's deadline is its own)."""
    from sospoly.budget import Deadline
    from tritools.solve.robust import TlsSearch

    opts = tritools.TriangulationOptions()
    rng = np.random.default_rng(59)
    searches = []
    for _ in range(4):
        P, obs, _, _ = robust_protocol_scene(9, 2, 1.0, rng)
        s = TlsSearch(P, None, np.full(9, 200.0), opts, 0.0, points=obs)
        s.set_deadline(Deadline.after(0.5))
        searches.append(s)
    group = run_mod._Group(searches, None)
    ends = np.array([s.deadline.end for s in searches])
    group._clock -= 0.8                                   # 0.8 s of stack time: 0.2 s each, 0.6 s credited
    assert not group._expired().any()
    np.testing.assert_allclose([s.deadline.end for s in searches], ends + 0.6, atol=0.05)
    one = run_mod._Group(searches[:1], None)
    end = searches[0].deadline.end
    one._clock -= 0.8
    one._expired()
    assert searches[0].deadline.end == end


def test_ten_view_batch_within_per_problem_limits():
    """120 ten-view tracks with four wrong matches, each allowed twice the time of one single call: the stack as a
    whole takes longer, each problem's share far less -- all certified, none stopped by the time limit (before the
    stack charged shares, problems of a long stack ran out of time while others were computed)."""
    import time

    rng = np.random.default_rng(61)
    probs = [robust_protocol_scene(10, 4, 1.0, rng)[:2] for _ in range(120)]
    tritools.triangulate(*probs[0], robust=200.0)
    t = time.perf_counter()
    assert tritools.triangulate(*probs[1], robust=200.0).optimal
    limit = 2 * (time.perf_counter() - t)
    res = tritools.triangulate_many(probs, robust=200.0, time_limit=limit)
    assert all(r.status != tritools.Status.TIME_LIMIT for r in res)
    assert all(r.optimal and enum_mod.ENUMERATED in r.message for r in res)
