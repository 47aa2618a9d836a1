"""The reduced *moment form* of a single-block image-form LMI (see :class:`MomentReduction`)."""
from __future__ import annotations

import threading
from collections import OrderedDict

import numpy as np
import scipy.sparse as sp

from ...algebra.svec import smat, svec, svec_scale, triu_pairs
from ...tolerances import Tolerances
from .core import IpmResult, Layout, Operator, mehrotra
from .lapack import cho_solve, cholesky, solve_lower

__all__ = ["MomentReduction", "reduction_for", "REDUCE_MIN_FRACTION"]

#: reduction plans by sparsity pattern (least recently used dropped beyond _REDUCTIONS_MAX)
_REDUCTIONS: OrderedDict = OrderedDict()
_REDUCTIONS_MAX = 32
#: the reduced form is used when pair columns are at least this fraction of all columns
#: (a structural choice: below it the reduction saves little; not a numerical tolerance)
REDUCE_MIN_FRACTION = 0.25


def reduction_for(A: sp.spmatrix, q: np.ndarray, n: int):
    """The cached :class:`MomentReduction` of A's sparsity pattern (None: not reducible)."""
    A = sp.csc_matrix(A)
    A.sort_indices()
    key = (A.shape, n, hash(A.indptr.tobytes()), hash(A.indices.tobytes()), hash((q != 0).tobytes()))
    if key in _REDUCTIONS:
        _REDUCTIONS.move_to_end(key)
        return _REDUCTIONS[key]
    plan = MomentReduction.build(A, q != 0, n)
    _REDUCTIONS[key] = plan
    while len(_REDUCTIONS) > _REDUCTIONS_MAX:
        _REDUCTIONS.popitem(last=False)
    return plan


