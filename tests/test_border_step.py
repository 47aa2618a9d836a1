"""The plan's border step (review of #22's mixed-region exponent, wave 35): the degree-2 certificate sees an ellipse
border as its filled ellipse, so where the optimum's projection lies inside a border its bound stops at the
convexified value; the step before the views program keeps degree-4 blocks only on the cliques of those views.

References: the filled-ellipse twin's certified optimum (the degree-2 bound of the border problem equals it) and a
multi-start local minimisation of the caller's cost sum_i d(P_i X, R_i)^2 (an attained value)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

import tritools
from tritools import Ellipse, EllipseBorder
from tritools.model.constraints import Method
from tritools.scene import uncertain_problem
from tritools.solve.options import TriangulationOptions
from tritools.solve.plan import BORDERS, degree_plan


def _attained(C, regs, X0, seed=0):
    def d(X):
        h = np.einsum("nij,j->ni", C, np.append(X, 1.0))
        return np.array([r.distance(p) for r, p in zip(regs, h[:, :2] / h[:, 2:])])
    rng = np.random.default_rng(seed)
    starts = [X0] + [X0 + rng.normal(0, 1e-2, 3) for _ in range(3)]
    return min(float(np.sum(least_squares(d, s, xtol=1e-14, ftol=1e-14, gtol=1e-14).fun ** 2)) for s in starts)


def test_plan_puts_the_border_step_before_the_views_step():
    opts = TriangulationOptions()
    plan = degree_plan(opts, 16, 60, 2, borders=True)
    assert [(s.delta, s.formulation, s.focus) for s in plan] == [(2, "dense", None), (4, "views", BORDERS),
                                                                 (4, "views", None)]
    assert all(s.focus is None for s in degree_plan(opts, 16, 60, 2))                       # no border: as before
    assert all(s.focus is None for s in degree_plan(opts.replace(sparsity="views"), 16, 60, 2, borders=True))
    assert all(s.focus is None for s in degree_plan(opts.replace(method="theorem1"), 16, 60, 4, borders=True))
    assert degree_plan(opts, 16, 60, 2, borders=True)[1].method == Method.COROLLARY1


@pytest.mark.slow
@pytest.mark.parametrize("seed", [2])
def test_border_step_certifies_with_a_smaller_program(seed):
    C, regs, _ = uncertain_problem(16, seed, kinds="mixed")
    filled = [Ellipse(r.center_, r.D) if type(r) is EllipseBorder else r for r in regs]
    twin = tritools.triangulate(C, filled, max_delta=2)
    two = tritools.triangulate(C, regs, max_delta=2)
    assert twin.optimal and not two.optimal
    assert two.gamma_lb == pytest.approx(twin.gamma_ub, rel=1e-6)          # the degree-2 bound: the filled optimum
    res = tritools.triangulate(C, regs)
    assert res.optimal and res.delta == 4 and res.sparsity == "views"
    full = tritools.triangulate(C, regs, delta=4, sparsity="views", method="corollary1")
    assert full.optimal and res.n_lmivar < 0.6 * full.n_lmivar           # the border step decided, not the views one
    f_att = _attained(C, regs, res.X)
    assert 32 * res.gamma_lb ** 2 <= f_att * (1 + 1e-9)
    assert 32 * res.gamma_ub ** 2 == pytest.approx(f_att, rel=1e-6)


def test_border_focus_names_the_borders_holding_the_projection_inside():
    from types import SimpleNamespace

    from tritools.solve.plan import Step
    from tritools.solve.stages.sdp import border_focus

    P = np.hstack([np.eye(3), np.array([[0.0], [0.0], [1.0]])])           # X = 0 projects to (0, 0)
    C = np.stack([P] * 4)
    regs = [EllipseBorder([0.5, 0.0], np.diag([1.0, 4.0])),    # (0, 0) inside: 0.25 < 1
            EllipseBorder([3.0, 0.0], np.eye(2)),              # outside
            Ellipse([0.0, 0.0], np.eye(2)),                    # filled: never a border view
            EllipseBorder([0.0, 1.5], np.diag([1.0, 4.0]))]    # inside along its long axis: 2.25 / 4 < 1
    step = Step(Method.COROLLARY1, 4, "views", focus=BORDERS)
    ctx = SimpleNamespace(best=SimpleNamespace(X=np.zeros(3)), cams=C, regions=regs)
    assert border_focus(ctx, step).focus == (0, 3)
    assert border_focus(SimpleNamespace(best=None, cams=C, regions=regs), step) is None
    ctx.regions = regs[1:3]
    ctx.cams = C[:2]
    assert border_focus(ctx, step) is None
