"""Review 42b (independent, sospoly): the minimiser of the re-centring step chosen by exact values (F1)."""
from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest

import sospoly as sp


def _exact(p: sp.Polynomial, pt) -> float:
    """p at the float point ``pt`` in rational arithmetic (independent of sospoly's own evaluation)."""
    return float(sum(Fraction(c) * math.prod(Fraction(float(v)) ** k for v, k in zip(pt, e))
                     for e, c in p.terms.items()))


@pytest.mark.parametrize("shift", [(1000.0, -1000.0), pytest.param((1000.0, 1000.0), marks=pytest.mark.slow),
                                   pytest.param((2000.0, -1000.0), marks=pytest.mark.slow)])
def test_a_translated_motzkin_polynomial_is_never_certified_above_its_minimum(shift):
    """Motzkin's polynomial translated and expanded in floats (the data keep its minimum, -1 after the constant's
    rounding, at integer points): a candidate valued +860 exactly read -9.8e4 in floats, was taken as the minimiser,
    and the origin's scale (1.8e19) certified a gap of 0.72 (the minimiser's scale is 8)."""
    x, y = sp.variables("x y")
    M = x ** 4 * y ** 2 + x ** 2 * y ** 4 - 3 * x ** 2 * y ** 2 + 1
    Mt = M.subs({"x": x - shift[0], "y": y - shift[1]})
    witness = min(_exact(Mt, (shift[0] + a, shift[1] + b)) for a in (-1.0, 1.0) for b in (-1.0, 1.0))
    res = sp.minimize(Mt, degree=8, radius=1.01 * math.hypot(abs(shift[0]) + 1, abs(shift[1]) + 1))
    assert res.lower_bound is None or res.lower_bound <= witness
    if res.upper_bound is not None:
        assert _exact(Mt, res.minimizers[0]) == pytest.approx(res.upper_bound, rel=1e-12, abs=1e-9)
    if res.optimal:
        assert res.upper_bound - witness <= sp.DEFAULT_TOLERANCES.gap_tolerance(res.upper_bound, res.scale)
        assert res.scale <= 64.0                  # decided at the minimiser's scale, not the origin's


def test_a_certified_minimiser_meets_the_constraints_as_given():
    """A quintic on (x - A)(B - x) >= 0, A = 1.2e5, B = 5.1e6: the minimiser was screened on the balanced program and
    reported certified 2.2e-6 (relative) outside the constraint as given (F2); a minimiser is now reported only within
    the documented tolerance, here in rational arithmetic."""
    (x,) = sp.variables("x")
    terms = {(0,): 0.6016483866275941, (1,): 9.969249885868775e-07, (2,): 1.2346925924028293e-12,
             (3,): 4.1161715511804083e-19, (4,): -1.5759203942886688e-25, (5,): -8.496698355220286e-31}
    f = sp.Polynomial(("x",), terms)
    A, B = 119976.75447474046, 5145539.459061242
    h = (x - A) * (B - x)
    res = sp.minimize(f, ineq=[h])
    cmax = max(abs(c) for c in h.terms.values())
    for p in res.minimizers + tuple(res.candidates or ()):
        assert -_exact(h, p) <= sp.DEFAULT_TOLERANCES.feasibility * max(1.0, cmax)
    assert res.lower_bound is not None and res.lower_bound <= -3080.79300      # the minimum (the review's mpmath)
    assert res.upper_bound is None or res.upper_bound >= res.lower_bound


@pytest.mark.parametrize("n", [9, pytest.param(12, marks=pytest.mark.slow)])
def test_is_sos_refutes_a_polynomial_negative_at_a_point_in_many_variables(n):
    """sum (v_i^2 - a_i)^2 + sum (v_i - v_{i+1} - (sqrt a_i - sqrt a_{i+1}))^2 - 1e-8 is -1e-8 at sqrt(a): refuted
    in 8 variables, "SOS" from 9 on, where the witness search only evaluated its starts (F3)."""
    v = sp.variables("v", n=n)
    a = [float(t) for t in np.random.default_rng(n).uniform(0.3, 2.0, size=n)]
    p = sum((v[i] ** 2 - a[i]) ** 2 for i in range(n)) \
        + sum((v[i] - v[i + 1] - (math.sqrt(a[i]) - math.sqrt(a[i + 1]))) ** 2 for i in range(n - 1)) - 1e-8
    assert _exact(p, [math.sqrt(t) for t in a]) < 0
    assert not sp.is_sos(p).is_sos
