"""minimize beyond recentre.MAX_TERMS: exact values always, no certificate decided at the origin's scale when the
minimiser is away from it (review 25b F3).

f(v) = sum_i (w_i^4 - 3 w_i^2) + (sum_i w_i)^4 with w = v - 100 in 10 variables (10626 terms once expanded about
the minimiser; integer coefficients, so the float data are exact; minimum -9n/4 = -22.5): the result was "optimal"
with a gap of 5644 decided at the origin's scale 3.5e13, and upper_bound a float value below the true minimum.
"""
from fractions import Fraction

import pytest

import sospoly as sp
import sospoly.recentre as recentre
from sospoly.recentre import MAX_TERMS, _expanded_terms


def _exact(p, pt):
    tot = Fraction(0)
    for e, c in p.terms.items():
        t = Fraction(c)
        for v, d in zip(pt, e):
            t *= Fraction(float(v)) ** d
        tot += t
    return tot


def _quartic(n):
    V = sp.variables(" ".join(f"v{i}" for i in range(n)))
    W = [v - 100.0 for v in V]
    return sum(w ** 4 - 3 * w ** 2 for w in W) + sum(W) ** 4


@pytest.mark.parametrize("cap", [None, 1000])
def test_translated_quartic_beyond_max_terms(cap, monkeypatch):
    """Decided at the minimiser's scale (10626 terms, below SCALE_MAX_TERMS), or -- the cap lowered below them --
    not certified."""
    f = _quartic(10)
    assert _expanded_terms(f) > MAX_TERMS
    if cap is not None:
        monkeypatch.setattr(recentre, "SCALE_MAX_TERMS", cap)
    r = sp.minimize(f)
    assert r.lower_bound is not None and r.lower_bound <= -22.5
    assert r.upper_bound is not None and Fraction(r.upper_bound) >= _exact(f, r.minimizers[0]) >= Fraction(-45, 2)
    gap = r.upper_bound - r.lower_bound
    assert not r.optimal or gap <= sp.DEFAULT_TOLERANCES.gap_tolerance(r.upper_bound, 32.0)
    assert not r.optimal
    assert cap is None or "minimiser's scale" in r.message
