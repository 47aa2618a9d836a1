"""SOS programs through both Gram forms and both back-ends; is_sos; N_LMIVAR counts (SPEC §4, §8)."""
import math

import numpy as np
import pytest

import sospoly as sp
from sospoly import (
    GramForm,
    Polynomial,
    SOSProgram,
    SolveStatus,
    build_psatz,
    n_lmivar_formula,
    sigma,
    solve_program,
    tau,
)

x, y = sp.variables("x y")
CAMEL = 4 * x**2 - 2.1 * x**4 + x**6 / 3 + x * y - 4 * y**2 + 4 * y**4
MOTZKIN = x**4 * y**2 + x**2 * y**4 - 3 * x**2 * y**2 + 1
# six-hump camel global minimum -1.0316284535 (Jamil & Yang 2013, benchmark f_30); its plain SOS
# bound (f - c SOS, degree 6) is exact (Parrilo & Sturmfels 2003, "Minimizing polynomial functions").
CAMEL_MIN = -1.031628453489877


def prog_camel():
    prog = SOSProgram(("x", "y"))
    c = prog.scalar("c")
    prog.add_sos(CAMEL - c, name="u")
    prog.maximize(c)
    return prog, CAMEL_MIN


def prog_disk():
    """max c s.t. f - c - s (1 - x^2 - y^2) SOS, s SOS (S-procedure, exact by the S-lemma).

    min of (x-2)^2 + (y-1)^2 on the unit disk = (sqrt(5) - 1)^2 = 6 - 2 sqrt(5) (distance to the disk).
    """
    prog = SOSProgram(("x", "y"))
    c = prog.scalar("c")
    s = prog.sos_poly(0, name="s")
    prog.add_sos((x - 2) ** 2 + (y - 1) ** 2 - c - s * (1 - x**2 - y**2), name="u")
    prog.maximize(c)
    return prog, 6 - 2 * math.sqrt(5)


def prog_circle():
    """max c s.t. x + y - c + r (x^2 + y^2 - 1) SOS, r free of degree 0: min x + y on the circle = -sqrt 2."""
    prog = SOSProgram(("x", "y"))
    c = prog.scalar("c")
    r = prog.free_poly(0, name="r")
    prog.add_sos(x + y - c + r * (x**2 + y**2 - 1), name="u")
    prog.maximize(c)
    return prog, -math.sqrt(2)


def prog_minimize_sense():
    """A MINIMIZE program: the least t with t (1 + x^2)^2 - x^2 SOS.

    x^2 / (1 + x^2)^2 <= 1/4 with equality at x = +-1 (AM-GM), and t (1 + x^2)^2 - x^2 is a
    univariate nonnegative polynomial (hence SOS) exactly when t >= 1/4: the optimum is 1/4.
    """
    prog = SOSProgram(("x", "y"))
    t = prog.scalar("t")
    prog.add_sos(t * (1 + x**2) ** 2 - x**2, name="u")
    prog.minimize(t)
    return prog, 0.25


PROGRAMS = [prog_camel, prog_disk, prog_circle, prog_minimize_sense]


def _check_identity(prog, sol, name="u"):
    """b(v)^T G b(v) equals the SOS expression evaluated at the solution, at random points."""
    con = next(c for c in prog.sos_constraints if c.name == name)
    poly = sol.value(con.expr)
    G = sol.grams[name]
    pts = np.random.default_rng(0).uniform(-1.5, 1.5, size=(15, 2))
    got = np.array([con.gram.blocks[0].evaluate(v) @ G @ con.gram.blocks[0].evaluate(v) for v in pts])
    np.testing.assert_allclose(got, poly.evaluate(pts), atol=1e-6 * max(1.0, poly.max_abs_coefficient()), rtol=1e-6)
    assert np.linalg.eigvalsh(G)[0] >= -1e-6 * max(1.0, np.abs(G).max())


