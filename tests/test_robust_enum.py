"""The few-view TLS path (tritools.solve.robust_enum): every inlier set in one masked stack.

Every bound is checked against an independent reference -- multi-start scipy least squares per subset (an
attained value, so a bound above it is wrong), the TLS optimum as the minimum over inlier sets -- and against the
branch and bound with the enumeration switched off."""
from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.optimize import least_squares

import tritools
import tritools.solve.robust_enum as enum_mod
from tritools.scene import random_scene, robust_protocol_scene
from tritools.solve.robust import tls_cost

TOL = tritools.TriangulationOptions().tolerances


def _l2_local(cams, x, S, starts) -> tuple:
    """(min over starts of sum_{i in S} d_i^2 at a local minimiser, that minimiser)."""
    best, Xb = np.inf, None
    for X0 in starts:
        def res(X):
            u = np.einsum("nij,j->ni", cams[S], np.append(X, 1.0))
            return (u[:, :2] / u[:, 2:] - x[S]).ravel()
        sol = least_squares(res, X0, xtol=1e-14, ftol=1e-14, gtol=1e-14)
        f = float(np.sum(sol.fun ** 2))
        if f < best:
            best, Xb = f, sol.x
    return best, Xb


def _reference(cams, x, c, starts) -> float:
    """min over inlier sets of f_TLS at multi-start local L2 minimisers of the set, and the |S| <= 1 values
    min_i c^2(V - i) (>= the TLS optimum; equal to it when the starts find each set's minimum)."""
    N = len(x)
    c2 = np.asarray(c, float) ** 2
    best = min(float(np.sum(np.delete(c2, i))) for i in range(N))
    for k in range(2, N + 1):
        for S in map(list, itertools.combinations(range(N), k)):
            _, X = _l2_local(cams, x, S, starts + [np.mean(starts, axis=0)])
            u = np.einsum("nij,j->ni", cams, np.append(X, 1.0))
            best = min(best, tls_cost(np.linalg.norm(u[:, :2] / u[:, 2:] - x, axis=1), c))
    return best


def _rescaled(cams, x, s):
    """The same scene in pixel units times s (cameras' image rows and the points)."""
    A = np.diag([s, s, 1.0])
    return np.einsum("ij,njk->nik", A, cams), x * s


def _check(res, cams, x, c, X_true, enumerated=True):
    N = len(x)
    f_ref = _reference(cams, x, c, [X_true, X_true + 0.2, X_true - 0.2])
    f_lb, f_ub = 2 * N * res.gamma_lb ** 2, 2 * N * res.gamma_ub ** 2
    assert f_lb <= f_ref * (1 + 1e-9) + 1e-300, (f_lb, f_ref)
    assert res.gamma_lb <= res.gamma_ub
    d = np.linalg.norm(np.einsum("nij,j->ni", cams, np.append(res.X, 1.0))[:, :2]
                       / np.einsum("nij,j->ni", cams, np.append(res.X, 1.0))[:, 2:] - x, axis=1)
    assert f_ub == pytest.approx(tls_cost(d, c), rel=1e-9)
    np.testing.assert_array_equal(res.inliers, d < c)
    if res.optimal:
        assert f_ub <= f_ref * (1 + 1e-6), (f_ub, f_ref)      # certified: it reached the reference optimum
    assert (enum_mod.ENUMERATED in res.message) == enumerated
    return f_ref


