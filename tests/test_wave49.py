"""Wave 49: fundamental matrices from the cameras' 4 x 4 determinants with their proven error (issue #22).

:func:`tritools.model.fundamental_det.fundamental_determinants` (what :func:`tritools.model.stacked.fundamental_stack`
now returns) is checked against the exact fundamental matrix of the float cameras in rationals: its bound holds for
ordinary, nearly coincident, pixel-scaled, georeferenced and extreme-scaled cameras, is ~1e-14 on normalised ones
(below the pseudo-inverse form's measured error, which the old model understated), and F agrees with the scalar
:func:`tritools.model.geometry.fundamental_matrix` up to scale.  End to end: the Lagrangian bounds of single calls
stay below an independent two-view reference.
"""
from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from tritools.model.fundamental_det import determinant_form, fundamental_determinants
from tritools.model.geometry import fundamental_matrix
from tritools.model.stacked import fundamental_stack, view_pairs
from tritools.scene import random_scene

from .test_wave47 import _exact_fundamental, _two_view_reference


def _cameras(rng, kind: str) -> np.ndarray:
    """Two cameras (2, 3, 4) of an adversarial kind."""
    C = rng.normal(size=(2, 3, 4))
    if kind == "near":                      # centres ~1e-3..1e-9 apart
        C[1] = C[0] + rng.normal(size=(3, 4)) * 10.0 ** -float(rng.integers(3, 10))
    elif kind == "pixels":                  # principal point at ~1e6 px, focal length ~1e3
        K = np.array([[1e3, 0, 1e6], [0, 1e3, -1e6], [0, 0, 1.0]])
        C = K @ C
    elif kind == "georef":                  # centres at ~1e6 from the origin, 1 apart
        c = 1e6 + rng.normal(size=(2, 3))
        R = [np.linalg.qr(rng.normal(size=(3, 3)))[0] for _ in range(2)]
        C = np.array([np.hstack([R[k], (-R[k] @ c[k])[:, None]]) for k in range(2)])
    elif kind == "extreme":                 # cameras scaled by 1e+-200
        C = C * np.array([1e200, 1e-200])[:, None, None]
    return C


def _exact_error(F: np.ndarray, Pi: np.ndarray, Pj: np.ndarray) -> float:
    """min over lambda of ||F - lambda D||_F for the exact D of the float cameras, in rationals (the lambda of the
    least-squares fit), as a float."""
    D = _exact_fundamental(Pi, Pj)
    Fx = [[Fraction(float(F[k, l])) for l in range(3)] for k in range(3)]
    lam = sum(Fx[k][l] * D[k][l] for k in range(3) for l in range(3)) / \
        sum(D[k][l] ** 2 for k in range(3) for l in range(3))
    return float(sum((Fx[k][l] - lam * D[k][l]) ** 2 for k in range(3) for l in range(3))) ** 0.5


@pytest.mark.parametrize("kind", ["plain", "near", "pixels", "georef", "extreme"])
def test_determinant_fundamental_bound_holds_against_the_exact_matrix(kind):
    rng = np.random.default_rng(["plain", "near", "pixels", "georef", "extreme"].index(kind))
    I, J = np.array([0]), np.array([1])
    for _ in range(12):
        C = _cameras(rng, kind)
        F, ok, e = fundamental_determinants(C[None], I, J)
        assert ok[0, 0] and np.isfinite(e[0, 0])
        assert abs(np.linalg.norm(F[0, 0]) - 1.0) < 1e-15
        err = _exact_error(F[0, 0], C[0], C[1])
        assert err <= e[0, 0], (kind, err, e[0, 0])
        if kind == "plain":                 # ~1 ulp of F, and the bound not far above it
            assert e[0, 0] < 1e-13


def test_fundamental_stack_agrees_with_the_scalar_fundamental_matrix_up_to_scale():
    """F of the stack (determinants) against geometry.fundamental_matrix (the pseudo-inverse form), normalised and
    signed alike: the same matrix within the latter's round-off, on every pair of random scenes."""
    for N, seed in ((2, 0), (5, 1), (10, 2)):
        C = np.asarray(random_scene(N, 1, noise_px=1.0, seed=seed).cameras)
        F, defined = fundamental_stack(C[None])
        assert defined.all()
        for k, (i, j) in enumerate(zip(*view_pairs(N))):
            G = fundamental_matrix(C[i], C[j])
            G = G / np.linalg.norm(G)
            G = G * np.sign(np.sum(G * F[0, k]))
            assert np.abs(G - F[0, k]).max() < 1e-11


def test_stack_errors_are_the_determinants_bounds_and_undefined_pairs_are_inf():
    """fundamental_stack(errors=True): the bound of fundamental_determinants where a pair is defined, inf where its
    centres coincide (a duplicated view, -2.5 P)."""
    C = np.asarray(random_scene(4, 1, noise_px=1.0, seed=4).cameras)
    C = np.concatenate([C, -2.5 * C[:1]])
    F, defined, E = fundamental_stack(C[None], errors=True)
    I, J = view_pairs(5)
    same = (I == 0) & (J == 4)
    assert not defined[0, same].any() and np.isinf(E[0, same]).all() and not F[0, same].any()
    assert defined[0, ~same].all() and (E[0, ~same] < 1e-12).all()        # (raw cameras: ~1e-13)
    _, ok, e = fundamental_determinants(C[None], I, J)
    assert np.array_equal(E[0, ~same], e[0, ~same])


def test_determinant_form_in_longdouble_bounds_tighter_than_in_double():
    """determinant_form's error bound scales with the unit round-off of the type it runs in (fundamental_bounds keeps
    longdouble; F itself is formed in double), and both hold against the exact determinants."""
    rng = np.random.default_rng(9)
    C = rng.normal(size=(1, 2, 3, 4))
    I, J = np.array([0]), np.array([1])
    D_ld, dD_ld = determinant_form(C, I, J)
    D_d, dD_d = determinant_form(C, I, J, np.float64)
    exact = _exact_fundamental(C[0, 0], C[0, 1])
    for D, dD in ((D_ld, dD_ld), (D_d, dD_d)):
        for k in range(3):
            for l in range(3):
                assert abs(Fraction(*D[0, 0, k, l].as_integer_ratio()) - exact[k][l]) <= Fraction(float(dD[0, 0, k, l]))
    if np.finfo(np.longdouble).eps < np.finfo(np.float64).eps:
        assert (dD_ld < dD_d / 100).all()


def test_two_view_single_calls_stay_below_the_exact_reference():
    """End to end on the new F: certified two-view single calls (verification) bound gamma* from below, against the
    independent pencil-of-planes reference, at pixel scales 1 and 1e6 and in a georeferenced world."""
    import tritools

    for seed in range(6):
        sc = random_scene(2, 3, noise_px=1.0, seed=100 + seed)
        C, x = np.asarray(sc.cameras), np.asarray(sc.points2d)
        for j in range(3):
            r = tritools.triangulate(C, x[j])
            assert r.optimal
            ref = _two_view_reference(C, x[j])
            assert r.gamma_lb <= ref * (1 + 1e-9) + 1e-12
            assert r.gamma_ub >= ref * (1 - 1e-9)
