"""Review 26a, findings F4, F6, F8, F9 (sospoly's general modelling layer).

References are independent of sospoly: closed forms (the minimum of a univariate quartic a x^4 - b x^2 + c is
c - b^2 / (4 a), and every nonnegative univariate polynomial is SOS, so max{c : f - c SOS} = min f exactly), and
numpy's eigenvalues for the curvature of a quadratic.
"""
from __future__ import annotations

import numpy as np
import pytest

import sospoly as sp
from sospoly.algebra.basis import monomials
from sospoly.algebra.quadexpr import CURVATURE_RTOL, convex_factor
from sospoly.solvers.optimality import check_optimality
from sospoly.status import SolveStatus


def _quartic_min(a, b, c):
    """min of a x^4 - b x^2 + c (a, b > 0), closed form."""
    return c - b * b / (4.0 * a)


def _max_c_program(f, form=sp.GramForm.IMAGE):
    p = sp.SOSProgram(("x",))
    c = p.scalar("c")
    p.add_sos(f - c, name="u")
    p.maximize(c)
    return p


# ---------------------------------------------------------------- F4: OPTIMAL means the optimum, both entry points
@pytest.mark.parametrize("coef", [(1.0, 3e4, 1e8), (1e16, 3e12, 1e8), (1.0, 3.0, 1.0), (1e-3, 2.0, 5.0)])
@pytest.mark.parametrize("form", [sp.GramForm.IMAGE, sp.GramForm.KERNEL])
def test_optimal_is_the_optimum_or_not_claimed(coef, form):
    a, b, c0 = coef
    (x,) = sp.variables("x")
    f = a * x**4 - b * x**2 + c0
    true = _quartic_min(a, b, c0)
    allowed = 1e-5 * max(1.0, abs(true), b * b / (4 * a), c0)        # the terms' scale at the minimiser
    p = _max_c_program(f, form)
    sol = sp.solve_program(p, form=form)
    res = sp.solve_conic_problem(sp.lower(p, form))
    for status, obj in ((sol.status, sol.objective), (res.status, res.objective)):
        if status == SolveStatus.OPTIMAL:
            assert abs(obj - true) <= allowed, (status, obj, true)
        elif obj is not None:             # a value reported beside a non-optimal status: a feasible point's
            assert obj <= true + allowed, (status, obj, true)
    assert (sol.status == SolveStatus.OPTIMAL) == (res.status == SolveStatus.OPTIMAL)   # one rule


def test_well_scaled_quartic_stays_optimal():
    (x,) = sp.variables("x")
    sol = sp.solve_program(_max_c_program(x**4 - 3 * x**2 + 1))
    assert sol.status == SolveStatus.OPTIMAL
    assert abs(sol.objective - _quartic_min(1, 3, 1)) <= 1e-7


def test_badly_scaled_quartic_not_claimed_optimal():
    """The review's case A, kernel form: the solver's point is 8.6e4 above the optimum (Gram lambda_min -1.9e-4,
    ||b(x*)||^2 = 2.25e8); whatever the solver returns now, no OPTIMAL above the optimum."""
    (x,) = sp.variables("x")
    p = _max_c_program(x**4 - 3e4 * x**2 + 1e8, sp.GramForm.KERNEL)
    sol = sp.solve_program(p, form=sp.GramForm.KERNEL)
    true = _quartic_min(1, 3e4, 1e8)
    assert not (sol.status == SolveStatus.OPTIMAL and sol.objective > true + 1e-5 * 2.25e8)
    assert sol.objective is None or sol.objective <= true + 1e-5 * 2.25e8


def test_check_optimality_measures_the_defect_effect():
    """A hand-made pair for min -c s.t. [[1 - c, 0], [0, 1]] PSD (optimum c = 1, dual Z = e1 e1^T): the primal
    point c = 1 + e violates the cone by e, whose effect on the objective is e tr(Z) = e."""
    prog = sp.SOSProgram(("x",))
    c = prog.scalar("c")
    prog.add_lmi([[1 - c, 0.0], [0.0, 1.0]])
    prog.maximize(c)
    cp = sp.lower(prog)
    z = cp.A.shape[0] * [0.0]
    z = np.array(z)
    z[0] = 1.0                                 # svec(e1 e1^T): the dual of the (0, 0) entry
    for e in (1e-9, 1e-3):
        opt = check_optimality(cp, np.array([1.0 + e]), z, sp.DEFAULT_TOLERANCES)
        assert opt.primal_effect == pytest.approx(e, rel=1e-6)
        assert opt.ok == (e < 1e-6)


