"""Review 25b F7 (low): the zero objective, rigorous_psatz_bound's inputs, minimize_ratios' degree type."""
import math

import pytest

import sospoly as sp

x, y = sp.variables("x y")


def test_zero_objective_is_not_unbounded():
    r = sp.minimize(0 * x)
    assert r.status != sp.SolveStatus.INFEASIBLE and "unbounded" not in r.message
    assert r.lower_bound is not None and -1e-6 <= r.lower_bound <= 0.0


@pytest.mark.parametrize("c,radius,err", [(0.0, -1.0, ValueError), (0.0, math.nan, ValueError),
                                          (0.0, [1.0, -2.0], ValueError), ("0", 1.0, TypeError)])
def test_rigorous_bound_inputs(c, radius, err):
    ps = sp.build_psatz(x ** 2 + 1, degree=2)
    sol = sp.solve_psatz(ps).solution
    with pytest.raises(err, match="rigorous_psatz_bound"):
        sp.rigorous_psatz_bound(ps, sol, c, radius)
    assert sp.rigorous_psatz_bound(ps, sol, 0.5, 2.0).lower_bound <= 1.0


@pytest.mark.parametrize("c,radius", [(0.9, math.inf), (math.nan, 1.0)])
def test_rigorous_bound_nothing_provable(c, radius):
    """An infinite radius or a non-finite level proves nothing: -inf, never NaN or a finite bound."""
    ps = sp.build_psatz(x ** 2 + 1, degree=2)
    sol = sp.solve_psatz(ps).solution
    assert sp.rigorous_psatz_bound(ps, sol, c, radius).lower_bound == -math.inf


def test_rigorous_bound_needs_a_solution():
    ps = sp.build_psatz(x ** 2 + 1, degree=2)
    with pytest.raises(TypeError, match="ProgramSolution"):
        sp.rigorous_psatz_bound(ps, None, 0.0, 1.0)


def test_ratios_degree_type():
    with pytest.raises(TypeError, match="degree"):
        sp.minimize_ratios([(x ** 2, 1 + x ** 2)], ineq=[1 - x ** 2], degree=True)


def test_robinson_status_agrees_with_its_numbers():
    """Review 25b F5: status inconsistent_bounds with lower <= upper after the exact re-valuation, the message citing
    a float value -1.96e56 of a polynomial that is >= 0 everywhere."""
    z = sp.variables("x y")
    X, Y = z
    robinson = (X ** 6 + Y ** 6 + 1 - (X ** 4 * Y ** 2 + X ** 2 * Y ** 4 + X ** 4 + X ** 2 + Y ** 4 + Y ** 2)
                + 3 * X ** 2 * Y ** 2)
    r = sp.minimize(robinson, degree=6)
    if r.lower_bound is not None and r.upper_bound is not None and r.lower_bound <= r.upper_bound:
        assert r.status != sp.SolveStatus.INCONSISTENT and "numerical failure" not in r.message
    assert r.lower_bound is None or r.lower_bound <= 0.0
    assert r.upper_bound is None or r.upper_bound >= 0.0
