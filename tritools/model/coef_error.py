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

from sospoly.analysis import monomial_sup

__all__ = ["det4", "minor_rows", "fundamental_errors", "EXTENDED", "MinorErrors", "EpipolarErrors",
           "ConstraintErrors", "ExactMatrix"]

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
        err = (24 * _EPS_LD * perm).astype(float) * (1 + 1e-6) + 5e-324        # (never rounded down to 0)
        if extended:
            return d, err
        out = d.astype(float)
        return out, err + _EPS * np.abs(out)


def minor_rows(W: np.ndarray, M1: np.ndarray, dM1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(M2, E): the rows m2 = W M1 (``M1`` in extended precision with error bound ``dM1``) rounded to double, and
    E >= |M2 - W M1_exact| entrywise (module docstring, Theorem 1): the rounding of the extended product (gamma_n of
    |W| |M1|, the last rounding to double) and |W| dM1."""
    n = M1.shape[0]
    absW = np.abs(W)
    with np.errstate(over="ignore", invalid="ignore"):
        if W.shape[0] * n * M1.shape[1] <= EXTENDED_PRODUCT_MAX:
            P = W.astype(_LD) @ M1
            M2 = P.astype(float)
            E = (np.abs(M2.astype(_LD) - P)).astype(float) * (1 + 4 * _EPS) \
                + (n + 4) * _EPS_LD * (absW @ np.abs(M1).astype(float)) * (1 + (n + 4) * _EPS)
        else:                       # numpy's extended product has no BLAS: seconds at eight views; double instead
            M1d = M1.astype(float)
            lost = np.abs((M1 - M1d.astype(_LD)).astype(float))       # what rounding M1 to double dropped
            M2 = W @ M1d
            E = ((n + 4) * _EPS * (absW @ (np.abs(M1d) + lost)) + absW @ lost) * (1 + (n + 8) * _EPS)
        E = E + (absW @ dM1) * (1 + (n + 4) * _EPS) + 5e-324
    return M2, np.where(np.isfinite(E), E, np.inf)


#: the largest W @ M1 (rows x inner x columns) formed in extended precision (~0.3 s); beyond, in double with its bound
EXTENDED_PRODUCT_MAX = 2e7


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


@dataclass(frozen=True)
class MinorErrors:
    """Theorem 1's rows ``rows`` (indices among the constraints of a list): ``coef[k]`` bounds the coefficient
    errors of row k on the monomials ``exponents`` (M, n) over all generators."""
    rows: np.ndarray
    exponents: np.ndarray
    coef: np.ndarray

    def bounds(self, r: np.ndarray) -> np.ndarray:
        with np.errstate(over="ignore", invalid="ignore"):
            b = self.coef @ monomial_sup(self.exponents, r) if self.coef.size else np.zeros(len(self.rows))
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
        r = np.abs(np.asarray(radius, float))
        out = np.zeros(self.n)
        for part in self.parts:
            out[part.rows] = part.bounds(r)
        return out



def _dyadic(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(integer mantissas, exponents) with A = m * 2**e exactly (int64 mantissas of 53 bits; 0 for zeros)."""
    m, e = np.frexp(np.asarray(A, float))
    return (m * 2.0 ** 53).astype(np.int64), e.astype(np.int64) - 53


def _exact_det(a: list, shift: int) -> tuple[int, int]:
    """det of the 4 x 4 integer matrix ``a`` (rows of Python integers) times 2**shift exactly, by Laplace's
    expansion: (integer, exponent)."""
    d = 0
    for (p, q), (r, s), sign in _PAIRS:
        d += int(sign) * (a[0][p] * a[1][q] - a[0][q] * a[1][p]) * (a[2][r] * a[3][s] - a[2][s] * a[3][r])
    return d, shift


def _integer_rows(A: np.ndarray) -> tuple[list, list]:
    """Matrices (T, R, C) of floats as integer rows: A[t, r] = ints[t][r] * 2**e[t, r] exactly, each row brought to
    the smallest exponent of its non-zero entries; returns (ints as nested lists, per-matrix exponent sums)."""
    if A.size == 0:
        return [[[] for _ in range(A.shape[1])] for _ in range(A.shape[0])], [0] * A.shape[0]
    mi, ex = _dyadic(A)
    big = np.iinfo(np.int64).max
    e0 = np.where(mi != 0, ex, big).min(axis=2)
    e0 = np.where(e0 == big, 0, e0)
    sh = np.where(mi != 0, ex - e0[..., None], 0).tolist()
    mil = mi.tolist()
    ints = [[[m << k for m, k in zip(mr, sr)] for mr, sr in zip(mt, st)] for mt, st in zip(mil, sh)]
    return ints, e0.sum(axis=1).tolist()


def _rounded(num: int, exp: int) -> tuple[float, float]:
    """(num * 2**exp rounded to the nearest double, a bound of that rounding's error); inf where it overflows."""
    if num == 0:
        return 0.0, 0.0
    try:
        val = float(num << exp) if exp >= 0 else num / (1 << -exp)      # (int true division: correctly rounded)
    except OverflowError:
        return (np.inf if num > 0 else -np.inf), np.inf
    p, q = val.as_integer_ratio()                                       # q a power of two
    k = max(q.bit_length() - 1, -exp, 0)
    diff = abs((p << (k - (q.bit_length() - 1))) - (num << (k + exp)))  # |val - exact| * 2**k, exactly
    return val, (diff / (1 << k)) * (1 + 4 * _EPS) + 5e-324


class ExactMatrix:
    """A matrix of exact dyadic rationals ``num * 2**exp`` (Python integers), for Theorem 1's minors of few views."""

    def __init__(self, num: list, exp: list, shape: tuple):
        self.num, self.exp, self.shape = num, exp, shape

    @classmethod
    def of_terms(cls, rows: np.ndarray, live: np.ndarray, minor: np.ndarray, mono: np.ndarray, shape: tuple):
        """Entry (minor[t], mono[t]) = det(rows[t]) exactly for the ``live`` terms (one term per entry)."""
        num = [[0] * shape[1] for _ in range(shape[0])]
        exp = [[0] * shape[1] for _ in range(shape[0])]
        idx = np.flatnonzero(live)
        ints, shifts = _integer_rows(rows[idx])
        for k, t in enumerate(idx):
            d, e = _exact_det(ints[k], shifts[k])
            if d:
                i, j = int(minor[t]), int(mono[t])
                if num[i][j]:                   # (never in Theorem 1's structure; exact all the same)
                    e0 = min(e, exp[i][j])
                    d = (d << (e - e0)) + (num[i][j] << (exp[i][j] - e0))
                    e = e0
                num[i][j], exp[i][j] = d, e
        return cls(num, exp, shape)

    def columns(self, idx) -> ExactMatrix:
        idx = [int(j) for j in idx]
        return ExactMatrix([[row[j] for j in idx] for row in self.num], [[row[j] for j in idx] for row in self.exp],
                           (self.shape[0], len(idx)))

    def rows(self, keep) -> ExactMatrix:
        idx = np.flatnonzero(keep)
        return ExactMatrix([self.num[i] for i in idx], [self.exp[i] for i in idx], (len(idx), self.shape[1]))

    def times(self, W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(M2, E): W @ self in exact arithmetic, rounded to the nearest doubles, and bounds of that rounding."""
        W = np.asarray(W, float)
        n2, n = W.shape
        cols = self.shape[1]
        if not (n2 and n and cols):
            return np.zeros((n2, cols)), np.zeros((n2, cols))
        ints, _ = _integer_rows(W[None])
        Wi = ints[0]
        mi, ex = _dyadic(W)
        big = np.iinfo(np.int64).max
        Wexp = np.where(mi != 0, ex, big).min(axis=1)
        Wexp = np.where(Wexp == big, 0, Wexp).tolist()
        M2, E = np.zeros((n2, cols)), np.zeros((n2, cols))
        for m in range(cols):
            live = [j for j in range(n) if self.num[j][m]]
            if not live:
                continue
            e0 = min(self.exp[j][m] for j in live)
            D = [(j, self.num[j][m] << (self.exp[j][m] - e0)) for j in live]
            for k in range(n2):
                row = Wi[k]
                M2[k, m], E[k, m] = _rounded(sum(row[j] * d for j, d in D), Wexp[k] + e0)
        return M2, E
