"""The suspect-set stage of the robust (TLS) search (:mod:`tritools.solve.robust_suspects`).

Its cover bound is checked against an independent enumeration of inlier sets (scipy least squares from several
starts on every subset: an attained value, so a bound above it is a bound above the optimum) for *any* suspect
set O, also sets holding clean views; the search with the stage against the search without it (same status,
inlier set and value), single calls against batches, and adversarial inputs (pixel scales 1e-3..1e6, a
georeferenced world, duplicated wrong matches, three wrong matches, two views)."""
import itertools

import numpy as np
import pytest
from scipy.optimize import least_squares

import tritools
import tritools.solve.robust_suspects as rs
from tritools.solve.robust import TlsSearch, tls_cost
from tests.robust_refs import drive_one, outlier_track
from tritools.scene import random_scene


def _scene(N, n_out, seed, noise=1.0):
    return outlier_track(N, n_out, seed, noise, seed_offset=77, shift=(60.0, 500.0))


def _dist(cams, x, X):
    u = np.einsum("nij,j->ni", cams, np.append(X, 1.0))
    return np.linalg.norm(u[:, :2] / u[:, 2:] - x, axis=1)


def _enumerated(cams, x, c, X_true) -> float:
    """min over inlier sets S (|S| >= 2) of f_TLS at S's local L2 minimisers from four starts, and the value
    sum of all but the largest c^2 (a point on one view's ray): an attained value, >= the TLS optimum."""
    N = len(x)
    best = float(np.sum(np.sort(np.asarray(c, float) ** 2)[:-1]))
    starts = [X_true, X_true + 0.3, X_true - 0.3, np.zeros(3)]
    for k in range(2, N + 1):
        for S in map(list, itertools.combinations(range(N), k)):
            for X0 in starts:
                def res(X, S=S):
                    u = np.einsum("nij,j->ni", cams[S], np.append(X, 1.0))
                    return (u[:, :2] / u[:, 2:] - x[S]).ravel()
                X = least_squares(res, X0, xtol=1e-13, ftol=1e-13).x
                best = min(best, tls_cost(_dist(cams, x, X), c))
    return best


def _search(cams, x, c):
    return TlsSearch(cams, None, np.asarray(c, float), tritools.TriangulationOptions(), 0.0, points=x)


@pytest.mark.parametrize("seed,N,n_out", [(0, 4, 1), (1, 5, 1), (2, 5, 2), (3, 6, 2), (4, 6, 0)])
def test_cover_bound_below_the_enumeration_for_any_suspect_set(seed, N, n_out):
    """min(min_{j in O} LB(node {j}), c^2(O) + TLS LB(V - O)) <= the enumerated optimum for every O of one or two
    views -- the true wrong matches, clean views, mixtures -- at c = 4 and 20 px; and the true wrong matches
    (one or two) give a bound that meets the enumerated optimum within the certificate rule."""
    cams, x, X, out = _scene(N, n_out, seed)
    for cval in (4.0, 20.0):
        c = np.full(N, cval)
        f_ref = _enumerated(cams, x, c, X)
        for k in (1, 2):
            for O in map(frozenset, itertools.combinations(range(N), k)):
                s = _search(cams, x, c)
                s.offer(X)
                W = frozenset(range(N)) - O
                drive_one(s.verify_first(W, *[frozenset((j, u)) for j in O for u in range(N) if u != j]), s.bounds)
                inside = min(rs._inlier_node(s, j) for j in O)
                outside = drive_one(rs._outside(s, W, float(np.sum(c[sorted(O)] ** 2))), s.bounds)
                lb = min(inside, outside)
                assert lb <= f_ref * (1 + 1e-9) + 1e-9, (O, lb, f_ref)
                if O == frozenset(out.tolist()) and cval == 20.0:
                    assert s.tol.certified(lb, f_ref, s.scale), (lb, f_ref)


@pytest.mark.parametrize("seed,N,n_out,cval", [(5, 3, 1, 20.0), (6, 5, 1, 4.0), (7, 6, 2, 20.0), (8, 7, 1, 4.0),
                                               (9, 7, 2, 4.0), (10, 6, 3, 20.0), (11, 8, 0, 4.0)])
def test_stage_gives_the_full_search_result(seed, N, n_out, cval, monkeypatch):
    """With and without the stage: the same status, inlier set and value; no lower bound above the enumeration
    (N <= 7); the one-wrong-match tracks are certified by the stage itself (no branch-and-bound node)."""
    cams, x, X, out = _scene(N, n_out, seed)
    c = np.full(N, cval)
    fast = tritools.triangulate(cams, x, robust=c)
    many = tritools.triangulate_many([(cams, x), (cams, x)], robust=c)
    monkeypatch.setattr(rs, "ENABLED", False)
    plain = tritools.triangulate(cams, x, robust=c)
    assert fast.optimal and plain.optimal
    for r in (fast, *many):
        assert r.status == plain.status and r.optimal
        np.testing.assert_array_equal(r.inliers, plain.inliers)
        assert r.gamma_ub == pytest.approx(plain.gamma_ub, rel=1e-6)
    if n_out == 1:
        assert " 0 nodes" in fast.message and not fast.inliers[out].any()
    if N <= 7:
        f_ref = _enumerated(cams, x, c, X)
        for r in (fast, plain, *many):
            assert 2 * N * r.gamma_lb ** 2 <= f_ref * (1 + 1e-9) + 1e-9
            assert 2 * N * r.gamma_ub ** 2 <= f_ref * (1 + 1e-6) + 1e-9


