"""Batched robust (TLS) problems: the point problems' cameras are checked in one vectorised call per view count
(:func:`tritools.solve.robust_batch._point_searches`); a bad camera still gets the per-problem named error and
never stops the batch, and the good problems equal their single-point results."""
import numpy as np
import pytest

import tritools
from tritools.scene import random_scene


def test_bad_cameras_in_a_robust_batch_get_named_errors():
    sc = random_scene(5, 2, noise_px=0.5, seed=3)
    cams, x = sc.cameras, sc.points2d
    rank = cams.copy()
    rank[2] = 0.0
    rank[2, 0, 0] = 1.0                                      # rank 1: not a camera
    same = np.repeat(cams[:1], 5, axis=0)                    # every camera equal: ill-posed
    probs = [(cams, x[0]), (rank, x[0]), (same, x[1]), (cams, x[1])]
    many = tritools.triangulate_many(probs, robust=5.0)
    assert many[1].status == tritools.Status.INVALID_INPUT and "cameras[2]" in many[1].message
    assert many[2].status == tritools.Status.ILL_POSED and "equal" in many[2].message    # valid data, no problem
    for k in (0, 3):
        single = tritools.triangulate(*probs[k], robust=5.0)
        assert many[k].status == single.status and many[k].optimal
        np.testing.assert_array_equal(many[k].inliers, single.inliers)
        # (a single call's normalisation refines with the scalar LM twin: the same numbers up to round-off)
        assert many[k].gamma_ub == pytest.approx(single.gamma_ub, rel=1e-9)
        assert many[k].gamma_lb == pytest.approx(single.gamma_lb, rel=1e-9)


def test_batch_time_limits_are_per_problem(monkeypatch):
    """drive() charges each search its own steps and an even share of a round's batched calls; the rest of the
    round moves its deadline on, before it resumes: with a fake clock, two searches whose rounds take 1 s of
    batched calls and 0.1 s of own steps each are charged 0.6 s a round, not 1.2 s.  One search: nothing moves."""
    import tritools.solve.robust_drive as R

    clock = [0.0]
    monkeypatch.setattr(R.time, "monotonic", lambda: clock[0])
    monkeypatch.setattr(R, "compute_many", lambda requests: clock.__setitem__(0, clock[0] + 1.0))

    class Fake:
        def __init__(self, end):
            from sospoly.budget import Deadline
            self.deadline, self.opts, self.bounds = Deadline(end), None, None

        def set_deadline(self, d):
            self.deadline = d

        def run(self):
            for _ in range(3):
                clock[0] += 0.1
                yield ["subset"]
            clock[0] += 0.1
            return self.deadline.end

    class Opts:
        class budget:
            @staticmethod
            def deadline():
                from sospoly.budget import Deadline
                return Deadline(clock[0] + 10.0)

    two = [Fake(None), Fake(None)]
    for f in two:
        f.opts = Opts
    ends = R.drive(two)
    # each search's deadline when it returns (during its 4th step): 10 s from the start plus the time it was not
    # charged.  Search 0 starts its last step at 3.6 s, charged 3 steps of 0.1 s and 3 halves of 1 s: 1.8 s;
    # search 1 starts it at 3.7 s with the same charge.
    assert ends[0] == pytest.approx(10.0 + 3.6 - 1.8) and ends[1] == pytest.approx(10.0 + 3.7 - 1.8)
    one = Fake(5.0)
    assert R.drive([one]) == [5.0]


