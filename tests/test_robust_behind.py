"""A certified TLS optimum behind a camera says so in its message, as the L2 result does (review 33a L9): which
inlier views see it behind them, on single calls and in batches, with and without ``require_in_front``."""
from __future__ import annotations

import numpy as np
import pytest

import tritools
from tritools import Status


def _behind_problem(wrong: bool, z: float = -5.0):
    P = np.array([np.hstack([np.eye(3), t[:, None]]) for t in
                  (np.zeros(3), np.array([1.0, 0, 0]), np.array([0.0, 1, 0]), np.array([1.0, 1, 0]))])
    h = P @ np.array([0.2, 0.1, z, 1.0])
    x = h[:, :2] / h[:, 2:]
    if wrong:
        x[3] += [0.3, -0.2]                      # a wrong match: view 3 an outlier at c = 0.01
    return P, x


@pytest.mark.parametrize("wrong", [False, True])
@pytest.mark.parametrize("require", [False, True])
def test_tls_messages_name_the_inlier_views_behind(wrong, require):
    P, x = _behind_problem(wrong)
    opts = tritools.TriangulationOptions(require_in_front=require)
    single = tritools.triangulate(P, x, robust=0.01, options=opts)
    many = tritools.triangulate_many([(P, x)] * 2, robust=0.01, options=opts)
    expect = "certified TLS optimum, but behind camera(s) 0, 1, 2" + ("" if wrong else ", 3")
    for r in (single, *many):
        assert r.optimal and r.in_front is False
        assert r.status == (Status.BEHIND_CAMERA if require else Status.OPTIMAL)
        assert list(r.inliers) == [True, True, True, not wrong]
        assert expect in r.message, r.message
        if wrong:
            assert "behind camera(s) 0, 1, 2;" in r.message or r.message.endswith("0, 1, 2")


def test_no_behind_note_in_front():
    P, x = _behind_problem(True, z=5.0)
    r = tritools.triangulate(P, x, robust=0.01)
    assert r.optimal and r.in_front and "behind" not in r.message
