"""Rigorous bounds of the coefficient error of the projection constraints (SPEC §3, §7).

The projection constraints m2 (Theorem 1) and x~_i^T F_ij x~_j (Corollary 1) are built in floating point from
the (normalised, float) cameras.  The true projections v* of a scene point make the *exact* constraints vanish,
but the computed polynomial g~_k has coefficients off by some e_k, so g~_k(v*) = (g~_k - g_k)(v*) is not 0.  A
Positivstellensatz certificate q (f - c) = s_0 + sum_k r_k g~_k + ... then only gives, at v*,

    f(v*) >= c - margin - sum_k |r_k(v*)| |g~_k(v*)|,

and with multipliers of 1e7 (a keypoint at 1e9 px: the minors' rows nearly parallel, their determinants 1e-9
of Hadamard's bound and the unit-scaled rows correct to 1e-6 only) the last term exceeded the gap: the
"rigorous" bound c_LB was 7.77 where 1.08 is attained (wave 44's reproducer).  This module bounds, per
constraint, every coefficient's distance to one of an exact constraint's: ``|coef(g~_k) - coef(g_k)| <= E_k``
entrywise, as a polynomial with non-negative coefficients on the same monomials;
:class:`ConstraintErrors` turns them into bounds of |g~_k(v*)| on a box (``sup E_k``), which
:func:`sospoly.rigorous_psatz_bound` charges as ``sum_k sup|r_k| sup E_k`` (its ``eq_error``).

* :func:`det4`: 4 x 4 determinants by Laplace expansion along the first two rows in extended precision
  (``numpy.longdouble``; plain double where it is no wider), with the a-posteriori bound
  ``gamma_12 perm(|A|) + eps |d|`` (every term of the expansion is a product of two 2 x 2 determinants; the
  permanent of |A| bounds the sum of the absolute terms; the last term is the rounding to double).
* Theorem 1: m2 = D U2^T diag(1/n) M1 (D the unit scaling of each row, U2 the kept left singular vectors, n the row
  norms of M1), which is S2 V2^T in exact arithmetic.  Any W gives constraints W M1_exact that vanish at every
  exactly feasible b1, so with W = D U2^T diag(1/n) formed in floats, the rows are *defined* as W M1 and computed
  from the extended-precision determinants: ``E = |M2 - W M1~| + |W| dM1`` with both terms ~1e-19 relative
  (double precision left only the SVD's backward error, amplified by 1/sigma_k: up to 1e-11 per coefficient).
* Corollary 1: F_ij's exact entries are (-1)^(k+l) det[P_i without row k; P_j without row l]; the computed
  unit-norm F~ is compared with lambda F_det (lambda fitted): ``E = |F~ - lambda F_det| + |lambda| dF_det``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["det4", "minor_rows", "fundamental_errors", "EXTENDED", "MinorErrors", "EpipolarErrors",
           "ConstraintErrors"]

_EPS = float(np.finfo(float).eps)
#: whether numpy's longdouble is wider than double here (x86: 64-bit mantissa); the bounds use its own epsilon
EXTENDED = bool(np.finfo(np.longdouble).eps < np.finfo(float).eps)
_LD = np.longdouble if EXTENDED else np.float64
_EPS_LD = float(np.finfo(_LD).eps)

# (column pair of rows 0-1, complementary pair of rows 2-3, sign) of the Laplace expansion along rows 0 and 1
_PAIRS = (((0, 1), (2, 3), 1.0), ((0, 2), (1, 3), -1.0), ((0, 3), (1, 2), 1.0),
          ((1, 2), (0, 3), 1.0), ((1, 3), (0, 2), -1.0), ((2, 3), (0, 1), 1.0))


def det4(rows: np.ndarray, extended: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(d, err) for stacked 4 x 4 matrices ``rows`` (..., 4, 4): d the determinants rounded to double, err >=
    |d - det| in exact arithmetic of the given (float) entries (module docstring).  ``extended``: d is returned in
    the extended precision it was computed in (``numpy.longdouble``) and err bounds that value's error."""
    A = np.asarray(rows, float).astype(_LD)
    B = np.abs(A)
    d = np.zeros(A.shape[:-2], _LD)
    perm = np.zeros(A.shape[:-2], _LD)
    for (p, q), (r, s), sign in _PAIRS:
        top = A[..., 0, p] * A[..., 1, q] - A[..., 0, q] * A[..., 1, p]
        bot = A[..., 2, r] * A[..., 3, s] - A[..., 2, s] * A[..., 3, r]
        d += sign * top * bot
        perm += (B[..., 0, p] * B[..., 1, q] + B[..., 0, q] * B[..., 1, p]) * \
            (B[..., 2, r] * B[..., 3, s] + B[..., 2, s] * B[..., 3, r])
    with np.errstate(over="ignore"):
        # gamma_k perm(|A|) with k = 2 (2x2 minors) + 1 (their product) + 5 (the sum of six) + 1 (sign), doubled for
        # the permanent's own rounding; then the rounding to double
        err = (24 * _EPS_LD * perm).astype(float) * (1 + 1e-6)
        if extended:
            return d, err
        out = d.astype(float)
        return out, err + _EPS * np.abs(out)


