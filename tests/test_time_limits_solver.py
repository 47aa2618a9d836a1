"""Issue 22: no call exceeds its time limit by more than 10% (plus a fixed 0.3 s for the clock reads and
the report around the solver).

Clarabel's ``time_limit`` is checked between interior-point iterations; its set-up, initial point and one
iteration cannot be interrupted.  Before the fix, Theorem 1 with mixed regions on 8 views at delta = 4 with
``time_limit=3`` returned after 6.8 s: the build left 0.15 s and Clarabel's uninterruptible start took 4.2 s.
The Clarabel back-end now predicts that start from the program's size
(:class:`sospoly.budget.ClarabelTimeModel`), does not start an attempt that cannot finish it before the
deadline, and gives Clarabel the time left minus that start."""
from __future__ import annotations

import time

import numpy as np
import pytest
import scipy.sparse as sp

import sospoly
import tritools
from sospoly.algebra.svec import svec
from sospoly.budget import ClarabelTimeModel, Deadline
from sospoly.lowering.conic import Cone, ConicProblem
from sospoly.solvers.backends import Attempt, ClarabelBackend, RawStatus
from tritools import TriangulationOptions, triangulate
from tritools.scene import uncertain_problem


def _lambda_min_problem(side: int, seed: int = 0) -> tuple[ConicProblem, float]:
    """max c s.t. S - c I >= 0: optimum lambda_min(S) (a closed form)."""
    rng = np.random.default_rng(seed)
    S = rng.standard_normal((side, side))
    S = S + S.T
    L = side * (side + 1) // 2
    A = svec(np.eye(side)).reshape(L, 1)
    prob = ConicProblem(np.array([-1.0]), sp.csc_matrix(A), svec(S), (Cone("psd", L, side),), 1, ())
    return prob, float(np.linalg.eigvalsh(S)[0])


def test_time_model_grows_with_the_blocks_and_follows_measurements():
    m = ClarabelTimeModel()
    small, big = m.first_iteration([10], 100), m.first_iteration([68] * 11, 10000)
    assert 0 < small < 0.1 < 1.0 < big                      # 11 blocks of side 68: seconds, not milliseconds
    assert m.iteration([68] * 11, 10000) < big
    m.observe([68] * 11, 10000, setup_seconds=4 * big, solve_seconds=8 * big, iterations=1)   # a slow machine
    assert m.scale > 1.0
    slow = m.first_iteration([68] * 11, 10000)
    assert slow > big
    for _ in range(50):                                     # clipped: one odd measurement cannot run away
        m.observe([68] * 11, 10000, setup_seconds=1e6, solve_seconds=0.0, iterations=0)
    assert m.scale == pytest.approx(ClarabelTimeModel.SCALE_RANGE[1]) and m.scale <= ClarabelTimeModel.SCALE_RANGE[1]
    before = m.scale
    m.observe([3], 10, setup_seconds=1e-4, solve_seconds=1e-4, iterations=3)                   # noise: ignored
    assert m.scale == before


def test_fast_small_programs_never_make_the_model_optimistic():
    """A test suite's fast small programs once pulled the scale to 1/4, and an 8-view Theorem 1 start then
    overran its 3 s limit by 5 s: small programs are not observed, and faster measurements move the scale a
    quarter of the way, never below SCALE_RANGE[0]."""
    m = ClarabelTimeModel()
    for _ in range(100):
        m.observe([12] * 4, 500, setup_seconds=0.06, solve_seconds=0.02, iterations=10)     # small, fast
    assert m.scale == 1.0
    m.observe([68] * 11, 10000, setup_seconds=0.1, solve_seconds=0.1, iterations=10)        # large, fast
    assert 0.75 <= m.scale < 1.0
    for _ in range(100):
        m.observe([68] * 11, 10000, setup_seconds=0.1, solve_seconds=0.1, iterations=10)
    assert m.scale == pytest.approx(ClarabelTimeModel.SCALE_RANGE[0]) and ClarabelTimeModel.SCALE_RANGE[0] >= 0.5
    m.observe([68] * 11, 10000, setup_seconds=60.0, solve_seconds=0.0, iterations=0)        # one slow: at once
    assert m.scale > 1.0


