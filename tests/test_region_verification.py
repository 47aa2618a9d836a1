"""Issue #22: the degree-2 verification with region multipliers for every region type
(tritools.solve.regions_verify, the single path's ``verify-regions``; tritools.solve.ellipses, the vectorised
filled ellipses of triangulate_many).  References are independent: the delta = 2 SDP of the same program
(a certificate by verification must be one the SDP gives too, at the same value) and dense multi-start
Levenberg-Marquardt on the exact distances (gamma_LB never above an attained value)."""
from __future__ import annotations

import numpy as np
import pytest

import tritools
from tritools.model.geometry import dlt, refine_l2, validate_cameras
from tritools.model.regions import Ellipse, EllipseBorder, Point, Polytope, Segment
from tritools.scene import random_scene
from tritools.solve.ellipses import verify_ellipses
from tritools.solve.options import options_from
from tritools.solve.regions_verify import (closest_on_ellipses, reduce_views, region_bound, region_forms,
                                           view_quadratics)
from tritools.solve.stages import FAST_DEFAULT, ImplName, run_point
from tritools.solve.stages.context import PointContext

#: bounds of one program by two methods agree to the certificate rule's gap tolerance in c = 2N gamma^2 units
#: (gap_abs + gap_rel = 2e-6 at a normalised c of order one: both bounds lie within it below the same upper bound)
C_TOL = 2e-6


def _rotation(rng) -> np.ndarray:
    a = rng.uniform(0, np.pi)
    return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])


def _region(kind: str, p, rng, size: float = 1.0):
    """A region of ``kind`` around the keypoint p (pixels), a few pixels across, random orientation."""
    R = _rotation(rng)
    if kind == "ellipse":
        return Ellipse(p, size ** 2 * R @ np.diag([1.0, 0.1]) @ R.T)
    if kind == "border":
        return EllipseBorder(p, size ** 2 * R @ np.diag([1.0, 0.3]) @ R.T)
    if kind == "segment":
        return Segment(p, size * R[:, 0])
    if kind == "box":
        B = np.diag([1 / (0.7 * size), 1 / (0.3 * size)]) @ R.T
        return Polytope(B, -B @ np.asarray(p, float))
    if kind == "mixed":
        return _region(("ellipse", "box", "segment", "point")[rng.integers(4)], p, rng, size)
    return Point(p)


def _problems(kind: str, n_views: int, n_points: int, noise: float, seed: int, size: float = 1.0):
    sc = random_scene(n_views, n_points, noise_px=noise, seed=seed)
    rng = np.random.default_rng(seed)
    cams = validate_cameras(sc.cameras)
    return [(cams, [_region(kind, p, rng, size) for p in sc.points2d[j]]) for j in range(n_points)]


def _multistart(cams, regions, X0, starts: int = 12) -> float:
    """An independent upper reference on gamma*: the best LM local optimum from perturbed starts."""
    rng = np.random.default_rng(1)
    X0 = np.asarray(X0, float)
    best = float(tritools.gamma(X0, cams, regions))
    for _ in range(starts):
        X = refine_l2(X0 + rng.normal(scale=0.2 * (1 + np.linalg.norm(X0)), size=3), cams, regions)
        if X is not None:
            best = min(best, float(tritools.gamma(X, cams, regions)))
    return best


