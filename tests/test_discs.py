"""Uncertain keypoints (disc regions) certified by verification (tritools.solve.discs), against independent
references: the degree-2 SDP of the same program, multi-start local minimisation of the exact distances to the
discs, and the closed form gamma* = 0 when every view's disc meets the true point's projection."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

import tritools
from tritools import Ellipse, Point, Segment
from tritools.model.geometry import dlt
from tritools.scene import random_scene
from tritools.solve.discs import as_disc_problem, disc_radius, verify_discs


def _discs(centres, rho):
    return [Ellipse(c, rho ** 2 * np.eye(2)) for c in centres]


def _reference(C, x, rho, starts=10, seed=0) -> float:
    """Best attained RMS distance to the discs over LM runs (exact distances) from perturbed DLT starts."""
    rng = np.random.default_rng(seed)
    X0 = dlt(C, x)

    def res(X):
        h = C @ np.append(X, 1.0)
        d = h[:, :2] / h[:, 2:] - x
        r = np.linalg.norm(d, axis=1)
        return d * np.maximum(0.0, 1 - rho / np.maximum(r, 1e-300))[:, None]

    best = np.inf
    for k in range(starts):
        r = least_squares(lambda X: res(X).ravel(), X0 + (0 if k == 0 else 0.05 * rng.normal(size=3)), method="trf")
        best = min(best, float(np.sqrt(np.sum(r.fun ** 2) / (2 * len(x)))))
    return best


@pytest.mark.parametrize("n_views,noise,seed", [(2, 2.0, 0), (3, 1.0, 1), (4, 3.0, 2), (6, 1.0, 3)])
def test_disc_verification_agrees_with_the_sdp_and_a_reference(n_views, noise, seed):
    sc = random_scene(n_views, 6, noise_px=noise, seed=200 + seed)
    C = np.asarray(sc.cameras)
    b = verify_discs(np.broadcast_to(C, (6,) + C.shape), sc.points2d, np.ones((6, n_views)))
    assert b.certified.mean() >= 0.8
    for m in np.nonzero(b.certified)[0][:3]:
        ref = _reference(C, sc.points2d[m], 1.0)
        assert b.gamma_lb[m] <= ref * (1 + 1e-9) + 1e-12
        assert b.gamma_ub[m] <= ref * (1 + 1e-6) + 1e-9
        sdp = tritools.triangulate(C, _discs(sc.points2d[m], 1.0), "corollary1", 2, 2, path="sdp")
        assert sdp.optimal and abs(sdp.gamma_ub - b.gamma_ub[m]) <= 1e-6 * max(1.0, sdp.gamma_ub)


def test_discs_meeting_the_true_projections_give_zero():
    sc = random_scene(4, 3, noise_px=0.3, seed=9)           # noise well inside 2 px discs: gamma* = 0
    C = np.asarray(sc.cameras)
    b = verify_discs(np.broadcast_to(C, (3,) + C.shape), sc.points2d, np.full((3, 4), 2.0))
    # gamma_UB keeps the projections' round-off margin (report.gamma_upper): ~1e-13 px, not exactly 0
    assert b.certified.all() and np.all(b.gamma_ub < 1e-10) and np.all(b.gamma_lb == 0)


def test_long_disc_tracks_use_the_band_and_stay_sound():
    sc = random_scene(20, 3, noise_px=2.0, seed=4)
    C = np.asarray(sc.cameras)
    b = verify_discs(np.broadcast_to(C, (3,) + C.shape), sc.points2d, np.full((3, 20), 1.0))
    assert b.certified.all()
    for m in range(3):
        assert b.gamma_lb[m] <= _reference(C, sc.points2d[m], 1.0) * (1 + 1e-9)


def test_batches_of_discs_are_verified_and_match_single_calls():
    sc = random_scene(3, 8, noise_px=1.5, seed=12)
    problems = [(sc.cameras, _discs(sc.points2d[m], 1.0)) for m in range(8)]
    many = tritools.triangulate_many(problems, progress=False)
    assert all(r.optimal for r in many)
    assert sum(r.certified_by == "verification" for r in many) >= 6
    for (C, regs), r in zip(problems[:3], many[:3]):
        one = tritools.triangulate(C, regs)
        assert one.optimal and abs(one.gamma_ub - r.gamma_ub) <= 1e-9 * max(1.0, r.gamma_ub)
        assert r.residuals is not None and r.depths is not None and r.attempts[0].step == "verification"


def test_only_exact_discs_take_the_disc_path():
    assert disc_radius(Ellipse([1.0, 2.0], 4.0 * np.eye(2))) == 2.0
    assert disc_radius(Ellipse([1.0, 2.0], np.diag([4.0, 1.0]))) is None
    assert disc_radius(Point([1.0, 2.0])) is None
    sc = random_scene(3, 1, noise_px=1.0, seed=3)
    regs = [Ellipse(c, np.diag([4.0, 1.0])) for c in sc.points2d[0]]     # ellipses: the vectorised ellipse path
    assert np.shape(as_disc_problem(sc.cameras, regs)[2]) == (3, 2, 2)
    mixed = as_disc_problem(sc.cameras, regs[:2] + [Point(sc.points2d[0][2])])       # a point: D = 0
    assert mixed is not None and not np.any(mixed[2][2])
    assert as_disc_problem(sc.cameras, regs[:2] + [Segment(sc.points2d[0][2], [1.0, 0.0])]) is None
    assert as_disc_problem(sc.cameras, [Point(p) for p in sc.points2d[0]]) is None    # all points: point path


@pytest.mark.parametrize("scale,shift", [(1e-3, 0.0), (1e3, 1e6)])
def test_disc_certificates_follow_the_image_units(scale, shift):
    """Pixel coordinates and radii scaled and shifted: gamma scales with the image, the decision is the same."""
    sc = random_scene(4, 4, noise_px=2.0, seed=21)
    C = np.asarray(sc.cameras)
    T = np.array([[scale, 0, shift], [0, scale, shift], [0, 0, 1.0]])
    C2 = np.einsum("ij,njk->nik", T, C)
    ref = verify_discs(np.broadcast_to(C, (4,) + C.shape), sc.points2d, np.ones((4, 4)))
    new = verify_discs(np.broadcast_to(C2, (4,) + C2.shape), scale * sc.points2d + shift, np.full((4, 4), scale))
    assert ref.certified.all() and new.certified.all()
    np.testing.assert_allclose(new.gamma_ub / scale, ref.gamma_ub, rtol=1e-6)
    np.testing.assert_allclose(new.gamma_lb / scale, ref.gamma_lb, rtol=1e-5)