def test_optimism_from_smaller_programs_shrinks_with_the_size():
    """The CI run of the 9-view, delta = 4, 10 s case: 6- and 7-view programs (sum L^2 5.5e6 / 1.2e7) had pulled
    the scale to ~1/2, the 9-view start (3.0e7) was predicted 7.4 s with 9.4 s left, and it ended at 11.8 s.  Its
    measured set-up + first iteration was 0.73 of the prediction at scale 1: the scale learnt on smaller programs
    may not make a larger one cheaper than (size ratio)^GROWTH of it, and a smaller one keeps the full scale."""
    m = ClarabelTimeModel()
    six, nine = [45] * 6, [55] * 9                         # sum L^2 ~ 6e6 and ~2.3e7
    for _ in range(100):
        m.observe(six, 5000, setup_seconds=0.3, solve_seconds=3.0, iterations=9)   # 0.38 of the prediction
    assert m.scale == pytest.approx(ClarabelTimeModel.SCALE_RANGE[0])
    e6, e9 = m._entries(six), m._entries(nine)
    assert m.reference_entries == pytest.approx(e6)
    base9 = ClarabelTimeModel().first_iteration(nine, 5000)
    assert m.first_iteration(nine, 5000) == pytest.approx(base9 * min(1.0, m.scale * (e9 / e6) ** m.GROWTH))
    assert m.first_iteration(nine, 5000) >= 0.9 * base9 > 0.5 * base9
    assert m.first_iteration(six, 5000) == pytest.approx(m.scale * ClarabelTimeModel().first_iteration(six, 5000))
    m.observe(nine, 5000, setup_seconds=60.0, solve_seconds=0.0, iterations=0)    # slow: every size at once
    assert m.scale > 1.0 and m.first_iteration(nine, 5000) > base9


@pytest.mark.slow
def test_theorem1_within_the_limit_at_the_most_optimistic_scale(monkeypatch):
    """The flaky case: 7 views, delta = 4, 3 s, with the process model at its lowest scale."""
    from sospoly.budget import CLARABEL_TIME_MODEL
    monkeypatch.setattr(CLARABEL_TIME_MODEL, "scale", ClarabelTimeModel.SCALE_RANGE[0])
    res, elapsed = _timed_theorem1(7, 4, 3.0, seed=1)
    _check(res, elapsed, 3.0)


@pytest.mark.slow
def test_nine_views_within_the_limit_after_smaller_programs_lowered_the_scale(monkeypatch):
    """The CI failure (11.76 s against 10 s): the scale at 1/2, learnt on the 6-view program (sum L^2 5.5e6)."""
    from sospoly.budget import CLARABEL_TIME_MODEL
    monkeypatch.setattr(CLARABEL_TIME_MODEL, "scale", ClarabelTimeModel.SCALE_RANGE[0])
    monkeypatch.setattr(CLARABEL_TIME_MODEL, "reference_entries", 5.5e6)
    res, elapsed = _timed_theorem1(9, 4, 10.0, seed=1)
    _check(res, elapsed, 10.0)
    assert elapsed <= 10.0        # before: 10.7 s alone (Clarabel started with a 7.4 s prediction), 11.8 s in CI


def test_an_attempt_that_cannot_finish_its_first_iteration_is_not_started():
    prob, lam = _lambda_min_problem(6)
    be = ClarabelBackend()
    t0 = time.perf_counter()
    sol, att = be.solve_once(prob, deadline=Deadline.after(0.5), first_seconds=10.0)
    assert time.perf_counter() - t0 < 0.1
    assert sol is None and att.raw_status == RawStatus.TIME_LIMIT and att.iterations == 0
    assert "not started" in att.solver_status
    out = be.solve(prob, deadline=Deadline.after(10.0))     # enough time: solved, the closed form
    assert out.raw_status == RawStatus.SOLVED
    assert -out.primal_objective == pytest.approx(lam, abs=1e-6)
    made = out.attempts[0]
    assert made.iterations > 0 and 0 < made.start_seconds <= made.seconds      # the measured start of a retry


def test_the_retry_chain_starts_no_attempt_past_the_deadline(monkeypatch):
    """Every attempt fails numerically after 0.3 s: with a 0.5 s deadline the chain stops after the second
    attempt (the first measured 0.3 s, so a third would end past the deadline) with status time_limit."""
    prob, _ = _lambda_min_problem(4)
    started = []

    def failing(self, problem, label="default", overrides=None, deadline=None, first_seconds=0.0, stop_by=None):
        rem = deadline.remaining()
        if rem < first_seconds:
            return None, Attempt(label, RawStatus.TIME_LIMIT, "not started", 0, 0.0)
        started.append((label, rem))
        time.sleep(0.3)
        return None, Attempt(label, RawStatus.FAILED, "NumericalError", 0, 0.3)

    monkeypatch.setattr(ClarabelBackend, "solve_once", failing)
    t0 = time.perf_counter()
    out = ClarabelBackend().solve(prob, deadline=Deadline.after(0.5))
    elapsed = time.perf_counter() - t0
    assert out.raw_status in (RawStatus.TIME_LIMIT, RawStatus.FAILED)
    assert all(rem > 0 for _, rem in started) and len(started) <= 2
    assert elapsed < 0.5 * 1.1 + 0.3


def test_the_retry_chain_skips_settings_it_already_tried():
    """Above QDLDL_MAX_PSD_SIDE the 'qdldl' retry drops qdldl and would repeat the default attempt."""
    big, _ = _lambda_min_problem(45)
    small, _ = _lambda_min_problem(5)
    be = ClarabelBackend()
    labels_big = [label for label, _ in be._chain(big, True)]
    labels_small = [label for label, _ in be._chain(small, True)]
    assert labels_small == ["default", "qdldl", "no-equilibration", "regularised"]
    assert labels_big == ["default", "no-equilibration/faer", "regularised/faer"]
    assert len({str(o) for _, o in be._chain(big, True)}) == len(labels_big)


