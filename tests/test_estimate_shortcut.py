"""The views step decided on the earlier step's estimate (issue #22): the same certified bounds as with the
clique-moment extraction, and the extraction after all when the shortcut does not certify.

References: the same problem with the shortcut disabled (the full extraction), and an independent attained
value (tests/reference/regions.py: bounded least squares over X and the regions' parametrisations)."""
from __future__ import annotations

import numpy as np
import pytest

import tritools
from tests.reference.regions import region_reference, spec_of
from tritools.model.normalize import normalization_for
from tritools.scene import uncertain_problem
from tritools.solve.stages import estimate

LARGE = dict(noise_px=16.0, size_px=16.0)


def _views_step(r):
    return [a for a in r.attempts if a.delta == 4 and a.sparsity == "views"]


def _reference(cams, regs, r, X):
    return region_reference(cams, [spec_of(g) for g in regs], [X, r.X], np.random.default_rng(0))


@pytest.mark.slow
@pytest.mark.parametrize("n_views,seed", [(6, 1), (10, 1)])
def test_shortcut_certifies_the_same_bounds_as_the_extraction(monkeypatch, n_views, seed):
    cams, regs, X = uncertain_problem(n_views, seed, kinds="mixed", **LARGE)
    calls = []
    orig = estimate._best_candidate
    monkeypatch.setattr(estimate, "_best_candidate", lambda *a: calls.append(a[3]) or orig(*a))
    fast = tritools.triangulate(cams, regs, time_limit=120)
    n_fast = len(calls)
    monkeypatch.setattr(estimate, "_known_estimate_meets", lambda ctx, st: False)
    full = tritools.triangulate(cams, regs, time_limit=120)
    assert _views_step(fast) and _views_step(full)               # the views step decided both
    assert fast.optimal and full.optimal
    assert len(calls) - n_fast >= n_fast + 1                     # the shortcut skipped the views extraction
    assert fast.gamma_lb == pytest.approx(full.gamma_lb, rel=1e-9)
    assert fast.gamma_ub == pytest.approx(full.gamma_ub, rel=1e-6)
    ref = _reference(cams, regs, fast, X)
    assert fast.gamma_lb <= ref * (1 + 1e-9) and fast.gamma_ub <= ref * (1 + 1e-6)


@pytest.mark.slow
def test_a_shortcut_that_does_not_certify_falls_back_to_the_extraction(monkeypatch):
    """A planted poor earlier estimate, taken by force: the decision on it does not certify, so the extraction
    runs and the step certifies on its own estimate."""
    cams, regs, X = uncertain_problem(6, 1, kinds="mixed", **LARGE)
    taken = []

    def forced(ctx, st):
        if st.shortcut is not None or ctx.estimate_n is None:
            return False
        g, X_n, X_raw_n, x_n = ctx.estimate_n
        ctx.estimate_n = (10 * g + 1.0, X_n + 5.0, X_raw_n + 5.0, x_n)     # far from the minimiser
        taken.append(ctx.estimate_n[0])
        return True

    monkeypatch.setattr(estimate, "_known_estimate_meets", forced)
    r = tritools.triangulate(cams, regs, time_limit=120)
    assert taken                                                  # the shortcut was taken ...
    assert r.optimal and _views_step(r)                           # ... and the extraction certified after it
    ref = _reference(cams, regs, r, X)
    assert r.gamma_lb <= ref * (1 + 1e-9) and r.gamma_ub <= ref * (1 + 1e-6)
    # (the planted estimate's gamma is in the normalised units of the point's frame)
    assert r.gamma_ub * normalization_for(cams, regs).scale < taken[0]


@pytest.mark.parametrize("n_views,seed", [(6, 1), (10, 0)])
def test_degree2_step_decided_on_the_local_estimate(monkeypatch, n_views, seed):
    """Small regions: the degree-2 certificate meets the local estimate; no extraction runs, and the bounds are
    those of the full extraction."""
    cams, regs, X = uncertain_problem(n_views, seed, kinds="mixed")
    calls = []
    orig = estimate._best_candidate
    monkeypatch.setattr(estimate, "_best_candidate", lambda *a: calls.append(1) or orig(*a))
    fast = tritools.triangulate(cams, regs)
    assert fast.optimal and fast.delta == 2 and not calls
    monkeypatch.setattr(estimate, "_known_estimate_meets", lambda ctx, st: False)
    full = tritools.triangulate(cams, regs)
    assert full.optimal and calls
    assert fast.gamma_lb == pytest.approx(full.gamma_lb, rel=1e-9)
    assert fast.gamma_ub == pytest.approx(full.gamma_ub, rel=1e-7)
    ref = _reference(cams, regs, fast, X)
    assert fast.gamma_lb <= ref * (1 + 1e-9) and fast.gamma_ub <= ref * (1 + 1e-6)
    # the reported image points are the estimate's projections, as an extraction's x_i* (TriangulationResult's
    # image_points; the regions' closest points before wave 41)
    for i, P in enumerate(np.asarray(cams, float)):
        h = P @ np.append(fast.X, 1.0)
        p = h[:2] / h[2]
        assert np.linalg.norm(np.asarray(fast.image_points[i], float) - p) <= 1e-6 * (1 + np.abs(p).max())
