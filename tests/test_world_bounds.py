"""gamma_UB is an upper bound of the given float problem in any world frame (review 7 F1): evaluated at the reported
float estimate with compensated projections and rounded up (tritools.solve.report.gamma_upper).  Before, at
|X| ~ 1e8 the plain P (X, 1) lost ~8 digits and gamma_UB fell up to 3e-7 px below the exact optimum.

Reference: gamma at the reported X in exact rational arithmetic on the float data (Fractions), which is >= the
optimum gamma* since X is feasible; gamma_UB must be >= it, gamma_LB <= it up to the documented slack of the
normalised data (docs/certificates.md, "What the rigour covers")."""
from fractions import Fraction

import numpy as np
import pytest

import tritools
from tritools.model.exact import accurate_homogeneous, dot2
from tritools.model.frame import project_world
from tritools.model.geometry import project_homogeneous
from tritools.scene import random_scene
from tritools.solve.report import gamma_upper, point_report, points_report_stack

DIRECTION = np.array([1.0, -2.0, 0.5])


def _geo(P, shift):
    T = np.eye(4)
    T[:3, 3] = -shift
    return P @ T


def _f_exact(P, x, X, radii=None) -> Fraction:
    """sum_i d_i(X)^2 exactly (Fractions) at the float X; ``radii``: discs (distance max(0, |u - x| - r), whose
    square is bounded above here by (|u - x| - r)^2 via a float sqrt rounded up: enough for a >= test)."""
    Xh = [Fraction(v) for v in X] + [Fraction(1)]
    s = Fraction(0)
    for i, (Pi, xi) in enumerate(zip(P, x)):
        h = [sum(Fraction(Pi[r, c]) * Xh[c] for c in range(4)) for r in range(3)]
        d2 = (h[0] / h[2] - Fraction(xi[0])) ** 2 + (h[1] / h[2] - Fraction(xi[1])) ** 2
        if radii is not None:
            d = max(0.0, float(np.nextafter(np.sqrt(float(d2)), np.inf)) - radii[i]) * (1 - 1e-15)
            d2 = Fraction(d) ** 2
        s += d2
    return s


def _ub_holds(g_ub, f, n) -> bool:
    return Fraction(g_ub) ** 2 * 2 * n >= f


@pytest.mark.parametrize("offset", [0.0, 1e6, 1e8, 2.3e8])
def test_gamma_ub_is_above_the_exact_gamma_at_x_single_many_points(offset):
    bad = []
    for seed in range(8):
        sc = random_scene(3 + seed % 5, 1, noise_px=1.0, seed=100 + seed)
        P, x = _geo(np.array(sc.cameras, float), offset * DIRECTION), sc.points2d[0]
        for name, r in (("single", tritools.triangulate(P, x)),
                        ("many", tritools.triangulate_many([(P, x)], progress=False)[0]),
                        ("points", tritools.triangulate_points(P, x[None])[0])):
            f = _f_exact(P, x, r.X)
            g_x = float(np.sqrt(float(f) / (2 * len(P))))          # (the lb's documented slack: ~3e-14 px)
            if not (_ub_holds(r.gamma_ub, f, len(P)) and r.gamma_lb <= g_x + 3e-14 * max(1.0, g_x)):
                bad.append((seed, name, r.gamma_lb, r.gamma_ub, float(f)))
    assert not bad, bad


@pytest.mark.parametrize("offset", [0.0, 1e8])
def test_disc_batches_gamma_ub_above_the_exact_value(offset):
    sc = random_scene(4, 6, noise_px=2.0, seed=7)
    P = _geo(np.array(sc.cameras, float), offset * DIRECTION)
    probs = [(P, [tritools.Ellipse(p, 0.25 * np.eye(2)) for p in sc.points2d[m]]) for m in range(6)]
    for m, r in enumerate(tritools.triangulate_many(probs, progress=False)):
        f = _f_exact(P, sc.points2d[m], r.X, radii=np.full(4, 0.5))
        assert _ub_holds(r.gamma_ub, f, 4), (m, r.gamma_ub, float(f))
        assert r.gamma_lb <= r.gamma_ub


def test_accurate_homogeneous_is_faithful_where_the_plain_sum_cancels():
    rng = np.random.default_rng(1)
    P = rng.normal(size=(6, 3, 4))
    X = rng.normal(size=(6, 3)) * 1e8
    P[..., 3] = -np.einsum("nij,nj->ni", P[..., :3], X) + rng.normal(size=(6, 3))     # depths ~1
    Xh = np.concatenate([X, np.ones((6, 1))], axis=1)
    got = accurate_homogeneous(P, Xh[:, None, :])
    plain = np.einsum("nij,nj->ni", P, Xh)
    worst_plain = 0.0
    for n, r in np.ndindex(6, 3):
        exact = sum(Fraction(P[n, r, k]) * Fraction(Xh[n, k]) for k in range(4))
        assert abs(Fraction(got[n, r]) - exact) <= abs(exact) * Fraction(4.5e-16)
        worst_plain = max(worst_plain, abs(float(Fraction(plain[n, r]) - exact)) / abs(float(exact)))
    assert worst_plain > 1e-12            # the case really cancels: the plain sum is far off
    assert np.array_equal(dot2(P, np.broadcast_to(Xh[:, None, :], P.shape), np.zeros((6, 3))), got)


def test_the_three_projections_agree_bit_for_bit_in_a_far_world():
    sc = random_scene(5, 4, noise_px=1.0, seed=3)
    P = _geo(np.array(sc.cameras, float), 2.3e8 * DIRECTION)
    X = sc.points3d + 2.3e8 * DIRECTION
    u, _, fin = project_world(np.broadcast_to(P, (4,) + P.shape), X)
    assert fin.all()
    for m in range(4):
        for i in range(5):
            assert np.array_equal(project_homogeneous(np.append(X[m], 1.0)[None], P[i])[0], u[m, i])
    g, res, _ = points_report_stack(np.broadcast_to(P, (4,) + P.shape), sc.points2d, X)
    for m in range(4):
        rep = point_report(X[m], P, [tritools.Point(p) for p in sc.points2d[m]])
        assert rep.gamma == pytest.approx(g[m], rel=1e-15)
        np.testing.assert_allclose(rep.residuals, res[m], rtol=1e-15)     # (a distance's last bit may differ)


def test_gamma_upper_rounding():
    res = np.array([0.3, 0.4, 0.0])
    un = np.array([1e3, 2e3, 5e2])
    g = gamma_upper(res, un)
    plain = np.sqrt(np.sum(res ** 2) / 6)
    assert plain < g < plain * (1 + 1e-9)
    assert 0.0 < gamma_upper(np.zeros(3), un) < 1e-10                 # a zero distance keeps its round-off margin
    assert gamma_upper(np.array([0.3, np.inf]), np.ones(2)) == np.inf
    assert np.array_equal(gamma_upper(np.stack([res, 2 * res]), np.stack([un, un])),
                          [gamma_upper(res, un), gamma_upper(2 * res, un)])
