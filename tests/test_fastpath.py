"""The vectorised certification by verification (tritools.solve.fastpath, sospoly.analysis.verify batch).

References: closed forms (a circle), the single-program verify_quadratic, Hartley-Sturm's
exact two-view optimum (tests/reference), and the delta = 2 SDP path of tritools.solve.triangulate.
"""
from __future__ import annotations

import numpy as np
import pytest

import sospoly
import tritools
from sospoly.analysis.verify import quadratic_parts, verify_quadratic, verify_quadratic_batch
from tests.reference.hartley_sturm import hartley_sturm
from tritools import Point, Status
from tritools.solve.fastpath import verify_points
from tritools.scene import random_scene

# gamma agreement between two certified answers: both are within the certificate tolerance
# (gap_abs + gap_rel on c = 2N gamma'^2, c ~ 1) of the same optimum, i.e. ~1e-6 relative in gamma.
GAMMA_RTOL = 1e-6
# gamma_LB from two different certificates (both valid, each within ~1e-6 of c*): 1e-5 relative.
LB_RTOL = 1e-5


def _stack(scene):
    M = scene.n_points
    return np.broadcast_to(scene.cameras, (M,) + scene.cameras.shape), scene.points2d


def test_batch_matches_single_programs_and_closed_form():
    # min x + y on x^2 + y^2 = r^2 is -sqrt(2) r at -(1, 1) r / sqrt(2); at +(1, 1) r / sqrt(2) the
    # KKT multiplier makes the Lagrangian Hessian negative (no bound).  Stack both for several r.
    x, y = sospoly.variables("x y")
    radii = np.array([0.5, 1.0, 3.0])
    f0, f1, F2, g0, g1, G2, pts = [], [], [], [], [], [], []
    for r in radii:
        for sign in (-1, 1):
            p = quadratic_parts(x + y, x.gens)
            q = quadratic_parts(x**2 + y**2 - r**2, x.gens)
            f0.append(p[0]), f1.append(p[1]), F2.append(p[2])
            g0.append([q[0]]), g1.append([q[1]]), G2.append([q[2]])
            pts.append(sign * r * np.ones(2) / np.sqrt(2))
    b = verify_quadratic_batch(f0, f1, F2, g0, g1, G2, pts)
    assert b.certified.tolist() == [True, False] * 3
    np.testing.assert_allclose(b.lower_bound[::2], -np.sqrt(2) * radii, atol=1e-12)
    assert np.all(np.isnan(b.lower_bound[1::2])) and np.all(b.reason[1::2] == 1)
    for m in range(6):   # the single API is the batch of one: identical decision and bound
        single = verify_quadratic(x + y, [x**2 + y**2 - radii[m // 2] ** 2], pts[m])
        item = b.item(m)
        assert single.certified == item.certified and single.status == item.status
        assert (single.lower_bound is None) == (item.lower_bound is None)
        if item.lower_bound is not None:
            assert single.lower_bound == pytest.approx(item.lower_bound, abs=1e-14)


def test_batch_rejects_inconsistent_shapes():
    with pytest.raises(ValueError, match="inconsistent shapes"):
        verify_quadratic_batch(np.zeros(2), np.zeros((2, 3)), np.zeros((2, 3, 3)), np.zeros((2, 1)),
                               np.zeros((2, 1, 3)), np.zeros((2, 1, 4, 4)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match=r"\(M, N, 3, 4\)"):
        verify_points(np.zeros((3, 3, 4)), np.zeros((3, 2)))


@pytest.mark.parametrize("noise", [0.5, 5.0, 40.0])
def test_two_views_equal_hartley_sturm(noise):
    # 300 two-view points per noise level: every certified gamma is the exact optimum
    scene = random_scene(2, 300, noise_px=noise, seed=int(10 * noise))
    b = verify_points(*_stack(scene))
    assert b.certified.mean() > 0.9
    for j in np.nonzero(b.certified)[0]:
        _, cost = hartley_sturm(scene.cameras[0], scene.cameras[1], *scene.points2d[j])
        g = np.sqrt(cost / 4)
        assert abs(b.gamma_ub[j] - g) <= GAMMA_RTOL * max(1.0, g)
        assert b.gamma_lb[j] <= g * (1 + LB_RTOL) and b.gamma_lb[j] >= g * (1 - LB_RTOL)


@pytest.mark.parametrize("n_views", [3, 4, 5, 6, 8])
def test_certified_bound_is_below_every_feasible_value(n_views):
    # thousands of points (N = 3..8, noise up to 60 px): the certified gamma_LB can never exceed
    # gamma at any scene point; we test the true point, the DLT point and 20 random perturbations
    # of the estimate (an independent brute-force check of the bound's validity)
    rng = np.random.default_rng(n_views)
    for noise in (1.0, 60.0):
        scene = random_scene(n_views, 200, noise_px=noise, seed=100 + n_views)
        b = verify_points(*_stack(scene))
        for j in np.nonzero(b.certified)[0][:60]:
            regions = scene.regions(j)
            trial = np.vstack([scene.points3d[j], tritools.dlt(scene.cameras, scene.points2d[j]),
                               b.X[j] + rng.normal(scale=0.05, size=(20, 3))])
            g = tritools.gamma(trial, scene.cameras, regions)
            assert b.gamma_lb[j] <= np.min(g) * (1 + 1e-9) + 1e-9
            assert b.gamma_lb[j] <= b.gamma_ub[j] * (1 + LB_RTOL)


@pytest.mark.parametrize("n_views,noise,seed", [(2, 80.0, 0), (3, 20.0, 1), (3, 1.0, 2), (4, 60.0, 7),
                                                (5, 5.0, 4), (6, 80.0, 5), (8, 2.0, 6)])
def test_fast_path_against_sdp_path(n_views, noise, seed):
    # (a) fast-certified => the SDP certifies the same gamma; (b) SDP-certified => auto certifies
    scene = random_scene(n_views, 20, noise_px=noise, seed=300 + seed)
    problems = [(scene.cameras, scene.regions(j)) for j in range(20)]
    auto = tritools.triangulate_many(problems, "corollary1", 2, 2, progress=False)
    for (cams, regions), a in zip(problems, auto):
        sdp = tritools.triangulate(cams, regions, "corollary1", 2, 2, path="sdp")
        if a.certified_by == "verification":
            assert sdp.optimal, "the fast path certified a point the SDP path does not certify"
            assert abs(a.gamma_ub - sdp.gamma_ub) <= GAMMA_RTOL * max(1.0, sdp.gamma_ub)
            assert abs(a.gamma_lb - sdp.gamma_lb) <= LB_RTOL * max(1.0, sdp.gamma_lb)
        if sdp.optimal:
            assert a.optimal and a.certified_by in ("verification", "sdp")
        assert a.status == sdp.status or a.certified_by == "verification"


def test_single_triangulate_and_batch_decide_alike():
    scene = random_scene(4, 30, noise_px=30.0, seed=42)
    fast = verify_points(*_stack(scene))
    for j in range(30):
        single = tritools.triangulate(scene.cameras, scene.regions(j), "corollary1", 2, 2, path="auto")
        if not fast.certified[j]:
            assert single.certified_by != "verification"
        else:
            assert single.certified_by == "verification"
            # a single call refines with the scalar LM twin (tritools.model.stacked.refine_point): the same local
            # minimiser up to round-off -- a cost resolved to eps places X to ~sqrt(eps) (tests/test_scalar_twins.py)
            np.testing.assert_allclose(single.X, fast.X[j], rtol=1e-7, atol=1e-7)
            assert single.gamma_lb == pytest.approx(fast.gamma_lb[j], rel=1e-9)


def test_degenerate_problems_are_not_certified():
    scene = random_scene(3, 4, noise_px=1.0, seed=5)
    C, x = (np.array(a) for a in _stack(scene))
    C[1, 0, 0, 0] = np.nan                     # NaN camera
    C[2] = scene.cameras[0]                    # all cameras equal
    C[3, 1] = 0.0                              # rank-0 camera
    b = verify_points(C, x)
    assert b.certified.tolist() == [True, False, False, False]


def _oxford_subset(data, per_sequence):
    from tritools.io.oxford import PAPER_SEQUENCES, load_sequence

    out = []
    for seq in (load_sequence(name, data) for name in PAPER_SEQUENCES):
        for tr in seq.tracks[:per_sequence]:
            cams, pts = seq.problem(tr)
            out.append((cams, [Point(p) for p in pts]))
    return out


def test_oxford_subset_fast_path_agrees_with_sdp(oxford_data):
    problems = _oxford_subset(oxford_data, 300)           # 1800 real tracks through the fast path
    auto = tritools.triangulate_many(problems, "corollary1", 2, 2, progress=False)
    assert sum(r.certified_by == "verification" for r in auto) >= 0.99 * len(problems)
    rng = np.random.default_rng(0)
    for k in rng.choice(len(problems), 40, replace=False):   # 40 SDP solves
        sdp = tritools.triangulate(*problems[k], "corollary1", 2, 2, path="sdp")
        a = auto[k]
        if a.certified_by == "verification":
            assert sdp.optimal
            assert abs(a.gamma_ub - sdp.gamma_ub) <= GAMMA_RTOL * max(1.0, sdp.gamma_ub)
        if sdp.optimal:
            assert a.optimal


def test_oxford_corridor_point_falls_back(corridor_point):
    cams, pts = corridor_point
    assert not verify_points(cams[None], pts[None]).certified[0]
    res = tritools.triangulate_many([(cams, [Point(p) for p in pts])], "corollary1", 2, 2, progress=False)[0]
    assert res.status == Status.NOT_CERTIFIED and res.certified_by is None
    assert res.attempts[0].step == "verification" and res.attempts[0].status == "verification_failed"


def test_vectorised_scale_is_normalization_for_scale():
    """The batched paths normalise like triangulate (one implementation: the single problem is a stack of
    one), with s from the refined residual, not the DLT's (Example 5 cases at large theta are where the two
    differ by up to two decades)."""
    from tritools.model.normalize import normalization_for, normalization_stack
    from tritools.scene import example5_cases

    cases = example5_cases(0, n_points=3, thetas=(0.15, 0.2), trials=2)
    C = np.array([c.cameras for c in cases])
    x = np.array([c.image_points for c in cases])
    s = normalization_stack(C, x).scale
    ref = np.array([normalization_for(c.cameras, c.regions).scale for c in cases])
    assert np.allclose(s, ref, rtol=1e-12)


def test_overflowing_problem_does_not_break_its_batch():
    # |x| = 1e308 is finite but overflows in the normalisation; before the fix its NaN polynomials made
    # the batched SVD of verify_quadratic_batch raise LinAlgError for the whole stack
    scene = random_scene(3, 3, noise_px=1.0, seed=4)
    C, x = _stack(scene)
    x = x.copy()
    x[1, 0] = 1e308
    with np.errstate(all="ignore"):
        batch = verify_points(C, x)
    assert not batch.ok[1] and not batch.certified[1]
    alone = verify_points(C[[0, 2]], x[[0, 2]])
    np.testing.assert_array_equal(batch.certified[[0, 2]], alone.certified)
    assert alone.certified.all()
