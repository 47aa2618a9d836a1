"""Fundamental matrices from the cameras' 4 x 4 determinants, with a proven error bound.

The exact fundamental matrix of two float cameras P_i, P_j (x_i^T F_ij x_j = 0 at the projections of any point,
SPEC §7) has the entries D_kl = (-1)^(k+l) det[P_i without row k; P_j without row l].  By a Laplace expansion of each
determinant along its first two rows, D_kl = sum_c s_c m_i(k, c) m_j(l, c') from the 2 x 2 minors m(k, c) of each
camera's two rows other than k on the column pair c (c' its complement, s_c its sign): 18 minors per camera, shared
by every pair that holds it (:func:`determinant_form`, in double or in numpy's longdouble: 64-bit mantissa on x86).

Error (u' the unit round-off of the type the minors are formed in, u the double's): each minor errs by at most
gamma_2 of its absolute form mhat = |a_p b_q| + |a_q b_p|, so |D~ - D| <= dD = 16 u' sum_c mhat_i mhat_j (the
products, the six-term sum in any order and its rounding, generously; the sum of non-negative terms formed in the
same type and rounded up by (1 + 32 u)).

:func:`fundamental_determinants` returns F = fl(D~ / ||D~||) itself, the minors in double, each camera first divided
by a power of two near its largest entry (exact: D scales by a power of two, which the normalisation removes; nothing
overflows).  For the exact number lambda = 1 / ||D~||_computed,

    |F - lambda D| <= |F - lambda D~| + lambda |D~ - D| <= 3 u (1 + 4 u) |F| + dD / ||D~|| (1 + 8 u) + eta

entrywise (eta = 5e-324: an entry rounded into the subnormals; the minors' products in double assume no
underflow, so a camera with an entry below ``UNDERFLOW_SAFE`` of its largest takes longdouble's wider exponent range,
or no pair where the platform's longdouble is double), whose Frobenius norm, rounded up, is the bound e_F
returned beside F: the ``proven`` error of :func:`tritools.model.epipolar_data.epipolar_errors`.  On normalised
cameras e_F is ~5e-15..2e-14, where the pseudo-inverse form F = [e]_x P_i P_j^+ used before wave 49 erred by up to
~800 x 16 ulps (wave 47) and needed a second, longdouble determinant pass to bound it.
:func:`tritools.model.epipolar_data.fundamental_bounds` bounds any other F against the same determinants in longdouble.
"""
from __future__ import annotations

import numpy as np

from sospoly import pow2_above_array

__all__ = ["determinant_form", "fundamental_determinants", "UNDERFLOW_SAFE"]

_U = 2.0 ** -53
_LD = np.longdouble
#: the 2 x 2 column pairs (p, q) of a Laplace expansion of a 4 x 4 determinant along its first two rows, in the order
#: whose complements are the same list reversed, and their signs
_COLUMN_PAIRS = ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))
_PAIR_SIGNS = np.array([1.0, -1.0, 1.0, 1.0, -1.0, 1.0])
_ENTRY_SIGNS = np.array([[1.0, -1.0, 1.0], [-1.0, 1.0, -1.0], [1.0, -1.0, 1.0]])
_OTHER_ROWS = ((1, 2), (0, 2), (0, 1))
# flat indices (row * 4 + column) of the entries a_p, b_q, a_q, b_p of the minor a_p b_q - a_q b_p of rows (a, b) =
# _OTHER_ROWS[k] on the column pair _COLUMN_PAIRS[c], as (3, 6) arrays
_R1P, _R2Q, _R1Q, _R2P = (np.array([[4 * rows[ra] + cols[cb] for cols in _COLUMN_PAIRS] for rows in _OTHER_ROWS])
                          for ra, cb in ((0, 0), (1, 1), (0, 1), (1, 0)))


def determinant_form(C: np.ndarray, I: np.ndarray, J: np.ndarray, dtype=_LD) -> tuple[np.ndarray, np.ndarray]:
    """(D~, dD) (M, K, 3, 3), both in ``dtype`` (longdouble or float64): the determinants of the exact fundamental
    matrices D of the float cameras C (M, N, 3, 4) for the pairs (I, J) and bounds of |D~ - D| (module docstring, u'
    the unit round-off of ``dtype``, any order of the six-term sums; the cameras as given, no scaling)."""
    u = float(np.finfo(dtype).eps) / 2
    with np.errstate(over="ignore", invalid="ignore"):
        s = C.reshape(C.shape[:2] + (12,)).astype(dtype)      # the 2 x 2 minors of every camera at once
        ps, qs = s[..., _R1P] * s[..., _R2Q], s[..., _R1Q] * s[..., _R2P]
        m, mh = ps - qs, np.abs(ps) + np.abs(qs)              # (M, N, 3, 6)
        D = _pair_products(m * _PAIR_SIGNS, m[..., ::-1], I, J) * _ENTRY_SIGNS
        perm = _pair_products(mh, mh[..., ::-1], I, J)        # (its own rounding: within (1 + 8 u'))
        return D, 16 * u * perm * (1 + 32 * _U)


