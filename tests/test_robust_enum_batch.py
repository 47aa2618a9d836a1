"""Batches through the enumeration of every inlier set (tritools.solve.robust_enum_run.enumerate_many).

Every batch result is checked against single calls of the same problems and against an independent reference:
the TLS value by inlier-set enumeration with multi-start scipy least squares (tests/robust_refs.py, an attained
value, so a lower bound above it is wrong), never against the code's earlier output."""
from __future__ import annotations

import numpy as np
import pytest

import tritools
import tritools.solve.robust_enum as enum_mod
from tritools.scene import robust_protocol_scene
from tests.robust_refs import outlier_track, tls_by_subsets


def _assert_valid(res, cams, x, c, X_true):
    """lb <= the enumerated reference; certified results reach it; the reported inliers are d < c."""
    N = len(x)
    ref = tls_by_subsets(cams, x, c, [X_true, X_true + 0.3, X_true - 0.3] + ([res.X] if res.X is not None else []))
    assert res.gamma_lb <= res.gamma_ub
    assert 2 * N * res.gamma_lb ** 2 <= ref * (1 + 1e-9) + 1e-300
    if res.optimal:
        assert 2 * N * res.gamma_ub ** 2 <= ref * (1 + 1e-6) + 1e-300
    np.testing.assert_array_equal(res.inliers, res.residuals < c)


def _same_as_single(batch, cams, x, c):
    """A batch row decides as the single call: certificate, inlier set and value."""
    one = tritools.triangulate(cams, x, robust=c)
    assert bool(batch.optimal) == bool(one.optimal)
    np.testing.assert_array_equal(batch.inliers, one.inliers)
    assert batch.gamma_ub == pytest.approx(one.gamma_ub, rel=1e-6)
    return one


def _mixed_batch(seed: int):
    """Protocol scenes (c = 200 px) and random_scene tracks (c = 20 px, 40-400 px wrong matches) of 2..9 views,
    clean and with outliers, one per-view threshold array."""
    rng = np.random.default_rng(seed)
    probs, cs, truth = [], [], []
    for N, k, noise in [(3, 0, 1.0), (3, 1, 1.0), (4, 1, 5.0), (5, 2, 1.0), (6, 0, 5.0), (6, 2, 1.0), (7, 3, 1.0),
                        (8, 2, 5.0), (2, 0, 1.0), (9, 2, 1.0)]:
        P, obs, X, _ = robust_protocol_scene(N, k, noise, rng)
        probs.append((P, obs))
        cs.append(np.full(N, 200.0))
        truth.append(X)
    for N, k, s in [(3, 1, 1), (5, 1, 2), (6, 2, 3), (4, 0, 4)]:
        cams, x, X, _ = outlier_track(N, k, s + 10 * seed)
        probs.append((cams, x))
        cs.append(np.geomspace(10.0, 40.0, N))          # per-view thresholds
        truth.append(X)
    return probs, cs, truth


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1])
def test_mixed_batch_agrees_with_single_calls_and_the_reference(seed):
    """A batch of 2..9 views, clean and outlier tracks, scalar and per-view thresholds: the 2..8-view problems are
    enumerated in the batch (two views since wave 19), every row decides as its single call, every certified row
    reaches the enumerated reference and no lower bound is above it (the reference for N <= 6)."""
    probs, cs, truth = _mixed_batch(seed)
    res = tritools.triangulate_many(probs, robust=cs)
    for (cams, x), c, X, r in zip(probs, cs, truth, res):
        N = len(x)
        assert r.optimal
        _same_as_single(r, cams, x, c)
        if N <= 6:
            _assert_valid(r, cams, x, c, X)
    enumerated = sum(enum_mod.ENUMERATED in m for m in res.message)
    assert enumerated >= 10                               # most few-view rows decided by the stacked enumeration
    assert all(enum_mod.ENUMERATED in m for m, (_, x) in zip(res.message, probs) if len(x) == 2)


