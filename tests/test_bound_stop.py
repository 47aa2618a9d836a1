"""The best-bound stop (``TriangulationOptions.lower_bound_stop``) and the robust search's sub-problems
(:mod:`tritools.solve.robust_subsolve`): a stopped result is never certified, its bound is rigorous (below the
multi-start scipy L2 value, an attained value >= L2*), a stopped subset stays weak and is not exhausted, and the
robust calls keep their decisions and valid bounds against the enumerated TLS reference."""
from __future__ import annotations

import numpy as np
import pytest

import tritools
from tests.robust_refs import l2_min, tls_by_subsets
from tritools.model.regions import Point
from tritools.scene import robust_protocol_scene
from tritools.solve import robust_bounds as rb
from tritools.solve import robust_subsolve as rs
from tritools.solve.options import OptionError, TriangulationOptions
from tritools.solve.stages.sdp import BOUND_STOP

C = 200.0


def _scene(N, n_out, idx, seed=3, noise=5.0):
    """The ``idx``-th protocol scene of benchmarks/robust.py's cell (seed, N, n_out, noise)."""
    rng = np.random.default_rng([seed, N, n_out, int(noise * 10)])
    for _ in range(idx + 1):
        P, obs, X, out = robust_protocol_scene(N, n_out, noise, rng)
    return P, obs, X, out


def _starts(X):
    rng = np.random.default_rng(0)
    return [X] + [X + rng.normal(scale=s, size=3) for s in (0.1, 0.3, 1.0) for _ in range(4)]


@pytest.mark.parametrize("bad", [-1.0, np.nan, np.inf, True, "1"])
def test_option_is_checked(bad):
    with pytest.raises(OptionError) as exc:
        TriangulationOptions(lower_bound_stop=bad)
    assert exc.value.field == "lower_bound_stop"
    assert TriangulationOptions(lower_bound_stop=3).lower_bound_stop == 3.0


def test_stop_at_bound_is_rigorous_and_never_certified():
    """The three-view sub-problem holding the wrong match (cell N = 3, 20%, 5 px, scene 14): Corollary 1 reaches
    37052 (delta 2) and 40267 (delta 4) px^2, Theorem 1 delta 4 certifies 42284."""
    P, obs, X, _ = _scene(3, 1, 14)
    ref = l2_min(P, obs, _starts(X))
    full = tritools.triangulate(P, obs)
    assert full.optimal and 6 * full.gamma_lb ** 2 <= ref * (1 + 1e-9)
    level = np.sqrt(38000.0 / 6)                               # between the delta 2 and delta 4 bounds
    res = tritools.triangulate(P, obs, options=TriangulationOptions(lower_bound_stop=level))
    assert not res.optimal and res.status == tritools.Status.NOT_CERTIFIED and BOUND_STOP in res.message
    assert level <= res.gamma_lb < full.gamma_lb and 6 * res.gamma_lb ** 2 <= ref
    assert [(a.method, a.delta) for a in res.attempts if a.gamma_lb is not None] == \
        [("corollary1", 2), ("corollary1", 4)]                  # no exact-variety step
    high = tritools.triangulate(P, obs, options=TriangulationOptions(lower_bound_stop=2 * full.gamma_ub))
    assert high.optimal and (high.gamma_lb, high.gamma_ub) == (full.gamma_lb, full.gamma_ub)
    assert np.array_equal(high.X, full.X)


def _bounds(P, obs):
    opts = TriangulationOptions()
    return rb.SubsetBounds(P, [Point(p) for p in obs], opts, opts.budget.deadline())


@pytest.mark.parametrize("theorem_first", [False, True])
def test_stopped_subset_stays_weak_and_is_not_exhausted(monkeypatch, theorem_first):
    monkeypatch.setattr(rs, "THEOREM1_FIRST", theorem_first)
    P, obs, X, _ = _scene(3, 1, 14)
    ref = l2_min(P, obs, _starts(X))
    S = frozenset(range(3))
    sb = _bounds(P, obs)
    sb._solve_one(S, light=False, from_delta=4, need=39000.0)
    assert 39000.0 <= sb.bound(S) <= ref and S not in sb.exhausted
    if theorem_first:       # Theorem 1 delta 4 stops at an iterate proving the need (sospoly.solvers.level_scope)
        assert S in sb.weak and 39000.0 <= sb.bound(S) <= ref
    else:                                       # stopped after Corollary 1 delta 4: a later need solves it again
        assert S in sb.weak and sb.bound(S) < 41000.0
    # a later, larger need solves it again and reaches that need (stopped there or certified), never above L2*
    assert sb.strengthen(S, need=42000.0) and 42000.0 <= sb.bound(S) <= ref and S not in sb.exhausted
    plain = _bounds(P, obs)
    plain._solve_one(S, light=False, from_delta=4)
    assert plain.bound(S) > 42000.0 and S not in plain.weak and S not in plain.exhausted


