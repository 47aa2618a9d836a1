"""Exact basis reductions (sospoly.certificates.reduction): what they drop, that the bound is unchanged, that
the bound stays below independent minima, and the inaccurate-iterate policy of Tolerances."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import sospoly
from sospoly import Polynomial, SolveStatus, Tolerances, variables
from sospoly.certificates.reduction import leading_monomial
from sospoly.solvers.backends import Attempt, ConicSolution, RawStatus
from sospoly.solvers.solve import solve_conic


def _supports(*polys):
    return [np.array(sorted(p.terms), dtype=np.int64) for p in polys]


def _rows(B) -> set:
    return {tuple(int(k) for k in r) for r in np.asarray(B)}


def _bound(f, eq, ineq, degree, shape):
    ps = sospoly.build_psatz(f, eq, ineq, degree, "fixed", gens=f.gens, sparsity=shape)
    lb = sospoly.solve_psatz(ps, backend="clarabel", prove=False)     # the numerical c* (what the reductions keep)
    assert lb.status == SolveStatus.OPTIMAL, lb.message
    return lb.lower_bound, ps


# ----------------------------------------------------------------------------- what is dropped
def test_diagonal_reduction_drops_monomials_no_term_can_reach():
    # min x^2 + y^2 s.t. x y = 1 at degree 4: nothing but G[x^2, x^2] reaches x^4 (r (x y - 1) has x-degree <= 3)
    x, y = variables("x y")
    f, g = x ** 2 + y ** 2, x * y - 1
    shape = sospoly.dense_shape(2, 4, [2])
    red = sospoly.diagonal_reduction(shape, *_supports(f), _supports(g), ())
    dropped = _rows(shape.u_bases[0]) - _rows(red.u_bases[0])
    assert dropped == {(2, 0), (0, 2)}
    assert (1, 1) in _rows(red.u_bases[0])          # x^2 y^2 is reached by r (x y - 1): kept


def test_ideal_reduction_drops_multiples_of_the_leading_monomial():
    x, y, z = variables("x y z")
    g = x ** 2 + y ** 2 + z ** 2 - 1
    assert tuple(leading_monomial(_supports(g)[0])) == (2, 0, 0)
    shape = sospoly.dense_shape(3, 4, [2])
    red = sospoly.ideal_reduction(shape, _supports(g))
    assert _rows(shape.u_bases[0]) - _rows(red.u_bases[0]) == {(2, 0, 0)}
    # degree <= 1 monomials (first-order moments) are never dropped, and nothing is dropped without room in r
    assert {(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)} <= _rows(red.u_bases[0])
    narrow = replace(shape, r_supports=(np.zeros((1, 3), np.int64),))
    assert sospoly.ideal_reduction(narrow, _supports(g)) is narrow


def test_reduction_is_requested_by_the_shape_and_applied_against_the_data():
    x, y = variables("x y")
    f, g = x ** 2 + y ** 2, x * y - 1
    shape = sospoly.dense_shape(2, 4, [2])
    ps = sospoly.build_psatz(f, [g], [], 4, "fixed", gens=f.gens, sparsity=shape.reduced())
    assert ps.structure.shape.facial_reduction
    assert ps.structure.shape.u_bases[0].shape[0] < shape.u_bases[0].shape[0]
    assert shape.reduced().key != shape.key


# ----------------------------------------------------------------------------- the bound is unchanged
def test_reduced_bound_equals_the_known_minimum_and_the_unreduced_bound():
    x, y = variables("x y")
    f, g = x ** 2 + y ** 2, x * y - 1                  # minimum 2 at x = y = +-1
    shape = sospoly.dense_shape(2, 4, [2])
    full, _ = _bound(f, [g], [], 4, shape)
    red, ps = _bound(f, [g], [], 4, shape.reduced())
    assert red == pytest.approx(2.0, abs=1e-6)
    assert red == pytest.approx(full, abs=1e-6)
    assert ps.n_lmivar < sospoly.build_psatz(f, [g], [], 4, "fixed", gens=f.gens, sparsity=shape).n_lmivar


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_quadratic_form_on_the_sphere(seed):
    # min v^T A v on the unit sphere is lambda_min(A) exactly; the degree-4 bound with both reductions is exact
    rng = np.random.default_rng(seed)
    M = rng.normal(size=(3, 3))
    A = M + M.T
    v = variables("x y z")
    f = Polynomial(v[0].gens, {})
    for i in range(3):
        for j in range(3):
            f = f + float(A[i, j]) * v[i] * v[j]
    g = v[0] ** 2 + v[1] ** 2 + v[2] ** 2 - 1
    shape = sospoly.dense_shape(3, 4, [2])
    full, _ = _bound(f, [g], [], 4, shape)
    red, _ = _bound(f, [g], [], 4, shape.reduced())
    lam = float(np.linalg.eigvalsh(A)[0])
    assert red == pytest.approx(lam, abs=1e-6)
    assert red == pytest.approx(full, abs=1e-6)


def test_reduced_certificates_on_a_chain_stay_below_the_minimum():
    # min (a - 2)^2 + (b - 1)^2 + (c + 1)^2 s.t. a b = 1, b c = 1: on the feasible set b = t, a = c = 1/t, so
    # the minimum is a one-dimensional search.  The dense degree-4 bound is exact with and without the
    # reductions; the clique certificate (cliques {a, b}, {b, c}) is weaker but must stay below it.  Without the
    # reductions that clique program has no interior and the solver stops short ("almost solved").
    v = variables("a b c")
    f = (v[0] - 2) ** 2 + (v[1] - 1) ** 2 + (v[2] + 1) ** 2
    eq = [v[0] * v[1] - 1, v[1] * v[2] - 1]
    t = np.concatenate([np.linspace(-50, -1e-3, 200001), np.linspace(1e-3, 50, 200001)])
    fmin = float(np.min((1 / t - 2) ** 2 + (t - 1) ** 2 + (1 / t + 1) ** 2))
    dense = sospoly.dense_shape(3, 4, [2, 2])
    full, _ = _bound(f, eq, [], 4, dense)
    red, _ = _bound(f, eq, [], 4, dense.reduced())
    assert red == pytest.approx(full, abs=1e-6)
    assert red == pytest.approx(fmin, abs=1e-5) and red <= fmin + 1e-7
    cl = sospoly.clique_shape(3, 4, [(0, 1), (1, 2)], [{0, 1}, {1, 2}], [], [2, 2], [], low_degree=2)
    clique, _ = _bound(f, eq, [], 4, cl.reduced())
    assert clique <= red + 1e-7


# ----------------------------------------------------------------------------- the inaccurate-iterate policy
def test_tolerances_accept_inaccurate_is_a_validated_flag():
    assert Tolerances().accept_inaccurate is False
    with pytest.raises(ValueError, match="accept_inaccurate"):
        Tolerances(accept_inaccurate=1)


class _AlmostBackend:
    """Returns a fixed iterate with Clarabel's 'almost solved' status."""

    def __init__(self, x):
        self.x = x

    def solve(self, problem, accept=None, retry=True, deadline=None):
        att = Attempt("fake", RawStatus.ALMOST_SOLVED, "AlmostSolved", 1, 0.0)
        return ConicSolution(RawStatus.ALMOST_SOLVED, self.x, np.zeros(problem.n_rows), 0.0, 0.0, (att,))


