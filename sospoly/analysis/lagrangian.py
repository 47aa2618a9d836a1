"""The best degree-2 certificate of a quadratic program without an SDP: ascent on the Lagrangian dual.

For a quadratic f and quadratic equalities g_k (no inequalities), the degree-2 Positivstellensatz certificate with
q = 1 is u(v) = f(v) - c + lambda^T g(v) SOS with constant multipliers lambda (:mod:`sospoly.analysis.verify`), and
its SDP is the Lagrangian dual

    max_lambda d(lambda),   d(lambda) = min_v L(v, lambda),   L = f + lambda^T g = L0 + L1.v + v^T L2 v.

Where L2(lambda) is positive definite the inner minimum is attained at w = -(2 L2)^-1 L1 and

    d = L0 + L1.w / 2,   grad d = g(w),   Hessian of d = -J^T (2 L2)^-1 J,   J = [grad g_k(w)]_k,

so d is concave and smooth on that open set (Danskin).  Damped Newton steps on d + mu log det L2 (the set's
barrier) for mu falling tenfold once each weight's iterates are centred climb towards the SDP's value, stopping
at any ``target`` below it and giving up on one above it (:func:`out_of_reach`, the barrier's own gap bound), with
n x n Cholesky factorisations only (tens of microseconds each; an interior-point
solve of the same SDP costs ~10 iterations of a solver's set-up).  The supremum may lie on the boundary of the PD
set and be approached slowly (the "hard case"); within ``max_iter`` steps the ascent then ends below it: a valid,
weaker bound (tests/test_lagrangian_ascent.py compares with the SDP solved by Clarabel).  Verification at a
candidate (:func:`sospoly.analysis.verify.verify_quadratic_batch`) reads lambda from the candidate's KKT
conditions: the certificate when the relaxation is tight there; the ascent starts from those multipliers and
finds the best bound the degree-2 certificate gives when it is not (a bound below the optimum that may still
exceed a level a caller needs: a branch-and-bound prunes with it).

The multipliers found are only a proposal: the bound reported is computed from them by
:func:`sospoly.analysis.verify.bound_at_one` from the exact data, with its rigorous margin (PSD defect and
stationarity residual on the ball of the given radius), never from the ascent's own arithmetic.
"""
from __future__ import annotations

import numpy as np

from ..solvers.ipm.lapack import cho_solve, cholesky, solve_lower
from .verify import SparseQuadratics

__all__ = ["ascend_one", "out_of_reach", "ASCENT_MAX_ITER", "ASCENT_RTOL", "GIVE_UP_MARGIN"]

#: Newton iterations of :func:`ascend_one` at most (over all barrier weights)
ASCENT_MAX_ITER = 80
#: stop when an iteration raises d by less than this fraction of |d|
ASCENT_RTOL = 1e-12
#: halvings of a step in the line search before the ascent stops
_BACKTRACKS = 40


def _dense(G2: SparseQuadratics, K: int, n: int) -> np.ndarray:
    """(K, n, n) G2 of the first program of a sparse stack."""
    out = np.zeros((K, n, n))
    np.add.at(out, (G2.k, G2.i, G2.j), G2.vals[0])
    return out


def _value(F2, f1, f0, g0, g1, G2d, lam):
    """(d(lambda), w, Cholesky factor R of L2 (lower triangle; L2 = R R^T)) where L2(lambda) is positive definite,
    else (-inf, None, None)."""
    L2 = F2 + np.tensordot(lam, G2d, axes=1)
    if not np.isfinite(L2).all():
        return -np.inf, None, None
    try:
        R = cholesky(np.asfortranarray(L2), lower=True, overwrite=True)
    except np.linalg.LinAlgError:
        return -np.inf, None, None
    L1 = f1 + lam @ g1
    w = -0.5 * cho_solve(R, L1, lower=True)
    d = f0 + lam @ g0 + 0.5 * float(L1 @ w)
    return (d, w, R) if np.isfinite(d) else (-np.inf, None, None)


