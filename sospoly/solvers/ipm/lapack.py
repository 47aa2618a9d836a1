"""Direct LAPACK calls for the single-instance Newton solves of the interior-point method.

scipy.linalg's ``cho_factor`` / ``cho_solve`` / ``solve_triangular`` validate their arguments, look the
routine up and dispatch over batch axes on every call (~15-25 us each); the Newton solves of one small
instance (a 210 x 210 Schur complement, ten iterations, a dozen solves per iteration) spend as much in that
as in the solves.  Each function here calls the very LAPACK routine with the very arguments that the
scipy.linalg call named in its docstring makes (including its choice of storage order), so the results are
bit-identical; only the per-call checks are left out (callers pass finite 2-d float arrays of matching
shapes).
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as sla

__all__ = ["cholesky", "cho_solve", "solve_lower"]

_potrf = sla.lapack.dpotrf
_potrs = sla.lapack.dpotrs
_trtrs = sla.lapack.dtrtrs


def cholesky(a: np.ndarray, lower: bool, overwrite: bool = False) -> np.ndarray:
    """``sla.cho_factor(a, lower=lower, check_finite=False)[0]``: L with a = L L^T in the lower triangle
    (``lower``; else U = L^T in the upper one) of a Fortran-ordered array, the other triangle holding whatever
    ``a`` held there.  ``overwrite``: a Fortran-ordered ``a`` may be overwritten (no copy).  LinAlgError when
    a is not positive definite."""
    c, info = _potrf(a, lower=int(lower), overwrite_a=int(overwrite), clean=0)
    if info > 0:
        raise np.linalg.LinAlgError(f"{info}-th leading minor of the array is not positive definite")
    if info < 0:
        raise ValueError(f"illegal value in argument {-info} of potrf")
    return c


def cho_solve(c: np.ndarray, b: np.ndarray, lower: bool) -> np.ndarray:
    """``sla.cho_solve((c, lower), b, check_finite=False)``: x with L L^T x = b for the factor of
    :func:`cholesky` (``lower`` as given there)."""
    x, info = _potrs(c, b, lower=int(lower))
    if info != 0:
        raise ValueError(f"illegal value in argument {-info} of potrs")
    return x


def solve_lower(L: np.ndarray, b: np.ndarray, trans: bool = False) -> np.ndarray:
    """``sla.solve_triangular(L, b, lower=True, trans="T" if trans else "N", check_finite=False)``: x with
    L x = b (L^T x = b with ``trans``), L lower triangular.  Like scipy, a matrix that is not
    Fortran-contiguous is passed as its transpose (C order read as Fortran), an upper triangle."""
    if L.flags.f_contiguous:
        x, info = _trtrs(L, b, lower=1, trans=int(trans))
    else:
        x, info = _trtrs(L.T, b, lower=0, trans=int(not trans))
    if info > 0:
        raise np.linalg.LinAlgError(f"singular matrix: resolution failed at diagonal {info - 1}")
    if info < 0:
        raise ValueError(f"illegal value in argument {-info} of trtrs")
    return x
