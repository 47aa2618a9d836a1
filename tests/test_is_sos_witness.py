"""is_sos refutes a polynomial that is negative somewhere beyond its coefficients' round-off (review 25b F2).

A Gram matrix within the PSD margin (1e-7 relative) was admitted for p - eps with a double zero, which is negative
there: (x^2 - 1)^2 - 1e-8, 1e8 ((x^2 - 1)^2 - 1e-9) (-0.1 at x = 1), Rosenbrock - 1e-8 were "SOS".  Now a point
where p < 0 exactly (beyond the round-off of its coefficients) is searched from the Gram matrix's kernel and a few
local minimisations, and one found makes the answer INFEASIBLE with the point.
"""
from fractions import Fraction

import numpy as np
import pytest

import sospoly as sp
from sospoly import SolveStatus
from sospoly.sos_check import exact_value

x, y = sp.variables("x y")


@pytest.mark.parametrize("p", [(x ** 2 - 1) ** 2 - 1e-8, (x ** 2 - 1) ** 2 - 1e-10, 1e8 * ((x ** 2 - 1) ** 2 - 1e-9),
                               (1 - x) ** 2 + 100 * (y - x ** 2) ** 2 - 1e-8,
                               1e-6 * ((3.0 * x - 1) ** 2 * (y + 2) ** 2 - 1e-9)])
def test_negative_somewhere_is_not_sos(p):
    r = sp.is_sos(p)
    assert not r.is_sos and r.status == SolveStatus.INFEASIBLE
    v = eval(r.message.split("v = ")[1].split(" (exactly)")[0])       # the point in the message, in caller units
    assert exact_value(p, v) < 0


@pytest.mark.parametrize("scale", [1e-6, 1.0, 3.7e5])
def test_sums_of_squares_with_zeros_stay_sos(scale):
    for p in [(x ** 2 - 1) ** 2, (1 - x) ** 2 + 100 * (y - x ** 2) ** 2, (x * y - 1) ** 2 + (x - y) ** 2]:
        r = sp.is_sos(scale * p)
        assert r.is_sos and r.status == SolveStatus.FEASIBLE


def test_exact_value_is_exact():
    p = (x ** 2 - 1) ** 2 - 2.0 ** -27                                # dyadic: every coefficient exact
    assert exact_value(p, [1.0]) == -Fraction(1, 2 ** 27)
    assert exact_value(p, np.array([2.0])) == 9 - Fraction(1, 2 ** 27)
