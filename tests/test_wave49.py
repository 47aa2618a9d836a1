"""Wave 49: fundamental matrices from the cameras' 4 x 4 determinants with their proven error (issue #22).

:func:`tritools.model.fundamental_det.fundamental_determinants` (what :func:`tritools.model.stacked.fundamental_stack`
now returns) is checked against the exact fundamental matrix of the float cameras in rationals: its bound holds for
ordinary, nearly coincident, pixel-scaled, georeferenced and extreme-scaled cameras, is ~1e-14 on normalised ones
(below the pseudo-inverse form's measured error, which the old model understated), and F agrees with the scalar
:func:`tritools.model.geometry.fundamental_matrix` up to scale.  End to end: the Lagrangian bounds of single calls
stay below an independent two-view reference.
"""
from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from tritools.model.fundamental_det import determinant_form, fundamental_determinants
from tritools.model.geometry import fundamental_matrix
from tritools.model.stacked import fundamental_stack, view_pairs
from tritools.scene import random_scene

from .test_wave47 import _exact_fundamental, _two_view_reference


def _cameras(rng, kind: str) -> np.ndarray:
    """Two cameras (2, 3, 4) of an adversarial kind."""
    C = rng.normal(size=(2, 3, 4))
    if kind == "near":                      # centres ~1e-3..1e-9 apart
        C[1] = C[0] + rng.normal(size=(3, 4)) * 10.0 ** -float(rng.integers(3, 10))
    elif kind == "pixels":                  # principal point at ~1e6 px, focal length ~1e3
        K = np.array([[1e3, 0, 1e6], [0, 1e3, -1e6], [0, 0, 1.0]])
        C = K @ C
    elif kind == "georef":                  # centres at ~1e6 from the origin, 1 apart
        c = 1e6 + rng.normal(size=(2, 3))
        R = [np.linalg.qr(rng.normal(size=(3, 3)))[0] for _ in range(2)]
        C = np.array([np.hstack([R[k], (-R[k] @ c[k])[:, None]]) for k in range(2)])
    elif kind == "extreme":                 # cameras scaled by 1e+-200
        C = C * np.array([1e200, 1e-200])[:, None, None]
    return C


def _exact_error(F: np.ndarray, Pi: np.ndarray, Pj: np.ndarray) -> float:
    """min over lambda of ||F - lambda D||_F for the exact D of the float cameras, in rationals (the lambda of the
    least-squares fit), as a float."""
    D = _exact_fundamental(Pi, Pj)
    Fx = [[Fraction(float(F[k, l])) for l in range(3)] for k in range(3)]
    lam = sum(Fx[k][l] * D[k][l] for k in range(3) for l in range(3)) / \
        sum(D[k][l] ** 2 for k in range(3) for l in range(3))
    return float(sum((Fx[k][l] - lam * D[k][l]) ** 2 for k in range(3) for l in range(3))) ** 0.5


@pytest.mark.parametrize("kind", ["plain", "near", "pixels", "georef", "extreme"])
def test_determinant_fundamental_bound_holds_against_the_exact_matrix(kind):
    rng = np.random.default_rng(["plain", "near", "pixels", "georef", "extreme"].index(kind))
    I, J = np.array([0]), np.array([1])
    for _ in range(12):
        C = _cameras(rng, kind)
        F, ok, e = fundamental_determinants(C[None], I, J)
        assert ok[0, 0] and np.isfinite(e[0, 0])
        assert abs(np.linalg.norm(F[0, 0]) - 1.0) < 1e-15
        err = _exact_error(F[0, 0], C[0], C[1])
        assert err <= e[0, 0], (kind, err, e[0, 0])
        if kind == "plain":                 # ~1 ulp of F, and the bound not far above it
            assert e[0, 0] < 1e-13


def test_fundamental_stack_agrees_with_the_scalar_fundamental_matrix_up_to_scale():
    """F of the stack (determinants) against geometry.fundamental_matrix (the pseudo-inverse form), normalised and
    signed alike: the same matrix within the latter's round-off, on every pair of random scenes."""
    for N, seed in ((2, 0), (5, 1), (10, 2)):
        C = np.asarray(random_scene(N, 1, noise_px=1.0, seed=seed).cameras)
        F, defined = fundamental_stack(C[None])
        assert defined.all()
        for k, (i, j) in enumerate(zip(*view_pairs(N))):
            G = fundamental_matrix(C[i], C[j])
            G = G / np.linalg.norm(G)
            G = G * np.sign(np.sum(G * F[0, k]))
            assert np.abs(G - F[0, k]).max() < 1e-11


