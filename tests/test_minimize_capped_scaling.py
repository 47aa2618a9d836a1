"""No certificate where the variables' balancing is capped at 2^+-200 (review 25b F4): min (s x)^2 - s x at s = 1e100
was "optimal" at x = 0 (f = 0, the minimum -1/4), and min s x on the disc (s x)^2 + (s y)^2 <= 1 at s = 1e70 at a
point 14558 outside it: the tolerances acted at scales 5.9e79 and 8.6e9."""
import pytest

import sospoly as sp
from sospoly.scaling import balancing

x, y = sp.variables("x y")


@pytest.mark.parametrize("s", [1e65, 1e100])
def test_unbalanced_quadratic_not_certified(s):
    f = (s * x) ** 2 - s * x
    assert balancing([f], f.nvars).capped
    r = sp.minimize(f)
    assert not r.optimal and "2^+-200" in r.message
    assert r.lower_bound is None or r.lower_bound <= -0.25


def test_unbalanced_disc_not_certified():
    s = 1e70
    r = sp.minimize(s * x, ineq=[1 - (s * x) ** 2 - (s * y) ** 2])
    assert not r.optimal and (r.lower_bound is None or r.lower_bound <= -1.0)


def test_balanced_within_the_cap_still_certified():
    s = 1e50
    f = (s * x) ** 2 - s * x
    assert not balancing([f], f.nvars).capped
    r = sp.minimize(f)
    assert r.optimal and abs(r.upper_bound + 0.25) < 1e-12
