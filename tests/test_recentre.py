"""Strategy step 8 of sospoly.minimize (sospoly.recentre): a translated problem whose coefficients cancel near the
minimiser.  References are closed forms, exact rational arithmetic and a dense grid, never the code's output."""
from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

import sospoly
from sospoly.recentre import cancellation_scale, exact_value, translated, translation_point

x, y = sospoly.variables("x y")


def test_translated_double_well_is_certified_at_its_own_value_scale():
    """min (x - 1000)^4 - 3 (x - 1000)^2 + 1 = -1.25 at 1000 +- sqrt(1.5).  Expanded at the origin its coefficients
    reach 1e12; before step 8 the result was 'optimal' with lower bound -2575.7 (a gap of 1e-9 of the coefficients)."""
    f = (x - 1000) ** 4 - 3 * (x - 1000) ** 2 + 1
    res = sospoly.minimize(f)
    assert res.optimal
    assert res.lower_bound <= -1.25 <= res.upper_bound
    assert res.upper_bound - res.lower_bound <= 1e-5
    assert abs(abs(res.minimizers[0][0] - 1000) - np.sqrt(1.5)) < 1e-3
    assert res.scale <= 16 and "re-centred at the minimiser" in res.message


def test_two_variables_translated_far_away():
    """((x - 1000)^2 - 1)^2 + (y + 512)^2: minimum 0 at (999, -512) and (1001, -512)."""
    f = ((x - 1000) ** 2 - 1) ** 2 + (y + 512) ** 2
    res = sospoly.minimize(f)
    assert res.lower_bound is not None and res.lower_bound <= 0.0 <= res.upper_bound
    assert res.optimal and res.upper_bound - res.lower_bound <= 1e-5
    p = res.minimizers[0]
    assert min(abs(p[0] - 999), abs(p[0] - 1001)) < 1e-3 and abs(p[1] + 512) < 1e-3
    grid = np.linspace(990, 1010, 2001)
    assert res.lower_bound <= min(float(((g - 1000) ** 2 - 1) ** 2) for g in grid) + 1e-12


def test_inexact_data_never_contradicts_itself():
    """1000.1 is not a short float: the translation is not exact, so the first solve is kept, with f valued
    exactly at its points (a float evaluation at 1001 errs by ~1e-3 here)."""
    f = (x - 1000.1) ** 4 - 3 * (x - 1000.1) ** 2 + 1
    res = sospoly.minimize(f)
    assert res.lower_bound is not None and res.upper_bound is not None
    assert res.lower_bound <= res.upper_bound
    assert res.upper_bound == exact_value(f, res.minimizers[0])
    grid = np.linspace(998, 1003, 50001)
    fine = min(exact_value(f, [g]) for g in grid[::50])
    assert res.lower_bound <= fine
    if res.optimal:
        assert res.upper_bound - res.lower_bound <= 1e-6 * res.scale * 2 + 1e-6 * max(res.scale, abs(res.upper_bound))


@pytest.mark.parametrize("point", [[998.7, 0.0], [1e-3, 5.0], [-3.25, 1e6]])
def test_translation_is_exact_rational_arithmetic(point):
    p = 3 * x ** 3 * y - 7 * x * y ** 2 + 2 * y + 11
    t = translation_point(point)
    q = translated(p, t, exact=False)
    rng = np.random.default_rng(0)
    for _ in range(5):
        yv = rng.standard_normal(2)
        exact = sum(Fraction(float(c)) * (Fraction(float(yv[0])) + Fraction(float(t[0]))) ** a[0]
                    * (Fraction(float(yv[1])) + Fraction(float(t[1]))) ** a[1] for a, c in p.terms.items())
        assert abs(exact_value(q, yv) - float(exact)) <= 1e-12 * max(1.0, abs(float(exact)))
    assert np.all(np.abs(t - np.asarray(point)) <= np.abs(point) * 2.0 ** -11)


