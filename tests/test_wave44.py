"""Wave 44: the normalisation's exact image similarity (review 43c LOW-1), ..."""
from __future__ import annotations

import functools
import math

import mpmath
import numpy as np
import pytest

import tritools
from tritools import Ellipse, Point
from tritools.scene import random_scene


def _ellipse_distance_mp(center, D, p):
    """Exact (50-digit) distance from p to the filled ellipse {y : (y - c)' D^-1 (y - c) <= 1} of the float D."""
    F = lambda v: mpmath.mpf(float(v))      # noqa: E731
    a, b, d = F(D[0][0]), (F(D[0][1]) + F(D[1][0])) / 2, F(D[1][1])
    h = (a - d) / 2
    s = mpmath.sqrt(h * h + b * b)
    lmax = (a + d) / 2 + s
    lmin = (a * d - b * b) / lmax
    v = (h + s, b) if h >= 0 else (b, s - h)
    nv = mpmath.sqrt(v[0] ** 2 + v[1] ** 2)
    u = (v[0] / nv, v[1] / nv)
    e0, e1 = mpmath.sqrt(lmax), mpmath.sqrt(lmin)
    dx, dy = F(p[0]) - F(center[0]), F(p[1]) - F(center[1])
    y0, y1 = abs(dx * u[0] + dy * u[1]), abs(-dx * u[1] + dy * u[0])
    if (y0 / e0) ** 2 + (y1 / e1) ** 2 <= 1:
        return mpmath.mpf(0)
    G = lambda t: (e0 * y0 / (t + e0 ** 2)) ** 2 + (e1 * y1 / (t + e1 ** 2)) ** 2 - 1    # noqa: E731
    lo, hi = -e1 ** 2 + e1 * y1, -e1 ** 2 + mpmath.sqrt(e0 ** 2 * y0 ** 2 + e1 ** 2 * y1 ** 2) + e0 ** 2
    for _ in range(300):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if G(mid) > 0 else (lo, mid)
    t = (lo + hi) / 2
    return mpmath.sqrt((t * y0 / (t + e0 ** 2)) ** 2 + (t * y1 / (t + e1 ** 2)) ** 2)


def _gamma_mp(X, cams, regions, ellipses):
    """gamma(X) in 50 digits; ``ellipses`` maps view -> (centre, D) of a filled ellipse, other views are points."""
    mpmath.mp.dps = 50
    Xh = [mpmath.mpf(float(v)) for v in X] + [mpmath.mpf(1)]
    tot = mpmath.mpf(0)
    for i, (P, r) in enumerate(zip(np.asarray(cams, float), regions)):
        hh = [mpmath.fsum(mpmath.mpf(float(P[k, j])) * Xh[j] for j in range(4)) for k in range(3)]
        p = (hh[0] / hh[2], hh[1] / hh[2])
        if i in ellipses:
            dist = _ellipse_distance_mp(*ellipses[i], p)
        else:
            c = np.asarray(r.center, float)
            dist = mpmath.sqrt((p[0] - mpmath.mpf(c[0])) ** 2 + (p[1] - mpmath.mpf(c[1])) ** 2)
        tot += dist ** 2
    return mpmath.sqrt(tot / (2 * len(cams)))


def _thin_ellipse_problem(seed):
    """Zero-noise points plus a filled ellipse 1e2-1e5 px long and 1e5-1e6 times thinner whose border passes just
    beside the last view's observation (review 43c's LOW-1 family)."""
    rng = np.random.default_rng(seed)
    sc = random_scene(4, 1, noise_px=0.0, seed=seed)
    C, x = np.asarray(sc.cameras, float), np.asarray(sc.points2d, float)[0]
    L, ratio = 10 ** rng.uniform(2, 5), 10 ** rng.uniform(5, 5.999)
    b, th = L / 2 / ratio, rng.uniform(0.2, 1.3)
    u = np.array([math.cos(th), math.sin(th)])
    v = np.array([-u[1], u[0]])
    c = x[-1] - rng.uniform(-0.4, 0.4) * L * u - (b + b * 10 ** rng.uniform(-3, 0)) * v
    D = (L / 2) ** 2 * np.outer(u, u) + b ** 2 * np.outer(v, v)
    E = Ellipse(c, 0.5 * (D + D.T))
    return C, [Point(xi) for xi in x[:-1]] + [E], {3: (np.asarray(E.center, float), np.asarray(E.D, float))}


