"""Adversarial suite of issue #23: no false certificate, an estimate on every failure, the trivial bound.

References are independent of the code under test: gamma* = 0 where the regions contain the exact
projections of a known point (gamma(X_true) = 0 evaluated directly), closed-form minima of textbook
polynomials, re-centred twins of georeferenced scenes.
"""
from __future__ import annotations

import numpy as np
import pytest

import sospoly
import tritools
from tritools import Status
from tritools.model.regions import Ellipse, Polytope, Segment
from tritools.scene import uncertain_problem
from tritools.solve.trivial import TRIVIAL_BOUND

KINDS = ("point", "segment", "ellipse", "polytope")     # each contains the exact projection at zero noise


def zero_gamma_problem(n_views: int, seed: int):
    cams, regs, X = uncertain_problem(n_views, seed=seed, noise_px=0.0, kinds=tuple(KINDS[(i + seed) % 4]
                                                                                  for i in range(n_views)))
    assert tritools.gamma(X[None], cams, regs)[0] <= 1e-9          # the reference: gamma* = 0
    return cams, regs, X


def assert_zero_certified(r, cams, regs):
    assert r.status.certified and r.optimal and r.gamma_lb == 0.0
    assert r.X is not None and 0.0 <= r.gamma_ub <= 1e-8
    assert abs(tritools.gamma(r.X[None], cams, regs)[0] - r.gamma_ub) <= 1e-12     # gamma_UB is gamma(X)


# ----------------------------------------------------------------------------- gamma* = 0: the trivial bound
def test_almost_solved_gamma_zero_problem_certifies_through_the_trivial_bound():
    """The CLI's hand-written mixed problem (#23 blocking case): every Clarabel attempt ends AlmostSolved, yet
    X from the local estimate has gamma ~ 1e-17, so 0 <= gamma* <= gamma(X) certifies -- on the SDP path too."""
    from tests.test_cli import mixed_doc

    doc = mixed_doc()
    cams = np.array(doc["cameras"])
    regs = [Segment(**{k: v for k, v in doc["regions"][0].items() if k != "type"}),
            Ellipse(doc["regions"][1]["center"], doc["regions"][1]["D"]),
            Polytope(doc["regions"][2]["B"], doc["regions"][2]["c"])]
    for path in ("auto", "sdp"):
        r = tritools.triangulate(cams, regs, method="corollary1", delta=2, path=path)
        assert_zero_certified(r, cams, regs)
        assert r.certified_by in ("sdp", TRIVIAL_BOUND)


@pytest.mark.parametrize("n_views,seed", [(3, 0), (5, 1), (12, 2), (16, 3)])
def test_many_view_gamma_zero_problems_certify(n_views, seed):
    cams, regs, _ = zero_gamma_problem(n_views, seed)
    assert_zero_certified(tritools.triangulate(cams, regs), cams, regs)


def test_trivial_bound_certifies_after_a_time_limit_on_the_sdp_path():
    cams, regs, _ = zero_gamma_problem(12, 4)
    r = tritools.triangulate(cams, regs, path="sdp", budget=sospoly.Budget(time_limit=1e-3))
    assert_zero_certified(r, cams, regs)
    assert r.certified_by == TRIVIAL_BOUND and "time_limit" in r.message


def test_trivial_bound_needs_gamma_within_the_tolerance():
    """gamma* > 0 (noisy observations, small regions): never certified by the trivial bound."""
    for seed in range(3):
        cams, regs, _ = uncertain_problem(4, seed=seed, noise_px=2.0, size_px=0.1, kinds="polytope")
        r = tritools.triangulate(cams, regs, path="sdp", budget=sospoly.Budget(time_limit=1e-3))
        assert r.certified_by != TRIVIAL_BOUND and not r.optimal
        assert r.gamma_ub > 0.1


def test_points_paths_certify_exact_data():
    """Point regions at zero noise on the vectorised paths (verification, batched SDP) and the per-point path:
    every point certified with gamma_UB ~ 0 (the projections of the true points, gamma* = 0)."""
    from tritools.scene import random_scene

    scene = random_scene(n_views=4, n_points=20, noise_px=0.0, seed=5)
    for path in ("auto", "sdp"):
        res = tritools.triangulate_points(scene.cameras, scene.points2d, path=path)
        assert np.all(res.optimal) and np.all(res.gamma_lb <= res.gamma_ub) and np.all(res.gamma_ub <= 1e-8)


# ----------------------------------------------------------------------------- an estimate on every failure
@pytest.mark.parametrize("kinds", ["polytope", "mixed"])
def test_every_failure_carries_an_estimate(kinds):
    """A time limit too small for any SDP: the result still has X and gamma_UB = gamma(X) (the local L2
    refinement), a sensible one: no worse than the true point (the L2 optimum lies below it)."""
    cams, regs, X_true = uncertain_problem(6, seed=7, noise_px=1.5, size_px=0.2, kinds=kinds)
    r = tritools.triangulate(cams, regs, path="sdp", budget=sospoly.Budget(time_limit=1e-3))
    assert r.status == Status.TIME_LIMIT and not r.optimal
    assert r.X is not None and np.isfinite(r.gamma_ub)
    assert abs(tritools.gamma(r.X[None], cams, regs)[0] - r.gamma_ub) <= 1e-12
    assert r.gamma_ub <= tritools.gamma(X_true[None], cams, regs)[0] + 1e-9
