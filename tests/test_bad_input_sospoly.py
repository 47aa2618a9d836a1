"""Bad input to sospoly: clear Python errors for malformed data, a status (never a solver
exception) for well-formed programs without a bound."""
import math

import numpy as np
import pytest

import sospoly as sp
from sospoly import Polynomial, SOSProgram, SolveStatus

x, y = sp.variables("x y")


@pytest.mark.parametrize("bad", ["x**2 + 1", [1.0, 2.0], None, {"x": 1}, True])
def test_non_polynomial_objectives_raise_type_error(bad):
    with pytest.raises(TypeError):
        sp.minimize(bad)
    with pytest.raises(TypeError):
        sp.minimize(x**2, eq=[bad])
    with pytest.raises(TypeError):
        sp.minimize(x**2, ineq=[bad])
    with pytest.raises(TypeError):
        sp.is_sos(bad)


def test_arithmetic_with_non_numbers_raises_type_error():
    with pytest.raises(TypeError):
        x + "1"
    with pytest.raises(TypeError):
        x * [1, 2]
    with pytest.raises(TypeError):
        sp.as_polynomial("x")
    with pytest.raises(TypeError):
        sp.variables(["x"], n=2)


@pytest.mark.parametrize("degree", [3, 5])
def test_odd_degree_raises_value_error(degree):
    with pytest.raises(ValueError):
        sp.minimize(x**2 + y**2, degree=degree)


def test_too_small_degree_raises_value_error():
    with pytest.raises(ValueError):
        sp.minimize(x**4 + y**2, degree=2)            # deg f = 4 > 2
    with pytest.raises(ValueError):
        sp.minimize(x**2, ineq=[1 - x**4], degree=2)  # delta_min = 4
    with pytest.raises(ValueError):
        sp.minimize(x**2, degree=0)
    with pytest.raises(TypeError):
        sp.minimize(x**2, degree=4.0)
    with pytest.raises(ValueError):
        sp.tau(2, 3)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, np.float64("nan")])
def test_non_finite_coefficients_raise_value_error(bad):
    with pytest.raises(ValueError):
        Polynomial(("x",), {(1,): bad})
    with pytest.raises(ValueError):
        x * bad
    with pytest.raises(ValueError):
        x + bad
    with pytest.raises(ValueError):
        Polynomial.constant(bad, ("x",))
    with pytest.raises(ValueError):
        sp.minimize(x**2 + bad * y)


def test_malformed_polynomials_raise_value_error():
    with pytest.raises(ValueError):
        Polynomial(("x", "x"), {})
    with pytest.raises(ValueError):
        Polynomial(("x",), {(1, 0): 1.0})
    with pytest.raises(ValueError):
        Polynomial(("x",), {(-1,): 1.0})
    with pytest.raises(ValueError):
        sp.variables("")
    with pytest.raises(ValueError):
        x.subs({"w": 1.0})
    with pytest.raises(ZeroDivisionError):
        x / 0


def test_bad_multipliers_and_backends():
    with pytest.raises(ValueError):
        sp.minimize(x**2 + y**2, multiplier="banana")
    with pytest.raises(ValueError):
        sp.minimize(x**2 + y**2, multiplier=-1.0)
    with pytest.raises(ValueError):
        sp.minimize(x**2 + y**2, multiplier=0.0)
    with pytest.raises(ValueError):
        sp.minimize(x**2 + y**2, degree=4, multiplier=-(x**2) - 1)      # not SOS
    with pytest.raises(ValueError):
        sp.minimize(x**2 + y**2, degree=2, multiplier=1 + x**2)          # deg q + deg f > degree
    with pytest.raises(ValueError):
        sp.minimize(x**2 + y**2, backend="nosuchsolver")
    with pytest.raises(TypeError):
        sp.minimize(x**2 + y**2, backend=42)


def test_bad_programs():
    prog = SOSProgram(("x", "y"))
    c = prog.scalar("c")
    with pytest.raises(ValueError):
        prog.scalar("c")                              # duplicate block name
    with pytest.raises(ValueError):
        prog.add_sos(x**3 - c, degree=2)              # degree too small
    with pytest.raises(ValueError):
        prog.add_sos(x**2 - c, degree=3)              # odd degree
    with pytest.raises(ValueError):
        prog.maximize(c * x)                          # objective must be scalar
    with pytest.raises(TypeError):
        (c * x) * c                                   # bilinear in the decision variables
    assert type(c * c).__name__ == "QuadExpr"        # scalar x scalar: a quadratic form (issue 25)
    with pytest.raises(ValueError):
        prog.maximize(c * c)                          # a maximised quadratic must be concave
    with pytest.raises(ValueError):
        prog.add_inequality(c * x)                    # inequalities are scalar
    with pytest.raises(ValueError):
        prog.add_lmi([[c, 1.0], [2.0, c]])            # not symmetric
    with pytest.raises(ValueError):
        prog.add_lmi([[c, 1.0]])                      # not square
    with pytest.raises(ValueError):
        SOSProgram(())
    with pytest.raises(ValueError):
        sp.GramForm("diagonal")


