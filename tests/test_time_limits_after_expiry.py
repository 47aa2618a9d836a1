"""What runs after a time limit has passed (issue #22: no call exceeds its limit by more than 10%; wave 9).

No timings: the tests assert which work is skipped or bounded once the deadline has passed, that the results stay
valid (bounds against independent references), and that the vectorised point / disc evaluations that replace
per-view loops give the loops' numbers."""
import numpy as np
import pytest
from scipy.optimize import least_squares

import tritools
import tritools.model.geometry as geometry
import tritools.model.refine as refine
import tritools.solve.robust_bounds as rb
import tritools.solve.robust_suspects as rs
from sospoly.budget import Deadline, deadline_scope
from tritools.model.regions import Ellipse, Point, Segment
from tritools.scene import robust_protocol_scene
from tritools.solve.robust import TlsSearch
from tritools.solve.robust_verify import parent_frames, verify_in_parent


def _regions(x, kind, radius=1.0):
    return [Point(p) for p in x] if kind == "points" else [Ellipse(p, radius ** 2 * np.eye(2)) for p in x]


def _distances(P, x, X, kind, radius=1.0):
    h = P @ np.append(X, 1.0)
    d = np.linalg.norm(h[:, :2] / h[:, 2:] - x, axis=1)
    return d if kind == "points" else np.maximum(d - radius, 0.0)


# ----------------------------------------------------------------------------- vectorised points and discs
@pytest.mark.parametrize("kind", ["points", "discs"])
def test_vectorised_residuals_and_gamma_match_the_region_loop(kind):
    """The stacked residuals of the refinement and gamma of point / disc regions equal the per-view loop over the
    regions' own closest points (the generic path), also at pixel scales 1e-3 and 1e6 and inside the discs."""
    for seed, scale in [(0, 1.0), (1, 1e-3), (2, 1e6)]:
        P, x, X, _ = robust_protocol_scene(30, 5, 1.0, np.random.default_rng(seed))
        A = np.diag([scale, scale, 1.0])
        P, x = A @ P, x * scale
        regs = _regions(x, kind, 3.0 * scale)
        fun, vectorised = refine.residual_function(P, regs)
        assert vectorised
        for Y in (X, X + 0.05, X - 0.2):
            np.testing.assert_allclose(fun(Y), refine._looped_residuals(Y, P, regs), rtol=1e-12,
                                       atol=1e-12 * scale)
        Xs = np.array([X, X + 0.05, [np.nan, 0.0, 0.0]])
        loop = np.array([np.sqrt(sum(float(r.distance(geometry.project(Y, Pi))) ** 2 for Pi, r in zip(P, regs))
                                 / (2 * len(P))) if np.isfinite(Y).all() else np.inf for Y in Xs])
        got = geometry.gamma_validated(Xs, P, regs)
        assert np.isinf(got[2]) and np.isinf(loop[2])
        np.testing.assert_allclose(got[:2], loop[:2], rtol=1e-12)


def test_other_regions_keep_the_loop():
    P, x, X, _ = robust_protocol_scene(5, 0, 1.0, np.random.default_rng(3))
    regs = [Segment(p - 1, p + 1) for p in x]
    assert refine.disc_shapes(regs) is None and not refine.residual_function(P, regs)[1]


# ----------------------------------------------------------------------------- the refinement past the deadline
def count_residual_evaluations(monkeypatch) -> list:
    """A list that grows by one per evaluation of refine_l2's residuals (monkeypatched for the test)."""
    calls = []
    real = refine.residual_function

    def counted(cameras, regions):
        fun, vec = real(cameras, regions)
        return (lambda Y: calls.append(1) or fun(Y)), vec

    monkeypatch.setattr(geometry, "residual_function", counted)
    return calls