def minor_rows(W: np.ndarray, M1: np.ndarray, dM1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(M2, E): the rows m2 = W M1 (``M1`` in extended precision with error bound ``dM1``) rounded to double, and
    E >= |M2 - W M1_exact| entrywise (module docstring, Theorem 1): the rounding of the extended product (gamma_n of
    |W| |M1|, the last rounding to double) and |W| dM1."""
    n = M1.shape[0]
    with np.errstate(over="ignore", invalid="ignore"):
        Wl = W.astype(_LD)
        P = Wl @ M1
        M2 = P.astype(float)
        absW = np.abs(W)
        E = (np.abs(M2.astype(_LD) - P)).astype(float) * (1 + 4 * _EPS) \
            + ((n + 4) * _EPS_LD * (np.abs(Wl) @ np.abs(M1))).astype(float) * (1 + 1e-6) \
            + (absW @ dM1) * (1 + (n + 4) * _EPS)
    return M2, np.where(np.isfinite(E), E, np.inf)


def fundamental_errors(F: np.ndarray, Pi: np.ndarray, Pj: np.ndarray) -> np.ndarray:
    """(K, 3, 3) E >= |F~ - lambda F| entrywise for the computed matrices ``F`` (K, 3, 3) of the camera pairs
    ``Pi``, ``Pj`` (K, 3, 4) and some multiple lambda F of the exact fundamental matrix of those float cameras
    (module docstring, Corollary 1); inf where the determinant form vanishes or is not finite."""
    F = np.asarray(F, float)
    K = F.shape[0]
    rows = np.empty((K, 3, 3, 4, 4))
    for k in range(3):
        ik = [a for a in range(3) if a != k]
        for m in range(3):
            jm = [b for b in range(3) if b != m]
            rows[:, k, m, :2] = Pi[:, ik]
            rows[:, k, m, 2:] = Pj[:, jm]
    D, dD = det4(rows)
    sign = np.array([[1.0, -1.0, 1.0], [-1.0, 1.0, -1.0], [1.0, -1.0, 1.0]])
    D = D * sign
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        nn = np.einsum("kab,kab->k", D, D)
        lam = np.einsum("kab,kab->k", F, D) / nn
        E = np.abs(F - lam[:, None, None] * D) * (1 + 4 * _EPS) + np.abs(lam)[:, None, None] * dD * (1 + 4 * _EPS) \
            + 4 * _EPS * np.abs(F)
    ok = np.isfinite(E).all(axis=(1, 2)) & (nn > 0)
    return np.where(ok[:, None, None], E, np.inf)


def _monomial_sup(E: np.ndarray, r: np.ndarray) -> np.ndarray:
    with np.errstate(over="ignore", invalid="ignore"):
        return np.prod(np.where(E > 0, r[None, :] ** E, 1.0), axis=1)


@dataclass(frozen=True)
class MinorErrors:
    """Theorem 1's rows ``rows`` (indices among the constraints of a list): ``coef[k]`` bounds the coefficient
    errors of row k on the monomials ``exponents`` (M, n) over all generators."""
    rows: np.ndarray
    exponents: np.ndarray
    coef: np.ndarray

    def bounds(self, r: np.ndarray) -> np.ndarray:
        with np.errstate(over="ignore", invalid="ignore"):
            b = self.coef @ _monomial_sup(self.exponents, r) if self.coef.size else np.zeros(len(self.rows))
        return np.where(np.isnan(b), np.inf, b)

    def shifted(self, offset: int) -> MinorErrors:
        return MinorErrors(self.rows + offset, self.exponents, self.coef)


@dataclass(frozen=True)
class EpipolarErrors:
    """Corollary 1's rows ``rows``: x~_i^T F x~_j with ``variables[k]`` the generators of (x_i1, x_i2, x_j1, x_j2)
    and ``E[k]`` (3, 3) the coefficient error bounds of F (so |error| <= r~_i^T E r~_j with r~ = (r_1, r_2, 1))."""
    rows: np.ndarray
    variables: np.ndarray
    E: np.ndarray

    def bounds(self, r: np.ndarray) -> np.ndarray:
        if not len(self.rows):
            return np.zeros(0)
        rv = r[self.variables]
        one = np.ones(len(rv))
        ri = np.stack([rv[:, 0], rv[:, 1], one], axis=1)
        rj = np.stack([rv[:, 2], rv[:, 3], one], axis=1)
        with np.errstate(over="ignore", invalid="ignore"):
            b = np.einsum("ka,kab,kb->k", ri, self.E, rj)
        return np.where(np.isnan(b), np.inf, b)

    def shifted(self, offset: int) -> EpipolarErrors:
        return EpipolarErrors(self.rows + offset, self.variables, self.E)


@dataclass(frozen=True)
class ConstraintErrors:
    """Coefficient error bounds of ``n`` constraints (the rows no part names are exact: bound 0)."""
    n: int
    parts: tuple = ()

    def bounds(self, radius) -> np.ndarray:
        """(n,) bounds of |g~_k(v)| at the points of the box |v_i| <= r_i (``radius`` one per generator) that satisfy
        the exact constraints (those points make g_k vanish, so what g~_k shows there is its coefficient error)."""
        r = np.asarray(radius, float)
        out = np.zeros(self.n)
        for part in self.parts:
            out[part.rows] = part.bounds(r)
        return out

    def shifted(self, offset: int, n: int) -> ConstraintErrors:
        return ConstraintErrors(n, tuple(p.shifted(offset) for p in self.parts))

    @staticmethod
    def joined(n: int, parts) -> ConstraintErrors:
        return ConstraintErrors(n, tuple(parts))