@pytest.mark.parametrize("make", PROGRAMS, ids=lambda f: f.__name__)
def test_image_and_kernel_forms_agree(make):
    prog, ref = make()
    a = solve_program(prog, form=GramForm.IMAGE)
    b = solve_program(prog, form=GramForm.KERNEL)
    assert a.status == SolveStatus.OPTIMAL and b.status == SolveStatus.OPTIMAL
    assert abs(a.objective - b.objective) <= 1e-6
    # reference values in the program docstrings (closed forms / literature), tolerance 1e-6
    assert abs(a.objective - ref) <= 1e-6
    _check_identity(prog, a)
    _check_identity(prog, b)
    # the image form has exactly N_LMIVAR columns (SPEC §8)
    assert sp.lower(prog, GramForm.IMAGE).n_cols == prog.n_lmivar()


@pytest.mark.parametrize("make", PROGRAMS, ids=lambda f: f.__name__)
def test_clarabel_and_cvxpy_backends_agree(make):
    pytest.importorskip("cvxpy")
    prog, ref = make()
    a = solve_program(prog)                       # Clarabel called directly
    b = solve_program(prog, backend="cvxpy")      # same conic data through cvxpy
    assert a.status == SolveStatus.OPTIMAL and b.status == SolveStatus.OPTIMAL
    assert abs(a.objective - b.objective) <= 1e-6
    assert abs(b.objective - ref) <= 1e-6
    _check_identity(prog, b)
    assert any(att.label.startswith("cvxpy") for att in b.attempts)


def test_backends_agree_on_minimize_bounds():
    pytest.importorskip("cvxpy")
    for kw in (dict(f=CAMEL, degree=8), dict(f=x + y, eq=[x**2 + y**2 - 1], ineq=[x])):
        a = sp.minimize(**kw)
        b = sp.minimize(**kw, backend="cvxpy")
        k = sp.minimize(**kw, form="kernel")
        assert a.status == b.status == k.status == SolveStatus.OPTIMAL
        assert abs(a.lower_bound - b.lower_bound) <= 1e-6
        assert abs(a.lower_bound - k.lower_bound) <= 1e-6


def test_feasibility_programs_and_statuses():
    prog = SOSProgram(("x", "y"))
    prog.add_sos(x**2 - 2 * x * y + 2 * y**2 + 1)         # (x - y)^2 + y^2 + 1
    assert solve_program(prog).status == SolveStatus.FEASIBLE
    prog = SOSProgram(("x", "y"))
    prog.add_sos(x**2 - 3 * x * y + y**2)                 # indefinite quadratic form: not SOS
    sol = solve_program(prog)
    assert sol.status == SolveStatus.INFEASIBLE and not sol.status.ok
    assert sol.objective is None


def test_custom_lyapunov_program():
    """A quadratic Lyapunov function for dx/dt = -x + y, dy/dt = -x - y^3 (e.g. V = x^2 + y^2 gives
    dV/dt = -2 x^2 - 2 y^4): V - eps |v|^2 SOS and -dV/dt - eps x^2 SOS, with V's coefficients scalars."""
    prog = SOSProgram(("x", "y"))
    fx, fy = -x + y, -x - y**3
    monos = [x**2, x * y, y**2]
    a = [prog.scalar(f"a{k}") for k in range(3)]
    V = a[0] * monos[0] + a[1] * monos[1] + a[2] * monos[2]
    dV = sum((ak * (m.diff("x") * fx + m.diff("y") * fy) for ak, m in zip(a[1:], monos[1:])),
             a[0] * (monos[0].diff("x") * fx + monos[0].diff("y") * fy))
    eps = 0.1
    prog.add_sos(V - eps * (x**2 + y**2), name="positive")
    prog.add_sos(-1.0 * dV - eps * x**2, degree=4, name="decrease")
    prog.add_equality(a[0] + a[2], 2.0)          # normalisation (the conditions are homogeneous in a)
    sol = solve_program(prog)
    assert sol.status == SolveStatus.FEASIBLE
    Vnum = sol.value(V)
    # independent check of the certificate on a grid: V > 0 and dV/dt < 0 away from the origin
    g = np.linspace(-1, 1, 9)
    pts = np.array([(p, q) for p in g for q in g if (p, q) != (0.0, 0.0)])
    dVnum = Vnum.diff("x") * fx + Vnum.diff("y") * fy
    assert np.all(Vnum.evaluate(pts) > 0)
    assert np.all(dVnum.evaluate(pts) < 0)
    # an unstable system (dx/dt = x, dy/dt = y) has no such V: the program is infeasible
    bad = SOSProgram(("x", "y"))
    b = [bad.scalar(f"b{k}") for k in range(3)]
    Vb = b[0] * monos[0] + b[1] * monos[1] + b[2] * monos[2]
    dVb = b[0] * (2 * x * x) + b[1] * (2 * x * y) + b[2] * (2 * y * y)    # grad V . (x, y) = 2 V
    bad.add_sos(Vb - eps * (x**2 + y**2))
    bad.add_sos(-1.0 * dVb - eps * x**2)
    assert solve_program(bad).status == SolveStatus.INFEASIBLE


