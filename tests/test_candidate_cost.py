"""The estimate stage's candidate evaluation (:class:`tritools.solve.stages.estimate.CandidateCost`): the same
numbers as the plain evaluation it replaced (validated :func:`point_from_image_points` + :func:`gamma_validated`
per candidate), its vectorised twin equal to its scalar path, and the family search the same with and without
the vectorised scan -- so results stay bit-identical (the triangulations compared at the end)."""
from __future__ import annotations

import types

import numpy as np
import pytest

import tritools
from sospoly.analysis.extraction import CandidateFamily, best_in_family, lowered_exponents, monomial_jacobian
from tritools.model.geometry import gamma_validated, point_from_image_points, points_from_validated, \
    point_from_validated, image_points
from tritools.model.regions import Ellipse, Point
from tritools.scene import random_scene
from tritools.solve.stages import estimate
from tritools.solve.stages.estimate import CandidateCost


def _plain_value(v, cams, regs):
    """The evaluation before CandidateCost (validated cameras on every call, disc shapes found on every call)."""
    x = np.asarray(v, float).reshape(-1, 2)
    X = point_from_image_points(x, cams, centre=None)
    if X is None:
        return np.inf
    g = gamma_validated(np.asarray(X, float)[None], cams, regs)[0]
    return float(g) if np.isfinite(g) else np.inf


def _problem():
    return types.SimpleNamespace(image_points=lambda v: np.asarray(v, float).reshape(-1, 2))


def _candidates(x, rng, m=60, spread=30.0):
    V = x.ravel()[None] + spread * rng.standard_normal((m, x.size))
    V[3] = np.nan                       # a non-finite candidate: +inf
    V[4] = 1e300                        # an overflowing M0: +inf
    return V


@pytest.mark.parametrize("n_views,seed", [(2, 0), (3, 1), (5, 2)])
@pytest.mark.parametrize("kind", ["point", "ellipse"])
def test_candidate_cost_equals_the_plain_evaluation(n_views, seed, kind):
    sc = random_scene(n_views, 1, noise_px=3.0, seed=seed)
    x = sc.points2d[0]
    regs = [Point(p) for p in x] if kind == "point" else \
        [Ellipse(p, np.diag([1 / 9.0, 1 / 4.0])) for p in x]
    cost = CandidateCost(_problem(), sc.cameras, regs)
    V = _candidates(x, np.random.default_rng(seed))
    plain = []
    for v in V:
        try:
            plain.append(_plain_value(v, sc.cameras, regs))
        except (ValueError, np.linalg.LinAlgError):
            plain.append(np.inf)
    scalar = []
    for v in V:
        try:
            scalar.append(cost.value(v))
        except (ValueError, np.linalg.LinAlgError):
            scalar.append(np.inf)
    many = cost.many(V)
    assert np.isfinite(plain).sum() >= len(V) - 2
    assert np.array_equal(np.array(plain), np.array(scalar))        # bit for bit
    assert np.array_equal(np.array(plain), many)


def test_points_from_validated_equals_the_scalar_path_with_a_common_centre():
    rng = np.random.default_rng(3)
    K = np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]])
    Rs = [np.linalg.qr(rng.standard_normal((3, 3)))[0] for _ in range(3)]
    cams = np.stack([K @ R @ np.hstack([np.eye(3), -np.array([[1.0], [2.0], [3.0]])]) for R in Rs])
    x = image_points(np.array([0.3, -0.2, 9.0]), cams)
    xs = x[None] + rng.standard_normal((20, 3, 2))
    got = points_from_validated(xs, cams)
    for k in range(len(xs)):
        ref = point_from_validated(xs[k], cams)
        assert ref is not None and np.array_equal(got[k], ref)


def test_family_search_same_with_the_vectorised_scan():
    sc = random_scene(3, 1, noise_px=5.0, seed=4)
    x = sc.points2d[0]
    regs = [Point(p) for p in x]
    cost = CandidateCost(_problem(), sc.cameras, regs)
    rng = np.random.default_rng(5)
    b1 = np.concatenate([[1.0], x.ravel() + 20 * rng.standard_normal(x.size)])
    b2 = np.concatenate([[0.5], 0.5 * x.ravel() + 30 * rng.standard_normal(x.size)])
    W = np.stack([b1, b2], axis=1)
    c0 = W[0]
    Z = np.linalg.svd(c0[None])[2][1:].T
    fam = CandidateFamily(W, np.arange(1, x.size + 1), c0 / (c0 @ c0), Z)
    assert fam.dim == 1
    v1, f1 = best_in_family(fam, cost.value, max_evals=300)
    v2, f2 = best_in_family(fam, cost.value, max_evals=300, objective_many=cost.many)
    assert np.isfinite(f1) and f1 == f2 and np.array_equal(v1, v2)