# ---------------------------------------------------------------- F6: nonconvex quadratic objectives are refused
def test_nonconvex_objective_refused_naming_direction():
    p = sp.SOSProgram(("x",))
    a, b = p.scalar("a"), p.scalar("b")
    with pytest.raises(ValueError, match=r"convex.*\bb\b"):
        p.minimize(1e12 * (a * a) - 10 * (b * b))
    with pytest.raises(ValueError, match="concave"):
        p.maximize(10 * (b * b) - 1e12 * (a * a) + (a * b) * 1e7)      # convex in b: not concave


def test_indefinite_with_positive_diagonal_refused():
    p = sp.SOSProgram(("x",))
    a, b = p.scalar("a"), p.scalar("b")
    with pytest.raises(ValueError, match="convex"):
        p.minimize(a * a + b * b + 3 * (a * b))        # [[1, 1.5], [1.5, 1]]: eigenvalue -0.5


def test_badly_scaled_convex_objective_accepted_and_solved():
    """(1e6 a - b)^2 + 1e-6 (b - 2)^2 is convex (rank-deficient first part): minimum 0 at b = 2, a = 2e-6."""
    p = sp.SOSProgram(("x",))
    a, b = p.scalar("a"), p.scalar("b")
    d = 1e6 * a - b
    p.minimize(d * d + 1e-6 * ((b - 2) * (b - 2)))
    sol = sp.solve_program(p)
    assert sol.status == SolveStatus.OPTIMAL
    assert abs(sol.objective) <= 1e-6
    assert abs(sol.x[1] - 2.0) <= 1e-2


@pytest.mark.parametrize("seed", range(5))
def test_convex_factor_matches_numpy(seed):
    rng = np.random.default_rng(seed)
    n = 4
    Fr = rng.normal(size=(2, n)) * np.logspace(-4, 4, n)[None, :]
    P = Fr.T @ Fr                                        # PSD, rank 2, entries spanning 1e-8..1e8
    F, v, _ = convex_factor(P)
    assert F is not None and np.allclose(F.T @ F, P, rtol=1e-8, atol=1e-8 * np.abs(np.diag(P)).max())
    Q = P.copy()
    Q[0, 0] = -abs(Q[0, 0]) - 1.0
    F, v, rel = convex_factor(Q)
    assert F is None and float(v @ Q @ v) < 0             # a direction of negative curvature, checked directly
    off = 1 + 10 * CURVATURE_RTOL                            # [[1, off], [1, off]]: eigenvalue -10 CURVATURE_RTOL
    B = np.array([[1.0, off], [off, 1.0]])
    assert np.linalg.eigvalsh(B)[0] < 0 and convex_factor(B)[0] is None


# ---------------------------------------------------------------- F8: per-block PSD margins
@pytest.mark.parametrize("form", [sp.GramForm.IMAGE, sp.GramForm.KERNEL])
def test_mixed_scale_block_no_false_claim(form):
    (x,) = sp.variables("x")
    prog = sp.SOSProgram(("x",))
    c1, c2 = prog.scalar("c1"), prog.scalar("c2")
    prog.add_sos(1e-10 * (x**4 - 3 * x**2 + 1) - c1, name="tiny")
    prog.add_sos(x**2 + 1 - c2, name="big")
    prog.maximize(c1 + c2)
    s = sp.solve_program(prog, form=form)
    true_c1 = 1e-10 * _quartic_min(1, 3, 1)
    if s.status == SolveStatus.OPTIMAL:
        v1 = float(s.x[prog.block("c1").slice][0])
        assert v1 <= true_c1 + 1e-6 * 1e-10
        assert np.linalg.eigvalsh(s.grams["tiny"])[0] >= -1e-6 * np.abs(s.grams["tiny"]).max()
    alone = sp.SOSProgram(("x",))
    c = alone.scalar("c")
    alone.add_sos(1e-10 * (x**4 - 3 * x**2 + 1) - c)
    alone.maximize(c)
    sa = sp.solve_program(alone)
    assert sa.status == SolveStatus.OPTIMAL and abs(sa.objective - true_c1) <= 1e-6 * 1e-10


# ---------------------------------------------------------------- F9: validation
def test_add_lmi_refuses_nonsymmetric_at_any_scale():
    p = sp.SOSProgram(("x",))
    t, w = p.scalar("t"), p.scalar("w")
    with pytest.raises(ValueError, match="symmetric"):
        p.add_lmi([[t, 1e12 * w], [1e12 * w + 0.5 * t, 1.0]])
    p.add_lmi([[t, 1e12 * w + 0.5 * t], [0.5 * t + 1e12 * w, 1.0]])      # symmetric (other order): accepted


