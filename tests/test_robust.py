"""Certified truncated least squares (``robust=``): bounds against subset enumeration, inlier sets, the L2 limit,
bad input.  The reference TLS value enumerates every inlier set S and evaluates f_TLS at a multi-start local L2
minimiser of S (scipy, independent of tritools' solvers): an *upper* bound of the TLS optimum, so no reported
lower bound may exceed it and a certified value must reach it."""
import itertools
import math

import numpy as np
import pytest
from scipy.optimize import least_squares, minimize

import tritools
from tritools.scene import random_scene
from tritools.solve.robust import lookahead_bound, robust_thresholds, tls_cost


def _project(X, P):
    u = P @ np.append(X, 1.0)
    return u[:2] / u[2]


def _residuals(X, cams, regions):
    return np.array([r.distance(_project(X, P)) for P, r in zip(cams, regions)])


def _l2_local(cams, regions, starts):
    """Best local L2 minimiser of the sub-problem from several starts (upper bound of L2*)."""
    pts = all(isinstance(r, tritools.Point) for r in regions)
    best = None
    for X0 in starts:
        if pts:
            x = np.array([r.center for r in regions])
            sol = least_squares(lambda X: np.concatenate([_project(X, P) - xi for P, xi in zip(cams, x)]), X0,
                                xtol=1e-14, ftol=1e-14, gtol=1e-14)
            X = sol.x
        else:                   # per-view distances (non-smooth at 0, so a polish by Nelder-Mead follows)
            X = least_squares(lambda X: _residuals(X, cams, regions), X0, xtol=1e-12, ftol=1e-12).x
            X = minimize(lambda X: np.sum(_residuals(X, cams, regions) ** 2), X, method="Nelder-Mead",
                         options=dict(xatol=1e-9, fatol=1e-12, maxiter=300)).x
        if best is None or np.sum(_residuals(X, cams, regions) ** 2) < np.sum(_residuals(best, cams, regions) ** 2):
            best = X
    return best


def reference_tls(cams, regions, c, starts):
    """min over inlier sets of f_TLS at a local L2 minimiser of the set: an upper bound of min f_TLS, with the
    set and point attaining it."""
    N = len(regions)
    best = (np.inf, None)
    for k in range(2, N + 1):
        for S in itertools.combinations(range(N), k):
            X = _l2_local(cams[list(S)], [regions[i] for i in S], starts)
            f = tls_cost(_residuals(X, cams, regions), c)
            if f < best[0]:
                best = (f, X)
    return best


def outlier_scene(N, n_out, seed, noise=1.0, shift=(200.0, 600.0)):
    sc = random_scene(N, 1, noise_px=noise, seed=seed)
    rng = np.random.default_rng(seed + 1000)
    x = sc.points2d[0].copy()
    out = rng.choice(N, n_out, replace=False)
    ang = rng.uniform(0, 2 * np.pi, n_out)
    x[out] += rng.uniform(*shift, n_out)[:, None] * np.stack([np.cos(ang), np.sin(ang)], 1)
    return sc.cameras, x, sc.points3d[0], out


def _check_against_reference(res, cams, regions, c, X_true):
    N = len(regions)
    starts = [X_true, X_true + 0.3, X_true - 0.3, np.zeros(3)]
    f_ref, _ = reference_tls(cams, regions, c, starts)
    f_lb = 2 * N * res.gamma_lb ** 2
    f_ub = 2 * N * res.gamma_ub ** 2
    assert f_lb <= f_ref * (1 + 1e-9) + 1e-9, (f_lb, f_ref)
    assert res.gamma_lb <= res.gamma_ub
    # the reported upper bound is f_TLS at the reported X, and the inlier set its
    d = _residuals(res.X, cams, regions)
    assert f_ub == pytest.approx(tls_cost(d, c), rel=1e-9, abs=1e-9)
    np.testing.assert_array_equal(res.inliers, d < c)
    if res.optimal:
        assert f_ub <= f_ref * (1 + 1e-6) + 1e-9, (f_ub, f_ref)
    return f_ref


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("N", [3, 4, 6])
def test_points_bounds_against_enumeration(N, seed):
    n_out = [0, 1, N // 2][seed % 3]
    cams, x, X, _ = outlier_scene(N, n_out, seed)
    c = 8.0 if seed % 2 else 30.0
    res = tritools.triangulate(cams, x, robust=c)
    _check_against_reference(res, cams, [tritools.Point(p) for p in x], np.full(N, c), X)
    assert res.status in (tritools.Status.OPTIMAL, tritools.Status.NOT_CERTIFIED)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(4))
