"""The stages over a batch of point problems (tritools.solve.stages.batch): a column record plus the mask of the
rows still open, the same result as before the refactor, stages inserted without touching the others, a batch of
one equal to a single call."""
from __future__ import annotations

import numpy as np
import pytest

import tritools
from tritools.model.geometry import refine_l2, validate_cameras
from tritools.result import Status
from tritools.scene import random_scene
from tritools.solve.batch import per_point_runner, solve_point_stack
from tritools.solve.options import TriangulationOptions
from tritools.solve.stages import (BATCH_SDP_IMPLEMENTATIONS, BATCH_STAGES, BATCH_VERIFY_IMPLEMENTATIONS,
                                   FAST_DEFAULT, POINT_STAGES, Stage, run_batch, with_stage)


def _stack(n_views: int, n_points: int, noise: float, seed: int):
    """Cameras (M, N, 3, 4) and observed points (M, N, 2) of one random scene (every camera sees every point)."""
    sc = random_scene(n_views, n_points, noise_px=noise, seed=seed)
    C = validate_cameras(sc.cameras)
    x = np.array([[r.center for r in sc.regions(j)] for j in range(n_points)])
    return np.broadcast_to(C, (n_points,) + C.shape).copy(), x


def _multistart_gamma(C, x, X0) -> float:
    """An independent upper reference: the best local L2 optimum from perturbed starts."""
    rng = np.random.default_rng(0)
    regions = [tritools.Point(p) for p in x]
    best = np.inf
    for k in range(6):
        X = refine_l2(X0 + (0.0 if k == 0 else rng.normal(scale=0.3, size=3)), C, regions)
        if X is not None:
            best = min(best, float(tritools.gamma(X, C, regions)))
    return best


def _assert_same_rows(a, b, rows) -> None:
    """Rows ``rows`` of two records identical (status, bounds, estimate, attempts' steps and statuses)."""
    for m in rows:
        ra, rb = a[m], b[m]
        assert ra.status == rb.status and ra.optimal == rb.optimal and ra.delta == rb.delta
        np.testing.assert_array_equal(ra.X, rb.X)
        assert ra.gamma_lb == rb.gamma_lb and ra.gamma_ub == rb.gamma_ub
        assert [(t.step, t.status) for t in ra.attempts] == [(t.step, t.status) for t in rb.attempts]


def test_batch_stage_list_and_registries_are_named_data():
    assert [s.name for s in BATCH_STAGES] == ["plan", "verify", "sdp", "per_point", "report"]
    assert [i.name for i in BATCH_VERIFY_IMPLEMENTATIONS] == ["verify-points"]
    assert [i.name for i in BATCH_SDP_IMPLEMENTATIONS] == ["sdp-points"]
    with pytest.raises(ValueError, match="no stage named 'settle'"):
        with_stage(BATCH_STAGES, Stage("x", lambda ctx: None), after="settle")
    with pytest.raises(ValueError, match="already in the list"):
        with_stage(BATCH_STAGES, Stage("sdp", lambda ctx: None), before="report")


def test_batch_certificates_hold_against_an_independent_reference():
    """Every row the batch certifies: gamma_lb <= the multi-start L2 optimum <= gamma_ub (within the rule)."""
    C, x = _stack(4, 25, 2.0, seed=11)
    rec = solve_point_stack(C, x, TriangulationOptions()).record()
    assert rec.optimal.all()
    for m in range(len(x)):
        ref = _multistart_gamma(C[m], x[m], rec.X[m])
        assert rec.gamma_lb[m] <= ref * (1 + 1e-9) + 1e-12
        assert ref <= rec.gamma_ub[m] * (1 + 1e-9) + 1e-12
        assert rec.gamma_ub[m] - rec.gamma_lb[m] <= 1e-6 * max(1.0, rec.gamma_ub[m])


def test_an_inserted_stage_sees_the_open_rows_and_leaves_the_others_untouched():
    """A stage after ``verify`` that records the open rows: the results are those of the plain stages; the
    rows it saw open are exactly those whose verification failed (their first attempt says so)."""
    C, x = _stack(3, 60, 300.0, seed=3)           # 300 px noise: a few rows are not certified by verification
    seen = {}

    def count_open(ctx):
        seen["open"] = ctx.open.copy()

    opts = TriangulationOptions()
    stages = with_stage(BATCH_STAGES, Stage("count_open", count_open), after="verify")
    plain = solve_point_stack(C, x, opts).record()
    mine = solve_point_stack(C, x, opts, stages=stages).record()
    _assert_same_rows(plain, mine, range(len(x)))
    failed = np.array([r.attempts[0].status == "verification_failed" for r in plain])
    assert failed.any() and not failed.all()
    np.testing.assert_array_equal(seen["open"], failed)


