"""Time limits on long robust tracks (review 8 F1): the bounds that are not interruptible inside -- the all-pairs
Lagrangian bound (N(N-1)/2 multipliers, ~n^2 K flops) and the batched dense Corollary 1 SDP (its structure grows
~N^4) -- are only started where they fit in what is left of the deadline, or not at all above
``robust_bounds.SDP_STACK_MAX_VIEWS`` views."""
import time

import numpy as np

import tritools
import tritools.solve.robust_bounds as rb
from sospoly.budget import Deadline
from tritools.scene import random_cameras
from tritools.solve.fastpath import all_pairs_seconds, fits


def _long_track(N=200, wrong=60, seed=4):
    rng = np.random.default_rng(seed)
    Ps = random_cameras(N, rng)
    X = rng.normal(size=3)
    h = np.einsum("nij,j->ni", Ps, np.append(X, 1.0))
    xs = h[:, :2] / h[:, 2:] + rng.normal(size=(N, 2))
    xs[rng.choice(N, wrong, replace=False)] += rng.uniform(-300, 300, (wrong, 2))
    return Ps, xs


def test_all_pairs_estimate_and_fit():
    assert all_pairs_seconds(200) > 1.0 > all_pairs_seconds(20)
    assert all_pairs_seconds(50, 4) == 4 * all_pairs_seconds(50)
    assert fits(None, 200)
    assert not fits(Deadline.after(0.2), 200) and fits(Deadline.after(60.0), 200)
    assert fits(Deadline(None), 200) and not fits(Deadline.after(0.0), 10)


def test_robust_time_limit_on_a_200_view_track_with_wrong_matches(monkeypatch):
    """c = 2 px on 200 views, 30% wrong matches: the call stops with status time_limit within the limit plus a
    small step (CPU seconds: the machine's load does not move them), with valid bounds; before, one all-pairs bound
    (1.5 s) and a batched SDP over a 140-view subset (tens of seconds) ran past a 1-2 s limit."""
    Ps, xs = _long_track()
    sizes = []
    real = rb._sdp_stack
    monkeypatch.setattr(rb, "_sdp_stack", lambda C, x, o, d=None: sizes.append(C.shape[1]) or real(C, x, o, d))
    tritools.triangulate(Ps[:12], xs[:12], robust=2.0, time_limit=5.0)     # first-call costs (imports, caches)
    limit = 1.0
    c0 = time.process_time()
    r = tritools.triangulate(Ps, xs, robust=2.0, time_limit=limit)
    cpu = time.process_time() - c0
    assert r.status == tritools.Status.TIME_LIMIT, (r.status, r.message)
    assert cpu <= 1.1 * limit + 1.5, cpu        # 1.2 s alone, 2.1 s in a loaded full run; 20+ s with a 140-view SDP
    assert 0.0 <= r.gamma_lb <= r.gamma_ub
    assert all(n <= rb.SDP_STACK_MAX_VIEWS for n in sizes), sizes