def test_stack_errors_are_the_determinants_bounds_and_undefined_pairs_are_inf():
    """fundamental_stack(errors=True): the bound of fundamental_determinants where a pair is defined, inf where its
    centres coincide (a duplicated view, -2.5 P)."""
    C = np.asarray(random_scene(4, 1, noise_px=1.0, seed=4).cameras)
    C = np.concatenate([C, -2.5 * C[:1]])
    F, defined, E = fundamental_stack(C[None], errors=True)
    I, J = view_pairs(5)
    same = (I == 0) & (J == 4)
    assert not defined[0, same].any() and np.isinf(E[0, same]).all() and not F[0, same].any()
    assert defined[0, ~same].all() and (E[0, ~same] < 1e-12).all()        # (raw cameras: ~1e-13)
    _, ok, e = fundamental_determinants(C[None], I, J)
    assert np.array_equal(E[0, ~same], e[0, ~same])


def test_determinant_form_in_longdouble_bounds_tighter_than_in_double():
    """determinant_form's error bound scales with the unit round-off of the type it runs in (fundamental_bounds keeps
    longdouble; F itself is formed in double), and both hold against the exact determinants."""
    rng = np.random.default_rng(9)
    C = rng.normal(size=(1, 2, 3, 4))
    I, J = np.array([0]), np.array([1])
    D_ld, dD_ld = determinant_form(C, I, J)
    D_d, dD_d = determinant_form(C, I, J, np.float64)
    exact = _exact_fundamental(C[0, 0], C[0, 1])
    for D, dD in ((D_ld, dD_ld), (D_d, dD_d)):
        for k in range(3):
            for l in range(3):
                assert abs(Fraction(*D[0, 0, k, l].as_integer_ratio()) - exact[k][l]) <= Fraction(float(dD[0, 0, k, l]))
    if np.finfo(np.longdouble).eps < np.finfo(np.float64).eps:
        assert (dD_ld < dD_d / 100).all()


def test_two_view_single_calls_stay_below_the_exact_reference():
    """End to end on the new F: certified two-view single calls (verification) bound gamma* from below, against the
    independent pencil-of-planes reference, at pixel scales 1 and 1e6 and in a georeferenced world."""
    import tritools

    for seed in range(6):
        sc = random_scene(2, 3, noise_px=1.0, seed=100 + seed)
        C, x = np.asarray(sc.cameras), np.asarray(sc.points2d)
        for j in range(3):
            r = tritools.triangulate(C, x[j])
            assert r.optimal
            ref = _two_view_reference(C, x[j])
            assert r.gamma_lb <= ref * (1 + 1e-9) + 1e-12
            assert r.gamma_ub >= ref * (1 - 1e-9)


# ----------------------------------------------------------------------------------------------------------------
# Review 48a F1: a wrong match far off the image no longer costs the TLS certificate.

def _far_track(N: int, seed: int, magnitude: float):
    """A protocol track (1 px noise) whose views 1 and N - 2 are wrong matches ``magnitude`` px off the image, and its
    independent reference: the L2 optimum of the other views (scipy from the true point) plus c^2 per wrong match."""
    from scipy.optimize import least_squares

    from tritools.scene import robust_protocol_scene

    rng = np.random.default_rng(seed)
    P, x, X, _ = robust_protocol_scene(N, 0, 1.0, rng)
    bad = sorted({1, N - 2})                # (three views: one wrong match)
    x[bad] = np.array([[magnitude, -0.6 * magnitude], [-0.3 * magnitude, magnitude]])[:len(bad)]
    good = [i for i in range(N) if i not in bad]

    def res(Y):
        h = P[good] @ np.append(Y, 1.0)
        return (h[:, :2] / h[:, 2:] - x[good]).ravel()

    f_in = float(np.sum(least_squares(res, X, xtol=1e-15, ftol=1e-15, gtol=1e-15).fun ** 2))
    return P, x, np.sqrt((f_in + len(bad) * 5.0 ** 2) / (2 * N)), bad


