"""The leave-one-out bound with sub-bounds from two halves (:mod:`tritools.solve.robust_loo`): the split sub-bounds
against an independent multi-start L2 minimum of every W - k, the whole bound against the enumerated TLS optimum
on clean tracks whose L2 cost exceeds min c^2 (the root bound cannot certify them), and the search with it against
the search without it."""

import numpy as np
import pytest

import tritools
import tritools.solve.robust_suspects as rs
from tritools.scene import random_scene
from tritools.solve.robust import TlsSearch
from tests.robust_refs import assert_lb_below, assert_same_tls, drive_one, l2_min, primed_search, tls_by_subsets
from tritools.solve.robust_loo import _split, halves, leave_one_out


@pytest.mark.parametrize("seed,N", [(0, 6), (1, 7), (2, 8)])
def test_split_sub_bounds_below_every_leave_one_out_minimum(seed, N):
    """L2LB(A - k) + L2LB(B) (k in A) and L2LB(A) + L2LB(B - k) (k in B) never exceed the multi-start L2 minimum of
    W - k, and lose little against it on a clean track (the split frees about three degrees of freedom)."""
    sc = random_scene(N, 1, noise_px=1.0, seed=seed)
    cams, x, X = sc.cameras, sc.points2d[0], sc.points3d[0]
    s = TlsSearch(cams, None, np.full(N, 3.0), tritools.TriangulationOptions(), 0.0, points=x)
    W = frozenset(range(N))
    A, B = halves(W)
    assert A | B == W and not A & B
    drive_one(s.verify_first(A, B, *[A - {k} for k in A], *[B - {k} for k in B]), s.bounds)
    for k in range(N):
        split = _split(s.bounds, A - {k}, B) if k in A else _split(s.bounds, A, B - {k})
        rest = [i for i in range(N) if i != k]
        ref = l2_min(cams[rest], x[rest], [X, X + 0.2])
        assert split <= ref * (1 + 1e-9) + 1e-9
        assert split >= ref - 12.0                       # six fitted coordinates instead of three, 1 px noise


@pytest.mark.parametrize("seed,N,cval", [(3, 6, 2.0), (4, 7, 2.5), (5, 7, 3.0)])
def test_clean_track_bound_below_the_enumeration(seed, N, cval, monkeypatch):
    """Clean tracks whose L2 cost is above min c^2: the halves' leave-one-out bound <= the enumerated optimum; the
    search certifies them with or without the stage, with the same inliers and value."""
    sc = random_scene(N, 1, noise_px=1.0, seed=seed)
    cams, x, X = sc.cameras, sc.points2d[0], sc.points3d[0]
    c = np.full(N, cval)
    f_ref = tls_by_subsets(cams, x, c, [X, X + 0.3, X - 0.3])
    s, full = primed_search(cams, x, c, X)
    lb = drive_one(leave_one_out(s, full, 0.0), s.bounds)
    assert lb <= f_ref * (1 + 1e-9) + 1e-9
    fast = tritools.triangulate(cams, x, robust=c)
    monkeypatch.setattr(rs, "ENABLED", False)
    plain = tritools.triangulate(cams, x, robust=c)
    assert fast.optimal and " 0 nodes" in fast.message
    assert_same_tls(fast, plain)
    assert_lb_below((fast, plain), N, f_ref)
