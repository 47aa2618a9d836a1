"""The Levenberg-Marquardt refinement of one point on Python floats: the scalar twin of
:func:`tritools.model.stacked.refine_point` and :func:`tritools.model.stacked.gauss_newton_polish` for the few views
of a single call (issue #19: at three views each numpy call on a (3, 2, 3) array costs more than its arithmetic).

The maths is that of :func:`~tritools.model.stacked.refine_point`: minimise f(X) = sum_i ||Phi(X, P_i) - x^_i||^2
with Phi(X, P) = (P_1 X~, P_2 X~) / (P_3 X~), the Jacobian d Phi / d X = (P[:2, :3] - u P[2, :3]) / (P_3 X~), the
step -(J^T J + mu (1 + tr J^T J) / 3 I)^{-1} J^T r (:func:`~tritools.model.stacked.solve3`, Gaussian elimination
with partial pivoting; the pseudo-inverse where it is exactly singular), a step accepted iff f does not increase,
mu / 10 on acceptance (floor 1e-12) and x 10 otherwise, stopping when ||step|| <= LM_STEP_RTOL (1 + ||X||)
(converged) or mu > 1e12 (stalled) or after LM_MAX_ITER iterations; a projection is undefined where
|P_3 X~| <= PROJECTION_DENOM_RTOL |P_3| . |X~| (:func:`~tritools.model.stacked.project_stack`'s rule).  Then one
undamped Gauss-Newton step, kept only where it lowers f strictly (:func:`gauss_newton_polish`).

The same rules, the sums in view order instead of numpy's (BLAS) order: equal to the numpy twins up to round-off
(tests/test_single_call_twins.py).  Any point is a valid candidate for the bounds that use it (an upper bound is its
exact cost; a Lagrangian bound holds at any candidate), so round-off in X changes no rigour.
"""
from __future__ import annotations

import math

import numpy as np

from .geometry import PROJECTION_DENOM_RTOL

__all__ = ["refine_point_one", "refine_floats", "polish_floats", "solve3", "LM_MAX_ITER", "LM_STEP_RTOL",
           "FLOAT_MAX_VIEWS"]

#: Levenberg-Marquardt iterations at most (from the DLT start it converges in ~5-10).
LM_MAX_ITER = 100
#: a problem's iteration stops when its step is below LM_STEP_RTOL * (1 + ||X||) (normalised units, X ~ 1).
LM_STEP_RTOL = 1e-13
#: :func:`tritools.model.stacked.refine_point` and :func:`~tritools.model.stacked.gauss_newton_polish` of one
#: problem run on floats (:func:`refine_floats`, :func:`polish_floats`) up to this many views (issue #22: a single
#: call's refinement cost ~30 us per iteration on the (N, 2, 3) arrays at N = 2; from a start 0.1 off, CPU us per
#: refinement floats / arrays: 138 / 325 at N = 4, 196 / 294 at N = 8, 199 / 265 at N = 10).
FLOAT_MAX_VIEWS = 10


def refine_point_one(C: list, xhat: list, X: list) -> tuple:
    """(X (3 floats), ok, converged): :func:`tritools.model.stacked.refine_point` then
    :func:`tritools.model.stacked.gauss_newton_polish` (module docstring) for cameras C (N lists of 3 rows of 4
    floats), observations x^ (N pairs) and a start X (3 floats)."""
    views = [_split(P) for P in C]
    at = _project(views, xhat, X)
    if at is None:
        return list(X), False, False
    X, at, converged = _lm_loop(views, xhat, list(X), at)
    X = _gauss_newton(views, xhat, X, at)
    return X, all(math.isfinite(v) for v in X), converged