def test_points_bounds_against_enumeration_8_views(seed):
    cams, x, X, _ = outlier_scene(8, 3, seed, noise=2.0)
    c = np.full(8, 10.0)
    res = tritools.triangulate(cams, x, robust=c)
    _check_against_reference(res, cams, [tritools.Point(p) for p in x], c, X)
    assert res.optimal


def test_threshold_near_residuals_never_overclaims():
    """Thresholds at the noise level make many inlier sets nearly equal: whatever is certified must hold."""
    for seed in range(4):
        cams, x, X, _ = outlier_scene(5, 1, seed, noise=3.0)
        c = np.full(5, 4.0)
        res = tritools.triangulate(cams, x, robust=c)
        _check_against_reference(res, cams, [tritools.Point(p) for p in x], c, X)


@pytest.mark.parametrize("N,seed", [(3, 0)] + [pytest.param(4, s, marks=pytest.mark.slow) for s in range(3)])
def test_other_regions_bounds_against_enumeration(N, seed):
    """Segments and ellipses (distance 0 inside): the sub-bounds come from the SDP path."""
    cams, x, X, out = outlier_scene(N, 1, seed, noise=1.0)
    rng = np.random.default_rng(seed)
    regions = []
    for i, p in enumerate(x):
        if i % 2:
            regions.append(tritools.Segment(p, rng.normal(size=2) * 2.0))
        else:
            regions.append(tritools.Ellipse(p, np.diag([4.0, 1.0])))
    c = np.full(N, 20.0)
    res = tritools.triangulate(cams, regions, robust=c)
    _check_against_reference(res, cams, regions, c, X)
    assert res.optimal
    assert not res.inliers[out].any()


def test_inlier_set_recovered():
    cams, x, X, out = outlier_scene(7, 3, 11, noise=1.0, shift=(300, 500))
    res = tritools.triangulate(cams, x, robust=20.0)
    assert res.optimal and res.status == tritools.Status.OPTIMAL
    truth = np.ones(7, bool)
    truth[out] = False
    np.testing.assert_array_equal(res.inliers, truth)
    assert np.linalg.norm(res.X - X) < 0.05
    # the L2 estimate of the same data is pulled away by the outliers
    l2 = tritools.triangulate(cams, x)
    assert np.linalg.norm(l2.X - X) > 5 * np.linalg.norm(res.X - X)


def test_infinite_threshold_is_the_l2_problem():
    cams, x, _, _ = outlier_scene(5, 1, 3)
    l2 = tritools.triangulate(cams, x)
    inf = tritools.triangulate(cams, x, robust=np.inf)
    np.testing.assert_allclose(inf.X, l2.X)
    assert inf.gamma_ub == l2.gamma_ub and inf.gamma_lb == l2.gamma_lb and inf.optimal == l2.optimal
    assert inf.inliers.all() and l2.inliers is None
    big = tritools.triangulate(cams, x, robust=1e6)         # every view an inlier: the L2 optimum
    assert big.optimal and big.inliers.all()
    np.testing.assert_allclose(big.X, l2.X, rtol=1e-6, atol=1e-9)
    assert big.gamma_ub == pytest.approx(l2.gamma_ub, rel=1e-9)