@pytest.mark.parametrize("N", [3, 5, 7])
@pytest.mark.parametrize("magnitude", [1e6, 1e8])
def test_wrong_matches_far_off_the_image_keep_the_certificate(N, magnitude):
    """Two wrong matches 1e6 / 1e8 px off (review 48a F1: not_certified from 1e6 px on, the gap growing as their
    magnitude squared): certified, gamma_LB below and gamma_UB at the independent reference, the wrong matches out
    of the inlier set; the same in a batch."""
    import tritools

    P, x, ref, bad = _far_track(N, 10 + N, magnitude)
    for r in (tritools.triangulate(P, x, robust=5.0), tritools.triangulate_many([(P, x)], robust=5.0)[0]):
        assert r.optimal, (r.status, r.message)
        assert r.gamma_lb <= ref * (1 + 1e-12)
        assert abs(r.gamma_ub - ref) <= 1e-8 * ref
        assert not r.inliers[bad].any() and r.inliers.sum() == N - len(bad)


def test_far_wrong_matches_in_a_stack_of_points():
    """triangulate_many over several such tracks of one view count: one enumeration stack, its results reported by
    the stacked report (tls_reported_stack's ``splits``)."""
    import tritools

    tracks = [_far_track(6, 40 + k, 1e7) for k in range(6)]
    out = tritools.triangulate_many([(t[0], t[1]) for t in tracks], robust=5.0)
    for r, (_, _, ref, bad) in zip(out, tracks):
        assert r.optimal and r.gamma_lb <= ref * (1 + 1e-12) and not r.inliers[bad].any()


def test_split_lowering_is_the_smaller_of_the_two_lowered_bounds():
    """_split_lower: lb lowered by the kept views' magnitude, lb_out by every view's, the smaller reported; without a
    split the plain lowering."""
    from tritools.solve.decide import gamma_lower_one
    from tritools.solve.robust_report import _split_lower

    N, ub = 7, 2.05
    plain = _split_lower(58.9, 0.0, ub, N, 3e-6, 1.5e9, None)
    assert plain == gamma_lower_one(np.sqrt(58.9 / 14), ub, 1.0, 3e-6, 1.5e9)
    inner = _split_lower(58.9, 0.0, ub, N, 3e-6, 1.5e9, (700.0, 77.3))
    assert inner == gamma_lower_one(np.sqrt(58.9 / 14), ub, 1.0, 3e-6, 700.0) > plain
    # a set holding the wrong match with the least term: its bound, lowered by every view's magnitude, is reported
    low_out = _split_lower(58.9, 0.0, ub, N, 3e-6, 1.5e9, (700.0, 58.0))
    assert low_out == gamma_lower_one(np.sqrt(58.0 / 14), ub, 1.0, 3e-6, 1.5e9) < inner


def test_outside_split_takes_the_least_term_of_the_sets_holding_an_outside_view():
    from tritools.solve.robust_enum import subset_masks
    from tritools.solve.robust_report import outside_split

    W = subset_masks(4)
    terms = np.arange(len(W), dtype=float) + 10.0
    assert outside_split(W, terms, [False] * 4) is None
    mask, lb_out, lb_in, exact, nodes = outside_split(W, terms, [False, False, True, False])
    holds = W[:, 2] & (W.sum(axis=1) >= 2)
    assert mask.tolist() == [False, False, True, False] and lb_out == terms[holds].min() and exact is None is nodes
    assert lb_in == terms[~W[:, 2] & (W.sum(axis=1) >= 2)].min()


def test_enum_frame_caps_the_residuals_at_the_thresholds():
    """The enumeration frame's image scale from the DLT residuals capped at c^2 (where one exceeds it), the scalar
    twin and the stack alike; no threshold exceeded (or none given): the frame of before, bit for bit."""
    from tritools.scene import robust_protocol_scene
    from tritools.solve.robust_enum import enum_frame_one, enum_frames

    rng = np.random.default_rng(5)
    P, x, _, _ = robust_protocol_scene(6, 0, 1.0, rng)
    c2 = np.full(6, 25.0)
    plain = enum_frame_one(P, x)[0].scale
    assert enum_frame_one(P, x, c2)[0].scale == plain == enum_frames(P[None], x[None], c2[None])[0][0].scale
    x[2] = [1e6, -4e5]
    wide = enum_frame_one(P, x)[0].scale
    capped = enum_frame_one(P, x, c2)[0].scale
    assert wide < 1e-4 < capped <= 1.0                  # the wrong match no longer sets the unit
    assert capped == pytest.approx(enum_frames(P[None], x[None], c2[None])[0][0].scale, rel=1e-12)


