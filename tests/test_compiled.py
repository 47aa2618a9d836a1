"""Compile once, solve many (sospoly.lowering.compiled) and its use by tritools.

References: the uncompiled path (build_psatz + solve_psatz with Clarabel), the paper's Table 10
(Example 4, Theorem 1 delta = 4: gamma = 0.760, N_LMIVAR = 591) and the paper's N_LMIVAR values.
Tolerance on c: both solvers stop at the 1e-9 solver tolerances, so bounds agree to ~1e-8
relative on these normalised problems (c = O(1e-4 .. 10)); 1e-7 * max(1, |c|) leaves a decade.
"""
import numpy as np
import pytest

import sospoly
from sospoly import SolveStatus
from tritools.model.normalize import normalization_for
from tritools.model.problem import build_problem
from tritools.scene import paper_example, paper_table, random_scene
from tritools.solve.triangulate import STRUCTURE_CACHE, triangulate

RTOL_C = 1e-7


def close(a, b):
    return abs(a - b) <= RTOL_C * max(1.0, abs(b))


def tri_problem(cams, regs, method):
    norm = normalization_for(cams, regs)
    return build_problem(norm.cameras(cams), norm.regions(regs), method)


def uncompiled(f, eq, ineq, degree, gens=None, form="image"):
    ps = sospoly.build_psatz(f, eq, ineq, degree, gens=gens)
    return ps, sospoly.solve_psatz(ps, form=form)


@pytest.mark.parametrize("form", ["image", "kernel"])
def test_random_problems_match_uncompiled(form):
    """Random f, one equality, one inequality in 3 variables: same status, bound and Gram
    certificate (recomputed u(v) = b^T G b) as the uncompiled program, for several instances
    filled into one compiled structure."""
    v = sospoly.variables("a b c")
    rng = np.random.default_rng(7)

    def rand_quad(scale=1.0):
        p = sospoly.Polynomial.constant(float(rng.normal()), v[0].gens)
        for i in range(3):
            p = p + float(rng.normal()) * v[i]
            for j in range(i, 3):
                p = p + scale * float(rng.normal()) * v[i] * v[j]
        return p

    insts = []
    for _ in range(4):
        f = rand_quad() + 3 * (v[0] ** 2 + v[1] ** 2 + v[2] ** 2)
        insts.append((f, [rand_quad(0.3)], [2 - v[0] ** 2 - v[1] ** 2 - v[2] ** 2]))
    comp = sospoly.compile_psatz(*insts[0], degree=2, form=form)
    for f, eq, ineq in insts:
        ps, ref = uncompiled(f, eq, ineq, 2, form=form)
        got = comp.solve(f, eq, ineq, backend="clarabel")
        assert got.status == ref.status
        if ref.status == SolveStatus.OPTIMAL:
            assert close(got.lower_bound, ref.lower_bound)
            assert comp.n_lmivar == ps.n_lmivar
            G = got.solution.grams["u"]
            assert np.linalg.eigvalsh(G)[0] > -1e-7 * max(1.0, np.abs(G).max())


@pytest.mark.parametrize("k, n_lmivar", [(2, 5), (3, 6), (4, 7)])
def test_paper_examples_corollary1_delta2(k, n_lmivar):
    pb = tri_problem(*paper_example(k), "corollary1")
    ps, ref = uncompiled(pb.f, pb.eq, pb.ineq, 2, gens=pb.gens)
    comp = sospoly.compile_psatz(pb.f, pb.eq, pb.ineq, 2, gens=pb.gens)
    assert comp.n_lmivar == ps.n_lmivar == n_lmivar          # the paper's N_LMIVAR (Tables 8-10)
    for backend in ("clarabel", "ipm"):
        got = comp.solve(pb.f, pb.eq, pb.ineq, backend=backend)
        assert got.status == ref.status == SolveStatus.OPTIMAL
        assert close(got.lower_bound, ref.lower_bound)


