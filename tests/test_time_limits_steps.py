"""Steps that used to run past a time limit (issue #22, wave 12): each now reads the deadline inside the step.

No timings: a deadline that passes *during* the step (set by the step's own work, counted) or that is shorter than
the step is predicted to take makes it stop with the named status, and the results without such a deadline are
unchanged (the same iterates, the same numbers)."""
from __future__ import annotations

import time

import numpy as np
import pytest
from scipy.optimize import least_squares

import sospoly
import tritools.model.geometry as geometry
import tritools.model.refine as refine
from sospoly.budget import Deadline, TimeLimitReached, deadline_scope
from sospoly.certificates import program as program_mod
from sospoly.algebra.svec import svec
from sospoly.analysis.extraction import CandidateFamily, best_in_family, span_search
from sospoly.certificates.psatz import DataSlots, dense_shape, psatz_structure
from sospoly.lowering.conic import Cone
from sospoly.solvers.ipm import core, ipm_solve_batch
from tritools.scene import uncertain_problem
from tests.test_time_limits_after_expiry import count_residual_evaluations


class _Switch:
    """A deadline whose end moves: far away until :meth:`expire` (then passed)."""

    def __init__(self):
        self.end = float("inf")

    def expire(self):
        self.end = 0.0

    @property
    def expired(self):
        return self.end <= 0.0

    def remaining(self):
        return 0.0 if self.expired else 1e9


# ----------------------------------------------------------------------------- the certificate's multipliers
def _equality_program(k: int):
    x = sospoly.variables("x", n=4)
    f = sum((xi - 1) ** 2 for xi in x)
    eq = [x[i % 4] * x[(i + 1) % 4] - (i + 1) for i in range(k)]
    return f, eq, x


def test_multipliers_stop_at_a_deadline_that_passes_among_them(monkeypatch):
    """The equality multipliers r_k are made one by one with the deadline read before each (a dense 100-view
    program with discs has ~5,000 of them: 12 s past a 5 s limit before): the deadline passing at the first one
    stops the loop at the second with TimeLimitReached naming the multipliers."""
    f, eq, x = _equality_program(12)
    slots = DataSlots.of(f, eq, ())
    shape = dense_shape(4, 4, [g.degree for g in eq], [])
    made = []
    real = program_mod.SOSProgram.free_poly
    switch = _Switch()

    def counted(self, *a, **kw):
        made.append(1)
        switch.expire()
        return real(self, *a, **kw)

    whole = psatz_structure(slots, 4, shape, sospoly.Polynomial.constant(1.0, slots.gens))
    assert len(whole.r) == 12                                  # without a deadline: every multiplier
    monkeypatch.setattr(program_mod.SOSProgram, "free_poly", counted)
    with deadline_scope(switch), pytest.raises(TimeLimitReached, match="multipliers"):
        psatz_structure(slots, 4, shape, sospoly.Polynomial.constant(1.0, slots.gens))
    assert len(made) == 1


# ----------------------------------------------------------------------------- the interior-point iteration
def _lambda_min():
    """max c s.t. M - c I >= 0 (optimum lambda_min(M)) in the IPM's form: min -c, s = svec(M) - c svec(I)."""
    rng = np.random.default_rng(5)
    M = rng.standard_normal((6, 6))
    M = M + M.T
    A = svec(np.eye(6))[None, :, None]
    return A, svec(M)[None], np.array([-1.0]), (Cone("psd", 21, 6),), np.linalg.eigvalsh(M)[0]


def test_out_of_time_compares_the_time_left_with_the_next_iteration():
    assert not core.out_of_time(None, 10.0)
    assert not core.out_of_time(Deadline(None), 10.0)
    assert core.out_of_time(Deadline.after(0.0), 0.0)            # passed
    left = Deadline.after(30.0)
    assert core.out_of_time(left, 60.0)                          # the next iteration would end past it
    assert not core.out_of_time(left, 1.0)


def test_ipm_does_not_start_an_iteration_predicted_past_the_deadline(monkeypatch):
    """The first iteration is predicted from the program's size (core.predicted_iteration); with 60 s left and
    an iteration predicted at hours, the method stops before it with the reason "time limit".  With the real
    constant the same 60 s change nothing: the iterates equal those without a deadline, bit for bit."""
    A, b, q, cones, lam = _lambda_min()
    free = ipm_solve_batch(A, b, q, cones)
    assert free.converged[0] and abs(free.x[0, 0] - lam) < 1e-6
    timed = ipm_solve_batch(A, b, q, cones, deadline=Deadline.after(60.0))
    assert np.array_equal(timed.x, free.x) and timed.iterations[0] == free.iterations[0]
    monkeypatch.setattr(core, "IPM_SECONDS_PER_UNIT", 1e6)
    stopped = ipm_solve_batch(A, b, q, cones, deadline=Deadline.after(60.0))
    assert not stopped.converged[0] and stopped.reason[0] == "time limit" and stopped.iterations[0] == 0


