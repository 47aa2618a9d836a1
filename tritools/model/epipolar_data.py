"""How well computed epipolar constraints hold at true projections: the data error a Lagrangian bound must charge.

A degree-2 certificate bounds min{f : g = 0} by c(lambda) = min_v f(v) + sum_k lambda_k g_k(v), valid when every
true feasible point has g_k = 0.  The g_k used are built from *computed* fundamental matrices F~_k (unit Frobenius
norm, :func:`tritools.model.stacked.fundamental_stack`): at the true projections v* of a point, g~_k(v*) =
v~*_i^T F~_k v~*_j is not 0 but of the order of F~'s rounding, so the bound is really
min{f : g = 0} >= c - sum_k |lambda_k| e_k with e_k >= |g~_k(v*)| (:func:`sospoly.analysis.verify_quadratic_batch`'s
``constraint_error``).  At an ordinary candidate lambda is O(1) and the term is ~1e-14 of the bound; at a degenerate
one (all camera centres on a line, the candidate at infinity) the least-squares multipliers reach 1e13, and a
rounding of 1e-16 moved a TLS bound 0.16 px^2 above an attained value (review 27b F1: a rectified rig with zero
disparity certified gamma_LB 3.20784 where 3.20571 is attained).

:func:`epipolar_errors` bounds |g~_k(v)| on the ball ||v|| <= R of the minimisers by
e_k = max(EPIPOLAR_DATA_RTOL ||F~_k||_F, 4 |g~_k(v^)| / (||v~^_i|| ||v~^_j||)) (1 + R^2 / 2): F~'s error as a
multiple of the unit roundoff, or as measured at the candidate v^ (the projections of a point, so exactly feasible
in exact arithmetic: what g~ shows there is data error), times the largest ||v~_i|| ||v~_j|| on the ball (with
v~ = (v, 1) and ||v_i||^2 + ||v_j||^2 <= R^2).  Without the cameras that is a model of F~'s error, not a proof
of it; given the cameras F~ was computed from (``cameras``), the first term is a proof (:func:`fundamental_bounds`):
||F~ - lambda F_ij||_F for the exact fundamental matrix F_ij of those float cameras, whose entries are the 4 x 4
determinants (-1)^(k+l) det[P_i without row k; P_j without row l] (SPEC §7), computed from the cameras' 2 x 2 minors
with an a-posteriori error bound -- the computed F~ erred by up to ~800 times the model's 16 ulps on ordinary
two-view problems (wave 47), which a degenerate candidate's multipliers of 1e13 would carry into the bound.
"""
from __future__ import annotations

import numpy as np

from .fundamental_det import determinant_form
from .stacked import norms

__all__ = ["EPIPOLAR_DATA_RTOL", "epipolar_errors", "fundamental_bounds", "polynomial_errors"]

_U = 2.0 ** -53

#: the relative error assumed of a computed, unit-norm fundamental matrix (16 units in the last place)
EPIPOLAR_DATA_RTOL = 16 * 2.0 ** -52