@pytest.mark.parametrize("kind", ["points", "discs"])
def test_refinement_after_the_deadline_is_bounded_and_returns_its_best_iterate(kind, monkeypatch):
    """Past the active deadline, refine_l2 evaluates the residuals at most evaluations_after(N) times (counted),
    and its estimate is no worse than the start (any X is a valid estimate; gamma_UB only less tight)."""
    P, x, X, _ = robust_protocol_scene(400, 0, 1.0, np.random.default_rng(5))
    regs = _regions(x, kind)
    calls = count_residual_evaluations(monkeypatch)
    X0 = X + np.array([0.3, -0.2, 0.1])
    monkeypatch.setattr(refine, "MIN_EVALS_AFTER_DEADLINE", 5)
    monkeypatch.setattr(refine, "VIEW_EVALS_AFTER_DEADLINE", 5)
    with deadline_scope(Deadline.after(0.0)):
        Xr = geometry.refine_l2(X0, P, regs)
    assert len(calls) == 5                                    # stopped by the guard, not by convergence
    assert Xr is not None and np.all(np.isfinite(Xr))
    g = lambda Y: geometry.gamma_validated(np.asarray(Y, float)[None], P, regs)[0]   # noqa: E731
    assert g(Xr) <= g(X0)
    calls.clear()
    free = geometry.refine_l2(X0, P, regs)                    # no deadline: runs to convergence
    assert len(calls) > 5 and g(free) <= g(Xr) * (1 + 1e-12)
    ref = least_squares(lambda Y: _distances(P, x, Y, kind), X0, method="lm", xtol=1e-15, ftol=1e-15).x
    assert g(free) <= g(ref) * (1 + 1e-9)                     # an independent local minimum


def test_the_guard_allows_many_evaluations_to_small_problems():
    """The trivial bound after a time limit needs the local estimate to converge: stacked point / disc residuals
    keep scipy's whole budget (400 evaluations) past the deadline, a three-view looped problem over 100 (~25
    Levenberg-Marquardt iterations); the looped evaluations of more views (each N closest points, 10-140 us
    apiece) about LOOPED_VIEW_EVALS_AFTER_DEADLINE region distances in all (16 mixed regions used to get 500
    evaluations: 0.1-0.5 s past a limit), a 400-view one only the start and its Jacobian."""
    assert refine.evaluations_after(3, vectorised=False) >= 100
    assert refine.evaluations_after(400, vectorised=True) >= 400
    for n in (3, 12, 16, 30, 100):
        allowed = refine.evaluations_after(n, vectorised=False)
        assert allowed >= refine.MIN_LOOPED_EVALS_AFTER_DEADLINE
        assert allowed * n <= max(refine.LOOPED_VIEW_EVALS_AFTER_DEADLINE, 4 * n)
    assert refine.evaluations_after(16, vectorised=False) < 100
    assert refine.evaluations_after(400, vectorised=False) == refine.MIN_LOOPED_EVALS_AFTER_DEADLINE == 4


# ----------------------------------------------------------------------------- the robust search past the deadline
class _Almost:
    """A deadline that has not passed, with 1 ms left whenever asked."""
    end = 0.0
    expired = False

    @staticmethod
    def remaining():
        return 1e-3


class _SlowClock:
    """robust_verify's clock: every reading one second later (a chunk then takes 1 s)."""
    t = 0.0

    @classmethod
    def monotonic(cls):
        cls.t += 1.0
        return cls.t