def _feasible_start(F2, f1, f0, g0, g1, G2d, lam0):
    """The first of lam0, lam0 / 2, lam0 / 4, ..., 0 where L2 is positive definite, with its value; None."""
    t = 1.0
    for _ in range(_BACKTRACKS):
        lam = t * lam0
        d, w, R = _value(F2, f1, f0, g0, g1, G2d, lam)
        if R is not None:
            return lam, d, w, R
        t *= 0.5
    lam = np.zeros_like(lam0)
    d, w, R = _value(F2, f1, f0, g0, g1, G2d, lam)
    return (lam, d, w, R) if R is not None else None


def _log_det(R) -> float:
    """log det L2 from its Cholesky factor."""
    return 2.0 * float(np.sum(np.log(np.diagonal(R))))


def _barrier_terms(R, G2d):
    """(t (K,), T (K, K)): t_k = tr(L2^-1 G2_k) and T_kl = tr(L2^-1 G2_k L2^-1 G2_l) with L2 = R R^T, the gradient
    and (minus) the Hessian of log det L2(lambda)."""
    K, n = G2d.shape[:2]
    B = solve_lower(R, np.ascontiguousarray(G2d.transpose(1, 0, 2)).reshape(n, K * n))    # [R^-1 G2_k]_k
    Bt = np.ascontiguousarray(B.reshape(n, K, n).transpose(2, 1, 0)).reshape(n, K * n)   # [(R^-1 G2_k)^T]_k
    A = solve_lower(R, Bt).reshape(n, K, n).transpose(1, 0, 2)          # R^-1 G2_k R^-T (symmetric)
    return np.einsum("kaa->k", A), np.einsum("kab,lab->kl", A, A)


def ascend_one(f0: float, f1, F2, g0, g1, G2: SparseQuadratics, lam0, *, target: float | None = None,
               max_iter: int = ASCENT_MAX_ITER) -> tuple[np.ndarray, float] | None:
    """Multipliers lambda (K,) raising the Lagrangian dual d(lambda) of one program (module docstring) from ``lam0``
    (e.g. the KKT multipliers of a candidate), and the ascent's own d there (a float estimate: the caller's bound
    is :func:`sospoly.analysis.verify.bound_at_one` at these multipliers); it stops once d >= ``target``.  The
    program as in :func:`sospoly.analysis.verify.verify_quadratic_batch` for M = 1: f0 float, f1 (n,), F2 (n, n),
    g0 (K,), g1 (K, n), G2 a :class:`~sospoly.analysis.verify.SparseQuadratics` of one program.  None when no
    multipliers on the segment from lam0 to 0 make L2 positive definite.

    Newton's method on d + mu log det L2 for mu falling tenfold per round (the maximum of d often lies on the
    boundary of the positive definite set, where plain Newton steps are cut to nothing): the barrier's maximiser
    is within n mu of the dual's value; ``max_iter`` Newton steps in all.  Where the ascent from ``lam0`` ends below
    ``target``, a second one from lambda = 0 (when L2(0) is positive definite), the better kept: a start on the
    segment from lam0 to 0 next to the boundary of the positive definite set can stall at once (no Newton step
    raises the barrier function there) and give up below a dual supremum that passes the target (measured on
    robust five-view subsets holding a wrong match: the KKT start stuck at d = -6.7 and 0.048, the zero start
    reached 1.59 and 0.30 against targets 0.52 and 0.29)."""
    f0 = float(f0)
    f1, F2 = np.asarray(f1, float), np.asarray(F2, float)
    g0, g1 = np.asarray(g0, float), np.asarray(g1, float)
    K, n = g1.shape
    G2d = _dense(G2, K, n)
    lam0 = np.asarray(lam0, float)
    data = (F2, f1, f0, g0, g1, G2d)
    best = _ascend_from(data, lam0, target, max_iter)
    if target is not None and (best is None or best[1] < target) and np.any(lam0 != 0):
        again = _ascend_from(data, np.zeros_like(lam0), target, max_iter)     # (module docstring: a second start)
        if again is not None and (best is None or again[1] > best[1]):
            best = again
    return best


