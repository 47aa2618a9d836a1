"""The term-sparsity hierarchy (issue 25): certifies the SumOfSquares.jl term-sparsity tutorial polynomial and the
TSSOS README examples at their known minima with fewer LMI variables than the dense certificate; minima checked
against closed forms or multi-start local optimisation (independent of the SDP)."""
import numpy as np
import pytest
from scipy.optimize import minimize as sp_minimize

import sospoly as sp
from sospoly.certificates.term_hierarchy import parse_term_kind, term_levels

x1, x2, x3 = sp.variables("x1 x2 x3")
# SumOfSquares.jl "Term sparsity" tutorial (Example 3.5 of Wang-Magron-Lasserre, Chordal-TSSOS): minimum 0 at 0
TUTORIAL = (x1**2 - 2 * x1 * x2 + 3 * x2**2 - 2 * x1**2 * x2 + 2 * x1**2 * x2**2 - 2 * x2 * x3 + 6 * x3**2
            + 18 * x2**2 * x3 - 54 * x2 * x3**2 + 142 * x2**2 * x3**2)
# TSSOS README: unconstrained, and with 1 - x1^2 - 2 x2^2 >= 0, x2^2 + x3^2 - 1 = 0
README_F = 1 + x1**4 + x2**4 + x3**4 + x1 * x2 * x3 + x2
README_G = 1 - x1**2 - 2 * x2**2
README_H = x2**2 + x3**2 - 1


def _multistart(f, eq=(), ineq=(), starts=60, seed=0):
    """min f by SLSQP from random starts (an upper bound of the minimum, independent of any SDP)."""
    rng = np.random.default_rng(seed)
    cons = [{"type": "eq", "fun": g} for g in eq] + [{"type": "ineq", "fun": h} for h in ineq]
    best = np.inf
    for x0 in rng.uniform(-1.5, 1.5, size=(starts, 3)):
        r = sp_minimize(f, x0, constraints=cons, method="SLSQP", options={"ftol": 1e-14, "maxiter": 500})
        if r.success and all(abs(g(r.x)) < 1e-8 for g in eq) and all(h(r.x) > -1e-8 for h in ineq):
            best = min(best, float(r.fun))
    return best


def test_tutorial_polynomial_certifies_zero_cheaper_than_dense():
    term = sp.minimize(TUTORIAL, sparsity="term", degree=4)
    dense = sp.minimize(TUTORIAL, sparsity="none", degree=4)
    assert TUTORIAL([0.0, 0.0, 0.0]) == 0.0
    assert term.optimal and abs(term.lower_bound) < 1e-6 and term.lower_bound <= 1e-9
    assert term.sparsity.startswith("term") and term.n_lmivar < dense.n_lmivar
    # the chordal completion alone stops below the minimum, as SumOfSquares.jl's ChordalCompletion does
    for kind in ("term", "term:chordal:3"):
        lb = sp.solve_psatz(sp.build_psatz(TUTORIAL, degree=4, multiplier="putinar", sparsity=kind))
        assert lb.lower_bound < -1e-3, kind


def test_auto_picks_a_4_variable_certificate_on_the_tutorial_polynomial():
    """The dense certificate has 21 LMI variables; the Newton basis and the block term level have 4."""
    res = sp.minimize(TUTORIAL)
    assert res.optimal and abs(res.lower_bound) < 1e-6
    assert res.sparsity in ("newton", "term:block:1") and res.n_lmivar == 4


@pytest.mark.parametrize("constrained", [False, True], ids=["unconstrained", "constrained"])
def test_auto_tries_the_cheap_term_level_first(constrained):
    eq, ineq = ([README_H], [README_G]) if constrained else ((), ())
    auto = sp.minimize(README_F, eq, ineq, degree=4)
    dense = sp.minimize(README_F, eq, ineq, degree=4, sparsity="none")
    assert auto.optimal and auto.sparsity.startswith("term") and auto.n_lmivar < dense.n_lmivar
    assert abs(auto.lower_bound - dense.lower_bound) < 1e-6


@pytest.mark.parametrize("constrained", [False, True], ids=["unconstrained", "constrained"])
def test_tssos_readme_examples(constrained):
    eq, ineq = ([README_H], [README_G]) if constrained else ((), ())
    term = sp.minimize(README_F, eq, ineq, sparsity="term", degree=4)
    dense = sp.minimize(README_F, eq, ineq, sparsity="none", degree=4)
    ref = _multistart(lambda v: README_F(v), [lambda v: README_H(v)] if constrained else [],
                      [lambda v: README_G(v)] if constrained else [])
    assert dense.optimal and abs(dense.upper_bound - ref) < 1e-6            # the dense bound is the minimum
    assert term.optimal and term.n_lmivar < dense.n_lmivar
    assert abs(term.lower_bound - ref) < 1e-6 and term.lower_bound <= ref + 1e-9
    assert abs(term.lower_bound - dense.lower_bound) < 1e-6                  # no weaker than dense


def test_levels_end_with_the_block_closure_and_kinds_parse():
    f_support = TUTORIAL.exponents()
    levels = term_levels(f_support, [], [], 4)
    assert any(k.startswith("term:block") for k in levels)
    assert parse_term_kind("term") == ("chordal", 1)
    assert parse_term_kind("term:block:2") == ("block", 2)
    assert parse_term_kind("newton") is None
    for bad in ("term:square:1", "term:block:0", "term:block"):
        with pytest.raises(ValueError):
            parse_term_kind(bad)


def test_every_level_is_a_valid_bound_on_a_sign_symmetric_quartic():
    """x^4 + y^4 + z^4 - 4xyz + 1: min 0 at (1, 1, 1) and its sign orbit (AM-GM); every level <= 0, the last = 0."""
    x, y, z = sp.variables("x y z")
    f = x**4 + y**4 + z**4 - 4 * x * y * z + 1
    for kind in term_levels(f.exponents(), [], [], 4):
        lb = sp.solve_psatz(sp.build_psatz(f, degree=4, multiplier="putinar", sparsity=kind))
        assert lb.lower_bound is not None and lb.lower_bound <= 1e-7, kind
    res = sp.minimize(f, sparsity="term", degree=4)
    assert res.optimal and abs(res.lower_bound) < 1e-6
    assert np.allclose(np.abs(res.minimizers[0]), 1.0, atol=1e-4)