def test_batch_shares_no_clock():
    """90 ten-view tracks with two wrong matches (the CVPR 2023 protocol of benchmarks/robust.py; all certified
    with the default limit) in one batch, each allowed 6x the time of one of them solved alone: the batch as a
    whole takes longer than that limit, each problem's share far less -- all certified, none stopped by the
    time limit (the problems of a chunk had shared one clock started with the chunk)."""
    import importlib.util
    import pathlib
    import time

    path = pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "robust.py"
    spec = importlib.util.spec_from_file_location("robust_bench", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    rng = np.random.default_rng(7)
    probs = [bench.scene(10, 2, 1.0, rng)[:2] for _ in range(90)]
    tritools.triangulate(*probs[0], robust=200.0)                     # imports and first compilations
    t = time.perf_counter()
    assert tritools.triangulate(*probs[1], robust=200.0).optimal
    limit = 6 * (time.perf_counter() - t)
    t = time.perf_counter()
    res = tritools.triangulate_many(probs, robust=200.0, time_limit=limit)
    assert time.perf_counter() - t > limit                            # one shared clock would have run out
    assert all(r.status != tritools.Status.TIME_LIMIT for r in res)
    assert all(r.optimal for r in res)


def test_an_uncertified_result_past_its_deadline_says_time_limit(monkeypatch):
    """A leaf whose full-plan solve the deadline skipped (the search loop itself never saw the deadline pass)
    leaves the result uncertified with status time_limit, not not_certified; its bounds still hold.  The
    track: CVPR 2023 protocol, 5 views, one wrong match, whose search needs that solve."""
    import importlib.util
    import pathlib

    from sospoly.budget import Deadline

    import tritools.solve.robust_bounds as rb

    path = pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "robust.py"
    spec = importlib.util.spec_from_file_location("robust_bench", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    rng = np.random.default_rng([2, 5, 1, 10])
    cams, x = [bench.scene(5, 1, 1.0, rng)[:2] for _ in range(11)][10]
    full = tritools.triangulate(cams, x, robust=200.0)
    assert full.optimal
    real = rb.SubsetBounds.strengthen
    calls = []

    def late(self, S, *need):                   # the deadline passes just before the leaf's solve
        calls.append(S)
        self.deadline = Deadline(0.0)
        return real(self, S, *need)

    monkeypatch.setattr(rb.SubsetBounds, "strengthen", late)
    from tritools.solve import robust_cells
    import tritools.solve.robust_enum_run as run_mod
    monkeypatch.setattr(robust_cells, "ENABLED", False)        # the leaf solve of the inlier-set search
    monkeypatch.setattr(run_mod, "SOLVE_LAST_SET", False)       # (not the enumeration's own solve of that set)
    r = tritools.triangulate(cams, x, robust=200.0)
    assert calls and not r.optimal and r.status == tritools.Status.TIME_LIMIT
    assert r.gamma_lb <= full.gamma_ub * (1 + 1e-9) and r.gamma_lb <= r.gamma_ub


def test_per_problem_scalar_thresholds_and_named_errors():
    """Review 8 F6: M scalars for M problems of other view counts are one threshold per problem (each result equal to
    its single call); a list mixing scalars and per-view arrays works; a bad entry is named ``robust[k]`` in a short
    message."""
    from tritools.scene import robust_protocol_scene

    rng = np.random.default_rng(0)
    probs = [robust_protocol_scene(n, 1, 1.0, rng)[:2] for n in (4, 5, 6)]
    cs = [5.0, 10.0, 20.0]
    many = tritools.triangulate_many(probs, robust=cs, progress=False)
    for r, (P, x), c in zip(many, probs, cs):
        single = tritools.triangulate(P, x, robust=c)
        assert r.status == single.status and np.array_equal(r.inliers, single.inliers)
        assert r.gamma_ub == pytest.approx(single.gamma_ub, rel=1e-9)
    arr = tritools.triangulate_many(probs, robust=np.array(cs), progress=False)     # a 1-D array: the same rule
    assert [r.gamma_ub for r in arr] == [r.gamma_ub for r in many]
    mixed = tritools.triangulate_many(probs, robust=[5.0, np.full(5, 10.0), 20.0], progress=False)
    assert [r.status for r in mixed] == [r.status for r in many]
    with pytest.raises(ValueError, match=r"robust\[1\] \(problem 1\)") as exc:
        tritools.triangulate_many(probs, robust=[5.0, np.full(4, 10.0), 20.0], progress=False)
    assert len(str(exc.value)) < 200
    with pytest.raises(ValueError) as exc:
        tritools.triangulate_many(probs, robust=[5.0, np.full(5, -1.0), 20.0], progress=False)
    assert "robust[1]" in str(exc.value) and len(str(exc.value)) < 200


def test_batch_settled_by_its_l2_result_reads_as_the_single_call():
    """Review 8 F8: a region problem whose batched L2 certificate settles the TLS problem (every residual below c,
    f <= min c^2) is reported as the single call reports it: method tls, certified by the branch and bound's root,
    the same message and bounds."""
    rng = np.random.default_rng(3)
    cams = random_scene(4, 1, noise_px=0.5, seed=3).cameras
    X = np.array([0.1, -0.2, 0.05])
    h = np.einsum("nij,j->ni", cams, np.append(X, 1.0))
    x = h[:, :2] / h[:, 2:] + rng.normal(size=(4, 2)) * 0.5
    regions = [tritools.Ellipse(p, np.eye(2) * 0.25) for p in x]
    batch = tritools.triangulate_many([(cams, regions)], robust=5.0, progress=False)[0]
    single = tritools.triangulate(cams, regions, robust=5.0)
    assert single.optimal and batch.optimal
    for name in ("method", "certified_by", "message", "status"):
        assert getattr(batch, name) == getattr(single, name), name
    np.testing.assert_array_equal(batch.inliers, single.inliers)
    assert batch.gamma_ub == pytest.approx(single.gamma_ub, rel=1e-9)
    assert batch.gamma_lb == pytest.approx(single.gamma_lb, rel=1e-9)


def test_stacked_enumeration_results_equal_one_by_one():
    """enumerated_results (the batch's decided problems of one stack, one stacked report) gives each search exactly
    the result enumerated_result gives it alone (the scalar report, TlsSearch.result): status, bounds, X, inliers,
    image points, residuals, depths, message -- over pixel scales 1e-3 / 1 / 1e6, a georeferenced world, per-view
    thresholds, decided and undecided lower bounds."""
    import copy

    from tritools.scene import robust_protocol_scene
    from tritools.solve.robust import TlsSearch
    from tritools.solve.robust_enum_run import enumerated_result, enumerated_results

    rng = np.random.default_rng(5)
    opts = tritools.TriangulationOptions()
    searches, lbs = [], []
    for k in range(18):
        P, x, X, _ = robust_protocol_scene(6, k % 3, 2.0, rng)
        s = [1e-3, 1.0, 1e6][k % 3]
        P, x = np.diag([s, s, 1.0]) @ P, x * s
        if k % 4 == 1:
            shift = rng.uniform(-1, 1, 3) * 1e7
            T = np.eye(4)
            T[:3, 3] = -shift
            P, X = P @ T, X + shift
        c = 200.0 * s * rng.uniform(0.7, 1.4, 6)
        search = TlsSearch(P, None, c, opts, 0.0, points=x)
        search.offer(X)
        searches.append(search)
        lbs.append(search.best_f * [1 - 1e-9, 0.5, 0.0][k % 3])
    n = [3 + k for k in range(len(searches))]
    alone = [enumerated_result(copy.deepcopy(s), lb, m, 57) for s, lb, m in zip(searches, lbs, n)]
    stacked = enumerated_results(searches, lbs, n, 57)
    assert {r.optimal for r in alone} == {True, False}
    for a, b in zip(alone, stacked):
        da, db = a.to_dict(), b.to_dict()
        da.pop("timings"), db.pop("timings")
        for att in da["attempts"] + db["attempts"]:
            att.pop("seconds")
        assert da == db


def test_shared_per_view_thresholds_do_not_lose_the_batch_to_one_bad_problem():
    """Review 18: one array of per-view thresholds for a batch holding a malformed problem (one view, or cameras and
    observations of other counts) raised for the whole call; that problem now gets ``invalid_input`` with its own
    error and the others their results (equal to their single calls).  Invalid thresholds still raise."""
    from tritools.scene import robust_protocol_scene

    P, x, _, _ = robust_protocol_scene(4, 1, 0.5, np.random.default_rng(0))
    c = np.array([5.0, 5.0, np.inf, 5.0])
    single = tritools.triangulate(P, x, robust=c)
    for bad in [(P[:1], x[:1]), (P, x[:3]), (P[:2, :, :3], x[:2])]:
        rs = tritools.triangulate_many([(P, x), bad, (P, x)], robust=c, progress=False)
        assert [r.status.value for r in rs] == [single.status.value, "invalid_input", single.status.value]
        assert "ValueError" in rs[1].message and rs[1].inliers is None
        for r in (rs[0], rs[2]):
            assert r.gamma_ub == single.gamma_ub and np.array_equal(r.inliers, single.inliers)
    with pytest.raises(ValueError, match="positive"):
        tritools.triangulate_many([(P, x), (P[:1], x[:1])], robust=np.array([5.0, -1.0, 5.0, 5.0]), progress=False)
    # review 3: an array that fits only a 1-view problem (no triangulation) fits no problem: raised, not the
    # valid 4-view problem made invalid_input
    with pytest.raises(ValueError, match="one threshold per view"):
        tritools.triangulate_many([(P, x), (P[:1], x[:1])], robust=np.array([5.0]), progress=False)
    bad3 = x[:3].copy()
    bad3[0, 0] = np.nan                        # review 4: an invalid 3-view problem is no fit either
    with pytest.raises(ValueError, match="one threshold per view"):
        tritools.triangulate_many([(P, x), (P[:3], bad3)], robust=np.array([5.0, 5.0, 5.0]), progress=False)


def test_whole_call_limit_rows_past_the_end_are_cheap_and_valid():
    """Review 18: problems whose turn came after ``total_time_limit`` still ran their search (~1 ms each: 200
    problems took a 0.05 s limit to 0.3 s).  Now chunks shrink near the end and the problems not started get the
    DLT point's TLS numbers in one vectorised pass: valid, consistent rows (gamma_UB = gamma_TLS(X) rounded up,
    inliers d_i(X) < c, gamma_LB 0), and the call ends soon after its limit."""
    import time

    from tritools.scene import robust_protocol_scene
    from tritools.solve.call_limit import CUT_MESSAGE

    rng = np.random.default_rng(1)
    probs = [robust_protocol_scene(int(rng.choice([8, 12, 20])), 3, 1.0, rng)[:2] for _ in range(600)]
    tritools.triangulate_many(probs[:2], robust=3.0, progress=False)
    t = time.process_time()            # (this process's CPU: the work done, not the waits of a loaded machine)
    rs = tritools.triangulate_many(probs, robust=3.0, total_time_limit=0.05, progress=False)
    elapsed = time.process_time() - t
    assert elapsed < 0.5                                   # 0.9 s before (600 searches past the end)
    late = [(r, p) for r, p in zip(rs, probs) if r.status == tritools.Status.TIME_LIMIT and "DLT point" in r.message]
    assert len(late) > 400
    for r, (P, x) in late[::37]:
        assert CUT_MESSAGE in r.message and r.method == "tls" and not r.optimal and r.gamma_lb == 0.0
        h = P @ np.append(r.X, 1.0)
        d = np.linalg.norm(h[:, :2] / h[:, 2:] - x, axis=1)
        g = np.sqrt(np.sum(np.minimum(d, 3.0) ** 2) / (2 * len(x)))
        assert g <= r.gamma_ub <= g * (1 + 1e-9)
        assert np.array_equal(r.inliers, d < 3.0)


def test_triangulate_points_keeps_the_points_seen_in_fewer_than_two_views():
    """Review 18: one point seen in a single view made triangulate_points raise for the whole call; it now gets
    ``invalid_input`` naming it, the others their results (equal to the call without it), L2 and robust."""
    sc = random_scene(4, 5, seed=1)
    x = sc.points2d.copy()
    x[1, 1:] = np.nan
    x[3, :] = np.nan
    keep = np.array([True, False, True, False, True])
    for kw in ({}, {"robust": 5.0}):
        cut = tritools.triangulate_points(sc.cameras, x, progress=False, **kw)
        ref = tritools.triangulate_points(sc.cameras, x[keep], progress=False, **kw)
        assert [s.value for s in cut.status] == ["optimal", "invalid_input", "optimal", "invalid_input", "optimal"]
        assert "points2d[1] is visible in fewer than 2 views" in cut.message[1] and "points2d[3]" in cut.message[3]
        np.testing.assert_array_equal(cut.X[keep], ref.X)
        np.testing.assert_array_equal(cut.gamma_ub[keep], ref.gamma_ub)
        assert np.isnan(cut.X[~keep]).all() and not cut.optimal[~keep].any()
        if kw:
            assert not cut.inliers[1].any() and cut.inliers[0].all()
    allbad = np.full_like(x, np.nan)
    allbad[:, 0] = sc.points2d[:, 0]
    for kw in ({}, {"robust": 5.0}):           # every point seen once: every row invalid_input, width V (review 3)
        cut = tritools.triangulate_points(sc.cameras, allbad, progress=False, **kw)
        assert all(s.value == "invalid_input" for s in cut.status) and len(cut) == 5 and cut.width == 4
    for xx in (x, allbad):                     # the robust argument is checked whether or not any point is solved
        with pytest.raises(ValueError, match="robust"):
            tritools.triangulate_points(sc.cameras, xx, progress=False, robust=-1.0)


def test_rows_past_the_end_start_from_a_clean_view_pair():
    """Review 3 of wave 18: past the whole call's end a problem got the DLT point of all views, which every wrong
    match pulls off: 6-view problems of regions with one wrong match had 0/6 inliers at c = 3 px (their optimum
    5/6), and problems of regions paid ~4 ms each through their search.  The rows now take the best (least TLS
    cost) of the DLT points of all views and of view pairs (:func:`tritools.solve.robust_costs.tls_start_stack`):
    every wrong match out, the clean views in, gamma_UB the exact TLS value there, still no lower bound."""
    from tritools.scene import robust_protocol_scene
    from tritools.solve.call_limit import CUT_MESSAGE
    from tritools.solve.robust_costs import tls_start_stack

    rng = np.random.default_rng(2)
    scenes = [robust_protocol_scene(6, 1, 0.5, rng) for _ in range(40)]
    for regions in (False, True):
        probs = [(P, [tritools.Ellipse(x[0], np.eye(2) * 4.0)] + [tritools.Point(p) for p in x[1:]]) if regions
                 else (P, x) for P, x, _, _ in scenes]
        tritools.triangulate_many(probs[:2], robust=3.0, progress=False)
        rs = tritools.triangulate_many(probs, robust=3.0, total_time_limit=1e-4, progress=False)
        late = [(r, s) for r, s in zip(rs, scenes) if CUT_MESSAGE in r.message and "view pairs" in r.message]
        assert len(late) >= 30
        for r, (P, x, _, _) in late:
            assert r.status == tritools.Status.TIME_LIMIT and not r.optimal and r.gamma_lb == 0.0
            h = P @ np.append(r.X, 1.0)
            d = np.linalg.norm(h[:, :2] / h[:, 2:] - x, axis=1)
            if regions:
                d[0] = max(d[0] - 2.0, 0.0)
            np.testing.assert_allclose(r.residuals, d, rtol=1e-7, atol=1e-9)
            g = np.sqrt(np.sum(np.minimum(d, 3.0) ** 2) / 12)
            assert g <= r.gamma_ub <= g * (1 + 1e-9)
            assert np.array_equal(r.inliers, d < 3.0)
        wrong = np.array([s[3] for _, s in late])
        inl = np.array([r.inliers for r, _ in late])
        assert not (inl & wrong).any() and (inl | wrong).all()          # the wrong match out, every clean view in
    # the start itself: c = inf picks the least squared distance; two views have no pairs beside all views
    P, x, _, _ = scenes[0]
    X, ok = tls_start_stack(P[None], x[None], np.full((1, 6), np.inf))
    X2, ok2 = tls_start_stack(P[None, :2], x[None, :2], np.full((1, 2), 3.0))
    from tritools.model.stacked import dlt_stack
    assert ok[0] and ok2[0] and np.array_equal(X2, dlt_stack(P[None, :2], x[None, :2])[0])


@pytest.mark.parametrize("robust", [None, 3.0])
def test_rows_past_the_end_in_a_georeferenced_world(robust):
    """Review 4: rows past the whole call's end took the DLT point in the caller's frame; with the world shifted by
    1e6 it was ~100 off (0/6 inliers, an L2 gamma_UB of ~900 px) where the solved rows are within 1e-3.  The rows'
    DLT now runs in the re-centred frame of the per-point path (:func:`tritools.model.frame.recentred`)."""
    from tritools.scene import robust_protocol_scene
    from tritools.solve.call_limit import CUT_MESSAGE

    rng = np.random.default_rng(1)
    shift = np.array([1e6, -2e6, 5e5])
    kw = {} if robust is None else {"robust": robust}
    probs, truth = [], []
    for _ in range(20):
        P, x, X, _ = robust_protocol_scene(6, 0, 0.5, rng)
        T = np.eye(4)
        T[:3, 3] = -shift
        probs.append((P @ T, x))
        truth.append(X + shift)
    rs = tritools.triangulate_many(probs, total_time_limit=1e-6, progress=False, **kw)
    late = [(r, X) for r, X in zip(rs, truth) if CUT_MESSAGE in r.message and r.X is not None]
    assert len(late) >= 15
    for r, X in late:
        assert np.linalg.norm(r.X - X) < 0.05                    # the noise's scale, not the shift's
        assert r.gamma_ub < 3.0
        if robust is not None:
            assert r.inliers.all()
