"""Issue #22, review item: a robust (TLS) run of region problems whose L2 sub-problems hit the memory budget reports
``budget_exceeded`` (it reported ``not_certified``, losing the reason); with room it certifies, and the bounds
reported under the tight budget stay valid against the certified value."""
import numpy as np
import pytest

import sospoly
import tritools
from tritools.result import Status
from tritools.scene import random_scene


def _problem():
    sc = random_scene(5, 1, seed=3, noise_px=2.0)
    x = sc.points2d[0].copy()
    x[0] += 40.0                                              # one wrong match
    return sc.cameras, [tritools.Segment(p, np.array([3.0, 1.0])) for p in x]


@pytest.mark.slow
@pytest.mark.parametrize("many", [False, True])
def test_robust_regions_at_the_memory_budget_say_so(many):
    P, regions = _problem()
    tight = sospoly.Budget(time_limit=30, max_bytes=1e5)     # every SDP of a sub-problem refused
    if many:
        res = tritools.triangulate_many([(P, regions)], robust=5.0, budget=tight)[0]
    else:
        res = tritools.triangulate(P, regions, robust=5.0, budget=tight)
    ref = tritools.triangulate(P, regions, robust=5.0, budget=sospoly.Budget(time_limit=30, max_bytes=2 * 2 ** 30))
    assert ref.status == Status.OPTIMAL
    assert res.status == Status.BUDGET_EXCEEDED, (res.status, res.message)
    assert not res.optimal and "memory budget" in res.message
    assert res.gamma_lb <= ref.gamma_ub * (1 + 1e-9) and res.gamma_lb <= res.gamma_ub