def test_ipm_stops_when_less_is_left_than_the_last_iteration_took(monkeypatch):
    """After the first iteration the measured one is the prediction: a clock that advances 10 s per iteration
    against a deadline 25 s away stops the method after two iterations (the third would end past it), not at
    the deadline's passing."""
    A, b, q, cones, _ = _lambda_min()
    clock = {"t": 1000.0}
    monkeypatch.setattr(core.time, "monotonic", lambda: clock["t"])
    real = core._Newton.__init__

    def slow(self, *a, **kw):
        clock["t"] += 10.0
        real(self, *a, **kw)

    monkeypatch.setattr(core._Newton, "__init__", slow)
    monkeypatch.setattr(core, "predicted_iteration", lambda *a: 0.0)
    res = ipm_solve_batch(A, b, q, cones, deadline=Deadline(1025.0))
    assert res.reason[0] == "time limit" and res.iterations[0] == 2
    assert clock["t"] <= 1025.0                                   # never past the deadline


# ----------------------------------------------------------------------------- the refinement of other regions
def test_looped_refinement_after_the_deadline_is_bounded(monkeypatch):
    """Regions without a stacked distance (segments, ellipses, polytopes: each closest point 10-140 us) are
    refined through a loop over the views; past the deadline it makes at most evaluations_after(N, False) more
    evaluations (counted), and fewer once OVERRUN_SHARE_AFTER_DEADLINE of the limit has gone by (never fewer than
    evaluations_floor: the start); its estimate is no worse than the start."""
    P, R, X = uncertain_problem(16, seed=3, kinds="mixed")
    calls = count_residual_evaluations(monkeypatch)
    monkeypatch.setattr(refine, "LOOPED_VIEW_EVALS_AFTER_DEADLINE", 16 * 6)
    X0 = X + np.array([0.3, -0.2, 0.1])
    g = lambda Y: geometry.gamma_validated(np.asarray(Y, float)[None], P, R)[0]   # noqa: E731
    with deadline_scope(Deadline.after(0.0, span=1e9)):          # a long limit: the counted allowance decides
        Xr = geometry.refine_l2(X0, P, R)
    assert len(calls) == 6 == refine.evaluations_after(16, vectorised=False)
    assert Xr is not None and g(Xr) <= g(X0)
    calls.clear()
    with deadline_scope(Deadline.after(0.0)):                     # a zero limit: any time past it is too much
        Xz = geometry.refine_l2(X0, P, R)
    assert len(calls) == refine.evaluations_floor(vectorised=False) == 1
    assert Xz is not None and np.array_equal(Xz, X0)                   # the start: the estimate of last resort
    calls.clear()
    free = geometry.refine_l2(X0, P, R)
    assert len(calls) > 6 and g(free) <= g(Xr) * (1 + 1e-12)


# ----------------------------------------------------------------------------- minimiser candidates past the deadline
def test_span_search_and_family_scan_stop_at_the_deadline():
    """The candidate searches are heuristics whose every partial answer is valid: past the deadline no start is
    searched (span_search: no point; best_in_family: the family's first member, one evaluation)."""
    E = np.array([[0, 0], [1, 0], [0, 1]])
    W = np.array([[1.0], [1.0], [2.0]])                       # span of b(v*) = (1, v1, v2) at v* = (1, 2)
    found = span_search(W, E, [np.zeros(2)])
    assert found and np.allclose(found[0], [1.0, 2.0], atol=1e-6)
    with deadline_scope(Deadline.after(0.0)):
        assert span_search(W, E, [np.zeros(2)]) == []
    fam = CandidateFamily(np.eye(3), np.array([1, 2]), np.array([1.0, 0.0, 0.0]), np.eye(3)[:, 1:])   # v(t) = t
    evals = []

    def objective(v):
        evals.append(1)
        return float(np.sum((v - 1.0) ** 2))

    _, free_val = best_in_family(fam, objective, max_evals=400)
    assert free_val < 1e-3 and len(evals) > 1                  # the searched family: near its minimum at t = 1
    evals.clear()
    with deadline_scope(Deadline.after(0.0)):
        v, val = best_in_family(fam, objective, max_evals=400)
    assert len(evals) == 1 and val == objective(np.zeros(2)) and np.array_equal(v, np.zeros(2))
    # the deadline passing during a Nelder-Mead run (one evaluation of gamma over mixed regions is ~1 ms, a run
    # several hundred): it stops at the next evaluation with the best member evaluated so far
    switch, seen = _Switch(), []

    def expiring(v):
        seen.append((float(np.sum((v - 1.0) ** 2)), np.array(v)))
        if len(seen) == 8:
            switch.expire()
        return seen[-1][0]

    with deadline_scope(switch):
        v, val = best_in_family(fam, expiring, max_evals=400)
    assert len(seen) == 8 and val == min(e for e, _ in seen) and np.allclose(v, min(seen, key=lambda p: p[0])[1])


