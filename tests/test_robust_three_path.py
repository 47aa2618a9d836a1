"""Single robust calls of three point views (tritools.solve.robust_three): the enumeration without a stack.

Compared with the stacked enumeration of one problem (``robust_enum_run.THREE_VIEW_PATH = False``, the code the path
replaces for single calls) and with independent references: the TLS optimum by inlier-set enumeration with
multi-start scipy least squares (tests/robust_refs.py, an attained value: no lower bound may exceed it, a certified
upper bound must reach it)."""
from __future__ import annotations

import time

import numpy as np
import pytest

import tritools
import tritools.solve.robust_enum as enum_mod
import tritools.solve.robust_enum_run as run_mod
from tests.robust_refs import tls_by_subsets
from tritools.model.regions import Ellipse
from tritools.scene import robust_protocol_scene
from tritools.solve import robust_three
from tritools.solve.options import options_from
from tritools.solve.robust import TlsSearch, robust_thresholds, tls_cost

C = 200.0


def _enumerated(P, x, c=C, three=True, monkeypatch=None):
    """The enumeration's result (or None) of one search, by the three-view path or the stack of one."""
    monkeypatch.setattr(run_mod, "THREE_VIEW_PATH", three)
    search = TlsSearch(P, None, robust_thresholds(c, len(P)), options_from(None), time.perf_counter(), points=x)
    return run_mod.enumerate_tls(search), search


def _check_against_reference(res, P, x, c, X_true):
    """gamma_lb below the reference optimum, gamma_ub the exact f_TLS of X, the optimum reached when certified."""
    N = len(x)
    c = np.broadcast_to(np.asarray(c, float), (N,))
    f_ref = tls_by_subsets(P, x, c, [X_true, X_true + 0.2, X_true - 0.2, res.X])
    f_lb, f_ub = 2 * N * res.gamma_lb ** 2, 2 * N * res.gamma_ub ** 2
    assert f_lb <= f_ref * (1 + 1e-9) + 1e-300, (f_lb, f_ref)
    u = np.einsum("nij,j->ni", P, np.append(res.X, 1.0))
    d = np.linalg.norm(u[:, :2] / u[:, 2:] - x, axis=1)
    assert f_ub == pytest.approx(tls_cost(d, c), rel=1e-6)          # (gamma_ub: rounded up, at 5e6 m offsets too)
    np.testing.assert_array_equal(res.inliers, d < c)
    if res.optimal:
        assert f_ub <= f_ref * (1 + 1e-6), (f_ub, f_ref)


def _on_and_off(scenes, three, monkeypatch, switch_off):
    """(the results of ``scenes`` with a step on, which scenes were decided on, which off): ``switch_off()`` applies
    the monkeypatches that turn the step off between the two passes."""
    decided = {}
    for on in (True, False):
        if not on:
            switch_off()
        out = [_enumerated(P, x, three=three, monkeypatch=monkeypatch)[0] for P, x, _, _ in scenes]
        decided[on] = [r is not None for r in out]
        if on:
            rescued = out
    return rescued, decided[True], decided[False]


def _decides_more_below_the_reference(scenes, three, monkeypatch, switch_off):
    """With a step on, more of ``scenes`` are decided than with it off (``switch_off``, :func:`_on_and_off`), and every
    answer with it on is below the reference."""
    rescued, on, off = _on_and_off(scenes, three, monkeypatch, switch_off)
    assert sum(on) > sum(off)
    for (P, x, X, _), r in zip(scenes, rescued):
        if r is not None:
            _check_against_reference(r, P, x, C, X)


@pytest.mark.parametrize("n_out, noise", [(0, 1.0), (1, 1.0), (1, 5.0), (2, 5.0)])
def test_decides_where_the_stack_decides_with_the_same_answer(n_out, noise, monkeypatch):
    """Protocol scenes: wherever the stack of one decides, the three-view path decides too (it bounds the same rows
    or more, and refines the rows that fail), with the same inlier set, gamma_ub and certificate; its lower bound
    is never below the stack's by more than round-off."""
    rng = np.random.default_rng([n_out, int(noise), 8])
    decided = {True: 0, False: 0}
    for _ in range(12):
        P, x, _, _ = robust_protocol_scene(3, n_out, noise, rng)
        three, s3 = _enumerated(P, x, three=True, monkeypatch=monkeypatch)
        stack, s1 = _enumerated(P, x, three=False, monkeypatch=monkeypatch)
        decided[True] += three is not None
        decided[False] += stack is not None
        if stack is None:
            continue
        assert three is not None
        assert enum_mod.ENUMERATED in three.message
        assert three.optimal == stack.optimal
        np.testing.assert_array_equal(three.inliers, stack.inliers)
        assert three.gamma_ub == pytest.approx(stack.gamma_ub, rel=1e-9)
        assert three.gamma_lb >= stack.gamma_lb * (1 - 1e-9)
    assert decided[True] >= decided[False] >= 6


