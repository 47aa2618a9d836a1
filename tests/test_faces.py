"""Issue #22: verification of views whose candidate lies inside a segment or on one face of a polytope
(tritools.solve.faces: a positive multiplier on the inactive constraints, priced within the tolerance).

References are independent of the code under test: multi-start Levenberg-Marquardt on the exact distances to
the regions (an attained value: gamma_LB never above it) and the delta = 2 SDP of the same program (a
certificate by verification is one of the SDP's, at the same value)."""
from __future__ import annotations

import numpy as np
import pytest

import tritools
from sospoly import DEFAULT_TOLERANCES as tol
from tritools.model.regions import Polytope, Segment
from tritools.solve import faces
from tritools.solve.decide import gamma_from_c
from tritools.solve.options import options_from
from tritools.solve.regions_verify import region_bound
from tritools.solve.stages.context import PointContext

from tests.test_region_verification import C_TOL, _c, _multistart, _problems


def _bounds(cams, regions):
    """(c_lower, c_upper, tolerance) of region_bound at the local optimum, with the context's normalisation."""
    ctx = PointContext(cams, regions, options_from(None), 0.0)
    Xn = ctx.local()[1]
    lo, up, _ = region_bound(ctx.cams, ctx.cams_n, ctx.regs_n, Xn, [r.extent().radius for r in ctx.regs_n],
                             resolution=ctx.norm.resolution)
    return lo, up, ctx


def test_face_multipliers_certify_what_the_kkt_multipliers_do_not(monkeypatch):
    """On small boxes and segments some problems certify only with the face multiplier (the KKT ones leave a zero
    weight along the face); every such bound is below the multi-start reference."""
    gained = 0
    for kind, size, n_views, seed in (("box", 0.3, 4, 3), ("segment", 0.2, 4, 3)):
        for cams, regions in _problems(kind, n_views, 4, 2.0, seed, size):
            lo, up, ctx = _bounds(cams, regions)
            with monkeypatch.context() as m:
                m.setattr(faces, "FACE_MU_FRACTIONS", ())
                lo0, up0, _ = _bounds(cams, regions)
            assert up == up0
            assert not (lo < lo0)                         # the KKT bound is one of those tried: never lower
            if np.isfinite(lo):
                ref = _multistart(cams, regions, ctx.norm.world_point(ctx.local()[1]))
                assert gamma_from_c(lo, n_views, ctx.norm.scale) <= ref * (1 + 1e-9) + 1e-12
            gained += bool(tol.certified(lo, up)) and not bool(np.isfinite(lo0) and tol.certified(lo0, up0))
    assert gained >= 2


@pytest.mark.slow
@pytest.mark.parametrize("kind,size", [("box", 0.3), ("segment", 0.2)])
def test_face_certificates_are_ones_of_the_delta2_sdp(kind, size):
    n_cert = 0
    for n_views, seed in ((5, 2), (4, 3)):
        for cams, regions in _problems(kind, n_views, 4, 2.0, seed, size):
            r = tritools.triangulate(cams, regions)
            assert r.gamma_lb <= _multistart(cams, regions, r.X) * (1 + 1e-9) + 1e-12
            if r.certified_by != "verification":
                continue
            n_cert += 1
            sdp = tritools.triangulate(cams, regions, path="sdp", method="corollary1", delta=2, max_delta=2)
            assert sdp.optimal
            N = len(regions)
            assert abs(_c(sdp.gamma_lb, N) - _c(r.gamma_lb, N)) <= C_TOL * max(1.0, _c(r.gamma_ub, N))
    assert n_cert >= 4


@pytest.mark.slow
@pytest.mark.parametrize("k", [1e-3, 1.0, 1e6])
def test_pixel_scale_does_not_change_the_verdict_or_break_the_bound(k):
    """Image coordinates scaled by k (cameras K -> diag(k, k, 1) K, regions scaled about the origin): gamma scales
    by k, the bounds stay below the scaled reference, a certificate stays a certificate."""
    S = np.diag([k, k, 1.0])
    for cams, regions in _problems("box", 5, 3, 2.0, 2, 0.3) + _problems("segment", 4, 3, 2.0, 3, 0.2):
        base = tritools.triangulate(cams, regions)
        sc_regions = [Polytope(r.B / k, r.c) if isinstance(r, Polytope) else Segment(k * r.center, k * r.direction)
                      for r in regions]
        r = tritools.triangulate(np.einsum("ij,njk->nik", S, cams), sc_regions)
        ref = _multistart(cams, regions, base.X)
        assert r.gamma_lb <= k * ref * (1 + 1e-8) + 1e-12 * k
        assert r.gamma_lb <= r.gamma_ub
        assert r.optimal == base.optimal
        if r.optimal:
            assert r.gamma_ub == pytest.approx(k * base.gamma_ub, rel=1e-5, abs=1e-9 * k)