def test_clean_tracks_take_the_one_row_path_and_outliers_are_dropped():
    """Clean tracks in a batch are certified by the bound of all views (one row: 1 L2 sub-problem each); tracks
    with one wrong match drop exactly it; the lower bounds stay below the enumerated reference."""
    probs, truth, outs = [], [], []
    for s in range(6):
        cams, x, X, out = outlier_track(5, s % 2, 40 + s)
        probs.append((cams, x))
        truth.append(X)
        outs.append(out)
    res = tritools.triangulate_many(probs, robust=10.0)
    for (cams, x), X, out, r in zip(probs, truth, outs, res):
        assert r.optimal and enum_mod.ENUMERATED in r.message
        assert not r.inliers[out].any() and r.inliers.sum() == 5 - len(out)
        if not len(out):
            assert "1 L2 sub-problems" in r.message
        _assert_valid(r, cams, x, np.full(5, 10.0), X)


@pytest.mark.parametrize("pixel_scale", [1e-3, 1e6])
def test_pixel_scales(pixel_scale):
    """Image units times 1e-3 and 1e6 (thresholds alike): the batch is certified, drops the wrong matches, agrees
    with single calls and stays below the reference."""
    rng = np.random.default_rng(17)
    A = np.diag([pixel_scale, pixel_scale, 1.0])
    probs, truth, outs = [], [], []
    for N, k in [(3, 1), (5, 2), (6, 1), (4, 0)]:
        P, obs, X, out = robust_protocol_scene(N, k, 1.0, rng)
        probs.append((np.einsum("ij,njk->nik", A, P), obs * pixel_scale))
        truth.append(X)
        outs.append(out)
    c = 200.0 * pixel_scale
    res = tritools.triangulate_many(probs, robust=c)
    for (cams, x), X, out, r in zip(probs, truth, outs, res):
        assert r.optimal and enum_mod.ENUMERATED in r.message
        np.testing.assert_array_equal(r.inliers, ~out)
        _same_as_single(r, cams, x, c)
        _assert_valid(r, cams, x, np.full(len(x), c), X)


def test_georeferenced_world_and_duplicated_views():
    """Cameras in a georeferenced world (5e6 m offsets; each problem re-centred on its own cameras): the same
    inlier sets and values as the local frame, X shifted.  A duplicated view (no epipolar constraint between the
    copies) and a degenerate problem (every camera the same) in the same batch: valid bounds, the others
    unaffected."""
    rng = np.random.default_rng(23)
    T = np.eye(4)
    t = np.array([5e6, -3e6, 1e5])
    T[:3, 3] = -t
    local, geo, truth = [], [], []
    for N, k in [(3, 1), (5, 1), (7, 2), (8, 3)]:
        P, obs, X, _ = robust_protocol_scene(N, k, 1.0, rng)
        local.append((P, obs))
        geo.append((P @ T, obs))
        truth.append(X)
    P, obs, Xd, out = robust_protocol_scene(4, 1, 1.0, rng)
    dup = (np.concatenate([P, P[:1]]), np.concatenate([obs, obs[:1]]))
    same = (np.repeat(P[:1], 3, axis=0), obs[:3])
    res_local = tritools.triangulate_many(local, robust=200.0)
    res = tritools.triangulate_many(geo + [dup, same], robust=200.0)
    for a, b in zip(res_local, res[:4]):
        assert a.optimal and b.optimal and enum_mod.ENUMERATED in b.message
        np.testing.assert_array_equal(a.inliers, b.inliers)
        assert b.gamma_ub == pytest.approx(a.gamma_ub, rel=1e-6)
        np.testing.assert_allclose(b.X, a.X + t, rtol=0, atol=1e-5)
    _assert_valid(res[1], *geo[1], np.full(5, 200.0), truth[1] + t)
    _assert_valid(res[4], *dup, np.full(5, 200.0), Xd)
    assert res[5].gamma_lb is None or res[5].gamma_lb <= res[5].gamma_ub
    assert not res[5].optimal or res[5].inliers.sum() <= 1 or res[5].gamma_ub == 0.0