@pytest.mark.parametrize("pixel_scale", [1e-3, 1.0, 1e6])
@pytest.mark.parametrize("N, n_out", [(3, 1), (5, 2), (7, 2)])
def test_subset_bounds_below_every_subset_optimum(N, n_out, pixel_scale):
    """Every subset's bound after the closure, L(S) <= L2*(S) (multi-start reference, wrong matches included), at
    pixel scales 1e-3..1e6; the subsets without a wrong match are tight (1e-6 relative)."""
    rng = np.random.default_rng([N, n_out, 11])
    P, obs, X, out = robust_protocol_scene(N, n_out, 1.0, rng)
    cams, x = _rescaled(P, obs, pixel_scale)
    norm, Cn = enum_mod.enum_frame(cams, x)
    W = enum_mod.subset_masks(N)
    Xn = enum_mod.enum_candidates(Cn, W)
    lb, accepted = enum_mod.enum_bounds(cams, Cn, W, Xn, norm.scale, TOL)
    F, defined, E = enum_mod.fundamentals(cams[None], Cn[None])
    M = len(W)
    only, none = enum_mod.enum_bounds_rows(np.broadcast_to(Cn, (M,) + Cn.shape),
                                           np.broadcast_to(F[0], (M,) + F.shape[1:]),
                                           np.broadcast_to(defined[0], (M,) + defined.shape[1:]), W, Xn,
                                           np.full(M, norm.scale), TOL, accepted=False,
                                           errors=np.broadcast_to(E[0], (M,) + E.shape[1:]))
    assert none is None and np.array_equal(only, lb)          # the enumeration's call: the same bounds
    bits = W.astype(np.int64) @ (1 << np.arange(N))
    table = np.zeros(1 << N)
    table[bits] = lb
    L = enum_mod.closure(N, table)[bits]
    assert np.all(L >= lb)
    clean_tight = 0
    for m, row in enumerate(W):
        S = np.nonzero(row)[0].tolist()
        ref, _ = _l2_local(cams, x, S, [X, X + 0.2, X - 0.2, norm.world_point(Xn[m])])
        assert L[m] <= ref * (1 + 1e-9) + 1e-300, (S, L[m], ref)
        if not out[S].any():
            assert L[m] == pytest.approx(ref, rel=1e-6, abs=1e-12 * pixel_scale ** 2)
            clean_tight += 1
    assert clean_tight >= 1


@pytest.mark.slow
@pytest.mark.parametrize("pixel_scale", [1e-3, 1e6])
@pytest.mark.parametrize("N, n_out", [(3, 1), (5, 2), (7, 3)])
def test_certified_at_every_pixel_scale(N, n_out, pixel_scale):
    """The protocol scene with image units times 1e-3 and 1e6 (thresholds alike): enumerated, certified, the
    reference optimum reached, the lower bound below it, the ground-truth inlier set."""
    rng = np.random.default_rng([N, n_out, 5])
    P, obs, X, out = robust_protocol_scene(N, n_out, 1.0, rng)
    cams, x = _rescaled(P, obs, pixel_scale)
    c = np.full(N, 200.0 * pixel_scale)
    res = tritools.triangulate(cams, x, robust=c)
    assert res.optimal and res.status == tritools.Status.OPTIMAL
    _check(res, cams, x, c, X)
    np.testing.assert_array_equal(res.inliers, ~out)


@pytest.mark.parametrize("seed", range(4))
def test_same_result_as_the_branch_and_bound(seed, monkeypatch):
    """Protocol scenes at N = 3, 5, 7, 8 with 0-3 wrong matches, 1 and 5 px: the enumeration and the branch and bound
    (enumeration off) agree on certification, inlier set and gamma_ub; both lower bounds below the reference."""
    rng = np.random.default_rng([seed, 23])
    limit = enum_mod.ENUM_MAX_VIEWS
    for N, n_out, noise in [(3, 1, 1.0), (5, 1, 5.0), (5, 2, 1.0), (7, 0, 1.0), (7, 3, 5.0), (8, 2, 1.0)]:
        P, x, X, out = robust_protocol_scene(N, n_out, noise, rng)
        res = tritools.triangulate(P, x, robust=200.0)
        monkeypatch.setattr(enum_mod, "ENUM_MAX_VIEWS", 0)
        bb = tritools.triangulate(P, x, robust=200.0)
        monkeypatch.setattr(enum_mod, "ENUM_MAX_VIEWS", limit)
        assert enum_mod.ENUMERATED not in bb.message
        assert bb.optimal and res.optimal
        np.testing.assert_array_equal(res.inliers, bb.inliers)
        assert res.gamma_ub == pytest.approx(bb.gamma_ub, rel=1e-6)
        if seed == 0 and N <= 7:
            c = np.full(N, 200.0)
            f_ref = _check(res, P, x, c, X, enumerated=enum_mod.ENUMERATED in res.message)
            assert 2 * N * bb.gamma_lb ** 2 <= f_ref * (1 + 1e-9)


