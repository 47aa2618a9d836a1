"""sospoly.minimize's upper bounds come from points near the feasible set, not from points that meet the
constraints only by value (review 21a F3): a squared constraint (x^2 + y^2 - 1)^2 = 0 is met to 1e-6 by value 1e-3 off
its set, where f = x + y lies ~1e-4 below the true minimum -sqrt(2); such a point gave ``optimal=True`` with
lower = upper below the minimum.  ``sospoly.analysis.candidates.value_shift`` (first-order distance times
|grad f|) decides which points' values are upper bounds."""
from __future__ import annotations

import math

import numpy as np
import pytest

import sospoly as sp
from sospoly import DEFAULT_TOLERANCES as TOL
from sospoly.analysis.candidates import value_shift

F_MIN = -math.sqrt(2.0)


@pytest.mark.parametrize("refine", [False, True])
def test_squared_constraint_never_certifies_below_the_minimum(refine):
    x, y = sp.variables("x y")
    r = sp.minimize(x + y, eq=[(x ** 2 + y ** 2 - 1) ** 2], refine=refine)
    assert r.lower_bound is None or r.lower_bound <= F_MIN + 1e-12
    if r.upper_bound is not None:
        assert r.upper_bound >= F_MIN - TOL.gap_tolerance(F_MIN)          # an upper bound, within the rule
        for p in r.minimizers:
            assert abs(float(np.dot(p, p)) - 1.0) <= 1e-5                 # on the circle, not 1e-4 off it
    if r.optimal:
        assert r.upper_bound - r.lower_bound <= TOL.gap_tolerance(r.upper_bound)


def test_value_shift_covers_the_drop_to_the_set():
    """At points off the unit circle by h, along the minimiser's ray: the shift bounds the value drop f(p) - f(p on
    the set) from above (first order), for the plain and the squared constraint alike; round-off only on the set."""
    x, y = sp.variables("x y")
    f = x + y
    u = -np.ones(2) / math.sqrt(2)
    for h in (1e-2, 1e-4, 1e-6):
        p = (1 + h) * u
        drop = abs(float(f(p)) - F_MIN)
        for g in (x ** 2 + y ** 2 - 1, (x ** 2 + y ** 2 - 1) ** 2):
            assert value_shift(f, [g], [], p) >= drop * (1 - 1e-6)
    assert value_shift(f, [x ** 2 + y ** 2 - 1], [], np.array([1.0, 0.0])) <= 1e-13     # (its round-off only)
    # an inequality met with a slack: no shift; violated: a shift of its distance's order
    assert value_shift(f, [], [1 - x ** 2 - y ** 2], 0.5 * u) == 0.0
    assert value_shift(f, [], [1 - x ** 2 - y ** 2], 1.01 * u) >= math.sqrt(2) * 0.01 * (1 - 1e-6)


def test_a_variable_in_no_polynomial_changes_nothing():
    """Review 21a F5: x, y, z = variables("x y z") with z in no polynomial -- a box problem on (x, y) certified with
    two generators was unproven (no box holds z) and minimize_ratios refused its denominator.  Now solved without z:
    the same bounds, certified, every point with 0 in z and the caller's generators in the result."""
    x, y = sp.variables("x y")
    x3, y3, _ = sp.variables("x y z")
    f = lambda a, b: -(a - 0.3) ** 2 - (b - 0.2) ** 2                 # noqa: E731  (min -1.13 at (1, 1))
    box = lambda a, b: [a, 1 - a, b, 1 - b]                            # noqa: E731
    r2 = sp.minimize(f(x, y), ineq=box(x, y), degree=4)
    r3 = sp.minimize(f(x3, y3), ineq=box(x3, y3), degree=4)
    assert r2.optimal and r3.optimal and r3.gens == ("x", "y", "z")
    assert r3.lower_bound == pytest.approx(r2.lower_bound, rel=1e-9) and r3.lower_bound <= -1.13 + 1e-12
    assert all(len(p) == 3 and p[2] == 0.0 for p in r3.minimizers)
    q = sp.minimize_ratios([(x3 ** 2 + 1, x3 + 2)], ineq=[x3, 1 - x3])
    assert q.status == sp.SolveStatus.OPTIMAL and q.denominator_bounds[0] > 1.9


def test_later_degrees_feasible_points_are_not_lost_behind_a_first_infeasible_degree():
    """Review 21a F4: min -(x^2 + y^2 + z^2) on the simplex (min -1 at a vertex): degree 2 has no certificate
    (INFEASIBLE, 'try a larger degree'), degrees 4 and 6 solved and found the vertices; the result was the degree-2
    verdict with no upper bound.  Now the best result keeps the feasible points: upper bound -1, never INFEASIBLE."""
    x, y, z = sp.variables("x y z")
    r = sp.minimize(-(x ** 2 + y ** 2 + z ** 2), eq=[x + y + z - 1], ineq=[x, y, z])
    assert r.status != sp.SolveStatus.INFEASIBLE
    assert r.upper_bound == pytest.approx(-1.0, abs=1e-6)
    assert r.lower_bound is None or r.lower_bound <= -1.0 + 1e-9


def test_a_cusp_met_to_round_off_gives_no_upper_bound_below_the_minimum():
    """Review 21c F2: min x s.t. y^2 = x^3 in variables shifted by 3 (minimum 0 at the cusp): a point at x = -5e-5
    meets the shifted constraint to round-off (1e-15) where its gradient is ~1e-9, and its value -5e-5 was reported
    as the upper bound.  The round-off term of value_shift leaves it out: the upper bound is None or >= 0."""
    import warnings

    u, w = sp.variables("u w")
    x, y = u - 3.0, w - 3.0
    with warnings.catch_warnings(record=True) as seen:              # (and no scipy LinAlgWarning reaches the caller:
        warnings.simplefilter("always")                             # the IPM's singular Newton system is its own)
        r = sp.minimize(x + 0.0 * y, eq=[y ** 2 - x ** 3])
    assert not [m for m in seen if "LinAlgWarning" in type(m.message).__name__ or "Singular" in str(m.message)]
    assert r.upper_bound is None or r.upper_bound >= -TOL.gap_tolerance(0.0)
    assert r.lower_bound is None or r.lower_bound <= 1e-9
