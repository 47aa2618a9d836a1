"""A small batched primal-dual interior-point method for LMIs in dual form.

The conic standard form of :mod:`sospoly.conic` (Clarabel's)::

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
  on svec space (size n(n+1)/2), then M = A^T W A with sparse A (for Theorem 1
  delta = 4, where A's columns have <= 4 entries except the r_k columns).

Stopping rule (Clarabel's, with :class:`~sospoly.tolerances.Tolerances`):
|pobj - dobj| <= solver_gap_abs or <= solver_gap_rel min(|pobj|, |dobj|);
||A x + s - b||_inf <= solver_feas max(1, ||b|| + ||x|| + ||s||);
||A^T z + q||_inf <= solver_feas max(1, ||q|| + ||z||).  An instance that does not
meet it within ``ipm_max_iter`` iterations, or whose iterates diverge (infeasible
or unbounded problems: this method has no infeasibility certificates), is reported
``converged = False``; callers fall back to Clarabel.  Nothing here is trusted
either way: the a-posteriori certificate checks of :mod:`sospoly.solve` run on the
returned x.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from .svec import svec_scale, triu_pairs
from .tolerances import DEFAULT_TOLERANCES, Tolerances

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


def _ipm(schur, q, b, lay: _Layout, tol: Tolerances, AE_dense):
    B, m = q.shape
    p = lay.p
    nb = len(lay.sizes)
    bE = b[:, :p]
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
        feas_ok = (pres <= tol.solver_feas * np.maximum(1.0, nb_inf[active] + xinf + sinf)) \
            & (dres <= tol.solver_feas * np.maximum(1.0, nq_inf[active] + zinf))
        ok = ((gap <= tol.solver_gap_abs) | (gap <= tol.solver_gap_rel * np.minimum(np.abs(pobj), np.abs(dobj)))) \
            & feas_ok
        # pobj - dobj = <S, Z> + z^T rP + rD^T x exactly.  With large multipliers x (nearly dependent
        # constraints) the last term stalls above the gap tolerance although the iterate is optimal
        # to working precision; accept when the complementarity part meets the gap tolerance and
        # rD^T x stays below ipm_dual_residual_gap relative (Tolerances documents the bound).
        rdx = np.abs(np.einsum("bm,bm->b", rD, xa))
        comp = np.abs(pobj - dobj - np.einsum("bm,bm->b", rD, xa))
        scale_obj = np.maximum(1.0, np.abs(pobj))
        ok |= feas_ok & ((comp <= tol.solver_gap_abs) | (comp <= tol.solver_gap_rel * scale_obj)) \
            & (rdx <= tol.ipm_dual_residual_gap * scale_obj)
        diverged = ~np.isfinite(pobj) | ~np.isfinite(dobj) | (np.maximum(xinf, zinf) > tol.ipm_divergence)
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


def ipm_solve_sparse(A: sp.spmatrix, b: np.ndarray, q: np.ndarray, cones,
                     tolerances: Tolerances = DEFAULT_TOLERANCES) -> IpmResult:
    """One instance with sparse A (svec-Kronecker Schur complement); results with batch axis 1."""
    lay = layout_of(cones)
    A = sp.csr_matrix(A)
    if A.shape[0] != lay.n_rows:
        raise ValueError(f"the cones cover {lay.n_rows} rows but A has {A.shape[0]}")
    b = np.asarray(b, float).reshape(1, -1)
    q = np.asarray(q, float).reshape(1, -1)
    AE_dense = A[:lay.p].toarray()[None] if lay.p else None
    return _ipm(_SparseSchur(A, lay), q, b, lay, tolerances, AE_dense)
