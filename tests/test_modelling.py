"""SOSProgram as a modelling layer (issue 25): scalar inequalities, convex quadratic objectives, LMI and SOC
constraints, matrix SOS, moment matrices with bases, SDPA / CBF files.  Every optimum is checked against an
independent value: a closed form, numpy / scipy, cvxpy on hand-written data, or the SDPA manual's example."""
import math

import numpy as np
import pytest
import scipy.optimize as so

import sospoly as sp
from sospoly import SolveStatus

x, y = sp.variables("x y")


def _solve(prog, **kw):
    sol = sp.solve_program(prog, **kw)
    assert sol.status == SolveStatus.OPTIMAL, sol.message
    return sol


def test_inequalities_and_convex_quadratic_closed_form():
    """min (a - 2)^2 + (b - 1)^2 + a on 1 <= a <= 3: a = 3/2, b = 1, value 7/4."""
    prog = sp.SOSProgram(("x",))
    a, b = prog.scalar("a"), prog.scalar("b")
    prog.add_inequality(3 - a)
    prog.add_inequality(a - 1)
    prog.minimize((a - 2) * (a - 2) + (b - 1) * (b - 1) + a)
    for backend in (None, "cvxpy"):
        sol = _solve(prog, backend=backend)
        assert abs(sol.objective - 1.75) < 1e-6
        assert abs(sol.value(a).coefficient((0,)) - 1.5) < 1e-5
    prog.add_inequality(a - 4)                     # now 4 <= a <= 3: empty
    assert sp.solve_program(prog).status == SolveStatus.INFEASIBLE


def test_least_squares_objective_matches_numpy():
    rng = np.random.default_rng(3)
    M, r = rng.normal(size=(6, 3)), rng.normal(size=6)
    prog = sp.SOSProgram(("x",))
    z = [prog.scalar(f"z{k}") for k in range(3)]
    obj = 0.0
    for i in range(6):
        ri = z[0] * M[i, 0] + z[1] * M[i, 1] + z[2] * M[i, 2] - r[i]
        obj = ri * ri + obj
    prog.minimize(obj)
    sol = _solve(prog)
    zs, res, *_ = np.linalg.lstsq(M, r, rcond=None)
    assert abs(sol.objective - res[0]) < 1e-6 * max(1.0, res[0])
    assert np.allclose(sol.x[:3], zs, atol=1e-5)


def test_concave_maximisation_and_curvature_check():
    prog = sp.SOSProgram(("x",))
    a = prog.scalar("a")
    prog.maximize(-1.0 * (a * a) + 2 * a)          # max 2a - a^2 = 1 at a = 1
    assert abs(_solve(prog).objective - 1.0) < 1e-6
    with pytest.raises(ValueError, match="convex"):
        prog.minimize(-1.0 * (a * a))


def test_lmi_matches_eigenvalue_minimisation():
    """min_w lambda_max(A0 + w A1) as min t s.t. t I - A0 - w A1 PSD; reference: scipy on eigvalsh."""
    rng = np.random.default_rng(0)
    A0, A1 = (lambda B: B + B.T)(rng.normal(size=(3, 3))), (lambda B: B + B.T)(rng.normal(size=(3, 3)))
    prog = sp.SOSProgram(("x",))
    t, w = prog.scalar("t"), prog.scalar("w")
    prog.add_lmi([[t * float(i == j) - A0[i, j] - w * A1[i, j] for j in range(3)] for i in range(3)])
    prog.minimize(t)
    sol = _solve(prog)
    ref = so.minimize_scalar(lambda v: np.linalg.eigvalsh(A0 + v * A1)[-1], bounds=(-20, 20), method="bounded",
                             options={"xatol": 1e-10})
    assert abs(sol.objective - ref.fun) < 1e-6
    assert sol.min_eigenvalues["lmi0"] > -1e-7


def test_second_order_cone():
    prog = sp.SOSProgram(("x",))
    a, b = prog.scalar(), prog.scalar()
    prog.add_soc(1.0, [a, b])
    prog.minimize(a + b)
    assert abs(_solve(prog).objective + math.sqrt(2)) < 1e-7