def _l2_problems():
    """L2 problems with one wrong match (the robust search's sub-problems: verification fails, the SDP steps
    run; the first three search a one-parameter Gram kernel family, the last ends with Theorem 1)."""
    out = []
    for seed, n, off in [(12, 3, 400.0), (16, 3, 200.0), (14, 4, 300.0), (14, 3, 400.0)]:
        sc = random_scene(n, 1, noise_px=5.0, seed=seed)
        x = sc.points2d[0].copy()
        x[0] += np.array([off, -0.7 * off])
        out.append((sc.cameras, x))
    return out


class _PlainCost(CandidateCost):
    """The evaluation before CandidateCost, as a drop-in (no vectorised scan)."""

    def one(self, v):
        xn = self.problem.image_points(v)
        Xn = point_from_image_points(xn, self.cams, centre=self.centre)
        if Xn is None:
            return None
        g = gamma_validated(np.asarray(Xn, float)[None], self.cams, self.regs)[0]
        return (float(g), np.asarray(Xn, float), xn) if np.isfinite(g) else None

    def many(self, V):
        raise ValueError("no vectorised scan")      # best_in_family falls back to its loop


@pytest.mark.parametrize("k", range(4))
def test_triangulations_bit_identical_to_the_plain_evaluation(monkeypatch, k):
    cams, x = _l2_problems()[k]
    dims = []
    search = estimate.best_in_family
    monkeypatch.setattr(estimate, "best_in_family", lambda fam, *a, **kw: dims.append(fam.dim) or search(fam, *a, **kw))
    new = tritools.triangulate(cams, x)
    monkeypatch.setattr(estimate, "CandidateCost", _PlainCost)
    old = tritools.triangulate(cams, x)
    assert new.attempts[0].status == "verification_failed" and len(new.attempts) >= 3
    assert k == 3 or dims[0] == 1                       # the family search (vectorised scan) ran
    assert (new.status, new.optimal, new.gamma_lb, new.gamma_ub) == (old.status, old.optimal, old.gamma_lb,
                                                                   old.gamma_ub)
    assert np.array_equal(new.X, old.X) and [a.gamma_lb for a in new.attempts] == [a.gamma_lb for a in old.attempts]


def test_monomial_jacobian_equals_the_column_loop():
    """The span search's Jacobian (one stacked expression) bit for bit as the column loop it replaced."""
    rng = np.random.default_rng(7)
    n = 6
    E = np.array([e for d in range(4) for e in np.ndindex(*(4,) * n) if sum(e) == d], np.int64)
    L = lowered_exponents(E)
    for _ in range(300):
        v = rng.standard_normal(n) * 10.0 ** rng.uniform(-4, 4)
        v[rng.integers(n)] = 0.0 if rng.random() < 0.2 else v[0]
        loop = np.stack([E[:, j] * np.prod(v[None, :] ** L[j], axis=1) for j in range(n)], axis=1)
        assert np.array_equal(monomial_jacobian(v, E, L), loop)


def test_refused_cameras_raise_as_the_per_candidate_check_did():
    """Normalised cameras that fail the camera check (rank lost in extreme data): :meth:`one` raises its
    ValueError as the per-candidate check did, the family search sees +inf, the stacked scan too."""
    sc = random_scene(3, 1, noise_px=1.0, seed=2)
    cams = sc.cameras.copy()
    cams[0] = np.outer([1.0, 2.0, 3.0], [1.0, 0.0, 0.0, 1.0])             # rank 1
    cost = CandidateCost(_problem(), cams, [Point(p) for p in sc.points2d[0]])
    v = sc.points2d[0].ravel()
    with pytest.raises(ValueError, match="rank"):
        cost.one(v)
    with pytest.raises(ValueError, match="rank"):
        point_from_image_points(sc.points2d[0], cams)
    assert np.all(np.isinf(cost.many(np.stack([v, v + 1.0]))))
