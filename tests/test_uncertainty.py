"""Certified per-view uncertainty (tritools.uncertainty): coverage, witnesses, gaps, unbounded and empty
sets, scales, bad input; checked by sampling and by an independent conic solver (cvxpy)."""
import numpy as np
import pytest

import tritools
from tritools.model.geometry import image_points
from tritools import UncertaintyStatus, uncertainty, uncertainty_many


def look_at(C, target=(0.0, 0.0, 0.0), f=800.0, pp=(320.0, 240.0)):
    target = np.asarray(target, float)
    z = target - C
    z = z / np.linalg.norm(z)
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.array([x, y, z])
    K = np.array([[f, 0, pp[0]], [0, f, pp[1]], [0, 0, 1.0]])
    return K @ np.hstack([R, -R @ C[:, None]])


def scene(rng, n_views=3, f=800.0, pp=(320.0, 240.0), offset=(0.0, 0.0, 0.0), dist=5.0, spread=2.0):
    offset = np.asarray(offset, float)
    cams = []
    for _ in range(n_views):
        C = offset + np.array([rng.uniform(-spread, spread), rng.uniform(-spread, spread), -dist])
        cams.append(look_at(C, offset, f, pp))
    X = offset + rng.normal(size=3) * 0.3
    return np.array(cams), X


def random_region(rng, x, size, kind):
    """A region of the given kind containing x (x strictly inside, at a random place)."""
    if kind == "ellipse":
        A = rng.normal(size=(2, 2))
        D = size ** 2 * (A @ A.T + 0.3 * np.eye(2))
        L = np.linalg.cholesky(D)
        u = rng.normal(size=2)
        u *= rng.uniform(0, 0.95) / np.linalg.norm(u)
        return tritools.Ellipse(x - L @ u, D)
    if kind == "polytope":
        B = rng.normal(size=(4, 2)) / size
        t = rng.uniform(-0.9, 0.9, 4)
        return tritools.Polytope(B, t - B @ x)
    if kind == "segment":
        d = rng.normal(size=2) * size
        t = rng.uniform(-0.9, 0.9)
        return tritools.Segment(x - t * d, d)
    raise ValueError(kind)


def in_set(X, cams, regions, tol=0.0):
    """Independent membership test: tritools.project and the regions' own distances, depth > 0."""
    if np.any(tritools.depths(X, cams) <= 0):
        return False
    x = image_points(X, cams)
    return all(float(r.distance(p)) <= tol for r, p in zip(regions, x))


def check_covers(res, X, cams):
    assert np.all(res.lo <= X) and np.all(X <= res.hi), (res.lo, X, res.hi)
    d = tritools.depths(X, cams)
    assert np.all(res.depth_lo <= d) and np.all(d <= res.depth_hi)
    assert np.linalg.norm(X - res.estimate) <= res.max_distance


def sample_in_set(rng, res, cams, regions, n=40000):
    """Points of S found by rejection in the box enlarged 3 times (independent of the witnesses)."""
    c = (res.lo + res.hi) / 2
    h = (res.hi - res.lo) * 1.5
    P = c + rng.uniform(-1, 1, size=(n, 3)) * h
    ok = np.all(tritools.depths(P, cams) > 0, axis=1)
    x = image_points(P, cams)
    for i, r in enumerate(regions):
        ok &= np.asarray(r.distance(x[:, i])) <= 0.0
    return P[ok]


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("kind", ["ellipse", "polytope", "mixed"])
def test_true_point_and_sampled_points_covered(seed, kind):
    rng = np.random.default_rng(seed)
    for _ in range(5):
        cams, X = scene(rng, n_views=int(rng.integers(2, 5)))
        kinds = [kind] * len(cams) if kind != "mixed" else \
            [["ellipse", "polytope", "segment"][i % 3] for i in range(len(cams))]
        regions = [random_region(rng, x, 2.0, k) for x, k in zip(image_points(X, cams), kinds)]
        res = uncertainty(cams, regions, estimate=X + 0.01)
        assert res.status == UncertaintyStatus.BOUNDED and res.bounded and res.rigorous
        check_covers(res, X, cams)
        inside = sample_in_set(rng, res, cams, regions)
        assert len(inside) > (-1 if kind == "mixed" else 0)          # the sampler does find points of S
        for p in inside:
            check_covers(res, p, cams)