def test_matrix_sos_closed_form_and_factors():
    """max c s.t. [[x^2 + 1 - c, x], [x, x^2 + 1]] SOS: PSD for all x iff c <= min_u u + 1 - u/(u+1) = 1."""
    (t,) = sp.variables("t")
    prog = sp.SOSProgram(("t",))
    c = prog.scalar("c")
    con = prog.add_sos_matrix([[t**2 + 1 - c, t], [t, t**2 + 1]])
    prog.maximize(c)
    sol = _solve(prog)
    assert abs(sol.objective - 1.0) < 1e-6
    # the factors rebuild M(t) at the optimum
    cval = sol.objective
    H = con.factors(sol)
    for tv in (-1.3, 0.0, 0.7, 2.0):
        M = np.array([[tv**2 + 1 - cval, tv], [tv, tv**2 + 1]])
        R = sum(np.outer([h(np.array([tv])) for h in hr], [h(np.array([tv])) for h in hr]) for hr in H)
        assert np.allclose(R, M, atol=1e-5)


def test_matrix_sos_sostools_demo_and_a_non_psd_matrix():
    """SOSTOOLS' sosdemo9 matrix is SOS; [[1, x], [x, -1]] is not even PSD (entry (2,2) < 0)."""
    x1, x2, x3 = sp.variables("x1 x2 x3")
    off = x1 * x2 * x3**2 - x1**3 * x2 - x1 * x2 * (x2**2 + 2 * x3**2)
    P = [[x1**4 + x1**2 * x2**2 + x1**2 * x3**2, off],
         [off, x1**2 * x2**2 + x2**2 * x3**2 + (x2**2 + 2 * x3**2) ** 2]]
    prog = sp.SOSProgram(("x1", "x2", "x3"))
    con = prog.add_sos_matrix(P, basis=np.array([[2, 0, 0], [1, 1, 0], [1, 0, 1], [0, 2, 0], [0, 1, 1], [0, 0, 2]]))
    sol = sp.solve_program(prog)
    assert sol.status == SolveStatus.FEASIBLE
    pt = np.array([0.3, -1.1, 0.8])
    R = sum(np.outer([h(pt) for h in hr], [h(pt) for h in hr]) for hr in con.factors(sol))
    M = np.array([[P[0][0](pt), P[0][1](pt)], [P[1][0](pt), P[1][1](pt)]])
    assert np.allclose(R, M, atol=1e-5 * np.abs(M).max())
    bad = sp.SOSProgram(("x", "y"))
    bad.add_sos_matrix([[1.0 + 0 * x, x], [x, -1.0 + 0 * x]])
    assert sp.solve_program(bad).status == SolveStatus.INFEASIBLE


def test_moment_matrices_with_bases_and_atoms():
    (t,) = sp.variables("t")
    res = sp.minimize((t**2 - 1) ** 2, degree=4)
    assert res.optimal
    (mm,) = res.moment_matrices
    assert mm.monomials() == ("1", "t", "t^2")
    assert mm.basis.shape == (3, 1) and mm.matrix.shape == (3, 3)
    assert abs(mm.matrix[0, 0] - 1) < 1e-12 and abs(mm.moment((2,)) - 1) < 1e-4   # L(t^2) = 1 on {-1, 1}
    assert mm.is_flat()
    atoms = sorted(float(p[0]) for p in mm.atoms())
    assert np.allclose(atoms, [-1, 1], atol=1e-4)
    assert np.allclose([w for _, w in mm.measure()], [0.5, 0.5], atol=1e-4)     # the symmetric measure


@pytest.mark.parametrize("s", [1e-3, 1e3])
def test_moment_matrices_are_in_the_user_s_variables_when_the_program_is_scaled(s):
    """minimize solves a power-of-two rescaled program; the moments it returns are those of the caller's
    variables (the minimiser of (x - s)^2 + (y + 2 s)^2 is (s, -2 s): L(x) = s, L(y^2) = 4 s^2)."""
    f = (x - s) ** 2 + (y + 2 * s) ** 2
    res = sp.minimize(f, degree=2, sparsity="none")               # one dense block over (1, x, y)
    (mm,) = res.moment_matrices
    assert np.allclose(mm.matrix[0, 1:], [s, -2 * s], rtol=1e-4)
    assert mm.rank() == 1 and np.allclose(mm.atoms()[0], [s, -2 * s], rtol=1e-4)


def test_moment_matrix_of_a_unique_minimiser():
    f = (x - 1) ** 2 + (y + 2) ** 2 + x * y        # minimiser solves 2(x-1)+y = 0, 2(y+2)+x = 0
    res = sp.minimize(f, degree=2)
    xs = np.linalg.solve([[2, 1], [1, 2]], [2, -4])
    (mm,) = res.moment_matrices
    assert mm.monomials() == ("1", "x", "y")
    assert np.allclose(mm.matrix[0, 1:], xs, atol=1e-4)
    assert mm.rank() == 1 and np.allclose(mm.atoms()[0], xs, atol=1e-4)


