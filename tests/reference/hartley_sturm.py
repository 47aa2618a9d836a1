"""Exact two-view optimal (L2) triangulation of Hartley & Sturm (1997).

Independent of ``tritools``: the fundamental matrix is obtained from the bilinear
constraint ``det [[P1, x1, 0], [P2, 0, x2]] = 0`` (Hartley & Zisserman §17.1), and the
minimiser follows Hartley & Zisserman Algorithm 12.1:

1. translate both image points to the origin (``T1``, ``T2``);
2. rotate so that the epipoles are ``(1, 0, f1)`` and ``(1, 0, f2)``;
3. the epipolar line pencil parametrised by ``t`` gives the cost
   ``s(t) = t^2 / (1 + f1^2 t^2) + (c t + d)^2 / ((a t + b)^2 + f2^2 (c t + d)^2)``,
   whose stationary points are the real roots of the degree-6 polynomial
   ``g(t) = t ((a t + b)^2 + f2^2 (c t + d)^2)^2
   - (a d - b c) (1 + f1^2 t^2)^2 (a t + b) (c t + d)``;
4. evaluate ``s`` at the real roots and at ``t = inf``; take the minimum;
5. the optimal image points are the feet of the perpendiculars from the origin to
   the two epipolar lines, transferred back; ``X`` is their (exact) triangulation.

Conditioning: all of this is done in image coordinates ``x' = s (x - x_i)`` with one common
scale ``s`` (about one over the focal length), so that principal points at 1e6 px or
coordinates of 1e-3 do not spoil ``F`` in floating point; a common isotropic scale leaves the
minimiser unchanged and multiplies the cost by ``s^2``, which is divided out.
"""
from __future__ import annotations

import numpy as np

__all__ = ["fundamental_from_determinant", "hartley_sturm"]


def fundamental_from_determinant(P1: np.ndarray, P2: np.ndarray) -> np.ndarray:
    """``F`` with ``x2~' F x1~ = 0``: ``F[b, a] = det [[P1, e_a, 0], [P2, 0, e_b]]``."""
    F = np.zeros((3, 3))
    I = np.eye(3)
    for a in range(3):
        for b in range(3):
            M = np.zeros((6, 6))
            M[:3, :4] = P1
            M[3:, :4] = P2
            M[:3, 4] = I[a]
            M[3:, 5] = I[b]
            F[b, a] = np.linalg.det(M)
    return F


def _right_null(A: np.ndarray) -> np.ndarray:
    return np.linalg.svd(A)[2][-1]


def _foot(line: np.ndarray) -> np.ndarray:
    lam, mu, nu = line
    return np.array([-lam * nu, -mu * nu, lam * lam + mu * mu])


def _pixel_scale(P: np.ndarray, x: np.ndarray) -> float:
    """About the focal length of ``P`` (pixels per radian) seen from image point ``x``: the size of the
    rows of ``M = P[:, :3]`` after moving ``x`` to the origin, relative to the depth row."""
    M = P[:, :3] / np.linalg.norm(P[2, :3])
    return float(np.linalg.norm(M[:2] - np.outer(x, M[2])) / np.sqrt(2.0))


def _conditioned(P: np.ndarray, x: np.ndarray, s: float) -> np.ndarray:
    T = np.array([[s, 0.0, -s * x[0]], [0.0, s, -s * x[1]], [0.0, 0.0, 1.0]])
    Q = T @ P
    return Q / np.linalg.norm(Q)


def hartley_sturm(P1, P2, x1, x2) -> tuple[np.ndarray, float]:
    """Optimal triangulation from two views.

    Returns
    -------
    X : ndarray (3,)
        The global minimiser of ``||Phi(X, P1) - x1||^2 + ||Phi(X, P2) - x2||^2``.
    cost : float
        The minimal sum of squared reprojection errors.
    """
    P1, P2 = np.asarray(P1, float), np.asarray(P2, float)
    x1, x2 = np.asarray(x1, float), np.asarray(x2, float)
    s = 2.0 / (_pixel_scale(P1, x1) + _pixel_scale(P2, x2))
    X, cost = _hartley_sturm(_conditioned(P1, x1, s), _conditioned(P2, x2, s), np.zeros(2), np.zeros(2))
    return X, cost / s ** 2


