"""Sub-bounds of the robust (TLS) search verified in the parent's normalised frame
(:mod:`tritools.solve.robust_verify`): every bound against an independent multi-start L2 minimum of its subset, at
pixel scales 1e-3..1e6; the search with the path against the search without it (``IN_PARENT = False``) and against
the subset enumeration; adversarial inputs (duplicated views, zero noise, huge thresholds, every view an outlier)."""
import itertools

import numpy as np
import pytest
from scipy.optimize import least_squares

import tritools
import tritools.solve.robust_bounds as rb
import tritools.solve.robust_enum as enum_mod
from tritools.scene import robust_protocol_scene
from tests.robust_refs import l2_min, outlier_track, tls_by_subsets
from tritools.solve.robust_verify import parent_frames, verify_in_parent


def _subset_bounds(cams, x, k):
    subsets = [np.array(S) for S in itertools.combinations(range(len(x)), k)]
    frame = parent_frames(cams[None], x[None])[0]
    assert frame is not None
    good, lb, X = verify_in_parent([cams] * len(subsets), [frame] * len(subsets), subsets, [[]] * len(subsets),
                                   tritools.TriangulationOptions().tolerances)
    return subsets, good, lb, X


def l2_min_15(cams, x, starts) -> float:
    return l2_min(cams, x, starts, tol=1e-15)


@pytest.mark.parametrize("seed", range(2))
@pytest.mark.parametrize("pixel_scale", [1e-3, 1.0, 1e6])
def test_bounds_below_every_subset_optimum_at_every_pixel_scale(seed, pixel_scale):
    """Every accepted bound L2LB(S) <= L2*(S) (an attained multi-start value, so the check fails only if the bound
    is too high), for every subset of 2..6 views of a 6-view track with two wrong matches whose pixel units are
    rescaled by 1e-3..1e6 (cameras and points alike: L2* scales by the square); the clean subsets are accepted
    and tight (within 1e-6 relative of the reference)."""
    cams, x, X, out = outlier_track(6, 2, seed)
    A = np.diag([pixel_scale, pixel_scale, 1.0])
    cams, x = A @ cams, x * pixel_scale
    starts = [X, X + 0.3, X - 0.3]
    clean_tight = 0
    for k in range(2, 7):
        subsets, good, lb, Xs = _subset_bounds(cams, x, k)
        for S, g, b in zip(subsets, good, lb):
            if not g:
                continue
            ref = l2_min_15(cams[S], x[S], starts)
            assert b <= ref * (1 + 1e-9) + 1e-12 * pixel_scale ** 2
            if not set(S) & set(out):
                assert b >= ref * (1 - 1e-6) - 1e-9 * pixel_scale ** 2
                clean_tight += 1
    assert clean_tight == 2 ** 4 - 1 - 4                     # every clean subset of >= 2 views: accepted and tight


def test_outlier_pairs_bounded_above_the_threshold():
    """A pair holding a wrong match gets a bound that matters (above c^2 for c = 4 px) where its L2* is large."""
    cams, x, X, out = outlier_track(5, 1, 3)
    subsets, good, lb, _ = _subset_bounds(cams, x, 2)
    big = [b for S, g, b in zip(subsets, good, lb) if g and out[0] in S]
    refs = [l2_min_15(cams[S], x[S], [X]) for S in subsets if out[0] in S]
    assert sum(b > 16.0 for b in big) >= sum(r > 32.0 for r in refs) - 1 >= 1


@pytest.mark.parametrize("seed,N,n_out", [(1, 5, 1), (4, 6, 2), (7, 7, 2)])
def test_search_equals_the_per_subset_path_and_the_enumeration(seed, N, n_out, monkeypatch):
    """The search with the parent-frame sub-bounds gives the per-subset path's certificate, inlier set and value on
    the same points, single and batched; no lower bound above the enumerated TLS optimum, and the certified
    value reaches it."""
    cams, x, X, out = outlier_track(N, n_out, seed)
    c = np.full(N, 20.0)
    monkeypatch.setattr(enum_mod, "ENUM_MAX_VIEWS", 0)    # the search's sub-bounds (single calls and batches enumerate)
    monkeypatch.setattr("tritools.solve.robust_batch.BATCH_ENUM_MAX_VIEWS", 0)
    accepted = []
    real = rb.verify_in_parent
    monkeypatch.setattr(rb, "verify_in_parent", lambda *a: (lambda r: accepted.append(int(r[0].sum())) or r)(real(*a)))
    fast = tritools.triangulate(cams, x, robust=c)
    fast_many = tritools.triangulate_many([(cams, x), (cams, x)], robust=c)
    assert sum(accepted) >= N                                  # the path under test bounded the subsets
    monkeypatch.setattr(rb, "IN_PARENT", False)
    accepted.clear()
    plain = tritools.triangulate(cams, x, robust=c)
    assert not accepted
    assert fast.optimal and plain.optimal and all(r.optimal for r in fast_many)
    for r in (fast, *fast_many):
        np.testing.assert_array_equal(r.inliers, plain.inliers)
        assert r.gamma_ub == pytest.approx(plain.gamma_ub, rel=1e-6)
    assert not fast.inliers[out].any()
    f_ref = tls_by_subsets(cams, x, c, [X, X + 0.3, X - 0.3])
    for r in (fast, plain, *fast_many):
        assert 2 * N * r.gamma_lb ** 2 <= f_ref * (1 + 1e-9) + 1e-9
        assert 2 * N * r.gamma_ub ** 2 <= f_ref * (1 + 1e-6) + 1e-9


