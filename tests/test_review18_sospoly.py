"""Review 18 (sospoly): an unchecked unboundedness ray claimed c* = +inf on a bounded problem; a minimize call past
its deadline was reported as a numerical error; multiplier="free" with sparsity="auto" raised on decoupled
variables."""
import dataclasses
import types

import numpy as np
import pytest

import sospoly as sp
from sospoly.budget import Deadline
from sospoly.status import SolveStatus


def test_no_infinite_bound_from_an_unchecked_ray():
    x, y = sp.variables("x y")
    for s in (1.0, 1e8):                      # Clarabel reported dual infeasibility at 1e8 (true minimum 1e8)
        lb = sp.solve_psatz(sp.build_psatz(s * ((x - 1) ** 2 + (y + 2) ** 2), ineq=[x - 2], degree=4,
                                           multiplier="putinar"))
        assert lb.lower_bound is None or lb.lower_bound <= s * (1 + 1e-6)
        assert lb.status != SolveStatus.UNBOUNDED
    for kw in ({"ineq": [-1 - x ** 2]}, {"eq": [x ** 2 + 1]}):     # empty sets: the ray holds, +inf stays
        lb = sp.solve_psatz(sp.build_psatz((x - 1) ** 2 + y ** 2, degree=2, multiplier="putinar", **kw))
        assert lb.status == SolveStatus.UNBOUNDED and lb.lower_bound == np.inf


def test_check_unbounded_ray_rejects_what_leaves_the_cones():
    from sospoly.lowering.conic import ConicProblem
    from sospoly.solvers.solve import check_unbounded_ray

    x, = sp.variables("x")
    ps = sp.build_psatz((x - 1) ** 2, ineq=[-1 - x ** 2], degree=2, multiplier="putinar")
    prob = sp.CompiledPsatz(ps.structure, sp.GramForm.IMAGE).problem_from_theta(ps.theta)
    assert isinstance(prob, ConicProblem)
    sol = sp.solve_psatz(ps)
    assert sol.status == SolveStatus.UNBOUNDED
    ok, why = check_unbounded_ray(prob, np.zeros(prob.n_cols), sp.DEFAULT_TOLERANCES)
    assert not ok and "no ray" in why
    ok, _ = check_unbounded_ray(prob, None, sp.DEFAULT_TOLERANCES)
    assert not ok


def test_minimize_past_its_deadline_says_time_limit():
    from sospoly.minimize import _finish

    x, = sp.variables("x")
    best = sp.minimize((x - 1) ** 2, degree=2)
    assert best.optimal
    run = types.SimpleNamespace(deadline=Deadline.after(0.0), attempts=[])
    for status in (SolveStatus.NUMERICAL_ERROR, SolveStatus.UNPROVEN, SolveStatus.CHECK_FAILED):
        failed = dataclasses.replace(best, status=status, optimal=False)
        assert _finish(failed, run, 1.0).status == SolveStatus.TIME_LIMIT
    for status in (SolveStatus.INFEASIBLE, SolveStatus.BUDGET_EXCEEDED):
        verdict = dataclasses.replace(best, status=status, optimal=False)
        assert _finish(verdict, run, 1.0).status == status
    assert _finish(best, run, 1.0).status == SolveStatus.OPTIMAL       # certified stays certified


def test_free_multiplier_with_auto_sparsity_on_decoupled_variables():
    x, y = sp.variables("x y")
    r = sp.minimize((x - 1) ** 2 + (y + 2) ** 2, ineq=[x - 2], multiplier="free")
    assert r.lower_bound is not None and r.lower_bound <= 1.0 + 1e-9
    assert r.status == SolveStatus.OPTIMAL and r.sparsity == "dense"