SDPA_MANUAL_EXAMPLE1 = '''"Example 1: mDim = 3, nBLOCK = 1, {2}"
   3  =  mDIM
   1  =  nBOLCK
   2  = bLOCKsTRUCT
{48, -8, 20}
0 1 1 1 -11
0 1 2 2 23
1 1 1 1 10
1 1 1 2 4
2 1 2 2 -8
3 1 1 2 -8
3 1 2 2 -2
'''


def test_sdpa_manual_example(tmp_path):
    """The SDPA manual's example1.dat-s: objective -41.9 at x = (-1.1, -2.7375, -0.55)."""
    path = tmp_path / "example1.dat-s"
    path.write_text(SDPA_MANUAL_EXAMPLE1)
    res = sp.solve_conic_problem(sp.ConicProblem.from_sdpa(path))
    assert res.status == SolveStatus.OPTIMAL
    assert abs(res.objective + 41.9) < 1e-6
    assert np.allclose(res.x, [-1.1, -2.7375, -0.55], atol=1e-5)


def _mixed_program():
    prog = sp.SOSProgram(("x",))
    a, b, t = prog.scalar("a"), prog.scalar("b"), prog.scalar("t")
    prog.add_inequality(3 - a)
    prog.add_equality(a + b, 1.0)
    prog.add_soc(2.0, [a, b])
    prog.add_lmi([[t, 1.0], [1.0, a]])
    prog.minimize((a - 2) * (a - 2) + t)
    # reference: b = 1 - a, a^2 + b^2 <= 4 -> a <= (1 + sqrt 7)/2, t = 1/a; (a-2)^2 + 1/a decreasing there
    amax = (1 + math.sqrt(7)) / 2
    return prog, (amax - 2) ** 2 + 1 / amax


def _annulus_program():
    p = x**4 + y**4 - 3 * x * y
    prog = sp.SOSProgram(("x", "y"))
    c = prog.scalar("c")
    s1, s2 = prog.sos_poly(2, name="s1"), prog.sos_poly(2, name="s2")
    prog.add_sos(p - c - s1 * (x**2 + y**2 - 1) - s2 * (4 - x**2 - y**2), name="u")
    prog.maximize(c)
    return prog, -9 / 8


@pytest.mark.parametrize("make", [_mixed_program, _annulus_program], ids=["mixed-cones", "annulus"])
def test_sdpa_and_cbf_round_trip(make, tmp_path):
    prog, ref = make()
    P = sp.lower(prog)
    direct = sp.solve_conic_problem(P)
    assert direct.status == SolveStatus.OPTIMAL and abs(direct.objective - ref) < 1e-6
    P.to_sdpa(tmp_path / "p.dat-s")
    P.to_cbf(tmp_path / "p.cbf")
    for back in (sp.ConicProblem.from_sdpa(tmp_path / "p.dat-s"), sp.ConicProblem.from_cbf(tmp_path / "p.cbf")):
        assert back.n_cols == P.n_cols
        for backend in (None, "cvxpy"):
            res = sp.solve_conic_problem(back, backend=backend)
            assert res.status == SolveStatus.OPTIMAL
            assert abs(res.objective - ref) < 1e-6


def test_sdpa_zero_rows_come_back_as_equalities(tmp_path):
    prog, _ = _mixed_program()
    P = sp.lower(prog)
    P.to_sdpa(tmp_path / "p.dat-s")
    back = sp.ConicProblem.from_sdpa(tmp_path / "p.dat-s")
    kinds = [c.kind for c in back.cones]
    assert kinds.count("zero") == 1 and back.cones[0].dim == 1       # a + b = 1
    assert "nonneg" in kinds


@pytest.mark.parametrize("text,needle", [
    ("2\n1\n2\n1 2\n0 1 1 1 x\n", ":5:"),
    ("2\n1\n2\n1 2\n0 1 3 3 1.0\n", "outside block"),
    ("2\n1\n2\n1\n", "truncated"),
    ("2\n1\n2\n1 2\n5 1 1 1 1.0\n", "out of range"),
])
def test_bad_sdpa_files_name_the_line(text, needle, tmp_path):
    path = tmp_path / "bad.dat-s"
    path.write_text(text)
    with pytest.raises(ValueError, match=needle):
        sp.ConicProblem.from_sdpa(path)