@pytest.mark.parametrize("pixel_scale", [1e-3, 1.0, 1e6])
def test_bounds_below_the_reference_at_every_pixel_scale(pixel_scale):
    """The same scenes in image units times 1e-3..1e6 (thresholds alike) through tritools.triangulate: the lower
    bound below the independent reference, certified results at the reference optimum, the ground-truth inliers."""
    rng = np.random.default_rng([17, int(np.log10(pixel_scale)) + 5])
    A = np.diag([pixel_scale, pixel_scale, 1.0])
    for n_out in (0, 1):
        P, obs, X, out = robust_protocol_scene(3, n_out, 1.0, rng)
        cams, x = np.einsum("ij,njk->nik", A, P), obs * pixel_scale
        res = tritools.triangulate(cams, x, robust=C * pixel_scale)
        _check_against_reference(res, cams, x, C * pixel_scale, X)
        if res.optimal:
            np.testing.assert_array_equal(res.inliers, ~out)


def test_georeferenced_zero_noise_duplicated_views_and_infinite_thresholds():
    """A georeferenced world (5e6 m offset), exact data with one wrong match (f* = c^2 exactly), a duplicated view,
    and per-view thresholds with one infinite: no lower bound above the reference, certificates at it."""
    rng = np.random.default_rng(29)
    P, x, X, out = robust_protocol_scene(3, 1, 1.0, rng)
    T = np.eye(4)
    T[:3, 3] = -np.array([5e6, -3e6, 1e3])                      # world moved by +offset: P' = P T
    Xg = X + np.array([5e6, -3e6, 1e3])
    res = tritools.triangulate(P @ T, x, robust=C)
    _check_against_reference(res, P @ T, x, C, Xg)
    assert res.gamma_ub == pytest.approx(tritools.triangulate(P, x, robust=C).gamma_ub, rel=1e-6)

    P0, x0, X0, out0 = robust_protocol_scene(3, 1, 0.0, rng)   # zero noise: the inliers' pair costs 0
    res = tritools.triangulate(P0, x0, robust=C)
    _check_against_reference(res, P0, x0, C, X0)
    if res.optimal:
        assert 6 * res.gamma_ub ** 2 == pytest.approx(C * C, rel=1e-9)

    P2, x2, X2, _ = robust_protocol_scene(2, 0, 1.0, rng)        # a duplicated view: its pair has no epipolar line
    Pd, xd = np.concatenate([P2, P2[:1]]), np.concatenate([x2, x2[:1]])
    res = tritools.triangulate(Pd, xd, robust=C)
    _check_against_reference(res, Pd, xd, C, X2)

    c = np.array([C, np.inf, 50.0])
    res = tritools.triangulate(P, x, robust=c)
    _check_against_reference(res, P, x, c, X)


@pytest.mark.parametrize("N, n_out, three", [(3, 1, True), (7, 2, False)])
def test_refined_rows_rescue_failing_bounds(N, n_out, three, monkeypatch):
    """Rows polished by one LM step (robust_three.POLISH_STEPS, robust_enum_run.SINGLE_POLISH_STEPS) may stop short of
    their set's optimum, and a Lagrangian bound taken there fails: the path refines the failing rows on their own sets
    and bounds them again (``_second_chance``), deciding scenes that otherwise go to the branch and bound, with answers
    below the reference.  Switched off, fewer scenes are decided."""
    rng = np.random.default_rng(3)
    scenes = [robust_protocol_scene(N, n_out, 1.0, rng) for _ in range(30 if three else 20)]
    for later in ("_ascend_all", "_solve_all"):                       # (their own test below)
        monkeypatch.setattr(robust_three._ThreeViews, later, lambda self, lb: lb)
    monkeypatch.setattr(run_mod, "SOLVE_LAST_SET", False)              # (the stack's own solve: its test below)

    def switch_off():
        monkeypatch.setattr(robust_three._ThreeViews, "_second_chance", lambda self, lb: lb)
        monkeypatch.setattr(run_mod._Group, "_second_chance", lambda self, probs: None)

    rescued, on, off_ = _on_and_off(scenes, three, monkeypatch, switch_off)
    assert sum(on) > sum(off_)
    for (P, x, X, _), r, off in zip(scenes, rescued, off_):
        if r is not None and not off:
            _check_against_reference(r, P, x, C, X)