def test_scaled_pixels():
    """Rescaled image coordinates (1e-3 and 1e4 px) with rescaled thresholds: the same inlier set, certified."""
    cams, x, _, out = outlier_scene(5, 1, 4, noise=1.0, shift=(300, 400))
    ref = tritools.triangulate(cams, x, robust=20.0)
    for k in (1e-3, 1e4):
        S = np.diag([k, k, 1.0])
        res = tritools.triangulate(S @ cams, x * k, robust=20.0 * k)
        assert res.optimal
        np.testing.assert_array_equal(res.inliers, ref.inliers)
        assert res.gamma_ub == pytest.approx(k * ref.gamma_ub, rel=1e-6)
        assert res.gamma_lb <= res.gamma_ub


def test_per_view_thresholds_and_infinite_entries():
    cams, x, _, out = outlier_scene(5, 1, 5, noise=1.0, shift=(300, 400))
    c = np.full(5, 20.0)
    c[out[0]] = np.inf                       # that view can never be an outlier
    res = tritools.triangulate(cams, x, robust=c)
    assert res.inliers[out[0]]
    assert res.gamma_lb <= res.gamma_ub


@pytest.mark.parametrize("bad", [-1.0, 0.0, np.nan, "a", True, [1.0, 2.0], [[1.0]], None])
def test_bad_thresholds(bad):
    cams, x, _, _ = outlier_scene(3, 0, 0)
    if bad is None:
        assert tritools.triangulate(cams, x, robust=bad).inliers is None
        return
    with pytest.raises(ValueError, match="robust"):
        tritools.triangulate(cams, x, robust=bad)
    with pytest.raises(ValueError, match="robust"):
        robust_thresholds(bad, 3)


def test_result_json_round_trip():
    cams, x, _, _ = outlier_scene(4, 1, 6, shift=(300, 400))
    res = tritools.triangulate(cams, x, robust=20.0)
    back = tritools.TriangulationResult.from_dict(res.to_dict())
    np.testing.assert_array_equal(back.inliers, res.inliers)
    assert back.inliers.dtype == bool and back.gamma_lb == res.gamma_lb
    with pytest.raises(ValueError, match="inliers"):
        tritools.TriangulationResult("tls", "optimal", inliers=[0.5, 2.0])


def test_lookahead_bound_is_the_minimum():
    """The breakpoint rule against a dense grid."""
    rng = np.random.default_rng(0)
    for _ in range(50):
        a, c2 = rng.uniform(0, 10, 5), rng.uniform(0.5, 4, 5)
        lo, hi = sorted(rng.uniform(0, 8, 2))
        s = np.linspace(lo, hi, 20001)
        g = s + np.sum(np.minimum(c2[None], np.maximum(0, a[None] - s[:, None])), axis=1)
        assert lookahead_bound(lo, hi, a, c2) == pytest.approx(g.min(), abs=1e-3)
        assert lookahead_bound(lo, hi, a, c2) <= g.min() + 1e-12
    assert lookahead_bound(2.0, 1.0, np.ones(2), np.ones(2)) == np.inf


def test_triangulate_many_and_points():
    probs, outs = [], []
    for s in range(6):
        cams, x, _, out = outlier_scene(5, s % 2, s, shift=(300, 500))
        probs.append((cams, x))
        outs.append(out)
    many = tritools.triangulate_many(probs, robust=20.0)
    for (cams, x), r, out in zip(probs, many, outs):
        single = tritools.triangulate(cams, x, robust=20.0)
        np.testing.assert_array_equal(r.inliers, single.inliers)
        assert set(np.nonzero(~r.inliers)[0]) == set(out) and r.optimal
        assert r.gamma_ub == pytest.approx(single.gamma_ub, rel=1e-6)
    assert all(r.inliers is None for r in tritools.triangulate_many(probs[:2]))
    with pytest.raises(ValueError, match="robust"):
        tritools.triangulate_many(probs, robust=[1.0, 2.0])
    # one camera set, points as arrays, one view hidden
    cams = probs[0][0]
    pts = np.stack([probs[0][1], probs[0][1] + 1.0])
    pts[1, 0] = np.nan
    res = tritools.triangulate_points(cams, pts, robust=20.0)
    assert res.inliers.shape == (2, 5) and not res.inliers[1, 0]
    np.testing.assert_array_equal(res.inliers[0], many[0].inliers)
    assert res.optimal.all()
    with pytest.raises(ValueError, match="robust"):
        tritools.triangulate_points(cams, pts, robust=[1.0, 2.0])


