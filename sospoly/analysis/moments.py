"""Moment matrices with their monomial bases (SumOfSquares.jl's ``moment_matrix``, TSSOS's ``get_moment``).

The dual of the PSD cone of an SOS constraint u = b^T G b is a matrix M indexed by the same
basis b: at an optimal certificate of ``minimize`` (q = 1, Putinar) M[i, j] = L(b_i b_j) for the
linear functional L of the moment relaxation (Lasserre 2001), i.e. pseudo-moments of a measure
on the feasible set.  :class:`MomentMatrix` carries the basis as exponent rows (``basis``) and
readable monomials (:meth:`MomentMatrix.monomials`), the matrix normalised so that L(1) = 1 when
the constant monomial is in the basis, and the two ways to read the measure:

* :meth:`MomentMatrix.is_flat` -- the flat-extension test of Curto & Fialkow: rank M_d =
  rank M_{d-1} (M_{d-1} the submatrix of the monomials of degree <= d - 1); then M is the
  moment matrix of a measure with rank M atoms;
* :meth:`MomentMatrix.measure` / :meth:`MomentMatrix.atoms` -- the atoms and weights (Henrion & Lasserre
  2005 extraction, :func:`sospoly.analysis.extraction.extract_from_moment`, then nonnegative weights
  fitted to M; nothing is returned unless the atoms reproduce M).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..algebra.basis import MonomialIndex
from ..tolerances import DEFAULT_TOLERANCES, Tolerances
from .extraction import extract_from_moment

__all__ = ["MomentMatrix", "moment_matrices_of", "monomial_name"]


def monomial_name(exponent, gens) -> str:
    """``x*y^2`` for the exponent (1, 2) over (x, y); ``1`` for the constant."""
    parts = [g if e == 1 else f"{g}^{int(e)}" for g, e in zip(gens, exponent) if e]
    return "*".join(parts) if parts else "1"


@dataclass(frozen=True)
class MomentMatrix:
    """A moment matrix M (``matrix``) over the monomials ``basis`` (exponent rows over ``gens``):
    M[i, j] = L(b_i b_j).  ``name`` is the Gram block it is dual to."""
    name: str
    basis: np.ndarray
    matrix: np.ndarray
    gens: tuple

    def monomials(self) -> tuple:
        """The basis as readable monomials, e.g. ``('1', 'x', 'y', 'x^2', 'x*y', 'y^2')``."""
        return tuple(monomial_name(e, self.gens) for e in self.basis)

    def moment(self, exponent) -> float:
        """L(v^exponent) read from an entry b_i b_j = exponent (KeyError when no entry has that product)."""
        e = _exponent(exponent, self.basis.shape[1])
        for i, bi in enumerate(self.basis):
            rest = e - bi
            if np.all(rest >= 0):
                j = MonomialIndex(self.basis).find(rest[None], missing_ok=True)[0]
                if j >= 0:
                    return float(self.matrix[i, j])
        raise KeyError(f"no entry of this moment matrix has the monomial {tuple(int(t) for t in e)}")

    def rank(self, rel_tol: float = 1e-6) -> int:
        """Numerical rank: eigenvalues above ``rel_tol`` times the largest."""
        if isinstance(rel_tol, bool) or not isinstance(rel_tol, (int, float, np.integer, np.floating)) or \
                not 0 <= rel_tol < 1:
            raise ValueError(f"rel_tol must be a number in [0, 1), got {rel_tol!r}")
        lam = np.linalg.eigvalsh(self.matrix)
        return int(np.sum(lam > rel_tol * max(float(lam[-1]), 1e-300)))

    def is_flat(self, rel_tol: float = 1e-6) -> bool:
        """Curto-Fialkow flatness: rank of M equals the rank of its lower-degree submatrix."""
        deg = self.basis.sum(axis=1)
        low = deg < deg.max()
        if not low.any():
            return False
        sub = MomentMatrix(self.name, self.basis[low], self.matrix[np.ix_(low, low)], self.gens)
        return self.rank(rel_tol) == sub.rank(rel_tol)

    @property
    def variables(self) -> tuple:
        """Indices of the generators that occur in the basis (all of them for a dense certificate, one
        clique's for a correlative-sparsity block)."""
        return tuple(int(k) for k in np.nonzero(self.basis.max(axis=0) > 0)[0])

    def atoms(self, tol: Tolerances = DEFAULT_TOLERANCES, span_tol: float = 1e-3, fit_tol: float = 1e-3) -> list:
        """Atoms of the measure: points over :attr:`variables` (the points of :meth:`measure`)."""
        return [p for p, _ in self.measure(tol, span_tol, fit_tol)]

    def measure(self, tol: Tolerances = DEFAULT_TOLERANCES, span_tol: float = 1e-3, fit_tol: float = 1e-3) -> list:
        """(point, weight) pairs of an atomic measure whose moment matrix is M: candidate points from the
        Henrion-Lasserre extraction on M's range (b(p) in the range to ``span_tol``), weights by nonnegative
        least squares on sum_k w_k b(p_k) b(p_k)^T = M; [] unless that fit holds to ``fit_tol`` relative
        (then M is, to that accuracy, the moment matrix of these atoms).  Needs 1 and every variable of
        :attr:`variables` in the basis (ValueError otherwise)."""
        from scipy.optimize import nnls

        cols = list(self.variables)
        B = self.basis[:, cols]
        pts = []
        if not isinstance(tol, Tolerances):
            raise TypeError(f"tol must be a sospoly.Tolerances, got {type(tol).__name__}")
        for c in sorted(extract_from_moment(self.matrix, B, tol), key=lambda c: c.span_residual):
            p = np.asarray(c.point, float)
            if c.span_residual <= span_tol and np.all(np.isfinite(p)) and \
                    all(np.linalg.norm(p - q) > 1e-4 * max(1.0, np.linalg.norm(q)) for q in pts):
                pts.append(p)
        if not pts:
            return []
        V = np.array([np.prod(p[None, :] ** B, axis=1) for p in pts])           # b(p_k), one row each
        A = np.stack([np.outer(v, v).ravel() for v in V], axis=1)
        w, resid = nnls(A, self.matrix.ravel())
        if resid > fit_tol * max(1.0, float(np.linalg.norm(self.matrix))):
            return []
        keep = w > fit_tol * max(float(w.max()), 1e-300)
        return [(p, float(wk)) for p, wk, k in zip(pts, w, keep) if k]


def _normalised(M: np.ndarray, basis: np.ndarray) -> np.ndarray:
    const = MonomialIndex(basis).find(np.zeros((1, basis.shape[1]), np.int64), missing_ok=True)[0]
    if const >= 0 and M[const, const] > 0:
        return M / M[const, const]
    return M


def _exponent(exponent, n_vars: int) -> np.ndarray:
    """An exponent tuple of ``n_vars`` non-negative integers (ValueError naming ``exponent`` otherwise)."""
    try:
        raw = np.asarray(exponent)
    except (TypeError, ValueError):
        raw = np.asarray(None)
    ok = raw.dtype.kind in "iu" or (raw.dtype.kind == "f" and np.all(np.isfinite(raw)) and np.all(raw == np.round(raw)))
    if not ok or raw.shape != (n_vars,) or np.any(raw < 0):
        raise ValueError(f"exponent must be {n_vars} non-negative integers, got {exponent!r}")
    return raw.astype(np.int64)


def moment_matrices_of(constraint, solution, scale_exponents=None) -> tuple:
    """The moment matrices of an SOS constraint's Gram blocks in a solved program (one per block, basis
    from the constraint's :class:`~sospoly.algebra.basis.GramBlocks`).  ``scale_exponents`` k (n,): the program
    was solved in w with v = 2^k w (:class:`sospoly.scaling.VariableScaling`); the moments are returned in v,
    L(v^a v^b) = 2^{(a + b) . k} L(w^a w^b) (exact powers of two)."""
    if solution is None or not solution.moments:
        return ()
    out = []
    for name, blk in zip(constraint.block_names(), constraint.gram.blocks):
        M = solution.moments.get(name)
        if M is not None and np.all(np.isfinite(M)):
            M = np.asarray(M, float)
            if scale_exponents is not None and np.any(scale_exponents):
                e = np.asarray(blk.b, np.int64) @ np.asarray(scale_exponents, np.int64)
                with np.errstate(over="ignore"):        # (moments past the float range: inf, as reported)
                    M = np.ldexp(M, e[:, None] + e[None, :])
            out.append(MomentMatrix(name, np.asarray(blk.b), _normalised(M, blk.b), tuple(constraint.expr.gens)))
    return tuple(out)