class MomentReduction:
    r"""The image-form LMI of one PSD block, solved in its reduced *moment form*.

    Image form (Clarabel's standard form, p = 0): min q^T x, svec S = b - A x, S >= 0.  A
    *pair column* j has two entries, one of them in a *private* row p_j that no other column
    touches, and q_j = 0 (the alpha of :class:`~sospoly.lowering.conic.GramForm` IMAGE: +alpha on a
    non-canonical Gram pair, -alpha on the canonical one).  With x = (w, alpha), eliminating
    alpha_j through its private row leaves one equation per remaining (*shared*) row:

        E svec(S) = E b - E A_w w,    E = [I on shared rows; -A[o_j, j] / A[p_j, j] at (o_j, p_j)]

    (o_j the pair column's other row), E A_alpha = 0 and rank E = #rows - #alpha, so this is
    the kernel (coefficient-matching) form.  Each row of E^T has one entry: the adjoint
    operators A_a = smat(E^T e_a) have *disjoint* supports (a monomial's Gram pairs).  Its
    dual, in the variables y of the shared rows (z = E^T y the image form's dual):

        min (E b)^T y   s.t.  (E A_w)^T y = -q_w,   smat(E^T y) >= 0,

    is a dual-form LMI with m' = #shared rows columns and #w equality rows, solved by the
    same Mehrotra/HKM skeleton (:func:`.core.mehrotra`).  Its Schur complement
    M_ab = <A_a, Z A_b S^-1> is formed from the padded entry lists (i_t, j_t, v_t) of every
    A_b (at most K entries): P_b = Z A_b S^-1 = sum_t v_t Z[:, i_t] S^-1[j_t, :] is one
    batched matmul of (n x K)(K x n) products, M_ab = sum_t v_t P_b[i_t, j_t] one sparse
    product, O(m' n^2 K) instead of the O(m n^3) of the dense forms; the equality rows are
    eliminated with the Cholesky factor of M.  The image form's x, s, z are read back:
    w = -z_E, s = svec of the moment form's dual matrix (the Gram matrix),
    alpha_j = (b - s)[p_j] / A[p_j, j], z = E^T y.
    """

    @classmethod
    def build(cls, A: sp.csc_matrix, qnz: np.ndarray, n: int):
        L, m = A.shape
        if L != n * (n + 1) // 2 or m == 0:
            return None
        indptr, indices = A.indptr, A.indices
        nnzc = np.diff(indptr)
        rc = np.bincount(indices, minlength=L)
        cand = np.nonzero((nnzc == 2) & ~qnz)[0]
        p0 = indptr[cand]
        r1, r2 = indices[p0], indices[p0 + 1]
        priv1 = rc[r1] == 1
        priv2 = ~priv1 & (rc[r2] == 1)
        ok = priv1 | priv2
        cand, p0, r1, r2, priv1 = cand[ok], p0[ok], r1[ok], r2[ok], priv1[ok]
        if cand.size < REDUCE_MIN_FRACTION * m:
            return None
        self = cls.__new__(cls)
        self.n, self.L, self.m = n, L, m
        self.alpha_cols = cand
        self.pdat = np.where(priv1, p0, p0 + 1)
        self.odat = np.where(priv1, p0 + 1, p0)
        self.prow = np.where(priv1, r1, r2)
        orow = np.where(priv1, r2, r1)
        shared = np.ones(L, bool)
        shared[self.prow] = False
        shared_rows = np.nonzero(shared)[0]
        m2 = shared_rows.size
        self.m2 = m2
        row2col = np.empty(L, np.int64)
        row2col[shared_rows] = np.arange(m2)
        row2col[self.prow] = row2col[orow]
        # number the moment-form columns by their entry count, so that the Schur complement
        # runs one batched matmul per count on contiguous slices (no padding)
        # and put the columns the equality rows (E A_w)^T touch last: L^-1 (E A_w) then only
        # involves the trailing block of the Cholesky factor of M
        ii, jj = triu_pairs(n)
        size = np.bincount(row2col, weights=np.where(ii == jj, 1.0, 2.0), minlength=m2).astype(np.int64)
        wmask = np.ones(m, bool)
        wmask[cand] = False
        touched = np.zeros(m2, np.int64)
        touched[row2col[A[:, np.nonzero(wmask)[0]].tocoo().row]] = 1
        relabel = np.empty(m2, np.int64)
        relabel[np.lexsort((size, touched))] = np.arange(m2)
        row2col = relabel[row2col]
        self.n_touched = int(touched.sum())
        self.row2col = row2col
        self.srow = np.empty(m2, np.int64)          # the shared (canonical) row of each column
        self.srow[row2col[shared_rows]] = shared_rows
        self.w_cols = np.nonzero(wmask)[0]
        # ordered full-matrix entries of every A_a = smat(E^T e_a): (i, j, svec row, factor)
        off = np.nonzero(ii != jj)[0]
        er = np.concatenate([np.arange(L), off])
        ei = np.concatenate([ii, jj[off]])
        ej = np.concatenate([jj, ii[off]])
        ef = 1.0 / svec_scale(n)[er]
        ecol = row2col[er]
        order = np.argsort(ecol, kind="stable")
        er, ei, ej, ef, ecol = er[order], ei[order], ej[order], ef[order], ecol[order]
        counts = np.bincount(ecol, minlength=m2)
        K = int(counts.max())
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        slot = np.arange(er.size) - starts[ecol]
        self.K = K
        self.Ipad = np.zeros((m2, K), np.int64)
        self.Jpad = np.zeros((m2, K), np.int64)
        self.Rpad = np.zeros((m2, K), np.int64)
        self.Fpad = np.zeros((m2, K))
        self.Ipad[ecol, slot], self.Jpad[ecol, slot] = ei, ej
        self.Rpad[ecol, slot], self.Fpad[ecol, slot] = er, ef
        # runs of columns with equal entry counts (contiguous by the numbering above)
        cut = np.nonzero(np.diff(counts))[0] + 1
        self.groups = [(int(a), int(b), int(counts[a])) for a, b in zip(np.r_[0, cut], np.r_[cut, m2])]
        # sparse (m' x n^2) of vec(A_a), data refilled per instance: data = V[ent_a, ent_slot]
        EF = sp.csr_matrix((np.arange(1, er.size + 1, dtype=float), (ecol, ei * n + ej)), shape=(m2, n * n))
        perm = EF.data.astype(np.int64) - 1
        self.ef_pattern = (EF.indices, EF.indptr)
        self._local = threading.local()
        self.ef_src = (ecol[perm], slot[perm])
        return self

    def workspace(self, V: np.ndarray) -> dict:
        """Work buffers (allocating the (m', n, n) stack every iteration costs more than the
        product, and a fresh (m' x m') array is paged in anew every iteration: M and its factor live
        in buffers too; one set per thread, so a plan can be shared between threads) and the sparse
        vec(A_a) of this instance's values V."""
        m2, n, K = self.m2, self.n, self.K
        EF = sp.csr_matrix((V[self.ef_src], *self.ef_pattern), shape=(m2, n * n))
        bufs = getattr(self._local, "bufs", None)    # reused by later solves in the same thread
        if bufs is None:
            bufs = self._local.bufs = {"Zg": np.empty((m2, K, n)), "Rg": np.empty((m2, K, n)),
                                       "P": np.empty((m2, n, n)), "PT": np.empty((n * n, m2)),
                                       "Mr": np.empty((m2, m2), order="F")}
        return dict(bufs, EF=EF, V=V)

    # ------------------------------------------------------------------ Schur complement
    def schur(self, Z: np.ndarray, R: np.ndarray, ws: dict) -> np.ndarray:
        """M_ab = <A_a, Z A_b R> for all a, b (``ws`` from :meth:`workspace`; M is its buffer, overwritten by the
        next call in this thread)."""
        m2, n = self.m2, self.n
        Zg, Rg, P, PT = ws["Zg"], ws["Rg"], ws["P"], ws["PT"]
        np.take(Z, self.Ipad, axis=0, out=Zg)
        np.multiply(Zg, ws["V"][:, :, None], out=Zg)
        np.take(R, self.Jpad, axis=0, out=Rg)
        for a, b, k in self.groups:                                         # P_b = Z A_b R
            np.matmul(Zg[a:b, :k].transpose(0, 2, 1), Rg[a:b, :k], out=P[a:b])
        np.copyto(PT, P.reshape(m2, n * n).T)
        # M[a, b] = <A_a, P_b>; symmetric up to round-off (Cholesky reads one triangle).  scipy's public product
        # (a fresh array; its private kernel into a reused buffer saved ~4 us per call, not worth the coupling)
        return ws["EF"] @ PT

    # ------------------------------------------------------------------ one instance
    def solve(self, A: sp.spmatrix, b: np.ndarray, q: np.ndarray, tol: Tolerances, deadline=None,
              stop_at: float | None = None) -> IpmResult | None:
        """The image-form problem (A, b, q) through the moment form; None when the instance's values do
        not allow the reduction (a zero pivot A[p_j, j]).  ``stop_at``: stop (reason ``IPM_LEVEL``) at the first
        iterate whose image-form x has q^T x <= stop_at with the moment form's dual residual at most
        :data:`LEVEL_DRES` (the form's dual side is the Gram certificate: strictly PSD in the interior, its
        equalities held to round-off, so x is a certificate of that level up to the rigorous margin its
        caller charges)."""
        A = sp.csc_matrix(A)
        A.sort_indices()
        data = A.data
        ap, ao = data[self.pdat], data[self.odat]
        if np.any(ap == 0) or not (np.all(np.isfinite(data)) and np.all(np.isfinite(b)) and np.all(np.isfinite(q))):
            return None
        e = np.ones(self.L)
        e[self.prow] = -ao / ap
        m2 = self.m2
        cq = np.bincount(self.row2col, e * b, minlength=m2)                 # E b
        Aw = A[:, self.w_cols].tocoo()
        AE = np.zeros((self.w_cols.size, m2))                               # (E A_w)^T
        np.add.at(AE, (Aw.col, self.row2col[Aw.row]), e[Aw.row] * Aw.data)
        bE = -q[self.w_cols]
        op = _MomentOperator(self, e, AE, self.workspace(self.Fpad * e[self.Rpad]), tol)
        p = AE.shape[0]
        lay = Layout(p, [self.n])
        stop = None
        if stop_at is not None and np.isfinite(stop_at):
            def stop(active, it_, r):
                x = self._image_x(it_.zE[0], it_.Z[0][0], b, ap)
                return np.array([r.dres[0] <= LEVEL_DRES and float(q @ x) <= stop_at])
        # a stalled moment form goes to the unreduced method, which starts afresh: stopped at a plateau already
        it_, conv, its, why = mehrotra(op, cq[None], np.concatenate([bE, np.zeros(self.L)])[None], lay, tol, deadline,
                                       stop, flat_stall=True)
        y = it_.x[0]
        x = self._image_x(it_.zE[0], it_.Z[0][0], b, ap)
        z = e * y[self.row2col]
        pobj = float(q @ x)
        dobj = float(-(b @ z))
        return IpmResult(conv, x[None], z[None], svec(it_.Z[0][0])[None], np.array([pobj]), np.array([dobj]), its,
                         why)

    def _image_x(self, zE: np.ndarray, Zgram: np.ndarray, b: np.ndarray, ap: np.ndarray) -> np.ndarray:
        """The image-form x of a moment-form iterate: the free columns -z_E, each alpha column from its pivot row
        of svec(Z) (the Gram matrix)."""
        s = svec(Zgram)
        x = np.zeros(self.m)
        x[self.w_cols] = -zE
        x[self.alpha_cols] = (b[self.prow] - s[self.prow]) / ap
        return x


