"""Certification by verification for quadratic programs with *banded* structure, over a stack.

The Lagrangian bound of :mod:`sospoly.analysis.verify` for M programs of one structure

    min f(v) = f0 + f1.v + v^T F2 v   s.t.  g_k(v) = g0_k + g1_k.v + v^T G2_k v = 0  (k < K),

when the variables and the constraints are ordered so that the Hessian of the Lagrangian
``L2 = F2 + sum_k lambda_k G2_k`` is banded (bandwidth u) and the constraints' gradients overlap only for
nearby constraints (J J^T banded, bandwidth b): every dense step of :func:`verify_quadratic_batch` (an SVD of
the n x K Jacobian, an eigen-decomposition of the n x n Hessian) is replaced by a banded Cholesky
factorisation (:mod:`sospoly.analysis.banded`), so one program costs O(K b^2 + n u^2) instead of
O(n^2 K + n^3):

1. multipliers from the normal equations of the KKT system, (J J^T + rho I) lambda = -J grad f(v^), rho =
   ``RIDGE`` max diag (so a rank-deficient J still gives multipliers), and one step of iterative refinement.
   Any lambda gives a valid bound: these only need to be good, not exact;
2. a Cholesky factorisation R R^T of L2: where it succeeds, lambda_min(L2) >= -eps with eps the factorisation's
   rigorous backward-error bound (:func:`~sospoly.analysis.banded.cholesky_backward_error`); where it fails
   (L2 indefinite, or only semi-definite in floating point) no bound is computed here (``reason`` 1) and the
   caller may use the dense rule;
3. the stationary point w of L from the same factors (2 L2 w = -L1), checked by its residual r;
4. c = L(w) = min_v L(v, lambda) (<= min {f : g = 0}) minus, when ``radius`` bounds the norm of a minimiser, the
   rigorous margin of :func:`~sospoly.analysis.verify.verify_quadratic_batch`:
   eps (R + ||w||)^2 + ||r|| (R + ||w||) + 8 eps_mach (|L0| + |L1.w| + |w^T L2 w|).

*Fewer constraints only enlarge the feasible set*: a bound computed from the multipliers of any *subset* of a
program's constraints is a lower bound of the program's minimum (weak duality of the subset's Lagrangian,
whose feasible set contains the program's).  So a caller may pass a sparse subset of its constraints (e.g. the
epipolar constraints of a band of view pairs) and the bound stays valid; whether it is tight (certifies) is
what the caller measures.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..tolerances import DEFAULT_TOLERANCES, Tolerances
from .banded import band_cholesky, band_from_dense, band_matvec, band_solve, cholesky_backward_error
from .verify import SparseQuadratics, VerificationBatch, constraint_margin, objective_scales, stationary

__all__ = ["verify_quadratic_banded_batch", "RIDGE"]

#: ridge of the multipliers' normal equations, relative to their largest diagonal entry.
RIDGE = 1e-12


class _RowPattern:
    """The shared nonzero pattern (k, c) of the constraints' gradients J (K, n) over a stack, with the sparse
    summation matrices of the products the bound needs (each row of J has a few nonzeros, so J y, J^T lam and
    the band of J J^T cost O(nnz) per problem instead of O(K n))."""

    def __init__(self, pattern: np.ndarray):
        K, n = pattern.shape
        self.K, self.n = K, n
        self.k, self.c = np.nonzero(pattern)
        nnz = self.k.size
        idx = np.arange(nnz)
        self.rows = sp.csr_matrix((np.ones(nnz), (self.k, idx)), shape=(K, nnz))
        self.cols = sp.csr_matrix((np.ones(nnz), (self.c, idx)), shape=(n, nnz))
        self.pos = np.full((K, n), -1)
        self.pos[self.k, self.c] = idx
        a, b = [], []
        order = np.argsort(self.c, kind="stable")
        bounds = np.searchsorted(self.c[order], np.arange(n + 1))
        for col in range(n):                        # pairs of entries in one column, row(a) >= row(b)
            members = order[bounds[col]:bounds[col + 1]]
            A, B = np.meshgrid(members, members, indexing="ij")
            keep = self.k[A] >= self.k[B]
            a.append(A[keep])
            b.append(B[keep])
        self.a, self.b = np.concatenate(a), np.concatenate(b)
        d = self.k[self.a] - self.k[self.b]
        self.bandwidth = int(d.max()) if d.size else 0
        self.pairs = sp.csr_matrix((np.ones(d.size), (d * K + self.k[self.b], np.arange(d.size))),
                                   shape=((self.bandwidth + 1) * K, d.size))

    def times(self, Jv: np.ndarray, y: np.ndarray) -> np.ndarray:
        """(M, K): J y."""
        return (self.rows @ (Jv * y[:, self.c]).T).T

    def transpose_times(self, Jv: np.ndarray, lam: np.ndarray) -> np.ndarray:
        """(M, n): J^T lam."""
        return (self.cols @ (Jv * lam[:, self.k]).T).T

    def gram_band(self, Jv: np.ndarray) -> np.ndarray:
        """(M, b + 1, K): J J^T in lower banded storage."""
        return (self.pairs @ (Jv[:, self.a] * Jv[:, self.b]).T).T.reshape(len(Jv), self.bandwidth + 1, self.K)


def verify_quadratic_banded_batch(f0, f1, F2, g0, g1, G2: SparseQuadratics, points, *,
                                  tolerances: Tolerances = DEFAULT_TOLERANCES, radius=None,
                                  constraint_error=None) -> VerificationBatch:
    """The Lagrangian bound of the module docstring for M programs at once.

    Shapes as for :func:`~sospoly.analysis.verify.verify_quadratic_batch`: f0 (M,), f1 (M, n), F2 (M, n, n)
    (may be a broadcast view), g0 (M, K), g1 (M, K, n), G2 a :class:`~sospoly.analysis.verify.SparseQuadratics`,
    points (M, n); ``radius`` (scalar or (M,)) bounds the norm of a minimiser (None: no bound, reason 1 -- the banded
    factorisation does not certify the positive floor a bound without a ball needs).  ``min_hessian_eigenvalue`` of the
    result is the certified lower bound -eps of lambda_min(L2) (NaN where the factorisation failed).  Under an
    active deadline (:func:`sospoly.budget.deadline_scope`) the banded column loops raise
    :class:`sospoly.budget.TimeLimitReached` once it has passed (:mod:`sospoly.analysis.banded`).
    """
    f0, f1, g0, g1, v = (np.asarray(a, float) for a in (f0, f1, g0, g1, points))
    M, n = f1.shape
    K = g0.shape[1]
    fv = f0 + np.einsum("mi,mi->m", f1, v) + np.einsum("mi,mij,mj->m", v, F2, v)
    grad_f = f1 + 2 * np.einsum("mij,mj->mi", F2, v)
    pattern = np.any(g1 != 0, axis=0)
    pattern[G2.k, G2.i] = True
    pat = _RowPattern(pattern)
    g1c = g1[:, pat.k, pat.c]                                        # g1 on the pattern (it holds all of g1)
    Jv = g1c.copy()                                                  # grad g_k(v^) on the pattern
    np.add.at(Jv, (slice(None), pat.pos[G2.k, G2.i]), 2 * G2.vals * v[:, G2.j])
    lam = np.zeros((M, K))
    solved = np.ones(M, bool)
    if K:
        JJ = pat.gram_band(Jv)
        JJ[:, 0] += RIDGE * np.maximum(1.0, np.max(np.abs(JJ[:, 0]), axis=1))[:, None]
        Rj, solved = band_cholesky(JJ)
        Rj = np.where(solved[:, None, None], Rj, 1.0)
        lam = band_solve(Rj, -pat.times(Jv, grad_f))
        r = pat.transpose_times(Jv, lam) + grad_f                    # one step of iterative refinement
        lam = lam + band_solve(Rj, -pat.times(Jv, r))
        solved &= np.all(np.isfinite(lam), axis=1)
        lam = np.where(solved[:, None], lam, 0.0)
    L0 = f0 + np.einsum("mk,mk->m", lam, g0)
    L1 = f1 + pat.transpose_times(g1c, lam)
    fi, fj = np.nonzero(np.any(F2 != 0, axis=0))
    u = max(int(np.max(np.abs(G2.i - G2.j))) if G2.i.size else 0, int(np.max(np.abs(fi - fj))) if fi.size else 0)
    Hb = band_from_dense(F2, u)
    low = G2.i >= G2.j
    np.add.at(Hb, (slice(None), G2.i[low] - G2.j[low], G2.j[low]), G2.vals[:, low] * lam[:, G2.k[low]])
    R, pd = band_cholesky(Hb)
    pd &= solved
    eps = np.where(pd, cholesky_backward_error(np.where(pd[:, None, None], R, 0.0)), np.nan)
    R = np.where(pd[:, None, None], R, 1.0)
    w = np.where(pd[:, None], band_solve(R, -L1 / 2), 0.0)
    L2w = band_matvec(Hb, w)
    r_abs = np.linalg.norm(2 * L2w + L1, axis=1)
    s_f = objective_scales(f0, f1, F2)               # (the rules of verify_quadratic_batch at the objective's scale)
    in_range = stationary(r_abs, np.linalg.norm(L1, axis=1), s_f, tolerances)
    t1, t2 = np.einsum("mi,mi->m", L1, w), np.einsum("mi,mi->m", w, L2w)
    c = L0 + t1 + t2
    if radius is not None:
        reach = np.asarray(radius, float) + np.linalg.norm(w, axis=1)
        c = c - eps * reach ** 2 - r_abs * reach - 8 * np.finfo(float).eps * (np.abs(L0) + np.abs(t1) + np.abs(t2))
    if constraint_error is not None:               # (verify_quadratic_batch's constraint_error)
        c = c - constraint_margin(lam, np.broadcast_to(np.asarray(constraint_error, float), lam.shape))
    if radius is None:                 # the factorisation certifies lambda_min >= -eps only: no bound without a ball
        pd = np.zeros_like(pd)         # (verify.free_margins needs lambda_min > 0 beyond round-off; review 38a H1)
    reason = np.where(~pd, 1, np.where(~in_range, 2, 0))
    bounded = (reason == 0) & np.isfinite(c)
    lower = np.where(bounded, c, np.nan)
    certified = bounded & np.asarray(tolerances.certified(lower, fv, s_f), bool)
    return VerificationBatch(lower, fv, certified, lam, -eps, reason)
