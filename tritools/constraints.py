"""Projection constraints in the image domain (SPEC §3 and §7).

Theorem 1 (minors)
    M0(v) = [[I2, -x_1] P_1; ...; [I2, -x_N] P_N] is 2N x 4 and affine in v; the image
    points come from one scene point iff every 4x4 minor vanishes.  Row r of M0 is
    ``a_r + t_r c_r`` with ``a_r = P_i[k]``, ``c_r = -P_i[2]`` and ``t_r = x_ik`` a single
    variable, so a minor is multilinear in its rows' variables::

        det M0[R] = sum_{S subset R} prod_{r in S} t_r * det(rows c_r (r in S), a_r (r not in S))

    which gives the coefficient matrix M1 of m1 = M1 b1(v) with numeric 4x4
    determinants only (two rows of one view share c_r, so their product term is 0:
    minors have degree 2, 3 or 4).  SVD M1 = U1 S1 V1^T, N2 = numerical rank
    (``RANK_RTOL``), m2 = S2 V1^T b1: same zero set, N2 <= N1 entries.
Corollary 1 (epipolar)
    m1_ij = x~_i^T F_ij x~_j for i < j, F_ij from the camera pair (quadratic).

Both return plain :class:`sospoly.Polynomial` lists; the solver never appears here.
"""
from __future__ import annotations

import enum
from itertools import combinations

import numpy as np

from sospoly import Polynomial

from .geometry import fundamental_matrix

__all__ = ["Method", "RANK_RTOL", "COEF_RTOL", "minors_matrix", "theorem1_constraints", "corollary1_constraints"]

#: relative singular-value threshold for the numerical rank N2 of M1 (rows scaled to unit norm first).
#: Directions below it are dropped: at an exactly feasible point their values are float
#: round-off amplified by 1/sigma_k, and large multipliers r_k on them move c by
#: r_k * round-off (seen on the corridor point of Example 1: sigma_10/sigma_1 = 8e-10
#: makes the SDP inaccurate, sigma_7..9 ~ 3e-7 give a bound 7e-6 above f at the optimum).
#: Dropping rows only enlarges {m2 = 0}, so the lower bound stays valid (maybe weaker).
RANK_RTOL = 1e-6
#: m2 coefficients below COEF_RTOL * max|row| are SVD round-off and set to zero (this also fixes deg m2_i).
COEF_RTOL = 1e-12


class Method(str, enum.Enum):
    THEOREM1 = "theorem1"
    COROLLARY1 = "corollary1"


def _row_data(cameras: np.ndarray):
    """a_r, c_r and the variable index (0..2N-1, x_i1 -> 2i, x_i2 -> 2i+1) of each M0 row."""
    N = cameras.shape[0]
    a = np.empty((2 * N, 4))
    c = np.empty((2 * N, 4))
    for i, P in enumerate(cameras):
        a[2 * i], a[2 * i + 1] = P[0], P[1]
        c[2 * i] = c[2 * i + 1] = -P[2]
    return a, c, np.arange(2 * N)


def minors_matrix(cameras: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """M1 and the exponent rows b1 over the 2N image variables (x_11, x_12, ..., x_N2).

    Returns ``(M1, B1)`` with ``m1 = M1 @ b1(x)``; B1 rows are 0/1 exponent vectors.
    """
    cameras = np.asarray(cameras, float)
    a, c, _ = _row_data(cameras)
    nrow = a.shape[0]
    subsets = [S for k in range(5) for S in combinations(range(4), k)]
    monos: dict[tuple, int] = {}
    rows_out = []
    for R in combinations(range(nrow), 4):
        coef: dict[int, float] = {}
        for S in subsets:
            mono = tuple(sorted(R[k] for k in S))
            if len({r // 2 for r in mono}) != len(mono):
                continue  # two rows of one view: equal c rows, determinant 0
            rows = np.array([c[R[k]] if k in S else a[R[k]] for k in range(4)])
            d = np.linalg.det(rows)
            if d != 0.0:
                j = monos.setdefault(mono, len(monos))
                coef[j] = coef.get(j, 0.0) + d
        rows_out.append(coef)
    M1 = np.zeros((len(rows_out), len(monos)))
    for i, coef in enumerate(rows_out):
        for j, v in coef.items():
            M1[i, j] = v
    B1 = np.zeros((len(monos), nrow), dtype=np.int64)
    for mono, j in monos.items():
        B1[j, list(mono)] = 1
    return M1, B1


def _poly_from_row(gens, x_index, B1, row) -> Polynomial:
    n = len(gens)
    terms = {}
    for e, cf in zip(B1, row):
        if cf != 0.0:
            exp = [0] * n
            for k in np.nonzero(e)[0]:
                exp[x_index[k]] = int(e[k])
            terms[tuple(exp)] = float(cf)
    return Polynomial(gens, terms)


def theorem1_constraints(cameras: np.ndarray, gens, x_index) -> tuple[list[Polynomial], dict]:
    """m2 of Theorem 1 as polynomials in ``gens``.

    ``x_index[2i + k]`` is the position in ``gens`` of x_{i+1, k+1}.  Returns the list
    and diagnostics (N1, N2, singular values).
    """
    M1, B1 = minors_matrix(cameras)
    norms = np.linalg.norm(M1, axis=1)
    keep = norms > 0
    M1n = M1[keep] / norms[keep, None]
    U, S, Vt = np.linalg.svd(M1n, full_matrices=False)
    n2 = int(np.sum(S > RANK_RTOL * S[0])) if S.size else 0
    M2 = S[:n2, None] * Vt[:n2]
    polys = []
    for row in M2:
        row = row / np.max(np.abs(row))   # unit scale: same zero set, better conditioned SDP
        row = np.where(np.abs(row) > COEF_RTOL, row, 0.0)
        polys.append(_poly_from_row(tuple(gens), x_index, B1, row))
    return polys, {"N1": M1.shape[0], "N2": n2, "singular_values": S}


def corollary1_constraints(cameras: np.ndarray, gens, x_index) -> tuple[list[Polynomial], dict]:
    """The N(N-1)/2 epipolar constraints x~_i^T F_ij x~_j (SPEC §7), F_ij scaled to unit norm."""
    gens = tuple(gens)
    n = len(gens)
    N = cameras.shape[0]

    def var(k):
        e = [0] * n
        e[x_index[k]] = 1
        return Polynomial(gens, {tuple(e): 1.0})

    one = Polynomial.constant(1.0, gens)
    xt = [[var(2 * i), var(2 * i + 1), one] for i in range(N)]
    polys = []
    for i in range(N):
        for j in range(i + 1, N):
            F = fundamental_matrix(cameras[i], cameras[j])
            F = F / np.linalg.norm(F)
            p = Polynomial(gens, {})
            for a in range(3):
                for b in range(3):
                    if F[a, b] != 0.0:
                        p = p + float(F[a, b]) * xt[i][a] * xt[j][b]
            polys.append(p)
    return polys, {"N1": len(polys), "N2": len(polys)}