def test_ray_check_does_not_depend_on_the_objective_scale():
    # review 3 of wave 18: normalising q^T d = -1 shrank d under a large objective until any violation hid under
    # the margin's absolute floor; min s x s.t. x >= 0 is bounded for every s > 0 and d = -1 is no ray of it
    import scipy.sparse as sps

    from sospoly.lowering.conic import Cone, ConicProblem
    from sospoly.solvers.solve import check_unbounded_ray

    for s in (1e-9, 1.0, 1e9):
        prob = ConicProblem(q=np.array([s]), A=sps.csc_matrix(np.array([[-1.0]])), b=np.zeros(1),
                            cones=(Cone("nonneg", 1),), n_program_vars=1, psd_blocks=())
        ok, why = check_unbounded_ray(prob, np.array([-1.0]), sp.DEFAULT_TOLERANCES)
        assert not ok and "nonneg cone 0" in why
        ok, _ = check_unbounded_ray(prob, np.array([1.0]), sp.DEFAULT_TOLERANCES)
        assert not ok                                       # a feasible direction that does not descend
        flip = ConicProblem(q=np.array([-s]), A=prob.A, b=prob.b, cones=prob.cones, n_program_vars=1,
                            psd_blocks=())
        for d in (1e-6, 1.0, 1e6):                          # min -s x s.t. x >= 0: d > 0 is a ray at any length
            ok, why = check_unbounded_ray(flip, np.array([d]), sp.DEFAULT_TOLERANCES)
            assert ok, why


@pytest.mark.parametrize("backend", ["clarabel", "cvxpy"])
def test_empty_sets_are_proved_empty_by_every_backend(backend):
    # review 3 of wave 18: cvxpy reports unboundedness without a ray, so the ray check made every empty set a
    # numerical error there; the back-end now finds the ray (a homogeneous program) for the check
    if backend == "cvxpy":
        pytest.importorskip("cvxpy")
    x, y = sp.variables("x y")
    for kw in ({"ineq": [-1 - x ** 2]}, {"eq": [x ** 2 + 1]}, {"ineq": [x - 1, -x]}):
        lb = sp.solve_psatz(sp.build_psatz((x - 1) ** 2 + y ** 2, degree=2, multiplier="putinar", **kw),
                            backend=backend)
        assert lb.status == SolveStatus.UNBOUNDED and lb.lower_bound == np.inf, lb.message
    bounded = sp.solve_psatz(sp.build_psatz((x - 1) ** 2 + y ** 2, degree=2, ineq=[x - 2], multiplier="putinar"),
                             backend=backend)
    assert bounded.lower_bound is not None and bounded.lower_bound <= 1.0 + 1e-6


def test_ray_check_measures_each_cone_against_its_own_terms():
    # review 4: measured against the largest term of all cones, cancelling terms of another row (1e9 x2 - 1e9 x3)
    # or cones rescaled apart (1e-6 beside 1e6) let a violated cone pass; a zero row was checked absolutely
    import scipy.sparse as sps

    from sospoly.lowering.conic import Cone, ConicProblem
    from sospoly.solvers.rays import check_unbounded_ray

    T = sp.DEFAULT_TOLERANCES
    A = sps.csc_matrix(np.array([[-1.0, 0, 0], [0, 1e9, -1e9]]))      # min x1 s.t. x1 >= 0, 1e9 (x2 - x3) = 0
    prob = ConicProblem(q=np.array([1.0, 0, 0]), A=A, b=np.zeros(2), cones=(Cone("nonneg", 1), Cone("zero", 1)),
                        n_program_vars=3, psd_blocks=())
    for t in (0.0, 1e-3, 1.0, 1e3):
        assert not check_unbounded_ray(prob, np.array([-1.0, t, t]), T)[0]
    for s in (1e-6, 1.0, 1e6):                                         # PSD cone scaled by s, a big zero row
        A2 = sps.csc_matrix(np.array([[-s, 0, 0], [0, 0, 0], [-s, 0, 0], [0, 1e6, 1e6]]))
        prob2 = ConicProblem(q=np.array([1.0, 0, 0]), A=A2, b=np.zeros(4), cones=(Cone("psd", 3, 2), Cone("zero", 1)),
                             n_program_vars=3, psd_blocks=())
        assert not check_unbounded_ray(prob2, np.array([-1.0, 1e3, -1e3]), T)[0]
        assert check_unbounded_ray(dataclass_q(prob2, [-1.0, 0, 0]), np.array([1.0, 1e3, -1e3]), T)[0]
    zero = ConicProblem(q=np.array([-1.0, 0.0]), A=sps.csc_matrix(np.array([[1e-8, 0.0]])), b=np.zeros(1),
                        cones=(Cone("zero", 1),), n_program_vars=2, psd_blocks=())
    assert not check_unbounded_ray(zero, np.array([1.0, 1.0]), T)[0]    # min -x1 s.t. 1e-8 x1 = 0: bounded
    free = ConicProblem(q=np.array([0.0, 1.0]), A=sps.csc_matrix(np.array([[-1.0, 0.0]])), b=np.zeros(1),
                        cones=(Cone("nonneg", 1),), n_program_vars=2, psd_blocks=())
    assert check_unbounded_ray(free, np.array([0.0, -1.0]), T)[0]      # A d = 0, q^T d < 0: a ray


