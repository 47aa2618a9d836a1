"""The robust (TLS) search stops when certification is out of its reach (:mod:`tritools.solve.robust_futile`,
review 6, finding F6: a 7-view mixed-region problem ran to the 60 s limit re-solving L2 sub-problems that had
already failed, where the plain L2 call gives up in a few seconds).

The rule on its own (a leaf whose bound is exhausted and does not meet UB stops the search; not past the deadline,
not when switched off, not when the bound meets), the reviewer's problem end to end (not_certified, valid bounds,
the plain call's cost, an honest message; the batch the same), and certifiable region problems with and without
the rule (the same status and value: the rule never turns a certificate into not_certified)."""
import json
import math
import pathlib
import time
from types import SimpleNamespace

import numpy as np
import pytest

import tritools
import tritools.solve.robust_futile as rf
from tritools.solve.robust import tls_cost
from tests.robust_refs import assert_same_tls, outlier_track

DATA = pathlib.Path(__file__).parent / "data" / "robust_regions_futile.json"


class _Deadline:
    def __init__(self, expired=False):
        self.expired = expired


def _stub(best_f, exhausted, expired=False):
    """A search stand-in: 4 views, c^2 = 1 each, the leaf {0, 1, 2} (outlier 3) with the cached bound 0.5."""
    S = frozenset((0, 1, 2))
    bounds = SimpleNamespace(exhausted={S} if exhausted else set(), known=lambda T: True,
                             bound=lambda T: 0.5 if T == S else 0.0, inherited=lambda T: 0.5 if T == S else 0.0)
    tol = tritools.TriangulationOptions().tolerances
    s = SimpleNamespace(N=4, c2=np.ones(4), bounds=bounds, deadline=_Deadline(expired), best_f=best_f,
                        futile_leaf=None)
    s.meets = lambda lb: lb >= s.best_f or bool(tol.certified(lb, s.best_f, 1.0))
    return s, S


def test_rule_fires_only_on_an_exhausted_leaf_below_the_best_value(monkeypatch):
    s, S = _stub(best_f=2.0, exhausted=True)
    lb = rf.leaf_bound(s, S)
    assert lb == pytest.approx(1.5) and lb <= 1.5                 # c^2(outlier 3) + L2LB(S), rounded down
    assert rf.leaf_futile(s, S, lb) and s.futile_leaf == (S, lb)
    assert "certification out of reach" in rf.futile_message(s) and "3 views" in rf.futile_message(s)
    s, S = _stub(best_f=2.0, exhausted=False)                      # a light bound: the search may still raise it
    assert not rf.leaf_futile(s, S, 1.5)
    s, S = _stub(best_f=1.5, exhausted=True)                       # the bound meets the best value: no reason
    assert not rf.leaf_futile(s, S, 1.5)
    s, S = _stub(best_f=2.0, exhausted=True, expired=True)         # past the deadline the time limit says why
    assert not rf.leaf_futile(s, S, 1.5)
    monkeypatch.setattr(rf, "ENABLED", False)
    s, S = _stub(best_f=2.0, exhausted=True)
    assert not rf.leaf_futile(s, S, 1.5)


def _futile_problem():
    d = json.loads(DATA.read_text())
    c = np.array([math.inf if v == "inf" else float(v) for v in d["robust"]])
    return np.array(d["cameras"]), d["regions"], c


@pytest.mark.slow
def test_region_problem_stops_at_about_the_plain_cost():
    """The reviewer's problem at max_delta = 2: plain L2 gives up (not_certified); robust=c stops with
    not_certified too, the message says why, the bounds are valid (gamma_lb <= gamma_ub = gamma_TLS(X), f_lb below
    f_TLS at the plain L2 estimate, an attained value) and the CPU time is about the plain call's (was: the 60 s
    limit).  (Its delta = 4 program, once a numerical failure, certifies since the normalisation bounds the image
    scale by the ellipse borders' offset: tests/test_border_scale.py.)"""
    cams, regions, c = _futile_problem()
    t = time.process_time()
    plain = tritools.triangulate(cams, regions, max_delta=2)
    t_plain = time.process_time() - t
    t = time.process_time()
    res = tritools.triangulate(cams, regions, robust=c, max_delta=2)
    t_robust = time.process_time() - t
    assert plain.status == tritools.Status.NOT_CERTIFIED
    assert res.status == tritools.Status.NOT_CERTIFIED and not res.optimal
    assert "certification out of reach" in res.message and "7 views" in res.message
    assert t_robust < 2.0 * t_plain + 2.0, (t_robust, t_plain)
    N = len(regions)
    f_lb, f_ub = 2 * N * res.gamma_lb ** 2, 2 * N * res.gamma_ub ** 2
    assert f_lb <= f_ub
    assert f_ub == pytest.approx(tls_cost(res.residuals, c), rel=1e-9)
    assert f_lb <= tls_cost(plain.residuals, c) * (1 + 1e-9)
    np.testing.assert_array_equal(res.inliers, res.residuals < c)
    many = tritools.triangulate_many([(cams, regions)], robust=[c], max_delta=2)
    assert many[0].status == tritools.Status.NOT_CERTIFIED and "certification out of reach" in many[0].message


@pytest.mark.parametrize("N,seed,kinds", [(3, 0, "se"), (4, 1, "es"), (4, 2, "bp")])
def test_certifiable_region_problems_unchanged_by_the_rule(N, seed, kinds, monkeypatch):
    """Segments, ellipses, ellipse borders and points with a wrong match: with the rule and without it, the same
    status, inlier set and value (the rule only ends searches that cannot certify)."""
    cams, x, X, out = outlier_track(N, 1, seed, shift=(80.0, 300.0))
    rng = np.random.default_rng(seed)
    make = {"s": lambda p: tritools.Segment(p, rng.normal(size=2) * 2.0),
            "e": lambda p: tritools.Ellipse(p, np.diag([4.0, 1.0])),
            "b": lambda p: tritools.EllipseBorder(p, np.diag([2.0, 1.0])),
            "p": lambda p: tritools.Point(p)}
    regions = [make[kinds[i % len(kinds)]](p) for i, p in enumerate(x)]
    c = np.full(N, 20.0)
    on = tritools.triangulate(cams, regions, robust=c)
    monkeypatch.setattr(rf, "ENABLED", False)
    off = tritools.triangulate(cams, regions, robust=c)
    assert_same_tls(on, off)
    if off.optimal:
        assert on.optimal


def test_leaf_bound_takes_the_subsets_bounds():
    """leaf_bound(I) = c^2(V - I) + the largest cached bound of I and of its subsets (rounded down): a subset's
    bound holds for I (monotonicity)."""
    cams, x, X, out = outlier_track(6, 1, 3)
    from tritools.solve.robust import TlsSearch
    from tests.robust_refs import drive_one

    s = TlsSearch(cams, None, np.full(6, 4.0), tritools.TriangulationOptions(), 0.0, points=x)
    I = frozenset(range(5))
    T = frozenset((0, 1, 2))
    drive_one(s.need([T]), s.bounds)
    s.bounds._store(I, 0.0, None)                      # a weak bound of I itself
    assert rf.leaf_bound(s, I) == pytest.approx(16.0 + s.bounds.bound(T), rel=1e-9)
    assert rf.leaf_bound(s, I) <= 16.0 + s.bounds.bound(T)
    assert s.bounds.bound(T) > 0