def refine_floats(C: np.ndarray, xhat: np.ndarray, X: np.ndarray, max_iter: int = LM_MAX_ITER) -> tuple:
    """:func:`tritools.model.stacked.refine_point` of cameras C (N, 3, 4), points x^ (N, 2) from X (3,) on floats
    (the iterations of the module docstring, at most ``max_iter``): (X (3,) array, ok, converged)."""
    views, xh = [_split(P) for P in np.asarray(C, float).tolist()], np.asarray(xhat, float).tolist()
    Xl = [float(v) for v in X]
    at = _project(views, xh, Xl)
    if at is None:
        return np.array(X, float), False, False
    Xl, _, converged = _lm_loop(views, xh, Xl, at, max_iter)
    out = np.array(Xl)
    return out, bool(np.isfinite(out).all()), converged


def polish_floats(C: np.ndarray, xhat: np.ndarray, X: np.ndarray) -> np.ndarray:
    """:func:`tritools.model.stacked.gauss_newton_polish` of one problem (C (N, 3, 4), x^ (N, 2), X (3,)) on floats:
    X after one undamped Gauss-Newton step kept iff it lowers f strictly and stays finite (a copy)."""
    views, xh = [_split(P) for P in np.asarray(C, float).tolist()], np.asarray(xhat, float).tolist()
    Xl = [float(v) for v in X]
    at = _project(views, xh, Xl)
    return np.array(X, float) if at is None else np.array(_gauss_newton(views, xh, Xl, at))


def _split(P: list) -> tuple:
    """(rows 1-3 of the left block, last column, |third row's left block|, |its last entry|) of one camera."""
    return P[0][:3], P[1][:3], P[2][:3], (P[0][3], P[1][3], P[2][3]), [abs(v) for v in P[2][:3]], abs(P[2][3])


def _project(views: list, xhat: list, X: list):
    """(u (N pairs), den (N), f, r (2N)) at X, or None where a projection is undefined (module docstring) or u is
    not finite (f then not finite either)."""
    x0, x1, x2 = X
    ax0, ax1, ax2 = abs(x0), abs(x1), abs(x2)
    u, den, r = [], [], []
    for (a0, a1, a2, b, m2, mb), (p, q) in zip(views, xhat):
        d = a2[0] * x0 + a2[1] * x1 + a2[2] * x2 + b[2]
        if not abs(d) > PROJECTION_DENOM_RTOL * (m2[0] * ax0 + m2[1] * ax1 + m2[2] * ax2 + mb):
            return None                             # (also where the test is NaN: no division by an exact 0)
        u0 = (a0[0] * x0 + a0[1] * x1 + a0[2] * x2 + b[0]) / d
        u1 = (a1[0] * x0 + a1[1] * x1 + a1[2] * x2 + b[1]) / d
        u.append((u0, u1))
        den.append(d)
        r += [u0 - p, u1 - q]
    f = 0.0
    for v in r:
        f += v * v
    if not math.isfinite(f) and not all(math.isfinite(v) for uv in u for v in uv):
        return None
    return u, den, f, r


def _normal_equations(views: list, at: tuple) -> tuple:
    """(J^T J as 3 rows, J^T r) at a projection ``at`` of :func:`_project`."""
    u, den, _, r = at
    s00 = s01 = s02 = s11 = s12 = s22 = g0 = g1 = g2 = 0.0
    k = 0
    for (a0, a1, a2, _, _, _), (u0, u1), d in zip(views, u, den):
        for row, ui in ((a0, u0), (a1, u1)):
            j0, j1, j2 = (row[0] - ui * a2[0]) / d, (row[1] - ui * a2[1]) / d, (row[2] - ui * a2[2]) / d
            rk = r[k]
            k += 1
            s00 += j0 * j0
            s01 += j0 * j1
            s02 += j0 * j2
            s11 += j1 * j1
            s12 += j1 * j2
            s22 += j2 * j2
            g0 += j0 * rk
            g1 += j1 * rk
            g2 += j2 * rk
    return [[s00, s01, s02], [s01, s11, s12], [s02, s12, s22]], [g0, g1, g2]