@pytest.mark.parametrize("chain,expected", [(False, {"dsos": 0.5, "sdsos": 0.5, "sos": 1.0}),
                                            (True, {"dsos": 0.5, "sdsos": 1 / math.sqrt(2), "sos": 1 / math.sqrt(2)})],
                         ids=["all-pairs", "chain"])
def test_dsos_sdsos_closed_forms(chain, expected):
    """max c: x^2 + y^2 + z^2 + 2c (xy + yz [+ xz]) in the cone, basis (x, y, z).  Q = I + c E.
    All pairs (E = J - I): PSD iff c <= 1; DD iff 2c <= 1; SDD: blocks [[a, c], [c, a]] with 2a = 1, so c <= 1/2.
    Chain (E = path): PSD iff sqrt2 c <= 1; DD iff 2c <= 1; SDD with D = diag(1, sqrt2, 1): c <= 1/sqrt2."""
    x1, x2, x3 = sp.variables("x y z")
    B = np.eye(3, dtype=int)
    for kind, ref in expected.items():
        prog = sp.SOSProgram(("x", "y", "z"))
        c = prog.scalar("c")
        p = x1**2 + x2**2 + x3**2 + 2 * c * (x1 * x2 + x2 * x3 + (0 * x1 if chain else x1 * x3))
        {"dsos": prog.add_dsos, "sdsos": prog.add_sdsos, "sos": lambda q, basis: prog.add_sos(q, bases=[basis])}[
            kind](p, basis=B)
        prog.maximize(c)
        assert abs(_solve(prog).objective - ref) < 1e-6, kind


def test_dsos_bound_is_valid_and_its_gram_is_diagonally_dominant():
    p = x**4 + y**4 - 3 * x * y                      # min -9/8 (x = y = sqrt(3)/2)
    bounds = {}
    for kind in ("dsos", "sdsos", "sos"):
        prog = sp.SOSProgram(("x", "y"))
        c = prog.scalar("c")
        con = getattr(prog, f"add_{kind}")(p - c, degree=4)
        prog.maximize(c)
        sol = _solve(prog)
        bounds[kind] = sol.objective
        if kind == "dsos":
            Q = con.gram(prog, sol)
            off = np.abs(Q).sum(axis=1) - np.abs(np.diag(Q))
            assert np.all(np.diag(Q) - off >= -1e-7)
            b = con.basis                           # b^T Q b reproduces p - c at random points
            for pt in np.random.default_rng(1).normal(size=(5, 2)):
                bv = np.prod(pt[None, :] ** b, axis=1)
                assert abs(bv @ Q @ bv - (p(pt) - sol.objective)) < 1e-6 * max(1.0, abs(p(pt)))
    assert bounds["dsos"] <= bounds["sdsos"] + 1e-7 <= bounds["sos"] + 2e-7
    assert abs(bounds["sos"] + 9 / 8) < 1e-6 and bounds["dsos"] <= -9 / 8 + 1e-7


def test_lowered_columns_equal_n_lmivar_with_every_new_constraint():
    prog, _ = _mixed_program()
    con = prog.add_sos_matrix([[1.0 + 0 * x, 0 * x], [0 * x, 1.0 + 0 * x]])
    prog.add_dsos(x**2 + 1, degree=2)
    assert con.m == 2
    for form in (sp.GramForm.IMAGE,):
        assert sp.lower(prog, form).n_cols == prog.n_lmivar()


def test_bad_modelling_input_names_the_argument():
    prog = sp.SOSProgram(("x", "y"))
    a = prog.scalar("a")
    with pytest.raises(ValueError, match="add_soc xs"):
        prog.add_soc(a, [])
    with pytest.raises(ValueError, match="add_soc t"):
        prog.add_soc(a * x, [a])
    with pytest.raises(TypeError, match="add_inequality"):
        prog.add_inequality(a * a)
    with pytest.raises(ValueError, match="add_sos_matrix M"):
        prog.add_sos_matrix([[x, y], [x]])
    with pytest.raises(ValueError, match="symmetric"):
        prog.add_sos_matrix([[x, y], [x, y]])
    with pytest.raises(ValueError, match="degree"):
        prog.add_sos_matrix([[x**2, 0 * x], [0 * x, x**2]], degree=1)
    with pytest.raises(ValueError, match="psd_matrix side"):
        prog.psd_matrix(0)
    with pytest.raises(ValueError, match="degree"):
        sp.minimize_ratios([(x, 1 + x**2)], degree=3)
    with pytest.raises(TypeError, match="quadratic expression can only be scaled"):
        (a * a) * x