def test_georeferenced_world_zero_noise_and_duplicated_views():
    """A georeferenced world (5e6 m offsets): the same inlier set and value as the local frame.  Exact data with
    one wrong match: f* = c^2 exactly.  A duplicated view (same camera and observation: its pairs carry no epipolar
    constraint): valid bounds, the wrong match dropped."""
    rng = np.random.default_rng(31)
    P, x, X, out = robust_protocol_scene(6, 2, 1.0, rng)
    ref = tritools.triangulate(P, x, robust=200.0)
    t = np.array([5e6, -3e6, 1e5])
    T = np.eye(4)
    T[:3, 3] = -t
    geo = tritools.triangulate(P @ T, x, robust=200.0)
    assert ref.optimal and geo.optimal and enum_mod.ENUMERATED in geo.message
    np.testing.assert_array_equal(geo.inliers, ref.inliers)
    assert geo.gamma_ub == pytest.approx(ref.gamma_ub, rel=1e-6)
    np.testing.assert_allclose(geo.X, ref.X + t, rtol=0, atol=1e-5)
    _check(geo, P @ T, x, np.full(6, 200.0), X + t)

    sc = random_scene(5, 1, noise_px=0.0, seed=6)
    x0 = sc.points2d[0].copy()
    x0[1] += [80.0, -60.0]
    r = tritools.triangulate(sc.cameras, x0, robust=10.0)
    assert r.optimal and r.inliers.tolist() == [True, False, True, True, True]
    assert 2 * 5 * r.gamma_ub ** 2 == pytest.approx(100.0, rel=1e-9) and r.gamma_lb <= r.gamma_ub
    assert np.linalg.norm(r.X - sc.points3d[0]) < 1e-9

    P, x, X, out = robust_protocol_scene(4, 1, 1.0, np.random.default_rng(32))
    Pd, xd = np.concatenate([P, P[:1]]), np.concatenate([x, x[:1]])
    res = tritools.triangulate(Pd, xd, robust=200.0)
    _check(res, Pd, xd, np.full(5, 200.0), X, enumerated=enum_mod.ENUMERATED in res.message)
    assert not res.inliers[np.nonzero(out)[0]].any() or not res.optimal


def test_thresholds_inf_tiny_and_per_view():
    """An infinite threshold keeps its view (the wrong match there is an inlier); tiny thresholds (every view an
    outlier but one: the optimum sits on a view's ray, which the enumeration hands to the search); per-view
    thresholds -- every bound below the reference."""
    rng = np.random.default_rng(41)
    P, x, X, out = robust_protocol_scene(5, 1, 1.0, rng)
    w = int(np.nonzero(out)[0][0])
    c = np.full(5, 200.0)
    c[w] = np.inf
    res = tritools.triangulate(P, x, robust=c)
    assert res.inliers[w] and res.gamma_lb <= res.gamma_ub
    assert 2 * 5 * res.gamma_lb ** 2 <= _reference(P, x, c, [X, X + 0.2]) * (1 + 1e-9)
    tiny = tritools.triangulate(P, x, robust=1e-3)
    _check(tiny, P, x, np.full(5, 1e-3), X, enumerated=False)
    assert tiny.inliers.sum() <= 1
    per = np.array([5.0, 50.0, 200.0, 1e4, 2.0])
    r = tritools.triangulate(P, x, robust=per)
    _check(r, P, x, per, X, enumerated=enum_mod.ENUMERATED in r.message)


def test_closure_is_superadditive_and_never_raises_a_bound_above_its_parts():
    """closure(): L(S) = max(own, L(T) + L(S - T)) rounded down, by increasing size; |S| <= 1 stays 0."""
    N = 4
    table = np.zeros(1 << N)
    table[0b0011], table[0b1100], table[0b0101] = 3.0, 4.0, 1.0
    L = enum_mod.closure(N, table)
    assert L[0b1111] == pytest.approx(7.0, rel=1e-11) and L[0b1111] < 7.0
    assert L[0b0111] == pytest.approx(3.0, rel=1e-11) and L[0b1101] == pytest.approx(4.0, rel=1e-11)
    assert all(L[1 << i] == 0.0 for i in range(N)) and L[0] == 0.0


