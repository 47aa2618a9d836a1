"""minimize_ratios reports only a proven lower bound (review 25b).

The solver's lambda was reported as the bound: min (u^2 + 1)/(u + 2) on |u| <= 1 written in x = 1e-6 u gave
"optimal" at 0.4721360415 where the exact minimum is 2 sqrt(5) - 4 = 0.4721359550 (8.7e-8 above it; 1.6e-12 at
x = 1e6 u, 1.9e-15 unscaled).  Now the certificates' identity residuals (exact rationals) and PSD defects are
bounded on the constraints' box and subtracted, the variables are balanced by powers of two and every
normalisation is exact.
"""
import dataclasses
from decimal import Decimal, getcontext
from fractions import Fraction

import numpy as np
import pytest

import sospoly as sp
from sospoly import SolveStatus
from sospoly.ratios_proof import proven_ratio_bound

getcontext().prec = 50
EXACT = 2 * Decimal(5).sqrt() - 4                                       # min (u^2 + 1)/(u + 2) on [-1, 1]
(x,) = sp.variables("x")


def _below_exact(value: float) -> bool:
    return Decimal(Fraction(value).numerator) / Decimal(Fraction(value).denominator) <= EXACT


@pytest.mark.parametrize("s", [1e6, 1.0, 1e-6, 3.0e-4, 7.0e5])
def test_rescaled_variable_bound_is_proven_and_certified(s):
    u = s * x
    r = sp.minimize_ratios([(u ** 2 + 1, u + 2)], ineq=[1 - u ** 2])
    assert r.lower_bound is not None and _below_exact(r.lower_bound)
    assert r.optimal and abs(r.lower_bound - float(EXACT)) < 1e-8
    assert r.minimizers and abs(r.minimizers[0][0] * s - (5 ** 0.5 - 2)) < 1e-4


def test_scaled_objective_and_constraints():
    r = sp.minimize_ratios([(1e9 * (x ** 2 + 1), 3.0 * (x + 2))], ineq=[1e-7 * (1 - x ** 2)])
    exact = EXACT * Decimal(1e9) / 3
    lb = Fraction(r.lower_bound)
    assert Decimal(lb.numerator) / Decimal(lb.denominator) <= exact
    assert r.optimal and abs(r.lower_bound - float(exact)) < 1e-8 * float(exact)


def test_a_raised_level_is_not_proven():
    """The proof recomputes the identity from the decision values: a lambda raised by 1e-3 after the solve
    shows up as residual (e_0 = -1e-3 q_0), and the proven bound stays below the exact minimum."""
    r = sp.minimize_ratios([(x ** 2 + 1, x + 2)], ineq=[1 - x ** 2])
    sol, prog_names = r.solution, ["u0"]
    from sospoly.ratios import _build, _normalised
    pairs, eq, ineq, F = _normalised([(x ** 2 + 1, x + 2)], [], [1 - x ** 2])
    prog, names, weights = _build(pairs, eq, ineq, ("x",), r.degree)
    assert names == prog_names
    xs = np.array(sol.x, float)
    xs[prog.block("lambda").slice] += 1e-3
    forged = dataclasses.replace(sol, x=xs)
    q_min = [r.denominator_bounds[0] / 4.0]                            # q / 4: the normalised denominator
    lb, _ = proven_ratio_bound(prog, names, forged, pairs, eq, ineq, q_min, weights)
    assert lb * F <= float(EXACT) and np.isfinite(lb)


def test_an_unbounded_set_gives_no_bound():
    r = sp.minimize_ratios([(x ** 2 + 1, x ** 2 + 2)])
    assert r.status == SolveStatus.UNPROVEN and r.lower_bound is None and not r.optimal
    assert "box" in r.message
