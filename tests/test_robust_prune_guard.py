"""A TLS search prunes only within the report's gap guard (wave 11).

The search's certificate rule works on the scale min(c^2, rho^2), and rho (the RMS residual of the DLT over all
views) is inflated by a wrong match.  A node pruned by the rule's absolute part alone left a gap that the report's
guard (the coordinates' resolution in gamma) then refused: on this protocol scene the inlier pair's L2 optimum is
0.053 px^2 under c^2 = 40000 px^2, the search stopped at LB = 40000 and the result was "not certified" although the
pair's own (cheap) bound closes the gap.  `TlsSearch.meets` now asks both, so the search goes on to the leaf.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

import tritools
from sospoly import DEFAULT_TOLERANCES
from tritools.scene import robust_protocol_scene
from tritools.solve.robust_report import PRUNE_SHARE, guards_pass, reported_resolution

from tests.robust_refs import tls_by_subsets

C = 200.0


def _scene():
    rng = np.random.default_rng([3, 3, 1, 50])
    for _ in range(132):
        robust_protocol_scene(3, 1, 5.0, rng)
    return robust_protocol_scene(3, 1, 5.0, rng)


@pytest.fixture(scope="module")
def scene():
    return _scene()


def _reference(P, x, X_true):
    return tls_by_subsets(P, x, np.full(len(x), C), [X_true, np.zeros(3)])


def test_small_inlier_cost_under_a_large_threshold_is_certified(scene):
    P, x, X_true, out = scene
    ref = _reference(P, x, X_true)
    assert ref - C * C < 0.1                          # the case: an inlier pair of ~0.05 px^2 under c^2
    for r in (tritools.triangulate(P, x, robust=C), tritools.triangulate_many([(P, x)], robust=C)[0]):
        assert r.optimal, r.message
        np.testing.assert_array_equal(r.inliers, ~out)
        f_lb, f_ub = 6 * r.gamma_lb ** 2, 6 * r.gamma_ub ** 2
        assert f_lb <= ref * (1 + 1e-9) + 1e-9         # a valid bound (independent subset enumeration)
        assert f_ub >= ref * (1 - 1e-9)                # gamma_UB is attained: never below the optimum
        # the reported gap passes the report's own guard (not only the search's absolute part)
        resolved = reported_resolution(x, np.full(3, C), DEFAULT_TOLERANCES, P)
        assert guards_pass(r.gamma_lb, r.gamma_ub, 3, DEFAULT_TOLERANCES, resolved)


def test_meets_refuses_a_gap_only_the_absolute_part_passes(scene):
    """On this scene's search: a bound 0.053 px^2 under UB ~ 40000.05 meets the rule on the search's scale (~1.5e4
    px^2: its absolute part passes) but not the guard, so `meets` is False; the same bound minus 1e-9 relative of
    UB meets it (the relative part)."""
    from tritools.model.regions import Point
    from tritools.solve.options import TriangulationOptions
    from tritools.solve.robust import TlsSearch, robust_thresholds

    P, x, X_true, _ = scene
    regions = [Point(p) for p in x]
    c = robust_thresholds(C, 3)
    s = TlsSearch(P, regions, c, TriangulationOptions(), 0.0)
    r = tritools.triangulate(P, x, robust=C)
    s.offer(r.X)
    ub = s.best_f
    low = ub - 0.0533
    assert s.tol.certified_one(low, ub, s.scale)               # the rule on the search's scale alone passes
    assert not s.meets(low)                                     # the guard does not
    assert s.meets(ub * (1 - 1e-9))
    assert s.meets(ub + 1.0)
    g = math.sqrt(ub / 6)
    assert s.resolved < PRUNE_SHARE * 1e-4 * g                  # a resolution far below the gamma gap refused
