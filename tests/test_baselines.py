"""Tests of tritools.baselines (the paper's §5 comparison methods) and of the
Hartley-Sturm reference used to check them."""
import numpy as np
import pytest
from scipy import optimize

from tests.reference.hartley_sturm import hartley_sturm
from tritools.baselines import (BASELINES, dlt_baseline, nelder_mead, newton, particle_swarm,
                                point_cost_derivatives, sqp)
from tritools.model.geometry import M0, gamma, point_from_image_points
from tritools.model.regions import Point
from tritools.result import Status, TriangulationResult
from tritools.scene import paper_example, paper_table, random_scene

# certified optima of the paper (Tables 8-10, Theorem 1 rows): no estimate can do better
PAPER_OPTIMUM = {2: 0.412, 3: 0.138, 4: 0.760}


def paper_row(k, method):
    return next(r for r in paper_table(k) if r["method"] == method)


def reprojection_cost(X, P1, P2, x1, x2):
    """Sum of squared reprojection errors, written out independently of tritools."""
    out = 0.0
    for P, x in ((P1, x1), (P2, x2)):
        h = P @ np.append(X, 1.0)
        out += np.sum((h[:2] / h[2] - x) ** 2)
    return out


# ---------------------------------------------------------------- reference implementation
@pytest.mark.parametrize("seed", range(4))
def test_hartley_sturm_matches_dense_multistart_nelder_mead(seed):
    sc = random_scene(2, 2, noise_px=4.0, seed=100 + seed)
    rng = np.random.default_rng(seed)
    P1, P2 = sc.cameras
    for j in range(sc.n_points):
        x1, x2 = sc.points2d[j]
        X_hs, cost_hs = hartley_sturm(P1, P2, x1, x2)
        assert reprojection_cost(X_hs, P1, P2, x1, x2) == pytest.approx(cost_hs, rel=1e-9, abs=1e-12)
        best = np.inf
        starts = [sc.points3d[j] + rng.normal(scale=s, size=3) for s in (0.1, 0.5, 1.0, 3.0) for _ in range(5)]
        for X0 in starts:
            r = optimize.minimize(reprojection_cost, X0, args=(P1, P2, x1, x2), method="Nelder-Mead",
                                  options={"xatol": 1e-10, "fatol": 1e-14, "maxiter": 20000, "maxfev": 20000})
            best = min(best, r.fun)
        assert cost_hs <= best * (1 + 1e-7) + 1e-12          # HS is the global minimum ...
        assert best <= cost_hs * (1 + 1e-5) + 1e-10          # ... and the local search finds it too


def test_newton_matches_hartley_sturm_on_two_views():
    for seed in range(6):
        sc = random_scene(2, 3, noise_px=2.0, seed=seed)
        for j in range(sc.n_points):
            X_hs, cost = hartley_sturm(*sc.cameras, *sc.points2d[j])
            res = newton(sc.cameras, sc.regions(j))
            assert res.status is Status.NO_CERTIFICATE
            assert res.gamma_ub == pytest.approx(np.sqrt(cost / 4), rel=1e-7)
            assert np.linalg.norm(res.X - X_hs) <= 1e-6 * (1 + np.linalg.norm(X_hs))


# ---------------------------------------------------------------- Newton derivatives
def test_newton_derivatives_vs_finite_differences():
    cams, regions = paper_example(4)
    x = np.array([r.x for r in regions])
    X = np.array([-0.5, 0.2, 0.7])
    J, g, H = point_cost_derivatives(X, cams, x)
    assert J == pytest.approx(8 * gamma(X, cams, regions) ** 2, rel=1e-12)
    h = 1e-6
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        Jp, gp, _ = point_cost_derivatives(X + e, cams, x)
        Jm, gm, _ = point_cost_derivatives(X - e, cams, x)
        assert g[k] == pytest.approx((Jp - Jm) / (2 * h), rel=1e-6, abs=1e-8)
        assert np.allclose(H[:, k], (gp - gm) / (2 * h), rtol=1e-5, atol=1e-6)
    assert np.allclose(H, H.T)