@pytest.mark.parametrize("seed", [3, 4])
def test_witnesses_feasible_and_gap_tight(seed):
    rng = np.random.default_rng(seed)
    for _ in range(5):
        cams, X = scene(rng, n_views=3)
        regions = [random_region(rng, x, 1.5, k) for x, k in
                   zip(image_points(X, cams), ["ellipse", "polytope", "ellipse"])]
        res = uncertainty(cams, regions)
        assert res.gap_rel <= 1e-6
        for k in range(3):
            for W, bound in ((res.witness_lo, res.lo), (res.witness_hi, res.hi)):
                assert in_set(W[k], cams, regions)
                assert abs(W[k, k] - bound[k]) <= res.gap
        assert in_set(res.distance_witness, cams, regions)
        assert res.distance_inner <= res.max_distance <= np.sqrt(3) * res.distance_inner * 1.01 + 1e-12 or \
            res.distance_inner <= res.max_distance


def test_matches_independent_conic_solver():
    cp = pytest.importorskip("cvxpy")
    rng = np.random.default_rng(7)
    cams, X = scene(rng, n_views=3)
    regions = [random_region(rng, x, 2.0, "ellipse") for x in image_points(X, cams)]
    res = uncertainty(cams, regions)
    Y = cp.Variable(3)
    cons = []
    for P, r in zip(cams, regions):
        sgn = np.sign(np.linalg.det(P[:, :3]))
        a, s = sgn * P[:2] @ cp.hstack([Y, 1]), sgn * P[2] @ cp.hstack([Y, 1])
        L = np.linalg.cholesky(np.linalg.inv(r.D))
        cons.append(cp.SOC(s, L.T @ (a - r.center_ * s)))
    width = np.max(res.hi - res.lo)
    for k in range(3):
        lo = cp.Problem(cp.Minimize(Y[k]), cons).solve(solver=cp.CLARABEL)
        hi = cp.Problem(cp.Maximize(Y[k]), cons).solve(solver=cp.CLARABEL)
        assert res.lo[k] <= lo + 1e-7 * width and abs(res.lo[k] - lo) <= 1e-6 * width
        assert res.hi[k] >= hi - 1e-7 * width and abs(res.hi[k] - hi) <= 1e-6 * width


def test_parallel_rays_unbounded():
    cams = np.array([look_at(np.array([x, 0.0, -5.0]), np.array([x, 0.0, 0.0])) for x in (-1.0, 1.0)])
    pp = np.array([320.0, 240.0])
    regions = [tritools.Ellipse.circle(pp, 2.0), tritools.Ellipse.circle(pp, 2.0)]
    res = uncertainty(cams, regions, estimate=np.array([0.0, 0.0, 100.0]))
    assert res.status == UncertaintyStatus.UNBOUNDED and not res.bounded
    assert res.hi[2] == np.inf and np.isfinite(res.lo[2])       # in front of the cameras: z > -5
    assert np.all(res.lo[:2] == -np.inf) and np.all(res.hi[:2] == np.inf)    # the cones widen without end
    assert np.isfinite(res.witness_lo[2]).all() and in_set(res.witness_lo[2], cams, regions)
    assert res.max_distance == np.inf
    assert np.all(res.depth_hi == np.inf)
    far = np.array([0.0, 0.0, 1e7])                   # the rays meet at infinity: far points are in S
    assert in_set(far, cams, regions)


def test_empty_sets():
    rng = np.random.default_rng(5)
    cams, X = scene(rng, n_views=2)
    x = image_points(X, cams)
    res = uncertainty(cams, [tritools.Point(x[0] + 0.5), tritools.Point(x[1] - 0.5)])
    assert res.status == UncertaintyStatus.EMPTY
    assert np.all(res.lo == np.inf) and np.all(res.hi == -np.inf)
    far = [tritools.Ellipse.circle(x[0], 1.0), tritools.Ellipse.circle(x[1] + np.array([0.0, 80.0]), 1.0)]
    assert uncertainty(cams, far).status == UncertaintyStatus.EMPTY
    # the same noisy points with a dilation covering the noise: a bounded set holding X
    res = uncertainty(cams, [tritools.Point(x[0] + 0.5), tritools.Point(x[1] - 0.5)], dilation=0.75)
    assert res.status == UncertaintyStatus.BOUNDED
    check_covers(res, X, cams)