def test_no_extraction_past_the_deadline_the_earlier_estimate_stands_in(monkeypatch):
    """A step whose SDP returns after the call's deadline extracts no candidates (0.5-1.4 s past a 0.2-1 s limit
    on this six-view track before): the local estimate stands in, the result is ``time_limit`` with a valid
    lower bound (below an independent upper bound of the optimum) and gamma_UB the objective at the reported X."""
    import tritools
    import tritools.solve.stages.estimate as est
    import tritools.solve.stages.sdp as sdp
    from tritools.scene import robust_protocol_scene

    P, x, X, _ = robust_protocol_scene(6, 1, 1.0, np.random.default_rng(6010))
    real_solve, extracted = sdp.solve_psatz, []

    def late(ctx, *a, **kw):
        out = real_solve(ctx, *a, **kw)
        while not ctx.settings.deadline.expired:            # the deadline passes before the extraction
            time.sleep(0.01)
        return out

    monkeypatch.setattr(sdp, "solve_psatz", late)
    monkeypatch.setattr(est, "_best_candidate", lambda *a: extracted.append(1))
    r = tritools.triangulate(P, x, time_limit=0.5)
    assert not extracted
    assert r.status == tritools.Status.TIME_LIMIT and not r.optimal

    def gamma(Y):
        h = P @ np.append(Y, 1.0)
        return float(np.sqrt(np.sum((h[:, :2] / h[:, 2:] - x) ** 2) / (2 * len(P))))

    ref = min(gamma(X), gamma(least_squares(lambda Y: (lambda h: (h[:, :2] / h[:, 2:] - x).ravel())(
        P @ np.append(Y, 1.0)), X, method="lm").x))
    assert r.gamma_lb is not None and r.gamma_lb <= ref * (1 + 1e-9)
    assert r.gamma_ub == pytest.approx(gamma(r.X), rel=1e-9) and r.gamma_ub >= r.gamma_lb


# ----------------------------------------------------------------------------- the vectorised stages of a batch
def test_a_stack_deadline_ends_with_the_batch_call():
    """The vectorised stages of a batch got M x the per-point limit whatever the call's total_time_limit (six
    100-view tracks under total_time_limit=0.2 ran their band and all-pairs bounds for ~2 s): the stack's
    deadline now ends with the enclosing call."""
    from tritools import TriangulationOptions
    from tritools.solve.call_limit import call_limit
    from tritools.solve.settings import stack_deadline

    opts = TriangulationOptions()
    assert stack_deadline(opts, 6).remaining() > 300            # 6 x the default 60 s per point
    with call_limit(0.5):
        assert stack_deadline(opts, 6).remaining() <= 0.5
    with call_limit(1e-9):
        time.sleep(1e-3)
        assert stack_deadline(opts, 6).expired
    assert stack_deadline(TriangulationOptions(budget=sospoly.Budget(time_limit=None)), 6).end is None


def test_batched_sdp_starts_nothing_past_its_deadline(monkeypatch):
    """Past its deadline the batched degree-2 SDP hands every problem back with the named reason before its
    epipolar data (~0.4 s at 6 x 100 views)."""
    import tritools.solve.sdp_batch as sb
    from tritools.scene import random_scene

    sc = random_scene(5, 3, seed=2)
    C = np.repeat(sc.cameras[None], 3, axis=0)
    x = sc.points2d                                             # (3 points, 5 views, 2)
    done = sb.solve_corollary1_points(C, x)
    assert done.done.all()
    monkeypatch.setattr(sb, "fundamental_stack_both",
                        lambda *a: pytest.fail("epipolar data computed past the deadline"))
    late = sb.solve_corollary1_points(C, x, deadline=Deadline.after(0.0))
    assert not late.done.any() and set(late.reason) == {"time limit reached before the batched SDP"}