def test_parent_verification_starts_no_chunk_predicted_past_the_deadline(monkeypatch):
    """In chunks: the first one holds the subsets predicted to end in time (``_first_cost`` each, at least one), a
    later one those the time per subset so far says end before the deadline; the others are not started: their
    subsets are not accepted (bound 0, no estimate)."""
    import tritools.solve.robust_verify as rv

    P, x, X, _ = robust_protocol_scene(12, 0, 1.0, np.random.default_rng(2))
    frame = parent_frames(P[None], x[None])[0]
    subsets = [np.array(sorted(set(range(12)) - {j})) for j in range(12)]
    monkeypatch.setattr(rv, "CHUNK_VIEW_ROWS", 33)           # 3 subsets of 11 views per chunk
    monkeypatch.setattr(rv, "time", _SlowClock)
    args = ([P] * 12, [frame] * 12, subsets, [[]] * 12, tritools.TriangulationOptions().tolerances)
    good, lb, Xs = verify_in_parent(*args, deadline=_Almost())
    full, lb_full, _ = verify_in_parent(*args)
    first = max(1, min(3, int(1e-3 // rv._first_cost(11))))       # the first chunk: as many as are predicted to fit
    assert full.all() and good[:first].all() and not good[first:].any()
    assert np.all(lb[first:] == 0.0) and np.isnan(Xs[first:]).all()
    np.testing.assert_allclose(lb[:first], lb_full[:first], rtol=1e-12)   # (a stack of one: other last bits)
    monkeypatch.setattr(rv, "_first_cost", lambda k: 1e-4)         # predicted to fit: a whole first chunk of 3
    good, lb, Xs = verify_in_parent(*args, deadline=_Almost())
    assert good[:3].all() and not good[3:].any()
    np.testing.assert_allclose(lb[:3], lb_full[:3], rtol=1e-12)      # (a stack of 3 against one of 12: numpy's
    # vectorised loops may round the last bits of stacks of other sizes differently: numpy 2.4 does here)


def test_compute_many_past_the_deadline_stores_zero_without_packing(monkeypatch):
    """Past the deadline the sub-bounds requested get 0 (valid) and no pair packing bound (O(|S|^2) per subset)."""
    P, x, X, _ = robust_protocol_scene(40, 12, 1.0, np.random.default_rng(1))
    search = TlsSearch(P, None, np.full(40, 2.0), tritools.TriangulationOptions(), 0.0, points=x)
    search.bounds.compute([frozenset((0, 1)), frozenset((2, 3))])
    search.set_deadline(Deadline.after(0.0))
    monkeypatch.setattr(rb.SubsetBounds, "packing_bound", lambda self, S: pytest.fail("packing after the deadline"))
    big = [frozenset(range(40)) - {j} for j in range(40)]
    search.bounds.compute(big)
    assert all(search.bounds.known(S) and search.bounds.bound(S) == 0.0 for S in big)


def test_suspect_cover_past_the_deadline_builds_no_pairs(monkeypatch):
    """Past the deadline the suspects' cover requests no view pairs (|O| (N - 1) of them: 15,000 frozensets at
    N = 200 with 30% wrong matches, ~0.1 s after a limit) and gives the valid bound 0."""
    P, x, X, out = robust_protocol_scene(120, 36, 1.0, np.random.default_rng(8))
    search = TlsSearch(P, None, np.full(120, 2.0), tritools.TriangulationOptions(), 0.0, points=x)
    search.offer(X)
    O = frozenset(range(120)) - search.best_S
    assert len(O) > 10
    search.set_deadline(Deadline.after(0.0))
    monkeypatch.setattr(TlsSearch, "verify_first", lambda self, *S: pytest.fail(f"{len(S)} subsets requested"))
    gen = rs.cover(search, O)
    with pytest.raises(StopIteration) as stop:
        next(gen)
    assert stop.value.value == 0.0


def test_robust_call_with_an_early_limit_keeps_valid_bounds():
    """A 120-view track with 30% wrong matches and a limit that passes early: status time_limit, bounds below the
    TLS cost at the true point (an upper bound of the optimum computed outside tritools)."""
    P, x, X, out = robust_protocol_scene(120, 36, 1.0, np.random.default_rng(8))
    r = tritools.triangulate(P, x, robust=2.0, time_limit=0.05)
    assert r.status == tritools.Status.TIME_LIMIT
    d = _distances(P, x, X, "points")
    ref = np.sqrt(np.sum(np.minimum(d * d, 4.0)) / (2 * len(d)))
    assert 0.0 <= r.gamma_lb <= ref * (1 + 1e-9) and r.gamma_lb <= r.gamma_ub


@pytest.mark.parametrize("kind", ["discs"])
def test_robust_disc_screen_matches_the_exact_costs(kind):
    """The TLS screen and residuals of disc regions (vectorised) equal the exact per-region costs of point_report."""
    from tritools.solve.report import point_report
    from tritools.solve.robust import tls_cost

    P, x, X, _ = robust_protocol_scene(25, 5, 1.0, np.random.default_rng(4))
    regs = _regions(x, kind)
    c = np.full(25, 2.0)
    search = TlsSearch(P, regs, c, tritools.TriangulationOptions(), 0.0)
    Xs = np.array([X, X + 0.1, X - 0.3])
    exact = [point_report(Y, P, regs).residuals for Y in Xs]
    np.testing.assert_allclose(search.screen(Xs), [tls_cost(d, c) for d in exact], rtol=1e-12)
    np.testing.assert_allclose(search.residuals(X), exact[0], rtol=1e-12, atol=1e-12)


def test_no_band_bound_started_where_its_estimate_does_not_fit(monkeypatch):
    """The band bound of a width is started only where band_seconds fits in what is left of the deadline (one band
    call at N = 400 takes 0.08-0.22 s); the all pairs, estimated to fit, still bound the 20-view problem validly."""
    import tritools.solve.fastpath as fp

    assert fp.band_seconds(400, 8) > fp.band_seconds(400, 4) > fp.band_seconds(100, 4)
    assert fp.band_seconds(100, 4, 3) == pytest.approx(3 * fp.band_seconds(100, 4))
    P, x, X, _ = robust_protocol_scene(20, 0, 1.0, np.random.default_rng(6))

    class Short:
        end, expired = 0.0, False

        @staticmethod
        def remaining():
            return 0.5 * fp.band_seconds(20, fp.BAND_WIDTHS[0])

    assert fp.all_pairs_seconds(20) < Short.remaining()
    free = fp.verify_points(P[None], x[None])
    monkeypatch.setattr(fp, "cpu_share", lambda: 1.0)                 # a quiet machine
    monkeypatch.setattr(fp, "_band_bounds", lambda *a, **k: pytest.fail("band started past its estimate"))
    b = fp.verify_points(P[None], x[None], deadline=Short())
    assert b.ok[0] and np.isfinite(b.gamma_lb[0])
    assert b.gamma_lb[0] <= free.gamma_ub[0] * (1 + 1e-9)


def test_cpu_share_from_the_load_average(monkeypatch):
    """Wall-clock deadlines: on an over-committed machine a step's wall time is its CPU time over the share of a
    core the process gets (cores / load), never below MIN_CPU_SHARE; 1 on a quiet machine or without a load
    average.  The bounds' time estimates are divided by it (a band that fits a quiet machine does not fit under
    load)."""
    import os

    import sospoly.budget as budget
    import tritools.solve.fastpath as fp

    cores = os.cpu_count() or 1
    for load, share in [(0.0, 1.0), (cores, 1.0), (4.0 * cores, 0.25), (1e6, budget.MIN_CPU_SHARE)]:
        monkeypatch.setattr(os, "getloadavg", lambda load=load: (load, load, load))
        assert budget.cpu_share() == pytest.approx(share)

    def unavailable():
        raise OSError

    monkeypatch.setattr(os, "getloadavg", unavailable)
    assert budget.cpu_share() == 1.0

    class Left:
        end, expired = 0.0, False

        @staticmethod
        def remaining():
            return 1.5 * fp.band_seconds(100, 4)

    monkeypatch.setattr(fp, "cpu_share", lambda: 1.0)
    assert fp.seconds_fit(Left(), fp.band_seconds(100, 4))
    monkeypatch.setattr(fp, "cpu_share", lambda: 0.5)
    assert not fp.seconds_fit(Left(), fp.band_seconds(100, 4))


@pytest.mark.parametrize("kind", ["points", "discs"])
def test_screen_past_the_deadline_ranks_only_its_first_block(kind, monkeypatch):
    """The screen of many candidates runs in blocks of SCREEN_BLOCK candidate-views; one that starts past the
    deadline screens only a first block of SCREEN_LATE candidate-views and the rest rank last (inf); before it, every
    candidate gets its f_TLS."""
    import tritools.solve.robust as robust

    P, x, X, _ = robust_protocol_scene(40, 8, 1.0, np.random.default_rng(9))
    regs = None if kind == "points" else _regions(x, kind)
    search = TlsSearch(P, regs, np.full(40, 2.0), tritools.TriangulationOptions(), 0.0,
                       points=x if kind == "points" else None)
    monkeypatch.setattr(robust, "SCREEN_BLOCK", 400)                  # 10 candidates per block
    monkeypatch.setattr(robust, "SCREEN_LATE", 200)                   # 5 past the deadline
    Xs = X + np.random.default_rng(0).normal(scale=0.1, size=(35, 3))
    full = search.screen(Xs)
    assert np.isfinite(full).all()
    d = np.array([_distances(P, x, Y, kind) for Y in Xs])
    np.testing.assert_allclose(full, np.sum(np.minimum(d * d, 4.0), axis=1), rtol=1e-9)
    search.set_deadline(Deadline.after(0.0))
    late = search.screen(Xs)
    np.testing.assert_array_equal(late[:5], full[:5])
    assert np.isinf(late[5:]).all()


def test_expired_cache_in_a_shared_batch_leaves_the_others_their_packing_bounds(monkeypatch):
    """compute_many serves several searches at once (a robust batch): the items of a search whose deadline has passed
    get 0 and no packing bound, those of a search with time left still get theirs."""
    P, x, X, _ = robust_protocol_scene(30, 9, 1.0, np.random.default_rng(1))
    opts = tritools.TriangulationOptions()
    late, live = (TlsSearch(P, None, np.full(30, 2.0), opts, 0.0, points=x) for _ in range(2))
    pairs = [frozenset((i, j)) for i in range(30) for j in range(i + 1, 30)]
    rb.compute_many([(late.bounds, pairs), (live.bounds, pairs)])
    late.set_deadline(Deadline.after(0.0))
    packed = []
    real = rb.SubsetBounds.packing_bound
    monkeypatch.setattr(rb.SubsetBounds, "packing_bound", lambda self, S: packed.append(self) or real(self, S))
    big = [frozenset(range(30)) - {j} for j in range(30)]
    rb.compute_many([(late.bounds, big), (live.bounds, big)])
    assert packed and all(sb is live.bounds for sb in packed)
    assert all(late.bounds.bound(S) == 0.0 for S in big)
    assert all(live.bounds.known(S) for S in big)


def test_banded_loops_stop_at_the_active_deadline():
    """The banded Cholesky and solves read the active deadline in their column loops: past it they raise
    TimeLimitReached (a 400-view band takes 0.1-0.3 s, past a short limit); without one, the same factor as LAPACK's."""
    import scipy.linalg

    from sospoly.analysis.banded import band_cholesky, band_from_dense, band_solve
    from sospoly.budget import TimeLimitReached

    rng = np.random.default_rng(0)
    n, b = 200, 3
    A = np.zeros((n, n))
    for d in range(b + 1):
        A += np.diag(rng.uniform(-0.2, 0.2, n - d), -d) + (np.diag(rng.uniform(-0.2, 0.2, n - d), d) if d else 0)
    A = 0.5 * (A + A.T) + 4.0 * np.eye(n)
    ab = band_from_dense(A[None], b)
    R, ok = band_cholesky(ab)
    assert ok[0]
    np.testing.assert_allclose(R[0], scipy.linalg.cholesky_banded(ab[0], lower=True), rtol=1e-12, atol=1e-12)
    rhs = rng.normal(size=(1, n))
    np.testing.assert_allclose(A @ band_solve(R, rhs)[0], rhs[0], atol=1e-10)
    with deadline_scope(Deadline(0.0)):
        with pytest.raises(TimeLimitReached):
            band_cholesky(ab)
        with pytest.raises(TimeLimitReached):
            band_solve(R, rhs)


def test_band_bound_interrupted_by_the_deadline_leaves_no_bound(monkeypatch):
    """A band bound whose column loops meet the active deadline gives no lower bound (NaN, valid) instead of
    raising or running on: the 60-view track is then left to the caller's time limit."""
    import tritools.solve.fastpath as fp

    P, x, X, _ = robust_protocol_scene(60, 0, 1.0, np.random.default_rng(8))
    free = fp.verify_points(P[None], x[None])
    assert free.certified[0]
    monkeypatch.setattr(fp, "seconds_fit", lambda deadline, seconds: True)     # started however little time is left
    with deadline_scope(Deadline(0.0)):
        b = fp.verify_points(P[None], x[None], deadline=Deadline(None))
    assert not b.certified[0] and np.isnan(b.gamma_lb[0])


def test_time_limit_counts_from_the_call_entry(monkeypatch):
    """A call's time limit counts from its entry (the input checks are inside it): the point stages and the robust
    search see a deadline at most time_limit after the call started, however long the checks before them took."""
    import time

    import tritools.solve.settings as settings
    from sospoly.budget import Budget
    from tritools import TriangulationOptions
    from tritools.solve.stages.context import PointContext

    P, x, X, _ = robust_protocol_scene(6, 0, 1.0, np.random.default_rng(2))
    opts = TriangulationOptions(budget=Budget(time_limit=0.5))
    t0 = time.perf_counter() - 0.3                       # the call started 0.3 s ago (slow input checks)
    ctx = PointContext(P, [Point(p) for p in x], opts, t0)
    assert ctx.settings.deadline.remaining() <= 0.2 + 1e-3
    assert settings.call_deadline(opts, time.perf_counter() - 1.0).expired
    assert settings.call_deadline(TriangulationOptions(budget=Budget(time_limit=None)), 0.0).end is None
    seen = []
    monkeypatch.setattr(tritools.solve.robust.TlsSearch, "set_deadline",
                        lambda self, d: seen.append(d.remaining()) or setattr(self, "deadline", d))
    tritools.triangulate(P, x, robust=2.0, time_limit=0.5)
    assert seen and seen[0] <= 0.5


def test_sampled_pairs_are_the_combinations_draw():
    """The candidate stage's pairs without the full list: the same pairs in the same order as drawing from
    list(itertools.combinations(range(N), 2)) with the same generator (79,800 pairs at N = 400)."""
    import itertools

    from tritools.solve.robust import MAX_PAIRS
    from tritools.solve.robust_rays import sampled_pairs

    for N in (2, 3, 10, 32, 33, 120, 400):
        for seed in range(2):
            pairs = list(itertools.combinations(range(N), 2))
            rng = np.random.default_rng(seed)
            if len(pairs) > MAX_PAIRS:
                pairs = [pairs[k] for k in rng.choice(len(pairs), MAX_PAIRS, replace=False)]
            assert sampled_pairs(N, np.random.default_rng(seed), MAX_PAIRS) == [frozenset(p) for p in pairs]


def test_a_verification_cut_by_the_limit_says_time_limit_not_budget_exceeded():
    """A 100-view track with 30% wrong matches: the bands do not certify and the all-pairs bound (estimated
    0.22 s) does not fit in a 0.2 s limit; the dense SDP after it is refused by the memory budget.  The call said
    ``budget_exceeded`` ("use a larger budget"), although without the limit the verification certifies: the limit
    stopped it, so ``time_limit`` with the reason, and its estimate is the no-limit call's optimum."""
    from tritools.solve.fastpath import fits

    P, x, _, _ = robust_protocol_scene(100, 30, 1.0, np.random.default_rng(1))
    assert not fits(Deadline.after(0.2), 100)
    cut = tritools.triangulate(P, x, time_limit=0.2)
    full = tritools.triangulate(P, x)
    assert full.optimal
    assert cut.status == tritools.Status.TIME_LIMIT and not cut.optimal
    assert "all-pairs bound did not fit" in cut.message
    assert cut.attempts[0].status == "time_limit"
    assert cut.gamma_lb is None or cut.gamma_lb <= full.gamma_ub * (1 + 1e-9)
    assert cut.gamma_ub >= full.gamma_lb * (1 - 1e-12)


def test_region_verification_is_not_started_when_its_bound_cannot_fit(monkeypatch):
    """100 views of mixed regions at a 0.05 s limit: the local estimate took ~40 ms, then the region verification
    spent ~30 ms on its per-view set-up before its Lagrangian bound was skipped for time (1.36x the limit).  It is
    not started now when its set-up and cheapest bound do not fit (:func:`region_bound_fits`), and the attempt
    says time_limit."""
    import tritools.solve.stages.verify as verify
    from tritools.scene import uncertain_problem
    from tritools.solve.regions_verify import region_bound_fits

    assert region_bound_fits(None, 100) and region_bound_fits(Deadline.after(10.0), 100)
    assert not region_bound_fits(Deadline.after(0.01), 100)         # 30 ms of set-up alone
    assert region_bound_fits(Deadline.after(0.05), 5)
    P, R = uncertain_problem(12, seed=5, kinds="mixed")[:2]
    free = tritools.triangulate(P, R)
    monkeypatch.setattr(verify, "region_bound_fits", lambda deadline, n: False)
    called = []
    monkeypatch.setattr(verify, "region_bound", lambda *a, **k: called.append(1))
    cut = tritools.triangulate(P, R, time_limit=5.0, max_delta=2)
    assert not called and cut.attempts[0].status == "time_limit"
    # the plan goes on (here with time for its SDP): a certificate stays a certificate, with the same optimum
    assert cut.status == free.status and cut.optimal == free.optimal
    assert cut.gamma_lb <= free.gamma_ub * (1 + 1e-9) and free.gamma_lb <= cut.gamma_ub * (1 + 1e-9)


def test_a_region_sub_problem_without_time_for_its_set_up_is_not_started(monkeypatch):
    """Robust calls on 100 views of mixed regions at 0.05 s started their all-views L2 sub-problem with ~40 ms left;
    its regions' normalisation and the verification's set-up cannot stop at a deadline (1.2-1.6x the limit).  A
    sub-problem of regions is started only with SUB_REGION_SETUP_SECONDS a view left: else bound 0 (valid), weak."""
    import tritools.solve.robust_bounds as rbounds
    from tritools.scene import uncertain_problem
    from tritools.solve.options import TriangulationOptions

    P, R = uncertain_problem(12, seed=3, kinds="mixed")[:2]
    calls = []
    monkeypatch.setattr(rbounds, "solve_subproblem", lambda *a, **k: calls.append(k) or None)
    opts = TriangulationOptions()
    S = frozenset(range(12))
    sb = rbounds.SubsetBounds(P, R, opts, Deadline.after(12 * rbounds.SUB_REGION_SETUP_SECONDS / 2))
    sb._solve_one(S)
    assert not calls and sb._lb[S] == 0.0 and S in sb.weak and S not in sb.exhausted
    sb = rbounds.SubsetBounds(P, R, opts, Deadline.after(10.0))
    sb._solve_one(S)
    assert len(calls) == 1                           # with time: started (the stub answers None: bound 0)
    pts = rbounds.SubsetBounds(P, [Point(r.center) for r in R], opts, Deadline.after(1e-4))
    pts._solve_one(S)
    assert len(calls) == 2                           # point sub-problems have no such set-up: started


def test_a_looped_refinement_with_an_iterate_stops_at_the_overrun_share():
    """Past the deadline the looped residuals (N closest points each) kept a floor of 4 evaluations even when the
    refinement already had an iterate: ~10 ms past a 0.05 s limit at 100 views of mixed regions.  With an iterate
    (``early``), the overrun share stops it; the vectorised guard keeps its floor."""
    import time

    fun = lambda X: np.asarray(X, float)      # noqa: E731
    with deadline_scope(Deadline.after(0.001)):
        time.sleep(0.01)                      # well past the deadline and its overrun share
        for early, expected in ((True, 1), (False, 4)):
            guard = refine.EvaluationGuard(fun, 100, 4, early=early)
            n = 0
            with pytest.raises(refine.RefinementStopped):
                for _ in range(10):
                    guard(np.ones(3))
                    n += 1
            assert n == expected and guard.best_X is not None