# ---------------------------------------------------------------- paper's examples
@pytest.mark.parametrize("k,method,fn", [
    (2, "nms", nelder_mead), (2, "sqp", sqp),
    (3, "nms", nelder_mead), (3, "sqp", sqp),
    (4, "nms", nelder_mead),
])
def test_baselines_reproduce_paper_rows(k, method, fn):
    """NMS and SQP from the algebraic-error start reproduce Tables 8-10 (Ex. 2: both reach the
    optimum 0.412; Ex. 3: SQP the optimum 0.138, NMS stops at 0.139; Ex. 4: NMS stops at 1.597)."""
    cams, regions = paper_example(k)
    row = paper_row(k, method)
    res = fn(cams, regions)
    assert res.method == method
    assert res.status is Status.NO_CERTIFICATE and res.gamma_lb is None and res.optimal is None
    assert round(res.gamma_ub, 3) == pytest.approx(row["gamma"], abs=1e-9)
    assert np.max(np.abs(res.X - row["X"])) <= 1.5e-3
    assert res.timings["total"] > 0


def test_example4_newton_and_pso_close_to_paper():
    cams, regions = paper_example(4)
    # our damped Newton reaches the certified optimum where the paper's classical Newton diverged
    res = newton(cams, regions)
    assert round(res.gamma_ub, 3) == pytest.approx(0.760, abs=1e-9)
    assert np.max(np.abs(res.X - paper_row(4, "theorem1")["X"])) <= 1e-3
    assert res.image_points.shape == (4, 2)
    # PSO, like the paper's, ends on the face X3 = +100 of the box with gamma ~ 0.824
    p = particle_swarm(cams, regions, seed=0)
    assert p.X[2] == pytest.approx(100.0) and abs(p.gamma_ub - 0.824) < 2e-3


@pytest.mark.parametrize("k", [2, 3, 4])
def test_no_baseline_beats_the_certified_optimum(k):
    cams, regions = paper_example(k)
    for name, fn in BASELINES.items():
        res = fn(cams, regions)
        if res.status is Status.INVALID_INPUT:
            assert name == "newton" and k in (2, 3)
            continue
        assert res.gamma_ub >= PAPER_OPTIMUM[k] - 5e-4, name
        assert res.gamma_ub == pytest.approx(gamma(res.X, cams, regions), rel=1e-12)


def test_dlt_baseline_is_the_algebraic_minimiser():
    cams, regions = paper_example(4)
    res = dlt_baseline(cams, regions)
    centres = np.array([r.center for r in regions])
    assert np.allclose(res.X, point_from_image_points(centres, cams))
    A = M0(centres, cams)
    w = np.append(res.X, 1.0)
    w /= np.linalg.norm(w)
    assert np.linalg.norm(A @ w) == pytest.approx(np.linalg.svd(A, compute_uv=False)[-1], rel=1e-9)
    res_n = dlt_baseline(cams, regions, init="normalized")
    assert res_n.gamma_ub > 0 and not np.allclose(res_n.X, res.X)
    with pytest.raises(ValueError, match="init"):
        dlt_baseline(cams, regions, init="bogus")


def test_pso_seeded_and_bounded():
    cams, regions = paper_example(3)
    a = particle_swarm(cams, regions, seed=5)
    b = particle_swarm(cams, regions, seed=5)
    assert np.array_equal(a.X, b.X)
    assert np.all(np.abs(a.X) <= 100.0)
    c = particle_swarm(cams, regions, seed=5, bounds=2.0)
    assert np.all(np.abs(c.X) <= 2.0)
    assert "iterations" in a.message


# ---------------------------------------------------------------- status handling and bad input
def test_newton_not_applicable_to_non_point_regions():
    cams, regions = paper_example(2)
    res = newton(cams, regions)
    assert isinstance(res, TriangulationResult)
    assert res.status is Status.INVALID_INPUT and res.X is None and "point" in res.message