def test_batch_of_tracks_equals_single_calls(monkeypatch):
    """A batch of 3-8-view tracks, 0-2 wrong matches each: every result equals its single call and the batch
    without the stage (status, inliers, gamma_ub); no track lost."""
    probs = []
    for seed in range(24):
        N = 3 + seed % 6
        cams, x, _, _ = _scene(N, min(seed % 3, N - 2), 100 + seed)
        probs.append((cams, x))
    fast = tritools.triangulate_many(probs, robust=4.0)
    single = [tritools.triangulate(cams, x, robust=4.0) for cams, x in probs]
    monkeypatch.setattr(rs, "ENABLED", False)
    plain = tritools.triangulate_many(probs, robust=4.0)
    assert len(fast) == len(probs)
    for a, b, p in zip(fast, single, plain):
        for r in (b, p):
            assert a.status == r.status
            np.testing.assert_array_equal(a.inliers, r.inliers)
            assert a.gamma_ub == pytest.approx(r.gamma_ub, rel=1e-6)
            assert a.gamma_lb <= a.gamma_ub and (not a.optimal or r.optimal)


@pytest.mark.parametrize("pixel_scale", [1e-3, 1e6])
def test_pixel_scales_and_georeferenced_world(pixel_scale):
    """Pixel units rescaled (cameras, points and threshold alike) and the world moved by 1e6: the same inlier set
    and certificate, gamma_ub scaled by the pixel scale."""
    cams, x, X, out = _scene(6, 1, 12)
    ref = tritools.triangulate(cams, x, robust=10.0)
    A = np.diag([pixel_scale, pixel_scale, 1.0])
    T = np.eye(4)
    T[:3, 3] = -np.array([4e6, -2e6, 1e6])
    res = tritools.triangulate(A @ cams @ T, x * pixel_scale, robust=10.0 * pixel_scale)
    assert ref.optimal and res.optimal and " 0 nodes" in ref.message
    np.testing.assert_array_equal(res.inliers, ref.inliers)
    assert not res.inliers[out].any()
    assert res.gamma_ub == pytest.approx(ref.gamma_ub * pixel_scale, rel=1e-5)


def test_duplicated_wrong_match_and_two_views():
    """A wrong match in two copies of one view (two suspects at the same point): certified with both copies out;
    a two-view track (the stage does not apply) still certified."""
    cams, x, X, _ = _scene(4, 0, 13)
    cams, x = np.concatenate([cams, cams[:1]]), np.concatenate([x, x[:1]])
    x[[0, 4]] += [180.0, -240.0]
    res = tritools.triangulate(cams, x, robust=8.0)
    assert res.optimal and res.inliers.tolist() == [False, True, True, True, False]
    f_ref = _enumerated(cams, x, np.full(5, 8.0), X)
    assert 2 * 5 * res.gamma_lb ** 2 <= f_ref * (1 + 1e-9) + 1e-9
    two = tritools.triangulate(cams[1:3], x[1:3], robust=8.0)
    assert two.optimal and two.inliers.all()


def test_drive_restores_the_garbage_collector(monkeypatch):
    """A drive of many searches pauses the cyclic collector and restores its state after (enabled or not), also
    when a search fails."""
    import gc

    import tritools.solve.robust_drive as rd

    monkeypatch.setattr(rd, "GC_PAUSE_FROM", 2)
    monkeypatch.setattr("tritools.solve.robust_enum.ENUM_MAX_VIEWS", 0)     # batches of few views enumerate first
    monkeypatch.setattr("tritools.solve.robust_batch.BATCH_ENUM_MAX_VIEWS", 0)
    cams, x, _, _ = _scene(4, 1, 14)
    probs = [(cams, x), (cams, x[:3]), (cams, x)]            # the middle one is malformed: invalid_input
    seen = []
    real = rd.compute_many
    monkeypatch.setattr(rd, "compute_many", lambda req: seen.append(gc.isenabled()) or real(req))
    assert gc.isenabled()
    res = tritools.triangulate_many(probs, robust=10.0)
    assert gc.isenabled() and seen and not any(seen)
    assert res[1].status == tritools.Status.INVALID_INPUT and res[0].optimal and res[2].optimal
    gc.disable()
    try:
        tritools.triangulate_many(probs, robust=10.0)
        assert not gc.isenabled()
    finally:
        gc.enable()


@pytest.mark.parametrize("seed,N", [(700, 30), (701, 40)])
def test_one_view_with_a_far_lower_threshold_is_settled_by_the_suspect_stage(seed, N):
    """Review 8 F4: a clean track, c = 5 px, but one view's threshold at half its own L2 residual (so it is the
    optimum's one outlier).  The pairs cannot bound "that view kept an inlier" (the root is capped at its c_j^2);
    the group bound of all views over the X that keep it does.  Certified at the root (0 nodes) with the value of
    the independent reference: c_j^2 + the multi-start L2 minimum of the other views (an attained value)."""
    from tests.robust_refs import l2_min

    sc = random_scene(N, 1, noise_px=1.0, seed=seed)
    cams, x, X = sc.cameras, sc.points2d[0], sc.points3d[0]
    l2 = tritools.triangulate(cams, x)
    j = int(np.argsort(l2.residuals)[N // 2])
    c = np.full(N, 5.0)
    c[j] = 0.5 * l2.residuals[j]
    r = tritools.triangulate(cams, x, robust=c, time_limit=30)
    rest = [i for i in range(N) if i != j]
    f_ref = c[j] ** 2 + l2_min(cams[rest], x[rest], [X, l2.X])
    assert r.optimal and " 0 nodes" in r.message, r.message
    assert not r.inliers[j] and r.inliers.sum() == N - 1
    assert 2 * N * r.gamma_lb ** 2 <= f_ref * (1 + 1e-9)
    assert 2 * N * r.gamma_ub ** 2 == pytest.approx(f_ref, rel=1e-6)