def test_cli_solve_robust(tmp_path, capsys):
    from tests.cli_util import run, write

    from tritools.io.problem_file import problem_to_dict, problems_to_json

    cams, x, _, out = outlier_scene(5, 1, 7, shift=(300, 500))
    f = write(tmp_path, problems_to_json([problem_to_dict(cams, [tritools.Point(p) for p in x], "p")]))
    rc, stdout, _ = run(["solve", f, "--robust", "20", "--json"], capsys)
    assert rc == 0
    import json

    rec = json.loads(stdout)[0]
    assert rec["optimal"] and rec["inliers"] == [i not in out for i in range(5)]
    rc, stdout, _ = run(["solve", f, "--robust", "20"], capsys)
    assert rc == 0 and "4/5 inliers" in stdout
    rc, _, err = run(["solve", f, "--robust", "-3"], capsys)
    assert rc == 2 and "--robust" in err and len(err.strip().splitlines()) == 1


def test_cli_colmap_robust_round_trip(tmp_path, capsys):
    """Injected wrong matches leave the tracks (POINT3D_ID -1), nothing else does, the points get closer to the
    truth; the sidecar message and the JSON say how many observations went."""
    import json

    from tests.cli_util import run
    from tritools.io.colmap import read_model_arrays
    from tritools.io.colmap.formats import write_model_arrays
    from tritools.sfm.synthetic import synthetic_arrays

    a, truth = synthetic_arrays(n_points=16, n_images=8, camera="PINHOLE", seed=3, max_track=6)
    rng = np.random.default_rng(0)
    lens = np.diff(a.track_offsets)
    bad = {}
    for p in np.nonzero(lens >= 4)[0][:5]:
        j = a.track_offsets[p] + rng.integers(lens[p])
        g = a.kp_offsets[a.track_image[j]] + a.track_kp[j]
        a.kp_xy[g] += rng.choice([-1, 1], 2) * 60.0
        bad[int(p)] = int(g)
    write_model_arrays(a, tmp_path / "in", "txt")
    rc, out, err = run(["colmap", tmp_path / "in", tmp_path / "out", "--robust", "10", "--json"], capsys)
    assert rc == 0, err
    summary = json.loads(out)
    b = read_model_arrays(tmp_path / "out")
    for p in range(a.n_points):
        s, e = b.track_offsets[p], b.track_offsets[p + 1]
        kept = set((b.kp_offsets[b.track_image[s:e]] + b.track_kp[s:e]).tolist())
        s0, e0 = a.track_offsets[p], a.track_offsets[p + 1]
        before = set((a.kp_offsets[a.track_image[s0:e0]] + a.track_kp[s0:e0]).tolist())
        expect = before - {bad[p]} if p in bad else before
        assert kept == expect, p
    removed = np.array(sorted(bad.values()))
    assert np.all(b.kp_point3D[removed] == -1)
    others = np.setdiff1d(np.nonzero(a.kp_point3D != -1)[0], removed)
    np.testing.assert_array_equal(b.kp_point3D[others], a.kp_point3D[others])
    err_out = np.linalg.norm(b.point_xyz - truth, axis=1)
    assert np.all(err_out[list(bad)] < 0.05)
    msgs = {r["point3D_id"]: r["message"] for r in summary["points"]}
    assert all("1 outlier observation(s) removed" in msgs[int(a.point_ids[p])] for p in bad)
    rc, _, err = run(["colmap", tmp_path / "in", tmp_path / "out2", "--robust", "0"], capsys)
    assert rc == 2 and "--robust" in err