def epipolar_errors(F: np.ndarray, pairs: tuple, v: np.ndarray, radius, cameras: np.ndarray | None = None,
                    proven: np.ndarray | None = None) -> np.ndarray:
    """(M, K) bounds e_k of the module docstring for F (M, K, 3, 3) of the view pairs ``pairs`` = (I, J) (rows of
    zeros: dropped constraints, e = 0), the candidates v (M, 2N) and the radii (M,) (or a scalar); ``cameras``
    (M, N, 3, 4): the cameras F was computed from, whose :func:`fundamental_bounds` replace the model's 16 ulps;
    ``proven`` (M, K): those bounds computed already (e.g. once per problem for many subsets of its pairs)."""
    F = np.asarray(F, float)
    M, K = F.shape[:2]
    I, J = (np.asarray(p, int) for p in pairs)
    vt = np.concatenate([np.asarray(v, float).reshape(M, -1, 2), np.ones((M, np.asarray(v).shape[1] // 2, 1))],
                        axis=2)
    vi, vj = vt[:, I], vt[:, J]                                          # (M, K, 3)
    with np.errstate(invalid="ignore", over="ignore"):
        g = np.einsum("mka,mkab,mkb->mk", vi, F, vj)
        seen = 4 * np.abs(g) / (norms(vi, axis=2) * norms(vj, axis=2))      # (np.linalg.norm's numbers)
        base = EPIPOLAR_DATA_RTOL * norms(F, axis=(2, 3))
        if proven is None:
            proven = base if cameras is None else fundamental_bounds(cameras, (I, J), F)
        proven = np.where(base > 0, proven, 0.0)
        e = np.maximum(proven, np.where(np.isfinite(seen), seen, np.inf))
        R = np.broadcast_to(np.asarray(radius, float), (M,))
        return np.where(base > 0, e * (1.0 + R[:, None] ** 2 / 2) * (1 + 1e-12), 0.0)


def fundamental_bounds(C: np.ndarray, pairs: tuple, F: np.ndarray) -> np.ndarray:
    """(M, K) upper bounds of ||F~_k - lambda_k F_k||_F for the computed matrices F~ (M, K, 3, 3) of the view pairs
    ``pairs`` = (I, J) of cameras C (M, N, 3, 4), some number lambda_k and the exact fundamental matrix F_k of the
    float cameras (module docstring; inf where its computed determinant form vanishes or is not finite).

    F_k's entries D_kl = (-1)^(k+l) sum_c s_c m_i(k, c) m_j(l, c') from the 2 x 2 minors m(k, c) of each camera's two
    rows other than k on the column pair c (c' its complement, s_c its sign), in longdouble (unit round-off u'); each
    minor errs by at most gamma_2 of its absolute form mhat, so |D~ - D| <= 16 u' sum_c mhat_i mhat_j (the products,
    their six-term sum and the rounding of that sum of non-negative terms, generously) + u |D~| (the rounding to
    double).  With lambda = <F~, D~> / <D~, D~>: |F~ - lambda D| <=
    |F~ - lambda D~| + |lambda| |D~ - D| entrywise, each float operation charged (the bound holds for the float
    lambda as computed, as for any number)."""
    C = np.asarray(C, float)
    I, J = (np.asarray(p, int) for p in pairs)
    with np.errstate(over="ignore", invalid="ignore"):
        D_ld, dD = determinant_form(C, I, J)
        D = D_ld.astype(float)                                # (rounded once more: u |D|)
        dD = dD.astype(float) * (1 + 4 * _U) + _U * np.abs(D) + 5e-324      # (a bound below 2^-1074: the last term)
        F = np.asarray(F, float)
        nn = np.einsum("mkab,mkab->mk", D, D)
        lam = (np.einsum("mkab,mkab->mk", F, D) / nn)[..., None, None]
        lD = np.abs(lam * D)
        E = np.abs(F - lam * D) * (1 + 4 * _U) + 4 * _U * (lD + np.abs(F)) + np.abs(lam) * dD * (1 + 4 * _U)
        out = norms(E, axis=(2, 3)) * (1 + 8 * _U)
    return np.where(np.isfinite(out) & (nn > 0), out, np.inf)


def polynomial_errors(eq, point: np.ndarray, radius: float) -> np.ndarray:
    """(K,) the same bounds for constraints given as quadratic polynomials built from computed data (the generic
    verification of a built problem): e_k = max(EPIPOLAR_DATA_RTOL sum_a |c_ka|, 4 |g_k(v^)|) max(1, R^2), each
    coefficient c_ka known to within EPIPOLAR_DATA_RTOL of the largest and every monomial of degree <= 2 at most
    max(1, R^2) on the ball; v^ the candidate (a true feasible point)."""
    out = []
    for g in eq:
        coef = float(np.sum(np.abs(np.asarray(g.coefficients(), float))))
        seen = 4 * abs(float(g(np.asarray(point, float))))
        out.append(max(EPIPOLAR_DATA_RTOL * coef, seen if np.isfinite(seen) else np.inf))
    r = float(radius)
    return np.array(out) * max(1.0, r * r) * (1 + 1e-12)     # (r * r: inf past the largest float, ** raises)
