"""A point of a batch gets its time limit once: the per-point path after the batch stages gets what is left of it,
and the batched SDP stops at the stack's deadline (review 27a: a 50-view track of random keypoints took 11.2 s
under a 5 s limit -- 9.7 s in the batched SDP, whose IPM had no deadline, then a fresh 5 s for the per-point path;
66.9 s under the default 60 s)."""
import sys
import time

import numpy as np
import pytest

import tritools


def _garbage_track(N: int, seed: int = 1):
    """N cameras on a circle looking at the origin, one random keypoint each (no consistent point)."""
    rng = np.random.default_rng(seed)
    K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    cams = []
    for v in range(1, N + 1):
        a = 2 * np.pi * v / N
        c = np.array([10 * np.cos(a), 0, 10 * np.sin(a)])
        z = -c / 10
        x = np.cross([0, 1.0, 0], z)
        x /= np.linalg.norm(x)
        R = np.vstack([x, np.cross(z, x), z])
        cams.append(K @ np.hstack([R, (-R @ c)[:, None]]))
    return np.array(cams), rng.uniform([0, 0], [640, 480], (N, 2))


def test_a_batch_point_keeps_its_time_limit():
    C, x = _garbage_track(40)
    limit = 1.5
    t0 = time.perf_counter()
    res = tritools.triangulate_points(C, x[None], time_limit=limit, layout="points_views")
    wall = time.perf_counter() - t0
    assert res.status[0] == "time_limit", (res.status[0], res.message[0])
    assert wall <= 1.5 * limit + 0.5, wall


def test_the_batched_sdp_stops_at_its_deadline():
    from sospoly.budget import Deadline
    from tritools.solve.sdp_batch import solve_corollary1_points

    C, x = _garbage_track(40)
    solve_corollary1_points(C[None], x[None], deadline=Deadline.after(60.0))       # (compiles the structure)
    t0 = time.perf_counter()
    b = solve_corollary1_points(C[None], x[None], deadline=Deadline.after(0.3))
    assert time.perf_counter() - t0 <= 0.3 * 1.5 + 0.3
    assert not b.done[0] and "time" in b.reason[0]


def test_a_stack_under_a_whole_call_limit_is_solved_in_slices(monkeypatch):
    """Review 33a M1: 40,000 tracks of 20 views went through the batch stages as one stack, whose vectorised steps
    no deadline interrupts: a 3 s ``--total-time-limit`` ran to 18-21 s.  Under a whole-call limit the stack is
    solved in slices sized from the measured pace, each begun only where it fits before the end; every row stays."""
    import tritools.solve.batch as batch
    from tritools.scene import random_scene
    from tritools.solve.options import TriangulationOptions

    sizes = []
    real = batch.PointStack

    def spy(C, x, *a, **k):
        sizes.append(len(x))
        return real(C, x, *a, **k)

    monkeypatch.setattr(batch, "PointStack", spy)
    sc = random_scene(6, 40, noise_px=1.0, seed=7)
    M = 2000
    C = np.broadcast_to(np.asarray(sc.cameras), (M, 6, 3, 4)).copy()
    x = np.tile(np.asarray(sc.points2d), (M // 40, 1, 1))
    rec = batch.solve_point_stack(C, x, TriangulationOptions(total_time_limit=5.0)).record()
    assert len(rec) == M and sum(sizes) <= M
    assert len(sizes) > 1 and max(sizes) < M                    # before: one stack of all 2000 rows
    status = np.array([s.value if hasattr(s, "value") else s for s in rec.status])
    assert set(status) <= {"optimal", "time_limit"} and (status == "optimal").sum() >= sizes[0]
    assert np.isfinite(rec.gamma_ub).all()                         # every row with its estimate
    sizes.clear()
    rec = batch.solve_point_stack(C, x, TriangulationOptions()).record()
    assert sizes == [M] and len(rec) == M                          # no whole-call limit: one stack, as before


def test_slices_keep_solving_when_the_reserve_model_exceeds_the_limit(monkeypatch):
    """Review 33c M1: the reserve for the rows of last resort (a model, 3x their measured cost) exceeded a 3 s limit on
    20,000 six-view rows, and no slice began (0 certified, where one stack certified all in 2.5 s).  The reserve is
    capped as ``reserved_end`` caps it, and never above the measured pace of solving a row."""
    import tritools.solve.batch as batch
    from tritools.scene import random_scene
    from tritools.solve.options import TriangulationOptions

    model = batch.reserve_for
    monkeypatch.setattr(batch, "reserve_for", lambda views: 10.0 * model(views))     # the model 30x the cost
    sc = random_scene(6, 40, noise_px=1.0, seed=11)
    M = 2000
    C = np.broadcast_to(np.asarray(sc.cameras), (M, 6, 3, 4)).copy()
    x = np.tile(np.asarray(sc.points2d), (M // 40, 1, 1))
    assert batch.reserve_for((6,)) * M > 3.0
    rec = batch.solve_point_stack(C, x, TriangulationOptions(total_time_limit=3.0)).record()
    status = np.array([s.value if hasattr(s, "value") else s for s in rec.status])
    assert len(rec) == M and (status == "optimal").sum() > M // 2


@pytest.mark.parametrize("limit", [1e308, sys.float_info.max])
def test_a_huge_finite_whole_call_limit_is_no_limit(limit):
    """Review 33c (HIGH): a limit from ~3e306 s up overflowed the slice size (OverflowError: cannot convert float
    infinity to integer) in every point batch; it is no limit."""
    from tritools.scene import random_scene

    sc = random_scene(4, 30, noise_px=1.0, seed=5)
    free = tritools.triangulate_points(np.asarray(sc.cameras), np.asarray(sc.points2d))
    got = tritools.triangulate_points(np.asarray(sc.cameras), np.asarray(sc.points2d), total_time_limit=limit)
    assert np.array_equal(got.gamma_ub, free.gamma_ub) and np.array_equal(got.optimal, free.optimal)


def test_an_empty_stack_under_a_whole_call_limit_has_no_rows():
    """Review of this wave's slices: an empty stack under a limit raised in the sample of rows of last resort."""
    from tritools.scene import random_scene
    from tritools.solve.batch import solve_point_stack
    from tritools.solve.options import TriangulationOptions

    sc = random_scene(3, 2, seed=1)
    rec = solve_point_stack(np.zeros((0, 3, 3, 4)), np.zeros((0, 3, 2)), TriangulationOptions(total_time_limit=2.0))
    assert len(rec.record()) == 0
    got = tritools.triangulate_points(np.asarray(sc.cameras), np.zeros((0, 3, 2)), total_time_limit=2.0)
    assert len(got.status) == 0