def test_masked_candidates_are_the_subset_problems():
    """A masked row's candidate is the L2 estimate of its subset alone (the masked views take no part)."""
    rng = np.random.default_rng(51)
    P, x, X, out = robust_protocol_scene(5, 2, 1.0, rng)
    norm, Cn = enum_mod.enum_frame(P, x)
    W = enum_mod.subset_masks(5)
    Xn = enum_mod.enum_candidates(Cn, W)
    assert np.isfinite(Xn).all()
    for m in (0, 5, 12, len(W) - 1):
        S = np.nonzero(W[m])[0].tolist()
        ref, Xr = _l2_local(P, x, S, [X, norm.world_point(Xn[m])])
        Xm = norm.world_point(Xn[m])
        u = np.einsum("nij,j->ni", P[S], np.append(Xm, 1.0))
        f = float(np.sum((u[:, :2] / u[:, 2:] - x[S]) ** 2))
        assert f == pytest.approx(ref, rel=1e-4, abs=1e-6)


def test_time_limit_and_degenerate_data_go_to_the_search():
    """An expired time limit: no enumeration, the search's time_limit status with valid bounds.  Two views are
    enumerated (tests/test_robust_two_views.py), unless the search itself was asked for."""
    rng = np.random.default_rng(61)
    P, x, X, out = robust_protocol_scene(5, 1, 1.0, rng)
    timed = tritools.triangulate(P, x, robust=200.0, time_limit=1e-9)
    assert timed.status == tritools.Status.TIME_LIMIT and enum_mod.ENUMERATED not in timed.message
    assert timed.gamma_lb <= timed.gamma_ub
    two = tritools.triangulate(P[:2], x[:2], robust=200.0)
    assert enum_mod.ENUMERATED in two.message and two.optimal
    timed2 = tritools.triangulate(P[:2], x[:2], robust=200.0, time_limit=1e-9)
    assert enum_mod.ENUMERATED not in timed2.message and timed2.gamma_lb <= timed2.gamma_ub


@pytest.mark.parametrize("baseline", [1e-2, 1e-4])
def test_tiny_baselines(baseline, monkeypatch):
    """Camera centres within ``baseline`` (the point ~2 away) and one wrong match: the enumeration's bounds and
    the branch and bound's cross-check (neither lower bound above the other's value), both certified, and the
    enumeration's value within 1e-9 of the search's (its estimate finished by an undamped Gauss-Newton step)."""
    from tritools.scene import PROTOCOL_K

    rng = np.random.default_rng(7)
    for N in (3, 5, 7):
        c0 = np.array([0.0, 0.0, -2.0])
        P = np.array([PROTOCOL_K @ np.hstack([np.eye(3), -(c0 + baseline * rng.normal(size=3))[:, None]])
                      for _ in range(N)])
        X = rng.uniform(-0.5, 0.5, 3)
        h = P @ np.append(X, 1.0)
        x = h[:, :2] / h[:, 2:] + 0.1 * rng.normal(size=(N, 2))
        x[0] += [150.0, 80.0]
        res = tritools.triangulate(P, x, robust=20.0)
        monkeypatch.setattr(enum_mod, "ENUM_MAX_VIEWS", 0)
        bb = tritools.triangulate(P, x, robust=20.0)
        monkeypatch.undo()
        assert enum_mod.ENUMERATED in res.message and res.optimal and bb.optimal
        assert res.gamma_lb <= bb.gamma_ub * (1 + 1e-12) and bb.gamma_lb <= res.gamma_ub * (1 + 1e-12)
        assert res.gamma_ub == pytest.approx(bb.gamma_ub, rel=1e-9)
        np.testing.assert_array_equal(res.inliers, bb.inliers)
        assert not res.inliers[0]