def test_foreign_decision_variables_refused():
    (x,) = sp.variables("x")
    p1 = sp.SOSProgram(("x",))
    p1.scalar("a"), p1.scalar("b")
    c1 = p1.scalar("c")
    p3 = sp.SOSProgram(("x",))
    u = [p3.scalar(f"u{k}") for k in range(3)]
    with pytest.raises(ValueError, match="another SOSProgram"):
        p3.add_sos(x**2 + 1 - c1)
    with pytest.raises(ValueError, match="another SOSProgram"):
        p3.maximize(c1)
    with pytest.raises(ValueError, match="two different SOSPrograms"):
        _ = u[0] + c1
    p3.add_sos(x**2 + 1 - u[2])                          # its own variables still work
    p3.maximize(u[2])
    s = sp.solve_program(p3)
    assert s.status == SolveStatus.OPTIMAL and abs(s.objective - 1.0) <= 1e-7


def test_cbf_invalid_objsense(tmp_path):
    path = tmp_path / "bad.cbf"
    path.write_text("VER\n3\n\nOBJSENSE\nMAXIMISE\n\nVAR\n1 1\nF 1\n\nCON\n1 1\nL+ 1\n\nOBJACOORD\n1\n0 1.0\n\n"
                    "ACOORD\n1\n0 0 -1.0\n\nBCOORD\n1\n0 1.0\n")
    with pytest.raises(ValueError, match=r"bad\.cbf:\d+: OBJSENSE"):
        sp.ConicProblem.from_cbf(path)
    path.write_text(path.read_text().replace("MAXIMISE", "MAX"))
    r = sp.solve_conic_problem(sp.ConicProblem.from_cbf(path))   # max x s.t. 1 - x >= 0: 1
    assert r.status == SolveStatus.OPTIMAL and abs(r.objective - 1.0) <= 1e-7


def test_extraction_refuses_bad_inputs_with_valueerror():
    with pytest.raises(ValueError, match="3 x 3"):
        sp.extract_from_gram(np.zeros((1, 1)), monomials(2, 1))
    with pytest.raises(ValueError, match="non-finite"):
        sp.extract_from_gram(np.full((3, 3), np.nan), monomials(2, 1))
    with pytest.raises(ValueError):
        sp.extract_from_gram(np.eye(2), monomials(2, 1))
    with pytest.raises(ValueError, match="6 x 6"):
        sp.extract_from_moment(np.eye(3), monomials(2, 2))
    # a right-sized rank-one moment matrix at v = (2, -1) gives v back
    b = monomials(2, 1)
    m = np.array([1.0, 2.0, -1.0])
    assert any(np.allclose(cand.point, [2.0, -1.0], atol=1e-6) for cand in sp.extract_from_moment(np.outer(m, m), b))


def test_exact_check_and_factors_on_unsolved_solutions():
    (x,) = sp.variables("x")
    ps = sp.build_psatz(x**2, [x - 1e8], (), 2)
    lb = sp.solve_psatz(ps)
    if lb.solution is not None and not lb.solution.grams:
        with pytest.raises(ValueError, match="no certificate"):
            sp.exact_check(ps, lb.solution, 0.0)
    with pytest.raises(ValueError, match="no certificate"):
        sp.exact_check(ps, None, 0.0)
    mp = sp.SOSProgram(("x",))
    c = mp.scalar("c")
    con = mp.add_sos_matrix([[x**2 + 1 - c, x], [x, x**2 + 1]])
    mp.maximize(c)
    failed = sp.ProgramSolution(SolveStatus.NUMERICAL_ERROR, None, None)
    with pytest.raises(ValueError, match="numerical_error"):
        con.factors(failed)
    with pytest.raises(TypeError):
        con.factors("not a solution")


def test_psatz_cache_user_key_holds_the_multiplier():
    """Review 26a F9: ``PsatzCache.get(..., key=k)`` returned the structure cached for another multiplier on a hit."""
    x, y = sp.variables("x y")
    cache = sp.PsatzCache()
    f, g = x ** 4 + y ** 4 - 3 * x * y, 1 - x ** 2 - y ** 2
    fixed, _ = cache.get(f, ineq=[g], degree=6, multiplier=1 + x ** 2 + y ** 2, key="k")
    putinar, _ = cache.get(f, ineq=[g], degree=6, multiplier="putinar", key="k")
    again, _ = cache.get(f, ineq=[g], degree=6, multiplier=1 + x ** 2 + y ** 2, key="k")
    assert putinar is not fixed and again is fixed
    assert cache.compiles == 2
