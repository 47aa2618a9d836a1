"""A small batched primal-dual interior-point method for LMIs in dual form.

The conic standard form of :mod:`sospoly.lowering.conic` (Clarabel's)::

    min q^T x   s.t.  A_E x = b_E,   S_k = smat(b_k - A_k x) >= 0   (k = 1..K blocks)

is the dual-form LMI  max (-q)^T x  s.t.  C_k - sum_i x_i A_{k,i} >= 0  with free
scalars x (for the Positivstellensatz programs: c, the coefficients of r, alpha and
the Gram entries of s), whose dual is  min <C, Z> + b_E^T z_E  s.t.
<A_i, Z> + (A_E^T z_E)_i = -q_i,  Z >= 0.

Method: infeasible-start Mehrotra predictor-corrector with the HKM direction

    dZ = sym(K S^-1) - Z - sym(Z dS S^-1),   K = sigma mu I - dZ_aff dS_aff,

which reduces every Newton step to the Schur complement system of the size of
the free scalars,  M_ij = sum_k tr(A_{k,i} Z_k A_{k,j} S_k^-1)  (augmented by A_E
when there are equality rows).  Two ways to form M:

* dense, batched: ``Z A_i S^-1`` for all i with numpy matmul on stacks, for a batch
  of B instances sharing one structure (cost O(B (m n^3 + m^2 n^2)) per iteration);
* svec-Kronecker, one instance with sparse A: the operator W = svec(sym(Z . S^-1))
  on svec space (size n(n+1)/2), then M = A^T W A with sparse A;
* reduced moment form, one instance whose image-form columns are mostly alpha pairs
  (:class:`_MomentReduction`, used by :func:`ipm_solve_sparse` when it applies, e.g.
  Theorem 1 at delta = 4): the alphas are eliminated, leaving the coefficient-matching
  rows, whose adjoint matrices have disjoint supports; M (one row per monomial of u) is
  then one batched matmul of thin products and one sparse product per iteration.

Stopping rule (Clarabel's, with :class:`~sospoly.tolerances.Tolerances`):
|pobj - dobj| <= solver_gap_abs or <= solver_gap_rel min(|pobj|, |dobj|);
||A x + s - b||_inf <= solver_feas max(1, ||b|| + ||x|| + ||s||);
||A^T z + q||_inf <= solver_feas max(1, ||q|| + ||z||).  An instance that does not
meet it within ``ipm_max_iter`` iterations, or whose iterates diverge (infeasible
or unbounded problems: this method has no infeasibility certificates), is reported
``converged = False``; callers fall back to Clarabel.  Nothing here is trusted
either way: the a-posteriori certificate checks of :mod:`sospoly.solvers.solve` run on the
returned x.
"""
from __future__ import annotations

import threading
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from .blas import with_single_threaded_blas
from ..algebra.svec import svec_scale, triu_pairs
from ..tolerances import DEFAULT_TOLERANCES, Tolerances

__all__ = ["IpmResult", "ipm_solve_batch", "ipm_solve_sparse"]


@dataclass(frozen=True)
class IpmResult:
    """Per-instance outcome of a batch (arrays have a leading batch axis)."""
    converged: np.ndarray        # (B,) bool
    x: np.ndarray                # (B, m)
    z: np.ndarray                # (B, n_rows): z_E then the svec blocks (Clarabel's row order)
    s: np.ndarray                # (B, n_rows)
    primal_objective: np.ndarray
    dual_objective: np.ndarray
    iterations: np.ndarray       # (B,) int
    reason: tuple                # per instance: "" or why it did not converge


# --------------------------------------------------------------------------- svec helpers (batched)
def _smat_batch(v: np.ndarray, n: int) -> np.ndarray:
    """(..., L) svec -> (..., n, n) symmetric."""
    i, j = triu_pairs(n)
    vals = v / svec_scale(n)
    X = np.zeros(v.shape[:-1] + (n, n))
    X[..., i, j] = vals
    X[..., j, i] = vals
    return X


def _svec_batch(X: np.ndarray) -> np.ndarray:
    n = X.shape[-1]
    i, j = triu_pairs(n)
    return 0.5 * (X[..., i, j] + X[..., j, i]) * svec_scale(n)