def test_per_problem_thresholds_and_option_errors():
    from tritools.sfm import OptionError, RetriangulationOptions

    probs = [(outlier_scene(4, 1, s, shift=(300, 400))[:2]) for s in range(2)]
    rs = tritools.triangulate_many(probs, robust=[[20.0] * 4, np.full(4, np.inf)])
    assert rs[0].inliers.sum() == 3 and rs[1].inliers.all()
    with pytest.raises(ValueError, match="robust"):
        tritools.triangulate_many(probs, robust=[[20.0] * 4])
    for bad in (-1.0, 0.0, "x", True):
        with pytest.raises(OptionError, match="robust"):
            RetriangulationOptions(robust=bad)
    assert RetriangulationOptions(robust=5).robust == 5.0


def test_benchmark_script_smoke(capsys):
    """benchmarks/robust.py end to end on a reduced grid: certified, reaches the reference, no lower bound above it,
    and the Shor peer runs."""
    import importlib.util
    import pathlib

    pytest.importorskip("cvxpy")
    path = pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "robust.py"
    spec = importlib.util.spec_from_file_location("robust_bench", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    mod.main(["--sizes", "4", "--fractions", "0.25", "--noise", "1", "--trials", "1", "--peer-max", "4",
              "--colmap-points", "0", "--oxford", "", "--no-pycolmap"])
    row = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("4 |")][0].split(" | ")
    assert row[3] == "1/1" and row[6] == "1/1" and row[7] == "0" and row[12] in ("0/1", "1/1")


def test_node_budget_and_time_limit_give_valid_bounds(monkeypatch):
    """A search stopped early reports not_certified / time_limit with bounds that still hold (the branch and
    bound itself: the enumeration of few-view problems, which has no nodes, is switched off)."""
    import tritools.solve.robust as robust_mod
    import tritools.solve.robust_enum as enum_mod
    import tritools.solve.robust_suspects as suspects
    from tritools.solve import robust_batch, robust_cells

    monkeypatch.setattr(enum_mod, "ENUM_MAX_VIEWS", 0)
    monkeypatch.setattr(robust_batch, "BATCH_ENUM_MAX_VIEWS", 0)    # (nor a single call's second try, wave 49)
    monkeypatch.setattr(robust_cells, "ENABLED", False)   # the cells certify it before any node
    monkeypatch.setattr(suspects, "ENABLED", False)      # the suspect stage certifies this scene without nodes
    cams, x, X, _ = outlier_scene(6, 2, 21, noise=1.0, shift=(300, 500))
    c = np.full(6, 20.0)
    full = tritools.triangulate(cams, x, robust=c)
    assert full.optimal and full.attempts[0].step == "branch-and-bound"
    monkeypatch.setattr(robust_mod, "MAX_NODES", 1)
    stopped = tritools.triangulate(cams, x, robust=c)
    assert stopped.status == tritools.Status.NOT_CERTIFIED and not stopped.optimal
    assert "node budget" in stopped.message
    assert stopped.gamma_lb <= full.gamma_ub * (1 + 1e-9) and stopped.gamma_lb <= stopped.gamma_ub
    monkeypatch.setattr(robust_mod, "MAX_NODES", 4000)
    timed = tritools.triangulate(cams, x, robust=c, time_limit=1e-6)
    assert timed.status == tritools.Status.TIME_LIMIT and "time limit" in timed.message
    assert timed.gamma_lb <= full.gamma_ub * (1 + 1e-9) and timed.gamma_lb <= timed.gamma_ub


