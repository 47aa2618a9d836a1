"""Symmetric banded matrices over a stack, in numpy: Cholesky factorisation, triangular solves, products.

A stack of M symmetric n x n matrices of bandwidth b is stored in *lower banded* form ``ab`` (M, b + 1, n):
``ab[m, d, c] = A_m[c + d, c]`` (entries with c + d >= n are zero), the layout of LAPACK's ``?pbtrf`` and of
``scipy.linalg.solveh_banded``.  Every routine loops over the n columns with numpy operations over the stack
and the band, so M problems of one structure cost ~n small numpy calls plus O(M n b^2) flops (scipy's
routines take one matrix per call).

:func:`band_cholesky` also returns a rigorous bound of the factorisation's backward error: the computed R
satisfies A + E = R^T R with |E| <= gamma_{b+2} |R^T| |R| (Higham, *Accuracy and Stability of Numerical
Algorithms*, Thm 10.5, inner products of at most b + 1 terms), so ||E||_2 <= gamma_{b+2} ||R||_F^2 and
lambda_min(A) >= -gamma_{b+2} ||R||_F^2 whenever the factorisation succeeds (every pivot positive).

The column loops read the active deadline (:func:`sospoly.budget.check_deadline`) every :data:`DEADLINE_COLUMNS`
columns and raise :class:`sospoly.budget.TimeLimitReached` once it has passed: a factorisation of a few thousand
columns takes a sizeable share of a short time limit, and its caller treats the interrupted bound as not computed.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from ..budget import check_deadline

__all__ = ["band_from_dense", "band_cholesky", "band_solve", "band_matvec", "cholesky_backward_error"]

_U = np.finfo(float).eps / 2        # unit round-off
#: columns between two reads of the active deadline in the column loops (one clock read: ~0.1 us)
DEADLINE_COLUMNS = 32
#: stacks up to this many problems are factored and solved one by one through LAPACK (``dpbtrf`` / ``dpbtrs``,
#: ~10-50 us each); the column loop over the stack costs ~20 us per column whatever the stack (a 30-view region
#: verification: ~150 columns, 3 ms per factorisation)
LAPACK_MAX_STACK = 16

_pbtrf = sla.lapack.dpbtrf
_pbtrs = sla.lapack.dpbtrs


def band_from_dense(A: np.ndarray, b: int) -> np.ndarray:
    """Lower banded storage (M, b + 1, n) of the stack A (M, n, n) (entries outside the band ignored)."""
    M, n = A.shape[:2]
    ab = np.zeros((M, b + 1, n))
    for d in range(min(b, n - 1) + 1):
        ab[:, d, :n - d] = np.diagonal(A, offset=-d, axis1=1, axis2=2)
    return ab


def band_cholesky(ab: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R, ok): the lower Cholesky factors in banded storage (same shape as ``ab``), ``ok[m]`` False where a
    pivot was not positive and finite (that problem's factor is meaningless: NaN or inf propagate within it).
    Stacks of at most :data:`LAPACK_MAX_STACK` problems go one by one through LAPACK's ``dpbtrf`` (the same lower
    banded storage); larger ones through the column loop over the stack.  Both compute a Cholesky factor by inner
    products of at most b + 1 terms, so the backward error bound of the module docstring holds for either."""
    ab = np.asarray(ab, dtype=float)
    M, b1, n = ab.shape
    if 0 < M <= LAPACK_MAX_STACK:
        return _cholesky_lapack(ab)
    b = b1 - 1
    A = np.zeros((M, b1, n + b))
    A[:, :, :n] = ab
    for d in range(1, b1):                     # entries below the last row are not part of the matrix
        A[:, d, max(n - d, 0):n] = 0.0
    d1, d2 = np.tril_indices(b)                # the pairs of sub-diagonal offsets 1 + d1 >= 1 + d2
    rows = d1 - d2
    with np.errstate(all="ignore"):            # a failed problem's numbers may overflow: it is flagged, not used
        for j in range(n):
            if j % DEADLINE_COLUMNS == 0:
                check_deadline("factoring a banded matrix")
            ljj = np.sqrt(A[:, 0, j])              # NaN for a negative pivot, 0 for a zero one: flagged below
            A[:, 0, j] = ljj
            if b:
                col = A[:, 1:, j] / ljj[:, None]
                A[:, 1:, j] = col
                A[:, rows, j + 1 + d2] -= col[:, d1] * col[:, d2]
        R = A[:, :, :n]
        ok = np.all(np.isfinite(R), axis=(1, 2)) & np.all(R[:, 0] > 0, axis=1)
    return R, ok