def _c(g, n):
    return 2 * n * g * g


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["ellipse", "border", "segment", "box", "mixed"])
def test_a_verification_certificate_is_one_of_the_delta2_sdp(kind):
    """Every certificate of ``verify-regions`` is also the delta = 2 SDP's, at the same value; gamma_LB is never
    above the multi-start reference; the path certifies a share of every type (for boxes and segments only where
    no view sits on a single face / inside a segment, see the module docstring)."""
    n_cert = 0
    for n_views, seed in ((3, 1), (5, 2)):
        for cams, regions in _problems(kind, n_views, 2, 2.0, seed, 0.2 if kind == "segment" else 1.0):
            r = tritools.triangulate(cams, regions)
            assert r.gamma_lb <= _multistart(cams, regions, r.X) * (1 + 1e-9) + 1e-12
            if r.certified_by != "verification":
                continue
            n_cert += 1
            assert r.optimal and r.attempts[0].step == "verification"
            sdp = tritools.triangulate(cams, regions, path="sdp", method="corollary1", delta=2, max_delta=2)
            assert sdp.optimal, f"verification certified {kind} at N={n_views}, the delta = 2 SDP does not"
            N = len(regions)
            assert abs(_c(sdp.gamma_lb, N) - _c(r.gamma_lb, N)) <= C_TOL * max(1.0, _c(r.gamma_ub, N))
            assert abs(sdp.gamma_ub - r.gamma_ub) <= 1e-6 * max(1.0, r.gamma_ub)
    assert n_cert >= (2 if kind == "ellipse" else 1)


def _ctx(cams, regions):
    return PointContext(cams, regions, options_from(None), 0.0)


@pytest.mark.parametrize("kind", ["ellipse", "border", "segment", "box", "point"])
def test_the_bound_holds_at_any_candidate(kind):
    """The Lagrangian bound is a lower bound whatever the candidate (here a perturbed, non-optimal one): its
    multipliers then are not the optimal ones, the bound weaker, never above gamma*'s reference."""
    for cams, regions in _problems(kind, 4, 3, 3.0, 7):
        ctx = _ctx(cams, regions)
        Xn = ctx.local()[1]
        ref = _multistart(cams, regions, ctx.norm.world_point(Xn))
        for shift in (0.0, 1e-3, 3e-2):
            Xp = Xn + shift * np.array([1.0, -0.5, 0.3])
            lo, up, _ = region_bound(ctx.cams, ctx.cams_n, ctx.regs_n, Xp, [r.extent().radius for r in ctx.regs_n],
                                     resolution=ctx.norm.resolution)
            if np.isfinite(lo):
                assert tritools.solve.decide.gamma_from_c(lo, 4, ctx.norm.scale) <= ref * (1 + 1e-9) + 1e-12


def test_view_quadratics_are_the_exact_minimum_over_the_region_variables():
    """min over y of the view's Lagrangian (dense grid search over y) equals x^T W x + 2 w^T x + q0."""
    rng = np.random.default_rng(3)
    p = np.zeros(2)
    for kind in ("ellipse", "border", "box", "segment"):
        reg = _region(kind, p, rng, size=1.0)
        u = np.array([2.0, 1.3])                       # outside every region: positive multipliers
        vq = view_quadratics(region_forms([reg]), [reg], u[None])
        assert vq.valid.all()
        x = np.array([0.4, -2.1])
        pred = x @ vq.W[0, 0] @ x + 2 * vq.w[0, 0] @ x + vq.q0[0, 0]
        # the multipliers and the Lagrangian of this view, recomputed from the reduced form's eigen data
        omega, Q, a, const, bounded = reduce_views(vq)
        z = Q[0, 0].T @ (x - a[0, 0])
        assert bounded.all()
        assert float(np.sum(omega[0, 0] * z * z) + const[0, 0]) == pytest.approx(pred, rel=1e-9, abs=1e-9)
        assert pred <= float(np.sum((x - reg.closest_point(x)) ** 2)) + 1e-12    # min L_y <= d(x, R)^2


