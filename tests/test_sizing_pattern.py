"""The budget check on the aggregate sparsity of the Gram blocks (sospoly.certificates.sizing, issue #22): a
degree-2 certificate whose variables couple only in small groups is sized on its cliques, in the image form
only; the cliques are those of the kept entries."""
import numpy as np
import pytest

import sospoly
from sospoly.algebra.polynomial import Polynomial
from sospoly.certificates.psatz import DataSlots, certificate_shape
from sospoly.certificates.sizing import check_size, gram_pattern_sides


def _chain_program(n_groups: int, group: int = 3):
    """f = sum_k ||v_k - a_k||^2 over groups v_k of ``group`` variables, one equality per group (a product inside
    it) and one coupling the first variable of consecutive groups, one inequality (a scalar multiplier block beside
    u's, so Clarabel's estimate is the program's): the Gram block of (1, v) keeps the groups' entries, the
    consecutive first variables and the constant's row."""
    n = n_groups * group
    gens = tuple(f"v{i}" for i in range(n))
    var = [Polynomial(gens, {tuple(int(j == i) for j in range(n)): 1.0}) for i in range(n)]
    f = sum(((v - 0.3 * (i + 1)) ** 2 for i, v in enumerate(var)), Polynomial(gens, {}))
    eq = [var[k * group] * var[k * group + 1] - 0.1 for k in range(n_groups)]
    eq += [var[k * group] * var[(k + 1) * group] - 0.2 for k in range(n_groups - 1)]
    return gens, f, eq, [4.0 - var[0] ** 2]


def test_cliques_of_a_chain_of_groups():
    gens, f, eq, ineq = _chain_program(20)
    shape = certificate_shape("none", gens, 2, f, eq, ineq)
    slots = DataSlots.of(f, eq, ineq, gens)
    sides = [c for b in gram_pattern_sides(shape, slots) for c in b]
    # the u block (1, v_0..v_59): squares and linear terms keep (0, i); products keep (g0, g0+1) and (g_k, g_k+1)
    assert shape.gram_sides()[0] == 61
    assert sides[-1] == 1                                # the inequality's multiplier block as it is
    # the constant is joined to every variable (linear terms), the rest is a tree: its cliques are the constant
    # with each kept product (20 in the groups, 19 between them) and with each group's third variable
    assert sorted(sides[:-1]) == [2] * 20 + [3] * 39


def test_image_form_sized_on_cliques_kernel_form_dense():
    gens, f, eq, ineq = _chain_program(20)           # u block of side 61
    shape = certificate_shape("none", gens, 2, f, eq, ineq)
    slots = DataSlots.of(f, eq, ineq, gens)
    dense = shape.size()
    budget = sospoly.Budget(max_bytes=dense.clarabel_bytes / 3)
    with pytest.raises(sospoly.BudgetExceeded):
        check_size(shape, budget, False, len(gens), 2, 2, slots=slots, image_form=False)
    check_size(shape, budget, False, len(gens), 2, 2, slots=slots, image_form=True)     # fits on its cliques
    with pytest.raises(sospoly.BudgetExceeded):                                           # but not below them
        check_size(shape, sospoly.Budget(max_bytes=1e5), False, len(gens), 2, 2, slots=slots, image_form=True)


def test_dense_data_keeps_the_dense_estimate():
    n = 6
    gens = tuple(f"y{i}" for i in range(n))
    var = [Polynomial(gens, {tuple(int(j == i) for j in range(n)): 1.0}) for i in range(n)]
    f = sum((var[i] * var[j] for i in range(n) for j in range(i, n)), Polynomial(gens, {}))
    shape = certificate_shape("none", gens, 2, f, (), ())
    sides = gram_pattern_sides(shape, DataSlots.of(f, (), (), gens))   # every product is data: one block
    assert sides == ((n + 1,),)


def test_compiled_structure_under_a_budget_between_the_estimates():
    gens, f, eq, ineq = _chain_program(20)
    shape = certificate_shape("none", gens, 2, f, eq, ineq)
    budget = sospoly.Budget(max_bytes=shape.size().clarabel_bytes / 3)
    with pytest.raises(sospoly.BudgetExceeded):
        sospoly.build_psatz(f, eq, ineq, 2, budget=budget)            # form unknown: the dense estimate
    cache = sospoly.PsatzCache()
    comp, theta = cache.get(f, eq, ineq, 2, budget=budget, form=sospoly.GramForm.IMAGE)
    lb = comp.solve_theta(theta)
    assert lb.lower_bound is not None and np.isfinite(lb.lower_bound)
    with pytest.raises(sospoly.BudgetExceeded):                    # the cached structure, in the kernel form
        cache.get(f, eq, ineq, 2, budget=budget, form=sospoly.GramForm.KERNEL)
