"""Review 26c (on this wave's fixes): the free multiplier's labels, and a fixed-q solve whose objective the optimality
rule drops.  References: closed forms (a linear objective on a disc, a quadratic on a line)."""
import sospoly as sp
from sospoly import SolveStatus

x, y = sp.variables("x y")


def test_free_q_optimal_only_where_an_infeasible_level_closes_the_bracket():
    """min 1e8 x on the disc of radius 1e-6 (-100): the bisection's upper end was a rejected answer (a Gram defect),
    read as 'no certificate there', and -282.5 was labelled OPTIMAL."""
    truth = -100.0
    lb = sp.solve_psatz(sp.build_psatz(1e8 * x + 0 * y, (), [1e-12 - x ** 2 - y ** 2], 2, "free"))
    assert lb.lower_bound is None or lb.lower_bound <= truth
    tol = sp.DEFAULT_TOLERANCES.gap_tolerance_one(truth, 1e8)
    assert lb.status != SolveStatus.OPTIMAL or lb.lower_bound >= truth - tol, (lb.status, lb.lower_bound)


def test_free_q_search_that_certifies_every_level_is_not_an_empty_set():
    """min 1e8 (x^2 + y^2) s.t. x + y = 1000 (5e13, feasible): the upward search ran out of steps and reported
    UNBOUNDED, 'the constraint set is empty'."""
    lb = sp.solve_psatz(sp.build_psatz(1e8 * (x ** 2 + y ** 2), [x + y - 1000], (), 2, "free"))
    assert lb.status != SolveStatus.UNBOUNDED
    assert lb.lower_bound is None or lb.lower_bound <= 5e13


def test_a_dropped_objective_is_inaccurate_without_a_bound():
    """A badly scaled quartic whose fixed-q answer fails the optimality rule (the primal cone defect moves its
    objective by 3e4 where 1e4 is allowed): INACCURATE, and an inaccurate iterate is never a bound (the contract of
    tests/test_strategy_fake.py); before the rule it was OPTIMAL, proven below the minimum -142447803.5."""
    t, = sp.variables("t")
    c = [float.fromhex(h) for h in ('0x1.296c3af9fcd38p+16', '0x1.a8a1dfad61598p+13', '-0x1.fd6dceb9a474cp+7',
                                    '0x1.b80101f79a48ap-1', '0x1.38e1217b02badp-10')]
    f = sum(ci * t ** i for i, ci in enumerate(c))
    lb = sp.solve_psatz(sp.build_psatz(f, degree=4, multiplier="putinar"))
    assert lb.lower_bound is None or lb.lower_bound <= -142447803.0
    assert lb.status != SolveStatus.OPTIMAL or lb.lower_bound is not None
