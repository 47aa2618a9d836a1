"""SumOfSquares.jl tutorials written with sospoly (issue 25): each published value is checked to 1e-6, with a
closed form or an independent local search beside it."""
import numpy as np
from scipy.optimize import minimize as sp_minimize

import sospoly as sp
from sospoly import SolveStatus


def test_polynomial_optimization_tutorial():
    """min x^3 - x^2 + 2xy - y^2 + y^3 on x, y >= 0, x + y >= 1 (Lasserre 2009, Ex. 2.2): 0 at (1, 0) and (0, 1).
    The interior-point solution's moment matrix is of maximal rank (5 of 6: not flat), so it is not the two
    atoms' matrix and ``measure()`` says so by returning nothing; the minimisers come from the Gram kernel."""
    x, y = sp.variables("x y")
    p = x**3 - x**2 + 2 * x * y - y**2 + y**3
    # the set is unbounded: minimize proves its bound on a ball holding a minimiser (docs/certificates.md).
    # On the set x^3 + y^3 >= (x+y)^3/4 and -x^2 + 2xy - y^2 >= -(x+y)^2, so p > 0 once x + y > 4: every
    # minimiser (p* = 0) has norm <= 4.
    res = sp.minimize(p, ineq=[x, y, x + y - 1], degree=4, radius=4.0)
    assert res.optimal and abs(res.lower_bound) < 1e-6
    pts = sorted(tuple(np.round(m, 4)) for m in res.minimizers)
    assert pts == [(0.0, 1.0), (1.0, 0.0)]
    (mm,) = res.moment_matrices
    assert mm.monomials() == ("1", "x", "y", "x^2", "x*y", "y^2")
    # a mixture of the two atoms: L(x) = w, L(y) = 1 - w, L(x^2) = L(x), L(xy) = 0 (w = 1/2 by symmetry only where
    # the interior-point iterates stay symmetric: 0.507 with another BLAS kernel)
    Lx, Ly = mm.moment((1, 0)), mm.moment((0, 1))
    assert abs(Lx + Ly - 1) < 1e-3 and 0.05 < Lx < 0.95
    assert abs(mm.moment((2, 0)) - Lx) < 1e-3 and abs(mm.moment((1, 1))) < 1e-3
    assert not mm.is_flat() and mm.measure() == []


def test_extracting_minimizers_tutorial():
    """Laurent (2009) Ex. 6.23: min -x1 - x2 on a set cut by two quartics and a box; the optimum is about -5.5080
    at (2.3295, 3.1785); the reference here is an independent multi-start local search."""
    x1, x2 = sp.variables("x1 x2")
    ineq = [x1, 3 - x1, x2, 4 - x2, 2 * x1**4 - 8 * x1**3 + 8 * x1**2 + 2 - x2,
            4 * x1**4 - 32 * x1**3 + 88 * x1**2 - 96 * x1 + 36 - x2]
    res = sp.minimize(-x1 - x2, ineq=ineq, degree=8)
    cons = [{"type": "ineq", "fun": (lambda v, h=h: h(v))} for h in ineq]
    best = min(r.fun for r in (sp_minimize(lambda v: -v[0] - v[1], x0, constraints=cons, method="SLSQP")
                               for x0 in np.random.default_rng(0).uniform([0, 0], [3, 4], size=(40, 2))) if r.success)
    # the proven lower bound carries the floating-point margin of the certificate (a few 1e-6 here)
    assert res.optimal and best - 1e-5 < res.lower_bound <= best + 1e-9
    assert abs(best + 5.5080) < 1e-3
    assert np.allclose(res.minimizers[0], [2.3295, 3.1785], atol=1e-3)


def test_getting_started_sosdemo1_gram_matrix():
    """2x^4 + 2x^3 y - x^2 y^2 + 5y^4 is SOS (SOSTOOLS sosdemo1); its decomposition rebuilds it."""
    x, y = sp.variables("x y")
    p = 2 * x**4 + 2 * x**3 * y - x**2 * y**2 + 5 * y**4
    res = sp.is_sos(p)
    assert res.is_sos
    rebuilt = sum((q * q for q in res.decomposition), sp.Polynomial.constant(0.0, p.gens))
    assert rebuilt.allclose(p, atol=1e-6)


def test_sum_of_squares_matrices_tutorial():
    """P(x) = [[x^2 - 2x + 2, x], [x, x^2]] is an SOS matrix (Blekherman-Parrilo-Thomas, Ex. 3.77)."""
    (x,) = sp.variables("x")
    P = [[x**2 - 2 * x + 2, x], [x, x**2]]
    prog = sp.SOSProgram(("x",))
    con = prog.add_sos_matrix(P)
    sol = sp.solve_program(prog)
    assert sol.status == SolveStatus.FEASIBLE
    for t in (-2.0, -0.3, 0.0, 1.0, 2.5):
        R = sum(np.outer([h(np.array([t])) for h in hr], [h(np.array([t])) for h in hr]) for hr in con.factors(sol))
        assert np.allclose(R, [[t * t - 2 * t + 2, t], [t, t * t]], atol=1e-5)


def test_sign_symmetry_tutorial_polynomial():
    """1 + x1^4 + x1 x2 + x2^4 + x3^2 (Lofberg 2009, Ex. 4) is SOS; its minimum is 7/8 (x1 = -x2 = 1/2, x3 = 0)."""
    x1, x2, x3 = sp.variables("x1 x2 x3")
    poly = 1 + x1**4 + x1 * x2 + x2**4 + x3**2
    assert sp.is_sos(poly).is_sos
    for sparsity in ("term", "auto"):
        res = sp.minimize(poly, sparsity=sparsity, degree=4)
        assert res.optimal and abs(res.lower_bound - 0.875) < 1e-6, sparsity