def test_is_sos_classics():
    # Motzkin (1967): nonnegative but not a sum of squares
    assert not sp.is_sos(MOTZKIN).is_sos
    # (x^2 + y^2 + 1) * Motzkin is SOS (the classic certificate of Motzkin >= 0, e.g. Parrilo's 2000 thesis)
    prod = (x**2 + y**2 + 1) * MOTZKIN
    res = sp.is_sos(prod)
    assert res.is_sos and res.status == SolveStatus.FEASIBLE
    total = Polynomial.constant(0.0, ("x", "y"))
    for d in res.decomposition:
        total = total + d**2
    assert (total - prod).max_abs_coefficient() <= 1e-6
    # a random sum of squares is SOS and its decomposition sums back to it
    rng = np.random.default_rng(11)
    E = sp.monomials(2, 2)
    q = sum((Polynomial(("x", "y"), {tuple(e): float(c) for e, c in zip(E, rng.standard_normal(len(E)))}) ** 2
             for _ in range(3)), Polynomial.constant(0.0, ("x", "y")))
    res = sp.is_sos(q)
    assert res.is_sos
    total = sum((d**2 for d in res.decomposition), Polynomial.constant(0.0, ("x", "y")))
    assert (total - q).max_abs_coefficient() <= 1e-6 * max(1.0, q.max_abs_coefficient())
    # negative and odd-degree polynomials are not
    assert not sp.is_sos(-x**2).is_sos
    r = sp.is_sos(x**3 + y**2 + 1)
    assert not r.is_sos and r.status == SolveStatus.INFEASIBLE
    assert not sp.is_sos(Polynomial.constant(-1.0, ("x",))).is_sos
    assert sp.is_sos(Polynomial.constant(2.0, ("x",))).is_sos
    # the kernel form and the cvxpy back-end agree on both answers
    assert not sp.is_sos(MOTZKIN, form="kernel").is_sos
    assert sp.is_sos(prod, form="kernel").is_sos
    if cvxpy_installed():
        assert sp.is_sos(prod, backend="cvxpy").is_sos


# ------------------------------------------------------------------ N_LMIVAR (SPEC §8)
CONFIGS = [
    (2, 4, (), ()), (2, 6, (2,), ()), (3, 4, (2, 3), (2,)), (3, 6, (), (2, 4)), (2, 4, (1,), (1, 2)),
    (4, 4, (2, 2), (2,)),
]


def _problem(nvars, delta, eq_deg, ineq_deg, multiplier="fixed"):
    v = sp.variables("v", n=nvars)
    f = sum((vi * vi for vi in v), Polynomial.constant(0.0, v[0].gens))
    eq = [v[0] ** d - 1 for d in eq_deg]
    ineq = [1 - v[-1] ** d if d % 2 == 0 else 1 - v[-1] for d in ineq_deg]
    return build_psatz(f, eq, ineq, degree=delta, multiplier=multiplier, gens=v[0].gens)