def _max_step(X: np.ndarray, dX: np.ndarray) -> np.ndarray:
    """Largest a with X + a dX >= 0 (inf when dX >= 0), X > 0; batched (B, n, n)."""
    try:
        L = np.linalg.cholesky(X)
    except np.linalg.LinAlgError:
        return np.zeros(X.shape[0])
    Li = np.linalg.inv(L)
    T = Li @ dX @ np.swapaxes(Li, -1, -2)
    lam = np.linalg.eigvalsh(0.5 * (T + np.swapaxes(T, -1, -2)))[..., 0]
    with np.errstate(divide="ignore"):
        return np.where(lam < 0, -1.0 / np.minimum(lam, -1e-300), np.inf)


def _inv_spd(X: np.ndarray) -> np.ndarray:
    L = np.linalg.cholesky(X)
    Li = np.linalg.inv(L)
    return np.swapaxes(Li, -1, -2) @ Li


class _Layout:
    """Row layout: p zero rows, then PSD blocks of sides ``sizes`` (svec rows)."""

    def __init__(self, n_zero: int, sizes):
        self.p = int(n_zero)
        self.sizes = tuple(int(n) for n in sizes)
        self.starts = []
        r = self.p
        for n in self.sizes:
            self.starts.append(r)
            r += n * (n + 1) // 2
        self.n_rows = r
        self.nu = sum(self.sizes)   # degree of the cone (mu = <S, Z> / nu)

    def block(self, k):
        n = self.sizes[k]
        return slice(self.starts[k], self.starts[k] + n * (n + 1) // 2)


def layout_of(cones) -> _Layout:
    """Layout from sospoly cones: at most one leading zero cone, then PSD cones only."""
    p, sizes = 0, []
    for i, c in enumerate(cones):
        if c.kind == "zero" and i == 0:
            p = c.dim
        elif c.kind == "psd":
            sizes.append(c.size)
        else:
            raise ValueError(f"the interior-point solver handles a leading zero cone and PSD cones only, "
                             f"got a {c.kind!r} cone at position {i}")
    return _Layout(p, sizes)


# --------------------------------------------------------------------------- the method
class _Schur:
    """Forms and factorises the Newton system for the current iterate."""

    def rhs_dot(self, k, H):  # A_k^T svec(H) for symmetric H, (B, m)
        raise NotImplementedError

    def apply(self, k, dx):   # A_k dx in svec, (B, L)
        raise NotImplementedError


class _DenseSchur(_Schur):
    def __init__(self, A: np.ndarray, lay: _Layout):
        self.A = A   # (B, n_rows, m)
        self.lay = lay
        self.AE = A[:, :lay.p, :]
        # full symmetric matrices of each column, per block: (B, m, n, n)
        self.full = [_smat_batch(np.swapaxes(A[:, lay.block(k), :], 1, 2), n) for k, n in enumerate(lay.sizes)]

    def subset(self, idx):
        out = _DenseSchur.__new__(_DenseSchur)
        out.A, out.lay, out.AE = self.A[idx], self.lay, self.AE[idx]
        out.full = [F[idx] for F in self.full]
        return out

    def M(self, Zs, Rs):
        B, m = self.A.shape[0], self.A.shape[2]
        M = np.zeros((B, m, m))
        for F, Z, R in zip(self.full, Zs, Rs):
            n = Z.shape[-1]
            Y = Z[:, None] @ F @ R[:, None]
            M += F.reshape(B, m, n * n) @ np.swapaxes(Y.reshape(B, m, n * n), 1, 2)
        return 0.5 * (M + np.swapaxes(M, 1, 2))

    def rhs_dot(self, k, Hs):
        return np.einsum("blm,bl->bm", self.A[:, self.lay.block(k), :], Hs)

    def apply(self, k, dx):
        return np.einsum("blm,bm->bl", self.A[:, self.lay.block(k), :], dx)

    def AE_dot(self, zE):
        return np.einsum("bpm,bp->bm", self.AE, zE)

    def AE_apply(self, x):
        return np.einsum("bpm,bm->bp", self.AE, x)


class _SparseSchur(_Schur):
    """One instance (B = 1) with sparse A.

    M_ab = <A_a, Z A_b R> is formed as: T_b = A_b R for all b at once (sparse (m n x n)
    times dense), Y = Z [T_1 ... T_m] (one gemm of n x n by n x m n), M = S vec(Y) with S
    the sparse (m x n^2) matrix of vec(A_a): O(nnz n + m n^3 + nnz m) per iteration."""

    def __init__(self, A: sp.spmatrix, lay: _Layout):
        A = sp.csr_matrix(A)
        self.lay = lay
        self.AE = A[:lay.p]
        self.AEt = self.AE.T.tocsr()
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

    def M(self, Zs, Rs):
        m = self.m
        M = np.zeros((m, m))
        for k, (Z, R) in enumerate(zip(Zs, Rs)):
            n = self.lay.sizes[k]
            T = (self.rowmats[k] @ R[0]).reshape(m, n, n)                       # T_b = A_b R
            Y = (Z[0] @ T.transpose(1, 0, 2).reshape(n, m * n)).reshape(n, m, n)  # Y[i, b, l] = (Z A_b R)_il
            M += self.flatmats[k] @ Y.transpose(0, 2, 1).reshape(n * n, m)
        return (0.5 * (M + M.T))[None]

    def rhs_dot(self, k, Hs):
        return (self.Akt[k] @ Hs[0])[None]

    def apply(self, k, dx):
        return (self.Ak[k] @ dx[0])[None]

    def AE_dot(self, zE):
        return (self.AEt @ zE[0])[None]

    def AE_apply(self, x):
        return (self.AE @ x[0])[None]


def _solve_newton(M, AE_dense, p):
    """A solver for [[M, A_E^T], [A_E, 0]] [dx; dzE] = r over a batch, with one step of
    iterative refinement (M becomes ill-conditioned near degenerate optima)."""
    B, m = M.shape[0], M.shape[1]
    if p:
        K = np.zeros((B, m + p, m + p))
        K[:, :m, :m] = M
        K[:, :m, m:] = np.swapaxes(AE_dense, 1, 2)
        K[:, m:, :m] = AE_dense
    else:
        K = M
    reg = 1e-14 * np.maximum(1.0, np.abs(np.diagonal(M, axis1=1, axis2=2)).max(axis=1))
    Kr = K.copy()
    idx = np.arange(m)
    Kr[:, idx, idx] += reg[:, None]
    if B == 1:
        if p == 0:
            try:
                cf = sla.cho_factor(Kr[0], check_finite=False)
                base = lambda r: sla.cho_solve(cf, r[0], check_finite=False)[None]  # noqa: E731
            except (np.linalg.LinAlgError, ValueError):
                cf = None
        if p or cf is None:
            lu = sla.lu_factor(Kr[0], check_finite=False)
            base = lambda r: sla.lu_solve(lu, r[0], check_finite=False)[None]  # noqa: E731
    else:
        base = lambda r: np.linalg.solve(Kr, r[..., None])[..., 0]  # noqa: E731

    def solve(r):
        x = base(r)
        return x + base(r - np.einsum("bij,bj->bi", K, x))
    return solve


def _stopping_rule(tol: Tolerances, pobj, dobj, rdx, pres, dres, pscale, dscale, xzinf):
    """(converged, diverged) by the module docstring's stopping rule, on scalars or on (B,) arrays.

    ``rdx`` = r_D^T x, ``pscale`` = ||b|| + ||x|| + ||s||, ``dscale`` = ||q|| + ||z||,
    ``xzinf`` = max(||x||, ||z||) (infinity norms).  pobj - dobj = <S, Z> + z^T r_P + r_D^T x
    exactly.  With large multipliers x (nearly dependent constraints) the last term stalls above
    the gap tolerance although the iterate is optimal to working precision; accepted also when
    the complementarity part meets the gap tolerance and |r_D^T x| stays below
    ipm_dual_residual_gap relative (Tolerances documents the bound)."""
    gap = np.abs(pobj - dobj)
    feas_ok = (pres <= tol.solver_feas * np.maximum(1.0, pscale)) & (dres <= tol.solver_feas * np.maximum(1.0, dscale))
    ok = ((gap <= tol.solver_gap_abs) | (gap <= tol.solver_gap_rel * np.minimum(np.abs(pobj), np.abs(dobj)))) \
        & feas_ok
    comp = np.abs(pobj - dobj - rdx)
    scale_obj = np.maximum(1.0, np.abs(pobj))
    ok = ok | (feas_ok & ((comp <= tol.solver_gap_abs) | (comp <= tol.solver_gap_rel * scale_obj))
               & (np.abs(rdx) <= tol.ipm_dual_residual_gap * scale_obj))
    diverged = ~np.isfinite(pobj) | ~np.isfinite(dobj) | (xzinf > tol.ipm_divergence)
    return ok, diverged


def _ipm(schur, q, b, lay: _Layout, tol: Tolerances, AE_dense):
    B, m = q.shape
    p = lay.p
    nb = len(lay.sizes)
    bk = [b[:, lay.block(k)] for k in range(nb)]
    scale_s = np.maximum(1.0, np.abs(b).max(axis=1))
    scale_z = np.maximum(1.0, np.abs(q).max(axis=1))
    x = np.zeros((B, m))
    zE = np.zeros((B, p))
    S = [scale_s[:, None, None] * np.eye(n) for n in lay.sizes]
    Z = [scale_z[:, None, None] * np.eye(n) for n in lay.sizes]
    nb_inf = np.abs(b).max(axis=1)
    nq_inf = np.abs(q).max(axis=1)
    converged = np.zeros(B, bool)
    its = np.zeros(B, int)
    reason = [""] * B
    active = np.arange(B)
    step_frac = tol.ipm_step_fraction
    history = np.full((B, 5), np.inf)    # last merit values (gap + residuals) per instance
    for it in range(tol.ipm_max_iter + 1):
        if active.size == 0:
            break
        sch = schur if active.size == B else schur.subset(active)
        qa, ba = q[active], b[active]
        xa, zEa = x[active], zE[active]
        Sa = [Sk[active] for Sk in S]
        Za = [Zk[active] for Zk in Z]
        # residuals
        svs = [_svec_batch(Sk) for Sk in Sa]
        svz = [_svec_batch(Zk) for Zk in Za]
        rP = [bk[k][active] - sch.apply(k, xa) - svs[k] for k in range(nb)]
        rE = ba[:, :p] - sch.AE_apply(xa) if p else np.zeros((active.size, 0))
        rD = qa + (sch.AE_dot(zEa) if p else 0.0) + sum(sch.rhs_dot(k, svz[k]) for k in range(nb))
        pobj = np.einsum("bm,bm->b", qa, xa)
        dobj = -(np.einsum("bp,bp->b", ba[:, :p], zEa) + sum(np.einsum("bl,bl->b", bk[k][active], svz[k])
                                                             for k in range(nb)))
        xinf = np.abs(xa).max(axis=1) if m else np.zeros(active.size)
        sinf = np.max([np.abs(v).max(axis=1) for v in svs], axis=0)
        zinf = np.max([np.abs(v).max(axis=1) for v in svz] + ([np.abs(zEa).max(axis=1)] if p else []), axis=0)
        pres = np.max([np.abs(r).max(axis=1) for r in rP] + ([np.abs(rE).max(axis=1)] if p else []), axis=0)
        dres = np.abs(rD).max(axis=1) if m else np.zeros(active.size)
        gap = np.abs(pobj - dobj)
        ok, diverged = _stopping_rule(tol, pobj, dobj, np.einsum("bm,bm->b", rD, xa), pres, dres,
                                      nb_inf[active] + xinf + sinf, nq_inf[active] + zinf, np.maximum(xinf, zinf))
        # stalled: the merit has not halved over the last 4 iterations (the iterates sit on a
        # face from which the Newton direction makes no progress): hand over to the fallback
        merit = gap + pres + dres
        stalled = (it >= 8) & (merit > 0.5 * history[active, 0])
        history[active, :-1] = history[active, 1:]
        history[active, -1] = merit
        done = ok | diverged | stalled | (it == tol.ipm_max_iter)
        for j in np.nonzero(done)[0]:
            g = active[j]
            converged[g] = bool(ok[j])
            its[g] = it
            if not ok[j]:
                reason[g] = "diverged (infeasible or unbounded?)" if diverged[j] else (
                    "stalled" if stalled[j] else "iteration limit")
        keep = ~done
        if not keep.any():
            break
        if not keep.all():
            active = active[keep]
            continue   # recompute on the compressed set (cheap) to keep the code single-path
        # ---- Newton system
        try:
            Ra = [_inv_spd(Sk) for Sk in Sa]
        except np.linalg.LinAlgError:
            for g in active:
                reason[g] = "lost positive definiteness"
                its[g] = it
            break
        M = sch.M(Za, Ra)
        mu = sum(np.einsum("bij,bij->b", Sk, Zk) for Sk, Zk in zip(Sa, Za)) / lay.nu
        try:
            solveK = _solve_newton(M, AE_dense[active] if p else None, p)
        except np.linalg.LinAlgError:
            for g in active:
                reason[g] = "singular Schur complement"
                its[g] = it
            break

        rPm = [_smat_batch(r, n) for r, n in zip(rP, lay.sizes)]

        def direction(Kmats):
            # dZ = sym(K R) - Z - sym(Z dS R),  dS = smat(rP - A dx)
            rhs = -rD.copy()
            for k in range(nb):
                H = (Kmats[k] @ Ra[k] if Kmats[k] is not None else 0.0) - Za[k] - Za[k] @ rPm[k] @ Ra[k]
                rhs -= sch.rhs_dot(k, _svec_batch(H))
            if p:
                sol = solveK(np.concatenate([rhs, rE], axis=1))
                dx, dzE = sol[:, :m], sol[:, m:]
            else:
                dx, dzE = solveK(rhs), np.zeros((active.size, 0))
            dS, dZ = [], []
            for k in range(nb):
                dSk = rPm[k] - _smat_batch(sch.apply(k, dx), lay.sizes[k])
                T = Za[k] @ dSk @ Ra[k]
                KR = Kmats[k] @ Ra[k] if Kmats[k] is not None else 0.0
                dZk = KR - Za[k] - T
                dZk = 0.5 * (dZk + np.swapaxes(dZk, 1, 2))
                dS.append(dSk)
                dZ.append(dZk)
            return dx, dzE, dS, dZ

        def steps(dS, dZ):
            ap = np.min([_max_step(Sa[k], dS[k]) for k in range(nb)], axis=0)
            ad = np.min([_max_step(Za[k], dZ[k]) for k in range(nb)], axis=0)
            return ap, ad

        dx, dzE, dS, dZ = direction([None] * nb)
        ap, ad = steps(dS, dZ)
        ap1, ad1 = np.minimum(1.0, ap), np.minimum(1.0, ad)
        mu_aff = sum(np.einsum("bij,bij->b", Sa[k] + ap1[:, None, None] * dS[k], Za[k] + ad1[:, None, None] * dZ[k])
                     for k in range(nb)) / lay.nu
        sigma = np.clip((mu_aff / np.maximum(mu, 1e-300)) ** 3, 0.0, 1.0)
        Kc = [sigma[:, None, None] * mu[:, None, None] * np.eye(n) - dZ[k] @ dS[k] for k, n in enumerate(lay.sizes)]
        dx, dzE, dS, dZ = direction(Kc)
        ap, ad = steps(dS, dZ)
        ap = np.minimum(1.0, step_frac * ap)
        ad = np.minimum(1.0, step_frac * ad)
        x[active] = xa + ap[:, None] * dx
        if p:
            zE[active] = zEa + ad[:, None] * dzE
        for k in range(nb):
            S[k][active] = Sa[k] + ap[:, None, None] * dS[k]
            Z[k][active] = Za[k] + ad[:, None, None] * dZ[k]
    zfull = np.concatenate([zE] + [_svec_batch(Zk) for Zk in Z], axis=1)
    sfull = np.concatenate([np.zeros((B, p))] + [_svec_batch(Sk) for Sk in S], axis=1)
    pobj = np.einsum("bm,bm->b", q, x)
    dobj = -np.einsum("br,br->b", b, zfull)
    return IpmResult(converged, x, zfull, sfull, pobj, dobj, its, tuple(reason))


@with_single_threaded_blas
def ipm_solve_batch(A: np.ndarray, b: np.ndarray, q: np.ndarray, cones,
                    tolerances: Tolerances = DEFAULT_TOLERANCES) -> IpmResult:
    """Solve B instances of one structure: A (B, n_rows, m) dense, b (B, n_rows), q (B, m) or (m,)."""
    A = np.asarray(A, float)
    b = np.asarray(b, float)
    if A.ndim != 3:
        raise ValueError(f"A must have shape (batch, rows, columns), got {A.shape}")
    B, nr, m = A.shape
    q = np.broadcast_to(np.asarray(q, float), (B, m)).copy()
    if b.shape != (B, nr):
        raise ValueError(f"b must have shape {(B, nr)}, got {b.shape}")
    lay = layout_of(cones)
    if lay.n_rows != nr:
        raise ValueError(f"the cones cover {lay.n_rows} rows but A has {nr}")
    for name, arr in (("A", A), ("b", b), ("q", q)):
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} contains NaN or inf")
    return _ipm(_DenseSchur(A, lay), q, b, lay, tolerances, A[:, :lay.p, :])