def test_point_and_ellipse_views():
    rng = np.random.default_rng(11)
    cams, X = scene(rng, n_views=3)
    x = image_points(X, cams)
    regions = [tritools.Point(x[0]), tritools.Ellipse.circle(x[1] + 0.3, 1.0), tritools.Ellipse.circle(x[2], 1.0)]
    res = uncertainty(cams, regions)
    assert res.status == UncertaintyStatus.BOUNDED
    assert np.all(res.lo <= X + 1e-9 * np.abs(X)) and np.all(X - 1e-9 * np.abs(X) <= res.hi)
    for W in (res.witness_lo, res.witness_hi):
        for w in W:
            assert in_set(w, cams, regions, tol=1e-6)


@pytest.mark.parametrize("f, pp", [(1e-3, (1e-3, 2e-3)), (1e6, (1e6, -3e5)), (800.0, (320.0, 240.0))])
@pytest.mark.parametrize("offset", [np.zeros(3), np.array([4.2e6, -1.3e6, 3.0e2])])
def test_adversarial_scales(f, pp, offset):
    rng = np.random.default_rng(21)
    cams, X = scene(rng, n_views=3, f=f, pp=pp, offset=offset)
    size = 2.0 * f / 800.0
    regions = [random_region(rng, x, size, "ellipse") for x in image_points(X, cams)]
    res = uncertainty(cams, regions)
    assert res.status == UncertaintyStatus.BOUNDED
    check_covers(res, X, cams)
    assert res.gap_rel <= 1e-6
    for w in np.vstack([res.witness_lo, res.witness_hi]):
        assert in_set(w, cams, regions)


def test_sign_and_scale_of_cameras_do_not_matter():
    rng = np.random.default_rng(8)
    cams, X = scene(rng, n_views=3)
    regions = [random_region(rng, x, 2.0, "ellipse") for x in image_points(X, cams)]
    a = uncertainty(cams, regions)
    b = uncertainty(cams * np.array([-1.0, 3e4, -2e-5])[:, None, None], regions)
    w = np.max(a.hi - a.lo)
    assert np.allclose(a.lo, b.lo, atol=1e-7 * w) and np.allclose(a.hi, b.hi, atol=1e-7 * w)


def test_border_uses_hull():
    rng = np.random.default_rng(9)
    cams, X = scene(rng, n_views=2)
    x = image_points(X, cams)
    border = [tritools.EllipseBorder(x[0] + np.array([1.0, 0.0]), np.eye(2)),
              tritools.EllipseBorder(x[1], np.eye(2) * 4)]
    res = uncertainty(cams, border)
    assert res.convexified and res.status == UncertaintyStatus.BOUNDED
    check_covers(res, X, cams)


def test_many_matches_single():
    rng = np.random.default_rng(12)
    cams_list, regions_list, Xs = [], [], []
    for i in range(6):
        cams, X = scene(rng, n_views=2 + i % 2)
        cams_list.append(cams)
        Xs.append(X)
        regions_list.append([random_region(rng, x, 2.0, "ellipse") for x in image_points(X, cams)])
    many = uncertainty_many(cams_list, regions_list, estimates=np.array(Xs))
    for c, r, X, m in zip(cams_list, regions_list, Xs, many):
        one = uncertainty(c, r, estimate=X)
        w = np.max(one.hi - one.lo)
        assert np.allclose(one.lo, m.lo, atol=1e-6 * w) and np.allclose(one.hi, m.hi, atol=1e-6 * w)
        check_covers(m, X, c)