def dataclass_q(prob, q):
    return dataclasses.replace(prob, q=np.asarray(q, float))


def test_infeasible_only_with_a_checked_farkas_certificate():
    # review 4: Clarabel's unchecked PrimalInfeasible on rescaled feasible programs (14 of 200 random ones) was
    # reported `infeasible`; a certificate z in K*, A^T z = 0, b^T z < 0 is now checked like a ray
    import scipy.sparse as sps

    from sospoly.lowering.conic import Cone, ConicProblem
    from sospoly.solvers.rays import check_infeasibility
    from sospoly.solvers.solve import solve_conic_problem

    T = sp.DEFAULT_TOLERANCES
    for s in (1e-6, 1.0, 1e6):                  # x >= 1 and x <= 0, rows scaled apart: infeasible at every scale
        prob = ConicProblem(q=np.array([1.0]), A=sps.csc_matrix(np.array([[-1.0], [s]])), b=np.array([-1.0, 0.0]),
                            cones=(Cone("nonneg", 2),), n_program_vars=1, psd_blocks=())
        assert solve_conic_problem(prob).status == SolveStatus.INFEASIBLE
        assert check_infeasibility(prob, np.array([1.0, 1.0 / s]), T)[0]
        assert not check_infeasibility(prob, np.array([1.0, 0.5 / s]), T)[0]     # A^T z != 0
        assert not check_infeasibility(prob, np.array([-1.0, -1.0 / s]), T)[0]   # outside K*, b^T z > 0
    feasible = ConicProblem(q=np.array([1.0]), A=sps.csc_matrix(np.array([[-1.0], [1.0]])), b=np.array([-1.0, 2.0]),
                            cones=(Cone("nonneg", 2),), n_program_vars=1, psd_blocks=())
    assert not check_infeasibility(feasible, np.array([1.0, 1.0]), T)[0]        # b^T z = 1 > 0
    assert solve_conic_problem(feasible).status == SolveStatus.OPTIMAL
    x, y = sp.variables("x y")
    motzkin = x ** 4 * y ** 2 + x ** 2 * y ** 4 - 3 * x ** 2 * y ** 2 + 1
    assert not sp.is_sos(motzkin).is_sos                                         # the classic non-SOS polynomial


@pytest.mark.parametrize("backend", ["cvxpy", "cvxpy:SCS"])
def test_cvxpy_infeasibility_comes_with_a_checked_certificate(backend):
    # cvxpy reports infeasibility without a certificate; the back-end finds one (a feasibility program) and the
    # check verifies it: infeasible programs stay infeasible, and a Psatz program's non-SOS answer stays a "no"
    pytest.importorskip("cvxpy")
    import scipy.sparse as sps

    from sospoly.lowering.conic import Cone, ConicProblem
    from sospoly.solvers.solve import solve_conic_problem

    for s in (1e-3, 1.0, 1e3):
        prob = ConicProblem(q=np.array([1.0]), A=sps.csc_matrix(np.array([[-1.0], [s]])), b=np.array([-1.0, 0.0]),
                            cones=(Cone("nonneg", 2),), n_program_vars=1, psd_blocks=())
        r = solve_conic_problem(prob, backend=backend)
        assert r.status == SolveStatus.INFEASIBLE, r.message
    x, y = sp.variables("x y")
    motzkin = x ** 4 * y ** 2 + x ** 2 * y ** 4 - 3 * x ** 2 * y ** 2 + 1
    assert not sp.is_sos(motzkin, backend=backend).is_sos