def test_world_origin_magnitude_over_some_views_twin_and_stack():
    from tritools.model.magnitude import world_origin_magnitude_one, world_origin_magnitudes

    rng = np.random.default_rng(8)
    for _ in range(20):
        N = int(rng.integers(2, 7))
        C = rng.normal(size=(N, 3, 4))
        x = rng.normal(size=(N, 2)) * 100
        X, o = rng.normal(size=3), rng.normal(size=3)
        views = rng.random(N) < 0.5
        one = world_origin_magnitude_one(C, x, X, o, entries=True, views=views)
        st = world_origin_magnitudes(C[None], x[None], X[None], o[None], entries=True, views=views[None])[0]
        assert one == st
        full = world_origin_magnitude_one(C, x, X, o, entries=True)
        assert one <= full
        if views.any():
            assert one == world_origin_magnitude_one(C[views], x[views], X, o, entries=True)


def test_two_view_stationary_point_ignores_round_off_leading_terms():
    """robust_two._stationary with an epipole at infinity up to round-off (f_1 = 1e-17, as the determinant-form F of
    a sideways pair gives): the same optimum as at f_1 = 0 (np.roots lost every digit to the 1e-68 leading term:
    a cost of 5.7e11 where Hartley-Sturm's is 0.016)."""
    from tritools.solve.robust_two import _stationary

    rng = np.random.default_rng(3)
    for _ in range(20):
        a, b, c, d, f0 = rng.normal(size=5)
        exact = _stationary(a, b, c, d, f0, 0.0)
        near = _stationary(a, b, c, d, f0, 1e-17)
        assert near == pytest.approx(exact, rel=1e-9, abs=1e-12)


# ----------------------------------------------------------------------------------------------------------------
# Review 49a F1: a stacked conic solve no longer lets a block stop at the stack's (the sum's) tolerances.

def _look(c, target):
    z = target - c
    z = z / np.linalg.norm(z)
    x = np.cross([0, 1.0, 0], z)
    x /= np.linalg.norm(x)
    R = np.array([x, np.cross(z, x), z])
    K = np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]])
    return K @ np.hstack([R, (-R @ c)[:, None]])


def test_uncertainty_many_box_beside_an_unbounded_problem_is_the_single_calls():
    """A zero-noise [point, 1 px disc, point] problem in one uncertainty_many with three 1 px discs on a 1e-4 baseline
    (an unbounded set of the same structure): its box as tight as the single call's (before: ~2e4 times wider, the
    bounded blocks stopping at the stack's tolerance beside the boxed-out unbounded one), the same statuses."""
    import tritools
    from tritools import Ellipse, Point

    rng = np.random.default_rng(1)
    for t in range(4):
        sc = random_scene(3, 1, noise_px=0.0, seed=t)
        C, x = np.asarray(sc.cameras), np.asarray(sc.points2d)[0]
        A = [Point(x[0]), Ellipse(x[1], np.eye(2)), Point(x[2])]
        X = rng.normal(size=3) * 0.3
        cams = np.array([_look(np.array([b, 0.0, -5.0]), X) for b in (0.0, 1e-4, -1e-4)])
        h = cams @ np.append(X, 1.0)
        B = [Ellipse(p, np.eye(2)) for p in h[:, :2] / h[:, 2:]]
        one = tritools.uncertainty(C, A)
        both = tritools.uncertainty_many([C, cams], [A, B])
        assert one.status.value == both[0].status.value == "bounded" and both[1].status.value == "unbounded"
        assert np.max(both[0].hi - both[0].lo) <= 10 * np.max(one.hi - one.lo) + 1e-15
        assert both[0].contains(np.asarray(sc.points3d)[0])