def test_bad_input():
    rng = np.random.default_rng(13)
    cams, X = scene(rng, n_views=2)
    regions = [tritools.Ellipse.circle(x, 1.0) for x in image_points(X, cams)]
    with pytest.raises(ValueError, match="dilation"):
        uncertainty(cams, regions, dilation=-1.0)
    with pytest.raises(ValueError, match="dilation"):
        uncertainty(cams, regions, dilation=[1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="estimate"):
        uncertainty(cams, regions, estimate=[0.0, np.nan, 1.0])
    with pytest.raises(ValueError):
        uncertainty(cams, regions[:1])
    with pytest.raises(ValueError, match="cameras"):
        uncertainty(np.zeros((2, 3, 4)), regions)
    with pytest.raises(TypeError, match="options"):
        uncertainty(cams, regions, options={"dilation": 1})
    with pytest.raises(ValueError, match="level"):
        uncertainty(cams, regions, level=-1.0)
    with pytest.raises(ValueError, match="dilation"):
        uncertainty(cams, regions, level=1.0, dilation=1.0)
    with pytest.raises(ValueError, match="one entry per point"):
        uncertainty_many([cams], [regions, regions])


def test_bounded_noise_coverage_batch():
    """Noise uniform in the regions (discs and ellipses around the noisy observation hold the true
    projection): every true point is in its certified box, depth intervals and distance ball."""
    rng = np.random.default_rng(31)
    cams_list, regions_list, Xs = [], [], []
    for _ in range(300):
        cams, X = scene(rng, n_views=int(rng.integers(2, 4)))
        regs = []
        for x in image_points(X, cams):
            r = rng.uniform(0.5, 3.0)
            u = rng.normal(size=2)
            u *= r * np.sqrt(rng.uniform()) / np.linalg.norm(u)           # uniform in the disc
            regs.append(tritools.Ellipse.circle(x + u, r))
        cams_list.append(cams)
        regions_list.append(regs)
        Xs.append(X)
    res = uncertainty_many(cams_list, regions_list)
    for r, c, X in zip(res, cams_list, Xs):
        assert r.status == UncertaintyStatus.BOUNDED
        check_covers(r, X, c)


def _level_problem():
    rng = np.random.default_rng(17)
    cams, X = scene(rng, n_views=3)
    x = image_points(X, cams) + rng.uniform(-0.5, 0.5, (3, 2))
    return rng, cams, X, [tritools.Point(p) for p in x]


def _check_level(res, rng, cams, X, regions, tau):
    """Points with gamma <= tau (sampled around X) lie in the bounds; witnesses are points of L near them."""
    P = X + rng.uniform(-1, 1, size=(20000, 3)) * (res.hi - res.lo)
    inside = P[tritools.gamma(P, cams, regions) <= tau]
    assert len(inside) > 10
    for p in inside:
        check_covers(res, p, cams)
    for W, bound in ((res.witness_lo, res.lo), (res.witness_hi, res.hi)):
        assert np.all(np.isfinite(W))                          # local searches found points of L
        for k, w in enumerate(W):
            assert tritools.gamma(w, cams, regions) <= tau
            assert abs(w[k] - bound[k]) <= res.gap


def test_level_set_relaxation_contains_the_level_set():
    rng, cams, X, regions = _level_problem()
    res = uncertainty(cams, regions, level=1.0, options=tritools.UncertaintyOptions(level_degree=None))
    assert res.definition == "level_relaxed" and res.status == UncertaintyStatus.BOUNDED
    assert 0 < res.gap_rel < 0.5                               # the relaxation's looseness, measured
    _check_level(res, rng, cams, X, regions, 1.0)


@pytest.mark.slow
def test_level_set_sos_bounds_are_tight_and_valid():
    rng, cams, X, regions = _level_problem()
    relaxed = uncertainty(cams, regions, level=1.0, options=tritools.UncertaintyOptions(level_degree=None))
    res = uncertainty(cams, regions, level=1.0)
    assert res.definition == "level_sos" and res.status == UncertaintyStatus.BOUNDED
    assert np.all(relaxed.lo <= res.lo) and np.all(res.hi <= relaxed.hi)
    assert res.gap_rel < 1e-3                                  # the SOS bounds meet the local extremes
    _check_level(res, rng, cams, X, regions, 1.0)


def test_exact_points_with_roundoff_widening_hold_the_point():
    rng = np.random.default_rng(41)
    opts = tritools.UncertaintyOptions()                     # widen_roundoff=True, the default
    for f, offset in ((800.0, (0.0, 0.0, 0.0)), (1e6, (4.2e6, -1.3e6, 3e2))):
        for _ in range(5):
            cams, X = scene(rng, n_views=int(rng.integers(2, 5)), f=f, offset=offset)
            res = uncertainty(cams, [tritools.Point(x) for x in image_points(X, cams)], options=opts)
            assert res.status == UncertaintyStatus.BOUNDED
            assert np.all(res.lo <= X) and np.all(X <= res.hi)


@pytest.mark.filterwarnings("error::RuntimeWarning")   # handled overflow stays inside
def test_noisy_points_are_empty_and_small_dilation_recovers():
    rng = np.random.default_rng(43)
    for _ in range(10):
        cams, X = scene(rng, n_views=int(rng.integers(2, 4)))
        noisy = [tritools.Point(p + rng.uniform(-0.5, 0.5, 2)) for p in image_points(X, cams)]
        assert uncertainty(cams, noisy).status == UncertaintyStatus.EMPTY
        res = uncertainty(cams, noisy, dilation=0.75)
        assert res.status == UncertaintyStatus.BOUNDED and np.all(res.lo <= X) and np.all(X <= res.hi)


@pytest.mark.parametrize("kind", ["point", "ellipse", "polytope", "segment", "border"])
def test_dilation_contains_the_r_neighbourhood(kind):
    from tritools.uncertain.sets import dilate
    rng = np.random.default_rng(51)
    c = np.array([320.0, 240.0])
    region = {"point": tritools.Point(c), "ellipse": tritools.Ellipse(c, np.array([[9.0, 2.0], [2.0, 4.0]])),
              "polytope": random_region(rng, c, 3.0, "polytope"), "segment": tritools.Segment(c, [4.0, -1.0]),
              "border": tritools.EllipseBorder(c, np.eye(2) * 4.0)}[kind]
    r = 1.5
    big = dilate(region, r)
    P = c + rng.uniform(-12, 12, size=(20000, 2))
    near = P[np.asarray(region.distance(P)) <= r]
    assert len(near) > 100
    assert np.all(np.asarray(big.distance(near)) == 0.0)


def test_result_carries_the_triangulation_angle():
    K = np.diag([800.0, 800.0, 1.0])
    cams = np.array([K @ np.hstack([np.eye(3), [[-b], [0.0], [0.0]]]) for b in (0.0, 1.0)])   # centres 0, (1,0,0)
    X = np.array([0.5, 0.0, 10.0])
    regions = [tritools.Ellipse.circle(tritools.project(X, P), 1.0) for P in cams]
    res = uncertainty(cams, regions, estimate=X)
    assert res.angle_deg == pytest.approx(np.degrees(2 * np.arctan(0.05)), rel=1e-9)
    assert res.angle_deg == pytest.approx(tritools.triangulation_angle(cams, X), rel=1e-12)


def test_a_mirrored_reconstruction_in_its_own_world_frame():
    """A mirrored world (z -> -z: every det M < 0) holds the same scene: read as ``reflected`` its set is the
    mirror image of the original's (true point inside, positive depths); read as right-handed every
    consistent point lies behind the cameras, so the set is empty.  The ``dilation`` shortcut keeps the
    other options (it rebuilt them from defaults before)."""
    from tritools.uncertain.api import UncertaintyOptions

    rng = np.random.default_rng(8)
    cams, X = scene(rng, n_views=3)
    regions = [random_region(rng, x, 2.0, "ellipse") for x in image_points(X, cams)]
    S = np.diag([1.0, 1.0, -1.0, 1.0])
    mirrored = cams @ S                                     # P' = P S sees S X exactly where P sees X
    a = uncertainty(cams, regions)
    b = uncertainty(mirrored, regions, options=UncertaintyOptions(world_frame="reflected"))
    assert a.status == b.status == UncertaintyStatus.BOUNDED
    w = np.max(a.hi - a.lo)
    assert np.allclose(b.lo, [a.lo[0], a.lo[1], -a.hi[2]], atol=1e-7 * w)
    assert np.allclose(b.hi, [a.hi[0], a.hi[1], -a.lo[2]], atol=1e-7 * w)
    assert np.allclose(b.depth_lo, a.depth_lo, rtol=1e-7) and np.all(b.depth_lo > 0)
    c = uncertainty(mirrored, regions)
    assert c.status == UncertaintyStatus.EMPTY
    d = uncertainty(mirrored, regions, options=UncertaintyOptions(world_frame="reflected"), dilation=1.0)
    assert d.status == UncertaintyStatus.BOUNDED and np.all(d.lo <= S[:3, :3] @ X) and np.all(S[:3, :3] @ X <= d.hi)
    with pytest.raises(ValueError, match="world_frame"):
        UncertaintyOptions(world_frame="left")
