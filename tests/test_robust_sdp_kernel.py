"""The batched delta = 2 SDP's lower bounds on rows handed back only for their Gram kernel
(tritools.solve.robust_bounds._sdp_stack): still below the L2 optimum, found by dense multi-start."""
import numpy as np
import pytest
from scipy.optimize import least_squares

import tritools
from tritools.scene import sphere_cameras
from tritools.solve import robust_bounds as rb
from tritools.solve.sdp_batch import solve_corollary1_points

K = np.array([[1012.0, 0, 1054], [0, 1012.0, 581], [0, 0, 1.0]])


def _scene(rng, N=3):
    """The CVPR 2023 protocol (benchmarks/robust.py): cameras on a sphere of radius 2 looking at the origin, one
    observation replaced by a uniform image point."""
    P = sphere_cameras(N, rng, K)
    h = P @ np.append(rng.uniform(-0.5, 0.5, 3), 1.0)
    obs = h[:, :2] / h[:, 2:] + rng.normal(size=(N, 2))
    obs[rng.integers(N)] = rng.uniform([0, 0], [2108, 1162])
    return P, obs


def _l2_min(P, obs, rng, starts=60):
    """min over X of sum_i ||Phi(X, P_i) - x_i||^2 by Levenberg-Marquardt from many starts (an upper bound on the
    optimum, at it in practice)."""
    def res(X):
        h = P @ np.append(X, 1.0)
        return (h[:, :2] / h[:, 2:] - obs).ravel()

    best = np.inf
    for X0 in rng.uniform(-3, 3, (starts, 3)):
        sol = least_squares(res, X0, method="lm", xtol=1e-14, ftol=1e-14)
        if np.all(np.isfinite(sol.fun)):
            best = min(best, float(sol.fun @ sol.fun))
    return best


def test_kernel_hand_back_bounds_are_below_the_l2_optimum():
    rng = np.random.default_rng(0)
    scenes = [_scene(rng) for _ in range(60)]
    C = np.array([P for P, _ in scenes])
    x = np.array([o for _, o in scenes])
    b = solve_corollary1_points(C, x)
    kernel = rb._kernel_hand_backs(b)
    assert kernel.sum() >= 2, "no row handed back for its Gram kernel: the case this test covers is gone"
    decided, gamma_lb, X, certified = rb._sdp_stack(C, x, tritools.TriangulationOptions())
    assert np.all(decided[kernel]) and not np.any(certified[kernel])
    assert np.all(np.isnan(X[kernel]))                      # no estimate from those rows
    np.testing.assert_array_equal(decided[~kernel], b.done[~kernel] & np.isfinite(b.gamma_lb[~kernel]))
    ref_rng = np.random.default_rng(1)
    useful = 0
    for m in np.nonzero(kernel)[0]:
        lb = 2 * 3 * gamma_lb[m] ** 2 * rb.ROUND_DOWN
        ref = _l2_min(C[m], x[m], ref_rng)
        assert lb <= ref * (1 + 1e-9), (m, lb, ref)
        useful += lb >= 0.5 * ref
    assert useful >= 1                                      # the bounds are not vacuous


def test_kernel_rule_ignores_other_hand_backs():
    """Rows handed back for any other reason (here: coincident camera centres) are not taken."""
    rng = np.random.default_rng(2)
    P, obs = _scene(rng)
    P[1] = P[0] * 2.0                                       # the same camera, scaled: one centre
    b = solve_corollary1_points(P[None], obs[None])
    assert not b.done[0]
    assert not rb._kernel_hand_backs(b)[0]


@pytest.mark.slow
def test_strengthen_from_delta4_is_a_valid_tight_bound(monkeypatch):
    """A weak 3-view subset holding a wrong match, strengthened with the plan from delta = 4 (its delta = 2 bound
    known): below the multi-start L2 minimum, within 1e-6 of it (these problems certify), and the sub-solve
    started at delta = 4."""
    from tritools import Point, triangulate
    from tritools.solve import triangulate as tri_mod

    rng = np.random.default_rng(0)
    scenes = [_scene(rng) for _ in range(40)]
    opts = tritools.TriangulationOptions()
    seen = []
    real = tri_mod.triangulate

    def spy(cams, regions, options=None, **kw):
        res = real(cams, regions, options=options, **kw)
        seen.append(res.attempts[0].delta if res.attempts else None)
        return res

    monkeypatch.setattr(tri_mod, "triangulate", spy)
    ref_rng = np.random.default_rng(3)
    done = 0
    for P, obs in scenes[:8]:
        sb = rb.SubsetBounds(P, [Point(p) for p in obs], opts, opts.budget.deadline())
        S = frozenset(range(3))
        sb._store(S, 0.0, None)
        sb.weak.add(S)                          # as after a batched delta = 2 SDP that did not certify
        assert sb.strengthen(S)
        ref = _l2_min(P, obs, ref_rng)
        assert sb.bound(S) <= ref * (1 + 1e-9)
        full = triangulate(P, [Point(p) for p in obs], options=opts)
        if full.optimal:
            assert sb.bound(S) >= ref * (1 - 1e-6)
            done += 1
    assert done >= 4
    assert len(seen) == 8 and all(d == rb.FULL_FROM_DELTA for d in seen)