@pytest.mark.parametrize("seed", [105, 7, 21])
def test_thin_ellipse_lower_bound_is_valid_after_normalisation(seed):
    """Review 43c LOW-1: the normalisation scaled D by s^2 with s not a power of two; at an axis ratio of ~1e6 the
    rounding moved the border, the normalised problem's bound exceeded the caller's optimum and gamma_lb was clamped
    to the rounded-up gamma_ub, above the exact gamma(X) (seed 105: by 1.6e-11 px, 1e-6 relative, certified).  With a
    power-of-two scale the similarity is exact."""
    C, regions, ellipses = _thin_ellipse_problem(seed)
    for res in (tritools.triangulate(C, regions), tritools.triangulate_many([(C, regions)])[0]):
        assert res.X is not None and res.gamma_lb is not None
        gX = _gamma_mp(res.X, C, regions, ellipses)
        assert mpmath.mpf(res.gamma_lb) <= gX, (seed, res.status, res.gamma_lb, float(gX))
        assert mpmath.mpf(res.gamma_ub) >= gX


@pytest.mark.parametrize("k", [1e6, 1e9])
def test_sum_of_ratios_with_a_scaled_numerator_is_certified(k):
    """Review 43b M3: the docs' example with the first numerator times 1e6 gave no bound at all (every back-end's
    PSD check failed on the second certificate's Gram block, ~1e-6 after the objective's normalisation); each
    certificate now has its own power-of-two weight.  Closed form: k (2 sqrt 5 - 4) + 3/2."""
    import sospoly as sp
    x, y = sp.variables("x y")
    r = sp.minimize_ratios([(k * (x ** 2 + 1), x + 2), (y ** 2 + 2, y ** 2 + 1)], ineq=[1 - x ** 2, 1 - y ** 2])
    exact = k * (2 * math.sqrt(5) - 4) + 1.5
    assert r.lower_bound is not None and r.upper_bound is not None, r.message
    assert r.lower_bound <= exact * (1 + 1e-15)
    assert r.optimal and r.status == sp.SolveStatus.OPTIMAL
    assert abs(r.upper_bound - exact) <= 1e-7 * exact


def test_fixed_multiplier_psatz_far_from_its_optimum_is_not_optimal():
    """Review 43b M2: min 1e8 x on the disc of radius 1e-6, degree 2, q = 1: the program's optimum is -100 (exact,
    s = 1e8 / (2r)); the solver's level -1719 passed the optimality rule (its floor used ||x||_inf over every decision
    variable, the multiplier's Gram entry ~1e12) and was reported OPTIMAL.  Now a level the rule accepts is the
    optimum to its tolerance, and whatever is reported stays a valid bound."""
    import sospoly as sp
    x, y = sp.variables("x y")
    r = 1e-6
    lb = sp.solve_psatz(sp.build_psatz(1e8 * x, ineq=[r ** 2 - x ** 2 - y ** 2], degree=2, multiplier=1.0))
    if lb.status == sp.SolveStatus.OPTIMAL:
        assert abs(lb.lower_bound + 100.0) <= 1e-3, lb.lower_bound
    assert lb.lower_bound is None or lb.lower_bound <= -100.0


@functools.lru_cache
def _fold_radius(k1, k2):
    """The first r > 0 where r (1 + k1 r^2 + k2 r^4) stops rising (a fine grid; 10 where it does not in [0, 10])."""
    rs = np.linspace(0.0, 10.0, 200001)
    slope = 1 + 3 * k1 * rs ** 2 + 5 * k2 * rs ** 4
    return float(rs[np.argmax(slope <= 0)]) if np.any(slope <= 0) else 10.0


def _radial_root(k1, k2, r_d):
    """The smallest r >= 0 with r (1 + k1 r^2 + k2 r^4) = r_d before the first fold (bisection), None where there is
    none, "edge" within 1e-6 of the fold's value (either answer is right)."""
    g = lambda r: r * (1 + k1 * r * r + k2 * r ** 4)        # noqa: E731
    end = _fold_radius(k1, k2)
    if abs(g(end) - r_d) <= 1e-6:
        return "edge"
    if g(end) < r_d:
        return None
    lo, hi = 0.0, end
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if g(mid) < r_d else (lo, mid)
    return 0.5 * (lo + hi)


@pytest.mark.parametrize("model, params, k1, k2, f, cx", [
    ("SIMPLE_RADIAL", (300.0, 320.0, 240.0, -0.3), -0.3, 0.0, 300.0, 320.0),
    ("RADIAL", (800.0, 320.0, 240.0, -0.5, 0.1), -0.5, 0.1, 800.0, 320.0),
    ("OPENCV", (500.0, 500.0, 320.0, 240.0, -0.5, 0.1, 0.0, 0.0), -0.5, 0.1, 500.0, 320.0),
    ("FULL_OPENCV", (300.0, 300.0, 320.0, 240.0, -0.5, 0.1, 0, 0, 0, 0, 0, 0), -0.5, 0.1, 300.0, 320.0)])