@pytest.mark.parametrize("scale,shift", [(1e-3, 0.0), (1.0, 0.0), (1e3, 1e6)])
def test_ellipses_follow_the_image_units(scale, shift):
    """Vectorised ellipses: pixel coordinates and shapes scaled and shifted, gamma scales with the image, the
    decision is the same; thin ellipses (axis ratio 1e4) included."""
    sc = random_scene(5, 6, noise_px=2.0, seed=31)
    C = np.asarray(sc.cameras)
    rng = np.random.default_rng(0)
    D = np.array([[(R := _rotation(rng)) @ np.diag([1.0, 1e-8 if (j + i) % 3 == 0 else 0.2]) @ R.T
                   for i in range(5)] for j in range(6)])
    T = np.array([[scale, 0, shift], [0, scale, shift], [0, 0, 1.0]])
    C2 = np.einsum("ij,njk->nik", T, C)
    ref = verify_ellipses(np.broadcast_to(C, (6,) + C.shape), sc.points2d, D)
    new = verify_ellipses(np.broadcast_to(C2, (6,) + C2.shape), scale * sc.points2d + shift, scale ** 2 * D)
    assert ref.certified.sum() >= 4
    np.testing.assert_array_equal(new.certified, ref.certified)
    np.testing.assert_allclose(new.gamma_ub / scale, ref.gamma_ub, rtol=1e-6)
    np.testing.assert_allclose(new.gamma_lb[ref.certified] / scale, ref.gamma_lb[ref.certified], rtol=1e-5)
    for j in np.nonzero(ref.certified)[0]:
        regs = [Ellipse(p, d) for p, d in zip(sc.points2d[j], D[j])]
        assert ref.gamma_lb[j] <= _multistart(C, regs, ref.X[j]) * (1 + 1e-9) + 1e-12


@pytest.mark.slow
def test_vectorised_ellipses_equal_the_delta2_sdp():
    """triangulate_many on filled ellipses (vectorised path) against the delta = 2 SDP of each problem."""
    probs = _problems("ellipse", 4, 5, 2.0, 41)
    res = tritools.triangulate_many(probs, progress=False)
    assert sum(r.certified_by == "verification" for r in res) >= 4
    for (cams, regions), r in zip(probs, res):
        if r.certified_by != "verification":
            continue
        assert "batch_share" in r.timings                  # through the vectorised ellipse group
        sdp = tritools.triangulate(cams, regions, path="sdp", method="corollary1", delta=2, max_delta=2)
        assert sdp.optimal
        assert abs(_c(sdp.gamma_lb, 4) - _c(r.gamma_lb, 4)) <= C_TOL * max(1.0, _c(r.gamma_ub, 4))


def test_views_inside_their_region_and_many_views_use_the_band(monkeypatch):
    """Discs and ellipses at 30 views where some views lie inside their region (zero noise in those views): the
    kept views are compacted, so the band of view pairs certifies them without the all-pairs bound."""
    import tritools.solve.fastpath as fp

    sc = random_scene(30, 4, noise_px=1.0, seed=5)
    C = np.asarray(sc.cameras)
    x = np.array(sc.points2d)
    x[:, ::4] = sc.points2d_true[:, ::4]             # every 4th view exact: inside a 1 px region
    calls = []
    orig = fp._all_pairs_bounds
    monkeypatch.setattr(fp, "_all_pairs_bounds", lambda *a, **k: calls.append(1) or orig(*a, **k))
    probs = [(C, [Ellipse(p, np.eye(2)) for p in x[j]]) for j in range(4)]
    probs += [(C, [Ellipse(p, np.diag([2.0, 0.5])) for p in x[j]]) for j in range(4)]
    res = tritools.triangulate_many(probs, progress=False)
    assert all(r.optimal and r.certified_by == "verification" for r in res)
    assert not calls
    for (cams, regions), r in zip(probs, res):
        assert r.gamma_lb <= _multistart(cams, regions, r.X, starts=3) * (1 + 1e-9) + 1e-12