def _check_against_enumeration(cams, x, c, starts):
    N = len(x)
    f_ref = tls_by_subsets(cams, x, c, starts)
    res = tritools.triangulate(cams, x, robust=c)
    many = tritools.triangulate_many([(cams, x)], robust=c)[0]
    for r in (res, many):
        assert r.gamma_lb <= r.gamma_ub
        assert 2 * N * r.gamma_lb ** 2 <= f_ref * (1 + 1e-9) + 1e-9
        if r.optimal:
            assert 2 * N * r.gamma_ub ** 2 <= f_ref * (1 + 1e-6) + 1e-9
            d = r.residuals
            assert np.array_equal(r.inliers, d < c)
    return res, many


def test_duplicated_views():
    """Two copies of each of three views (coincident centres inside the sub-problems) and one wrong match (twice)."""
    cams, x, X, out = outlier_track(3, 0, 5)
    x[2] += [150.0, -90.0]
    cams, x = np.concatenate([cams, cams]), np.concatenate([x, x])
    res, many = _check_against_enumeration(cams, x, np.full(6, 10.0), [X, X + 0.2])
    assert res.optimal and not res.inliers[[2, 5]].any() and res.inliers[[0, 1, 3, 4]].all()


def test_zero_noise():
    cams, x, X, out = outlier_track(6, 2, 8, noise=0.0)
    res, many = _check_against_enumeration(cams, x, np.full(6, 5.0), [X, X + 0.2])
    assert res.optimal and many.optimal
    assert np.linalg.norm(res.X - X) < 1e-6 * (1 + np.linalg.norm(X))


def test_every_threshold_huge():
    """c far above every residual: the TLS problem is the L2 problem (every view an inlier)."""
    cams, x, X, out = outlier_track(5, 1, 9)
    res, many = _check_against_enumeration(cams, x, np.full(5, 1e7), [X, X + 0.2])
    l2 = tritools.triangulate(cams, x)
    assert res.inliers.all() and res.gamma_ub == pytest.approx(l2.gamma_ub, rel=1e-6)


def test_every_view_an_outlier():
    """Random image points in every view, a small threshold: the bounds still hold against the enumeration."""
    cams, x, X, out = outlier_track(5, 0, 10)
    x = x + np.random.default_rng(3).uniform(-300, 300, x.shape)
    res, many = _check_against_enumeration(cams, x, np.full(5, 2.0), [X, X + 0.2, X - 0.2])
    assert res.inliers.sum() <= 2


@pytest.mark.parametrize("offset,cam_scale", [(1e6, 1.0), (0.0, 1e8), (1e5, 1e-6)])
def test_georeferenced_world_and_rescaled_cameras(offset, cam_scale, monkeypatch):
    """The world moved by 1e5..1e6 (georeferenced) and the camera matrices multiplied by 1e-6..1e8 (the same
    cameras projectively): the same inlier set and value as the per-subset path, bounds below the enumeration."""
    cams, x, X, out = outlier_track(6, 2, 12)
    T = np.eye(4)
    T[:3, 3] = -offset                                       # X_world = X + offset: P' = P T
    cams = cam_scale * (cams @ T)
    X = X + offset
    c = np.full(6, 20.0)
    fast = tritools.triangulate(cams, x, robust=c)
    monkeypatch.setattr(rb, "IN_PARENT", False)
    plain = tritools.triangulate(cams, x, robust=c)
    assert fast.optimal
    np.testing.assert_array_equal(fast.inliers, plain.inliers)
    assert not fast.inliers[out].any()
    assert fast.gamma_ub == pytest.approx(plain.gamma_ub, rel=1e-6)
    f_ref = tls_by_subsets(cams, x, c, [X, X + 0.3, X - 0.3])
    assert 2 * 6 * fast.gamma_lb ** 2 <= f_ref * (1 + 1e-9) + 1e-9
    assert 2 * 6 * fast.gamma_ub ** 2 <= f_ref * (1 + 1e-6) + 1e-9