def _ascend_from(data: tuple, lam0: np.ndarray, target: float | None, max_iter: int):
    """:func:`ascend_one` from one start (the first positive definite point of the segment from ``lam0`` to 0):
    (lambda, d) or None."""
    F2, f1, f0, g0, g1, G2d = data
    n = len(f1)
    start = _feasible_start(F2, f1, f0, g0, g1, G2d, lam0)
    if start is None:
        return None
    lam, d, w, R = start
    best = (lam, d)
    mu = _BARRIER_START * max(1.0, abs(d)) / n
    steps = 0
    while steps < max_iter:
        if target is not None and best[1] >= target:
            break
        centred = False
        for _ in range(_STEPS_PER_ROUND):
            steps += 1
            moved = _newton_step(F2, f1, f0, g0, g1, G2d, lam, d, w, R, mu)
            if moved is None:
                centred = True                           # no step raises phi: its maximiser for this mu
                break
            lam, d, w, R, decrement = moved
            if d > best[1]:
                best = (lam, d)
            if (target is not None and d >= target) or steps >= max_iter:
                break
            if decrement <= _CENTRED * mu:
                centred = True                           # (centred for this mu: the next, smaller one)
                break
        if centred and target is not None and out_of_reach(d, mu, n, target):
            break
        if n * mu <= ASCENT_RTOL * max(1.0, abs(best[1])):
            break
        mu *= 0.1
    return best[0], float(best[1])


def out_of_reach(d: float, mu: float, n: int, target: float) -> bool:
    """Is ``target`` above the dual's supremum, judged at a centred iterate of barrier weight ``mu``?  The barrier
    problem max d + mu log det L2 is, up to a constant, the standard one of the SDP max {t : [[L0 - t, L1^T / 2],
    [L1 / 2, L2]] PSD} (its t-part is maximised at t = d - mu), whose central point of weight mu has a gap of at
    most (n + 1) mu: sup d <= d(lambda_mu) + n mu.  An iterate centred to a Newton decrement of
    :data:`_CENTRED` mu is not the central point, so the test keeps :data:`GIVE_UP_MARGIN` times that gap.  Only
    ends the ascent early (no bound is read from it): a wrong call costs the caller's next step, never a bound."""
    return d + GIVE_UP_MARGIN * n * mu < target


#: :func:`out_of_reach` asks the target to exceed a centred iterate's d by this many times the central gap n mu
GIVE_UP_MARGIN = 4.0


#: the first barrier weight, relative to max(1, |d|) / n at the start
_BARRIER_START = 1e-2
#: Newton steps per barrier weight at most
_STEPS_PER_ROUND = 20
#: a weight's Newton iterations stop once the Newton decrement g^T H^-1 g is at most this many times mu (near its
#: barrier's maximiser: lowering mu before that leaves the iterates against the boundary, where steps are cut)
_CENTRED = 0.25


def _newton_step(F2, f1, f0, g0, g1, G2d, lam, d, w, R, mu):
    """One damped Newton step on phi = d + mu log det L2 from lam (backtracking while L2 is positive definite and
    phi rises): (lam, d, w, R, Newton decrement at lam) after it, or None when no step raises phi (converged for
    this mu)."""
    K = len(g0)
    grad = g0 + g1 @ w + np.einsum("i,kij,j->k", w, G2d, w)              # grad d = g(w)
    J = g1 + 2.0 * np.einsum("kij,j->ki", G2d, w)                         # rows: grad g_k(w)
    Y = solve_lower(R, np.ascontiguousarray(J.T))                       # J (2 L2)^-1 J^T = Y^T Y / 2
    t, T = _barrier_terms(R, G2d)
    H = 0.5 * (Y.T @ Y) + mu * T                                          # minus the Hessian of phi
    g = grad + mu * t
    try:
        step = np.linalg.solve(H + 1e-14 * max(np.trace(H), 1e-300) * np.eye(K), g)
    except np.linalg.LinAlgError:
        return None
    phi = d + mu * _log_det(R)
    a = 1.0
    for _ in range(_BACKTRACKS):
        dn, wn, Rn = _value(F2, f1, f0, g0, g1, G2d, lam + a * step)
        if Rn is not None and dn + mu * _log_det(Rn) > phi:
            return lam + a * step, dn, wn, Rn, float(g @ step)
        a *= 0.5
    return None
