"""The best-bound stop inside the interior-point method (sospoly.solvers.level_scope): a solve that needs only
"f >= level" stops at the first moment-form iterate proving it.  Checked against known minima (sospoly) and a
scipy multi-start L2 reference (tritools): the stopped bound reaches the level, is rigorous, and stays below the
true optimum; without a level, above the optimum, or without accept_inaccurate nothing changes."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import sospoly as sp
import tritools
from sospoly.solvers import IPM_LEVEL, AutoBackend, active_level, level_scope, stop_threshold
from tests.robust_refs import l2_min
from tritools.scene import robust_protocol_scene
from tritools.solve.stages.sdp import BOUND_STOP


def _program():
    """min sum (v^2 - 1)^2 + 1 + (ab - c)^2 / 10 s.t. ab = c, d = ef over R^6: minimum 1 (v = 1), and the
    degree-4 SOS bound is exact (f - 1 is a sum of squares); one Gram block, solved in the moment form."""
    xs = sp.variables("a b c d e f")
    f = sum((v ** 2 - 1) ** 2 for v in xs) + 1 + 0.1 * (xs[0] * xs[1] - xs[2]) ** 2
    return sp.build_psatz(f, eq=[xs[0] * xs[1] - xs[2], xs[3] - xs[4] * xs[5]], degree=4)


def _solve(ps, level, accept=True):
    tol = dataclasses.replace(sp.DEFAULT_TOLERANCES, accept_inaccurate=accept)
    with level_scope(level):
        return sp.solve_psatz(ps, backend=AutoBackend(tol), tolerances=tol)


def test_scope_and_threshold():
    assert active_level() is None
    with level_scope(2.0):
        assert active_level() == 2.0
        with level_scope(None):
            assert active_level() is None
        assert active_level() == 2.0
    assert active_level() is None
    with level_scope(float("inf")):
        assert active_level() is None
    with pytest.raises(TypeError, match="level"):
        with level_scope("1"):
            pass
    # maximised (sign -1): -q.x + off >= level  <=>  q.x <= off - level; minimised: q.x + off <= level
    assert stop_threshold(3.0, -1.0, 0.5) == -2.5 and stop_threshold(3.0, 1.0, 0.5) == 2.5
    assert stop_threshold(None, -1.0, 0.0) is None


def test_stops_at_the_level_with_a_rigorous_bound_below_the_minimum():
    ps = _program()
    full = _solve(ps, None)
    assert full.status == sp.SolveStatus.OPTIMAL and abs(full.lower_bound - 1.0) < 1e-6
    n_full = full.solution.attempts[-1].iterations
    lb = _solve(ps, 0.5)
    att = lb.solution.attempts[-1]
    assert lb.status == sp.SolveStatus.INACCURATE and att.solver_status == IPM_LEVEL
    assert att.iterations <= n_full
    obj = lb.solution.objective
    rig = sp.rigorous_psatz_bound(ps, lb.solution, obj, 3.0)
    assert 0.5 <= rig.lower_bound <= 1.0 + 1e-12 and rig.lower_bound <= obj


@pytest.mark.parametrize("level,accept", [(5.0, True), (0.5, False)])
def test_no_stop_above_the_optimum_or_without_accept_inaccurate(level, accept):
    lb = _solve(_program(), level, accept)
    assert lb.status == sp.SolveStatus.OPTIMAL and abs(lb.lower_bound - 1.0) < 1e-6
    assert all(a.solver_status != IPM_LEVEL for a in lb.solution.attempts)


@pytest.mark.parametrize("idx", [0, 32])
def test_theorem1_three_views_stops_early_with_a_valid_bound(idx):
    """The robust search's costly node: three views, one wrong match, Theorem 1 at delta = 4 needing a level far
    below L2* (RESULTS "Wave 12").  With lower_bound_stop the moment-form IPM stops at an iterate: the result is
    not certified, its gamma_lb is at least the level and at most the L2 value of a scipy multi-start."""
    rng = np.random.default_rng([7, 3, 1, 10 if idx == 0 else 50])
    for _ in range(idx + 1):
        P, obs, X, _ = robust_protocol_scene(3, 1, 1.0 if idx == 0 else 5.0, rng)
    rs = np.random.default_rng(1)
    ref = l2_min(P, obs, [X] + [X + rs.normal(scale=s, size=3) for s in (0.1, 0.5, 2.0) for _ in range(4)])
    level = np.sqrt(0.2 * ref / 6)
    opts = tritools.TriangulationOptions(method="theorem1", delta=4, max_delta=4)
    full = tritools.triangulate(P, obs, options=opts)
    assert full.optimal and 6 * full.gamma_lb ** 2 <= ref * (1 + 1e-9)
    res = tritools.triangulate(P, obs, options=opts.replace(lower_bound_stop=level))
    assert not res.optimal and BOUND_STOP in res.message
    assert level <= res.gamma_lb <= full.gamma_lb and 6 * res.gamma_lb ** 2 <= ref
    assert any("level reached" in s for a in res.attempts for s in a.solver)
