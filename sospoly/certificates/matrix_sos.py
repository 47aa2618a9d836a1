"""Matrix sum-of-squares constraints (SumOfSquares.jl's ``SOSMatrixCone``).

A symmetric m x m polynomial matrix M(v) is *SOS* when M(v) = H(v)^T H(v) for a polynomial matrix
H, equivalently when y^T M(v) y is SOS in (v, y) with a Gram basis y (x) b(v) (Gram on y (x) b(v)):

    M(v) = (I_m (x) b(v))^T G (I_m (x) b(v)),     G = G^T PSD of side m |b|,

i.e. entry by entry  M_kl(v) = sum_{i,j} G[(k,i),(l,j)] b_i(v) b_j(v),  with (k,i) the row k |b| + i.
b holds every monomial of degree <= deg/2 (deg the largest entry degree, rounded up to even), or
the given ``basis``.  :meth:`SOSProgram.add_sos_matrix` adds a PSD matrix variable G and one
polynomial identity per entry; the lowered problem is a zero cone and one PSD block.

Extraction: G = sum_r lambda_r w_r w_r^T gives M(v) = sum_r h_r(v) h_r(v)^T with
h_r(v)_k = sqrt(lambda_r) sum_i w_r[(k,i)] b_i(v) (:meth:`MatrixSOSConstraint.factors`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..algebra.basis import even_degree, exponent_rows, monomials
from ..algebra.linpoly import LinPoly
from ..algebra.polynomial import Polynomial

__all__ = ["MatrixSOSConstraint", "add_sos_matrix"]


@dataclass(frozen=True)
class MatrixSOSConstraint:
    """A matrix SOS constraint: its Gram block name (``solution.grams[name]``), the size m of M and the
    monomial basis b (exponent rows) of the Gram matrix on y (x) b(v)."""
    name: str
    m: int
    basis: np.ndarray
    gens: tuple

    def gram(self, solution) -> np.ndarray:
        """G, the PSD Gram matrix of side m |b| (rows (k, i) -> k |b| + i); ValueError for a solution without it
        (not optimal: a failed solve carries no Gram matrices) and TypeError for something that is no solution."""
        grams = getattr(solution, "grams", None)
        if not isinstance(grams, dict):
            raise TypeError(f"MatrixSOSConstraint {self.name!r}: expected a ProgramSolution, got "
                            f"{type(solution).__name__}")
        if self.name not in grams:
            status = getattr(getattr(solution, "status", None), "value", "unknown")
            raise ValueError(f"MatrixSOSConstraint {self.name!r}: the solution (status {status}) has no Gram "
                             "matrix for it; only a solved program's solution carries one")
        return grams[self.name]

    def factors(self, solution, rel_tol: float = 1e-9) -> tuple:
        """Polynomial vectors h_r (each a tuple of m Polynomials) with M(v) = sum_r h_r(v) h_r(v)^T (up to
        the solver's accuracy; eigenvalues of G below ``rel_tol`` times the largest are dropped)."""
        G = self.gram(solution)
        lam, W = np.linalg.eigh(G)
        s = self.basis.shape[0]
        out = []
        for r in range(lam.size):
            if lam[r] <= rel_tol * max(float(lam[-1]), 0.0) or lam[r] <= 0:
                continue
            w = np.sqrt(lam[r]) * W[:, r]
            out.append(tuple(Polynomial(self.gens, {tuple(int(t) for t in e): float(c)
                                                    for e, c in zip(self.basis, w[k * s:(k + 1) * s]) if c != 0.0})
                             for k in range(self.m)))
        return tuple(out)


def _triu_index(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """svec position of the pair (min, max) (column-wise upper triangle, :func:`sospoly.algebra.svec.triu_pairs`)."""
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    return hi * (hi + 1) // 2 + lo


def _gram_entry(gens, basis: np.ndarray, k: int, l: int, start: int) -> LinPoly:
    """sum_{i,j} G[(k,i),(l,j)] b_i b_j as a LinPoly over the PSD-matrix block starting at column ``start``."""
    s = basis.shape[0]
    i, j = np.meshgrid(np.arange(s), np.arange(s), indexing="ij")
    i, j = i.ravel(), j.ravel()
    E = basis[i] + basis[j]
    cols = start + _triu_index(k * s + i, l * s + j)
    return LinPoly(gens, E, np.zeros(E.shape[0]), np.arange(E.shape[0]), cols, np.ones(E.shape[0]))


def add_sos_matrix(program, M, degree: int | None = None, name: str | None = None,
                   basis=None) -> MatrixSOSConstraint:
    """Require the symmetric polynomial matrix ``M`` (list of lists of Polynomials / LinPolys / numbers) to
    be SOS (module docstring).  ``degree``: the even degree of the certificate (default: the largest
    entry degree rounded up); ``basis``: the exponent rows of b instead."""
    from .program import square_entries

    rows = square_entries(M, "add_sos_matrix M")
    m = len(rows)
    ent = [[program._as_linpoly(v) for v in r] for r in rows]
    for k in range(m):
        for l in range(k + 1, m):
            d = ent[k][l] - ent[l][k]
            if np.abs(d.const).max(initial=0.0) > 1e-12 or np.abs(d.vals).max(initial=0.0) > 1e-12:
                raise ValueError(f"add_sos_matrix M must be symmetric: M[{k}][{l}] != M[{l}][{k}]")
    deg = max(e.degree for r in ent for e in r)
    if basis is not None:
        b = exponent_rows(basis, program.nvars_poly, "add_sos_matrix basis")
    else:
        if degree is None:
            degree = max(deg, 0) + (max(deg, 0) % 2)
        degree = even_degree(degree, max(deg, 0), "add_sos_matrix degree (even, >= the entries' degree)")
        b = monomials(program.nvars_poly, degree // 2)
    s = b.shape[0]
    name = name or f"sosmat{len(program.blocks)}"
    program.psd_matrix(m * s, name=name)
    start = program.block(name).start
    for k in range(m):
        for l in range(k, m):
            program.add_identity(ent[k][l] - _gram_entry(program.gens, b, k, l, start), name=f"{name}[{k},{l}]")
    return MatrixSOSConstraint(name, m, b, program.gens)