@pytest.mark.slow
@pytest.mark.parametrize("k", [4, 24])
def test_split_bound_replaces_the_whole_problem_solve(k, monkeypatch):
    """Two 5-view tracks with one wrong match whose leaf 'every view an inlier' is not pruned by the packing and
    delta = 2 bounds (benchmarks/robust.py, batch cell N = 5, 20%, 1 px): the split bound L2LB(T) + L2LB(S - T)
    over triples T holding the wrong match prunes it with no full-plan solve of the 5 views; the same inlier set and
    value as the full-plan path (``SPLIT_TRIES = 0``), bounds below the enumeration.  Since the batched SDP's
    bounds on rows handed back for their Gram kernel are kept, these leaves need no solve at all (asserted first);
    the split is then exercised with those bounds dropped (as before)."""
    rng = np.random.default_rng([3, 5, 1, 10])
    for _ in range(k + 1):
        P, x, X, out = robust_protocol_scene(5, 1, 1.0, rng)
    monkeypatch.setattr(enum_mod, "ENUM_MAX_VIEWS", 0)         # the branch and bound's leaves (robust_enum: N <= 8)
    sizes = []
    real = rb.SubsetBounds._solve_one
    monkeypatch.setattr(rb.SubsetBounds, "_solve_one",
                        lambda self, S, light=True, **kw: sizes.append((len(S), light)) or real(self, S, light, **kw))
    kept = tritools.triangulate(P, x, robust=200.0)
    assert kept.optimal and not any(size >= 3 and not light for size, light in sizes)
    monkeypatch.setattr(rb, "_kernel_hand_backs", lambda b: np.zeros(len(b.done), bool))
    sizes.clear()
    split = tritools.triangulate(P, x, robust=200.0)
    assert (5, False) not in sizes and (3, False) in sizes
    sizes.clear()
    monkeypatch.setattr(rb, "SPLIT_TRIES", 0)
    whole = tritools.triangulate(P, x, robust=200.0)
    assert (5, False) in sizes                                  # the case does need more than delta = 2 there
    assert split.optimal and whole.optimal
    np.testing.assert_array_equal(split.inliers, whole.inliers)
    np.testing.assert_array_equal(kept.inliers, whole.inliers)
    np.testing.assert_array_equal(split.inliers, ~out)
    assert split.gamma_ub == pytest.approx(whole.gamma_ub, rel=1e-9)
    assert kept.gamma_ub == pytest.approx(whole.gamma_ub, rel=1e-9)
    f_ref = tls_by_subsets(P, x, np.full(5, 200.0), [X, X + 0.1, X - 0.1])
    for r in (kept, split, whole):
        assert 2 * 5 * r.gamma_lb ** 2 <= f_ref * (1 + 1e-9) + 1e-9
        assert 2 * 5 * r.gamma_ub ** 2 <= f_ref * (1 + 1e-6) + 1e-9


def test_polish_early_stop_reaches_the_local_minimum():
    """polish_rows stops a row once its's cost moves by 1e-13 of it: from warm starts it ends at the local minimum that
    scipy's Levenberg-Marquardt reaches from the same start (cost within 1e-9), with a stack of rows that
    converge at different speeds (clean tracks and tracks with a wrong match)."""
    from tritools.solve.robust_verify import _cost, polish_rows

    rng = np.random.default_rng(11)
    scenes = [robust_protocol_scene(4, k % 2, 1.0, rng) for k in range(6)]
    frames = parent_frames(np.array([P for P, *_ in scenes]), np.array([x for _, x, *_ in scenes]))
    Cn = np.array([f.cameras_n for f in frames])
    X0 = np.array([f.Xn for f in frames]) + 1e-3 * rng.normal(size=(6, 3))
    got = _cost(Cn, polish_rows(Cn, X0, 50))
    for m in range(6):
        def res(X, m=m):
            h = Cn[m] @ np.append(X, 1.0)
            return (h[:, :2] / h[:, 2:]).ravel()

        ref = least_squares(res, X0[m], method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
        assert got[m] <= 2 * ref.cost * (1 + 1e-9) + 1e-300
    assert np.all(_cost(Cn, polish_rows(Cn, X0, 6)) <= _cost(Cn, X0))