def test_degenerate_segment_and_segment_end():
    """A zero-length segment is its point (same verdict and value); a segment whose end is the optimum's
    projection (the rest of it pointing away) keeps a valid bound and certifies with its end multiplier."""
    (cams, regions), = _problems("point", 4, 1, 2.0, 5)
    pts = tritools.triangulate(cams, regions)
    zero = tritools.triangulate(cams, [Segment(regions[0].center, [0.0, 0.0])] + regions[1:])
    assert zero.optimal == pts.optimal and zero.gamma_ub == pytest.approx(pts.gamma_ub, rel=1e-9)
    u0 = pts.image_points[0]
    away = u0 - regions[0].center                          # from the observed point towards the projection
    d = 3.0 * away / np.linalg.norm(away)
    end = [Segment(u0 + d, d)] + regions[1:]               # t = -1 at the optimum's projection u0
    r = tritools.triangulate(cams, end)
    ref = _multistart(cams, end, r.X)
    assert r.gamma_lb <= ref * (1 + 1e-9) + 1e-12
    assert r.optimal
    assert r.gamma_ub <= pts.gamma_ub * (1 + 1e-9)          # the segment holds the point's optimum projection


@pytest.mark.slow
def test_thin_boxes_keep_valid_bounds():
    """Boxes of 1 x 0.002 px (nearly segments: the face multiplier's weight across the long face is large) and
    1e-3 x 1 px: gamma_LB never above the multi-start reference; a verification certificate agrees with the
    delta = 2 SDP where that certifies (on the 1e-3 px boxes the SDP's rounding-safe bound is weaker: 0.8335888 vs
    0.8335895 for an attained 0.83358952, not certified, or Clarabel stops with InsufficientProgress -- numerics of
    B entries ~2e3 per px, not a wrong bound)."""
    rng = np.random.default_rng(11)
    n_cert = 0
    for n_views, seed, (w, h) in ((4, 3, (0.5, 1e-3)), (5, 2, (5e-4, 0.5))):
        sc = tritools.scene.random_scene(n_views, 3, noise_px=2.0, seed=seed)
        for j in range(3):
            regions = []
            for p in sc.points2d[j]:
                a = rng.uniform(0, np.pi)
                B = np.diag([1 / w, 1 / h]) @ np.array([[np.cos(a), np.sin(a)], [-np.sin(a), np.cos(a)]])
                regions.append(Polytope(B, -B @ p))
            r = tritools.triangulate(sc.cameras, regions)
            assert r.gamma_lb <= _multistart(sc.cameras, regions, r.X) * (1 + 1e-9) + 1e-12
            if r.certified_by == "verification":
                n_cert += 1
                sdp = tritools.triangulate(sc.cameras, regions, path="sdp", method="corollary1", delta=2, max_delta=2)
                gap = C_TOL * max(1.0, _c(r.gamma_ub, n_views))
                assert sdp.gamma_lb is None or _c(sdp.gamma_lb, n_views) <= _c(r.gamma_ub, n_views) + gap
                if sdp.optimal:
                    assert abs(_c(sdp.gamma_lb, n_views) - _c(r.gamma_lb, n_views)) <= gap
    assert n_cert >= 2


@pytest.mark.slow
@pytest.mark.parametrize("kind,size", [("segment", 0.2), ("box", 0.3)])
def test_many_duplicated_and_georeferenced_views(kind, size):
    """14 views (the band of view pairs on the kept views), a duplicated view, and the world moved 1e6 units
    away: gamma_LB never above the multi-start reference (the untranslated problem's, to 1e-7), and
    the face multipliers still certify by verification."""
    n_ver = 0
    for cams, regions in _problems(kind, 14, 2, 2.0, 9, size):
        r = tritools.triangulate(cams, regions)
        assert r.gamma_lb <= _multistart(cams, regions, r.X) * (1 + 1e-9) + 1e-12
        n_ver += r.certified_by == "verification"
    for cams, regions in _problems(kind, 4, 2, 2.0, 3, size):
        dup_c, dup_r = np.concatenate([cams, cams[:1]]), regions + regions[:1]
        r = tritools.triangulate(dup_c, dup_r)
        assert r.gamma_lb <= _multistart(dup_c, dup_r, r.X) * (1 + 1e-9) + 1e-12
        n_ver += r.certified_by == "verification"
        T = np.eye(4)
        T[:3, 3] = -np.array([1e6, 2e6, 3e5])
        base = tritools.triangulate(cams, regions)
        geo = tritools.triangulate(np.einsum("nij,jk->nik", cams, T), regions)
        # C T rounds the cameras (entries ~1e9 in the last column) and gamma at |X| ~ 1e6 is evaluated with
        # ~1e-9 relative error, so the translated problem is the original one only to ~1e-8 (main: the same)
        assert geo.gamma_lb <= _multistart(cams, regions, base.X) * (1 + 1e-7)
        assert geo.optimal == base.optimal
        n_ver += geo.certified_by == "verification"
    assert n_ver >= 4


def test_no_face_multiplier_started_without_the_time_the_last_bound_took():
    """Each bound of face_bound costs about the same and its view quadratics do not look at the deadline: a
    multiplier is not tried once less is left than the last bound took (issue #22: calls past their limit)."""
    import time

    from sospoly.budget import Deadline
    from tritools.solve.regions_verify import region_forms

    forms = region_forms([Segment([0.0, 0.0], [1.0, 0.0]), Segment([1.0, 1.0], [0.0, 1.0])])
    calls = []

    def bound_at(mu):
        calls.append(mu)
        time.sleep(0.03)
        return 0.0                              # never certifies against c_upper = 1

    faces.face_bound(bound_at, forms, 1.0, tol, deadline=Deadline.after(0.05))
    assert len(calls) == 1                      # 20 ms left after the first 30 ms bound
    calls.clear()
    faces.face_bound(bound_at, forms, 1.0, tol, deadline=Deadline.after(10.0))
    assert len(calls) == 1 + len(faces.FACE_MU_FRACTIONS)
