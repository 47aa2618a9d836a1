"""Certification by verification (sospoly.analysis.verify) against the SDP path.

The fast path must never certify a point the degree-2 SDP does not certify, and when it
certifies, both paths must report the same optimum (the Lagrangian bound with the KKT
multipliers *is* a degree-2 certificate with constant multipliers).
"""
from __future__ import annotations

import numpy as np
import pytest

import sospoly
import tritools
from sospoly.analysis.verify import quadratic_parts, verify_quadratic
from tritools import Point, Status
from tritools.scene import random_scene


def test_quadratic_parts_round_trip():
    x, y = sospoly.variables("x y")
    p = 3 + 2 * x - y + 4 * x**2 - 6 * x * y + 0.5 * y**2
    p0, p1, P2 = quadratic_parts(p, p.gens)
    for v in np.random.default_rng(0).normal(size=(5, 2)):
        assert p0 + p1 @ v + v @ P2 @ v == pytest.approx(p(v), abs=1e-12)


def test_lagrangian_bound_on_the_circle():
    # min x + y on x^2 + y^2 = 1 is -sqrt(2) at -(1, 1)/sqrt(2): closed form
    x, y = sospoly.variables("x y")
    ver = verify_quadratic(x + y, [x**2 + y**2 - 1], -np.ones(2) / np.sqrt(2))
    assert ver.certified and ver.lower_bound == pytest.approx(-np.sqrt(2), abs=1e-12)
    # at the maximiser the KKT multiplier makes the Hessian negative: no certificate
    ver = verify_quadratic(x + y, [x**2 + y**2 - 1], np.ones(2) / np.sqrt(2))
    assert not ver.certified and ver.lower_bound is None


@pytest.mark.parametrize("n_views,noise,seed", [(2, 2.0, 0), (3, 1.0, 1), (4, 3.0, 2), (6, 1.0, 3), (3, 30.0, 4)])
def test_fast_path_agrees_with_sdp(n_views, noise, seed):
    scene = random_scene(n_views, 12, noise_px=noise, seed=900 + seed)
    for j in range(scene.n_points):
        regions = scene.regions(j)
        fast = tritools.triangulate(scene.cameras, regions, "corollary1", 2, 2, path="auto")
        sdp = tritools.triangulate(scene.cameras, regions, "corollary1", 2, 2, path="sdp")
        if fast.certified_by == "verification":
            assert sdp.optimal, "the fast path certified a point the SDP does not certify"
            assert abs(fast.gamma_ub - sdp.gamma_ub) <= 1e-6 * max(1.0, sdp.gamma_ub)
            assert abs(fast.gamma_lb - sdp.gamma_lb) <= 1e-5 * max(1.0, sdp.gamma_lb)
        else:
            assert fast.certified_by in ("sdp", None)
            assert fast.status == sdp.status
        assert fast.gamma_lb <= fast.gamma_ub + 1e-6


def test_fast_path_only_for_point_regions_at_delta_2():
    cams, regions = tritools.paper_example(3)   # segments: inequalities -> SDP path
    res = tritools.triangulate(cams, regions, "corollary1", path="auto")
    assert res.certified_by in ("sdp", None)
    with pytest.raises(ValueError, match="path"):
        tritools.triangulate(cams, regions, "corollary1", path="fast")


def test_corridor_point_not_certified_by_verification(corridor_point):
    cams, pts = corridor_point
    res = tritools.triangulate(cams, [Point(p) for p in pts], "corollary1", 2, 2, path="auto")
    assert res.status == Status.NOT_CERTIFIED and res.certified_by is None