# ----------------------------------------------------------------------------- the data slots' index
def test_data_slots_not_indexed_when_the_index_cannot_end_in_time(monkeypatch):
    """Indexing the stacked supports (and looking an instance's coefficients up in them) is one native call each
    (~1.3 s of CPU at 100 disc regions, dense): not started when its predicted time does not fit in what is
    left of the deadline; with time enough, the same slots and theta as without a deadline."""
    import sospoly.certificates.psatz as psatz

    f, eq, _ = _equality_program(6)
    free = DataSlots.of(f, eq, ())
    with deadline_scope(Deadline.after(60.0)):
        timed = DataSlots.of(f, eq, ())
        assert timed.key() == free.key()
        assert np.array_equal(timed.theta(f, eq), free.theta(f, eq))
    monkeypatch.setattr(psatz, "INDEX_SECONDS_PER_ENTRY", 1e3)      # hours: more than the 60 s left
    with deadline_scope(Deadline.after(60.0)), pytest.raises(TimeLimitReached, match="indexing the data's supports"):
        DataSlots.of(f, eq, ())
    with deadline_scope(Deadline.after(60.0)), pytest.raises(TimeLimitReached, match="coefficients"):
        free.theta(f, eq)
    assert np.array_equal(free.theta(f, eq), DataSlots.of(f, eq, ()).theta(f, eq))    # no deadline: no refusal


# ----------------------------------------------------------------------------- the moment form's plateaus
#: merits (|pobj - dobj| + pres + dres) per iteration of recorded moment-form solves (wave 12 traces): a
#: Theorem 1 delta = 4 three-view program that stalls on a plateau from iteration 7, and the converging run
#: (four views) that came closest to a plateau from iteration 8 (its merit fell 4.2x over two iterations there)
STALLING = [2.4, 1.1, 0.82, 0.34, 1.8e-2, 8.4e-4, 3.0e-5, 7.4e-5, 7.7e-5, 7.7e-5, 7.7e-5, 7.7e-5]
CONVERGING = [2.41, 5.22, 3.81, 3.43, 0.861, 0.0592, 0.00376, 0.000244, 2.11e-05, 3.11e-06, 1.05e-06, 7.41e-07,
              1.79e-07, 1.4e-08, 3.37e-09]


def _first_stall(merits, flat):
    history = np.full((1, 5), np.inf)
    for it, m in enumerate(merits):
        if core.stalled_rule(it, np.array([m]), history, flat)[0]:
            return it
        history[0, :-1] = history[0, 1:]
        history[0, -1] = m
    return None


def test_the_moment_form_stops_at_a_plateau_not_on_a_converging_run():
    """The halving rule declares the plateau stalled at iteration 11; the flat rule (the moment form's: its
    fallback, the unreduced method, starts afresh, so the result is the same) at 8.  Neither fires on the
    converging run."""
    assert _first_stall(STALLING, flat=False) == 11
    assert _first_stall(STALLING, flat=True) == 8
    assert _first_stall(CONVERGING, flat=False) is None and _first_stall(CONVERGING, flat=True) is None


def test_region_verification_not_started_past_the_deadline(monkeypatch):
    """The local estimate the region verification starts from can end past the deadline (a looped refinement of
    30 mixed regions); the verification (a face bound over every view's closest points) is then not started: the
    call ends ``time_limit`` with the local estimate, gamma_UB the objective at its X."""
    import tritools
    import tritools.solve.stages.context as context
    import tritools.solve.stages.verify as verify
    from tritools.scene import uncertain_problem

    P, R, _ = uncertain_problem(6, seed=6000, kinds="mixed")
    real_local, started = context.local_estimate, []

    def late(cams, regs):
        out = real_local(cams, regs)
        t_end = time.monotonic() + 0.6                       # past the 0.5 s limit of the call
        while time.monotonic() < t_end:
            time.sleep(0.01)
        return out

    monkeypatch.setattr(context, "local_estimate", late)
    monkeypatch.setattr(verify, "region_bound", lambda *a, **kw: started.append(1) or pytest.fail("started"))
    r = tritools.triangulate(P, R, time_limit=0.5)
    assert not started and r.status == tritools.Status.TIME_LIMIT and not r.optimal
    h = P @ np.append(r.X, 1.0)
    u = h[:, :2] / h[:, 2:]
    g = float(np.sqrt(sum(float(reg.distance(ui)) ** 2 for reg, ui in zip(R, u)) / (2 * len(R))))
    assert r.gamma_ub == pytest.approx(g, rel=1e-9)


