"""Review 28a (independent, uncertain-region paths): a huge region's extent overflowed a Python float power
(OverflowError out of ``triangulate``), and a thin ellipse accepted by its constructor was refused in the normalised
frame (no estimate at all).

References: the regions' own constructor rule and distances, and a multi-start simplex search of gamma (an attained
value, so an upper bound of gamma*).
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize

import tritools
from tritools import Ellipse, EllipseBorder, Polytope, Segment, Status
from tritools.model.regions.ellipse import PD_RTOL
from tritools.solve.report import solve_ball


def _example():
    cams, regs = tritools.paper_example(4)
    return np.asarray(cams, float)[:3], regs[:3]


def _reference(cams, regions, starts) -> float:
    def f(X):
        return tritools.gamma(X, cams, regions)
    return min(minimize(f, X0, method="Nelder-Mead", options=dict(xatol=1e-12, fatol=1e-15, maxiter=4000)).fun
               for X0 in starts if X0 is not None)


@pytest.mark.parametrize("width", [1e160, 1e300])
def test_a_huge_polytope_gives_a_result_not_an_overflow(width):
    cams, regs = _example()
    x = np.asarray(regs[0].x, float)
    huge = Polytope(np.eye(2) / width, -x / width)         # |y - x| <= width along each axis
    problem = [huge, regs[1], regs[2]]
    res = tritools.triangulate(cams, problem)
    assert res.X is not None and np.isfinite(res.gamma_ub)
    assert res.gamma_ub == pytest.approx(tritools.gamma(res.X, cams, problem), rel=1e-9)
    ref = _reference(cams, problem, [res.X, tritools.dlt(cams, np.array([x, regs[1].x, regs[2].x]))])
    assert res.gamma_lb is None or res.gamma_lb <= ref * (1 + 1e-9)
    batch = tritools.triangulate_many([(cams, problem)])[0]
    assert batch.status != Status.SOLVER_FAILED and "OverflowError" not in batch.message
    assert tritools.triangulate(cams, problem, robust=1.0).X is not None


def test_solve_ball_of_huge_extents_is_infinite_not_an_error():
    x = np.zeros(2)
    assert solve_ball([Segment(x, [1e200, 0.0]), Segment(x, [1e200, 0.0])], 1.0) == np.inf
    assert 5.0 <= solve_ball([Segment(x, [3.0, 4.0])], 0.0) < 6.0     # the end point (3, 4) and the parameter


def _thin(k: int, cls):
    a = 0.05 + 0.07 * k
    R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    D = R @ np.diag([0.09, (0.3e-6 * (1 + 2e-5)) ** 2]) @ R.T        # axis ratio just above sqrt(PD_RTOL)
    return cls(np.array([0.05, -0.02]), 0.5 * (D + D.T))


@pytest.mark.parametrize("cls", [Ellipse, EllipseBorder])
@pytest.mark.parametrize("k", [7, 31])
def test_a_thin_ellipse_accepted_by_its_constructor_keeps_its_estimate(cls, k):
    cams, regs = _example()
    thin = _thin(k, cls)
    thin = cls(thin.center + np.asarray(regs[0].x, float), thin.D)
    problem = [thin, regs[1], regs[2]]
    res = tritools.triangulate(cams, problem)
    assert res.X is not None and res.gamma_ub is not None       # numerical_failure with no estimate before
    assert res.gamma_ub == pytest.approx(tritools.gamma(res.X, cams, problem), rel=1e-9)
    ref = _reference(cams, problem, [res.X])
    assert res.gamma_ub <= ref * (1 + 1e-6)
    assert res.gamma_lb is None or res.gamma_lb <= ref * (1 + 1e-9)


@pytest.mark.parametrize("cls", [Ellipse, EllipseBorder])
def test_similarity_carries_a_thin_ellipse_over(cls):
    thin = _thin(7, cls)
    lam = np.linalg.eigvalsh(thin.D)
    assert lam[0] > PD_RTOL * lam[1]                                  # accepted as given
    for s in (3.0, 1 / 3.0, 1e-3, 7.123):
        copy = thin.similarity(s, [1.0, -2.0])
        assert type(copy) is cls
        np.testing.assert_allclose(copy.center, s * (thin.center - [1.0, -2.0]), rtol=1e-14)
        np.testing.assert_allclose(copy.semi_axes, s * thin.semi_axes, rtol=1e-4)   # (lam_min to ~eps lam_max)
        major = np.linalg.eigh(thin.D)[1][:, 1]                     # the same ellipse, scaled: along its major
        p = copy.center + 0.5 * copy.semi_axes[0] * major           # axis the levels agree (to the 1e-5 of D^-1
        q = thin.center + (p - copy.center) / s                     # at condition 1e12, the constructor's own)
        assert copy.level(p) == pytest.approx(thin.level(q), rel=1e-3) and copy.level(p) == pytest.approx(0.25,
                                                                                                        rel=1e-3)
    with pytest.raises(ValueError, match="positive definite"):
        cls([0.0, 0.0], np.diag([1.0, 1e-13]))                       # the constructor's rule is unchanged


def test_a_too_thin_ellipse_is_refused_for_being_thin():
    # review 28a F3: "must be positive definite" for diag(1, 1e-12), which is positive definite
    for cls in (Ellipse, EllipseBorder):
        with pytest.raises(ValueError, match="not thinner than") as err:
            cls([0.0, 0.0], np.diag([1.0, 1e-12]))
        assert "PD_RTOL" in str(err.value)
        with pytest.raises(ValueError, match="must be positive definite, got eigenvalues"):
            cls([0.0, 0.0], np.diag([1.0, -1.0]))


def test_a_free_multiplier_runs_with_the_default_sparsity():
    # review 28a: multiplier='free' with sparsity 'auto' raised ValueError inside the solve at N >= 6 (the plan
    # chose the views formulation, where no free q exists); the plan keeps it dense, and 'views' is refused up front
    from tritools.scene import random_scene

    sc = random_scene(6, 1, noise_px=1.0, seed=3)
    cams, x = np.asarray(sc.cameras), np.asarray(sc.points2d)[0]
    res = tritools.triangulate(cams, x, multiplier="free", delta=4, max_delta=4, method="corollary1")
    assert res.X is not None and np.isfinite(res.gamma_ub)
    assert all(a.sparsity == "dense" for a in res.attempts if a.delta == 4)
    assert res.gamma_lb is None or res.gamma_lb <= res.gamma_ub * (1 + 1e-9)
    with pytest.raises(tritools.OptionError, match="multiplier"):
        tritools.TriangulationOptions(multiplier="free", sparsity="views")


def test_verification_with_a_huge_ball_neither_raises_nor_loses_an_exact_bound():
    # the read-through after review 28a F1: the scalar twin squared the ball's reach with a Python float ** (an
    # OverflowError for radius 1e200), and 0 * inf made the stacked bound NaN; an exactly PSD, exactly stationary
    # Lagrangian needs no margin on any ball
    import sospoly
    from sospoly.analysis import verify_quadratic, verify_quadratic_batch
    from tritools.model.epipolar_data import polynomial_errors

    x, y = sospoly.variables("x y")
    f = (x - 1) ** 2 + (y - 2) ** 2                      # min on x = y: 0.5 at (1.5, 1.5)
    near = verify_quadratic(f, [x - y], [1.5, 1.5], radius=10.0)
    assert near.certified and near.lower_bound <= 0.5
    for radius in (1e200, np.inf):
        far = verify_quadratic(f, [x - y], [1.5, 1.5], radius=radius)
        assert far.lower_bound == near.lower_bound and far.certified
        stacked = verify_quadratic_batch(np.array([5.0, 5.0]), np.array([[-2.0, -4.0]] * 2), np.stack([np.eye(2)] * 2),
                                         np.zeros((2, 1)), np.array([[[1.0, -1.0]]] * 2), np.zeros((2, 1, 2, 2)),
                                         np.array([[1.5, 1.5]] * 2), radius=np.array([radius, 10.0]))
        assert stacked.lower_bound[0] == stacked.lower_bound[1] <= 0.5
    assert polynomial_errors([x - y], [1.5, 1.5], 1e200)[0] == np.inf
