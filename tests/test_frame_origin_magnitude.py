"""gamma_LB is lowered for the rounding of the frame's origin column (review 25a F1/F2).

The cameras handed to the normalisation are the caller's with their last column rounded once (a georeferenced
world re-centred on the cameras' mean; the robust search's frame).  A relative error u there moves the
projection of a point near the estimate by u (|P_k o~| + |x| |P_3 o~|) / |P_3 X~|, which the lowering by
u |x_i| sec theta did not cover where the frame's origin is far from the point relative to its depth: three
views 1e8 from the origin whose centres spread ~700 depths (L2 certified 6.7e-11 px and 5.7e-12 px above the
exact cost at a real point), and a zero-noise optimum 1e-9 from a camera centre (not certified, gamma_LB 26%
above a real point's cost).  The real points are X0 + dx with X0 and dx floats, their sum kept exact.
"""
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

import tritools
from tritools.model.normalize import normalization_stack

DATA = Path(__file__).parent / "data" / "frame_origin_cases.npz"


def _exact_f(P, x, X):
    Xh = list(X) + [Fraction(1)]
    tot = Fraction(0)
    for Pi, xi in zip(P, x):
        h = [sum(Fraction(float(Pi[r, k])) * Xh[k] for k in range(4)) for r in range(3)]
        tot += (h[0] / h[2] - Fraction(float(xi[0]))) ** 2 + (h[1] / h[2] - Fraction(float(xi[1]))) ** 2
    return tot


def _case(tag):
    d = np.load(DATA)
    P, x = d[f"P_{tag}"].reshape(-1, 3, 4), d[f"obs_{tag}"].reshape(-1, 2)
    real = [Fraction(float(a)) + Fraction(float(b)) for a, b in zip(d[f"X0_{tag}"], d[f"dx_{tag}"])]
    return P, x, real


@pytest.mark.parametrize("tag,certified", [("a", True), ("b", True), ("c", False)])
def test_lower_bound_below_a_real_points_cost(tag, certified):
    P, x, real = _case(tag)
    f_real = _exact_f(P, x, real)
    for r in (tritools.triangulate(P, x), tritools.triangulate_many([(P, x)])[0]):
        assert r.gamma_lb is not None
        assert 2 * len(P) * Fraction(r.gamma_lb) ** 2 <= f_real
        assert bool(r.optimal) == certified                       # the certified ones stay certified
        assert _exact_f(P, x, [Fraction(float(v)) for v in r.X]) <= 2 * len(P) * Fraction(r.gamma_ub) ** 2


def test_robust_lower_bound_below_a_real_points_cost():
    P, x, real = _case("a")
    f_real = _exact_f(P, x, real)                                 # every residual below c: f_TLS = f
    r = tritools.triangulate(P, x, robust=1e6)
    assert r.gamma_lb is not None and 2 * len(P) * Fraction(r.gamma_lb) ** 2 <= f_real


def test_origin_magnitude_is_that_of_the_given_frame():
    """The stack's magnitude is at least the frame's origin term, equal for a stack and its item, and invariant to
    each camera's scale (a power of two keeps the normalised cameras' bits)."""
    P, x, _ = _case("a")
    st = normalization_stack(P[None], x[None])
    m = float(st.magnitude[0])
    assert m == st.item(0).magnitude and m > 1e6                  # f |C_i - o| / depth >> |x| here
    st2 = normalization_stack((P * np.array([4.0, 0.25, 1024.0])[:, None, None])[None], x[None])
    assert float(st2.magnitude[0]) == pytest.approx(m, rel=1e-9)