def test_georeferenced_world_and_zero_noise():
    cams, x, _, out = outlier_scene(6, 2, 3, noise=1.0, shift=(300, 500))
    ref = tritools.triangulate(cams, x, robust=20.0)
    t = np.array([5e6, -3e6, 1e5])
    T = np.eye(4)
    T[:3, 3] = -t                                   # the same scene in a georeferenced frame
    geo = tritools.triangulate(cams @ T, x, robust=20.0)
    assert ref.optimal and geo.optimal
    np.testing.assert_array_equal(geo.inliers, ref.inliers)
    assert geo.gamma_ub == pytest.approx(ref.gamma_ub, rel=1e-6)
    np.testing.assert_allclose(geo.X, ref.X + t, rtol=0, atol=1e-6)
    sc = random_scene(5, 1, noise_px=0.0, seed=6)
    x0 = sc.points2d[0].copy()
    x0[1] += [80.0, -60.0]
    r = tritools.triangulate(sc.cameras, x0, robust=10.0)   # exact data but one view: f* = c^2 exactly
    assert r.optimal and r.inliers.tolist() == [True, False, True, True, True]
    assert r.gamma_ub == pytest.approx(np.sqrt(100.0 / 10)) and r.gamma_lb <= r.gamma_ub
    assert np.linalg.norm(r.X - sc.points3d[0]) < 1e-9


def test_batch_equals_single_and_reference():
    """triangulate_many / triangulate_points with robust= (point problems go straight to the chunked search,
    sub-bounds batched per subset size across problems) give the single-point result exactly -- inliers,
    status, bounds -- on a mixed batch (2-6 views, clean tracks, 1-2 outliers, a threshold met by a residual),
    and every bound holds against the subset enumeration."""
    probs, truth = [], []
    for s, (N, n_out) in enumerate([(2, 0), (3, 0), (3, 1), (4, 1), (5, 0), (5, 2), (6, 1), (4, 0)]):
        cams, x, X, _ = outlier_scene(N, n_out, 40 + s, shift=(15.0, 400.0))
        probs.append((cams, x))
        truth.append(X)
    many = tritools.triangulate_many(probs, robust=10.0)
    for (cams, x), r, X in zip(probs, many, truth):
        single = tritools.triangulate(cams, x, robust=10.0)
        assert r.status == single.status and r.optimal == single.optimal
        np.testing.assert_array_equal(r.inliers, single.inliers)
        assert r.gamma_lb == pytest.approx(single.gamma_lb, rel=1e-9, abs=1e-12)
        assert r.gamma_ub == pytest.approx(single.gamma_ub, rel=1e-9, abs=1e-12)
        # single calls of three views polish their rows less (robust_three.POLISH_STEPS) and reach the inlier set's L2
        # optimum from another start: the same gamma (above), X within the optimum's flat directions
        np.testing.assert_allclose(r.X, single.X, rtol=1e-6, atol=1e-10)
        _check_against_reference(r, cams, [tritools.Point(p) for p in x], np.full(len(x), 10.0), X)
    assert sum(r.optimal for r in many) >= 7
    # the arrays API: shared cameras of the 6-view problem, three copies with different hidden views
    cams, x = probs[6]
    pts = np.stack([x, x, x])
    pts[1, 0] = pts[2, 5] = np.nan
    res = tritools.triangulate_points(cams, pts, robust=10.0)
    for m in range(3):
        v = np.isfinite(pts[m, :, 0])
        single = tritools.triangulate(cams[v], pts[m, v], robust=10.0)
        np.testing.assert_array_equal(res.inliers[m, v], single.inliers)
        assert not res.inliers[m, ~v].any()
        assert res.optimal[m] == single.optimal
        assert res.gamma_ub[m] == pytest.approx(single.gamma_ub, rel=1e-9)
        assert res.gamma_lb[m] == pytest.approx(single.gamma_lb, rel=1e-9, abs=1e-12)