#: the moment form's relative dual residual (the Gram certificate's equalities) below which an iterate may stop
#: at the caller's level (:meth:`MomentReduction.solve`); measured ~1e-15 from the first iteration on
LEVEL_DRES = 1e-10


#: regularisations tried on a Schur complement: r, 100 r, 10^4 r (times its largest diagonal entry, at least 1)
_REGULARIZATION_STEPS = 3


def _regularized_cholesky(A: np.ndarray, buf: np.ndarray, reg: float) -> np.ndarray:
    """The lower Cholesky factor of A + reg 100^k max(1, max |diag A|) I, into ``buf`` (Fortran order, n x n,
    overwritten), for the first k = 0, 1, 2 at which it is numerically positive definite (LinAlgError after
    the last); A itself is left as it is (the Newton solves refine against it)."""
    dmax = max(1.0, float(np.abs(np.diagonal(A)).max()))
    for k in range(_REGULARIZATION_STEPS):
        np.copyto(buf, A)                        # potrf's storage order: factorised in place
        buf[np.diag_indices(A.shape[0])] += reg * 100.0 ** k * dmax
        try:
            return cholesky(buf, lower=True, overwrite=True)
        except np.linalg.LinAlgError:
            if k == _REGULARIZATION_STEPS - 1:
                raise
    raise AssertionError("unreachable")  # pragma: no cover