@with_single_threaded_blas
def ipm_solve_sparse(A: sp.spmatrix, b: np.ndarray, q: np.ndarray, cones,
                     tolerances: Tolerances = DEFAULT_TOLERANCES) -> IpmResult:
    """One instance with sparse A; results with batch axis 1.

    One PSD block whose image-form columns mostly are *pair columns* (two entries, one of
    them in a row no other column touches, zero cost: the alpha of ``GramForm.IMAGE``) is
    solved in its reduced moment form (:class:`_MomentReduction`, Schur complement over the
    coefficient-matching rows with disjoint supports); anything else with the
    svec-Kronecker Schur complement of :class:`_SparseSchur`."""
    lay = layout_of(cones)
    A = A if sp.issparse(A) else sp.csr_matrix(A)
    if A.shape[0] != lay.n_rows:
        raise ValueError(f"the cones cover {lay.n_rows} rows but A has {A.shape[0]}")
    b = np.asarray(b, float).reshape(1, -1)
    q = np.asarray(q, float).reshape(1, -1)
    if lay.p == 0 and len(lay.sizes) == 1:
        Ac = sp.csc_matrix(A)     # the reduction reads columns: one conversion (none for a ConicProblem's A)
        Ac.sort_indices()
        red = _reduction_for(Ac, q[0], lay.sizes[0])
        if red is not None:
            res = red.solve(Ac, b[0], q[0], tolerances)
            if res is not None and res.converged[0]:
                return res
            # not converged (e.g. stalled on some Example 5 cases): the unreduced method next,
            # the caller's fallback (Clarabel) after that
    A = sp.csr_matrix(A)
    AE_dense = A[:lay.p].toarray()[None] if lay.p else None
    return _ipm(_SparseSchur(A, lay), q, b, lay, tolerances, AE_dense)


