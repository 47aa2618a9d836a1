"""The scalar twins of a single robust call's steps (issue #19, single calls at three views), each against the
vectorised rule it mirrors:

* :func:`tritools.model.frame.world_origin_one` vs :func:`tritools.model.frame.world_origins` (bit for bit);
* :func:`tritools.solve.robust_three.three_rest` / ``exact_terms`` vs the masked sums of the stack (bit for bit);
* :func:`tritools.solve.report.projections_and_spread_one` vs ``projections_and_spread_views`` (bit for bit);
* :func:`tritools.solve.robust_enum.refine_row_one` vs :func:`~tritools.solve.robust_enum.refine_rows` (up
  to round-off: the sums in view order instead of BLAS's), and both against scipy's least squares on the set.

Cameras: protocol scenes, rescaled (1e-6..1e8), georeferenced (offsets 1e3..1e9), points near a principal plane,
huge and zero coordinates."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

from tritools.model.frame import world_frame, world_origin_one, world_origins
from tritools.scene import robust_protocol_scene
from tritools.solve import robust_enum as enum
from tritools.solve import robust_three
from tritools.solve.report import projections_and_spread, projections_and_spread_one, projections_and_spread_views
from tritools.solve.robust_bounds import ROUND_DOWN
from tritools.solve.robust_enum import refine_row_one, refine_rows
from tritools.solve.robust_enum_run import lower_bounds


def _cameras(rng, N, kind):
    """Protocol cameras, plain / rescaled / georeferenced / with a duplicated centre / random matrices."""
    P, x, X, _ = robust_protocol_scene(N, 0, 1.0, rng)
    if kind == "scaled":
        P = P * 10.0 ** rng.uniform(-6, 8)
    elif kind == "geo":
        off = rng.normal(size=3) * 10 ** rng.uniform(3, 9)
        P = P.copy()
        P[:, :, 3] -= P[:, :, :3] @ off
        X = X + off
    elif kind == "duplicate":
        P = P.copy()
        P[1] = 3.0 * P[0]
    elif kind == "random":
        P = rng.normal(size=P.shape) * 10.0 ** rng.integers(-5, 5, size=(N, 1, 1)).astype(float)
    return P, x, X


KINDS = ("plain", "scaled", "geo", "duplicate", "random")


@pytest.mark.parametrize("kind", KINDS)
def test_world_origin_one_is_the_stack_bit_for_bit(kind):
    rng = np.random.default_rng(["plain", "scaled", "geo", "duplicate", "random"].index(kind))
    moved = 0
    for _ in range(300):
        N = int(rng.integers(2, 8))
        P, _, _ = _cameras(rng, N, kind)
        ref = world_origins(P[None])[0]
        got = world_origin_one(P)
        assert got.tobytes() == ref.tobytes(), (kind, ref, got)
        assert world_frame(P).origin.tobytes() == ref.tobytes()
        moved += bool(np.any(ref != 0))
    if kind == "geo":
        assert moved > 250                           # the twin's move branch is exercised


def test_world_frame_beyond_the_twin_is_the_stack():
    """From 8 views on, numpy's sum over the views depends on the layout: world_frame keeps the stack there."""
    rng = np.random.default_rng(3)
    for N in (8, 9, 12):
        P, _, _ = _cameras(rng, N, "geo")
        assert world_frame(P).origin.tobytes() == world_origins(P[None])[0].tobytes()


def test_three_rest_and_exact_terms_are_the_masked_sums_bit_for_bit():
    rng = np.random.default_rng(4)
    W = enum.subset_masks(3)
    for k in range(3000):
        N = 3 if k % 2 else int(rng.integers(2, 12))
        c = 10.0 ** rng.uniform(-150, 160, N) if k % 3 == 0 else rng.uniform(0.1, 1000.0, N)
        if k % 7 == 0:
            c[rng.integers(N)] = np.inf
        with np.errstate(over="ignore"):
            c2 = c * c
        ref = float(lower_bounds(np.array([np.inf]), np.full((1, 1), np.inf), c2[None])[0])
        assert robust_three.exact_terms(c2) == ref
        assert robust_three.exact_terms(c2.tolist()) == ref
        if N == 3:
            with np.errstate(over="ignore", invalid="ignore"):
                rest = np.sum(np.where(W, 0.0, c2[None]), axis=1) * ROUND_DOWN
            assert np.array(robust_three.three_rest(c2.tolist())).tobytes() == rest.tobytes()


