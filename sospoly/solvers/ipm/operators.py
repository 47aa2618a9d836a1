"""Operators of the interior-point skeleton (:mod:`.core`) for explicit constraint matrices.

* :class:`DenseOperator` -- a batch of B instances with dense A (B, n_rows, m): the Schur
  complement from the full symmetric matrices of every column, ``Z A_i S^-1`` for all i with
  numpy matmul on stacks, O(B (m n^3 + m^2 n^2)) per iteration;
* :class:`SparseOperator` -- one instance with sparse A: M_ab = <A_a, Z A_b R> formed as
  T_b = A_b R for all b at once (sparse (m n x n) times dense), Y = Z [T_1 ... T_m] (one gemm),
  M = S vec(Y) with S the sparse (m x n^2) matrix of vec(A_a): O(nnz n + m n^3 + nnz m).

Both factorise the augmented system [[M, A_E^T], [A_E, 0]] with a 1e-14 diagonal regularisation
of M and one step of iterative refinement (M becomes ill-conditioned near degenerate optima).
"""
from __future__ import annotations

import warnings

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from ...algebra.svec import smat, svec_scale, triu_pairs
from .core import Layout, Operator
from .lapack import cho_solve, cholesky

__all__ = ["DenseOperator", "SparseOperator", "newton_solver"]


def newton_solver(M: np.ndarray, AE: np.ndarray | None, p: int):
    """``solve(r_x, r_E) -> (dx, dz_E)`` for [[M, A_E^T], [A_E, 0]] over a batch (M (B, m, m), A_E (B, p, m))."""
    B, m = M.shape[0], M.shape[1]
    if p:
        K = np.zeros((B, m + p, m + p))
        K[:, :m, :m] = M
        K[:, :m, m:] = np.swapaxes(AE, 1, 2)
        K[:, m:, :m] = AE
    else:
        K = M
    reg = 1e-14 * np.maximum(1.0, np.abs(np.diagonal(M, axis1=1, axis2=2)).max(axis=1))
    Kr = K.copy()
    idx = np.arange(m)
    Kr[:, idx, idx] += reg[:, None]
    base = None
    if B == 1:
        if p == 0:
            try:
                cf = cholesky(Kr[0], lower=False)
                base = lambda r: cho_solve(cf, r[0], lower=False)[None]  # noqa: E731
            except (np.linalg.LinAlgError, ValueError):
                base = None
        if base is None:
            with warnings.catch_warnings():       # an exactly singular K: its solves go non-finite, and the IPM's
                warnings.simplefilter("ignore", sla.LinAlgWarning)   # own checks hand the program on (no stderr)
                lu = sla.lu_factor(Kr[0], check_finite=False)
            base = lambda r: sla.lu_solve(lu, r[0], check_finite=False)[None]  # noqa: E731
    else:
        base = lambda r: np.linalg.solve(Kr, r[..., None])[..., 0]  # noqa: E731

    def solve(rx, rE):
        r = np.concatenate([rx, rE], axis=1) if p else rx
        x = base(r)
        x = x + base(r - np.einsum("bij,bj->bi", K, x))
        return x[:, :m], x[:, m:]
    return solve


class DenseOperator(Operator):
    def __init__(self, A: np.ndarray, lay: Layout):
        self.A = A   # (B, n_rows, m)
        self.lay = lay
        self.AE = A[:, :lay.p, :]
        # full symmetric matrices of each column, per block: (B, m, n, n)
        self.full = [smat(np.swapaxes(A[:, lay.block(k), :], 1, 2), n) for k, n in enumerate(lay.sizes)]

    def subset(self, idx):
        out = DenseOperator.__new__(DenseOperator)
        out.A, out.lay, out.AE = self.A[idx], self.lay, self.AE[idx]
        out.full = [F[idx] for F in self.full]
        return out

    def factor(self, Zs, Rs):
        B, m = self.A.shape[0], self.A.shape[2]
        M = np.zeros((B, m, m))
        for F, Z, R in zip(self.full, Zs, Rs):
            n = Z.shape[-1]
            Y = Z[:, None] @ F @ R[:, None]
            M += F.reshape(B, m, n * n) @ np.swapaxes(Y.reshape(B, m, n * n), 1, 2)
        return newton_solver(0.5 * (M + np.swapaxes(M, 1, 2)), self.AE, self.lay.p)

    def adjoint(self, k, v):
        return np.einsum("blm,bl->bm", self.A[:, self.lay.block(k), :], v)

    def apply(self, k, x):
        return np.einsum("blm,bm->bl", self.A[:, self.lay.block(k), :], x)

    def eq_adjoint(self, z):
        return np.einsum("bpm,bp->bm", self.AE, z)

    def eq_apply(self, x):
        return np.einsum("bpm,bm->bp", self.AE, x)


class SparseOperator(Operator):
    """One instance (B = 1) with sparse A (see the module docstring)."""

    def __init__(self, A: sp.spmatrix, lay: Layout):
        A = sp.csr_matrix(A)
        self.lay = lay
        self.AE = A[:lay.p]
        self.AEt = self.AE.T.tocsr()
        self.AE_dense = self.AE.toarray()[None] if lay.p else None
        self.Ak = [A[lay.block(k)].tocsc() for k in range(len(lay.sizes))]
        self.Akt = [a.T.tocsr() for a in self.Ak]
        m = A.shape[1]
        self.m = m
        self.rowmats, self.flatmats = [], []
        for k, n in enumerate(lay.sizes):
            c = self.Ak[k].tocoo()
            i, j = triu_pairs(n)
            pi, pj = i[c.row], j[c.row]
            v = c.data / svec_scale(n)[c.row]
            off = pi != pj
            bb = np.concatenate([c.col, c.col[off]])
            ii = np.concatenate([pi, pj[off]])
            jj = np.concatenate([pj, pi[off]])
            vv = np.concatenate([v, v[off]])
            self.rowmats.append(sp.csr_matrix((vv, (bb * n + ii, jj)), shape=(m * n, n)))
            self.flatmats.append(sp.csr_matrix((vv, (bb, ii * n + jj)), shape=(m, n * n)))

    def subset(self, idx):
        return self

    def factor(self, Zs, Rs):
        m = self.m
        M = np.zeros((m, m))
        for k, (Z, R) in enumerate(zip(Zs, Rs)):
            n = self.lay.sizes[k]
            T = (self.rowmats[k] @ R[0]).reshape(m, n, n)                       # T_b = A_b R
            Y = (Z[0] @ T.transpose(1, 0, 2).reshape(n, m * n)).reshape(n, m, n)  # Y[i, b, l] = (Z A_b R)_il
            M += self.flatmats[k] @ Y.transpose(0, 2, 1).reshape(n * n, m)
        return newton_solver((0.5 * (M + M.T))[None], self.AE_dense, self.lay.p)

    def adjoint(self, k, v):
        return (self.Akt[k] @ v[0])[None]

    def apply(self, k, x):
        return (self.Ak[k] @ x[0])[None]

    def eq_adjoint(self, z):
        return (self.AEt @ z[0])[None]

    def eq_apply(self, x):
        return (self.AE @ x[0])[None]