def test_a_stage_closing_rows_by_a_user_rule():
    """A stage before ``verify`` closing the rows observed outside a 2000 px image: those rows keep its status
    and message with no bounds and no attempts; every other row is what the plain stages give."""
    C, x = _stack(3, 30, 1.0, seed=4)
    far = np.zeros(len(x), bool)
    far[[2, 9, 17]] = True
    x[far, 0, 0] += 1e4

    def inside_image(ctx):
        out = ctx.open & (np.abs(ctx.x) > 2000).any(axis=(1, 2))
        ctx.close(np.nonzero(out)[0], Status.INVALID_INPUT, "outside the 2000 px image")

    stages = with_stage(BATCH_STAGES, Stage("inside_image", inside_image), before="verify")
    plain = solve_point_stack(C, x, TriangulationOptions()).record()
    mine = solve_point_stack(C, x, TriangulationOptions(), stages=stages).record()
    _assert_same_rows(plain, mine, np.nonzero(~far)[0])
    for m in np.nonzero(far)[0]:
        r = mine[m]
        assert r.status == Status.INVALID_INPUT and r.message == "outside the 2000 px image"
        assert r.gamma_lb is None and r.gamma_ub is None and not r.optimal and r.attempts == ()
    assert mine.status[~far].tolist() == plain.status[~far].tolist()


def test_without_fast_implementations_every_row_goes_through_the_point_stages():
    """``fast=()``: the batch verify and sdp stages do nothing and ``per_point`` solves every row -- the same
    decisions and bounds (within the solver's accuracy) as the vectorised implementations."""
    C, x = _stack(3, 6, 1.0, seed=8)
    opts = TriangulationOptions()
    fast = run_batch(C, x, opts, per_point=per_point_runner())
    slow = run_batch(C, x, opts, fast=(), per_point=per_point_runner())
    assert fast.done.all() and not fast.objects
    assert not slow.done.any() and sorted(slow.objects) == list(range(len(x))) and not slow.open.any()
    for m in range(len(x)):
        a, b = fast.record([m])[0], slow.objects[m]
        assert a.status == b.status and a.optimal == b.optimal
        assert abs(a.gamma_ub - b.gamma_ub) <= 1e-7 * max(1.0, b.gamma_ub)
        assert abs(a.gamma_lb - b.gamma_lb) <= 1e-6 * max(1.0, b.gamma_ub)


def test_open_rows_left_by_a_list_without_per_point_are_still_solved():
    C, x = _stack(2, 5, 1.0, seed=2)
    stages = tuple(s for s in BATCH_STAGES if s.name != "per_point")
    rec = solve_point_stack(C, x, TriangulationOptions(path="sdp", max_delta=4, delta=4, method="corollary1"),
                            stages=stages).record()
    assert len(rec) == 5 and all(r.status is not None for r in rec)
    assert (rec.delta == 4).all()                # the batch stages do not apply at delta = 4: all per point


@pytest.mark.parametrize("n_views,noise,seed", [(2, 0.0, 1), (3, 1.0, 2), (5, 3.0, 3), (4, 40.0, 5)])
def test_a_batch_of_one_is_a_single_call(n_views, noise, seed):
    """The batch stages on a batch of one (the single call's fast set: no batched SDP) give the single call's
    decision, bounds and estimate."""
    C, x = _stack(n_views, 1, noise, seed)
    opts = TriangulationOptions()
    ctx = run_batch(C, x, opts, fast=FAST_DEFAULT, per_point=per_point_runner())
    row = ctx.objects[0] if 0 in ctx.objects else ctx.record([0])[0]
    single = tritools.triangulate(C[0], x[0])
    assert row.status == single.status and row.optimal == single.optimal
    assert abs(row.gamma_ub - single.gamma_ub) <= 1e-9 * max(1.0, single.gamma_ub)
    assert abs(row.gamma_lb - single.gamma_lb) <= 1e-7 * max(1.0, single.gamma_ub)
    np.testing.assert_allclose(row.X, single.X, rtol=1e-7, atol=1e-9 * np.linalg.norm(single.X))


def test_point_stages_are_untouched_by_the_batch_list():
    assert [s.name for s in POINT_STAGES] == ["plan", "verify", "trivial", "sub_problem", "steps", "exact_variety",
                                              "settle", "world_frame", "report"]


def test_triangulate_many_engine_runs_the_batch_stages_per_group():
    """``solve_point_problems`` (the engine of ``triangulate_many``) with an inserted stage: groups of 2 and 3
    views and a non-point problem, results in input order; the rule's rows closed, every other row equal to
    ``triangulate_many``'s."""
    from tritools.solve.batch import solve_point_problems

    C2, x2 = _stack(2, 4, 1.0, seed=6)
    C3, x3 = _stack(3, 4, 1.0, seed=7)
    ell = (C3[0], [tritools.Ellipse(p, 4.0 * np.eye(2)) for p in x3[0]])
    problems = [(C2[0], x2[0]), (C3[0], x3[0]), ell, (C2[1], x2[1] + 5e3), (C3[1], x3[1]), (C2[2], x2[2])]

    def inside_image(ctx):
        ctx.close(np.nonzero(ctx.open & (np.abs(ctx.x) > 4e3).any(axis=(1, 2)))[0], Status.INVALID_INPUT, "outside")

    rule = Stage("inside_image", inside_image)
    opts = TriangulationOptions()
    rec = solve_point_problems(problems, opts, stages=with_stage(BATCH_STAGES, rule, before="verify")).record()
    plain = tritools.triangulate_many(problems)
    assert rec[3].status == Status.INVALID_INPUT and rec[3].message == "outside" and not plain[3].message
    _assert_same_rows(plain, rec, [0, 1, 2, 4, 5])
    assert rec.n_views.tolist() == [2, 3, 3, 2, 3, 2] and rec[2].optimal == plain[2].optimal
