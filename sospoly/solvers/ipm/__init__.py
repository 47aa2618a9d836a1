"""A small batched primal-dual interior-point method for LMIs in dual form.

One Mehrotra predictor-corrector skeleton (:mod:`.core`, HKM direction, Clarabel's stopping rule)
with pluggable operators: dense batched A (:class:`.operators.DenseOperator`), one instance with
sparse A (:class:`.operators.SparseOperator`) and the reduced moment form of a single-block image-form
LMI (:class:`.moment.MomentReduction`).  Nothing here is trusted: the a-posteriori certificate checks
of :mod:`sospoly.solvers.solve` run on the returned x, and callers fall back to Clarabel when an
instance did not converge.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ...tolerances import DEFAULT_TOLERANCES, Tolerances, as_tolerances
from ..blas import with_single_threaded_blas
from .core import IPM_LEVEL, IpmResult, Layout, layout_of, mehrotra, result_of, stopping_rule
from .moment import MomentReduction, reduction_for
from .operators import DenseOperator, SparseOperator

__all__ = ["IPM_LEVEL", "IpmResult", "Layout", "layout_of", "stopping_rule", "ipm_solve_batch", "ipm_solve_sparse",
           "MomentReduction"]


@with_single_threaded_blas
def ipm_solve_batch(A: np.ndarray, b: np.ndarray, q: np.ndarray, cones,
                    tolerances: Tolerances = DEFAULT_TOLERANCES, *, deadline=None) -> IpmResult:
    """Solve B instances of one structure: A (B, n_rows, m) dense, b (B, n_rows), q (B, m) or (m,)."""
    tolerances = as_tolerances(tolerances)
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
    it_, conv, its, why = mehrotra(DenseOperator(A, lay), q, b, lay, tolerances, deadline)
    return result_of(it_, conv, its, why, q, b, lay)


@with_single_threaded_blas
def ipm_solve_sparse(A: sp.spmatrix, b: np.ndarray, q: np.ndarray, cones,
                     tolerances: Tolerances = DEFAULT_TOLERANCES, *, deadline=None,
                     stop_at: float | None = None, almost=None) -> IpmResult:
    """One instance with sparse A; results with batch axis 1.

    One PSD block whose image-form columns mostly are *pair columns* (two entries, one of them in a
    row no other column touches, zero cost: the alpha of ``GramForm.IMAGE``) is solved in its reduced
    moment form (:class:`MomentReduction`); anything else (and a reduced solve that did not converge)
    with the svec-Kronecker Schur complement of :class:`SparseOperator`.  ``stop_at``: the moment form stops
    at an iterate with q^T x <= stop_at (reason ``IPM_LEVEL``, :mod:`sospoly.solvers.level`); the other form
    ignores it.  ``almost``: a predicate on the moment form's result; a stalled moment form whose iterate it
    accepts is returned as it is (reason ``"stalled"``, not converged: the caller takes it as "almost solved",
    :func:`sospoly.solvers.backends.ipm_almost_solved`) instead of starting the unreduced method afresh (measured:
    three-view Theorem 1 programs at delta = 4 stalling after 10 iterations at relative gaps 4e-9..2e-8, residuals
    ~1e-12; the unreduced method then took 50-90 ms more, benchmarks/RESULTS.md, wave 23)."""
    tolerances = as_tolerances(tolerances)
    lay = layout_of(cones)
    A = A if sp.issparse(A) else sp.csr_matrix(A)
    if A.shape[0] != lay.n_rows:
        raise ValueError(f"the cones cover {lay.n_rows} rows but A has {A.shape[0]}")
    b = np.asarray(b, float).reshape(1, -1)
    q = np.asarray(q, float).reshape(1, -1)
    if lay.p == 0 and len(lay.sizes) == 1:
        Ac = sp.csc_matrix(A)     # the reduction reads columns: one conversion (none for a ConicProblem's A)
        Ac.sort_indices()
        red = reduction_for(Ac, q[0], lay.sizes[0])
        if red is not None and red.m2 < A.shape[1]:      # only when the moment form is the smaller system
            res = red.solve(Ac, b[0], q[0], tolerances, deadline, stop_at)
            if res is not None and (res.converged[0] or res.reason[0] in ("time limit", IPM_LEVEL)):
                return res
            if res is not None and res.reason[0] == "stalled" and almost is not None and almost(res):
                return res
            # not converged (e.g. stalled on some Example 5 cases): the unreduced method next,
            # the caller's fallback (Clarabel) after that
    it_, conv, its, why = mehrotra(SparseOperator(A, lay), q, b, lay, tolerances, deadline)
    return result_of(it_, conv, its, why, q, b, lay)
