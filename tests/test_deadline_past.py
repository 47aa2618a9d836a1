"""Nothing starts past a deadline that a later stage has to pay for (issue #22: "no call exceeds its time limit by
more than 10%"): the interior-point backend does not set up a program once the deadline has passed, and a plan of
SDP steps has its answer of last resort (the local estimate) before its first step, not after the step the deadline
cut."""
import numpy as np
import scipy.sparse as sp

import tritools
from sospoly.budget import Deadline
from sospoly.lowering.conic import Cone, ConicProblem
from sospoly.solvers import backends
from sospoly.solvers.backends import IpmBackend, RawStatus
from sospoly.algebra.svec import svec
from tritools.scene import uncertain_problem


def _lmin(n=4, seed=0):
    """max c s.t. A - c I >= 0 in conic form (one PSD block: the IPM's program)."""
    M = np.random.default_rng(seed).standard_normal((n, n))
    A = svec(np.eye(n))[:, None]
    return ConicProblem(np.array([-1.0]), sp.csc_matrix(A), svec(M @ M.T), (Cone("psd", n * (n + 1) // 2, n),), 1, ())


def test_the_ipm_is_not_set_up_past_the_deadline(monkeypatch):
    import sospoly.solvers.ipm as ipm

    def boom(*a, **k):
        raise AssertionError("the IPM was set up past the deadline")
    monkeypatch.setattr(ipm, "ipm_solve_sparse", boom)
    monkeypatch.setattr(ipm, "ipm_solve_batch", boom)
    sol = IpmBackend().solve(_lmin(), deadline=Deadline.after(0.0))
    assert sol.attempts[0].label == backends.IPM_LABEL
    assert sol.attempts[0].raw_status == RawStatus.TIME_LIMIT and sol.attempts[0].iterations == 0
    assert all(a.raw_status == RawStatus.TIME_LIMIT for a in sol.attempts)
    assert sol.x is None


def test_the_ipm_still_solves_before_the_deadline():
    prob = _lmin()
    sol = IpmBackend().solve(prob, deadline=Deadline.after(60.0))
    M = np.random.default_rng(0).standard_normal((4, 4))
    assert sol.raw_status == RawStatus.SOLVED
    assert abs(-sol.primal_objective - np.linalg.eigvalsh(M @ M.T)[0]) < 1e-6


def test_sdp_steps_have_the_local_estimate_before_the_first_step():
    P, R, _ = uncertain_problem(6, seed=1, kinds="mixed")
    res = tritools.triangulate(P, R, path="sdp")
    keys = list(res.timings)
    assert "local" in keys and "build" in keys
    assert keys.index("local") < keys.index("build")        # computed before the step's problem was built
    assert res.X is not None and res.gamma_ub is not None


def test_default_q_is_the_power_of_one_plus_the_squared_norm():
    from sospoly import Polynomial
    from sospoly.certificates.psatz import default_q
    gens = ("a", "b", "c")
    norm2 = Polynomial.constant(1.0, gens)
    for k in range(len(gens)):
        norm2 = norm2 + Polynomial(gens, {tuple(2 * (j == k) for j in range(3)): 1.0})
    for delta, deg_f, k in ((2, 2, 0), (4, 2, 1), (6, 2, 2), (4, 4, 0), (3, 0, 1)):
        q = default_q(gens, delta, deg_f)
        assert q.terms == (norm2 ** k).terms and q.gens == gens


def test_a_search_over_regions_computes_a_candidate_s_residuals_once(monkeypatch):
    from tritools.solve import robust
    P, R, X = uncertain_problem(5, seed=2, kinds="mixed")
    s = robust.TlsSearch(P, R, np.full(5, 3.0), tritools.TriangulationOptions(), 0.0)
    calls = []
    real = robust.point_report
    monkeypatch.setattr(robust, "point_report", lambda *a, **k: calls.append(1) or real(*a, **k))
    d = s.residuals(X)
    assert len(calls) == 1 and s.residuals(np.array(X, float)) is d and len(calls) == 1
    assert not d.flags.writeable
    assert np.array_equal(d, real(X, s.C, s.regions, s.opts.world_frame).residuals)
    s.residuals(X + 1.0)
    assert len(calls) == 2
    monkeypatch.setattr(robust, "RESIDUAL_MEMO", 1)         # full: it starts afresh, and stays right
    e = s.residuals(X + 2.0)
    assert len(s._memo) == 1 and np.array_equal(e, real(X + 2.0, s.C, s.regions, s.opts.world_frame).residuals)


def _shifted_problem(N=6, seed=7):
    """Mixed regions, c = 5 px, the two views outside the first centre pair moved 94 px away (wrong matches)."""
    from tritools.solve.robust_rays import sampled_pairs
    P, R, X = uncertain_problem(N, seed=seed, kinds="mixed")
    first = sorted(sampled_pairs(N, np.random.default_rng(1), 8)[0])
    bad = [i for i in range(N) if i not in first][:2]
    R = list(R)
    for i in bad:
        R[i] = R[i].similarity(1.0, np.array([-80.0, 50.0]))
    return P, R, bad


def test_a_robust_search_over_regions_has_an_anytime_candidate_with_an_inlier_set():
    """A limit that ends the search before any L2 sub-problem returns: the best centre-pair DLT point, with the wrong
    matches out (review 15 F3: the local L2 estimate of every view, every view an outlier, gamma_UB = c / sqrt 2)."""
    P, R, bad = _shifted_problem()
    c = 5.0
    for limit in (1e-4, 1e-3):
        res = tritools.triangulate(P, R, robust=c, time_limit=limit)
        assert res.status == tritools.Status.TIME_LIMIT and not res.optimal
        assert res.gamma_ub < c / np.sqrt(2) * (1 - 1e-6)
        assert res.inliers.sum() >= 2 and not res.inliers[bad].any()
    full = tritools.triangulate(P, R, robust=c)
    assert full.optimal and full.gamma_lb <= res.gamma_ub      # the anytime value is an upper bound of the optimum
    assert not full.inliers[bad].any()


def test_centre_pair_candidates_are_the_dlt_points_of_the_centres():
    from tritools.model.geometry import dlt
    from tritools.solve import robust
    from tritools.solve.robust_rays import CENTRE_PAIRS, centre_pair_candidates, sampled_pairs
    for N in (2, 4, 7):
        P, R, _ = uncertain_problem(N, seed=3, kinds="mixed")
        s = robust.TlsSearch(P, R, np.full(N, 5.0), tritools.TriangulationOptions(), 0.0)
        Xs = centre_pair_candidates(s)
        pairs = sampled_pairs(N, np.random.default_rng(1), CENTRE_PAIRS)
        assert len(Xs) == min(CENTRE_PAIRS, N * (N - 1) // 2) == len(pairs)
        for X, p in zip(Xs, pairs):
            i, j = sorted(p)
            ref = dlt(s.C[[i, j]], np.array([R[i].center, R[j].center]))
            assert np.allclose(X, ref, rtol=1e-6, atol=1e-9 * (1 + np.abs(ref).max()))


def test_default_q_names_a_degree_that_is_not_an_integer():
    import pytest
    from sospoly.certificates.psatz import default_q
    for bad in (2.0, 4.0, None, "4", True):
        with pytest.raises(TypeError, match="delta"):
            default_q(["x"], bad, 2)
    with pytest.raises(TypeError, match="deg_f"):
        default_q(["x"], 4, 2.0)
    assert default_q(["x"], np.int64(4), 2).terms == {(0,): 1.0, (2,): 1.0}


def test_a_batch_reports_region_problems_it_did_not_reach_from_their_centres(monkeypatch):
    """Past the whole call's end, a problem with regions gets the DLT point of its region centres, gamma_UB its exact
    value there, status time_limit -- no refinement, no normalisation (review 15 F1) -- and a problem that does not
    validate still gets invalid_input naming what is wrong."""
    from tritools.model.geometry import dlt
    from tritools.solve import call_limit
    from tritools.solve.report import point_report

    probs = [uncertain_problem(6, 40 + j, kinds="mixed")[:2] for j in range(4)]
    bad = (probs[0][0][:, :, :3], probs[0][1])                 # 3x3 cameras
    def no_local(*a, **k):
        raise AssertionError("a problem past the end was refined")
    monkeypatch.setattr("tritools.solve.trivial.local_estimate", no_local)
    monkeypatch.setattr("tritools.solve.stages.context.local_estimate", no_local)
    res = tritools.triangulate_many(probs + [bad], total_time_limit=1e-9)
    assert len(res) == 5 and res[4].status == tritools.Status.INVALID_INPUT and "shape" in res[4].message
    for (P, R), r in zip(probs, res[:4]):
        assert r.status == tritools.Status.TIME_LIMIT and not r.optimal and r.gamma_lb is None
        assert call_limit.CUT_MESSAGE in r.message and "region centres" in r.message
        X = dlt(P, np.array([reg.center for reg in R]))
        assert np.allclose(r.X, X, rtol=1e-9, atol=1e-12)
        rep = point_report(r.X, P, R)
        assert r.gamma_ub == rep.gamma and np.array_equal(r.residuals, rep.residuals)


def _robust_search(N, n_out, seed=3):
    import time

    from tritools.scene import robust_protocol_scene
    from tritools.solve.options import options_from
    from tritools.solve.robust import TlsSearch, robust_thresholds

    P, x, X, _ = robust_protocol_scene(N, n_out, 1.0, np.random.default_rng(seed))
    s = TlsSearch(P, None, robust_thresholds(5.0, N), options_from(None), time.perf_counter(), points=x)
    s.set_deadline(Deadline(None))
    return s, X


def test_a_screen_started_past_the_deadline_takes_one_small_block():
    """TlsSearch.screen ranks candidates in blocks; one that starts past the deadline evaluates SCREEN_LATE
    candidate-views only (the rest rank last), one before it evaluates every candidate."""
    from tritools.solve import robust as rob

    s, X = _robust_search(400, 80)
    Xs = X + np.random.default_rng(0).normal(size=(500, 3)) * 0.1
    assert np.isfinite(s.screen(Xs)).all()
    s.set_deadline(Deadline.after(0.0))
    f = s.screen(Xs)
    n = max(1, rob.SCREEN_LATE // 400)
    assert np.isfinite(f[:n]).all() and np.isinf(f[n:]).all()


def test_the_rays_golden_section_stops_at_the_deadline(monkeypatch):
    """robust_rays.ray_candidates: the sweep's screen, then no golden-section step once the deadline has passed
    (each screen call computes its first block whatever the time: 22 of them ran ~30 ms past a 0.05 s limit at
    400 views); before the deadline the golden section runs its steps."""
    from tritools.solve import robust_rays

    calls = {}
    for late in (False, True):
        s, _ = _robust_search(12, 3)
        s.offer(np.zeros(3))
        screen = s.screen
        n = []

        def counted(Xs, screen=screen, n=n):
            n.append(len(Xs))
            out = screen(Xs)
            if late:
                s.set_deadline(Deadline.after(0.0))          # the deadline passes during the sweep's screen
            return out
        s.screen = counted
        out = robust_rays.ray_candidates(s)
        calls[late] = len(n)
        assert out and all(np.isfinite(X).all() for X in out)
    assert calls[True] == 1 and calls[False] > robust_rays.GOLDEN_STEPS


def test_a_batch_past_its_total_limit_keeps_every_row_of_bad_input():
    """triangulate_many past its total_time_limit reports the point problems it did not reach from one vectorised
    estimate (call_limit.expired_points); a problem with NaN cameras, an infinite observation, a camera of rank < 3
    or all cameras equal among them gets the per-point check's invalid_input row (the message a batch without the
    limit gives) instead of failing the call (it raised LinAlgError) or an estimate, and the others keep theirs."""
    from tritools.scene import robust_protocol_scene

    P, x, _, _ = robust_protocol_scene(4, 0, 1.0, np.random.default_rng(0))
    Pb, xb, Pr = P.copy(), x.copy(), P.copy()
    Pb[1, 0, 0], xb[2, 0], Pr[0, 1] = np.nan, np.inf, 0.0
    Pe = np.broadcast_to(P[0], P.shape).copy()                    # all cameras equal: ill-posed
    probs = [(P, x), (Pb, x), (P, xb), (P * 1e300, x), (P, x + 1.0), (Pr, x), (Pe, x)]
    free = tritools.triangulate_many(probs)
    cut = tritools.triangulate_many(probs, total_time_limit=1e-9)
    assert len(cut) == len(probs)
    for k in (1, 2, 5, 6):                                        # non-finite, rank < 3, all equal
        bad = tritools.Status.ILL_POSED if k == 6 else tritools.Status.INVALID_INPUT     # equal: valid, no problem
        assert cut[k].status == free[k].status == bad
        assert cut[k].message == free[k].message
    for k in (0, 3, 4):
        assert cut[k].status == tritools.Status.TIME_LIMIT and cut[k].X is not None and cut[k].gamma_ub is not None


def test_batches_of_extreme_cameras_raise_no_numpy_warning():
    """Cameras scaled by 1e300 / 1e-300 (the same cameras) in triangulate_many and triangulate_points: the batch
    steps' overflow is checked for finiteness, and numpy's warnings (an exception under -W error) stay inside; every
    point certified as with unscaled cameras."""
    import warnings

    from tritools.scene import robust_protocol_scene

    P, x, _, _ = robust_protocol_scene(4, 0, 1.0, np.random.default_rng(0))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        many = tritools.triangulate_many([(P * k, x) for k in (1.0, 1e300, 1e-300)])
        pts = [tritools.triangulate_points(P * k, np.array([x, x + 1.0])) for k in (1e300, 1e-300)]
    assert all(r.optimal for r in many)
    assert all(bool(np.all(r.optimal)) for r in pts)