@pytest.mark.parametrize("step", ["_ascend_all", "_solve_all"])
def test_all_views_bounds_decide_more_and_stay_below_the_reference(step, monkeypatch):
    """One wrong match among three views: the candidate's KKT multipliers give the all-views set no bound.  The
    best degree-2 certificate (sospoly.analysis.ascend_one, ``_ascend_all``) often exceeds UB; where it does not,
    the search's own sub-problem (Theorem 1 at delta = 4 stopped at UB, ``_solve_all``) does: the three-view path
    decides those scenes instead of handing them to the branch and bound; every answer below the reference
    (enumeration of the inlier sets with multi-start L2 optima).  Each step switched off alone (the other off
    too), fewer scenes are decided."""
    rng = np.random.default_rng(7)
    scenes = [robust_protocol_scene(3, 1, noise, rng) for noise in (1.0, 5.0) for _ in range(20)]
    other = {"_ascend_all": "_solve_all", "_solve_all": "_ascend_all"}[step]
    monkeypatch.setattr(robust_three._ThreeViews, other, lambda self, lb: lb)
    _decides_more_below_the_reference(scenes, True, monkeypatch,
                                      lambda: monkeypatch.setattr(robust_three._ThreeViews, step, lambda self, lb: lb))


def test_stacked_enumeration_ascent_decides_more_and_stays_below_the_reference(monkeypatch):
    """The stacked enumeration (a batch's path; 3 and 5 views here) bounds the rows still failing in its second round by
    the best degree-2 certificate (``_Group._ascend``): more scenes decided than without it, every answer below the
    reference (enumeration of the inlier sets with multi-start L2 optima)."""
    scenes = []
    for N, n_out in ((3, 1), (5, 2)):
        for noise in (1.0, 5.0):
            rng = np.random.default_rng(13)
            scenes += [robust_protocol_scene(N, n_out, noise, rng) for _ in range(20)]
    monkeypatch.setattr(run_mod, "SOLVE_LAST_SET", False)              # (the stack's own solve: its test below)
    _decides_more_below_the_reference(scenes, False, monkeypatch,
                                      lambda: monkeypatch.setattr(run_mod._Group, "_ascend", lambda self, probs: None))


def test_stacked_enumeration_solves_the_all_views_subproblem_as_a_single_call_does(monkeypatch):
    """The stacked enumeration of three-view problems (a batch's path) solves the all-views sub-problem itself where
    that set alone keeps LB below UB (``_Group._solve_all``, the single call's ``_solve_all``): more scenes decided
    than without it (they went to the branch and bound), every answer below the reference; through
    ``triangulate_many`` no problem of such a batch reaches the branch and bound, and each batch result has the
    single call's status and inlier set."""
    rng = np.random.default_rng(7)
    scenes = [robust_protocol_scene(3, 1, noise, rng) for noise in (1.0, 5.0) for _ in range(20)]
    off = lambda: monkeypatch.setattr(run_mod._Group, "_solve_all", lambda self, probs: None)     # noqa: E731
    _decides_more_below_the_reference(scenes, False, monkeypatch, off)
    monkeypatch.undo()
    import tritools.solve.robust_drive as drive_mod

    searched = []
    drive = drive_mod.drive
    monkeypatch.setattr(drive_mod, "drive", lambda searches: searched.extend(searches) or drive(searches))
    probs = [(P, x) for P, x, _, _ in scenes]
    batch = tritools.triangulate_many(probs, robust=C)
    assert searched == []
    for (P, x), r in zip(probs, batch):
        one = tritools.triangulate(P, x, robust=C)
        assert (r.status, r.optimal) == (one.status, one.optimal)
        np.testing.assert_array_equal(r.inliers, one.inliers)


def test_batch_sub_problems_of_others_do_not_use_up_a_problems_time_limit(monkeypatch):
    """Per-problem time limits in a batch: the all-views sub-problems the stack solves for some problems are credited
    to the others' deadlines (the stack's rule, ``_Group._expired``).  Each such solve made 0.45 s slower (after it:
    its own limit is not touched), the second starts after the 0.4 s each problem may use; every problem is still
    decided, as without a limit."""
    import tritools.solve.robust_bounds as rb

    rng = np.random.default_rng(7)
    probs = [robust_protocol_scene(3, 1, noise, rng)[:2] for noise in (1.0, 5.0) for _ in range(20)]
    solved = []
    solve = rb.SubsetBounds.solve_full

    def slow(self, S, need, X=None):
        out = solve(self, S, need, X)
        time.sleep(0.45)
        solved.append(1)
        return out

    monkeypatch.setattr(rb.SubsetBounds, "solve_full", slow)
    out = tritools.triangulate_many(probs, robust=C, time_limit=0.4)
    assert len(solved) >= 2
    assert all(r.optimal for r in out), [r.status for r in out if not r.optimal]