def test_adversarial_regions():
    """Degenerate polytopes (touching slabs: a segment), duplicated views, a huge region holding every view's
    projection (gamma* = 0), a georeferenced world: never a contradiction, gamma_LB below the reference."""
    sc = random_scene(4, 2, noise_px=2.0, seed=9)
    cams = validate_cameras(sc.cameras)
    p = sc.points2d[0]
    rng = np.random.default_rng(2)
    B = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])      # the third slab touches a corner: a point polytope
    cases = [
        [Polytope(B, -(B @ p[i]) - [0.0, 0.0, 3.0]) if i == 0 else _region("box", p[i], rng) for i in range(4)],
        [_region("ellipse", p[i], rng) for i in (0, 1, 1, 2)],
        [Ellipse(p[i], 1e6 * np.eye(2)) for i in range(4)],
    ]
    camsets = [cams, cams[[0, 1, 1, 2]], cams]
    for c, regs in zip(camsets, cases):
        r = tritools.triangulate(c, regs)
        assert r.gamma_lb is None or r.gamma_lb <= r.gamma_ub
        assert r.gamma_lb <= _multistart(c, regs, r.X) * (1 + 1e-9) + 1e-12
    huge = tritools.triangulate(cams, cases[2])
    assert huge.optimal and huge.gamma_ub < 1e-10          # 0 up to the projections' round-off margin
    # a georeferenced world: the same problem translated by 1e6 m
    H = np.eye(4)
    H[:3, 3] = -1e6
    geo = np.einsum("nij,jk->nik", cams, H)
    regs = [_region("ellipse", q, np.random.default_rng(4)) for q in p]
    a, b = tritools.triangulate(cams, regs), tritools.triangulate(geo, regs)
    assert a.optimal == b.optimal and b.gamma_ub == pytest.approx(a.gamma_ub, rel=1e-5, abs=1e-9)


def test_closest_points_on_thin_ellipses():
    """The Newton secular iteration against the regions' own closest point (Eberly's bisection), axis ratios
    up to 1e4, points near and far."""
    rng = np.random.default_rng(1)
    for ax in ([1.0, 1.0], [3.0, 0.5], [1e4, 1.0], [1.0, 1e-4]):
        sig = np.array(ax)
        U = rng.normal(size=(500, 2)) * sig * rng.choice([0.5, 2.0, 100.0], size=(500, 1))
        Y, t = closest_on_ellipses(U, np.broadcast_to(sig, (500, 2)))
        ref = Ellipse([0.0, 0.0], np.diag(sig ** 2)).closest_point(U)
        d, d_ref = np.linalg.norm(U - Y, axis=1), np.linalg.norm(U - ref, axis=1)
        np.testing.assert_allclose(d, d_ref, rtol=1e-10, atol=1e-12 * sig.max())
        assert np.all(t >= 0) and np.all((t > 0) == (np.sum(U ** 2 / sig ** 2, axis=1) > 1))


def test_dlt_reference_is_independent():
    """The multi-start reference does not use the code under test: it only calls refine_l2 and gamma."""
    cams, regions = _problems("ellipse", 3, 1, 1.0, 3)[0]
    X0 = dlt(cams, np.array([r.center for r in regions]))
    assert np.isfinite(_multistart(cams, regions, X0))


def test_vectorised_mixed_points_discs_ellipses_equal_the_single_path():
    """Problems mixing points, discs and ellipses go through the vectorised ellipse group (D = 0 for a point);
    a single call takes the same path on a stack of one (the same numbers); each equals ``verify-regions`` (an
    independent implementation: the regions' own closest points, scipy LM) in decision and bounds, and stays
    below the multi-start reference."""
    sc = random_scene(6, 6, noise_px=1.5, seed=12)
    cams = validate_cameras(sc.cameras)
    rng = np.random.default_rng(5)
    kinds = (lambda p: Point(p), lambda p: Ellipse(p, np.eye(2)), lambda p: _region("ellipse", p, rng))
    probs = [(cams, [kinds[(i + j) % 3](p) for i, p in enumerate(sc.points2d[j])]) for j in range(6)]
    many = tritools.triangulate_many(probs, progress=False)
    assert sum(r.optimal for r in many) >= 5
    regions_only = FAST_DEFAULT - {ImplName.VERIFY_ELLIPSES}
    for (c, regs), r in zip(probs, many):
        one = run_point(c, regs, options_from(None), fast=regions_only)
        same = tritools.triangulate(c, regs)                 # the vectorised path on a stack of one
        assert [a.step for a in same.attempts] == ["verification"] and same.optimal == r.optimal
        assert same.gamma_lb == pytest.approx(r.gamma_lb, rel=1e-12, abs=1e-15)
        assert "batch_share" in r.timings and r.optimal == one.optimal
        assert abs(_c(r.gamma_lb, 6) - _c(one.gamma_lb, 6)) <= C_TOL * max(1.0, _c(one.gamma_ub, 6))
        assert r.gamma_ub == pytest.approx(one.gamma_ub, rel=1e-6, abs=1e-9)
        assert r.gamma_lb <= _multistart(c, regs, r.X, starts=4) * (1 + 1e-9) + 1e-12


