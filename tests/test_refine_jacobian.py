"""The local refinement's analytic Jacobian (tritools.model.refine.disc_jacobian) against central differences of the
residuals, for points, discs (projections outside and inside), and its use in refine_l2: the refined gamma is a local
minimum (no better point by a dense scipy multi-start with finite differences, to round-off)."""
import numpy as np
import pytest
from scipy.optimize import least_squares

from tritools.model.geometry import refine_l2
from tritools.model.refine import disc_jacobian, disc_residuals, residual_function, residual_jacobian
from tritools.model.regions import Ellipse, Point
from tritools.scene import random_scene


def _central(fun, X, h=1e-6):
    J = np.empty((len(fun(X)), 3))
    for k in range(3):
        e = np.zeros(3)
        e[k] = h * max(1.0, abs(X[k]))
        J[:, k] = (fun(X + e) - fun(X - e)) / (2 * e[k])
    return J


@pytest.mark.parametrize("seed", range(4))
def test_jacobian_matches_differences(seed):
    sc = random_scene(5, 1, noise_px=2.0, seed=seed)
    rng = np.random.default_rng(seed)
    centres = sc.points2d[0] + rng.normal(0, 30, (5, 2))
    radii = np.array([0.0, 5.0, 80.0, 0.0, 12.0])        # points, discs the projection is outside / inside of
    X = sc.points3d[0] + rng.normal(0, 0.05, 3)
    J = disc_jacobian(X, sc.cameras, centres, radii)
    Jn = _central(lambda Y: disc_residuals(Y, sc.cameras, centres, radii), X)
    np.testing.assert_allclose(J, Jn, rtol=1e-5, atol=1e-6 * np.abs(Jn).max())
    inside = np.linalg.norm(sc.cameras[2] @ np.append(X, 1) / (sc.cameras[2] @ np.append(X, 1))[2]
                            - np.append(centres[2], 1)) < radii[2]
    if inside:
        assert np.all(J[4:6] == 0.0)


def test_jacobian_for_every_region_kind():
    """Points and discs: the stacked closed form; other regions (here ellipses the point lies outside of): through
    RegionStack.residual_derivatives (tests/test_region_stack.py), no longer scipy's forward differences."""
    sc = random_scene(3, 1, noise_px=1.0, seed=0)
    pts = [Point(p) for p in sc.points2d[0]]
    assert callable(residual_jacobian(sc.cameras, pts))
    ell = [Ellipse(p + 5.0, np.diag([1.0, 4.0])) for p in sc.points2d[0]]
    jac = residual_jacobian(sc.cameras, ell)
    assert callable(jac)
    fun, _ = residual_function(sc.cameras, ell)
    X = sc.points3d[0]
    F = np.column_stack([(fun(X + e) - fun(X - e)) / 2e-6 for e in np.eye(3) * 1e-6])
    assert np.abs(jac(X) - F).max() <= 1e-5 * np.abs(F).max()


@pytest.mark.parametrize("seed", range(3))
def test_refine_reaches_a_local_minimum(seed):
    sc = random_scene(4, 1, noise_px=3.0, seed=seed)
    regs = [Point(p) for p in sc.points2d[0]]
    X0 = sc.points3d[0] + 0.1
    X = refine_l2(X0, sc.cameras, regs)
    fun, _ = residual_function(sc.cameras, regs)
    ref = least_squares(fun, X0, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15).x
    f, fr = float(fun(X) @ fun(X)), float(fun(ref) @ fun(ref))
    assert f <= fr * (1 + 1e-9) + 1e-18