def test_an_inaccurate_iterate_is_returned_only_on_request_and_never_as_optimal():
    x, y = variables("x y")
    f, g = x ** 2 + y ** 2, x * y - 1
    ps = sospoly.build_psatz(f, [g], [], 2, "fixed", gens=f.gens)
    good = sospoly.solve_psatz(ps, backend="clarabel")
    assert good.status == SolveStatus.OPTIMAL
    comp = sospoly.CompiledPsatz(ps.structure)
    problem = comp.problem_from_theta(ps.theta)
    xs = np.zeros(problem.n_cols)
    xs[: good.solution.x.size] = good.solution.x
    status, sol, mins, _, _ = solve_conic(problem, _AlmostBackend(xs))
    assert status == SolveStatus.INACCURATE and not mins
    status, sol, mins, _, msg = solve_conic(problem, _AlmostBackend(xs), Tolerances(accept_inaccurate=True))
    assert status == SolveStatus.INACCURATE and mins and "checks passed" in msg
    bad = xs.copy()
    bad[:] = 1e3 * np.sign(np.arange(bad.size) % 2 - 0.5)       # far from any certificate: the check refuses it
    status, *_ = solve_conic(problem, _AlmostBackend(bad), Tolerances(accept_inaccurate=True))
    assert status == SolveStatus.CHECK_FAILED
    lb = sospoly.solve_psatz(ps, backend=_AlmostBackend(xs), tolerances=Tolerances(accept_inaccurate=True))
    assert lb.status == SolveStatus.INACCURATE and lb.lower_bound is None
    assert lb.solution.objective == pytest.approx(good.lower_bound, abs=1e-8)
