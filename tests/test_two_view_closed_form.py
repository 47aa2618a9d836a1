"""The closed-form two-view L2 optimum of single robust calls (:func:`tritools.solve.robust_two.two_view_optimum`):
against the independent Hartley-Sturm reference (tests/reference/hartley_sturm.py, its own fundamental matrix from
a determinant and its own conditioning) and against multi-start least squares, in the normalised frame of
:func:`tritools.solve.robust_enum.enum_frame`; the robust call that starts from it keeps its certificates, its
bounds and its decisions.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

import tritools
import tritools.solve.robust_three as r3
import tritools.solve.robust_two as r2
from tests.reference.hartley_sturm import hartley_sturm
from tritools.model.stacked import project_stack
from tritools.scene import robust_protocol_scene
from tritools.solve import robust_enum as enum


def _framed(P, x):
    frame, Cn = enum.enum_frame(P, x)
    F, defined, _ = enum.fundamentals(P[None], Cn[None])
    assert defined[0, 0]
    return frame, Cn, F[0, 0]


def _sideways(rng):
    """Two cameras translated along their common x axis (epipoles at infinity: f_0 = f_1 = 0) and a point."""
    K = np.array([[900.0, 0, 640], [0, 900, 360], [0, 0, 1]])
    P = np.array([K @ np.hstack([np.eye(3), [[-b], [0.0], [0.0]]]) for b in (0.0, 0.3)])
    X = np.array([0.1, -0.2, 4.0]) + rng.normal(scale=0.1, size=3)
    h = P @ np.append(X, 1.0)
    return P, h[:, :2] / h[:, 2:] + rng.normal(scale=2.0, size=(2, 2))


def _scenes(seed: int, n: int):
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        if k % 7 == 6:
            out.append(_sideways(rng))
            continue
        P, x, _, _ = robust_protocol_scene(2, int(rng.integers(0, 2)), float(rng.choice([0.0, 1.0, 5.0])), rng)
        s = float(rng.choice([1e-3, 1.0, 1e5]))
        out.append((np.diag([s, s, 1.0]) @ P, x * s))
    return out


@pytest.mark.parametrize("seed", [0, 1])
def test_closed_form_cost_is_hartley_sturm(seed):
    """Its cost (normalised units / s^2) is the reference's pixel cost, and the DLT of its corrected points has that
    cost: clean tracks, wrong matches, zero noise, pixel scales 1e-3..1e5, epipoles at infinity."""
    for P, x in _scenes(seed, 60):
        frame, Cn, F = _framed(P, x)
        y0, y1, cost = r2.two_view_optimum(F)
        ref = hartley_sturm(P[0], P[1], x[0], x[1])[1]
        pixel = cost / frame.scale ** 2
        assert pixel == pytest.approx(ref, rel=1e-7, abs=1e-12 * float(np.max(np.abs(x))) ** 2)
        Xn = r2.optimum_candidate(Cn, F)
        u = project_stack(Cn[None], Xn[None])[0][0]
        assert float(np.sum(u ** 2)) == pytest.approx(cost, rel=1e-6, abs=1e-14)


def test_closed_form_is_the_global_minimum_of_multi_start():
    """No start of 16 (Levenberg-Marquardt, tight tolerances) finds a lower two-view cost than the closed form (up to
    the round-off of the polynomial's roots, ~1e-12 in the normalised frame's units at zero noise: the call refines
    the candidate after)."""
    rng = np.random.default_rng(5)
    for P, x in _scenes(5, 40):
        _, Cn, F = _framed(P, x)
        Xn = r2.optimum_candidate(Cn, F)

        def r(X):
            return project_stack(Cn[None], X[None])[0][0].ravel()

        f = float(np.sum(r(Xn) ** 2))
        starts = [Xn, np.zeros(3)] + [rng.normal(scale=s, size=3) for s in (0.1, 1.0, 10.0) for _ in range(5)]
        best = min(2 * least_squares(r, X0, method="lm", xtol=1e-15, ftol=1e-15).cost for X0 in starts)
        assert f <= best * (1 + 1e-7) + 1e-10


def test_epipole_at_an_observation():
    """An epipole at the origin of a normalised image (an observation on the baseline) has no closed form; an
    observation 1e-3..1 px from the epipole is still certified by the single call, as by the batch, at the
    reference's optimum; no bound above it at 1e-6 px."""
    assert r2.two_view_optimum(np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])) is None
    K = np.array([[800.0, 0, 500], [0, 800, 400], [0, 0, 1]])
    R = np.array([[np.cos(0.3), 0, np.sin(0.3)], [0, 1, 0], [-np.sin(0.3), 0, np.cos(0.3)]])
    c1 = np.array([0.3, 0.1, 2.0])                            # camera 1's centre, in front of camera 0 (epipole
    P = np.array([K @ np.hstack([np.eye(3), np.zeros((3, 1))]), K @ np.hstack([R, (-R @ c1)[:, None]])])
    h = P[1] @ np.array([0.5, 0.0, 4.0, 1.0])                # (620, 440) in view 0)
    for off in (1e-6, 1e-3, 1.0):
        x = np.array([[620.0 + off, 440.0], h[:2] / h[2] + [3.0, -2.0]])
        res = tritools.triangulate(P, x, robust=50.0)
        many = tritools.triangulate_many([(P, x)], robust=50.0)[0]
        ref = min(hartley_sturm(P[0], P[1], x[0], x[1])[1], 2500.0)
        for r in (res, many):
            assert 4 * r.gamma_lb ** 2 <= ref * (1 + 1e-9) + 1e-9
            assert r.gamma_lb <= r.gamma_ub
        if off >= 1e-3:       # (at 1e-6 px the optimum nears camera 1's centre: either may decline, as before)
            assert res.optimal and many.optimal
            assert 4 * res.gamma_ub ** 2 == pytest.approx(4 * many.gamma_ub ** 2, rel=1e-6, abs=1e-6)


def test_single_calls_start_from_the_closed_form_and_keep_their_decisions(monkeypatch):
    """Every protocol call takes the closed form; certified, no lower bound above min(L2*, c^2) of the reference,
    gamma_UB = f_TLS(X) within the gap rule of it; ray samples only where UB exceeds a threshold (they cannot lower UB
    otherwise)."""
    used, rays = [], []
    real_opt, real_rays = r3.optimum_candidate, r3.ray_offers
    monkeypatch.setattr(r3, "optimum_candidate", lambda *a: used.append(1) or real_opt(*a))
    monkeypatch.setattr(r3, "ray_offers", lambda *a: rays.append(1) or real_rays(*a))
    rng = np.random.default_rng(11)
    skipped = 0
    for k in range(60):
        P, x, _, _ = robust_protocol_scene(2, k % 2, 1.0, rng)
        c = 200.0
        n = len(rays)
        res = tritools.triangulate(P, x, robust=c)
        ref = min(hartley_sturm(P[0], P[1], x[0], x[1])[1], c * c)
        f_lb, f_ub = 4 * res.gamma_lb ** 2, 4 * res.gamma_ub ** 2
        assert res.optimal
        assert f_lb <= ref * (1 + 1e-9) + 1e-9
        assert f_ub <= ref + 1e-6 * max(c * c, ref) * 2
        skipped += len(rays) == n
        if len(rays) == n:
            assert f_ub <= c * c
    assert len(used) == 60
    assert 0 < skipped < 60