def test_undistortion_keeps_only_central_roots(model, params, k1, k2, f, cx):
    """Review 44b HIGH-1: the OPENCV family's Newton undistortion kept roots on the other side of the axis or past
    the fold of a negative k (SIMPLE_RADIAL f = 300, k = -0.3: 48952 of 56160 grid pixels accepted where COLMAP
    undistorts 622), and the own models' branch test looked at the root's Jacobian only (third-branch roots past
    the fold of k1 = -0.5, k2 = 0.1).  Along the horizontal axis every accepted root must be the central root
    (bisection before the fold), and every pixel with one must be accepted."""
    from tritools.io.colmap.camera_models import undistorted_pixels
    r_d = np.concatenate([np.linspace(-2.5, 2.5, 501), [0.59, 0.61, 0.7, 0.9, -0.933]])
    xy = np.column_stack([cx + f * r_d, np.full(len(r_d), 240.0)])
    und, ok = undistorted_pixels(model, params, xy)
    for rd, u, good in zip(r_d, und, ok):
        ref = _radial_root(k1, k2, abs(rd))
        if ref == "edge":
            continue
        assert good == (ref is not None), (rd, u, good, ref)
        if good:
            assert (u[0] - cx) / f == pytest.approx(np.sign(rd) * ref, rel=1e-9, abs=1e-12), rd


def test_keypoint_beyond_the_fold_is_not_certified():
    """Review 44b HIGH-1 end to end: a keypoint inside a SIMPLE_RADIAL image beyond the model's fold (no central
    root; pycolmap's cam_from_img gives NaN) made its track certified at gamma 168 px; it is invalid_input now."""
    from tritools.io.colmap import Camera, Image, Model, Point3D, qvec_from_rotation
    from tritools.io.colmap.camera_models import pixels_from_camera
    from tritools.sfm import retriangulate

    params = (300.0, 320.0, 240.0, -0.3)
    cam = Camera(1, "SIMPLE_RADIAL", 640, 480, params)
    poses = [np.array([0.0, 0, 5]), np.array([-0.5, 0, 5]), np.array([0.5, 0, 5])]
    kps = [tuple(pixels_from_camera("SIMPLE_RADIAL", params, (t + np.array([0.0, 0.0, 0.0]))[None])[0]) for t in poses]
    kps[2] = (40.0, 0.0)
    images = {k + 1: Image(k + 1, tuple(qvec_from_rotation(np.eye(3))), tuple(t), 1, f"im{k}.jpg",
                           ((float(kps[k][0]), float(kps[k][1]), 1),)) for k, t in enumerate(poses)}
    model = Model({1: cam}, images, {1: Point3D(1, (0.01, 0.0, 0.0), (1, 2, 3), 0.0, ((1, 0), (2, 0), (3, 0)))})
    _, rep = retriangulate(model)
    r = rep.records[0]
    assert r.status.value == "invalid_input" and not r.certified, (r.status, r.message)


def test_bad_executor_is_refused_when_the_options_are_built():
    """Review 44b MEDIUM-1: RetriangulationOptions(executor=5) was accepted and died with AttributeError in the
    batch once a point needed an SDP; one rule (``batch.executor_problem``) for both entry points now."""
    from tritools.sfm import RetriangulationOptions
    with pytest.raises(ValueError, match="executor"):
        RetriangulationOptions(executor=5)
    with pytest.raises(TypeError, match="executor"):
        tritools.triangulate_many([], executor="process")
    assert RetriangulationOptions(executor=None).executor is None
    from concurrent.futures import ThreadPoolExecutor
    with pytest.raises(ValueError, match="executor"):
        RetriangulationOptions(executor=ThreadPoolExecutor)           # the class, not an instance (review 44c L3)


def test_retriangulate_folder_names_a_missing_path(tmp_path):
    """Review 44b LOW-4: retriangulate_folder(None, out) raised os.stat's TypeError, which names no argument."""
    from tritools.sfm import retriangulate_folder
    with pytest.raises(TypeError, match="in_dir"):
        retriangulate_folder(None, tmp_path / "out")
    with pytest.raises(TypeError, match="out_dir"):
        retriangulate_folder(tmp_path, 3)


def test_masked_thresholds_are_refused():
    """Review 44a LOW-2: np.asarray drops a masked array's mask, so a masked threshold was used as if unmasked."""
    sc = random_scene(3, 1, noise_px=1.0, seed=2)
    c = np.ma.masked_array([2.0, 3.0, 4.0], mask=[False, True, False])
    with pytest.raises(ValueError, match="masked"):
        tritools.triangulate(sc.cameras, sc.points2d[0], robust=c)
    r = tritools.triangulate(sc.cameras, sc.points2d[0], robust=c.filled(np.inf))
    assert r.inliers is not None and len(r.inliers) == 3


