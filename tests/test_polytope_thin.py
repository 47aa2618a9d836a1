"""Issue 24, defect 6: ``Polytope.distance`` is exact for boxes of any aspect ratio (a 2 x 1e10 box
was thinned to one of its long edges: distance 7.0 instead of 3.0), and fast for 1000 rows.

Reference: the closed form of the distance to an axis-aligned box, ``|max(|u| - w, 0)|``."""
from __future__ import annotations

import time

import numpy as np
import pytest

from tritools import gamma
from tritools.model.geometry import image_points
from tritools.model.regions import Polytope
from tritools.scene import paper_example


def _box_distance(q, center, half):
    return float(np.hypot(*np.maximum(np.abs(np.asarray(q, float) - center) - half, 0.0)))


@pytest.mark.parametrize("aspect", [5e9, 1e10, 1e11, 1e12])
@pytest.mark.parametrize("long_axis", [0, 1])
def test_distance_to_thin_boxes_matches_the_closed_form(aspect, long_axis):
    half = np.ones(2)
    half[long_axis] = aspect
    for center in (np.zeros(2), np.array([0.5, -0.25]) * half):
        R = Polytope.box(center, half)
        queries = center + np.array([[4.0, 0.0], [0.0, 4.0], [-4.0, 0.0], [0.0, -4.0], [0.3, 2.5], [2.5, 0.3]])
        for q in queries:
            d = R.distance(q)
            assert d == pytest.approx(_box_distance(q, center, half), rel=1e-12, abs=1e-9), (q, R.vertices)


def test_distance_to_a_rotated_thin_box():
    rng = np.random.default_rng(5)
    for _ in range(200):
        th = rng.uniform(0, np.pi)
        Rot = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
        half = np.array([10 ** rng.uniform(9.7, 12), 1.0])
        center = rng.normal(size=2) * 10
        B = np.diag(1 / half) @ Rot.T
        R = Polytope(B, -B @ center)
        u = rng.normal(size=2) * np.array([half[0], 3.0])
        d = R.distance(center + Rot @ u)
        exact = float(np.hypot(*np.maximum(np.abs(u) - half, 0.0)))
        assert abs(d - exact) <= 1e-6 * max(1.0, exact) + 1e-12 * half[0], (th, half, u, d, exact)


def test_thin_boxes_keep_gamma_exact():
    """gamma (the cost every estimate and gamma_UB is scored by) of a point whose projections lie in
    thin boxes is 0; a point 3 pixels across the box is at sqrt(3**2 / (2 N))."""
    cams, _ = paper_example(4)
    X = np.array([0.2, -0.1, 5.0])
    x = image_points(X, cams)
    regions = [Polytope.box(p, [1e10, 1.0]) for p in x]
    assert gamma(X, cams, regions) == 0.0
    for side in (4.0, -4.0):
        shifted = [Polytope.box(p + [0.0, side], [1e10, 1.0]) for p in x]
        assert gamma(X, cams, shifted) == pytest.approx(np.sqrt(9.0 / 2), rel=1e-9)    # 3 px in every view


def test_many_rows_are_fast():
    rng = np.random.default_rng(2)
    th = np.sort(rng.uniform(0, np.pi, 1000))
    B = np.column_stack([np.cos(th), np.sin(th)]) * rng.uniform(0.5, 2.0, (1000, 1))
    t0 = time.perf_counter()
    R = Polytope(B, rng.uniform(-0.5, 0.5, 1000))
    Q = rng.normal(size=(2000, 2)) * 5
    d = R.distance(Q)
    assert time.perf_counter() - t0 < 5.0
    inside = R.contains(Q)
    assert np.all(d[inside] == 0) and np.all(d[~inside] > 0)
    # every point's distance is at least its largest half-plane violation (a lower bound) and at most
    # the distance to the nearest vertex (an upper bound)
    nrm = np.hypot(B[:, 0], B[:, 1])
    viol = np.max((np.abs(Q @ B.T + R.c) - 1.0) / nrm, axis=1)
    assert np.all(d >= np.maximum(viol, 0) - 1e-12)
    near = np.min(np.hypot(*(Q[:, None, :] - R.vertices[None]).transpose(2, 0, 1)), axis=1)
    assert np.all(d <= near + 1e-12)