def _pair_products(A: np.ndarray, B: np.ndarray, I: np.ndarray, J: np.ndarray) -> np.ndarray:
    """(M, K, 3, 3) sum_c A[:, I_k, a, c] B[:, J_k, b, c] for A, B (M, N, 3, 6): where the pairs are at least half of
    all, one (3N x 6) (6 x 3N) product per problem and the pairs' blocks taken from it (a matrix product of
    doubles runs in BLAS: 16 us against 55 us of an einsum at N = 10), else a product per pair."""
    M, N = A.shape[:2]
    if 4 * len(I) >= N * (N - 1):
        full = A.reshape(M, 3 * N, 6) @ np.swapaxes(B.reshape(M, 3 * N, 6), 1, 2)
        return np.swapaxes(full.reshape(M, N, 3, N, 3), 2, 3)[:, I, J]
    return A[:, I] @ np.swapaxes(B[:, J], -1, -2)


def fundamental_determinants(C: np.ndarray, I: np.ndarray, J: np.ndarray
                             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(F (M, K, 3, 3) of unit Frobenius norm, ok (M, K), e_F (M, K)) for the cameras C (M, N, 3, 4) and the pairs
    (I, J): F = D~ / ||D~|| of the module docstring, ``ok`` where that and its bound are finite and D~ does not
    vanish (else F = 0, e_F = inf), e_F the proven bound of ||F - lambda D||_F for the exact D of the float
    cameras and some lambda.  The determinants in double (:func:`determinant_form`): 16 u' = 16 u there, so e_F ~
    2e-15 times the pairs' ratio sum_c mhat_i mhat_j / |D| (1.5-9 on normalised cameras).  A problem with a camera
    entry below ``UNDERFLOW_SAFE`` of its camera's largest (a product of four such entries could leave the doubles'
    normal range, where the relative error analysis fails) takes numpy's longdouble where its exponent range is
    wider, else gets no pair (ok False)."""
    C = np.asarray(C, float)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore", under="ignore"):
        top = np.maximum.reduce(np.abs(C).reshape(C.shape[:2] + (12,)), axis=-1)
        S = C / pow2_above_array(top)[..., None, None]         # exact (a power of two per camera)
        A = np.abs(S)
        low = ((A > 0) & (A < UNDERFLOW_SAFE)).any(axis=(1, 2, 3))
        F, ok, e = _normalised(S, I, J, np.float64)
        if low.any():
            if np.finfo(_LD).minexp < -2000:         # (an exponent range beyond the doubles's)
                F[low], ok[low], e[low] = _normalised(S[low], I, J, _LD)
            else:
                ok[low] = False
    return np.where(ok[..., None, None], F, 0.0), ok, np.where(ok, e, np.inf)


#: camera entries (of a camera divided by a power of two near its largest) below this may underflow in the products
#: of four entries of :func:`determinant_form` in double (2^-250: four of them stay above 2^-1000)
UNDERFLOW_SAFE = 2.0 ** -250


def _normalised(S: np.ndarray, I: np.ndarray, J: np.ndarray, dtype) -> tuple:
    """(F, ok, e_F) of :func:`fundamental_determinants` for scaled cameras S, the determinants in ``dtype``: F =
    fl(D~ / ||D~||) (norm and quotient in ``dtype``, rounded to double once) within (u + 2 u') (1 + 4 u) |F| +
    dD / ||D~|| (1 + 8 u) + eta of lambda D entrywise (module docstring)."""
    u_t = float(np.finfo(dtype).eps) / 2
    D, dD = determinant_form(S, I, J, dtype)
    nrm = np.sqrt(np.add.reduce((D * D).reshape(D.shape[:2] + (9,)), axis=-1))
    ok = np.isfinite(nrm) & (nrm > 0)
    safe = np.where(ok, nrm, 1)
    F = (D / safe[..., None, None]).astype(float)
    ok &= np.isfinite(F).all(axis=(2, 3))
    # (in dtype, then rounded: a ratio, no underflow; 1e-320 ~ 2000 subnormal units: products of two minors near 2^-552
    # round absolutely)
    rel = ((dD + 1e-320) / safe[..., None, None]).astype(float)
    E = (_U + 2 * u_t) * (1 + 4 * _U) * np.abs(F) + rel * (1 + 8 * _U) + 5e-324
    e = np.sqrt(np.add.reduce((E * E).reshape(E.shape[:2] + (9,)), axis=-1)) * (1 + 8 * _U)
    ok &= np.isfinite(e)        # (a norm below the doubles' range: no bound in double, the pair is not used)
    return np.where(ok[..., None, None], F, 0.0), ok, np.where(ok, e, np.inf)