@pytest.mark.parametrize("kind", KINDS + ("principal_plane", "huge", "zeros"))
def test_projections_and_spread_one_is_the_stack_bit_for_bit(kind):
    rng = np.random.default_rng(len(kind))
    not_finite = 0
    for _ in range(300):
        N = int(rng.integers(2, 8))
        P, _, X = _cameras(rng, N, kind if kind in KINDS else "plain")
        if kind == "principal_plane":              # near camera 0's centre, or on its principal plane exactly
            c = np.linalg.svd(P[0])[2][-1]
            X = c[:3] / c[3] + rng.normal(size=3) * 10.0 ** rng.uniform(-12, 0)
            if rng.random() < 0.3:                 # dyadic X and third row: P_3 . X~ = 0 in exact arithmetic
                X = np.round(X * 2.0 ** 20) / 2.0 ** 20
                P = P.copy()
                P[0, 2, :3] = np.round(P[0, 2, :3] * 2.0 ** 20) / 2.0 ** 20
                P[0, 2, 3] = -(P[0, 2, :3] @ X)
        elif kind == "huge":                       # the compensated products overflow: the plain sums
            X = X * 10.0 ** rng.uniform(-300, 300)
        elif kind == "zeros":
            X = np.where(rng.random(3) < 0.4, 0.0, X * 10.0 ** rng.uniform(-6, 6))
        ref = projections_and_spread_views(P, X)
        got = projections_and_spread_one(P, X)
        assert got[0].tobytes() == ref[0].tobytes() and np.array_equal(got[1], ref[1]), (kind, ref, got)
        assert got[2] == ref[2] or (np.isnan(got[2]) and np.isnan(ref[2]))
        not_finite += not ref[1].all()
        got = projections_and_spread(P, X)        # the dispatch (N <= 7 here: the twin)
        assert got[0].tobytes() == ref[0].tobytes() and np.array_equal(got[1], ref[1])
    if kind == "principal_plane":
        assert not_finite > 0                      # the undefined-projection branch is exercised


def _set_optimum(Cn, views, X0):
    """scipy's least squares of the normalised set (observations at the origin): an independent reference."""
    C = Cn[views]

    def res(X):
        h = C @ np.append(X, 1.0)
        return (h[:, :2] / h[:, 2:]).ravel()
    sol = least_squares(res, X0, xtol=1e-15, ftol=1e-15, gtol=1e-15, method="lm")
    return sol.x, float(np.sum(sol.fun ** 2))


@pytest.mark.parametrize("noise", [0.0, 1.0, 5.0])
def test_refine_row_one_matches_refine_rows_up_to_round_off(noise):
    """On the rows the enumeration refines (the polished candidates of each inlier set), against the stacked LM (a
    stack of two rows): the same success, the same least-squares value to 1e-9 relative (each stops at its own
    round-off), near scipy's optimum of the set (an independent reference), and the same point to the precision a
    minimum allows (X to ~sqrt(u) relative in its flat directions).  A stack of one row is the twin itself."""
    rng = np.random.default_rng(int(noise) + 10)
    n = 0
    for _ in range(40):
        N = int(rng.integers(3, 8))
        P, x, _, _ = robust_protocol_scene(N, int(rng.integers(0, N - 1)), noise, rng)
        frame, Cn = enum.enum_frame(P, x)
        W = enum.subset_masks(N)
        X0 = enum.enum_candidates(Cn, W, 1)
        for r in rng.choice(len(W), min(4, len(W)), replace=False):
            if not np.isfinite(X0[r]).all():
                continue
            views = np.nonzero(W[r])[0].tolist()
            Xa, oka = refine_rows(Cn[None].repeat(2, 0), X0[[r, r]], W[[r, r]])     # (a stack of two: the LM stack)
            Xb, okb = refine_row_one(Cn, X0[r], views)
            assert okb == bool(oka[0])
            one = refine_rows(Cn[None], X0[r][None], W[r][None])               # a stack of one: the twin
            assert one[0][0].tobytes() == Xb.tobytes() and bool(one[1][0]) == okb
            if not okb:
                continue
            n += 1
            fa, fb = _cost(Cn, views, Xa[0]), _cost(Cn, views, Xb)
            assert abs(fa - fb) <= 1e-9 * max(fa, fb) + 1e-28, (fa, fb)
            _, fs = _set_optimum(Cn, views, Xb)
            assert fb <= fs * (1 + 1e-4) + 1e-28, (fb, fs)      # (the stack too stops short by ~3e-6 at times)
            assert np.max(np.abs(Xa[0] - Xb)) <= 1e-5 * (1 + np.max(np.abs(Xb)))
    assert n > 100


def _cost(Cn, views, X) -> float:
    h = Cn[views] @ np.append(X, 1.0)
    return float(np.sum((h[:, :2] / h[:, 2:]) ** 2))
