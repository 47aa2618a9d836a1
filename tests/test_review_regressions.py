"""Regressions from the independent review of the #18 refactor (each reproduced first on the merged main)."""
from dataclasses import dataclass

import numpy as np
import pytest

import tritools
from tritools.model.regions import RegionPolynomials
from tritools.scene import random_scene
from tritools.solve.options import OptionError, OptionTypeError


@dataclass(frozen=True, eq=False)
class Dot(tritools.Region):
    """A point region of a user's that does not declare extent()."""
    px: float
    py: float
    kind = "dot_review"
    n_aux = 0

    def polynomials(self, x, y):
        return RegionPolynomials((x[0] - self.px) ** 2 + (x[1] - self.py) ** 2)

    def closest_point(self, points):
        return np.broadcast_to(self.center, np.shape(points)).copy()

    @property
    def center(self):
        return np.array([self.px, self.py])

    def similarity(self, s, t):
        return type(self)(s * (self.px - t[0]), s * (self.py - t[1]))


@dataclass(frozen=True, eq=False)
class DotPoint(Dot):
    """The same, claiming the point fast path."""
    kind = "dotpoint_review"

    @property
    def is_point(self):
        return True


def _gamma(X, cams, x, c=np.inf):
    """gamma_TLS(X) = sqrt(sum_i min(d_i^2, c^2) / 2N) (c = inf: the L2 gamma), from the cameras themselves."""
    h = cams @ np.append(X, 1.0)
    d2 = np.sum((h[:, :2] / h[:, 2:3] - x) ** 2, axis=1)
    return float(np.sqrt(np.sum(np.minimum(d2, c * c)) / (2 * len(x))))


def test_robust_batch_past_its_whole_call_limit_keeps_an_estimate():
    """Non-point regions in a robust batch whose whole-call limit expired before any candidate: status time_limit
    with X, gamma_UB = gamma_TLS(X) and the inlier set (was numerical_failure, no X)."""
    sc = random_scene(4, 3, noise_px=1.0, seed=2)
    probs = [(sc.cameras, [tritools.Ellipse.circle(p, 0.5) for p in sc.points2d[k]]) for k in range(3)]
    out = tritools.triangulate_many(probs, robust=5.0, total_time_limit=1e-6)
    assert len(out) == 3
    for r, (cams, regs) in zip(out, probs):
        assert r.status == tritools.Status.TIME_LIMIT and not r.optimal and r.X is not None
        assert r.inliers is not None and len(r.inliers) == 4
        h = cams @ np.append(r.X, 1.0)
        u = h[:, :2] / h[:, 2:3]
        d = np.array([np.linalg.norm(u[i] - reg.closest_point(u[i])) for i, reg in enumerate(regs)])
        assert r.gamma_ub == pytest.approx(np.sqrt(np.sum(np.minimum(d, 5.0) ** 2) / 8), rel=1e-9)
        assert r.gamma_lb is None or r.gamma_lb <= r.gamma_ub


@pytest.mark.parametrize("cls", [Dot, DotPoint])
def test_a_region_without_extent_is_refused_on_every_path(cls):
    cams, regs = tritools.paper_example(4)
    R = [cls(*r.x) for r in regs]
    for call in (lambda: tritools.triangulate(cams, R), lambda: tritools.triangulate(cams, R, robust=1.0)):
        with pytest.raises(TypeError, match=r"extent\(\)"):
            call()
    for kw in ({}, {"robust": 1.0}):
        r = tritools.triangulate_many([(cams, R), (cams, regs)], **kw)
        assert r[0].status == tritools.Status.INVALID_INPUT and "extent()" in r[0].message
        ref = _gamma(r[1].X, cams, np.array([g.x for g in regs]), kw.get("robust", np.inf))
        assert r[1].optimal and r[1].gamma_ub == pytest.approx(ref, rel=1e-9)


@pytest.mark.parametrize("kw, field, kind", [({"multiplier": float("inf")}, "multiplier", OptionError),
                                             ({"multiplier": float("nan")}, "multiplier", OptionError),
                                             ({"backend": 3}, "backend", OptionTypeError)])
def test_unusable_options_are_refused_when_given(kw, field, kind):
    with pytest.raises(kind) as info:
        tritools.TriangulationOptions(**kw)
    assert info.value.field == field