def _cholesky_lapack(ab: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`band_cholesky` one problem at a time through ``dpbtrf`` (lower); a non-finite matrix or a failed
    factorisation (info != 0) is not ok."""
    M, b1, n = ab.shape
    R = np.ones_like(ab)
    ok = np.zeros(M, bool)
    for m in range(M):
        check_deadline("factoring a banded matrix")
        a = ab[m].copy()
        for d in range(1, b1):                  # entries below the last row are not part of the matrix
            a[d, max(n - d, 0):] = 0.0
        if not np.all(np.isfinite(a)):
            continue
        c, info = _pbtrf(a, lower=1)
        if info == 0 and np.all(np.isfinite(c)) and np.all(c[0] > 0):
            R[m], ok[m] = c, True
    return R, ok


def cholesky_backward_error(R: np.ndarray) -> np.ndarray:
    """A bound of ||E||_2 for A + E = R^T R (module docstring), hence of -lambda_min(A) for a successful
    factorisation, per problem: gamma_{b+2} ||R||_F^2, times 1 + gamma_{n(b+1)+1} for the rounding of the computed
    sum of squares and of gamma itself, plus n (2b + 1)(b + 3) 2^-1074 for underflow (each of the at most
    n (2b + 1) entries of E gains at most (b + 3) half-spacings of the subnormal numbers: review 17 found banded
    matrices near 1e-315 whose residual 1e-323 exceeded the bound without it)."""
    R = np.asarray(R, dtype=float)
    b1, n = R.shape[1], R.shape[2]
    k = b1 + 1
    gamma = k * _U / (1 - k * _U)
    terms = n * b1 + 1
    sum_rounding = 1.0 + terms * _U / (1 - terms * _U)
    tiny = float(n * (2 * b1 - 1) * (b1 + 2)) * 2.0 ** -1074
    return gamma * np.einsum("mdc,mdc->m", R, R) * sum_rounding * (1 + 4 * _U) + tiny


def band_solve(R: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """x with R R^T x = rhs for lower banded Cholesky factors R (M, b + 1, n) (finite, positive diagonal) and
    rhs (M, n)."""
    R, rhs = np.asarray(R, dtype=float), np.asarray(rhs, dtype=float)
    M, b1, n = R.shape
    if 0 < M <= LAPACK_MAX_STACK:
        out = np.empty((M, n))
        for m in range(M):
            check_deadline("solving a banded system")
            x, info = _pbtrs(R[m], rhs[m][:, None], lower=1)
            out[m] = x[:, 0] if info == 0 else np.nan
        return out
    b = b1 - 1
    # the rows of L: Lrow[:, j, t] = L[j, j - b + t] = R[b - t, j - b + t] (t < b; zero outside the matrix)
    Rp = np.zeros((M, b1, n + b))
    Rp[:, :, b:] = R
    t = np.arange(b)
    Lrow = Rp[:, b - t[None, :], np.arange(n)[:, None] + t[None, :]]        # (M, n, b)
    diag = R[:, 0]
    y = np.zeros((M, n + b))                    # y[:, b + c] is y_c (zero padding in front)
    for j in range(n):                          # forward: L y = rhs
        if j % DEADLINE_COLUMNS == 0:
            check_deadline("solving a banded system")
        y[:, b + j] = (rhs[:, j] - np.einsum("mt,mt->m", Lrow[:, j], y[:, j:j + b])) / diag[:, j]
    x = np.zeros((M, n + b))                    # x[:, c] is x_c (zero padding at the end)
    below = R[:, 1:]
    for j in range(n - 1, -1, -1):              # backward: L^T x = y, L[j + d, j] = R[d, j]
        if j % DEADLINE_COLUMNS == 0:
            check_deadline("solving a banded system")
        x[:, j] = (y[:, b + j] - np.einsum("md,md->m", below[:, :, j], x[:, j + 1:j + 1 + b])) / diag[:, j]
    return x[:, :n]


def band_matvec(ab: np.ndarray, v: np.ndarray) -> np.ndarray:
    """A v for the symmetric stack in lower banded storage ``ab`` (M, b + 1, n) and v (M, n)."""
    n = ab.shape[2]
    out = ab[:, 0] * v
    for d in range(1, min(ab.shape[1], n)):
        out[:, d:] += ab[:, d, :n - d] * v[:, :n - d]
        out[:, :n - d] += ab[:, d, :n - d] * v[:, d:]
    return out