# --------------------------------------------------------------------------- one instance, reduced form
#: reduction plans by sparsity pattern (least recently used dropped beyond _REDUCTIONS_MAX)
_REDUCTIONS: OrderedDict = OrderedDict()
_REDUCTIONS_MAX = 32
#: the reduced form is used when pair columns are at least this fraction of all columns
#: (a structural choice: below it the reduction saves little; not a numerical tolerance)
_REDUCE_MIN_FRACTION = 0.25


def _reduction_for(A: sp.spmatrix, q: np.ndarray, n: int):
    """The cached :class:`_MomentReduction` of A's sparsity pattern (None: not reducible)."""
    A = sp.csc_matrix(A)
    A.sort_indices()
    key = (A.shape, n, hash(A.indptr.tobytes()), hash(A.indices.tobytes()), hash((q != 0).tobytes()))
    if key in _REDUCTIONS:
        _REDUCTIONS.move_to_end(key)
        return _REDUCTIONS[key]
    plan = _MomentReduction.build(A, q != 0, n)
    _REDUCTIONS[key] = plan
    while len(_REDUCTIONS) > _REDUCTIONS_MAX:
        _REDUCTIONS.popitem(last=False)
    return plan


_syevr = sla.lapack.dsyevr
_trtri = sla.lapack.dtrtri


