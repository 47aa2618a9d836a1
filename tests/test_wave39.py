"""Wave 39: the review leftovers of wave 38 (sospoly messages) and this wave's reviews."""
from __future__ import annotations

import numpy as np
import pytest

import sospoly as sp


def test_ratios_on_an_empty_set_report_the_empty_set_not_a_denominator():
    """Review 38a L6: minimize_ratios on {x^2 + y^2 + 1 = 0} blamed the denominator ("not certified positive,
    certified lower bound -inf"); minimize proves the set empty, and so does minimize_ratios now: lower bound +inf
    (every sum of ratios is bounded below by +inf on the empty set), minimize's status and message."""
    x, y = sp.variables("x y")
    eq = [x**2 + y**2 + 1]
    r = sp.minimize_ratios([(x, y + 2)], eq=eq)
    m = sp.minimize(y + 2, eq=eq)
    assert m.lower_bound == np.inf
    assert r.lower_bound == np.inf and r.upper_bound is None and not r.optimal
    assert r.status == m.status
    assert "empty" in r.message and "not certified positive" not in r.message


def test_ratios_on_a_nonempty_set_still_check_denominators():
    """The empty-set exit does not swallow a denominator that changes sign on a non-empty set."""
    x, = sp.variables("x")
    r = sp.minimize_ratios([(1 + 0 * x, x)], ineq=[1 - x**2])
    assert r.status == sp.SolveStatus.INFEASIBLE and r.lower_bound is None
    assert "terms[0].q is not certified positive" in r.message


@pytest.mark.parametrize("gens, error, words", [
    ((1, 2), TypeError, "gens[0] must be a variable name"),
    (("x", None), TypeError, "gens[1] must be a variable name"),
    (("x", "x"), ValueError, "'x' twice"),
    (3, TypeError, "gens must be a sequence"),
])
def test_gens_that_are_not_distinct_names_are_named(gens, error, words):
    """Review 38a L7: minimize(x**2, gens=(1, 2)) said "variables ['x'] are not among (1, 2)"; the entry that is
    not a variable name (or is repeated) is named, for minimize and for with_gens itself."""
    x, = sp.variables("x")
    with pytest.raises(error) as e:
        sp.minimize(x**2, gens=gens)
    assert words in str(e.value)
    with pytest.raises(error):
        x.with_gens(gens)


def test_gens_in_another_order_still_work():
    x, y = sp.variables("x y")
    p = (x - 1) ** 2 + (y + 2) ** 2
    q = p.with_gens(("y", "x", "z"))
    assert q.gens == ("y", "x", "z") and q.coefficient((2, 0, 0)) == 1.0
    r = sp.minimize(p, gens=["y", "x"])
    assert r.optimal and abs(r.lower_bound) < 1e-6
