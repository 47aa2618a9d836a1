"""Batched robust (TLS) problems: the point problems' cameras are checked in one vectorised call per view count
(:func:`tritools.solve.robust_batch._point_searches`); a bad camera still gets the per-problem named error and
never stops the batch, and the good problems equal their single-point results."""
import numpy as np

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
    assert many[2].status == tritools.Status.INVALID_INPUT and "equal" in many[2].message
    for k in (0, 3):
        single = tritools.triangulate(*probs[k], robust=5.0)
        assert many[k].status == single.status and many[k].optimal
        np.testing.assert_array_equal(many[k].inliers, single.inliers)
        assert many[k].gamma_ub == single.gamma_ub and many[k].gamma_lb == single.gamma_lb


def test_batch_time_limits_are_per_problem():
    """drive() charges each search its own steps and an even share of a round's batched calls: the rest of the
    round moves its deadline on (one search: nothing moves)."""
    from sospoly.budget import Deadline

    from tritools.solve.robust import _credit

    class Fake:
        def __init__(self, end):
            self.deadline = Deadline(end)

        def set_deadline(self, d):
            self.deadline = d

    s = [Fake(100.0), Fake(100.0), Fake(None), Fake(50.0)]
    _credit(s, {0: 1.0, 1: 3.0, 2: 0.5, 3: 0.5}, 2.0)          # round: 2 s batched + 5 s of steps
    assert s[0].deadline.end == 100.0 + 7.0 - 1.0 - 0.5
    assert s[1].deadline.end == 100.0 + 7.0 - 3.0 - 0.5
    assert s[2].deadline.end is None and s[3].deadline.end == 50.0 + 7.0 - 0.5 - 0.5
    one = [Fake(10.0)]
    _credit(one, {0: 4.0}, 3.0)
    assert one[0].deadline.end == 10.0