def test_stacked_enumeration_solves_the_last_open_set_at_any_view_count(monkeypatch):
    """Four and five views with two wrong matches: where one set alone keeps a problem open after the ascent (a
    wrong match left in it: the degree-2 certificate falls short), the stack solves that set's sub-problem
    (``SOLVE_LAST_SET``: :meth:`SubsetBounds.solve_full`, stopping at what the term needs) instead of handing the
    problem to the branch and bound: more scenes decided by the enumeration, every answer below the reference."""
    scenes = []
    for N in (4, 5):
        rng = np.random.default_rng([N, 21])
        scenes += [robust_protocol_scene(N, 2, noise, rng) for noise in (1.0, 5.0) for _ in range(12)]
    _decides_more_below_the_reference(scenes, False, monkeypatch,
                                      lambda: monkeypatch.setattr(run_mod, "SOLVE_LAST_SET", False))


@pytest.mark.parametrize("c", [200.0, 20.0, 3.0, 0.5])
def test_two_view_path_decides_where_the_stack_decides_with_the_same_answer(c, monkeypatch):
    """Two views (``robust_three.two_view_tls``): wherever the stack of one decides, the single-call path decides too,
    with the same inlier set, gamma_ub and certificate, a lower bound never below the stack's, and both below the
    closed form min(L2*, c_1^2, c_2^2) of the independent reference; thresholds from above every residual (both views
    inliers) to below the noise (the optimum on a ray: one inlier)."""
    rng = np.random.default_rng([int(c * 10), 2])
    decided = {True: 0, False: 0}
    for k in range(12):
        P, x, X, _ = robust_protocol_scene(2, k % 2, 5.0, rng)
        two, _ = _enumerated(P, x, c=c, three=True, monkeypatch=monkeypatch)
        stack, _ = _enumerated(P, x, c=c, three=False, monkeypatch=monkeypatch)
        decided[True] += two is not None
        decided[False] += stack is not None
        if two is not None:
            _check_against_reference(two, P, x, c, X)
        if stack is None:
            continue
        assert two is not None
        assert enum_mod.ENUMERATED in two.message
        assert two.optimal == stack.optimal
        np.testing.assert_array_equal(two.inliers, stack.inliers)
        assert two.gamma_ub == pytest.approx(stack.gamma_ub, rel=1e-9)
        assert two.gamma_lb >= stack.gamma_lb * (1 - 1e-9)
    assert decided[True] >= decided[False] >= 10


def test_other_view_counts_and_regions_are_not_taken():
    """Only searches of three point views (two: ``two_view_tls``): others get None (the stacked enumeration or the
    search runs)."""
    rng = np.random.default_rng(5)
    P, x, _, _ = robust_protocol_scene(4, 1, 1.0, rng)
    s = TlsSearch(P, None, robust_thresholds(C, 4), options_from(None), time.perf_counter(), points=x)
    assert robust_three.three_view_tls(s) is None
    assert robust_three.two_view_tls(s) is None
    s2 = TlsSearch(P[:2], None, robust_thresholds(C, 2), options_from(None), time.perf_counter(), points=x[:2])
    assert robust_three.three_view_tls(s2) is None and robust_three.two_view_tls(s2) is not None
    P3, x3 = P[:3], x[:3]
    regions = [Ellipse(p, np.eye(2) / 4.0) for p in x3]
    s = TlsSearch(P3, regions, robust_thresholds(C, 3), options_from(None), time.perf_counter())
    assert not s.points and robust_three.three_view_tls(s) is None


def test_three_view_terms_and_lower_bound_equal_the_stacked_rule_bit_for_bit():
    """robust_three's scalar twins (three_terms, exact_terms, three_lower_bound) give closed_terms' and lower_bounds'
    numbers exactly: bounds from 0 to 1e300, infinite thresholds, pairs whose bound exceeds the whole set's own."""
    W = enum_mod.subset_masks(3)
    rng = np.random.default_rng(23)
    for _ in range(3000):
        lb = np.where(rng.random(4) < 0.2, 0.0, rng.random(4) * 10.0 ** rng.integers(-5, 300, 4))
        c2 = (rng.random(3) * 10.0 ** rng.integers(-3, 150, 3)) ** 2
        c2[rng.random(3) < 0.1] = np.inf
        with np.errstate(over="ignore", invalid="ignore"):
            rest = np.sum(np.where(W, 0.0, c2[None]), axis=1) * enum_mod.ROUND_DOWN
        ub = float(rng.choice([np.inf, rng.random() * 10.0 ** rng.integers(-3, 300)]))
        ref_terms = run_mod.closed_terms(3, W, lb[None], rest[None])[0]
        got_terms = robust_three.three_terms(lb.tolist(), rest.tolist())
        assert np.array_equal(np.array(got_terms), ref_terms), (lb, rest)
        ref = float(run_mod.lower_bounds(np.array([ub]), ref_terms[None], c2[None])[0])
        assert robust_three.three_lower_bound(ub, got_terms, robust_three.exact_terms(c2)) == ref, (lb, c2, ub)