def test_points_with_missing_views_and_zero_noise():
    """triangulate_points with NaN (unseen) observations: every track of 3..8 seen views is enumerated inside the
    batch; exact data with one wrong match gives f* = c^2 exactly and X at the true point."""
    sc = tritools.scene.random_scene(8, 12, noise_px=0.0, seed=9)
    x = np.array(sc.points2d, float)
    rng = np.random.default_rng(3)
    for m in range(12):
        x[m, rng.choice(8, m % 5, replace=False)] = np.nan      # 8..4 seen views
    seen = np.isfinite(x[..., 0])
    wrong = [int(np.nonzero(seen[m])[0][0]) for m in range(12)]
    for m, v in enumerate(wrong):
        x[m, v] += [90.0, -70.0]
    res = tritools.triangulate_points(sc.cameras, x, robust=10.0)
    for m in range(12):
        r = res[m]
        n = int(seen[m].sum())
        assert r.optimal and enum_mod.ENUMERATED in r.message
        assert 2 * n * r.gamma_ub ** 2 == pytest.approx(100.0, rel=1e-9) and r.gamma_lb <= r.gamma_ub
        assert np.linalg.norm(r.X - sc.points3d[m]) < 1e-8


def test_time_limit_in_a_batch():
    """An expired per-problem time limit: no enumerated result, the search's time_limit statuses, valid bounds."""
    rng = np.random.default_rng(29)
    probs = [robust_protocol_scene(5, 1, 1.0, rng)[:2] for _ in range(3)]
    res = tritools.triangulate_many(probs, robust=200.0, time_limit=1e-9)
    full = tritools.triangulate_many(probs, robust=200.0)
    for r, f in zip(res, full):
        assert enum_mod.ENUMERATED not in r.message and not r.optimal
        assert r.status == tritools.Status.TIME_LIMIT
        assert r.gamma_lb is None or r.gamma_lb <= f.gamma_ub * (1 + 1e-9)


def test_one_failing_stack_never_decides_another_problem(monkeypatch):
    """A stack that raises (degenerate data) is retried problem by problem: the others are still enumerated."""
    import tritools.solve.robust_enum_run as run_mod

    rng = np.random.default_rng(31)
    probs = [robust_protocol_scene(5, 1, 1.0, rng)[:2] for _ in range(4)]
    real = run_mod._Group.run

    def run(self):
        if len(self.group) > 1:
            raise np.linalg.LinAlgError("a degenerate stack")
        return real(self)

    monkeypatch.setattr(run_mod._Group, "run", run)
    res = tritools.triangulate_many(probs, robust=200.0)
    assert all(r.optimal and enum_mod.ENUMERATED in r.message for r in res)


def test_the_orders_decide_alike(monkeypatch):
    """The staged order (batches) on single calls, and the open sets' candidates always computed (LATER_FROM = 0):
    the same certificates, inlier sets and values as the default single call, no lower bound above another
    order's value."""
    import tritools.solve.robust_enum_run as run_mod

    rng = np.random.default_rng(37)
    for N, k, noise in [(3, 1, 1.0), (4, 2, 5.0), (5, 2, 1.0), (6, 1, 5.0), (7, 3, 1.0), (8, 2, 1.0)]:
        P, x, _, _ = robust_protocol_scene(N, k, noise, rng)
        runs = [tritools.triangulate(P, x, robust=200.0)]
        for name, value in (("STAGED_FROM", 1), ("LATER_FROM", 0)):
            monkeypatch.setattr(run_mod, name, value)
            runs.append(tritools.triangulate(P, x, robust=200.0))
            monkeypatch.undo()
        for r in runs[1:]:
            assert r.optimal == runs[0].optimal
            np.testing.assert_array_equal(r.inliers, runs[0].inliers)
            assert r.gamma_ub == pytest.approx(runs[0].gamma_ub, rel=1e-6)
        assert all(a.gamma_lb <= b.gamma_ub * (1 + 1e-9) for a in runs for b in runs)
        assert runs[0].optimal               # (a random "outlier" within c of the projection is an inlier)
        np.testing.assert_array_equal(runs[0].inliers, runs[0].residuals < 200.0)
