"""A compensated dot product rounded exactly where it cancels beyond twice the working precision.

Ogita, Rump and Oishi's Dot2 errs by u |s| + ~16 u^2 sum |a_k x_k|: relative to |s| that is unbounded where the
sum cancels more than ~106 bits (a numerator next to the image origin in a georeferenced world: a projection within
~1e-18 of the scale of its terms).  ``tritools.solve.report.gamma_upper`` assumes every homogeneous image errs by at
most ``HOMOGENEOUS_RTOL`` relative, so a reported gamma_UB could fall below the exact cost at the reported X where
the observation sits on such a projection (wave 24's closing note).  ``dot2`` now rounds every entry that cancels
more than 40 bits exactly (``math.fsum`` of the exact products' parts); its scalar twin does the same.
"""
from fractions import Fraction

import numpy as np

from tritools.model.exact import EXACT_ROUNDING_RATIO, HOMOGENEOUS_RTOL, dot2, two_prod, two_sum
from tritools.model.frame import _dot2_one, project_world, project_world_one
from tritools.model.geometry import project_points_views
from tritools.solve.report import gamma_upper


def _cancelling_rows(n, seed=0):
    """Rows a (n, 4) and points x (n, 4) (x_2 = x_3 = 1) whose exact dot products cancel to ~u^2 or to 0: a_2 and a_3
    absorb the float and the rounding error of a_0 x_0 + a_1 x_1."""
    rng = np.random.default_rng(seed)
    A, X = [], []
    for _ in range(n):
        a = rng.standard_normal(4) * 2.0 ** rng.integers(-5, 5, 4)
        x = np.array([rng.standard_normal(), rng.standard_normal(), 1.0, 1.0])
        e01 = Fraction(a[0]) * Fraction(x[0]) + Fraction(a[1]) * Fraction(x[1])
        a[2] = -float(e01)
        a[3] = -float(e01 + Fraction(a[2]))
        A.append(a)
        X.append(x)
    return np.array(A), np.array(X)


def _exact(a, x, b=0.0):
    return sum((Fraction(float(ai)) * Fraction(float(xi)) for ai, xi in zip(a, x)), Fraction(float(b)))


def _dot2_unrounded(a, x):
    """Dot2 without the exact rounding (the algorithm as it was): the reference that shows the rows are hard."""
    s = c = 0.0
    for ak, xk in zip(a, x):
        p, ep = two_prod(ak, xk)
        s, es = two_sum(s, p)
        c = c + (ep + es)
    return s + c


def test_dot2_is_correctly_rounded_where_it_cancels():
    A, X = _cancelling_rows(400)
    out = dot2(A, X, np.zeros(len(A)))
    exact = [_exact(a, x) for a, x in zip(A, X)]
    assert all(out[k] == float(e) for k, e in enumerate(exact))           # Fraction -> float: correctly rounded
    hard = sum(_dot2_unrounded(a, x) != float(e) for a, x, e in zip(A, X, exact))
    assert hard > 50                                                     # Dot2 alone misses these


def test_dot2_with_an_addend_is_correctly_rounded():
    A, X = _cancelling_rows(200, seed=1)
    b = A[:, 3].copy()                                                   # the last term as b (moved cameras' form)
    out = dot2(A[:, :3], X[:, :3], b)
    assert all(out[k] == float(_exact(A[k, :3], X[k, :3], b[k])) for k in range(len(A)))


def test_dot2_keeps_its_numbers_where_it_does_not_cancel():
    rng = np.random.default_rng(2)
    A, X = rng.standard_normal((500, 4)), rng.standard_normal((500, 4))
    out = dot2(A, X, np.zeros(500))
    assert np.array_equal(out, [_dot2_unrounded(a, x) for a, x in zip(A, X)])
    S = np.abs(A * X).sum(axis=1)
    assert np.all(S <= EXACT_ROUNDING_RATIO * np.abs(out))               # none of them was re-rounded