def test_loose_blocks_are_those_whose_own_gap_exceeds_the_tolerances_at_their_scale():
    from sospoly.solvers.stacked_conic import LOOSE_GAP_FACTOR, StackedConicOptions, _loose_blocks

    opts = StackedConicOptions()
    q = np.array([[1.0], [1.0], [1.0]])
    x = np.array([[1.0], [1e8], [1.0]])
    b = np.array([[-1.0], [-1e8], [-1.0]])
    z = np.array([[1.0], [1.0 - 1e-6], [1.0 - 1e-6]])     # gaps 0, 1e2 (at a scale of 1e8), 1e-6 (at a scale of 1)
    tol = LOOSE_GAP_FACTOR * (opts.tol_gap_abs + opts.tol_gap_rel * 1e8)
    assert 1e2 > tol
    assert _loose_blocks(q, b, x, z, opts).tolist() == [False, True, True]
    z[1] = 1.0 - 1e-19
    assert _loose_blocks(q, b, x, z, opts).tolist() == [False, False, True]


# ----------------------------------------------------------------------------------------------------------------
# Review 49b: single calls of 9-10 views (M1) and two views in a georeferenced world (M2).

@pytest.mark.parametrize("N", [9, 10])
def test_far_wrong_matches_single_call_of_nine_or_ten_views_is_certified_like_the_batch(N):
    """Single calls of more views than a single call enumerates: where the search leaves a track with wrong matches
    1e7 px off uncertified, the batch's enumeration (and its split bound) decides it, as in a batch (review 49b M1)."""
    import tritools

    P, x, ref, bad = _far_track(N, 60 + N, 1e7)
    one = tritools.triangulate(P, x, robust=5.0)
    many = tritools.triangulate_many([(P, x)], robust=5.0)[0]
    assert one.optimal and many.optimal
    assert one.gamma_lb <= ref * (1 + 1e-12) and abs(one.gamma_ub - ref) <= 1e-8 * ref
    assert np.array_equal(one.inliers, many.inliers) and not one.inliers[bad].any()


def test_two_views_georeferenced_with_a_wrong_match_far_off_keep_their_inlier():
    """Review 49b M2: a world 1e7 from the origin, a wrong match ~1e9 px off, c = 5: the capped frame left the
    two-view single call at 0/2 inliers (gamma_UB 3.54); two views are not capped (their inlier set is one view):
    1/2 inliers at gamma_UB = c / 2 = 2.5, the single call as the batch."""
    import tritools

    C = np.array([[[527.343040918857, -662.3810962511644, -159.87682922662165, 20534223591.12133],
                   [90.8721052017625, -235.74960867480831, 796.0931996354915, -889345659.1542579],
                   [-0.46806113484567735, -0.878605512097169, 0.09471603961023702, -1763747.7598003563]],
                  [[86.64132369404561, -599.42431027417, 612.8489024881085, 4296479299.253986],
                   [-726.2001080477141, 157.00840327394408, 381.5517846542654, -21100555293.17258],
                   [-0.5893708066593318, -0.7903035667325579, -0.16751813235445923, -3689552.587772479]]])
    x = np.array([[334.8771082266243, 223.5134908878445], [812341521.9659, 377984093.415523]])
    one = tritools.triangulate(C, x, robust=5.0)
    many = tritools.triangulate_many([(C, x)], robust=5.0)[0]
    for r in (one, many):
        assert r.inliers.sum() == 1 and abs(r.gamma_ub - 2.5) < 1e-9
        assert r.gamma_lb <= 2.5
    assert one.status == many.status


def test_determinant_fundamental_bound_holds_with_entries_spanning_the_exponent_range():
    """Cameras whose rows differ by 1e-100..1e-200 in scale (a product of four entries leaves the doubles' range):
    computed in longdouble (UNDERFLOW_SAFE), the bound still holds against the exact determinants."""
    from tritools.model.fundamental_det import UNDERFLOW_SAFE

    rng = np.random.default_rng(11)
    I, J = np.array([0]), np.array([1])
    for scale in (1e-100, 1e-150, 1e-200):
        C = rng.normal(size=(2, 3, 4))
        C[:, 2] *= scale                     # the depth rows: an image scaling diag(1, 1, scale), tiny in every camera
        assert (np.abs(C / np.abs(C).max(axis=(1, 2), keepdims=True)) < UNDERFLOW_SAFE).any()
        F, ok, e = fundamental_determinants(C[None], I, J)
        assert ok[0, 0] and np.isfinite(e[0, 0])
        assert _exact_error(F[0, 0], C[0], C[1]) <= e[0, 0]