def test_example4_theorem1_delta4_ipm_matches_clarabel_and_paper():
    cams, regs = paper_example(4)
    res = triangulate(cams, regs, "theorem1", delta=4)          # compiled structure + 'auto' backend
    row = next(r for r in paper_table(4) if r["method"] == "theorem1")
    assert res.optimal and res.n_lmivar == row["n_lmivar"] == 591
    assert abs(res.gamma_ub - row["gamma"]) < 5e-4                # the paper prints 3 decimals
    assert res.attempts[-1].solver[0] == "ipm:converged"
    pb = tri_problem(cams, regs, "theorem1")
    comp, _ = STRUCTURE_CACHE.get(pb.f, pb.eq, pb.ineq, 4, gens=pb.gens,
                                  key=(4, ("Point",) * 4, "theorem1", 4, "image"))
    ipm = comp.solve(pb.f, pb.eq, pb.ineq, backend="ipm")
    clar = comp.solve(pb.f, pb.eq, pb.ineq, backend="clarabel")
    assert ipm.status == clar.status == SolveStatus.OPTIMAL
    assert close(ipm.lower_bound, clar.lower_bound)


def test_batched_ipm_agrees_with_clarabel_on_random_corollary1_instances():
    """A few hundred seeded Corollary 1 delta = 2 instances (N = 2..5): the batch's c* equals
    Clarabel's on the same compiled data; nearly all are solved by the batch itself."""
    n_total = n_ipm = 0
    for N, npts in ((2, 80), (3, 80), (4, 50), (5, 40)):
        sc = random_scene(N, npts, noise_px=1.0, seed=100 + N)
        pbs = [tri_problem(sc.cameras, sc.regions(j), "corollary1") for j in range(npts)]
        comp = sospoly.compile_psatz(pbs[0].f, pbs[0].eq, pbs[0].ineq, 2, gens=pbs[0].gens)
        thetas = np.array([comp.theta(p.f, p.eq, p.ineq) for p in pbs])
        out = comp.solve_batch(thetas=thetas)
        for th, lb in zip(thetas, out):
            ref = comp.solve_theta(th, backend="clarabel")
            assert lb.status == ref.status == SolveStatus.OPTIMAL
            assert close(lb.lower_bound, ref.lower_bound)
            n_ipm += lb.solution.attempts[0].label == "ipm-batch" and len(lb.solution.attempts) == 1
        n_total += npts
    assert n_total == 250 and n_ipm >= 0.95 * n_total


def test_batch_bounds_agree_with_single_solves():
    """CompiledPsatz.batch_bounds: certified bounds (ok) equal Clarabel's single solves; the
    returned Gram matrices are PSD to the margin and their eigendecomposition is theirs."""
    sc = random_scene(3, 30, noise_px=1.0, seed=7)
    pbs = [tri_problem(sc.cameras, sc.regions(j), "corollary1") for j in range(30)]
    comp = sospoly.compile_psatz(pbs[0].f, pbs[0].eq, pbs[0].ineq, 2, gens=pbs[0].gens)
    thetas = np.array([comp.theta(p.f, p.eq, p.ineq) for p in pbs])
    bb = comp.batch_bounds(thetas)
    assert bb.ok.sum() >= 28
    for th, lb, ok in zip(thetas, bb.lower_bound, bb.ok):
        if ok:
            assert close(lb, comp.solve_theta(th, backend="clarabel").lower_bound)
    G = bb.gram[bb.ok]
    np.testing.assert_allclose(np.einsum("bij,bj,bkj->bik", bb.eigenvectors[bb.ok], bb.eigenvalues[bb.ok],
                                         bb.eigenvectors[bb.ok]), G, atol=1e-9 * np.abs(G).max())
    x, y = sospoly.variables("x y")
    two_blocks = sospoly.compile_psatz(x ** 2 + y ** 2, [], [1 - x ** 2], degree=2)
    with pytest.raises(ValueError, match="one PSD block"):
        two_blocks.batch_bounds(two_blocks.theta(x ** 2 + y ** 2, [], [1 - x ** 2]))


def test_mismatch_errors_are_clear():
    x, y = sospoly.variables("x y")
    comp = sospoly.compile_psatz(x ** 2 + y ** 2 - x, [x * y - 1], [], degree=2)
    with pytest.raises(sospoly.StructureMismatch, match="eq\\[0\\].*outside the structure's support"):
        comp.theta(x ** 2 + y ** 2, [x * y - 1 + y], [])
    with pytest.raises(sospoly.StructureMismatch, match="1 equalities"):
        comp.theta(x ** 2, [], [])
    with pytest.raises(sospoly.StructureMismatch, match="degree"):
        comp.theta(x ** 2 + y ** 2, [x - 1], [])
    with pytest.raises(sospoly.StructureMismatch, match="entries per instance"):
        comp.problem_from_theta(np.zeros(comp.n_theta + 1))
    with pytest.raises(ValueError, match="NaN"):
        comp.problem_from_theta(np.full(comp.n_theta, np.nan))
    with pytest.raises(ValueError, match="free-q"):
        sospoly.compile_psatz(x ** 2, [x * y - 1], [], degree=2, multiplier="free")


