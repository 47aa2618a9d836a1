"""Sum-of-ratios objectives (issue 25): certified bounds of sum_i p_i/q_i against closed forms and a dense grid."""
import math

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

import sospoly as sp
from sospoly import SolveStatus

x, y = sp.variables("x y")


def test_separable_ratios_closed_form():
    """(x^2 + 1)/(x + 2) on [-1, 1]: min 2 sqrt5 - 4 at x = sqrt5 - 2; (y^2 + 2)/(y^2 + 1) = 1 + 1/(1 + y^2): 3/2
    at y = +-1."""
    res = sp.minimize_ratios([(x**2 + 1, x + 2), (y**2 + 2, y**2 + 1)], ineq=[1 - x**2, 1 - y**2])
    ref = 2 * math.sqrt(5) - 4 + 1.5
    assert res.status == SolveStatus.OPTIMAL and res.optimal
    assert abs(res.lower_bound - ref) < 1e-6 and res.lower_bound <= ref + 1e-9
    assert res.minimizers and abs(res.minimizers[0][0] - (math.sqrt(5) - 2)) < 1e-4
    assert abs(abs(res.minimizers[0][1]) - 1) < 1e-6
    assert all(b > 0 for b in res.denominator_bounds)


def test_coupled_ratios_against_a_dense_grid():
    """f(t) = (t^2 + 0.5)/(1 + t^2) + (t - 1)^2/(2 + t) + t/(t^2 + 3) on [-1, 2]: reference from a grid + refine."""
    (t,) = sp.variables("t")
    terms = [(t**2 + 0.5, 1 + t**2), ((t - 1) ** 2, 2 + t), (t, t**2 + 3)]
    res = sp.minimize_ratios(terms, ineq=[(t + 1) * (2 - t)], degree=4)

    def f(v):
        return (v * v + 0.5) / (1 + v * v) + (v - 1) ** 2 / (2 + v) + v / (v * v + 3)
    grid = np.linspace(-1, 2, 300001)
    k = int(np.argmin(f(grid)))
    ref = minimize_scalar(f, bounds=(grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]), method="bounded",
                          options={"xatol": 1e-12}).fun
    assert res.lower_bound is not None and res.lower_bound <= ref + 1e-7
    assert res.optimal and abs(res.lower_bound - ref) < 1e-5


def test_denominator_not_positive_is_refused_with_a_status():
    res = sp.minimize_ratios([(x**2 + 1, x)], ineq=[1 - x**2])        # q = x vanishes on [-1, 1]
    assert res.status == SolveStatus.INFEASIBLE and res.lower_bound is None
    assert "terms[0].q" in res.message


@pytest.mark.parametrize("terms,err", [([], ValueError), ([(x, 1.0, 2.0)], TypeError), ([("x", x)], TypeError),
                                       ([(x, 0 * x)], ValueError)])
def test_bad_terms(terms, err):
    with pytest.raises(err, match="terms"):
        sp.minimize_ratios(terms)
