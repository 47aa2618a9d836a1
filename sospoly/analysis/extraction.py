"""Extraction of minimisers from an optimal Gram matrix or moment matrix (SPEC §6).

At an optimal certificate u*(v) = b(v)^T U* b(v) with U* >= 0, every minimiser v*
satisfies b(v*) in ker(U*) (the paper's (51)); dually, the moment matrix M has
b(v*) b(v*)^T in its range.  Both give a matrix W whose column span contains
b(v*) for every minimiser; then

* if dim span W = 1, v* is read from W's degree-1 entries after scaling the
  constant monomial's entry to 1;
* otherwise the Henrion-Lasserre procedure (2005) is applied: column echelon
  form of W, multiplication matrices N_k for each variable on the echelon
  monomials, a random combination's ordered Schur decomposition, and the points
  read from the common eigenvectors.  It needs the echelon monomials x_k * beta
  to stay in the basis (flat extension); when they do not (e.g. half-degree 1)
  the kernel vectors themselves are returned as candidates, scaled as above.

Candidates are only *candidates*: callers evaluate feasibility and the objective.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from ..algebra.basis import MonomialIndex
from ..budget import deadline_passed
from ..tolerances import DEFAULT_TOLERANCES, Tolerances

__all__ = ["Candidate", "CandidateFamily", "kernel_family", "best_in_family", "kernel_basis", "range_basis",
           "candidates_from_span", "extract_from_gram",
           "extract_from_moment", "henrion_lasserre", "has_constant_entry", "KERNEL_CONSTANT_RTOL", "lowered_exponents",
           "monomial_jacobian", "OBJECTIVE_ERRORS"]

#: a kernel vector w gives the candidate w[degree-1 rows] / w[0] only when |w[0]| > KERNEL_CONSTANT_RTOL max |w|
#: (else its constant entry is numerically zero and the quotient meaningless).
KERNEL_CONSTANT_RTOL = 1e-10


@dataclass(frozen=True)
class Candidate:
    """A minimiser candidate ``point`` read from a span (``source``: gram, moment, -hl, -span, -mean) with
    its relative span residual."""
    point: np.ndarray
    source: str             # "gram-kernel", "gram-hl", "moment", "moment-hl"
    span_residual: float    # ||b(v) - proj_W b(v)|| / ||b(v)||


def has_constant_entry(w) -> np.ndarray | bool:
    """Whether kernel vectors ``w`` (along the last axis; the first entry multiplies the monomial 1) have a
    usable constant entry: |w_0| > KERNEL_CONSTANT_RTOL max_k |w_k| (vectorised over leading axes)."""
    w = np.asarray(w, float)
    out = np.abs(w[..., 0]) > KERNEL_CONSTANT_RTOL * np.maximum(np.max(np.abs(w), axis=-1), 1e-300)
    return bool(out) if out.ndim == 0 else out


def _degree1_rows(basis: np.ndarray) -> np.ndarray | None:
    n = basis.shape[1]
    index = MonomialIndex(basis)
    idx = index.find(np.eye(n, dtype=np.int64), missing_ok=True)
    const = index.find(np.zeros((1, n), dtype=np.int64), missing_ok=True)
    if np.any(idx < 0) or const[0] != 0:
        return None
    return idx


def kernel_basis(G: np.ndarray, tol: Tolerances = DEFAULT_TOLERANCES) -> np.ndarray:
    """Orthonormal eigenvectors of the (numerically) zero eigenvalues of G; at least one."""
    lam, V = np.linalg.eigh(G)
    top = max(abs(lam[-1]), 1e-300)
    r = max(1, int(np.sum(lam <= tol.kernel_rel * top)))
    return V[:, :r]


def range_basis(M: np.ndarray, tol: Tolerances = DEFAULT_TOLERANCES) -> np.ndarray:
    """sqrt(lambda)-scaled eigenvectors of the numerically non-zero eigenvalues of M."""
    lam, V = np.linalg.eigh(M)
    top = max(lam[-1], 1e-300)
    keep = lam >= tol.moment_rank_rel * top
    if not keep.any():
        keep[-1] = True
    return V[:, keep][:, ::-1] * np.sqrt(np.maximum(lam[keep][::-1], 0.0))


def _span_residual(W: np.ndarray, basis: np.ndarray, point: np.ndarray) -> float:
    bv = np.prod(point[None, :] ** basis, axis=1)
    Q, _ = np.linalg.qr(W)
    r = bv - Q @ (Q.T @ bv)
    return float(np.linalg.norm(r) / max(np.linalg.norm(bv), 1e-300))


def _column_echelon(W: np.ndarray, pivot_tol: float) -> tuple[np.ndarray, list[int]]:
    """U with U[pivots] = I and span U = span W (Gauss-Jordan on W^T)."""
    A = W.T.copy()
    r, s = A.shape
    pivots = []
    row = 0
    for col in range(s):
        if row >= r:
            break
        k = row + int(np.argmax(np.abs(A[row:, col])))
        if abs(A[k, col]) <= pivot_tol:
            A[row:, col] = 0.0
            continue
        A[[row, k]] = A[[k, row]]
        A[row] /= A[row, col]
        others = np.arange(r) != row
        A[others] -= np.outer(A[others, col], A[row])
        pivots.append(col)
        row += 1
    return A[: len(pivots)].T, pivots


def henrion_lasserre(W: np.ndarray, basis: np.ndarray, seed: int = 0) -> list[np.ndarray] | None:
    """Points whose b(v) span span(W), or None when the basis is too small (no flat extension)."""
    n = basis.shape[1]
    scale = max(np.max(np.abs(W)), 1e-300)
    U, piv = _column_echelon(W / scale, pivot_tol=1e-8)
    r = len(piv)
    if r == 0:
        return None
    index = MonomialIndex(basis)
    B = basis[piv]
    Ns = []
    for k in range(n):
        shifted = B.copy()
        shifted[:, k] += 1
        rows = index.find(shifted, missing_ok=True)
        if np.any(rows < 0):
            return None
        Ns.append(U[rows, :])
    rng = np.random.default_rng(seed)
    lam = rng.random(n)
    lam /= lam.sum()
    N = sum(l * Nk for l, Nk in zip(lam, Ns))
    T, Q = sla.schur(N, output="real")
    return [np.array([Q[:, j] @ Nk @ Q[:, j] for Nk in Ns]) for j in range(r)]


#: span-residual searches run for spans of dimension > 1 with at most this many variables, from at most
#: SPAN_SEARCH_STARTS starting points (a few ms each).
SPAN_SEARCH_MAX_VARS = 30
SPAN_SEARCH_STARTS = 8
#: residual evaluations per start (Levenberg-Marquardt with the analytic Jacobian converges in a few
#: iterations near a point of the span; runs that need more are not converging)
SPAN_SEARCH_EVALS = 60


def lowered_exponents(E: np.ndarray) -> np.ndarray:
    """L (n, s, n) with L[j] = E with column j lowered by one (0 stays 0): the exponents of d b / d v_j."""
    n = E.shape[1]
    return np.stack([np.where(np.arange(n)[None, :] == j, np.maximum(E - 1, 0), E) for j in range(n)])


def monomial_jacobian(v: np.ndarray, E: np.ndarray, lowered: np.ndarray) -> np.ndarray:
    """D (s, n), D_ij = d b_i / d v_j = E_ij v^(E_i - e_j) for the monomials b_i = v^(E_i) (``lowered`` from
    :func:`lowered_exponents`): one stacked expression, equal bit for bit to the column loop
    ``E[:, j] * prod(v ** lowered[j], axis=1)`` (the same products in the same order; tests/test_candidate_cost.py)."""
    return (E.T * np.prod(v ** lowered, axis=2)).T


def span_search(W: np.ndarray, basis: np.ndarray, starts, seed: int = 0) -> list[np.ndarray]:
    """Points v with b(v) in span(W), found by minimising the relative span residual
    ||(I - Q Q^T) b(v)|| / ||b(v)|| (Q an orthonormal basis of span W) from the given starts and a few
    seeded random ones.  A fallback when the span is not *flat* (Henrion-Lasserre needs a flat extension;
    interior-point solutions often sit at the centre of a face and mix minimisers with spurious
    directions).  Past the active deadline (:func:`sospoly.budget.deadline_passed`) no further start is
    searched: the points found so far are returned."""
    from scipy.optimize import least_squares

    n = basis.shape[1]
    if n > SPAN_SEARCH_MAX_VARS:
        return []
    Q, _ = np.linalg.qr(W)
    E = np.asarray(basis, np.int64)

    def resid(v):
        with np.errstate(over="ignore", invalid="ignore"):
            bv = np.prod(v[None, :] ** E, axis=1)
        nb = np.linalg.norm(bv)
        r = (bv - Q @ (Q.T @ bv)) / max(nb, 1e-300)
        return np.where(np.isfinite(r), r, 1e6)

    # analytic Jacobian: d b_i / d v_j = E_ij v^(E_i - e_j); r = P b / |b| with P = I - Q Q^T
    lowered = lowered_exponents(E)

    def jac(v):
        with np.errstate(over="ignore", invalid="ignore"):
            bv = np.prod(v[None, :] ** E, axis=1)
            D = monomial_jacobian(v, E, lowered)
            nb = max(np.linalg.norm(bv), 1e-300)
            J = D / nb - np.outer(bv, bv @ D) / nb ** 3
            J = J - Q @ (Q.T @ J)
        return np.where(np.isfinite(J), J, 0.0)

    rng = np.random.default_rng(seed)
    pts = [np.asarray(s, float) for s in starts if np.all(np.isfinite(s)) and np.linalg.norm(s) < 1e6]
    pts += list(rng.standard_normal((max(0, SPAN_SEARCH_STARTS - len(pts)), n)))
    found = []
    for v0 in pts[:SPAN_SEARCH_STARTS]:
        if deadline_passed():           # the points found so far (every candidate is checked by its caller)
            break
        try:
            res = least_squares(resid, v0, jac=jac, method="lm", xtol=1e-14, ftol=1e-14, max_nfev=SPAN_SEARCH_EVALS)
        except (ValueError, np.linalg.LinAlgError):
            continue
        if np.all(np.isfinite(res.x)) and np.linalg.norm(res.fun) <= 1e-6:
            found.append(res.x)
    return found


def candidates_from_span(W: np.ndarray, basis: np.ndarray, source: str) -> list[Candidate]:
    deg1 = _degree1_rows(basis)
    if deg1 is None:
        raise ValueError("the Gram basis must contain 1 and every variable to read minimisers")
    out: list[Candidate] = []
    if W.shape[1] > 1:
        pts = henrion_lasserre(W, basis)
        if pts is not None:
            out += [Candidate(p, source + "-hl", _span_residual(W, basis, p)) for p in pts if np.all(np.isfinite(p))]
        starts = [p for p in (pts or [])]
        starts += [W[deg1, k] / W[0, k] for k in range(W.shape[1]) if abs(W[0, k]) > 1e-10]
        out += [Candidate(p, source + "-span", _span_residual(W, basis, p)) for p in span_search(W, basis, starts)]
    for k in range(W.shape[1]):
        w = W[:, k]
        if has_constant_entry(w):
            p = w[deg1] / w[0]
            out.append(Candidate(p, source, _span_residual(W, basis, p)))
    if W.shape[1] > 1:
        # the vector of the span with unit constant entry closest to the first moments
        c0 = W[0, :]
        if np.linalg.norm(c0) > 1e-12:
            a = c0 / (c0 @ c0)
            p = (W @ a)[deg1]
            out.append(Candidate(p, source + "-mean", _span_residual(W, basis, p)))
    return out


def _matrix_and_basis(M, basis, what: str) -> tuple[np.ndarray, np.ndarray]:
    """``M`` as a square float matrix of the side of ``basis`` (rows: exponent vectors), or ValueError naming
    ``what`` (review 26a F9: sizes that disagree raised IndexError deep inside)."""
    M = np.asarray(M, dtype=float)
    basis = np.asarray(basis)
    if basis.ndim != 2 or not basis.shape[0]:
        raise ValueError(f"{what}: the basis must be a non-empty 2-D array of exponent rows, got shape {basis.shape}")
    if M.ndim != 2 or M.shape != (basis.shape[0], basis.shape[0]):
        raise ValueError(f"{what}: the matrix must be {basis.shape[0]} x {basis.shape[0]} (one row per basis "
                         f"monomial), got shape {M.shape}")
    return M, basis


def extract_from_gram(G: np.ndarray, basis: np.ndarray, tol: Tolerances = DEFAULT_TOLERANCES) -> list[Candidate]:
    """Candidates v* with b(v*) in the numerical kernel of the optimal Gram matrix (ValueError for a matrix
    that does not match the basis or is not finite)."""
    G, basis = _matrix_and_basis(G, basis, "extract_from_gram")
    if not np.all(np.isfinite(G)):
        raise ValueError("extract_from_gram: the Gram matrix has non-finite entries")
    return candidates_from_span(kernel_basis(G, tol), basis, "gram")


def extract_from_moment(M: np.ndarray, basis: np.ndarray, tol: Tolerances = DEFAULT_TOLERANCES) -> list[Candidate]:
    """Candidates from the moment (dual) matrix with a rank test (none from a non-finite matrix or one whose
    (0, 0) entry is not positive; ValueError for a matrix that does not match the basis)."""
    M, basis = _matrix_and_basis(M, basis, "extract_from_moment")
    if not np.all(np.isfinite(M)) or M[0, 0] <= 0:
        return []
    return candidates_from_span(range_basis(M / M[0, 0], tol), basis, "moment")


@dataclass(frozen=True)
class CandidateFamily:
    """All candidates the numerical kernel offers: v(t) = (W a(t))[deg-1 rows] / (W a(t))[0],
    with a(t) = a0 + Z t ranging over the coefficient vectors whose constant entry is 1.

    When the Gram kernel has dimension k > 1 the paper's rule ("eigenvectors of the
    smallest eigenvalue") leaves a (k-1)-dimensional family; :func:`best_in_family`
    searches it for the member that is best for the caller's own criterion.
    """
    W: np.ndarray
    deg1: np.ndarray
    a0: np.ndarray
    Z: np.ndarray

    @property
    def dim(self) -> int:
        return self.Z.shape[1]

    def point(self, t) -> np.ndarray:
        w = self.W @ (self.a0 + self.Z @ np.asarray(t, float))
        return w[self.deg1] / w[0]


def kernel_family(G: np.ndarray, basis: np.ndarray, tol: Tolerances = DEFAULT_TOLERANCES) -> CandidateFamily | None:
    W = kernel_basis(G, tol)
    deg1 = _degree1_rows(basis)
    c0 = W[0, :]
    if deg1 is None or np.linalg.norm(c0) < 1e-12:
        return None
    a0 = c0 / (c0 @ c0)
    # orthonormal basis of {a : c0 . a = 0}
    _, _, Vt = np.linalg.svd(c0[None, :])
    Z = Vt[1:].T
    return CandidateFamily(W, deg1, a0, Z)


#: the errors of an objective that :func:`best_in_family` counts as +inf (a candidate it cannot evaluate)
OBJECTIVE_ERRORS = (ValueError, FloatingPointError, np.linalg.LinAlgError)


def best_in_family(family: CandidateFamily, objective, max_evals: int = 400,
                   objective_many=None) -> tuple[np.ndarray, float]:
    """Minimise ``objective(v)`` over the family (Nelder-Mead from several starts), with at most about
    ``max_evals`` evaluations of ``objective`` in all (a third for the scan of a one-parameter family, the
    rest shared by the starts).  ``objective_many``: the vectorised twin of ``objective`` (points (m, n) ->
    values (m,), the same numbers), used for the scan; an evaluation that raises (ValueError,
    FloatingPointError, LinAlgError) or is not finite counts as +inf either way.  Past the active deadline
    (:func:`sospoly.budget.deadline_passed`) no further start is searched, and a search under way stops: the best
    member so far is returned."""

    def obj_t(t):
        try:
            val = float(objective(family.point(t)))
        except OBJECTIVE_ERRORS:
            return np.inf
        return val if np.isfinite(val) else np.inf

    def scan(grid):
        if objective_many is not None:
            try:
                vals = np.asarray(objective_many(np.array([family.point([t]) for t in grid])), float)
                return np.where(np.isfinite(vals), vals, np.inf)
            except OBJECTIVE_ERRORS:
                pass
        return np.array([obj_t([t]) for t in grid])

    starts = [np.zeros(family.dim)]
    for k in range(family.W.shape[1]):
        # the coefficient vector of the k-th kernel vector, rescaled to unit constant entry
        if abs(family.W[0, k]) > 1e-12:
            a = np.eye(family.W.shape[1])[k] / family.W[0, k]
            starts.append(family.Z.T @ (a - family.a0))
    best_t, best_v = starts[0], obj_t(starts[0])
    if family.dim == 0:
        return family.point(best_t), best_v
    if family.dim == 1:
        # a one-parameter family: scan it whole (t = tan(theta) reaches both ends) first
        grid = np.tan(np.linspace(-np.pi / 2, np.pi / 2, max(8, max_evals // 3) + 2)[1:-1])
        vals = scan(grid)
        starts += [np.array([grid[k]]) for k in np.argsort(vals)[:3]]
        max_evals -= grid.size
    per_start = max(10, max_evals // len(starts))
    for t0 in starts:
        if deadline_passed():           # the best member so far (any member is a legitimate candidate)
            break
        t, v, stopped = _nelder_mead_until_deadline(obj_t, t0, per_start)
        if v < best_v:
            best_t, best_v = t, v
        if stopped:
            break
    return family.point(best_t), best_v


class _DeadlinePassed(Exception):
    """Raised inside a Nelder-Mead run when the active deadline passes (:func:`_nelder_mead_until_deadline`)."""


def _nelder_mead_until_deadline(objective, t0, maxfev: int) -> tuple:
    """(t, objective(t), stopped): scipy's Nelder-Mead from ``t0`` (at most ``maxfev`` evaluations; its result,
    the best vertex, is the best point it evaluated), or -- when the active deadline passes during the run (one
    evaluation of gamma through the regions' closest points is ~1 ms at 6 mixed regions, a run several hundred)
    -- the best point evaluated so far (``stopped``; (t0, inf) when none was)."""
    from scipy.optimize import minimize as sp_min

    seen = {"t": np.asarray(t0, float), "v": np.inf}

    def watched(t):
        if deadline_passed():
            raise _DeadlinePassed
        v = objective(t)
        if v < seen["v"]:
            seen["t"], seen["v"] = np.array(t, float), v
        return v

    try:
        res = sp_min(watched, t0, method="Nelder-Mead", options={"maxfev": maxfev, "xatol": 1e-10, "fatol": 1e-12})
    except _DeadlinePassed:
        return seen["t"], seen["v"], True
    return res.x, float(res.fun), False