def test_deadline_between_the_stacks(monkeypatch):
    """A deadline that passes during the enumeration (the first candidate stack made slow): no enumerated result,
    the search's time_limit status, the enumeration's candidate as the estimate and valid bounds."""
    import time as _time

    rng = np.random.default_rng(71)
    P, x, X, out = robust_protocol_scene(5, 1, 1.0, rng)
    full = tritools.triangulate(P, x, robust=200.0)
    real = enum_mod.enum_candidates
    monkeypatch.setattr(enum_mod, "enum_candidates", lambda Cn, W, steps=None: _time.sleep(0.3) or real(Cn, W, steps))
    res = tritools.triangulate(P, x, robust=200.0, time_limit=0.2)
    assert res.status == tritools.Status.TIME_LIMIT and not res.optimal
    assert enum_mod.ENUMERATED not in res.message
    assert res.gamma_lb <= full.gamma_ub * (1 + 1e-9) and res.gamma_lb <= res.gamma_ub
    assert res.gamma_ub == pytest.approx(full.gamma_ub, rel=1e-6)     # the candidate found before the deadline


def test_floor_scale_never_above_the_decision_scale():
    """The enumeration decides at robust.scale_from(SCALE_BOUNDS[1], c^2) and relies on its being at most the
    documented decision_scale (the normalisation clips its image scale to SCALE_BOUNDS): checked on zero-noise,
    1e-3 and 1e6 pixel-scale, georeferenced and clean/outlier scenes, scalar and per-view thresholds."""
    from tritools.model.normalize import SCALE_BOUNDS
    from tritools.model.regions import Point
    from tritools.solve.robust import decision_scale, scale_from

    rng = np.random.default_rng(81)
    T = np.eye(4)
    T[:3, 3] = -np.array([5e6, -3e6, 1e5])
    for N, n_out, noise in [(3, 0, 0.0), (5, 1, 1.0), (7, 3, 5.0)]:
        P, x, X, out = robust_protocol_scene(N, n_out, noise, rng)
        for cams, pts in [(P, x), _rescaled(P, x, 1e-3), _rescaled(P, x, 1e6), (P @ T, x)]:
            for c in (np.full(N, 200.0), np.geomspace(1e-3, 1e4, N), np.append(np.full(N - 1, np.inf), 2.0)):
                c2 = c * c
                assert scale_from(SCALE_BOUNDS[1], c2) <= decision_scale(cams, [Point(p) for p in pts], c2)


def test_first_of_runs_equals_numpy_unique_on_sorted_keys():
    """robust_enum.first_of_runs (the best row of each problem in a stack): np.unique's return_index on sorted
    keys, empty and single-run arrays included."""
    import numpy as np

    from tritools.solve.robust_enum import first_of_runs as _first_of_runs

    rng = np.random.default_rng(0)
    for _ in range(500):
        a = np.sort(rng.integers(0, rng.integers(1, 10), size=rng.integers(0, 30)))
        assert np.array_equal(_first_of_runs(a), np.unique(a, return_index=True)[1])


@pytest.mark.parametrize("by_size", [False, True])
def test_precomputed_f_errors_reach_their_pairs(by_size):
    """F's proven errors are computed once per problem (:func:`fundamentals`) and gathered per subset: an error of
    inf on the pair (0, 1) only costs the bounds of the subsets holding both views 0 and 1 (their bound drops to
    0); every other subset keeps the bound it has with the finite errors."""
    N = 4
    rng = np.random.default_rng(5)
    P, obs, X, out = robust_protocol_scene(N, 0, 1.0, rng)
    norm, Cn = enum_mod.enum_frame(P, obs)
    W = enum_mod.subset_masks(N)
    Xn = enum_mod.enum_candidates(Cn, W)
    F, defined, E = enum_mod.fundamentals(P[None], Cn[None])
    assert np.isfinite(E).all() and (E > 0).all()
    M = len(W)
    args = (np.broadcast_to(Cn, (M,) + Cn.shape), F, defined, W, Xn, np.full(M, norm.scale), TOL)
    problem = np.zeros(M, int)
    lb, _ = enum_mod.enum_bounds_rows(*args, problem=problem, by_size=by_size, accepted=False, errors=E)
    bad = E.copy()
    bad[0, 0] = np.inf                                   # view_pairs(4)[0] is the pair (0, 1)
    lb_bad, _ = enum_mod.enum_bounds_rows(*args, problem=problem, by_size=by_size, accepted=False, errors=bad)
    both = W[:, 0] & W[:, 1]
    assert (lb[both] > 0).all() and (lb_bad[both] == 0).all()
    assert np.array_equal(lb_bad[~both], lb[~both])