def test_scalar_twin_is_bit_equal():
    A, X = _cancelling_rows(300, seed=3)
    rng = np.random.default_rng(4)
    A = np.vstack([A, rng.standard_normal((100, 4))])
    X = np.vstack([X, rng.standard_normal((100, 4))])
    vec = dot2(A, X, np.zeros(len(A)))
    one = np.array([_dot2_one(a.tolist(), x.tolist()) for a, x in zip(A, X)])
    assert np.array_equal(vec, one)


def _tiny_numerator_camera():
    """A camera whose first numerator cancels to exactly 0 at X (an observation at the image origin's scale),
    with a denominator that cancels too (so the view is compensated) and a positive depth."""
    A, X = _cancelling_rows(400, seed=5)
    for a, x in zip(A, X):
        if _exact(a, x) == 0 and _dot2_unrounded(a, x) != 0:
            break
    else:
        raise AssertionError("no row with an exact zero that Dot2 misses")
    Xw = x[:3]
    row1 = np.array([0.375, -1.5, 0.0, 0.0])                             # a second numerator at ~u^2 of its terms
    e01 = Fraction(row1[0]) * Fraction(x[0]) + Fraction(row1[1]) * Fraction(x[1])
    row1[2] = -float(e01)
    row1[3] = -float(e01 + Fraction(row1[2]))
    row2 = np.array([0.5, -0.25, 0.75, 0.0])
    row2[3] = -float(_exact(row2[:3], Xw)) + 2.0 ** -30                  # depth 2^-30 after ~2^0 terms: cancels
    P = np.array([a, row1, row2])
    return P, Xw, _dot2_unrounded(a, x) / _dot2_unrounded(row2, x)


def test_projection_next_to_the_image_origin_is_exact():
    P, Xw, old_u0 = _tiny_numerator_camera()
    Xf = [Fraction(float(v)) for v in Xw] + [Fraction(1)]
    h = [sum(Fraction(float(P[r, k])) * Xf[k] for k in range(4)) for r in range(3)]
    assert h[0] == 0 and h[2] > 0 and old_u0 != 0
    u_exact = (h[0] / h[2], h[1] / h[2])
    u_vec = project_points_views(np.append(Xw, 1.0)[None], P[None])[0, 0]
    u_world = project_world(P[None, None], Xw[None])[0][0, 0]
    u_one = project_world_one([P.tolist()], Xw.tolist())[0][0]
    for u in (u_vec, u_world, u_one):
        assert u[0] == 0.0
        assert abs(Fraction(float(u[1])) - u_exact[1]) <= 3 * HOMOGENEOUS_RTOL * abs(u_exact[1])
    assert abs(u_exact[1]) < 1e-20                                       # both numerators at the origin


def test_gamma_ub_covers_an_observation_on_the_rounded_projection():
    """The observation placed where unrounded Dot2 put the projection: the float residual was 0 and gamma_UB's
    relative margin ~1e-13 |u| below the exact distance |old_u0| (> 0)."""
    P, Xw, old_u0 = _tiny_numerator_camera()
    u, _, fin = project_world(P[None, None], Xw[None])
    x = np.array([[old_u0, float(u[0, 0, 1])]])
    assert fin[0]
    res = np.linalg.norm(u[0] - x, axis=1)
    g_ub = gamma_upper(res[None], np.linalg.norm(u[0], axis=1)[None])[0]
    Xf = [Fraction(float(v)) for v in Xw] + [Fraction(1)]
    h = [sum(Fraction(float(P[r, k])) * Xf[k] for k in range(4)) for r in range(3)]
    d2 = (h[0] / h[2] - Fraction(old_u0)) ** 2 + (h[1] / h[2] - Fraction(float(x[0, 1]))) ** 2
    assert Fraction(float(g_ub)) ** 2 * 2 >= d2 > 0