def test_exact_value_is_an_upper_value_and_beats_floating_point():
    f = (x - 1000) ** 4 - 3 * (x - 1000) ** 2 + 1
    v = [1000 + np.sqrt(1.5)]
    truth = sum(Fraction(float(c)) * Fraction(float(v[0])) ** a[0] for a, c in f.terms.items())
    assert Fraction(exact_value(f, v)) >= truth and exact_value(f, v) - float(truth) <= 2 * np.spacing(1.25)


def test_no_re_centring_where_nothing_cancels():
    """Motzkin at its minimiser (1, 1), and the origin itself: the measure says no."""
    m = x ** 4 * y ** 2 + x ** 2 * y ** 4 - 3 * x ** 2 * y ** 2 + 1
    assert not cancellation_scale(m, [1.0, 1.0]).worth_translating
    assert not cancellation_scale(m, [1e-9, -1e-9]).worth_translating
    f = (x - 1000) ** 4 - 3 * (x - 1000) ** 2 + 1
    assert cancellation_scale(f + 0 * y, [998.8, 0.0]).worth_translating


@pytest.mark.parametrize("s, a", [(1.0, 1e3), (1e6, 1e3), (1.0, 1e4), (1.0, 1e5)])
def test_translated_family_against_the_given_polynomial(s, a):
    """The review's family s (((x - a)^2 - 1)^2 + (y - a)^2).  Expanded in floating point its coefficients are
    rounded (at a = 1e5 the constant by ~1e4), so the reference is the *given* polynomial valued exactly on a
    grid around (a +- 1, a); the bounds must hold for it and the upper bound is its exact value."""
    f = s * (((x - a) ** 2 - 1) ** 2 + (y - a) ** 2)
    res = sospoly.minimize(f)
    assert res.lower_bound is not None and res.upper_bound is not None
    assert res.upper_bound == exact_value(f, res.minimizers[0])
    grid = min(exact_value(f, [a + dx, a + dy]) for dx in np.linspace(-1.5, 1.5, 61) for dy in (-0.1, 0.0, 0.1))
    assert res.lower_bound <= grid
    assert res.lower_bound <= res.upper_bound
    if res.optimal:
        assert res.upper_bound - res.lower_bound <= sospoly.DEFAULT_TOLERANCES.gap_tolerance(res.upper_bound, res.scale)


def test_the_decision_is_at_the_minimisers_scale_also_without_a_constant_there():
    """Review 5, F1: translated polynomials whose minimum value is 0 (nothing anchors a balancing of f(y + t)) were
    decided at the origin's scale (up to 3e20) and certified points far from the minimum.  a = 1e5: the given float
    polynomial's constant is rounded by ~1e4, its minimum 9215 is inside that noise, and the bounds (valid) do not
    meet at the minimiser's scale."""
    a = 1e5
    f = ((x - a) ** 2 - 1) ** 2 + (y - a) ** 2
    res = sospoly.minimize(f)
    cut = cancellation_scale(f, [a + 1.0, a])
    assert cut.st <= 64 < cut.s0
    assert res.scale <= 64
    assert res.lower_bound <= 9215.0 <= res.upper_bound
    assert not res.optimal or res.upper_bound - res.lower_bound <= \
        sospoly.DEFAULT_TOLERANCES.gap_tolerance(res.upper_bound, res.scale)


def test_upper_bound_is_the_exact_value_at_the_point_everywhere():
    """Review 5, F3: without re-centring the upper bound was a floating-point value, 4e-11 below the exact minimum
    of a convex quadratic.  Now it is f at the point in rational arithmetic, rounded up."""
    f = 3.3 * (x - 0.7) ** 2 + 1.9 * (y + 0.35) ** 2 - 2.537912372204689 + 0.1 * x * y
    res = sospoly.minimize(f)
    assert res.upper_bound == exact_value(f, res.minimizers[0])
    assert res.lower_bound <= res.upper_bound
