"""Unconstrained polynomials that are unbounded below, recognised before any SDP is solved.

An SOS solver works to a tolerance: for ``f = x^2 - 1e-6 x y`` (indefinite, unbounded below) the
program ``max c : f - c SOS`` is infeasible only by ~1e-13, below the solver's tolerance, and a
"certified" finite lower bound was reported.  :func:`recession_direction` finds, for an unconstrained
``f``, a direction ``d`` with ``f(t d) -> -inf`` when one of these certainly exists:

* ``deg f`` odd: the top-degree form ``f_top`` is odd, so ``f_top(-d) = -f_top(d) < 0`` for some ``d``
  (the coordinate axes and a few fixed directions are tried);
* ``deg f = 2``, ``f = x' Q x + b' x + c``: ``Q`` has an eigenvalue below ``-tol`` (``tol`` =
  :data:`EIG_RTOL` ``* n * ||Q||``: beyond the rounding of the eigen-decomposition), or ``Q`` is positive
  semidefinite with eigenvalues within ``tol`` of zero along which ``b`` has a component
  (``f(-t N N' b) = -t ||N'b||^2 + O(tol t^2)``) and the exact test :func:`exactly_unbounded` on the float data
  confirms it (up to ``EXACT_MAX_VARS`` variables; beyond, no claim);
* ``deg f`` even ``> 2``: ``f_top`` is negative at one of the tried directions, or at a local minimiser
  of ``f_top`` on the unit sphere started from the three best (a sufficient test only).

Each direction is confirmed by evaluating ``f_top(d) < 0`` (or the linear decrease) before it is
returned.  ``None`` means no such direction was found, not that ``f`` is bounded below.
"""
from __future__ import annotations

import numpy as np

from ..algebra.polynomial import Polynomial

__all__ = ["recession_direction", "unbounded_result", "exactly_unbounded", "EIG_RTOL", "EXACT_MAX_VARS",
           "LOCAL_SEARCH_MAX_VARS", "MAX_TRIAL_ENTRIES"]

#: eigenvalues of the quadratic part within ``EIG_RTOL * n * ||Q||`` of zero are treated as zero.
EIG_RTOL = 64 * float(np.finfo(float).eps)
#: above this many variables only the fixed trial directions are tried for degrees above 2 (no local search).
LOCAL_SEARCH_MAX_VARS = 40
#: work bound of the test (floats): trial directions x top-form entries (the check stays well below a second).
MAX_TRIAL_ENTRIES = 20_000_000
#: floats per evaluation block of the top form.
MAX_EVAL_ENTRIES = 4_000_000


def _split(f: Polynomial) -> tuple[np.ndarray, np.ndarray, int]:
    E, c = f.exponents(), f.coefficients()
    deg = E.sum(axis=1)
    return E, c, int(deg.max()) if len(deg) else 0