def test_point_distances_match_point_report():
    """The vectorised residuals of the search (point regions) against the scalar point_report, including a
    view whose projection is undefined (the point on its principal plane: inf in both)."""
    from tritools.solve.report import point_report
    from tritools.solve.robust import point_distances2

    cams, x, X, _ = outlier_scene(5, 1, 3)
    regions = [tritools.Point(p) for p in x]
    rng = np.random.default_rng(1)
    Xs = np.vstack([X, X + rng.normal(size=(5, 3))])
    P = cams[2] / np.linalg.norm(cams[2][2, :3])
    Xp = np.round((X - (P[2] @ np.append(X, 1.0)) * P[2, :3]) * 2.0 ** 10) / 2.0 ** 10
    cams = cams.copy()                  # on the principal plane of view 2 in exact arithmetic (dyadic numbers of few
    cams[2, 2, :3] = np.round(cams[2, 2, :3] * 2.0 ** 10) / 2.0 ** 10          # bits: every product and sum exact)
    cams[2, 2, 3] = -(cams[2, 2, :3] @ Xp)
    Xs = np.vstack([Xs, Xp])
    d2 = point_distances2(cams, x, Xs)
    for X_, row in zip(Xs, d2):
        ref = point_report(X_, cams, regions).residuals
        assert np.array_equal(np.isinf(row), np.isinf(ref))
        fin = np.isfinite(ref)
        np.testing.assert_allclose(np.sqrt(row[fin]), ref[fin], rtol=1e-12, atol=1e-9)
    assert np.isinf(d2[-1, 2])


def test_robust_thresholds_of_a_float_equal_the_general_path():
    """A plain float threshold (the fast path) gives the array of the general path (a numpy scalar, a list); the
    edges (MIN_THRESHOLD itself, inf) are accepted and below it, NaN, 0 and negatives refused alike."""
    from tritools.solve.robust import MIN_THRESHOLD

    for c in (200.0, 1e-3, 1e300, math.inf, MIN_THRESHOLD):
        got = robust_thresholds(c, 4)
        assert got.dtype == float and got.shape == (4,)
        assert np.array_equal(got, robust_thresholds(np.float64(c), 4))
        assert np.array_equal(got, robust_thresholds([c] * 4, 4))
    for bad in (MIN_THRESHOLD / 2, math.nan, 0.0, -0.0, -1.0, -math.inf):
        with pytest.raises(ValueError, match="robust"):
            robust_thresholds(bad, 3)


def test_point_distances_of_rows_equal_the_single_candidate_twin():
    """point_distances2_rows (one candidate per problem, the enumeration stack's offers) equals point_distances2_one
    bit for bit, over cameras and points from 1e-6 to 1e6 in scale, candidates near and far, a candidate on a
    principal plane (inf) and one at 1e305 (overflowing projections: inf); and the finite values match
    point_report's residuals."""
    from tritools.solve.report import point_report
    from tritools.solve.robust_costs import point_distances2_one, point_distances2_rows

    rng = np.random.default_rng(11)
    for N in (3, 7, 10):
        R = 40
        C = rng.normal(size=(R, N, 3, 4)) * 10.0 ** rng.uniform(-6, 6, size=(R, 1, 1, 1))
        x = rng.normal(size=(R, N, 2)) * 10.0 ** rng.uniform(-3, 6, size=(R, 1, 1))
        X = rng.normal(size=(R, 3)) * 10.0 ** rng.uniform(-3, 7, size=(R, 1))
        X[0] = X[0] - (C[0, 1, 2, :3] @ X[0] + C[0, 1, 2, 3]) / (C[0, 1, 2, :3] @ C[0, 1, 2, :3]) * C[0, 1, 2, :3]
        X[1], C[1] = 1e305, C[1] * 1e10                          # overflowing products
        got = point_distances2_rows(C, x, X)
        for r in range(R):
            with np.errstate(all="ignore"):                      # (the scalar's overflowing products warn)
                want = point_distances2_one(C[r], np.abs(C[r, :, 2]), x[r], X[r])
            assert want.dtype == got.dtype and np.array_equal(want, got[r])
        assert np.isinf(got[0, 1]) and np.isinf(got[1]).all()
        ref = point_report(X[5], C[5], [tritools.Point(p) for p in x[5]]).residuals
        fin = np.isfinite(ref)
        np.testing.assert_allclose(np.sqrt(got[5][fin]), ref[fin], rtol=1e-9)