@pytest.mark.parametrize("cfg", CONFIGS)
def test_n_lmivar_formula_matches_program(cfg):
    nvars, delta, eq_deg, ineq_deg = cfg
    ps = _problem(nvars, delta, eq_deg, ineq_deg)
    assert n_lmivar_formula(nvars, delta, eq_deg, ineq_deg) == ps.n_lmivar
    assert sp.lower(ps.program).n_cols == ps.n_lmivar
    free = _problem(nvars, delta, eq_deg, ineq_deg, multiplier="free")
    assert n_lmivar_formula(nvars, delta, eq_deg, ineq_deg, free_q_degree=delta - 2) == free.n_lmivar


def test_n_lmivar_paper_values():
    # SPEC §8, by hand: 8 variables (3 views + one 2-d region), delta = 4:
    # tau(8, 4) = 45*46/2 - C(12, 4) = 1035 - 495 = 540, so 1 + tau = 541.
    assert tau(8, 4) == 540 and sigma(8, 2) == 45 and sigma(8, 1) == 9
    assert n_lmivar_formula(8, 4) == 541
    # Corollary 1: 3 epipolar constraints (degree 2) + k quadratic inequalities.
    # delta = 2: 1 + 3 + k;  delta = 4: 541 + 3*45 + k*45 (paper's Examples 2, 3, 4: 5/721, 6/766, 7/811)
    for k, (d2, d4) in zip((1, 2, 3), ((5, 721), (6, 766), (7, 811))):
        assert n_lmivar_formula(8, 2, (2, 2, 2), (2,) * k) == d2
        assert n_lmivar_formula(8, 4, (2, 2, 2), (2,) * k) == d4
        assert _problem(8, 2, (2, 2, 2), (2,) * k).n_lmivar == d2
    assert _problem(8, 4, (2, 2, 2), (2,)).n_lmivar == 721
    # Example 1 tables: points only, delta = 2: 1 + N(N-1)/2 = 2, 4, 7, 11, 16 for N = 2..6
    for N, ref in zip(range(2, 7), (2, 4, 7, 11, 16)):
        assert n_lmivar_formula(2 * N, 2, (2,) * (N * (N - 1) // 2)) == ref


def cvxpy_installed() -> bool:
    from sospoly.solvers.backends import cvxpy_available

    return cvxpy_available()


def test_unknown_or_uninstalled_solver_is_an_error_naming_it():
    """An unknown cvxpy solver is a ValueError, a known one not installed an ImportError; both name it
    and are raised before any solve (not a numerical_error after retries)."""
    pytest.importorskip("cvxpy")
    import cvxpy

    with pytest.raises(ValueError, match="NOSUCH"):
        sp.minimize(x**2 + 1, backend="cvxpy:NOSUCH")
    with pytest.raises(ValueError, match="nosuch"):
        sp.minimize(x**2 + 1, backend="nosuch")
    missing = [s for s in ("MOSEK", "GUROBI", "COPT", "XPRESS") if s not in cvxpy.installed_solvers()]
    if missing:
        with pytest.raises(ImportError, match=missing[0]):
            sp.minimize(x**2 + 1, backend=f"cvxpy:{missing[0]}")
    from tritools.solve.options import TriangulationOptions

    with pytest.raises(ValueError, match="NOSUCH"):
        TriangulationOptions(backend="cvxpy:NOSUCH")


def test_without_cvxpy_the_default_chain_skips_it_and_naming_it_says_how_to_install(monkeypatch):
    import builtins
    import importlib

    mz = importlib.import_module("sospoly.minimize")
    be = importlib.import_module("sospoly.solvers.backends")

    real = builtins.__import__

    def no_cvxpy(name, *a, **k):
        if name == "cvxpy" or name.startswith("cvxpy."):
            raise ImportError("No module named 'cvxpy'")
        return real(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", no_cvxpy)
    monkeypatch.setattr(mz, "cvxpy_available", lambda: False)
    assert all(b != "cvxpy" for _, b in mz._retry_chain(None, None))
    with pytest.raises(ImportError, match=r"sospoly-tritools\[cvxpy\]"):
        be.get_backend("cvxpy")
    assert sp.minimize(x**2 + 1).status == SolveStatus.OPTIMAL
