"""The level set is the points in front of every camera (review 23a F1).

``uncertainty(..., level=tau)`` bounds ``L(tau) = {X : gamma(X) <= tau, depth_i(X) >= 0}``
(docs/uncertainty.md); gamma -- and ``triangulate``'s certificate -- ignore cheirality, so an L2 optimum behind a
camera is not a point of L.  Before, the docs defined L without the depths while the bounds (the per-view set's
relaxation) kept them, and the witnesses could be points behind a camera.  Checked here against independent
references: exact rational depths and gamma, and a dense constrained multi-start search for points of L.
"""
from fractions import Fraction
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

import tritools

DATA = Path(__file__).parent / "data" / "level_behind_camera.npz"


def _exact(P, x, X):
    """(gamma(X), signed depths sign(det M_i) p3_i . X~) in rational arithmetic (independent of tritools)."""
    Xf = [Fraction(float(v)) for v in X] + [Fraction(1)]
    s, dep = Fraction(0), []
    for Pi, xi in zip(P, x):
        h = [sum(Fraction(float(Pi[r, k])) * Xf[k] for k in range(4)) for r in range(3)]
        s += (h[0] / h[2] - Fraction(float(xi[0]))) ** 2 + (h[1] / h[2] - Fraction(float(xi[1]))) ** 2
        dep.append(float(h[2]) * float(np.sign(np.linalg.det(Pi[:, :3]))))
    return float(s / (2 * len(P))) ** 0.5, np.array(dep)


def _front_search(P, x, starts):
    """The smallest gamma^2 found in front of every camera: SLSQP from every start, depth_i >= 1e-9 |P_i|."""
    rows = np.array([np.sign(np.linalg.det(Pi[:, :3])) * Pi[2] / np.linalg.norm(Pi[2, :3]) for Pi in P])

    def g2(X):
        h = P @ np.append(X, 1.0)
        return float(np.sum((h[:, :2] / h[:, 2:] - x) ** 2)) / (2 * len(P))
    cons = {"type": "ineq", "fun": lambda X: rows[:, :3] @ X + rows[:, 3] - 1e-9}
    best = np.inf
    for X0 in starts:
        if np.any(rows[:, :3] @ X0 + rows[:, 3] <= 0):
            continue
        with np.errstate(all="ignore"):
            r = minimize(g2, X0, method="SLSQP", constraints=[cons], options={"maxiter": 300, "ftol": 1e-14})
        if np.all(np.isfinite(r.x)) and np.all(rows[:, :3] @ r.x + rows[:, 3] > 0):
            best = min(best, g2(r.x))
    return best


def test_empty_level_set_when_only_points_behind_a_camera_reach_the_level():
    d = np.load(DATA)
    P, x = d["P"], d["x"]
    opt = tritools.triangulate(P, x)
    assert opt.optimal and not opt.in_front
    g_opt, dep = _exact(P, x, opt.X)
    assert dep[0] < 0 < dep[1] and abs(g_opt - opt.gamma_ub) <= 1e-9          # the optimum is behind camera 0
    tau = opt.gamma_ub + 0.5
    lev = tritools.uncertainty(P, x, level=tau, estimate=opt.X)
    assert lev.status.value == "empty" and lev.rigorous
    # no point in front of both cameras reaches the level: dense constrained multi-start
    rng = np.random.default_rng(0)
    centres = np.array([np.linalg.svd(Pi)[2][-1] for Pi in P])
    centres = centres[:, :3] / centres[:, 3:]
    scale = float(np.linalg.norm(centres[0] - centres[1]))
    starts = list(centres.mean(0) + scale * rng.normal(size=(150, 3)) * rng.choice([0.1, 1, 10, 100], (150, 1)))
    assert np.sqrt(_front_search(P, x, starts)) > tau


def _two_views_at_an_epipole():
    """View 1 observes (0.36 px from) the epipole of camera 0: the L2 optimum sits next to camera 0's centre,
    behind it, and L extends in front of it along view 0's ray (the reviewer's second case)."""
    def look_at(C, f=800.0):
        z = -C / np.linalg.norm(C)
        xa = np.cross([0.0, 1.0, 0.0], z)
        xa /= np.linalg.norm(xa)
        R = np.array([xa, np.cross(z, xa), z])
        K = np.array([[f, 0, 320.0], [0, f, 240.0], [0, 0, 1.0]])
        return K @ np.hstack([R, -R @ C[:, None]])

    C0, C1 = np.array([0.3, 0.2, -10.0]), np.array([-2.0, 0.5, -20.0])
    P = np.array([look_at(C0), look_at(C1)])

    def proj(Pi, X):
        h = Pi @ np.append(X, 1.0)
        return h[:2] / h[2]
    x = np.array([proj(P[0], np.array([0.1, -0.1, 0.2])), proj(P[1], C0) + np.array([0.3, -0.2])])
    return P, x, C0


def test_level_box_holds_every_point_of_the_level_set_in_front_and_witnesses_are_in_front():
    P, x, C0 = _two_views_at_an_epipole()
    opt = tritools.triangulate(P, x)
    tau = 2.0
    lev = tritools.uncertainty(P, x, level=tau, estimate=opt.X)
    assert lev.status.value == "bounded" and lev.rigorous
    for W in (lev.witness_lo, lev.witness_hi):                # every witness is a point of L (exactly)
        for w in W:
            if np.all(np.isfinite(w)):
                g, dep = _exact(P, x, w)
                assert g <= tau * (1 + 1e-12) and np.all(dep >= 0)
    # points of L in front of both cameras, along view 0's ray and scattered around it: all in the box
    M = P[0][:, :3]
    ray = np.linalg.solve(M, np.append(x[0], 1.0))
    ray *= np.sign(np.linalg.det(M)) / np.linalg.norm(ray)
    rng = np.random.default_rng(1)
    inside = 0
    for t in np.concatenate([np.geomspace(1e-4, 5.0, 40), rng.uniform(0, 2.0, 40)]):
        X = C0 + t * ray + rng.normal(size=3) * 1e-3 * t
        g, dep = _exact(P, x, X)
        if g <= tau and np.all(dep >= 0):
            inside += 1
            assert np.all(X >= lev.lo) and np.all(X <= lev.hi), (t, X, lev.lo, lev.hi)
    assert inside >= 10