def _hartley_sturm(P1, P2, x1, x2) -> tuple[np.ndarray, float]:
    F = fundamental_from_determinant(P1, P2)
    F = F / np.linalg.norm(F)
    T1 = np.array([[1.0, 0.0, -x1[0]], [0.0, 1.0, -x1[1]], [0.0, 0.0, 1.0]])
    T2 = np.array([[1.0, 0.0, -x2[0]], [0.0, 1.0, -x2[1]], [0.0, 0.0, 1.0]])
    F = np.linalg.inv(T2).T @ F @ np.linalg.inv(T1)
    e1 = _right_null(F)
    e2 = _right_null(F.T)
    e1 = e1 / np.hypot(e1[0], e1[1])
    e2 = e2 / np.hypot(e2[0], e2[1])
    R1 = np.array([[e1[0], e1[1], 0.0], [-e1[1], e1[0], 0.0], [0.0, 0.0, 1.0]])
    R2 = np.array([[e2[0], e2[1], 0.0], [-e2[1], e2[0], 0.0], [0.0, 0.0, 1.0]])
    F = R2 @ F @ R1.T
    f1, f2 = e1[2], e2[2]
    a, b, c, d = F[1, 1], F[1, 2], F[2, 1], F[2, 2]

    Poly = np.polynomial.Polynomial
    t = Poly([0.0, 1.0])
    g = t * ((a * t + b) ** 2 + f2 ** 2 * (c * t + d) ** 2) ** 2 \
        - (a * d - b * c) * (1 + f1 ** 2 * t ** 2) ** 2 * (a * t + b) * (c * t + d)
    # drop negligible *leading* coefficients only (their roots go to t = inf, a candidate below); a small
    # low-order coefficient is a root near t = 0 (image points near the epipoles) and must stay
    coef = g.coef
    top = np.abs(coef).max()
    while len(coef) > 1 and abs(coef[-1]) <= 1e-14 * top:
        coef = coef[:-1]
    roots = np.polynomial.polynomial.polyroots(coef) if len(coef) > 1 else np.array([])
    candidates = [float(r.real) for r in np.atleast_1d(roots)]

    def s(tt):
        return tt * tt / (1 + f1 * f1 * tt * tt) + (c * tt + d) ** 2 / ((a * tt + b) ** 2 + f2 * f2 * (c * tt + d) ** 2)

    best_cost = 1.0 / f1 ** 2 + c * c / (a * a + f2 * f2 * c * c) if f1 != 0 else np.inf
    best_t = np.inf
    for tt in candidates:
        v = s(tt)
        if v < best_cost:
            best_cost, best_t = v, tt
    if np.isinf(best_t):
        l1 = np.array([f1, 0.0, -1.0])
        l2 = np.array([-f2 * c, a, c])
    else:
        l1 = np.array([best_t * f1, 1.0, -best_t])
        l2 = np.array([-f2 * (c * best_t + d), a * best_t + b, c * best_t + d])
    y1 = np.linalg.inv(T1) @ R1.T @ _foot(l1)
    y2 = np.linalg.inv(T2) @ R2.T @ _foot(l2)
    y1 = y1[:2] / y1[2]
    y2 = y2[:2] / y2[2]
    A = np.vstack([y1[0] * P1[2] - P1[0], y1[1] * P1[2] - P1[1],
                   y2[0] * P2[2] - P2[0], y2[1] * P2[2] - P2[1]])
    A = A / np.linalg.norm(A, axis=1, keepdims=True)
    w = _right_null(A)
    X = w[:3] / w[3]
    cost = float(np.sum((y1 - x1) ** 2) + np.sum((y2 - x2) ** 2))
    return X, cost