CELLS = [(3, 1, 14), (3, 1, 16), (5, 2, 10), (3, 1, 3), (4, 2, 5), (5, 2, 2)]


@pytest.mark.parametrize("N,n_out,idx", CELLS)
def test_robust_calls_keep_their_decisions_and_valid_bounds(monkeypatch, N, n_out, idx):
    P, obs, X, out = _scene(N, n_out, idx)
    new = tritools.triangulate(P, obs, robust=C)
    monkeypatch.setattr(rs, "BOUND_STOP", False)
    monkeypatch.setattr(rs, "THEOREM1_FIRST", False)
    old = tritools.triangulate(P, obs, robust=C)
    ref = tls_by_subsets(P, obs, np.full(N, C), _starts(X))
    for r in (new, old):
        assert 2 * N * r.gamma_lb ** 2 <= ref * (1 + 1e-9)
        assert not r.optimal or 2 * N * r.gamma_ub ** 2 <= ref * (1 + 1e-6)
    assert new.optimal == old.optimal and np.array_equal(new.inliers, old.inliers)
    assert new.gamma_ub == pytest.approx(old.gamma_ub, rel=1e-9)


def test_a_callers_level_is_not_passed_to_the_sub_problems(monkeypatch):
    """A caller's ``lower_bound_stop`` (a level of the whole problem) does not reach the sub-problems: a full-plan
    sub-solve without a need of its own runs its whole plan (else it would stop after Corollary 1 delta 4 and be
    taken as exhausted), and the robust call decides as without it."""
    monkeypatch.setattr(rs, "THEOREM1_FIRST", False)
    P, obs, X, _ = _scene(3, 1, 14)
    opts = TriangulationOptions(lower_bound_stop=1.0)
    out = rs.solve_subproblem(P, [Point(p) for p in obs], opts, light=False, from_delta=4, limit=np.inf,
                              need=np.inf, points=True)
    assert out.certified and out.lb > 42000.0 and not out.exhausted and not out.stopped
    plain = tritools.triangulate(P, obs, robust=C)
    low = tritools.triangulate(P, obs, robust=C, options=opts)
    assert plain.optimal and low.optimal and np.array_equal(plain.inliers, low.inliers)
    assert (low.gamma_lb, low.gamma_ub) == (plain.gamma_lb, plain.gamma_ub)


# ----------------------------------------------------------------------------- review 10b
def test_batch_rows_stop_at_the_level_like_single_calls():
    """A batch row decided but not certified by the batched degree-2 SDP stops there when its gamma_lb reaches the
    caller's lower_bound_stop, as a single call does (it went on at delta = 4, with another bound)."""
    from tritools.solve.options import TriangulationOptions

    rng = np.random.default_rng(11)
    probs = [robust_protocol_scene(3 + i % 2, 1, 5.0, rng)[:2] for i in range(60)]
    opts = TriangulationOptions(lower_bound_stop=0.0)
    many = tritools.triangulate_many(probs, options=opts, executor=None)
    stopped = 0
    for p, m in zip(probs, many):
        s = tritools.triangulate(*p, options=opts)
        assert (s.status, s.optimal, s.delta) == (m.status, m.optimal, m.delta)
        assert s.gamma_lb == pytest.approx(m.gamma_lb, rel=1e-9)
        stopped += not s.optimal
    assert stopped >= 3


def test_robust_sub_solves_respect_the_callers_max_delta(monkeypatch):
    """Theorem 1 first (delta = 4) is not run under a caller's max_delta = 2: no sub-problem bound above degree 2."""
    import tritools.solve.triangulate as tt

    P, obs, _, _ = _scene(3, 1, 14)
    orig, degrees = tt.triangulate, []

    def spy(*a, **k):
        r = orig(*a, **k)
        degrees.extend(t.delta for t in r.attempts if t.gamma_lb is not None)
        return r

    monkeypatch.setattr(tt, "triangulate", spy)
    r = tritools.triangulate(P, obs, robust=200.0, max_delta=2)
    assert degrees and max(degrees) <= 2
    assert not r.optimal


def test_refused_light_solve_is_not_weak():
    """Options that refuse the degree-2 cap (method corollary1 at delta 4) run the full plan: the subset is not
    weak, so a later strengthen does not solve the same plan again (and never weak and exhausted at once)."""
    from tritools.solve.options import TriangulationOptions
    from tritools.solve.robust_bounds import SubsetBounds
    from sospoly.budget import Deadline

    P, obs, _, _ = _scene(3, 1, 14)
    opts = TriangulationOptions(method="corollary1", delta=4)
    sb = SubsetBounds(P, [tritools.Point(p) for p in obs], opts, Deadline(None), points=obs)
    S = frozenset(range(3))
    sb._solve_one(S, light=True)
    assert S not in sb.weak
    assert not (S in sb.weak and S in sb.exhausted)