def test_cache_reuses_and_grows_support():
    x, y = sospoly.variables("x y")
    cache = sospoly.PsatzCache()
    a, _ = cache.get(x ** 2 + y ** 2, [x * y - 1], [], 2, key="k")
    b, _ = cache.get(x ** 2 + 2 * y ** 2, [3 * x * y - 2], [], 2, key="k")
    assert a is b and cache.compiles == 1
    c, _ = cache.get(x ** 2 + y ** 2 + x, [x * y - 1], [], 2, key="k")     # new term in f: union support
    assert c is not a and cache.compiles == 2
    assert c.contains(x ** 2 + y ** 2, [x * y - 1], []) and c.contains(x ** 2 + y ** 2 + x, [x * y], [])
    # the enlarged structure gives the uncompiled bound on both instances
    for f in (x ** 2 + y ** 2, x ** 2 + y ** 2 + x):
        _, ref = uncompiled(f, [x * y - 1], [], 2)
        assert close(c.solve(f, [x * y - 1], []).lower_bound, ref.lower_bound)


def test_cache_hit_theta_is_the_slots_theta_and_mismatches_still_raise():
    """A hit reads theta in one pass (no slots built for the instance): the same vector as the entry's own
    ``theta``, a subset of its terms is a hit, a term outside it grows the support, a degree that differs raises."""
    x, y = sospoly.variables("x y")
    cache = sospoly.PsatzCache()
    a, _ = cache.get(x ** 2 + y ** 2 + x, [x * y - 1], [], 2, key="k")
    b, th = cache.get(3 * x ** 2 + y ** 2, [x * y], [], 2, key="k")            # fewer terms: a hit
    assert b is a and cache.compiles == 1
    np.testing.assert_array_equal(th, a.theta(3 * x ** 2 + y ** 2, [x * y], []))
    assert np.count_nonzero(th) == 3
    c, _ = cache.get(x ** 2 + y ** 2 + y, [x * y - 1], [], 2, key="k")         # y outside: the union
    assert c is not a and cache.compiles == 2 and c.contains(x ** 2 + y ** 2 + x, [x * y - 1], [])
    with pytest.raises(sospoly.StructureMismatch, match="degree 0"):
        cache.get(x ** 2 + y ** 2, [x * 0 + 1], [], 2, key="k")              # inside the support, degree 0
    assert cache.compiles == 2


def test_lowered_structure_is_solved_only_by_the_solver_layer():
    """sospoly.lowering.compiled only lowers: its LoweredPsatz gives the same conic data as the solver's
    CompiledPsatz (a subclass), and solve_psatz refuses an instance bound to a bare LoweredPsatz (TypeError
    naming the argument) instead of failing with an AttributeError; the CompiledPsatz instance is solved
    to the uncompiled bound."""
    from sospoly.lowering.compiled import LoweredPsatz

    x, y = sospoly.variables("x y")
    ps, ref = uncompiled(x ** 2 + y ** 2 - x, [x * y - 1], [], 2)
    lowered, comp = LoweredPsatz(ps.structure), sospoly.CompiledPsatz(ps.structure)
    assert isinstance(comp, LoweredPsatz) and not hasattr(lowered, "solve_theta")
    a, b = lowered.problem_from_theta(ps.theta), comp.problem_from_theta(ps.theta)
    assert (a.A != b.A).nnz == 0 and np.array_equal(a.b, b.b) and np.array_equal(a.q, b.q)
    with pytest.raises(TypeError, match="psatz"):
        sospoly.solve_psatz(lowered.bind(ps.theta))
    assert close(sospoly.solve_psatz(comp.bind(ps.theta)).lower_bound, ref.lower_bound)


def test_conic_problem_with_parameters_is_refused_by_the_solver():
    """sospoly.solve_conic_problem solves numbers only: a lowered problem with parameters left is a ValueError."""
    x, y = sospoly.variables("x y")
    lowered = sospoly.CompiledPsatz(sospoly.build_psatz(x ** 2 + y ** 2 - x, [x * y - 1], [], 2).structure)
    with pytest.raises(ValueError, match="instantiate"):
        sospoly.solve_conic_problem(lowered.template)