class _TopForm:
    """The top-degree form of f, evaluated at many directions at once: each term has at most ``top``
    variables, so a term is a product of ``top`` padded factors ``d[col] ** pow`` (pow 0 -> 1)."""

    def __init__(self, E: np.ndarray, c: np.ndarray, top: int):
        rows = E.sum(axis=1) == top
        E, self.coef = E[rows], c[rows]
        order = np.argsort(-E, axis=1, kind="stable")[:, :top]       # a term's (at most top) variables first
        self.cols = order
        self.pows = np.take_along_axis(E, order, axis=1)
        self.top = top

    def __call__(self, D: np.ndarray) -> np.ndarray:
        """Values at the rows of ``D`` (K, n), in blocks bounding memory to ~MAX_EVAL_ENTRIES floats."""
        D = np.atleast_2d(np.asarray(D, float))
        out = np.empty(len(D))
        step = max(1, MAX_EVAL_ENTRIES // max(1, self.cols.size))
        for k in range(0, len(D), step):
            V = D[k:k + step][:, self.cols] ** self.pows[None]
            out[k:k + step] = np.prod(V, axis=2) @ self.coef
        return out


def _trial_directions(n: int, budget: int) -> np.ndarray:
    rng = np.random.default_rng(0)
    eye = np.eye(n)
    D = np.vstack([eye, -eye, rng.standard_normal((min(4 * n, 64), n))])
    return D[:max(2, budget)]


def _quadratic(E: np.ndarray, c: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    Q, b = np.zeros((n, n)), np.zeros(n)
    for e, v in zip(E, c):
        nz = np.flatnonzero(e)
        if e.sum() == 2:
            i, j = (nz[0], nz[0]) if len(nz) == 1 else (nz[0], nz[1])
            Q[i, j] += v / (1.0 if i == j else 2.0)
            Q[j, i] = Q[i, j]
        elif e.sum() == 1:
            b[nz[0]] += v
    return Q, b


def _quadratic_direction(E, c, n) -> np.ndarray | None:
    Q, b = _quadratic(E, c, n)
    lam, V = np.linalg.eigh(Q)
    tol = EIG_RTOL * n * max(float(np.max(np.abs(lam))), 0.0)
    if lam[0] < -tol:
        return V[:, 0]
    null = V[:, np.abs(lam) <= tol]
    if null.shape[1]:
        d = -null @ (null.T @ b)
        if float(b @ d) < -EIG_RTOL * n * float(np.linalg.norm(b)) * float(np.linalg.norm(d)) and np.any(d) \
                and n <= EXACT_MAX_VARS and exactly_unbounded(Q, b):
            return d / np.linalg.norm(d)
    return None


#: :func:`exactly_unbounded` decides quadratics of at most this many variables (rational elimination, O(n^3)).
EXACT_MAX_VARS = 40


def exactly_unbounded(Q: np.ndarray, b: np.ndarray) -> bool:
    """Is x' Q x + b' x unbounded below, decided exactly on the float data (rational arithmetic)?  True iff Q is not
    positive semidefinite, or it is and b is not in its range: symmetric elimination with the largest remaining
    diagonal as pivot, completing the square (a zero pivot needs its row zero and its linear coefficient zero).
    Eigenvalues within round-off of zero decide nothing: 1e-40 x^2 + 1e40 y^2 + x + y has a computed eigenvalue
    1e-40 << EIG_RTOL ||Q|| but its minimum -2.5e39 is an ordinary float (review 38a M1: it was called unbounded)."""
    from fractions import Fraction

    A = [[Fraction(float(v)) for v in row] for row in Q]
    r = [Fraction(float(v)) for v in b]
    rest = list(range(len(r)))
    while rest:
        k = max(rest, key=lambda i: A[i][i])
        rest.remove(k)
        p = A[k][k]
        if p < 0:
            return True
        if p == 0:
            if any(A[k][j] != 0 for j in rest) or r[k] != 0:
                return True                 # not PSD (a zero diagonal with a non-zero row), or b off the range
            continue
        for i in rest:
            m = A[i][k] / p
            if m:
                for j in rest:
                    A[i][j] -= m * A[k][j]
                r[i] -= m * r[k]
    return False


def recession_direction(f: Polynomial, eq=(), ineq=()) -> np.ndarray | None:
    """A unit direction along which the unconstrained ``f`` decreases to ``-inf`` (module docstring),
    or None (also whenever there are constraints: the feasible set may be bounded)."""
    if eq or ineq or f.nvars == 0:
        return None
    E, c, top = _split(f)
    n = f.nvars
    if top == 0:
        return None
    if top == 2:
        return _quadratic_direction(E, c, n)
    floor = EIG_RTOL * float(np.max(np.abs(c)))
    form = _TopForm(E, c, top)
    cost = max(1, form.cols.size)                    # entries per evaluation
    D = _trial_directions(n, MAX_TRIAL_ENTRIES // cost)
    D = D / np.linalg.norm(D, axis=1, keepdims=True)
    values = form(D)
    if n <= LOCAL_SEARCH_MAX_VARS and cost * n <= MAX_TRIAL_ENTRIES // 200:
        starts = D[np.argsort(values)[:3]]
        found = np.array([_descend(lambda d: float(form(d / np.linalg.norm(d))[0]), d) for d in starts])
        D = np.vstack([found / np.linalg.norm(found, axis=1, keepdims=True), D])
        values = np.concatenate([form(D[:len(found)]), values])
    bad = np.flatnonzero(values < -floor * np.sum(np.abs(D), axis=1) ** top)
    return D[bad[0]] if bad.size else None


def _descend(fun, d0: np.ndarray) -> np.ndarray:
    """A local minimiser of ``fun`` (the top form on the unit sphere) from ``d0`` (a few BFGS steps)."""
    from scipy.optimize import minimize as local_min

    res = local_min(fun, d0, method="BFGS", options={"maxiter": 50})
    return res.x if np.all(np.isfinite(res.x)) and np.any(res.x) else d0


def unbounded_result(fn, eqn, ineqn, gens, degree, fscale, seconds):
    """:func:`sospoly.minimize`'s result when the unconstrained ``fn`` has a direction of decrease to -inf:
    status ``infeasible`` (no lower bound at any degree), the direction in the message; else None."""
    from ..minimize import MinimizeResult
    from ..status import SolveStatus

    d = recession_direction(fn, eqn, ineqn)
    if d is None:
        return None
    msg = (f"f is unbounded below: f(t*d) -> -inf as t -> inf along d = {np.round(d, 6).tolist()} "
           f"(or bounded only far beyond floating-point resolution); no lower bound exists")
    return MinimizeResult(SolveStatus.INFEASIBLE, None, None, (), False, 0, degree, "-", gens, message=msg,
                          sparsity="-", scale=fscale, seconds=seconds)