def _timed_theorem1(n_views: int, delta: int, limit: float, seed: int, kinds="mixed", max_bytes=2 * 2 ** 30):
    cams, regions, _ = uncertain_problem(n_views, seed=seed, kinds=kinds)
    opts = TriangulationOptions(method="theorem1", delta=delta,
                                budget=sospoly.Budget(time_limit=limit, max_bytes=max_bytes))
    t0 = time.perf_counter()
    res = triangulate(cams, regions, options=opts)
    return res, time.perf_counter() - t0


def _check(res, elapsed, limit):
    assert elapsed <= 1.1 * limit + 0.3, f"{elapsed:.2f} s against a {limit} s limit ({res.status.value})"
    if res.status == tritools.Status.TIME_LIMIT:
        assert not res.optimal and "time limit" in res.message
    if res.gamma_lb is not None and res.gamma_ub is not None:
        assert res.gamma_lb <= res.gamma_ub * (1 + 1e-6) + 1e-9


@pytest.mark.parametrize("n_views, delta", [(6, 4), (8, 4)])
def test_theorem1_mixed_regions_within_one_second(n_views, delta):
    res, elapsed = _timed_theorem1(n_views, delta, 1.0, seed=1)
    _check(res, elapsed, 1.0)


@pytest.mark.slow
@pytest.mark.parametrize("n_views, delta, limit", [(7, 4, 3.0), (11, 4, 3.0), (6, 6, 3.0), (6, 4, 10.0),
                                                    (9, 4, 10.0), (11, 4, 10.0)])
def test_theorem1_mixed_regions_within_the_limit(n_views, delta, limit):
    """(6, 4, 10 s): Clarabel runs, fails numerically, the retry stops at its time_limit (measured 8.5 s; it
    took 10.0 s with a repeated retry before); the others stop in the build or before a start that cannot
    finish (8 views, 3 s: 6.8 s before the fix)."""
    res, elapsed = _timed_theorem1(n_views, delta, limit, seed=1)
    _check(res, elapsed, limit)


@pytest.mark.slow
def test_theorem1_eleven_view_point_track_at_delta_6():
    """The issue's case: 11 views, delta = 6, 15 s (measured 17.5 s before): set-up + one iteration of its
    2.6 GB program take ~12 s, so Clarabel is not started with 12 s left."""
    res, elapsed = _timed_theorem1(11, 6, 15.0, seed=2, kinds="point", max_bytes=4 * 2 ** 30)
    _check(res, elapsed, 15.0)


def test_a_step_cut_by_its_solver_time_limit_makes_the_result_time_limit():
    """A plan step whose solver stopped at its own time limit (MaxTime, a little before the call's deadline) left
    the earlier step's not_certified as the result: a robust search then took that sub-problem's bound as final
    ("certification out of reach", test_coplanar's five-view test under load).  Now any attempt ended by the time
    limit makes an uncertified result TIME_LIMIT, also while the deadline has not quite passed."""
    from types import SimpleNamespace

    from tritools.result import Attempt, Status, TriangulationResult
    from tritools.solve.stages.outcome import _stopped_short

    best = TriangulationResult("corollary1", Status.NOT_CERTIFIED, X=np.zeros(3), gamma_ub=1.0, gamma_lb=0.5,
                               optimal=False)
    ctx = SimpleNamespace(expired=False, skipped=None, steps=[], opts=None, verify_cut=False,
                          attempts=[Attempt("corollary1", 4, "not_certified"), Attempt("theorem1", 4, "time_limit")])
    assert _stopped_short(ctx, best).status == Status.TIME_LIMIT
    ctx.attempts = ctx.attempts[:1]
    assert _stopped_short(ctx, best).status == Status.NOT_CERTIFIED
    done = TriangulationResult("theorem1", Status.OPTIMAL, X=np.zeros(3), gamma_ub=1.0, gamma_lb=1.0, optimal=True)
    ctx.attempts = [Attempt("corollary1", 4, "time_limit")]
    assert _stopped_short(ctx, done).status == Status.OPTIMAL


def test_a_program_without_psd_blocks_never_breaks_the_model():
    """Review 17: a fast measurement of a program with no PSD blocks (sum L^2 = 0) recorded reference_entries = 0,
    and every later prediction divided by it (ZeroDivisionError in every Clarabel call with a deadline)."""
    m = ClarabelTimeModel()
    m.observe([], 200000, setup_seconds=0.05, solve_seconds=0.05, iterations=5)      # predicted 0.41 s: fast
    assert m.scale < 1.0 and m.reference_entries > 0
    assert m.first_iteration([68] * 11, 10000) > 0
    m.reference_entries = 0.0                                                        # as recorded before the fix
    assert m.scale_for(1e7) == 1.0