def test_zero_noise_and_duplicated_views():
    """Vectorised ellipses at 14 views: zero noise (every view inside its region: no view kept, gamma* = 0), and
    a duplicated view (coincident centres: that pair carries no constraint) with noise."""
    sc = random_scene(14, 3, noise_px=0.0, seed=17)
    C = np.asarray(sc.cameras)
    rng = np.random.default_rng(1)
    D = [(R := _rotation(rng)) @ np.diag([1.0, 0.3]) @ R.T for _ in range(14)]
    exact = [(C, [Ellipse(p, d) for p, d in zip(sc.points2d[j], D)]) for j in range(3)]
    for r in tritools.triangulate_many(exact, progress=False):
        assert r.optimal and r.gamma_ub == pytest.approx(0.0, abs=1e-9) and r.gamma_lb == 0.0
    noisy = random_scene(14, 3, noise_px=2.0, seed=17)
    Cd = np.concatenate([C, C[:1]])
    dup = [(Cd, [Ellipse(p, d) for p, d in zip(np.vstack([q, q[:1] + [0.5, -0.5]]), D + D[:1])])
           for q in noisy.points2d]
    for (c, regs), r in zip(dup, tritools.triangulate_many(dup, progress=False)):
        assert r.gamma_lb <= r.gamma_ub and r.gamma_lb <= _multistart(c, regs, r.X, starts=3) * (1 + 1e-9) + 1e-12
        assert r.optimal


@pytest.mark.parametrize("scale,shift", [(1e-3, 0.0), (1e3, 0.0), (3.0, -3e5)])
def test_region_bounds_follow_the_image_units(scale, shift):
    """verify-regions on segments, corners of boxes and ellipses: the same problem in image units scaled by
    1e-3..1e3 and shifted (coordinates up to ~1e6 px) gives the same decision and gamma bounds scaled by the
    same factor."""
    rng = np.random.default_rng(8)
    sc = random_scene(4, 2, noise_px=2.0, seed=23)
    cams = validate_cameras(sc.cameras)
    T = np.array([[scale, 0, -scale * shift], [0, scale, -scale * shift], [0, 0, 1.0]])
    kinds = ("ellipse", "segment", "ellipse", "box")
    for j in range(2):
        regs = [_region(k, p, rng, 0.2 if k == "segment" else 1.0) for k, p in zip(kinds, sc.points2d[j])]
        out = []
        for C, R in ((cams, regs), (np.einsum("ij,njk->nik", T, cams), [r.similarity(scale, [shift, shift])
                                                                          for r in regs])):
            ctx = _ctx(C, R)
            lo, up, _ = region_bound(ctx.cams, ctx.cams_n, ctx.regs_n, ctx.local()[1],
                                     [r.extent().radius for r in ctx.regs_n], resolution=ctx.norm.resolution)
            g = tritools.solve.decide.gamma_from_c
            out.append((g(lo, 4, ctx.norm.scale) if np.isfinite(lo) else np.nan, g(up, 4, ctx.norm.scale)))
        (lo0, up0), (lo1, up1) = out
        assert up1 == pytest.approx(scale * up0, rel=1e-6)
        met0, met1 = (bool(np.isfinite(lo) and lo >= up * (1 - 1e-6)) for lo, up in out)
        assert met0 == met1                            # the same decision (bounds meet or not)
        if met0:
            assert lo1 == pytest.approx(scale * lo0, rel=1e-5)
        for lo, up in out:                             # never above the attained value
            assert not lo > up * (1 + 1e-9)