def test_ill_posed_start_is_reported():
    cams = np.array([np.eye(3, 4), np.array([[1.0, 0, 0, -1], [0, 1, 0, 0], [0, 0, 1, 0]])])
    d = np.array([0.2, -0.1, 1.0])
    regions = [Point(d[:2] / d[2]), Point(d[:2] / d[2])]     # rays meet only at infinity
    for fn in (dlt_baseline, newton, nelder_mead, sqp):
        res = fn(cams, regions)
        assert res.status is Status.ILL_POSED and res.X is None, fn.__name__


@pytest.mark.parametrize("fn", list(BASELINES.values()), ids=list(BASELINES))
def test_bad_input_raises(fn):
    cams, regions = paper_example(4)
    with pytest.raises(ValueError, match="one region per view"):
        fn(cams, regions[:3])
    with pytest.raises(ValueError, match="NaN"):
        fn(np.where(np.eye(3, 4) > 0, np.nan, cams), regions)
    with pytest.raises(ValueError, match="all equal up to scale"):
        fn(np.array([cams[0]] * 4), regions)


# ---------------------------------------------------------------- result record
def test_triangulation_result_record():
    r = TriangulationResult("theorem1", "optimal", X=[1, 2, 3], gamma_ub=0.5, gamma_lb=0.4999, optimal=True,
                            delta=4, n_lmivar=676, image_points=np.zeros((3, 2)), timings={"total": 1.0})
    assert r.status is Status.OPTIMAL and r.status == "optimal"
    assert r.gap == pytest.approx(1e-4)
    assert r.X.shape == (3,) and not r.X.flags.writeable
    s = str(r)
    assert "theorem1" in s and "optimal" in s and "delta=4" in s
    assert r.to_dict()["status"] == "optimal" and r.to_dict()["X"] == [1.0, 2.0, 3.0]
    with pytest.raises(Exception):
        r.gamma_ub = 1.0
    assert TriangulationResult("nms", Status.NO_CERTIFICATE).gap is None
    with pytest.raises(ValueError, match="status"):
        TriangulationResult("x", "great")
    with pytest.raises(ValueError, match=r"X must have shape \(3,\)"):
        TriangulationResult("x", "optimal", X=[1, 2])
    with pytest.raises(ValueError, match="image_points"):
        TriangulationResult("x", "optimal", image_points=np.zeros(3))
    fields = [f for f in TriangulationResult.__dataclass_fields__]
    assert fields == ["method", "status", "X", "gamma_ub", "gamma_lb", "optimal", "delta", "n_lmivar",
                      "image_points", "X_raw", "gamma_ub_raw", "certified_by", "message", "timings", "attempts",
                      "sparsity", "in_front", "depths", "residuals", "inliers"]


def test_pycolmap_multiview_baseline_when_installed():
    pytest.importorskip("pycolmap", reason="pycolmap not installed (optional extra 'colmap')")
    from tritools.baselines import decompose_camera, pycolmap_multiview
    from tritools.scene import random_scene

    scene = random_scene(4, 2, noise_px=0.0, seed=5)
    for P in scene.cameras:
        K, Rt = decompose_camera(P)
        Q = K @ Rt
        # P = K [R | t] up to scale, R a rotation, K upper triangular with positive diagonal
        # parallel as vectors: |<Q, P>| = |Q| |P|
        assert (abs(abs(Q.ravel() @ P.ravel()) - np.linalg.norm(Q) * np.linalg.norm(P))
                <= 1e-9 * np.linalg.norm(Q) * np.linalg.norm(P))
        assert np.allclose(Rt[:, :3] @ Rt[:, :3].T, np.eye(3), atol=1e-10) and np.linalg.det(Rt[:, :3]) > 0
        assert np.allclose(np.tril(K, -1), 0) and np.all(np.diag(K) > 0)
    r = pycolmap_multiview(scene.cameras, scene.regions(0, noisy=False))
    np.testing.assert_allclose(r.X, scene.points3d[0], atol=1e-8 * max(1, np.linalg.norm(scene.points3d[0])))
    assert r.gamma_lb is None and r.optimal is None
