"""Wave 39: the review leftovers of wave 38 (sospoly messages) and this wave's reviews."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import sospoly as sp


def test_ratios_on_an_empty_set_report_the_empty_set_not_a_denominator():
    """Review 38a L6: minimize_ratios on {x^2 + y^2 + 1 = 0} blamed the denominator ("not certified positive,
    certified lower bound -inf"); minimize proves the set empty, and so does minimize_ratios now: lower bound +inf
    (every sum of ratios is bounded below by +inf on the empty set), minimize's status and message."""
    x, y = sp.variables("x y")
    eq = [x**2 + y**2 + 1]
    r = sp.minimize_ratios([(x, y + 2)], eq=eq)
    m = sp.minimize(y + 2, eq=eq)
    assert m.lower_bound == np.inf
    assert r.lower_bound == np.inf and r.upper_bound is None and not r.optimal
    assert r.status == m.status
    assert "empty" in r.message and "not certified positive" not in r.message


def test_ratios_on_a_nonempty_set_still_check_denominators():
    """The empty-set exit does not swallow a denominator that changes sign on a non-empty set."""
    x, = sp.variables("x")
    r = sp.minimize_ratios([(1 + 0 * x, x)], ineq=[1 - x**2])
    assert r.status == sp.SolveStatus.INFEASIBLE and r.lower_bound is None
    assert "terms[0].q is not certified positive" in r.message


@pytest.mark.parametrize("gens, error, words", [
    ((1, 2), TypeError, "gens[0] must be a variable name"),
    (("x", None), TypeError, "gens[1] must be a variable name"),
    (("x", "x"), ValueError, "'x' twice"),
    (3, TypeError, "gens must be a sequence"),
])
def test_gens_that_are_not_distinct_names_are_named(gens, error, words):
    """Review 38a L7: minimize(x**2, gens=(1, 2)) said "variables ['x'] are not among (1, 2)"; the entry that is
    not a variable name (or is repeated) is named, for minimize and for with_gens itself."""
    x, = sp.variables("x")
    with pytest.raises(error) as e:
        sp.minimize(x**2, gens=gens)
    assert words in str(e.value)
    with pytest.raises(error):
        x.with_gens(gens)


def test_gens_in_another_order_still_work():
    x, y = sp.variables("x y")
    p = (x - 1) ** 2 + (y + 2) ** 2
    q = p.with_gens(("y", "x", "z"))
    assert q.gens == ("y", "x", "z") and q.coefficient((2, 0, 0)) == 1.0
    r = sp.minimize(p, gens=["y", "x"])
    assert r.optimal and abs(r.lower_bound) < 1e-6


def test_shifted_rosenbrock_is_certified_at_its_minimiser_not_at_a_worse_point():
    """Review 39b: (1 - (x - 1024))^2 + 100 (y - (x - 1024)^2)^2 (integer data, minimum 0 at (1025, 1)) was
    "optimal" at (1117.0, 8643.5) with f = 8458.6 (decided at that point's scale 1.1e12, gap 6.3e5) after 60 s:
    the translated solve found (1025, 1) but its result was set aside.  The solves are pooled now (the better point
    decides the scale: 4096 there, no certificate from the first solve) and the program is translated again to the
    better point, where it is certified."""
    x, y = sp.variables("x y")
    f = (1 - (x - 1024.0)) ** 2 + 100 * (y - (x - 1024.0) ** 2) ** 2
    r = sp.minimize(f, budget=sp.Budget(time_limit=30.0))
    assert r.lower_bound <= 0.0                                    # valid: the minimum is 0
    assert r.optimal and r.upper_bound <= 1e-6
    assert np.allclose(r.minimizers[0], [1025.0, 1.0], atol=1e-3)
    assert float(f([1025.0, 1.0])) == 0.0


@pytest.mark.parametrize("make", [
    lambda x, y: x**2 + 100 * (y - x**2) ** 2,
    lambda x, y: x**2 + 100 * (y - x**2 - 2 * x) ** 2,            # Rosenbrock translated to its minimiser
])
def test_a_minimum_zero_at_the_origin_on_a_structural_face_is_proven(make):
    """Review 39b (found through the shifted Rosenbrock): a polynomial with no constant term, minimum 0 at the
    origin and a Gram matrix singular on a structural face gave "unproven_bound" (the exact face check reduced the
    certificate at the solver's level 3.8e-9 > 0, where the constant monomial is negative, before any margin); the
    reduction now keeps q's monomials live, and the lowered level is proven exactly."""
    x, y = sp.variables("x y")
    r = sp.minimize(make(x, y))
    assert r.optimal and -1e-6 <= r.lower_bound <= 0.0
    assert "structural kernel" in r.message
    assert np.allclose(r.minimizers[0], [0.0, 0.0], atol=1e-5)


def test_pooled_results_decide_at_the_better_points_scale():
    """sospoly.recentre.pooled: a certified result whose gap is small only at its own (large) scale loses the
    certificate when another solve of the same problem has a better point where the scale is small; the larger
    lower bound is kept, and both results' points are valued exactly."""
    import dataclasses

    from sospoly.recentre import pooled
    from sospoly.tolerances import Tolerances

    x, = sp.variables("x")
    f = (x - 1000.0) ** 4 + (x - 1000.0) ** 2                     # minimum 0 at 1000
    base = sp.minimize(x**2)                                       # a MinimizeResult to fill in
    far = dataclasses.replace(base, status=sp.SolveStatus.OPTIMAL, optimal=True, lower_bound=-5.0,
                              upper_bound=float(f([1001.0])), minimizers=(np.array([1001.0]),),
                              candidates=(np.array([1001.0]),), scale=2.0 ** 40)
    near = dataclasses.replace(far, optimal=False, lower_bound=-1.0, upper_bound=0.0,
                               minimizers=(np.array([1000.0]),), candidates=(np.array([1000.0]),))
    out = pooled(far, near, f, Tolerances(), 2.0 ** 40)
    assert not out.optimal
    assert out.lower_bound == -1.0 and out.upper_bound == 0.0
    assert np.array_equal(out.minimizers[0], [1000.0]) and out.scale < 2.0 ** 20


def test_rigorous_bound_of_a_solve_without_a_certificate_is_no_bound():
    """Review 39b: rigorous_psatz_bound on an inaccurate solve that returned no Gram matrices (x - 1e6)^2 + ...
    at degree 2) raised a bare KeyError 'u'; it now proves nothing (-inf), as for any unprovable margin."""
    from sospoly.analysis.rigor import rigorous_psatz_bound
    from sospoly.solvers.solve import ProgramSolution

    x, y = sp.variables("x y")
    ps = sp.build_psatz((x - 3) ** 2 + (y + 3) ** 2 + 5, degree=2)
    good = sp.solve_psatz(ps)
    assert good.solution.grams
    empty = dataclasses.replace(good.solution, grams={})
    rb = rigorous_psatz_bound(ps, empty, 4.0, 10.0)
    assert rb.lower_bound == -np.inf
    assert isinstance(empty, ProgramSolution)
    ok = rigorous_psatz_bound(ps, good.solution, good.solution.objective, 10.0)
    assert ok.lower_bound <= 5.0 and ok.lower_bound > 4.9


def _scaled_quartic_program(s):
    """The program of benchmarks/scaled_sos.py (one generator for the benchmark and these tests)."""
    import importlib.util
    import pathlib

    path = pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "scaled_sos.py"
    spec = importlib.util.spec_from_file_location("scaled_sos", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.scaled_quartic_program(s)


@pytest.mark.parametrize("s", [1.0, 1e-6, 1e-3, 2.0 ** -30, 1e3])
def test_solve_program_never_claims_an_objective_past_the_optimum_under_variable_scaling(s):
    """Review 39b A1: max c s.t. X^4 + Y^4 + 0.5 X Y + 1 - c SOS with X = s x (optimum 1 - 1/32 = 0.96875 for every
    s) was "optimal" at c = 1.00000000001 for s = 1e-6: the PSD test measured the Gram matrix against its largest
    entry and the data's floor, under which the rows of x^2 (entries 1e-24) hid.  Gram matrices are also tested at
    the balanced scale of their monomials (sospoly.solvers.balance): an optimal claim is the optimum's."""
    sol = sp.solve_program(_scaled_quartic_program(s))
    assert sol.status == sp.SolveStatus.OPTIMAL            # solved at the monomials' balanced scale (Balance)
    assert abs(sol.objective - 0.96875) < 1e-6


def test_balanced_scalings_of_a_lowered_program():
    """block_scalings fits k = 20 per variable for X = 2^-20 x (the data's monomials balanced), 0 (None) for
    balanced data; the PSD test at that scale rejects the false Gram matrix and accepts the true one."""
    from sospoly.solvers.balance import block_scalings

    S = block_scalings(sp.lower(_scaled_quartic_program(2.0 ** -20)))
    assert S["u"] is not None and set(np.log2(S["u"]).round().astype(int).tolist()) == {0, 20, 40}
    assert block_scalings(sp.lower(_scaled_quartic_program(1.0)))["u"] is None


def _annulus_program(s):
    x, y = sp.variables("x y")
    X, Y = x * (1.0 / s), y * (1.0 / s)
    prog = sp.SOSProgram(("x", "y"))
    c = prog.scalar("c")
    s1, s2 = prog.sos_poly(2, name="s1"), prog.sos_poly(2, name="s2")
    prog.add_sos(X**4 + Y**4 - 3 * X * Y - c - s1 * (X**2 + Y**2 - 1) - s2 * (4 - X**2 - Y**2), name="u")
    prog.maximize(c)
    return prog


@pytest.mark.parametrize("s", [1.0, 1000.0])
def test_a_bounded_program_is_never_called_unbounded_under_variable_scaling(s):
    """Review 39b A2: the docs' annulus S-procedure with x -> x / 1000 (optimum -9/8) was "unbounded" (the
    constraint set empty): the solver's ray passed the check, whose PSD cones were measured against their largest
    terms.  The ray is also checked at the balanced scale of the monomials now, and fails there."""
    sol = sp.solve_program(_annulus_program(s))
    assert sol.status == sp.SolveStatus.OPTIMAL
    assert abs(sol.objective + 9 / 8) < 1e-6


def test_a_translated_program_is_not_called_unbounded():
    """The same annulus translated by 1000 (coefficients that cancel: no power-of-two scaling balances them) was
    "unbounded" too; its ray fails the balanced check.  No claim is made (sospoly.minimize translates exactly,
    solve_program does not)."""
    x, y = sp.variables("x y")
    X, Y = x - 1000.0, y - 1000.0
    prog = sp.SOSProgram(("x", "y"))
    c = prog.scalar("c")
    s1, s2 = prog.sos_poly(2, name="s1"), prog.sos_poly(2, name="s2")
    prog.add_sos(X**4 + Y**4 - 3 * X * Y - c - s1 * (X**2 + Y**2 - 1) - s2 * (4 - X**2 - Y**2), name="u")
    prog.maximize(c)
    sol = sp.solve_program(prog)
    assert sol.status != sp.SolveStatus.UNBOUNDED
    if sol.status == sp.SolveStatus.OPTIMAL:
        assert abs(sol.objective + 9 / 8) < 1e-6


def test_balance_is_an_exact_equivalence():
    """Balance maps a solution of the balanced program back exactly (powers of two): q'^T x' = q^T x, the slack
    of the balanced program is R times the original's."""
    from sospoly.solvers.balance import balancing

    P = sp.lower(_annulus_program(1000.0))
    bal = balancing(P)
    assert bal is not None
    Q = bal.problem(P)
    rng = np.random.default_rng(0)
    xp = rng.normal(size=P.n_cols)
    x = bal.x(xp)
    assert np.array_equal(x / bal.cols, xp)
    assert np.isclose(float(Q.q @ xp), float(P.q @ x), rtol=1e-12)
    assert np.allclose(Q.b - Q.A @ xp, bal.rows * (P.b - P.A @ x), rtol=1e-9, atol=1e-9 * np.abs(Q.b).max())
    assert set(np.log2(bal.rows).tolist()) <= set(range(-400, 401)) and np.all(np.log2(bal.cols) % 1 == 0)


@pytest.mark.parametrize("field, bad", [("objective_sign=1.0", "objective_sign=nan"),
                                        ("objective_offset=0.0", "objective_offset=inf")])
def test_sdpa_header_with_a_non_finite_objective_is_refused(tmp_path, field, bad):
    """Review 39b A5: an SDPA file whose sospoly header says objective_sign=nan (or offset inf) was read and
    solved to an "optimal" NaN objective; now a ValueError naming file:line."""
    x, = sp.variables("x")
    prog = sp.SOSProgram(("x",))
    a = prog.scalar("a")
    prog.add_inequality(3 - a)
    prog.minimize(a)
    p = tmp_path / "q.dat-s"
    sp.lower(prog).to_sdpa(p)
    text = p.read_text()
    assert field in text
    p.write_text(text.replace(field, bad))
    with pytest.raises(ValueError, match=r"q\.dat-s:\d+: objective_(sign|offset) is not finite"):
        sp.ConicProblem.from_sdpa(p)


def _look_at(C):
    from tests.test_uncertainty import look_at      # (a camera at C looking at the origin, f = 800, pp (320, 240))

    return look_at(np.asarray(C, float))


def _three_views():
    rng = np.random.default_rng(5)
    P = np.array([_look_at(np.array(C)) for C in ([5., 0, 0], [0, 5., .5], [-3, -4, 1.])])
    Xt = np.array([.1, .2, -.1])
    x = np.array([(p @ np.append(Xt, 1))[:2] / (p @ np.append(Xt, 1))[2] for p in P]) + rng.normal(size=(3, 2))
    return P, x, Xt


def _point_optimum(P, x, X0):
    from scipy.optimize import least_squares

    def resid(X):
        h = P @ np.append(X, 1.0)
        return (h[:, :2] / h[:, 2:] - x).ravel()

    best = min((least_squares(resid, X0 + d, method="lm", xtol=1e-15, ftol=1e-15)
                for d in (np.zeros(3), np.full(3, 0.3), np.array([-0.5, 0.2, 0.4]))), key=lambda r: r.cost)
    return float(np.sqrt(2 * best.cost / (2 * len(P))))


@pytest.mark.parametrize("D", [1e-200, 1e-160, 1e-40])
def test_a_tiny_disc_is_never_the_whole_plane(D):
    """Review 39a F5 (HIGH): Ellipse(x0, 1e-200 I) (radius 1e-100 px) in a batch was "optimal" at gamma_ub 0.27211,
    the optimum *without* that view, at an X where gamma is 0.752 (the true optimum, the point problem's, 0.41500):
    the closest point on the ellipse overflowed (alpha^2 = 1e400), the Newton step was NaN and the projection came
    back inside.  Now solved in the units of the ellipse's axis: single calls, batches and robust batches certify
    the point problem's optimum (scipy least squares, the reference), and gamma_ub is gamma at X."""
    import tritools
    from tritools import Ellipse, Point

    P, x, Xt = _three_views()
    ref = _point_optimum(P, x, Xt)
    regions = [Ellipse(x[0], D * np.eye(2)), Point(x[1]), Point(x[2])]
    results = [tritools.triangulate(P, regions), tritools.triangulate_many([(P, regions)], progress=False)[0],
               tritools.triangulate_many([(P, regions)], robust=5.0, progress=False)[0]]
    for r in results:
        assert r.gamma_lb is None or r.gamma_lb <= ref * (1 + 1e-9)
        assert abs(tritools.gamma(r.X, P, regions) - r.gamma_ub) <= 1e-9 * max(1.0, r.gamma_ub)
        if r.optimal:
            assert r.gamma_ub <= ref * (1 + 1e-7)
    assert results[1].optimal


def test_closest_point_on_a_tiny_ellipse_is_on_it():
    """closest_on_ellipses for axes 1e-100 .. 1e-150 (alpha^2 beyond the float range): Y on the ellipse's border
    (to its own scale), t > 0, and the same numbers as before for an ordinary ellipse (exact power-of-two units)."""
    from tritools.solve.regions_verify import closest_on_ellipses

    U = np.array([[0.3, -1.7], [2.0, 0.5]])
    for s in (1e-100, 1e-150):
        sigma = np.array([[s, 2 * s], [3 * s, s]])
        Y, t = closest_on_ellipses(U, sigma)
        assert np.all(t > 0) and np.all(np.isfinite(Y))
        level = np.sum((Y / sigma) ** 2, axis=-1)
        assert np.allclose(level, 1.0, rtol=1e-9)
    sigma = np.array([[0.5, 2.0], [3.0, 1.0]])
    U = np.array([[0.3, -1.7], [4.0, 0.5]])                      # both outside
    Y, t = closest_on_ellipses(U, sigma)
    assert np.allclose(np.sum((Y / sigma) ** 2, axis=-1), 1.0, rtol=1e-12) and np.all(t > 0)


def test_too_many_variables_are_refused_before_any_name_is_built():
    """Review 39b A9: variables("w", n=10**9) built a billion names (> 30 s) before the MAX_VARIABLES check.  The
    count is refused first: an n whose int() would start building the names is never converted."""
    from sospoly.algebra.polynomial import MAX_VARIABLES

    class Huge(int):
        def __int__(self):
            raise AssertionError("the names were being built")

    with pytest.raises(ValueError, match="MAX_VARIABLES"):
        sp.variables("w", n=Huge(10**9))
    assert MAX_VARIABLES < 10**9 and len(sp.variables("w", n=100)) == 100


@pytest.mark.parametrize("spoil", ["underscore_id", "underscore_xyz", "nul"])
def test_colmap_text_numbers_are_colmaps_not_pythons(tmp_path, spoil):
    """Review 39b B3: the text reader took "1_0" as 10 (Python's digit separator; COLMAP's reader does not) and
    ignored NUL bytes; both are a format error naming points3D.txt:line now."""
    from tests.test_colmap import synthetic_model
    from tritools.io.colmap import ModelFormatError
    from tritools.io.colmap.formats import read_model, read_model_arrays, write_model

    model, _ = synthetic_model(n_points=4)
    folder = write_model(model, tmp_path / "m", "txt")
    p = folder / "points3D.txt"
    lines = p.read_text().splitlines()
    k = next(i for i, ln in enumerate(lines) if ln and not ln.startswith("#"))
    fields = lines[k].split(" ")
    if spoil == "underscore_id":
        fields[0] = fields[0][0] + "_" + fields[0][1:] if len(fields[0]) > 1 else "1_0"
    elif spoil == "underscore_xyz":
        fields[1] = "1_0.5"
    else:
        fields[2] = fields[2] + "\x00"
    lines[k] = " ".join(fields)
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(ModelFormatError, match=r"points3D\.txt:\d+"):
        read_model(folder)
    with pytest.raises(ModelFormatError, match=r"points3D\.txt:\d+"):
        read_model_arrays(folder)                              # the chunked reader of `tritools colmap`


@pytest.mark.parametrize("kind", ["point_disc", "disc_point"])
def test_an_unbounded_set_with_a_point_view_is_reported_unbounded(kind):
    """Review 39a F4: a point and a 3 px disc seen by cameras 0.01 apart at depth 6 (disparity 1.3 px: every point
    far along the point's ray stays in the disc, in front of both) was ``failed`` (box = whole space): the solver's
    float ray leaves the point's round-off disc.  Each view's own centre ray is tried too, exactly (recedes): the set
    is ``unbounded`` with its finite sides, and it holds the true X and the far points of that ray (the reference,
    checked with tritools.project only)."""
    import tritools

    P = np.array([_look_at(np.array([0.0, 0, -6])), _look_at(np.array([0.01, 0, -6]))])
    X = np.array([0.1, -0.2, 0.3])
    x = [tritools.project(X, p) for p in P]
    regs = [tritools.Point(x[0]), tritools.Ellipse.circle(x[1] + [0.4, -0.3], 3.0)]
    C0 = np.array([0.0, 0, -6])
    if kind == "disc_point":
        P, regs, x = P[::-1].copy(), regs[::-1], x[::-1]
    res = tritools.uncertainty(P, regs)
    assert res.status.value == "unbounded"
    assert np.all(res.lo <= X) and np.all(X <= res.hi)
    assert np.isfinite(res.lo).any() or np.isfinite(res.hi).any()           # a finite near side is reported
    for s in (1e1, 1e3, 1e6):
        Y = X + s * (X - C0)
        assert np.linalg.norm(tritools.project(Y, P[0 if kind == "point_disc" else 1]) - regs[0 if kind ==
                              "point_disc" else 1].center) < 1e-6 * max(1.0, s)
        assert np.all(res.lo <= Y) and np.all(Y <= res.hi)