def _step(A: list, g: list, mu: float) -> list:
    """-(A + mu (1 + tr A) / 3 I)^{-1} g (:func:`tritools.model.stacked.damped_step_one` on floats)."""
    damp = mu * (1.0 + (A[0][0] + A[1][1] + A[2][2])) / 3
    A = [[A[0][0] + damp, A[0][1], A[0][2]], [A[1][0], A[1][1] + damp, A[1][2]], [A[2][0], A[2][1], A[2][2] + damp]]
    x = solve3(A, g)
    if x is None:
        x = (np.linalg.pinv(np.array(A)) @ np.array(g)).tolist()
    return [-x[0], -x[1], -x[2]]


def _lm_loop(views: list, xhat: list, X: list, at: tuple, max_iter: int = LM_MAX_ITER) -> tuple:
    """The iterations (module docstring): (X, its projection, converged)."""
    mu = 1e-3
    for _ in range(max_iter):
        A, g = _normal_equations(views, at)
        step = _step(A, g, mu)
        Xt = [X[0] + step[0], X[1] + step[1], X[2] + step[2]]
        trial = _project(views, xhat, Xt)
        better = trial is not None and math.isfinite(trial[2]) and trial[2] <= at[2]
        small = math.sqrt(step[0] * step[0] + step[1] * step[1] + step[2] * step[2]) <= \
            LM_STEP_RTOL * (1.0 + math.sqrt(X[0] * X[0] + X[1] * X[1] + X[2] * X[2]))
        if better:
            X, at = Xt, trial
        mu = max(mu / 10, 1e-12) if better else mu * 10
        stalled = mu > 1e12
        if small or stalled:
            return X, at, small and not stalled
    return X, at, False


def _gauss_newton(views: list, xhat: list, X: list, at: tuple) -> list:
    """One undamped Gauss-Newton step from X, kept iff it lowers f strictly and stays finite."""
    if not math.isfinite(at[2]):
        return X
    A, g = _normal_equations(views, at)
    step = _step(A, g, 0.0)
    Xt = [X[0] + step[0], X[1] + step[1], X[2] + step[2]]
    trial = _project(views, xhat, Xt)
    if trial is not None and math.isfinite(trial[2]) and trial[2] < at[2] and all(math.isfinite(v) for v in Xt):
        return Xt
    return X


def solve3(A: list, g: list) -> list | None:
    """x with A x = g for a 3x3 matrix (lists), Gaussian elimination with partial pivoting (LAPACK gesv's
    algorithm on plain floats, unrolled: the pivot is the first row of the largest |A[i][k]|, i >= k, and each
    elimination computes only the entries that later steps read, the same operations as the loop over whole rows,
    bit for bit, tests/test_scalar_twins.py); None for an exactly singular A (gesv's LinAlgError)."""
    r0, r1, r2 = (A[0][0], A[0][1], A[0][2], g[0]), (A[1][0], A[1][1], A[1][2], g[1]), (A[2][0], A[2][1], A[2][2], g[2])
    if abs(r1[0]) > abs(r0[0]):                             # column 0: the pivot row swapped with row 0
        if abs(r2[0]) > abs(r1[0]):
            r0, r2 = r2, r0
        else:
            r0, r1 = r1, r0
    elif abs(r2[0]) > abs(r0[0]):
        r0, r2 = r2, r0
    p0 = r0[0]
    if p0 == 0.0:
        return None
    f = r1[0] / p0
    s1 = (r1[1] - f * r0[1], r1[2] - f * r0[2], r1[3] - f * r0[3])       # rows 1, 2 from column 1 on
    f = r2[0] / p0
    s2 = (r2[1] - f * r0[1], r2[2] - f * r0[2], r2[3] - f * r0[3])
    if abs(s2[0]) > abs(s1[0]):                             # column 1
        s1, s2 = s2, s1
    if s1[0] == 0.0:
        return None
    f = s2[0] / s1[0]
    t2 = (s2[1] - f * s1[1], s2[2] - f * s1[2])                           # row 2 from column 2 on
    if t2[0] == 0.0:
        return None
    x2 = t2[1] / t2[0]
    x1 = (s1[2] - s1[1] * x2) / s1[0]
    return [(r0[3] - r0[1] * x1 - r0[2] * x2) / r0[0], x1, x2]