class _MomentOperator(Operator):
    """The moment form as an :class:`~.core.Operator`: S = smat(E^T y) (A = -E^T, b = 0), equality rows
    (E A_w)^T y = -q_w; its Schur complement from :meth:`MomentReduction.schur`, factorised by Cholesky
    (regularised ``ipm_schur_regularization`` * max diag, raised 100x while M is numerically indefinite)
    with the equality rows eliminated through the Cholesky factor of their Schur complement (regularised
    the same way: :func:`_regularized_cholesky`)."""

    def __init__(self, red: MomentReduction, e: np.ndarray, AE: np.ndarray, ws: dict, tol: Tolerances):
        self.red, self.e, self.AE, self.ws, self.tol = red, e, AE, ws, tol

    def subset(self, idx):
        return self

    def _Et(self, y):
        return self.e * y[self.red.row2col]

    def _Ev(self, v):
        return np.bincount(self.red.row2col, self.e * v, minlength=self.red.m2)

    def apply(self, k, x):
        return -self._Et(x[0])[None]

    def adjoint(self, k, v):
        return -self._Ev(v[0])[None]

    def eq_apply(self, x):
        return (self.AE @ x[0])[None]

    def eq_adjoint(self, z):
        return (self.AE.T @ z[0])[None]

    def restore(self, dZ, rD, dzE):
        """The linear equations of Z (coefficient matching, E svec(dZ) = rD + AE^T dz) hold only up to the
        round-off of M, which grows like cond(S) as the moment matrix S tends to rank one; restore them
        exactly on the shared entries (E is the identity there), so the dual residual decreases by
        (1 - step) as in exact arithmetic."""
        red = self.red
        corr = np.zeros(red.L)
        corr[red.srow] = rD[0] + self.AE.T @ dzE[0] - self._Ev(svec(dZ[0][0]))
        return [dZ[0] + smat(corr, red.n)[None]]

    def factor(self, Zs, Rs):
        red, tol, AE = self.red, self.tol, self.AE
        m2, p = red.m2, AE.shape[0]
        M = red.schur(Zs[0][0], Rs[0][0], self.ws)
        Lc = _regularized_cholesky(M, self.ws["Mr"], tol.ipm_schur_regularization)
        t0 = m2 - red.n_touched
        if p:
            # AE^T vanishes on the leading rows: L^-1 AE^T = [0; L22^-1 AE2^T]
            C = solve_lower(Lc[t0:, t0:], AE[:, t0:].T)
            # SE is singular when the equality rows are linearly dependent: regularised like M (it was
            # regularised once and such programs went to the unreduced method at the first iteration)
            Le = _regularized_cholesky(C.T @ C, np.empty((p, p), order="F"), tol.ipm_schur_regularization)

        def base(r1, r2):
            # u = L^-1 r1; dz = SE^-1 (C^T u - r2); dy = L^-T (u - C dz), C = [0; C2] = L^-1 AE^T
            u = solve_lower(Lc, r1)
            if not p:
                return solve_lower(Lc, u, trans=True), np.zeros(0)
            dz = cho_solve(Le, C.T @ u[t0:] - r2, lower=True)
            u[t0:] -= C @ dz
            return solve_lower(Lc, u, trans=True), dz

        def solve(rx, rE):
            r1, r2 = rx[0], rE[0]
            dy, dz = base(r1, r2)
            ddy, ddz = base(r1 - M @ dy - AE.T @ dz, r2 - AE @ dy)
            return (dy + ddy)[None], (dz + ddz)[None]
        return solve