def test_all_pairs_bounds_as_many_problems_as_fit(monkeypatch):
    """A batch cut by its time limit runs the all-pairs bound on the problems that fit instead of none
    (fastpath.fitting, the rule of fastpath.seconds_fit): 0 past the deadline, everything without one, and floor(left /
    per-problem estimate) in between (cpu_share fixed at 1)."""
    from sospoly.budget import Deadline

    from tritools.solve import fastpath

    monkeypatch.setattr(fastpath, "cpu_share", lambda: 1.0)
    per = fastpath.all_pairs_seconds(100, 1)
    assert fastpath.fitting(None, 100, 7) == 7
    assert fastpath.fitting(Deadline.after(0.0), 100, 7) == 0
    assert fastpath.fitting(Deadline.after(2.5 * per), 100, 7) == 2
    assert fastpath.fitting(Deadline.after(100 * per), 100, 7) == 7


def test_deadline_overrun_is_the_share_of_the_limit_gone_by_since_it_passed():
    import time

    assert Deadline(None).overrun() == 0.0 and Deadline.after(None).span is None
    assert Deadline.after(10.0).overrun() == 0.0 and Deadline.after(10.0).span == 10.0
    late = Deadline(time.monotonic() - 1.0, span=2.0).overrun()
    assert 0.5 <= late < 0.75
    assert Deadline(time.monotonic() - 1.0).overrun() == float("inf")          # no span: any lateness is too much
    assert Deadline.after(-1.0, span=4.0).overrun() >= 0.25


def test_steps_stop_a_report_reserve_before_the_limit():
    """Review 18: past its steps' deadline a call still reports at its estimate (3-6 ms at 8-30 views of regions):
    the steps' deadline comes ``report_reserve(limit)`` before the limit (10%, at most 0.5 s)."""
    import time

    from tritools.solve.options import options_from
    from tritools.solve.settings import REPORT_RESERVE_MAX, call_deadline, report_reserve

    assert report_reserve(0.05) == pytest.approx(0.005) and report_reserve(60.0) == REPORT_RESERVE_MAX
    for limit in (0.05, 2.0, 60.0):
        t0 = time.perf_counter()
        d = call_deadline(options_from(None, time_limit=limit), t0)
        left = d.remaining()
        assert limit - report_reserve(limit) - 0.01 <= left <= limit - report_reserve(limit)


def test_report_reserve_grows_with_views_of_regions():
    """Wave 19: 100 views of mixed regions at 0.05 s ran 8-10 ms past the steps' deadline: the reserve covers the
    regions' share (REPORT_SECONDS_PER_REGION a view), never more than half the limit nor REPORT_RESERVE_MAX."""
    import time

    from tritools.solve.options import options_from
    from tritools.solve.settings import (REPORT_RESERVE_MAX, REPORT_RESERVE_TOP_SHARE, REPORT_SECONDS_PER_REGION,
                                         call_deadline, report_reserve)

    assert report_reserve(0.05, 100) == pytest.approx(max(0.005, 100 * REPORT_SECONDS_PER_REGION))
    assert report_reserve(0.05, 10) == pytest.approx(0.005)                 # the share where it is larger
    assert report_reserve(0.05, 10 ** 6) == pytest.approx(REPORT_RESERVE_TOP_SHARE * 0.05)
    assert report_reserve(60.0, 10 ** 6) == REPORT_RESERVE_MAX
    assert report_reserve(0.05, -3) == report_reserve(0.05)
    t0 = time.perf_counter()
    import tritools

    discs = [tritools.Ellipse([0.0, 0.0], np.eye(2))] * 100 + [tritools.Point([1.0, 2.0])] * 5     # points: no share
    left = call_deadline(options_from(None, time_limit=0.05), t0, discs).remaining()
    assert 0.05 - report_reserve(0.05, 100) - 0.01 <= left <= 0.05 - report_reserve(0.05, 100)


def test_mixed_regions_normalised_by_class_equal_one_by_one():
    """Normalization.regions stacks the regions of each class with a stacked construction (mixed lists too): the
    same fields as each region's own similarity, bit for bit, in the input order."""
    from tritools.model.normalize import normalization_for
    from tritools.scene import uncertain_problem

    P, R, _ = uncertain_problem(40, seed=4, kinds="mixed")
    assert len({type(r) for r in R}) >= 4
    norm = normalization_for(np.asarray(P), R)
    got = norm.regions(R)
    for i, (r, g) in enumerate(zip(R, got)):
        ref = r.similarity(norm.scale, norm.shifts[i])
        assert type(g) is type(ref)
        for name in ("center", "D", "B", "c", "vertices", "a", "b"):
            if hasattr(ref, name):
                assert np.array_equal(np.asarray(getattr(g, name)), np.asarray(getattr(ref, name))), (i, name)