def _max_step1(Li: np.ndarray, dX: np.ndarray) -> float:
    """Largest a with X + a dX >= 0 (inf when dX >= 0), X = L L^T > 0 given Li = L^-1."""
    T = Li @ dX @ Li.T
    w, _, _, _, info = _syevr(0.5 * (T + T.T), compute_v=0, range="I", il=1, iu=1)   # smallest eigenvalue
    if info:
        raise np.linalg.LinAlgError("eigenvalue computation failed")
    lam = float(w[0])
    return -1.0 / lam if lam < 0 else np.inf


class _MomentReduction:
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
    same Mehrotra/HKM method as :func:`_ipm`.  Its Schur complement
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
        if cand.size < _REDUCE_MIN_FRACTION * m:
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
        product; one set per thread, so a plan can be shared between threads) and the sparse
        vec(A_a) of this instance's values V."""
        m2, n, K = self.m2, self.n, self.K
        EF = sp.csr_matrix((V[self.ef_src], *self.ef_pattern), shape=(m2, n * n))
        bufs = getattr(self._local, "bufs", None)    # reused by later solves in the same thread
        if bufs is None:
            bufs = self._local.bufs = {"Zg": np.empty((m2, K, n)), "Rg": np.empty((m2, K, n)),
                                       "P": np.empty((m2, n, n)), "PT": np.empty((n * n, m2))}
        return dict(bufs, EF=EF, V=V)

    # ------------------------------------------------------------------ Schur complement
    def schur(self, Z: np.ndarray, R: np.ndarray, ws: dict) -> np.ndarray:
        """M_ab = <A_a, Z A_b R> for all a, b (``ws`` from :meth:`workspace`)."""
        m2, n = self.m2, self.n
        Zg, Rg, P, PT = ws["Zg"], ws["Rg"], ws["P"], ws["PT"]
        np.take(Z, self.Ipad, axis=0, out=Zg)
        np.multiply(Zg, ws["V"][:, :, None], out=Zg)
        np.take(R, self.Jpad, axis=0, out=Rg)
        for a, b, k in self.groups:                                         # P_b = Z A_b R
            np.matmul(Zg[a:b, :k].transpose(0, 2, 1), Rg[a:b, :k], out=P[a:b])
        np.copyto(PT, P.reshape(m2, n * n).T)
        return ws["EF"] @ PT       # M[a, b] = <A_a, P_b>; symmetric up to round-off (Cholesky reads one triangle)

    # ------------------------------------------------------------------ one instance
    def solve(self, A: sp.spmatrix, b: np.ndarray, q: np.ndarray, tol: Tolerances) -> IpmResult | None:
        """The image-form problem (A, b, q) through the moment form; None when the
        instance's values do not allow the reduction (a zero pivot A[p_j, j])."""
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
        ws = self.workspace(self.Fpad * e[self.Rpad])
        out = self._ipm(cq, AE, bE, e, ws, tol)
        y, zE, Smom, Zgram, conv, its, why = out
        s = _svec_batch(Zgram)
        x = np.zeros(self.m)
        x[self.w_cols] = -zE
        x[self.alpha_cols] = (b[self.prow] - s[self.prow]) / ap
        z = e * y[self.row2col]
        pobj = float(q @ x)
        dobj = float(-(b @ z))
        return IpmResult(np.array([conv]), x[None], z[None], s[None], np.array([pobj]), np.array([dobj]),
                         np.array([its]), (why,))

    def _ipm(self, cq, AE, bE, e, ws, tol: Tolerances):
        """Mehrotra predictor-corrector (HKM) on  min cq^T y, AE y = bE, smat(E^T y) >= 0;
        the same stopping rules as :func:`_ipm`.  Returns (y, zE, S, Z, converged, iterations, reason)."""
        n, m2, p = self.n, self.m2, AE.shape[0]
        row2col = self.row2col
        eye = np.eye(n)

        def Et(y):
            return e * y[row2col]

        def Ev(v):
            return np.bincount(row2col, e * v, minlength=m2)

        nb_inf = float(np.abs(bE).max()) if p else 0.0
        nq_inf = float(np.abs(cq).max())
        y, zE = np.zeros(m2), np.zeros(p)
        S = max(1.0, nb_inf) * eye
        Z = max(1.0, nq_inf) * eye
        history = [np.inf] * 5
        step_frac = tol.ipm_step_fraction
        reason, conv, it = "iteration limit", False, 0
        for it in range(tol.ipm_max_iter + 1):
            s, z = _svec_batch(S), _svec_batch(Z)
            rP = Et(y) - s
            rE = bE - AE @ y
            rD = cq + AE.T @ zE - Ev(z)
            pobj = float(cq @ y)
            dobj = -float(bE @ zE)
            xinf = float(np.abs(y).max())
            sinf = float(np.abs(s).max())
            zinf = max(float(np.abs(z).max()), float(np.abs(zE).max()) if p else 0.0)
            pres = max(float(np.abs(rP).max()), float(np.abs(rE).max()) if p else 0.0)
            dres = float(np.abs(rD).max())
            gap = abs(pobj - dobj)
            ok, diverged = _stopping_rule(tol, pobj, dobj, float(rD @ y), pres, dres, nb_inf + xinf + sinf,
                                          nq_inf + zinf, max(xinf, zinf))
            if ok:
                reason, conv = "", True
                break
            if diverged:
                reason = "diverged (infeasible or unbounded?)"
                break
            merit = gap + pres + dres
            if it >= 8 and merit > 0.5 * history[0]:
                reason = "stalled"
                break
            history = history[1:] + [merit]
            if it == tol.ipm_max_iter:
                break
            # ---- Newton system: [[M, AE^T], [AE, 0]], M by Cholesky, the equality rows by
            # the Cholesky factor of their Schur complement AE M^-1 AE^T
            try:
                Ls = np.linalg.cholesky(S)
                Li = _trtri(Ls, lower=1)[0]
                R = Li.T @ Li
                LiZ = _trtri(np.linalg.cholesky(Z), lower=1)[0]
                M = self.schur(Z, R, ws)
                # Cholesky of M + reg I, reg = ipm_schur_regularization * max diag, raised 100x
                # while M is numerically indefinite; the refinement in newton() uses M itself
                dmax = max(1.0, float(np.abs(np.diagonal(M)).max()))
                for k in range(3):
                    Mr = M.copy()
                    Mr[np.diag_indices(m2)] += tol.ipm_schur_regularization * 100.0 ** k * dmax
                    try:
                        cf = sla.cho_factor(Mr, lower=True, check_finite=False)
                        break
                    except np.linalg.LinAlgError:
                        if k == 2:
                            raise
                if p:
                    # AE^T vanishes on the leading rows: L^-1 AE^T = [0; L22^-1 AE2^T]
                    t0 = m2 - self.n_touched
                    C = sla.solve_triangular(cf[0][t0:, t0:], AE[:, t0:].T, lower=True, check_finite=False)
                    SE = C.T @ C
                    reg = tol.ipm_schur_regularization * max(1.0, float(np.abs(np.diagonal(SE)).max()))
                    SE[np.diag_indices(p)] += reg
                    cfe = sla.cho_factor(SE, lower=True, check_finite=False)
            except (np.linalg.LinAlgError, ValueError):
                reason = "singular Schur complement or lost positive definiteness"
                break
            mu = float(np.sum(S * Z)) / n

            Lc = cf[0]

            def base(r1, r2):
                # u = L^-1 r1; dz = SE^-1 (C^T u - r2); dy = L^-T (u - C dz), C = [0; C2] = L^-1 AE^T
                u = sla.solve_triangular(Lc, r1, lower=True, check_finite=False)
                if not p:
                    return sla.solve_triangular(Lc, u, lower=True, trans="T", check_finite=False), np.zeros(0)
                dz = sla.cho_solve(cfe, C.T @ u[t0:] - r2, check_finite=False)
                u[t0:] -= C @ dz
                return sla.solve_triangular(Lc, u, lower=True, trans="T", check_finite=False), dz

            def newton(r1, r2):
                dy, dz = base(r1, r2)
                e1 = r1 - M @ dy - AE.T @ dz
                e2 = r2 - AE @ dy
                ddy, ddz = base(e1, e2)
                return dy + ddy, dz + ddz

            rPm = _smat_batch(rP, n)
            ZrR = Z @ rPm @ R

            def direction(Kmat):
                KR = Kmat @ R if Kmat is not None else 0.0
                H = KR - Z - ZrR
                rhs = -rD + Ev(_svec_batch(H))
                dy, dz = newton(rhs, rE)
                dS = rPm + _smat_batch(Et(dy), n)
                dZ = KR - Z - Z @ dS @ R
                dZ = 0.5 * (dZ + dZ.T)
                # The linear equations of Z (coefficient matching, E svec(dZ) = rD + AE^T dz) hold
                # only up to the round-off of M, which grows like cond(S) as the moment matrix S
                # tends to rank one; restore them exactly on the shared entries (E is the identity
                # there), so the dual residual decreases by (1 - step) as in exact arithmetic.
                corr = np.zeros(self.L)
                corr[self.srow] = rD + AE.T @ dz - Ev(_svec_batch(dZ))
                return dy, dz, dS, dZ + _smat_batch(corr, n)

            dy, dz, dS, dZ = direction(None)
            ap1 = min(1.0, _max_step1(Li, dS))
            ad1 = min(1.0, _max_step1(LiZ, dZ))
            mu_aff = float(np.sum((S + ap1 * dS) * (Z + ad1 * dZ))) / n
            sigma = min(1.0, max(0.0, (mu_aff / max(mu, 1e-300)) ** 3))
            dy, dz, dS, dZ = direction(sigma * mu * eye - dZ @ dS)
            ap = min(1.0, step_frac * _max_step1(Li, dS))
            ad = min(1.0, step_frac * _max_step1(LiZ, dZ))
            y = y + ap * dy
            S = S + ap * dS
            zE = zE + ad * dz
            Z = Z + ad * dZ
        return y, zE, S, Z, conv, it, reason