def test_empty_constraint_set_gives_status_not_exception():
    """min x s.t. x^2 + 1 = 0: the feasible set is empty, so every c is a certified lower bound."""
    (x1,) = sp.variables("x")
    res = sp.minimize(x1, eq=[x1**2 + 1])
    assert res.status == SolveStatus.UNBOUNDED
    assert res.lower_bound == math.inf
    assert res.upper_bound is None and res.minimizers == () and not res.optimal


@pytest.mark.parametrize("f_degree", [(lambda v: v, 2), (lambda v: v**3 + v**2, 4), (lambda v: v, 4)])
def test_unbounded_objective_gives_infeasible_status(f_degree):
    """min x (or x^3 + x^2) with no constraints: unbounded below, no certificate at any degree.

    The SDP is only weakly infeasible, which interior-point solvers cannot detect (they report
    numerical errors); sospoly decides it exactly (odd degree and no constraints)."""
    make, degree = f_degree
    (x1,) = sp.variables("x")
    for mult in ("fixed", "free"):
        res = sp.minimize(make(x1), degree=degree, multiplier=mult)
        assert res.status == SolveStatus.INFEASIBLE
        assert res.lower_bound is None and not res.optimal and res.upper_bound is None
        assert "unbounded" in res.message


def test_even_unbounded_objective_gives_infeasible_status():
    res = sp.minimize(x**2 - y**2)                    # strongly infeasible SDP: detected by the solver
    assert res.status == SolveStatus.INFEASIBLE and res.lower_bound is None and not res.optimal
    pytest.importorskip("cvxpy")
    res = sp.minimize(x**2 - y**2, backend="cvxpy")
    assert res.status == SolveStatus.INFEASIBLE and res.lower_bound is None


def test_unsupported_degree_is_rejected_at_once():
    # degree 1e30 used to expand (1 + ||v||^2)^(delta/2 - 1) without end (a problem file with "delta": 1e30
    # hung the CLI); the Gram side C(n + delta/2, n) is checked against MAX_GRAM_SIDE first
    from sospoly.certificates.psatz import MAX_GRAM_SIDE, check_degree_supported

    with pytest.raises(ValueError, match=r"degree ~1e30 is not supported: .* in 2 variables .* side ~1e59"):
        sp.build_psatz(x**2 + y**2, degree=10**30)
    # 2 variables: C(2 + k, 2) <= 5000 up to k = 98 (C(100, 2) = 4950), so degree 196 passes, 198 (5050) does not
    check_degree_supported(2, 196)
    with pytest.raises(ValueError, match=f"side 5050 \\(limit {MAX_GRAM_SIDE}\\)"):
        check_degree_supported(2, 198)
    assert sp.build_psatz(x**2 + y**2, degree=4) is not None


def test_triangulate_names_the_unsupported_degree():
    import tritools

    cams, regions = tritools.paper_example(4)
    with pytest.raises(ValueError, match=r"^delta = 10+ is far beyond"):
        tritools.triangulate(cams, regions, "corollary1", delta=10**30)
    # a degree whose program cannot fit is refused by the budget before anything is built: a status, not a crash
    res = tritools.triangulate(cams, regions, "corollary1", delta=200)
    assert res.status == tritools.Status.BUDGET_EXCEEDED and "side" in res.message


def test_review21a_bad_arguments_are_named():
    """Review 21a F7: a radius that is not a number, an array radius, max_degree NaN, one polynomial where a
    sequence of constraints is expected, and a variable name that is not an identifier: a TypeError/ValueError
    naming the argument (before: numpy's 'truth value is ambiguous', 'Polynomial object is not iterable', ...)."""
    import numpy as np

    import sospoly as sp

    x, y = sp.variables("x y")
    for kw, exc, name in ((dict(radius="2"), TypeError, "radius"), (dict(radius=np.array([1.0, 2.0])), TypeError,
                                                                     "radius"),
                          (dict(radius=True), TypeError, "radius"), (dict(radius=-1.0), ValueError, "radius"),
                          (dict(max_degree=float("nan")), ValueError, "max_degree"),
                          (dict(eq=x ** 2 + y ** 2 - 1), TypeError, "eq"), (dict(ineq=3.0), TypeError, "ineq")):
        with pytest.raises(exc, match=name):
            sp.minimize(x + y, **kw)
    with pytest.raises(ValueError, match="identifiers"):
        sp.variables("1x")
    with pytest.raises(ValueError, match="identifiers"):
        sp.variables(["x", "y z"])
    assert sp.minimize(x + y, eq=[x ** 2 + y ** 2 - 1], radius=np.float64(2.0)).optimal     # numpy scalars are fine
