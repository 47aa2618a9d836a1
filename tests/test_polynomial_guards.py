"""Issue 24, defect 11: sospoly algebra has size guards (O(1) checks).

``variables(8000)`` took 23 s and 1.1 GB (a Python loop per exponent entry); ``p**10**6`` ran
unchecked; ``x + 10**400`` raised OverflowError instead of ValueError/TypeError."""
from __future__ import annotations

import math
import time

import pytest

from sospoly import Polynomial, variables
from sospoly.algebra import polynomial as poly_mod


def test_many_variables_are_created_quickly():
    t0 = time.perf_counter()
    v = variables("v", n=8000)
    elapsed = time.perf_counter() - t0
    assert elapsed < 8.0, elapsed                           # 23 s before (about 1 s now on a loaded machine)
    assert len(v) == 8000 and v[0].gens == v[-1].gens and v[0].gens[-1] == "v8000"
    assert v[4321].terms == {tuple(int(j == 4321) for j in range(8000)): 1.0}
    with pytest.raises(ValueError, match="MAX_VARIABLES"):
        variables("w", n=poly_mod.MAX_VARIABLES + 1)
    with pytest.raises(ValueError, match="duplicate variable names"):
        variables(["a", "b", "a"])


def test_huge_powers_are_refused_by_a_size_estimate():
    x, y = variables("x y")
    t0 = time.perf_counter()
    with pytest.raises(ValueError, match=r"p\*\*1000000 with 2 terms .*MAX_TERM_PRODUCTS"):
        (x + y) ** 10 ** 6
    assert time.perf_counter() - t0 < 0.1                   # refused before any work
    assert (x ** 10 ** 6).terms == {(10 ** 6, 0): 1.0}      # a monomial stays one term
    with pytest.raises(ValueError, match="overflowed"):
        (3 * x) ** 10 ** 6
    p = (x + 2 * y + 1) ** 12                               # ordinary powers are exact: the binomial theorem
    assert len(p.terms) == math.comb(14, 2) and p.coefficient((5, 4)) == math.factorial(12) / (
        math.factorial(5) * math.factorial(4) * math.factorial(3)) * 2 ** 4


def test_products_beyond_the_limit_are_refused(monkeypatch):
    x, y = variables("x y")
    monkeypatch.setattr(poly_mod, "MAX_TERM_PRODUCTS", 100)
    big = sum((x ** k * y ** (20 - k) for k in range(21)), Polynomial.constant(0.0, ("x", "y")))
    with pytest.raises(ValueError, match="441 term pairs"):
        big * big


@pytest.mark.parametrize("op", [lambda x: x + 10 ** 400, lambda x: 10 ** 400 - x, lambda x: x * 10 ** 400,
                                lambda x: Polynomial.constant(-10 ** 400, ("x",))])
def test_integers_beyond_the_float_range_are_value_errors(op):
    x, = variables("x")
    with pytest.raises(ValueError, match="integer of about 401 digits"):
        op(x)
