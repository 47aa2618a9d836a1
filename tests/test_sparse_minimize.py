"""sospoly at scale (issue #11): the default ``minimize`` on large sparse programs, against references
independent of sospoly -- known minima from the literature (source next to each), brute force and
multi-start local search on small cases, dynamic programming on chains, numpy re-implementations of
the objectives, and closed-form program sizes."""
from __future__ import annotations

import importlib.util
import itertools
import math
import pathlib

import numpy as np
import pytest
from scipy.optimize import minimize as sp_minimize

import sospoly as sp
from sospoly import DEFAULT_TOLERANCES as TOL, SolveStatus
from sospoly.analysis.complexity import n_lmivar_cliques, n_lmivar_shape
from sospoly.certificates.sparsity import correlative_sparsity

ROOT = pathlib.Path(__file__).resolve().parents[1]


def _load_benchmark():
    spec = importlib.util.spec_from_file_location("bench_sparse", ROOT / "benchmarks" / "sparse.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


BENCH = _load_benchmark()


# ----------------------------------------------------------------------------- numpy references
def rosenbrock_np(x):
    """Generalised Rosenbrock with the leading 1 (Waki, Kim, Kojima, Muramatsu 2006, SIAM J. Optim. 17(1),
    218-242); f* = 1 at (+-1, 1, ..., 1): f - 1 is a sum of squares vanishing exactly there."""
    x = np.asarray(x, float)
    return 1.0 + float(np.sum(100 * (x[1:] - x[:-1] ** 2) ** 2 + (1 - x[1:]) ** 2))


def chained_singular_np(x):
    """Chained singular function (Conn, Gould, Toint 1988, Math. Comp. 50, 399-430); f* = 0 at 0."""
    x = np.asarray(x, float)
    i = np.arange(0, x.size - 3, 2)
    return float(np.sum((x[i] + 10 * x[i + 1]) ** 2 + 5 * (x[i + 2] - x[i + 3]) ** 2
                        + (x[i + 1] - 2 * x[i + 2]) ** 4 + 10 * (x[i] - x[i + 3]) ** 4))


def broyden_np(x):
    """Broyden tridiagonal function (Moré, Garbow, Hillstrom 1981, problem 30); f* = 0."""
    x = np.asarray(x, float)
    xp = np.concatenate([[0.0], x, [0.0]])
    return float(np.sum(((3 - 2 * x) * x - xp[:-2] - 2 * xp[2:] + 1) ** 2))


def multistart(fun, n, starts=12, seed=0, scale=2.0):
    """Best local minimum of ``fun`` from seeded random starts (BFGS, numerical gradients)."""
    rng = np.random.default_rng(seed)
    best = math.inf
    for x0 in rng.uniform(-scale, scale, size=(starts, n)):
        best = min(best, float(sp_minimize(fun, x0, method="BFGS", options={"gtol": 1e-10}).fun))
    return best


def box_radius(name: str, n: int) -> float:
    """A bound of a global minimiser's norm (the box of minimize's proven bound, #23): chained singular's is 0,
    every other benchmark's minimisers lie in [-1, 1]^n."""
    return 1.0 if name == "chained_singular" else math.sqrt(n) + 1.0


def certified_at(res, fstar, f_np=None, rel=1e-6):
    """The result is certified, its lower bound is <= f* (up to the gap tolerance at the problem's scale)
    and within it, and (with ``f_np``) the reported upper bound is f at the first minimiser."""
    slack = TOL.gap_abs * res.scale + TOL.gap_rel * max(res.scale, abs(fstar))
    assert res.status == SolveStatus.OPTIMAL and res.optimal, res
    assert res.lower_bound <= fstar + slack, (res.lower_bound, fstar)
    assert res.lower_bound >= fstar - slack - rel * max(1.0, abs(fstar)), (res.lower_bound, fstar)
    assert res.upper_bound >= fstar - slack
    if f_np is not None:
        assert math.isclose(f_np(res.minimizers[0]), res.upper_bound, rel_tol=1e-9, abs_tol=1e-9)


# ----------------------------------------------------------------------------- reference checks
def test_references_independent_of_sospoly():
    """The numpy objectives equal the benchmark's sospoly polynomials, and multi-start local search does
    not beat the known minima on small cases."""
    rng = np.random.default_rng(1)
    for build, f_np in ((BENCH.rosenbrock, rosenbrock_np), (BENCH.chained_singular, chained_singular_np),
                        (BENCH.broyden, broyden_np)):
        f, _, _, fstar = build(8)
        for p in rng.normal(size=(3, 8)):
            assert math.isclose(f(p), f_np(p), rel_tol=1e-12, abs_tol=1e-12)
        assert multistart(f_np, 8) >= fstar - 1e-8
    assert rosenbrock_np(np.ones(8)) == 1.0 and chained_singular_np(np.zeros(8)) == 0.0


def test_constrained_chain_references_by_brute_force():
    """Bilinear chain on the box: a multilinear function is minimised at a vertex, so enumeration of
    {-1, 1}^n is exact (-(n - 1)); the Ising chain's dynamic programme equals enumeration."""
    n = 10
    verts = np.array(list(itertools.product((-1.0, 1.0), repeat=n)))
    assert np.min(np.sum(verts[:, :-1] * verts[:, 1:], axis=1)) == -(n - 1)
    J, h = BENCH.ising_data(n, seed=3)
    energies = np.sum(J * verts[:, :-1] * verts[:, 1:], axis=1) + verts @ h
    best, s = BENCH.ising_reference(J, h)
    assert math.isclose(best, energies.min(), abs_tol=1e-12)
    assert math.isclose(float(np.sum(J * s[:-1] * s[1:]) + s @ h), best, abs_tol=1e-12)


# ----------------------------------------------------------------------------- the targets
def test_rosenbrock_40_default_call():
    """Generalised Rosenbrock, n = 40: certified at f* = 1 by the correlative certificate in seconds, with
    N_LMIVAR under 5% of the dense count."""
    f, eq, ineq, fstar = BENCH.rosenbrock(40)
    res = sp.minimize(f)
    certified_at(res, fstar, rosenbrock_np)
    assert res.sparsity == "correlative" and res.degree == 4
    assert np.allclose(np.abs(res.minimizers[0]), 1.0, atol=1e-4)      # x_1 = +-1: x_1 occurs only squared
    assert np.allclose(res.minimizers[0][1:], 1.0, atol=1e-4)
    assert res.n_lmivar < 0.05 * sp.n_lmivar_formula(40, 4)
    assert res.seconds < 30
    assert res.attempts[0].backend == "clarabel"          # several Gram blocks: Clarabel's sparse KKT first


def test_chained_singular_40_default_call():
    """Chained singular, n = 40 (degenerate: singular Hessian at the minimiser): certified at 0."""
    f, _, _, fstar = BENCH.chained_singular(40)
    res = sp.minimize(f, radius=1.0)        # the minimiser is 0: the box of the proven bound (#23)
    certified_at(res, fstar, chained_singular_np)
    assert res.sparsity == "correlative"
    assert np.allclose(res.minimizers[0], 0.0, atol=1e-3)
    assert res.n_lmivar < 0.05 * sp.n_lmivar_formula(40, 4)


def test_broyden_40_default_call():
    """Broyden tridiagonal, n = 40: certified at 0 at degree 4 (its two nearby roots give clique moment
    matrices of rank 2 and 1 that only the greedy join turns into a starting point)."""
    f, _, _, fstar = BENCH.broyden(40)
    res = sp.minimize(f)
    certified_at(res, fstar, broyden_np)
    assert res.sparsity == "correlative" and res.degree == 4
    assert broyden_np(res.minimizers[0]) <= 1e-10


@pytest.mark.parametrize("n", [10, 40])
def test_bilinear_box_chain(n):
    """min sum x_i x_{i+1} on [-1, 1]^n = -(n - 1) (each term >= -1), at x_i = +-(-1)^i."""
    f, eq, ineq, fstar = BENCH.bilinear(n)
    res = sp.minimize(f, eq, ineq)
    certified_at(res, fstar)
    x = res.minimizers[0]
    assert np.allclose(np.abs(x), 1.0, atol=1e-4) and np.all(x[:-1] * x[1:] < 0)


@pytest.mark.parametrize("n, seed", [(12, 0), (40, 1)])
def test_ising_chain(n, seed):
    """Ising chain with fields on x_i^2 = 1 against the dynamic programme: the clique-wise degree-4
    certificate is exact on a chain (cliques of two binary variables, junction tree)."""
    f, eq, ineq, fstar = BENCH.ising(n, seed)
    J, h = BENCH.ising_data(n, seed)
    _, s = BENCH.ising_reference(J, h)
    res = sp.minimize(f, eq, ineq)
    certified_at(res, fstar)
    assert np.allclose(res.minimizers[0], s, atol=1e-4)


def test_floudas_4_10_default_call():
    """Floudas & Pardalos 1990, test 4.10 (Lasserre 2001, Table 3): f* = -5.5080 at (2.3295, 3.1785);
    cross-checked by a feasible grid and SLSQP from its best point."""
    x, y = sp.variables("x y")
    ineq = [2 * x**4 - 8 * x**3 + 8 * x**2 + 2 - y, 4 * x**4 - 32 * x**3 + 88 * x**2 - 96 * x + 36 - y,
            x * (3 - x), y * (4 - y)]
    gx, gy = np.meshgrid(np.linspace(0, 3, 601), np.linspace(0, 4, 801), indexing="ij")
    P = np.column_stack([gx.ravel(), gy.ravel()])
    feas = np.all([h.evaluate(P) >= 0 for h in ineq], axis=0)
    x0 = P[feas][np.argmin(-P[feas].sum(axis=1))]
    ref = sp_minimize(lambda v: -v[0] - v[1], x0, method="SLSQP", options={"ftol": 1e-14},
                      constraints=[{"type": "ineq", "fun": h.evaluate} for h in ineq])
    assert abs(ref.fun + 5.5080) <= 1e-4
    res = sp.minimize(-x - y, ineq=ineq)
    certified_at(res, float(ref.fun))
    assert np.allclose(res.minimizers[0], ref.x, atol=1e-4)


# ----------------------------------------------------------------------------- dense beside sparse
@pytest.mark.parametrize("name, n", [("rosenbrock", 6), ("chained_singular", 6), ("broyden", 8), ("bilinear", 8),
                                     ("ising", 8)])
def test_dense_and_sparse_agree(name, n):
    """Where both run, both certify the known minimum (the sparse bound is valid and tight here; it is not
    in general guaranteed to reach the dense one)."""
    f, eq, ineq, fstar = BENCH.BUILDERS[name](n)
    R = box_radius(name, n)
    auto = sp.minimize(f, eq, ineq, radius=R)
    dense = sp.minimize(f, eq, ineq, degree=auto.degree, sparsity="none", radius=R)
    certified_at(auto, fstar)
    certified_at(dense, fstar)
    assert dense.sparsity == "dense" and dense.n_lmivar == sp.n_lmivar_formula(
        n, auto.degree, [g.degree for g in eq], [h.degree for h in ineq])


def test_multistart_never_beats_the_sparse_bound():
    """Local minima found by multi-start search on small instances lie above the certified lower bound."""
    for build, f_np in ((BENCH.rosenbrock, rosenbrock_np), (BENCH.broyden, broyden_np)):
        f, _, _, _ = build(10)
        res = sp.minimize(f)
        assert multistart(f_np, 10, starts=8, seed=2) >= res.lower_bound - 1e-9


# ----------------------------------------------------------------------------- program sizes
def _clique_count(f, eq, ineq, degree):
    n = len(f.gens)
    cs = correlative_sparsity(n, f.exponents(), [g.exponents() for g in eq], [h.exponents() for h in ineq])
    overlaps = [len(set(c) & set(cs.cliques[p])) if p >= 0 else 0 for c, p in zip(cs.cliques, cs.parents)]
    ps = sp.build_psatz(f, eq, ineq, degree, "putinar", sparsity="correlative")
    closed = n_lmivar_cliques([len(c) for c in cs.cliques], cs.parents, overlaps, degree,
                              [r.shape[0] for r in ps.shape.r_supports], [s.shape[0] for s in ps.shape.s_bases])
    return closed, ps


@pytest.mark.parametrize("name, n, degree", [("rosenbrock", 20, 4), ("chained_singular", 20, 4), ("broyden", 20, 6),
                                             ("bilinear", 12, 4), ("ising", 12, 4)])
def test_clique_closed_form_equals_assembled(name, n, degree):
    f, eq, ineq, _ = BENCH.BUILDERS[name](n)
    closed, ps = _clique_count(f, eq, ineq, degree)
    assert closed == ps.n_lmivar == n_lmivar_shape(ps.shape)


def test_default_certificate_has_no_redundant_dense_block():
    """Without linear equalities the dense degree-2 block beside the cliques adds nothing (its Gram matrix
    has the cliques' chordal pattern, so it splits into clique blocks): the default certificate leaves it
    out -- the closed clique count -- and gets the bound the hybrid gets."""
    f, eq, ineq, _ = BENCH.broyden(12)
    closed, _ = _clique_count(f, eq, ineq, 4)
    auto = sp.minimize(f, degree=4, sparsity="correlative")
    hybrid = sp.minimize(f, degree=4, sparsity="correlative", low_degree=2)
    assert auto.n_lmivar == closed < hybrid.n_lmivar
    assert abs(auto.lower_bound - hybrid.lower_bound) <= 1e-6
    # a linear equality couples cliques through r_k of degree 1 in every variable: the block is kept
    x = sp.variables("x", n=6)
    g = sum(x) - 1.0
    chain = sum((x[i] - x[i + 1]) ** 4 for i in range(5)) + x[0] ** 2
    res = sp.minimize(chain, eq=[g], degree=4, sparsity="correlative")
    _, ps = _clique_count(chain, [g], [], 4)
    assert res.n_lmivar > ps.n_lmivar


def test_dense_40_variable_quartic_exceeds_the_budget():
    """sparsity="none" on a 40-variable quartic is refused before anything is built: a status, no abort."""
    f, _, _, _ = BENCH.chained_singular(40)
    res = sp.minimize(f, sparsity="none")
    assert res.status == SolveStatus.BUDGET_EXCEEDED and res.lower_bound is None and not res.optimal
    assert all(a.status == "budget_exceeded" for a in res.attempts)
    assert "exceeds the memory budget" in res.message
    size = BENCH.dense_size(40, 4, (), ())
    assert size.exceeds(sp.DEFAULT_BUDGET) and size.bytes > 4 * 2**30
    # and a budget too small even for the cliques: every step refused, still a status
    tiny = sp.minimize(f, budget=sp.Budget(max_bytes=1e4))
    assert tiny.status == SolveStatus.BUDGET_EXCEEDED and tiny.lower_bound is None


# ----------------------------------------------------------------------------- term sparsity, Newton polytope
x, y = sp.variables("x y")
MOTZKIN = x**4 * y**2 + x**2 * y**4 - 3 * x**2 * y**2 + 1            # min 0 at (+-1, +-1), not SOS (Motzkin 1967)
CAMEL = 4 * x**2 - 2.1 * x**4 + x**6 / 3 + x * y - 4 * y**2 + 4 * y**4  # f* = -1.0316284535 (Jamil & Yang 2013)
CAMEL_MIN = -1.031628453489877


def test_motzkin_newton_polytope():
    """With q = 1 + x^2 + y^2 (Reznick's multiplier) the Newton polytope of u = q (M - c) keeps 9 of the 15
    monomials of degree <= 4, and certifies the minimum 0."""
    q = 1 + x**2 + y**2
    res = sp.minimize(MOTZKIN, degree=8, sparsity="newton", multiplier=q, radius=2.0)
    dense = sp.minimize(MOTZKIN, degree=8, sparsity="none", multiplier=q, radius=2.0)
    certified_at(res, 0.0)
    certified_at(dense, 0.0)
    assert res.sparsity == "newton" and res.n_lmivar < dense.n_lmivar
    grams = [G for name, G in res.solution.grams.items() if name == "u"]
    assert grams and grams[0].shape == (9, 9)
    # q = 1: M - c is never SOS -- no certificate, never a bound above the minimum
    plain = sp.minimize(MOTZKIN, degree=8, sparsity="newton")
    assert not plain.optimal and (plain.lower_bound is None or plain.lower_bound <= 1e-6)


@pytest.mark.parametrize("sparsity", ["term", "newton"])
@pytest.mark.parametrize("f, fstar", [((1 - x) ** 2 + 100 * (y - x**2) ** 2, 0.0), (CAMEL, CAMEL_MIN),
                                      (x**4 + y**4 + 1 - x * y, 0.875)])
def test_term_and_newton_bounds_are_valid(sparsity, f, fstar):
    """Valid bounds (<= f*, closed forms: Rosenbrock 0; camel; x^4 + y^4 + 1 - xy = 7/8 at x = y = +-1/2) and
    never a crash, whatever the blocks hold (a term-sparsity block may lack 1 or some x_i)."""
    res = sp.minimize(f, sparsity=sparsity, radius=2.0)       # every minimiser has norm <= sqrt 2
    assert res.sparsity.startswith(sparsity)
    assert res.lower_bound is not None and res.lower_bound <= fstar + 1e-6
    if res.upper_bound is not None:
        assert res.upper_bound >= fstar - 1e-9
    if f.degree == 4 and fstar == 0.0:
        certified_at(res, fstar)                # Rosenbrock: one minimiser, the first moments find it


# ----------------------------------------------------------------------------- the benchmark script
def test_benchmark_quick_run(capsys):
    rows = BENCH.main(["--quick", "--problems", "broyden", "ising"])
    out = capsys.readouterr().out
    assert "command: `python benchmarks/sparse.py --quick --problems broyden ising`" in out
    assert "| problem | n | f* |" in out and "exceeds budget" in out
    assert all(r["certified"] and BENCH._valid(r) == "yes" for r in rows)
    dense = [r for r in rows if isinstance(r["dense"], dict)]
    assert dense and all(r["dense"]["certified"] for r in dense)
    assert "4 of 4 programs certified at their known minimum" in out


@pytest.mark.parametrize("name", ["rosenbrock", "chained_singular", "broyden", "bilinear", "ising"])
def test_n100_default_call(name):
    f, eq, ineq, fstar = BENCH.BUILDERS[name](100)
    res = sp.minimize(f, eq, ineq, radius=box_radius(name, 100))
    certified_at(res, fstar)
    assert res.sparsity == "correlative" and res.seconds < 60


@pytest.mark.slow
@pytest.mark.parametrize("name", ["rosenbrock", "chained_singular", "broyden", "bilinear", "ising"])
def test_n200_default_call(name):
    """The issue's largest size: certified well inside the default two-minute budget, about linearly in
    n (N_LMIVAR exactly twice the n = 100 count up to the chain's ends)."""
    f, eq, ineq, fstar = BENCH.BUILDERS[name](200)
    res = sp.minimize(f, eq, ineq, radius=box_radius(name, 200))
    certified_at(res, fstar)
    assert res.sparsity == "correlative" and res.seconds < 60
    half = sp.minimize(*BENCH.BUILDERS[name](100)[:3], radius=box_radius(name, 100))
    assert 1.9 < res.n_lmivar / half.n_lmivar < 2.1