#: review 44b MEDIUM-2: three PINHOLE views, one keypoint moved to (1e9, -1e9) px
_FAR_P = [[[669.7027251688561, 0.0, 542.1238418492657, 2560.0], [-70.92484959872152, 820.0, 229.28075739014542, 1920.0],
           [-0.29552020666133966, 0.0, 0.955336489125606, 8.0]],
          [[800.0, 0.0, 320.0, 2560.0], [0.0, 820.0, 240.0, 1920.0], [0.0, 0.0, 1.0, 8.0]],
          [[858.8356574321134, 0.0, 69.29151119112218, 2560.0], [70.92484959872152, 820.0, 229.28075739014542, 1920.0],
           [0.29552020666133966, 0.0, 0.955336489125606, 8.0]]]
_FAR_X = [[1e9, -1e9], [322.8857526674369, 341.5445398430696], [345.5763409773566, 340.8400799737439]]


@pytest.mark.parametrize("batch", [False, True])
def test_a_step_bound_above_the_plans_best_estimate_is_refuted(batch):
    """Review 44b MEDIUM-2: the Theorem 1 delta = 4 step's stalled iterate gave gamma_LB ~4650 px beside its own
    estimate at ~4680 px, while another step's estimate costs ~1736 px; the plan reported the largest lower bound
    clipped to the best gamma_UB (rounded up), above gamma(X) >= gamma*.  Such a bound is refuted now, and the
    largest bound of the other steps is reported (the iterate's invalid bound itself: an open finding)."""
    P, x = np.array(_FAR_P), np.array(_FAR_X)
    r = tritools.triangulate_many([(P, x)])[0] if batch else tritools.triangulate(P, x)
    assert r.X is not None and not r.optimal
    gX = _gamma_mp(r.X, P, [Point(v) for v in x], {})
    assert r.gamma_lb is None or mpmath.mpf(r.gamma_lb) <= gX, (r.gamma_lb, float(gX), r.message)
    assert mpmath.mpf(r.gamma_ub) >= gX


def test_power_of_two_scale_only_for_thin_ellipses():
    """The normalisation's image scale is a power of two (the similarity exact) when a region declares
    ``exact_scale`` (a filled ellipse or border thinner than EXACT_SCALE_RATIO), and the residual rule's own scale
    otherwise; ``power_of_two_below`` is the largest power of two at or below its argument, within SCALE_BOUNDS."""
    from tritools import EllipseBorder
    from tritools.model.normalize import SCALE_BOUNDS, normalization_for, power_of_two_below
    from tritools.model.regions.ellipse import EXACT_SCALE_RATIO
    for s in (3.0, 0.5, 1e-3, 7e7, 1.5e-8):
        p = power_of_two_below(s)
        assert math.frexp(p)[0] == 0.5 and (p <= s < 2 * p or p == 2 * power_of_two_below(s / 2) >= SCALE_BOUNDS[0])
    C, regions, _ = _thin_ellipse_problem(105)
    assert regions[-1].exact_scale and not Ellipse([0.0, 0.0], np.diag([4.0, 1.0])).exact_scale
    assert EllipseBorder([0.0, 0.0], np.diag([(EXACT_SCALE_RATIO * 1.01) ** 2, 1.0])).exact_scale
    s = normalization_for(C, regions).scale
    assert math.frexp(s)[0] == 0.5
    pts = [Point(r.center) for r in regions]
    s_pts = normalization_for(C, pts).scale
    assert s_pts != power_of_two_below(s_pts) and power_of_two_below(s_pts) == s


def test_full_opencv_analytic_jacobian_matches_central_differences():
    """The central-branch test's analytic Jacobian of FULL_OPENCV (tangential and rational terms) against central
    differences of the forward map (their own error ~1e-8 at these steps)."""
    from tritools.io.colmap import lens
    rng = np.random.default_rng(1)
    for _ in range(5):
        e = dict(zip(("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"),
                     rng.normal(scale=[0.3, 0.1, 0.01, 0.01, 0.05, 0.1, 0.05, 0.02])))
        uv = rng.normal(scale=0.6, size=(200, 2))
        Ja = lens._full_opencv_jacobian(e, uv)
        Jn = lens._jacobian(lambda p: lens.forward("FULL_OPENCV", e, p), uv)
        assert np.max(np.abs(Ja - Jn) / (1 + np.abs(Jn))) < 1e-6
